//! Before iceoryx2 uses them: this user's iceoryx2 root must be a real directory owned by this
//! user and not writable by group or others, and every file iceoryx2 keeps directly in
//! `/dev/shm` under this user's prefix must be this user's, readable and writable by no one else.
//!
//! Each check opens the object first and then examines the open descriptor (`fstat`), so nothing
//! can be swapped between the check and the verdict; `/dev/shm` is sticky, so once checked a
//! directory or file of ours cannot be renamed or replaced by another user.

use std::ffi::CString;
use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};

use super::{Iox2Location, TransportError};

/// Where iceoryx2 puts the files named by the global prefix.
const SHM_DIR: &str = "/dev/shm";

/// The suffix of iceoryx2's global management segment (`<prefix><hash>_node.<version>.global_mgmt`),
/// which iceoryx2 creates world-writable (0666) so that every user of a prefix can share it.
const GLOBAL_MGMT_SUFFIX: &str = ".global_mgmt";

/// Creates the root when it is missing (0700), then checks it: a directory (not a link), owned
/// by this user, not writable by group or others.
pub(super) fn check_root(loc: &Iox2Location) -> Result<(), TransportError> {
    let root = loc.root.as_str();
    let c = cpath(root)?;
    // SAFETY: mkdir(2) on a NUL-terminated path we own; an existing entry is checked below.
    if unsafe { libc::mkdir(c.as_ptr(), 0o700) } != 0 {
        let e = io::Error::last_os_error();
        if e.kind() != io::ErrorKind::AlreadyExists {
            return Err(check_failed(root, "iceoryx2 root directory", e));
        }
    }
    let flags = libc::O_RDONLY | libc::O_DIRECTORY | libc::O_NOFOLLOW | libc::O_CLOEXEC;
    let fd = match open(&c, flags) {
        Ok(fd) => fd,
        // O_NOFOLLOW on a link gives ELOOP, O_DIRECTORY on anything else ENOTDIR.
        Err(e) if matches!(e.raw_os_error(), Some(libc::ELOOP | libc::ENOTDIR)) => {
            let st = lstat(&c).map_err(|e| check_failed(root, "iceoryx2 root directory", e))?;
            return Err(unsafe_path(root, "not a directory (a link or a file)", &st));
        }
        Err(e) => return Err(check_failed(root, "iceoryx2 root directory", e)),
    };
    let st = fstat(&fd).map_err(|e| check_failed(root, "iceoryx2 root directory", e))?;
    if st.st_uid != uid() {
        return Err(unsafe_path(root, "owned by another user", &st));
    }
    if st.st_mode & 0o022 != 0 {
        return Err(unsafe_path(root, "writable by group or others", &st));
    }
    Ok(())
}

/// Checks every `/dev/shm/<prefix>*.global_mgmt`: owned by this user, else refused. With
/// `restrict`, one that group or others may read or write becomes owner-only (0600): iceoryx2
/// creates it 0666, and only a process of ours has created it under our prefix.
pub(super) fn check_global_mgmt(loc: &Iox2Location, restrict: bool) -> Result<(), TransportError> {
    let entries = std::fs::read_dir(SHM_DIR).map_err(|e| check_failed(SHM_DIR, "directory", e))?;
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        if !(name.starts_with(&loc.prefix) && name.ends_with(GLOBAL_MGMT_SUFFIX)) {
            continue;
        }
        let path = format!("{SHM_DIR}/{name}");
        let what = "iceoryx2 management segment";
        let c = cpath(&path)?;
        // O_PATH: no read or write access needed to examine it, nor to change its mode below.
        let fd = match open(&c, libc::O_PATH | libc::O_NOFOLLOW | libc::O_CLOEXEC) {
            Ok(fd) => fd,
            Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
            Err(e) => return Err(check_failed(&path, what, e)),
        };
        let st = fstat(&fd).map_err(|e| check_failed(&path, what, e))?;
        if st.st_mode & libc::S_IFMT != libc::S_IFREG {
            return Err(unsafe_path(&path, "not a regular file", &st));
        }
        if st.st_uid != uid() {
            return Err(unsafe_path(&path, "owned by another user", &st));
        }
        if restrict && st.st_mode & 0o077 != 0 {
            // chmod through the descriptor's /proc link changes exactly the file examined
            // (fchmod(2) refuses O_PATH descriptors).
            let via = cpath(&format!("/proc/self/fd/{}", fd.as_raw_fd()))?;
            // SAFETY: chmod(2) on a NUL-terminated path.
            if unsafe { libc::chmod(via.as_ptr(), st.st_mode & 0o700) } != 0 {
                return Err(check_failed(&path, what, io::Error::last_os_error()));
            }
        }
    }
    Ok(())
}

fn uid() -> libc::uid_t {
    // SAFETY: getuid(2) cannot fail and touches no memory of ours.
    unsafe { libc::getuid() }
}

fn cpath(path: &str) -> Result<CString, TransportError> {
    CString::new(path).map_err(|e| check_failed(path, "path", io::Error::other(e)))
}

fn open(path: &CString, flags: libc::c_int) -> io::Result<OwnedFd> {
    // SAFETY: open(2) on a NUL-terminated path; the descriptor is owned from here on.
    let fd = unsafe { libc::open(path.as_ptr(), flags) };
    if fd < 0 {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: `fd` was just opened and is owned by nobody else.
    Ok(unsafe { OwnedFd::from_raw_fd(fd) })
}

fn fstat(fd: &OwnedFd) -> io::Result<libc::stat> {
    // SAFETY: an all-zero `stat` is a valid value for fstat(2) to overwrite.
    let mut st: libc::stat = unsafe { std::mem::zeroed() };
    // SAFETY: fstat(2) on an open descriptor into a stat we own.
    if unsafe { libc::fstat(fd.as_raw_fd(), &mut st) } != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(st)
}

fn lstat(path: &CString) -> io::Result<libc::stat> {
    // SAFETY: as in `fstat`.
    let mut st: libc::stat = unsafe { std::mem::zeroed() };
    // SAFETY: lstat(2) on a NUL-terminated path into a stat we own.
    if unsafe { libc::lstat(path.as_ptr(), &mut st) } != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(st)
}

fn unsafe_path(path: &str, problem: &'static str, st: &libc::stat) -> TransportError {
    TransportError::UnsafeIox2Path {
        path: path.to_owned(),
        problem,
        owner: st.st_uid,
        mode: st.st_mode & 0o7777,
        uid: uid(),
    }
}

fn check_failed(path: &str, what: &'static str, source: io::Error) -> TransportError {
    TransportError::Iox2PathCheck {
        path: path.to_owned(),
        what,
        source,
    }
}
