//! A run directory: scenario.toml (as flown), telemetry.csv (streamed, complete ticks only) and
//! audit.json (written atomically: temporary file, then rename).

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::audit::AuditReport;
use crate::scenario::Scenario;
use crate::telemetry::TelemetryWriter;

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
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
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
        // Prove the directory is writable before any work starts.
        let probe = path.join(".write-probe");
        File::create(&probe).map_err(|source| RunDirError::Unwritable {
            path: path.to_path_buf(),
            what: "write into",
            source,
        })?;
        let _ = fs::remove_file(&probe);
        Ok(RunDir {
            path: path.to_path_buf(),
        })
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

    /// Open telemetry.csv for streaming.
    pub fn telemetry(&self, every: u64) -> Result<TelemetryWriter<BufWriter<File>>, RunDirError> {
        let p = self.path.join("telemetry.csv");
        let f = File::create(&p).map_err(io_err(&p))?;
        TelemetryWriter::new(BufWriter::with_capacity(1 << 20, f), every).map_err(io_err(&p))
    }

    /// Write audit.json atomically.
    pub fn write_audit(&self, report: &AuditReport) -> Result<(), RunDirError> {
        let p = self.path.join("audit.json");
        let text = serde_json::to_string_pretty(report).map_err(|e| RunDirError::Io {
            path: p.clone(),
            source: std::io::Error::other(e),
        })?;
        write_atomic(&p, text.as_bytes())
    }
}

/// Write a file through a temporary sibling and a rename, so readers never see half a file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), RunDirError> {
    let tmp = path.with_extension("tmp");
    {
        let mut f = File::create(&tmp).map_err(io_err(&tmp))?;
        f.write_all(bytes).map_err(io_err(&tmp))?;
        f.sync_all().map_err(io_err(&tmp))?;
    }
    fs::rename(&tmp, path).map_err(io_err(path))
}
