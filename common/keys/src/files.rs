//! The key files on disk: owner-only directories and files, created new, never overwritten.

use std::io::Write;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

/// What went wrong with a team's keys, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum KeyDirError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: already exists and is not empty (keys are never overwritten)", path.display())]
    Exists { path: PathBuf },
    #[error("{}: mode {mode:04o} lets others read it; keys must be their owner's only ({fix})", path.display())]
    Readable {
        path: PathBuf,
        mode: u32,
        fix: &'static str,
    },
    /// Others can replace the file (or, in the directory, its files) with their own authority's.
    #[error("{}: mode {mode:04o} lets others write it; keys must be their owner's only ({fix})", path.display())]
    Writable {
        path: PathBuf,
        mode: u32,
        fix: &'static str,
    },
    /// Owned by another user, who can change its mode and contents at will.
    #[error("{}: owned by user {owner}, not by user {me} who runs this; keys must be their owner's only", path.display())]
    NotOwned { path: PathBuf, owner: u32, me: u32 },
    #[error("{}: {detail}", path.display())]
    Certificate { path: PathBuf, detail: String },
    #[error("cannot make {what}: {source}")]
    Make {
        what: &'static str,
        #[source]
        source: rcgen::Error,
    },
}

impl KeyDirError {
    pub(crate) fn rcgen(what: &'static str) -> impl FnOnce(rcgen::Error) -> KeyDirError {
        move |source| KeyDirError::Make { what, source }
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> KeyDirError + '_ {
    move |source| KeyDirError::Io {
        path: path.to_owned(),
        source,
    }
}

/// `dir` made (0700), or already there and empty.
pub(crate) fn new_empty_dir(dir: &Path) -> Result<(), KeyDirError> {
    match std::fs::read_dir(dir).map(|mut e| e.next().is_some()) {
        Ok(true) => Err(KeyDirError::Exists {
            path: dir.to_owned(),
        }),
        Ok(false) => {
            use std::os::unix::fs::PermissionsExt;
            let owner_only = std::fs::Permissions::from_mode(0o700);
            std::fs::set_permissions(dir, owner_only).map_err(io(dir))
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => make_dir(dir),
        Err(e) => Err(io(dir)(e)),
    }
}

/// A new directory, 0700 (its parents as needed).
pub(crate) fn make_dir(dir: &Path) -> Result<(), KeyDirError> {
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(dir)
        .map_err(io(dir))
}

/// A new file, 0600 from its creation on (never a moment readable by others).
pub(crate) fn write_new(path: &Path, bytes: &[u8]) -> Result<(), KeyDirError> {
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)
        .map_err(io(path))?;
    f.write_all(bytes)
        .and_then(|_| f.sync_all())
        .map_err(io(path))
}

pub(crate) fn read(path: &Path) -> Result<Vec<u8>, KeyDirError> {
    std::fs::read(path).map_err(io(path))
}

/// `path` (a file or a directory) is ours, and only we can read, write or enter it: a key
/// directory another user can write lets them put their own authority's certificate and keys in
/// it (then their daemon joins our team), and one they own they can open at will.
pub(crate) fn check_private(path: &Path) -> Result<(), KeyDirError> {
    let m = std::fs::metadata(path).map_err(io(path))?;
    // SAFETY: geteuid(2) cannot fail.
    let me = unsafe { libc::geteuid() };
    if m.uid() != me {
        return Err(KeyDirError::NotOwned {
            path: path.to_owned(),
            owner: m.uid(),
            me,
        });
    }
    let mode = m.mode() & 0o7777;
    let fix = if m.is_dir() { "chmod 700" } else { "chmod 600" };
    let path = path.to_owned();
    if mode & 0o022 != 0 {
        return Err(KeyDirError::Writable { path, mode, fix });
    }
    if mode & 0o077 != 0 {
        return Err(KeyDirError::Readable { path, mode, fix });
    }
    Ok(())
}
