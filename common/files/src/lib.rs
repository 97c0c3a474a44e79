//! Files the tool reads and writes, done safely (README, "What happens when things go wrong"):
//!
//! - inputs (scenario files, a run's telemetry.csv and audit.json) are read only from regular
//!   files, and whole-file reads stop at [`MAX_INPUT_BYTES`]: `/dev/zero` or a FIFO given as a
//!   file is refused, never read forever or waited on;
//! - outputs never follow a symbolic link: an existing entry is removed (the link, not its
//!   target) and the file created anew with `O_EXCL`, which refuses a link planted in between;
//! - a write that fails for want of space says so with the free space left.

use std::fs::{self, File, OpenOptions};
use std::io::{self, Read, Write};
use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

/// The largest file read whole (a 2000-member scenario is about 0.3 MiB).
pub const MAX_INPUT_BYTES: u64 = 64 << 20;

/// A file that cannot be read or written, naming it.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// Reading or writing failed; a full file system is reported with its free space.
    #[error("{}: {}", path.display(), describe(path, source))]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    /// Not a regular file (a FIFO, a device, a directory, a socket).
    #[error("{}: is {kind}, not a regular file", path.display())]
    NotRegular { path: PathBuf, kind: &'static str },
    /// Larger than the tool reads whole.
    #[error("{}: larger than {} MiB; refusing to read it", path.display(), limit >> 20)]
    TooLarge { path: PathBuf, limit: u64 },
}

impl FileError {
    /// What is wrong, without the path (for messages that name the file already).
    pub fn reason(&self) -> String {
        match self {
            FileError::Io { path, source } => describe(path, source),
            FileError::NotRegular { kind, .. } => format!("it is {kind}, not a regular file"),
            FileError::TooLarge { limit, .. } => {
                format!("larger than {} MiB; refusing to read it", limit >> 20)
            }
        }
    }

    /// Whether the file system (or the user's quota) is full: a runtime fault, not bad input.
    pub fn is_disk_full(&self) -> bool {
        matches!(self, FileError::Io { source, .. } if is_disk_full(source))
    }
}

/// Whether an I/O error means the file system or the quota is full.
pub fn is_disk_full(e: &io::Error) -> bool {
    matches!(e.raw_os_error(), Some(libc::ENOSPC) | Some(libc::EDQUOT))
        || e.kind() == io::ErrorKind::StorageFull
}

/// An I/O error for people: a full file system comes with the free space where `path` lives.
pub fn describe(path: &Path, e: &io::Error) -> String {
    if !is_disk_full(e) {
        return e.to_string();
    }
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    match free_bytes(dir) {
        Some(free) => format!(
            "no space left on the device ({} KiB free in {}); free space there or choose another --out",
            free / 1024,
            dir.display()
        ),
        None => "no space left on the device; free space there or choose another --out".into(),
    }
}

/// Bytes available to this user on the file system holding `dir`.
pub fn free_bytes(dir: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: `c` is a valid NUL-terminated path and `st` a properly sized out-parameter.
    if unsafe { libc::statvfs(c.as_ptr(), &mut st) } != 0 {
        return None;
    }
    Some(st.f_bavail as u64 * st.f_frsize as u64)
}

fn io_at(path: &Path) -> impl FnOnce(io::Error) -> FileError + '_ {
    move |source| FileError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Open an input for reading: regular files only. `O_NONBLOCK` makes opening a FIFO return at
/// once instead of waiting for a writer; the type is then checked on the open descriptor (no
/// race between the check and the read).
pub fn open_input(path: &Path) -> Result<File, FileError> {
    let f = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(io_at(path))?;
    let t = f.metadata().map_err(io_at(path))?.file_type();
    if t.is_file() {
        return Ok(f);
    }
    let kind = if t.is_dir() {
        "a directory"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "a special file"
    };
    Err(FileError::NotRegular {
        path: path.to_path_buf(),
        kind,
    })
}

/// Read a regular file of at most `limit` bytes as UTF-8 text.
pub fn read_input(path: &Path, limit: u64) -> Result<String, FileError> {
    let f = open_input(path)?;
    let too_large = || FileError::TooLarge {
        path: path.to_path_buf(),
        limit,
    };
    let mut text = String::new();
    // One byte more than allowed tells a file at the limit from a larger one (a file can grow
    // after a metadata check, so the read itself is bounded).
    f.take(limit + 1)
        .read_to_string(&mut text)
        .map_err(io_at(path))?;
    if text.len() as u64 > limit {
        return Err(too_large());
    }
    Ok(text)
}

/// Create `path` for writing without following a symbolic link: an existing non-directory entry
/// is removed first (a link is removed, its target untouched), then the file is created with
/// `O_EXCL`, which fails rather than follow a link created meanwhile.
pub fn create_file(path: &Path) -> Result<File, FileError> {
    if let Ok(m) = fs::symlink_metadata(path) {
        if !m.is_dir() {
            fs::remove_file(path).map_err(io_at(path))?;
        }
    }
    OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)
        .map_err(io_at(path))
}

/// The temporary sibling `write_atomic` writes first (`audit.json` -> `audit.json.tmp`).
pub fn temporary_of(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".tmp");
    path.with_file_name(name)
}

/// Write a file through a temporary sibling and a rename, so readers never see half a file and
/// a failed write keeps the old file. Never follows a link; the temporary is removed on failure.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    let tmp = temporary_of(path);
    let written = create_file(&tmp).and_then(|f| fill(f, &tmp, bytes));
    let renamed = written.and_then(|()| fs::rename(&tmp, path).map_err(io_at(path)));
    if renamed.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    renamed
}

/// Write `bytes` from the start of `f`, drop anything beyond them and sync.
pub fn fill(mut f: File, path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    f.write_all(bytes).map_err(io_at(path))?;
    f.set_len(bytes.len() as u64).map_err(io_at(path))?;
    f.sync_all().map_err(io_at(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("cdm-files-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn writing_replaces_a_link_and_leaves_its_target_alone() {
        let d = scratch("link");
        let target = d.join("target");
        fs::write(&target, "precious").unwrap();
        std::os::unix::fs::symlink(&target, d.join("out.csv")).unwrap();
        write_atomic(&d.join("out.csv"), b"new").unwrap();
        assert_eq!(fs::read_to_string(&target).unwrap(), "precious");
        assert_eq!(fs::read_to_string(d.join("out.csv")).unwrap(), "new");
        assert!(!fs::symlink_metadata(d.join("out.csv"))
            .unwrap()
            .file_type()
            .is_symlink());
        let _ = fs::remove_dir_all(&d);
    }

    #[test]
    fn inputs_are_bounded_and_regular() {
        let d = scratch("input");
        let p = d.join("big");
        fs::write(&p, vec![b'a'; 100]).unwrap();
        assert!(matches!(
            read_input(&p, 99),
            Err(FileError::TooLarge { .. })
        ));
        assert_eq!(read_input(&p, 100).unwrap().len(), 100);
        assert!(matches!(
            read_input(Path::new("/dev/zero"), 10),
            Err(FileError::NotRegular { .. })
        ));
        assert!(matches!(
            read_input(&d, 10),
            Err(FileError::NotRegular { .. })
        ));
        let _ = fs::remove_dir_all(&d);
    }
}
