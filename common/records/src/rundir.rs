//! A run directory: scenario.toml (as flown), telemetry.csv (streamed, complete ticks only) and
//! audit.json (written atomically: temporary file, then rename; its room reserved when the
//! directory is opened, so a run that fills the disk still records its outcome). Nothing here
//! follows a symbolic link (`cdm_files::create_file`).

use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

use crate::audit::AuditReport;
use crate::telemetry::{Rewind, TelemetryWriter};
use cdm_files::FileError;
use cdm_scenario::Scenario;

/// Room reserved for audit.json when a run directory is opened (a paper40 audit with a few
/// hundred violations is about 60 KiB).
pub const AUDIT_RESERVE_BYTES: u64 = 128 << 10;

/// A run directory problem, naming the path.
#[derive(Debug, thiserror::Error)]
pub enum RunDirError {
    #[error("--out {path}: exists and is not empty (use --force to overwrite)")]
    NotEmpty { path: PathBuf },
    #[error("--out {path}: exists and is not a directory")]
    NotADirectory { path: PathBuf },
    /// The directory cannot be created or written (a parent is a file, a read-only or virtual
    /// file system, permissions).
    #[error("--out {path}: cannot {what} the run directory: {source}")]
    Unwritable {
        path: PathBuf,
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: {}", path.display(), cdm_files::describe(path, source))]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    File(#[from] FileError),
}

impl RunDirError {
    /// Whether the file system (or quota) is full: a runtime fault (exit 3), not bad input.
    pub fn is_disk_full(&self) -> bool {
        match self {
            RunDirError::Io { source, .. } | RunDirError::Unwritable { source, .. } => {
                cdm_files::is_disk_full(source)
            }
            RunDirError::File(f) => f.is_disk_full(),
            _ => false,
        }
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> RunDirError + '_ {
    move |source| RunDirError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// An open run directory.
pub struct RunDir {
    path: PathBuf,
}

impl RunDir {
    /// Create (or, with `force`, reuse) a run directory. A non-empty directory is refused unless
    /// `force`; with `force` the files this tool writes are replaced, others are left alone.
    pub fn create(path: &Path, force: bool) -> Result<Self, RunDirError> {
        if path.exists() {
            if !path.is_dir() {
                return Err(RunDirError::NotADirectory {
                    path: path.to_path_buf(),
                });
            }
            let mut entries = fs::read_dir(path).map_err(io_err(path))?;
            if entries.next().is_some() && !force {
                return Err(RunDirError::NotEmpty {
                    path: path.to_path_buf(),
                });
            }
        } else {
            fs::create_dir_all(path).map_err(|source| RunDirError::Unwritable {
                path: path.to_path_buf(),
                what: "create",
                source,
            })?;
        }
        // Reserving audit.json's room also proves the directory writable before any work.
        let dir = RunDir {
            path: path.to_path_buf(),
        };
        dir.reserve_audit().map_err(|e| match e {
            FileError::Io { source, .. } if !cdm_files::is_disk_full(&source) => {
                RunDirError::Unwritable {
                    path: path.to_path_buf(),
                    what: "write into",
                    source,
                }
            }
            other => RunDirError::File(other),
        })?;
        Ok(dir)
    }

    /// Allocate audit.json's temporary file (`audit.json.tmp`) at its full reserved size, so the
    /// final audit is written into blocks the run's telemetry cannot take.
    fn reserve_audit(&self) -> Result<(), FileError> {
        let tmp = cdm_files::temporary_of(&self.path.join("audit.json"));
        let f = cdm_files::create_file(&tmp)?;
        let at = |source| FileError::Io {
            path: tmp.clone(),
            source,
        };
        use std::os::fd::AsRawFd;
        let len = AUDIT_RESERVE_BYTES as libc::off_t;
        // SAFETY: a valid open descriptor and a non-negative range.
        let rc = unsafe { libc::posix_fallocate(f.as_raw_fd(), 0, len) };
        let reserved = match rc {
            0 => Ok(()),
            // No fallocate on this file system: write the bytes instead.
            libc::EOPNOTSUPP | libc::EINVAL => (&f)
                .write_all(&vec![b' '; AUDIT_RESERVE_BYTES as usize])
                .map_err(at),
            e => Err(at(io::Error::from_raw_os_error(e))),
        };
        if reserved.is_err() {
            drop(f);
            let _ = fs::remove_file(&tmp);
        }
        reserved
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Write scenario.toml (the scenario as flown).
    pub fn write_scenario(&self, s: &Scenario) -> Result<(), RunDirError> {
        write_atomic(&self.path.join("scenario.toml"), s.to_toml().as_bytes())
    }

    /// Write scenario.json (the same scenario for the member processes, which parse JSON with a
    /// fraction of TOML's memory) and return its path.
    pub fn write_member_scenario(&self, s: &Scenario) -> Result<PathBuf, RunDirError> {
        let p = self.path.join("scenario.json");
        write_atomic(&p, s.to_json().as_bytes())?;
        Ok(p)
    }

    /// Open telemetry.csv for streaming (whole ticks only, even when the disk fills up).
    pub fn telemetry(&self, every: u64) -> Result<TelemetryWriter<RunFile>, RunDirError> {
        let p = self.path.join("telemetry.csv");
        let file = cdm_files::create_file(&p)?;
        TelemetryWriter::new(
            RunFile {
                file,
                path: p.clone(),
            },
            every,
        )
        .map_err(io_err(&p))
    }

    /// Write audit.json atomically into the room reserved for it (a fresh temporary when the
    /// reservation is gone). On failure the previous audit.json, if any, is left as it was.
    pub fn write_audit(&self, report: &AuditReport) -> Result<(), RunDirError> {
        let p = self.path.join("audit.json");
        let text = serde_json::to_string_pretty(report).map_err(|e| RunDirError::Io {
            path: p.clone(),
            source: std::io::Error::other(e),
        })?;
        let tmp = cdm_files::temporary_of(&p);
        // The reservation is our own regular file; O_NOFOLLOW refuses a link put in its place.
        let reserved = OpenOptions::new()
            .write(true)
            .custom_flags(libc::O_NOFOLLOW)
            .open(&tmp)
            .ok()
            .filter(|f| f.metadata().is_ok_and(|m| m.is_file()));
        let Some(f) = reserved else {
            return write_atomic(&p, text.as_bytes());
        };
        let done = cdm_files::fill(f, &tmp, text.as_bytes()).and_then(|()| {
            fs::rename(&tmp, &p).map_err(|source| FileError::Io {
                path: p.clone(),
                source,
            })
        });
        if done.is_err() {
            let _ = fs::remove_file(&tmp);
        }
        Ok(done?)
    }
}

/// telemetry.csv: a file whose errors name it (and the free space when the disk is full).
pub struct RunFile {
    file: File,
    path: PathBuf,
}

impl RunFile {
    fn named(&self, e: io::Error) -> io::Error {
        let what = format!(
            "{}: {}",
            self.path.display(),
            cdm_files::describe(&self.path, &e)
        );
        io::Error::new(e.kind(), what)
    }
}

impl Write for RunFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.file.write(buf).map_err(|e| self.named(e))
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.flush().map_err(|e| self.named(e))
    }
}

impl Rewind for RunFile {
    fn rewind_to(&mut self, len: u64) -> io::Result<()> {
        self.file.rewind_to(len)
    }
}

/// Write a file through a temporary sibling and a rename, so readers never see half a file (see
/// [`cdm_files::write_atomic`]: never follows a link, keeps the old file on failure).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), RunDirError> {
    Ok(cdm_files::write_atomic(path, bytes)?)
}
