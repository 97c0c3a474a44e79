//! SIGINT / SIGTERM / SIGHUP / SIGQUIT to a flag, so loops stop cleanly (and release their
//! shared memory, and the orchestrator writes audit.json) instead of dying mid-write. SIGHUP is
//! what a closed terminal sends; its default action, like SIGQUIT's, kills at once.

use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// The last stopping signal received (0: none yet).
static SIGNAL: AtomicI32 = AtomicI32::new(0);

/// The signals that stop a process cleanly.
const STOPPING: [libc::c_int; 4] = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP, libc::SIGQUIT];

extern "C" fn on_signal(sig: libc::c_int) {
    SIGNAL.store(sig, Ordering::SeqCst);
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// The name of the stopping signal received last (`SIGHUP`, ...), or "a signal" when none was.
pub fn received() -> &'static str {
    match SIGNAL.load(Ordering::SeqCst) {
        libc::SIGINT => "SIGINT",
        libc::SIGTERM => "SIGTERM",
        libc::SIGHUP => "SIGHUP",
        libc::SIGQUIT => "SIGQUIT",
        _ => "a signal",
    }
}

/// Said on SIGBUS, which iceoryx2 gets when it writes into a shared-memory segment the file
/// system has no room for.
const BUS_MESSAGE: &[u8] = b"error: bus error (SIGBUS) touching shared memory: /dev/shm is probably full; free space there or enlarge it (e.g. `mount -o remount,size=1G /dev/shm`)\n";

extern "C" fn on_bus_error(_: libc::c_int) {
    // SAFETY: write(2) and _exit(2) are async-signal-safe; the buffer is static.
    unsafe {
        libc::write(2, BUS_MESSAGE.as_ptr().cast(), BUS_MESSAGE.len());
        libc::_exit(3);
    }
}

/// Install the handlers (idempotent) and return the flag they set.
pub fn install() -> &'static AtomicBool {
    // SAFETY: the handlers only store to an atomic, or write a static message and exit, which
    // is async-signal-safe.
    unsafe {
        for sig in STOPPING {
            libc::signal(sig, on_signal as *const () as libc::sighandler_t);
        }
        libc::signal(
            libc::SIGBUS,
            on_bus_error as *const () as libc::sighandler_t,
        );
    }
    &INTERRUPTED
}
