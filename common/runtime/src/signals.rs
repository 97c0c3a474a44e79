//! SIGINT / SIGTERM to a flag, so loops stop cleanly (and release their shared memory) instead
//! of dying mid-write.

use std::sync::atomic::{AtomicBool, Ordering};

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
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
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
        libc::signal(
            libc::SIGBUS,
            on_bus_error as *const () as libc::sighandler_t,
        );
    }
    &INTERRUPTED
}
