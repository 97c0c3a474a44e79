//! Why an export failed: one enum for every export, each variant naming the file or the flag at
//! fault and keeping the library error it wraps as its `source`. [`ExportError::is_bad_input`]
//! says whether the caller gave something wrong (exit 2) or the machine failed (exit 3).

use std::path::PathBuf;

use cdm_records::rundir::RunDirError;
use cdm_report::data::ReadError;
use cdm_rosbag::BagError;
use cdm_scenario::ScenarioError;
use cdm_trajectory::{FrameError, SplitError};

#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The scenario (a file, a built-in, a generated team) cannot be loaded or is invalid.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// `--scale`, `--origin` or `--eps` is unusable.
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// The plan cannot be cut into pieces the target (a Crazyflie) holds.
    #[error("export crazyswarm2: {0}")]
    Split(#[source] SplitError),
    /// An output directory could not be created.
    #[error("--out {}: cannot create: {source}", dir.display())]
    CreateDir {
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// `--out` already holds something (a file, or a directory that is not empty): it is not
    /// overwritten unless `--force`.
    #[error("--out {}: exists{} (use --force to overwrite)", out.display(), if *dir { " and is not empty" } else { "" })]
    OutExists { out: PathBuf, dir: bool },
    /// `--out` has no file name to write (a show file is named by it).
    #[error("--out {}: not a file name", out.display())]
    NotAFile { out: PathBuf },
    /// A file of the export could not be written (the error names it).
    #[error(transparent)]
    Write(#[from] RunDirError),
    /// The .skyc archive could not be assembled in memory.
    #[error("{}: {source}", file.display())]
    Zip {
        file: PathBuf,
        #[source]
        source: zip::result::ZipError,
    },
    /// A document could not be serialised (a bug: every number written is finite).
    #[error("{what}: {source}")]
    Json {
        what: &'static str,
        #[source]
        source: serde_json::Error,
    },
    /// The positional argument is neither a run directory nor a scenario file.
    #[error("{}: not a run directory (expected the --out of `simulate` or `launch`)", path.display())]
    NotARun { path: PathBuf },
    /// A map export of a scenario with no place on the Earth.
    #[error("export {export}: {} has no [origin] table: a map needs the latitude, longitude, altitude and heading of the scenario's (0, 0, 0)", file.display())]
    NoOrigin { export: &'static str, file: PathBuf },
    /// A run directory's audit.json or telemetry cannot be read (the error names the file).
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The bag could not be created at `--out`.
    #[error(transparent)]
    BagCreate(BagError),
    /// The run's commands.json cannot be read.
    #[error(transparent)]
    Commands(#[from] cdm_records::commands::RunCommandsError),
    /// The run's commands.json is not a command file of its scenario.
    #[error(transparent)]
    CommandFile(#[from] cdm_scenario::CommandsError),
    /// The bag could not be written once created.
    #[error(transparent)]
    Bag(BagError),
}

impl ExportError {
    /// Whether the caller's input is at fault (exit 2) rather than the machine (exit 3).
    pub fn is_bad_input(&self) -> bool {
        !matches!(
            self,
            ExportError::Zip { .. } | ExportError::Json { .. } | ExportError::Bag(_)
        )
    }
}
