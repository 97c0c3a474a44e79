//! Members forked from a template process rather than started from their binary: the OS side.
//!
//! Why: at N = 1000 a member spent about 5.3 ms of CPU from `exec` to its first port, most of it
//! the kernel's `exec`, the dynamic loader (whose CPU-feature probing traps to the hypervisor in
//! a VM) and reading the 1000-member scenario; a thousand of them were most of a launch's
//! start-up. A template process pays that once and forks each member from itself
//! (`cdm-member`'s `template.rs`). The orchestrator still owns every member as its child: the
//! template forks through a short-lived intermediate process, and the orchestrator, a
//! subreaper, adopts the member when the intermediate exits ([`become_subreaper`],
//! [`fork_detached`], [`Adopted`]).

use std::io;
use std::os::unix::process::ExitStatusExt;
use std::process::ExitStatus;

/// Makes this process the reaper of its orphaned descendants (`PR_SET_CHILD_SUBREAPER`): a
/// process forked by one of its children through an intermediate that exits becomes its child,
/// to be waited for and signalled like one it spawned.
pub fn become_subreaper() -> io::Result<()> {
    let (on, unused): (libc::c_ulong, libc::c_ulong) = (1, 0);
    // SAFETY: prctl with integer arguments only.
    let rc = unsafe { libc::prctl(libc::PR_SET_CHILD_SUBREAPER, on, unused, unused, unused) };
    if rc == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

/// A child this process did not fork itself but adopted as a subreaper: waited for, and
/// killed, by its pid, as `std::process::Child` does for one spawned.
#[derive(Debug)]
pub struct Adopted {
    pid: libc::pid_t,
    /// Once reaped: its pid may then belong to another process and is never signalled again.
    status: Option<ExitStatus>,
}

impl Adopted {
    /// The child `pid` (this process must be its parent).
    pub fn new(pid: u32) -> Self {
        Adopted {
            pid: pid as libc::pid_t,
            status: None,
        }
    }

    /// Its process id.
    pub fn id(&self) -> u32 {
        self.pid as u32
    }

    /// How it ended, if it has (reaping it), without waiting.
    pub fn try_wait(&mut self) -> io::Result<Option<ExitStatus>> {
        self.reap(libc::WNOHANG)
    }

    /// Waits until it ends (reaping it).
    pub fn wait(&mut self) -> io::Result<ExitStatus> {
        loop {
            match self.reap(0) {
                Ok(Some(s)) => return Ok(s),
                Ok(None) => {}
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
    }

    /// SIGKILL, unless it was reaped already (as `Child::kill`).
    pub fn kill(&mut self) -> io::Result<()> {
        if self.status.is_some() {
            return Ok(());
        }
        // SAFETY: kill(2) on our own child's pid, not reaped yet (so not reused).
        if unsafe { libc::kill(self.pid, libc::SIGKILL) } == 0 {
            Ok(())
        } else {
            Err(io::Error::last_os_error())
        }
    }

    fn reap(&mut self, flags: libc::c_int) -> io::Result<Option<ExitStatus>> {
        if let Some(s) = self.status {
            return Ok(Some(s));
        }
        let mut raw: libc::c_int = 0;
        // SAFETY: waitpid writes one int we own.
        let r = unsafe { libc::waitpid(self.pid, &mut raw, flags) };
        if r == self.pid {
            let s = ExitStatus::from_raw(raw);
            self.status = Some(s);
            Ok(Some(s))
        } else if r == 0 {
            Ok(None)
        } else {
            Err(io::Error::last_os_error())
        }
    }
}

/// Forks a process that runs `run` and exits with the code it returns (101 if it panics, as a
/// Rust program does), through an
/// intermediate process that exits at once: the new process is then not this process's child
/// but its parent's, when the parent is a subreaper ([`become_subreaper`]). Returns its pid
/// once the intermediate is reaped, so the parent can wait for it as soon as it has the pid.
///
/// For a single-threaded caller only: the new process is a copy of this one with only the
/// calling thread, and must not find a lock another thread held.
pub fn fork_detached(run: impl FnOnce() -> i32) -> io::Result<u32> {
    let mut fds = [0 as libc::c_int; 2];
    // SAFETY: pipe2 writes two ints into the array we own.
    if unsafe { libc::pipe2(fds.as_mut_ptr(), libc::O_CLOEXEC) } != 0 {
        return Err(io::Error::last_os_error());
    }
    let [read_end, write_end] = fds;
    // SAFETY: fork(2); the caller is single-threaded (documented above).
    let mid = unsafe { libc::fork() };
    if mid == 0 {
        // The intermediate: fork the member, tell its pid, exit without running any
        // destructor or exit handler of the template's.
        // SAFETY: plain syscalls on our own descriptors; `_exit` never returns.
        unsafe {
            libc::close(read_end);
            let pid = libc::fork();
            if pid == 0 {
                libc::close(write_end);
                // A panic must end this process (as it ends a started one, 101), never unwind
                // into the caller's code, which this copy would then go on running.
                let code = std::panic::catch_unwind(std::panic::AssertUnwindSafe(run));
                std::process::exit(code.unwrap_or(101));
            }
            // The pid, or minus the errno of the failed fork.
            let told = match pid {
                p if p > 0 => p,
                _ => -io::Error::last_os_error()
                    .raw_os_error()
                    .unwrap_or(libc::EAGAIN),
            };
            let bytes = told.to_ne_bytes();
            libc::write(write_end, bytes.as_ptr().cast(), bytes.len());
            libc::_exit(0);
        }
    }
    // SAFETY: our own descriptor, not used again.
    unsafe { libc::close(write_end) };
    if mid < 0 {
        let e = io::Error::last_os_error();
        // SAFETY: as above.
        unsafe { libc::close(read_end) };
        return Err(e);
    }
    let mut bytes = [0u8; std::mem::size_of::<libc::pid_t>()];
    let mut got = 0;
    while got < bytes.len() {
        // SAFETY: reads into the part of `bytes` not filled yet.
        let r = unsafe {
            libc::read(
                read_end,
                bytes[got..].as_mut_ptr().cast(),
                bytes.len() - got,
            )
        };
        match r {
            r if r > 0 => got += r as usize,
            0 => break,
            _ if io::Error::last_os_error().kind() == io::ErrorKind::Interrupted => {}
            _ => break,
        }
    }
    // SAFETY: our own descriptor, not used again.
    unsafe { libc::close(read_end) };
    let mut raw = 0;
    // SAFETY: waits for our own child; writes one int we own.
    while unsafe { libc::waitpid(mid, &mut raw, 0) } < 0 {
        if io::Error::last_os_error().kind() != io::ErrorKind::Interrupted {
            break;
        }
    }
    match libc::pid_t::from_ne_bytes(bytes) {
        pid if got == bytes.len() && pid > 0 => Ok(pid as u32),
        errno if got == bytes.len() && errno < 0 => Err(io::Error::from_raw_os_error(-errno)),
        _ => Err(io::Error::other(
            "the intermediate process ended without forking the member",
        )),
    }
}

/// Rewrites the command line `ps` and `/proc/<pid>/cmdline` show for this process: a forked
/// member shows the arguments it would have been started with, so tools (and operators) that
/// find a member by `--team T --id I` still do. The kernel's argument area (its bounds read
/// from `/proc/self/stat`) keeps its size: arguments beyond it are cut, the rest is zeros (the
/// template is started with room to spare).
///
/// The process's own arguments (`std::env::args`) read that area: call it only in a process
/// that no longer reads them.
pub fn set_cmdline<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let stat = std::fs::read_to_string("/proc/self/stat")?;
    // Fields after the command name's closing parenthesis start at field 3; `arg_start` and
    // `arg_end` are fields 48 and 49 (proc(5)).
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let field = |n: usize| fields.get(n - 3).and_then(|f| f.parse::<usize>().ok());
    let (Some(start), Some(end)) = (field(48), field(49)) else {
        return Err(io::Error::other("no argument area in /proc/self/stat"));
    };
    if end <= start || start == 0 {
        return Err(io::Error::other("an empty argument area"));
    }
    let room = end - start;
    let mut bytes = Vec::with_capacity(room);
    for a in args {
        bytes.extend_from_slice(a.as_ref().as_bytes());
        bytes.push(0);
    }
    bytes.resize(room, 0);
    bytes[room - 1] = 0;
    // SAFETY: [start, end) is this process's own argument area on its initial stack, mapped and
    // writable; `bytes` has exactly its length; nothing of ours points into it for reading
    // (the caller no longer reads its arguments).
    unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), start as *mut u8, room) };
    Ok(())
}

/// Sets the name `ps` and `/proc/<pid>/comm` show for this thread (at most 15 bytes kept).
pub fn set_name(name: &str) {
    let mut buf = [0u8; 16];
    let n = name.len().min(15);
    buf[..n].copy_from_slice(&name.as_bytes()[..n]);
    let unused: libc::c_ulong = 0;
    // SAFETY: PR_SET_NAME reads a NUL-terminated string of at most 16 bytes from `buf`.
    unsafe {
        libc::prctl(
            libc::PR_SET_NAME,
            buf.as_ptr() as libc::c_ulong,
            unused,
            unused,
            unused,
        )
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A detached process is adopted by its subreaper, which reads its exit code and its
    /// rewritten command line. The test forks, so the work is done in a child process of the
    /// test (itself single-threaded) that reports through its exit code.
    #[test]
    fn a_detached_process_is_adopted_with_its_exit_code_and_command_line() {
        // SAFETY: fork(2); the child only calls the functions under test and exits.
        let tester = unsafe { libc::fork() };
        assert!(tester >= 0, "fork: {}", io::Error::last_os_error());
        if tester == 0 {
            let code = (|| {
                become_subreaper().ok()?;
                let (rd, wr) = pipe()?;
                let pid = fork_detached(|| {
                    let ok = set_cmdline(&["agent", "--team", "t", "--id", "7"]).is_ok();
                    let one = [u8::from(ok)];
                    // SAFETY: writes one byte of ours to the test's pipe.
                    unsafe { libc::write(wr, one.as_ptr().cast(), 1) };
                    // Wait for the parent's check of the command line.
                    std::thread::sleep(std::time::Duration::from_millis(500));
                    7
                })
                .ok()?;
                let mut one = [0u8];
                // SAFETY: reads one byte into ours.
                (unsafe { libc::read(rd, one.as_mut_ptr().cast(), 1) } == 1 && one[0] == 1)
                    .then_some(())?;
                let cmd = std::fs::read(format!("/proc/{pid}/cmdline")).ok()?;
                cmd.starts_with(b"agent\0--team\0t\0--id\x007\0")
                    .then_some(())?;
                let mut child = Adopted::new(pid);
                let status = child.wait().ok()?;
                (status.code() == Some(7)).then_some(())?;
                child.kill().ok()?;
                Some(())
            })();
            // SAFETY: leaves the forked test process without running the harness's handlers.
            unsafe { libc::_exit(if code.is_some() { 0 } else { 1 }) };
        }
        let mut raw = 0;
        // SAFETY: waits for our own child.
        assert_eq!(unsafe { libc::waitpid(tester, &mut raw, 0) }, tester);
        assert_eq!(ExitStatus::from_raw(raw).code(), Some(0));
    }

    fn pipe() -> Option<(libc::c_int, libc::c_int)> {
        let mut fds = [0; 2];
        // SAFETY: pipe writes two ints into the array we own.
        (unsafe { libc::pipe(fds.as_mut_ptr()) } == 0).then_some((fds[0], fds[1]))
    }
}
