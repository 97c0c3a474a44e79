//! run.json: what a run's other files do not say of how it was flown, so that the run
//! directory alone is enough to fly it again (`orchestrator replay`). scenario.toml already has
//! the scenario as flown (its `[link]`, its travel time, its gains), commands.json the commands
//! and audit.json every loss as applied; run.json adds the options that shape telemetry and the
//! end of the run (`--every`, `--max-ticks`, `--stop-on-violation`, `--on-loss`,
//! `--telemetry`), the scripted losses as given, and the scenario's content hash, which ties the
//! directory's files to one another.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::rundir::{write_atomic, RunDirError};
use crate::telemetry::TelemetryFormat;

/// The file's name in a run directory.
pub const RUN_RECORD_FILE: &str = "run.json";

/// The `format` field of the version this code writes and reads.
pub const RUN_RECORD_FORMAT: &str = "cdm-run/1";

/// What flew the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RunMode {
    /// `orchestrator simulate`: the in-process engine.
    Simulate,
    /// `orchestrator launch` in lockstep: the processes under the shared clock.
    Lockstep,
    /// `orchestrator launch --realtime`: the processes on the wall clock.
    Realtime,
    /// `orchestrator replay`: a run flown again from its directory.
    Replay,
    /// `orchestrator replay` of a real-time run: flown again from the run's recordings, which
    /// stay in the run's directory (replay that one again).
    RealtimeReplay,
}

/// run.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunRecord {
    /// [`RUN_RECORD_FORMAT`].
    pub format: String,
    pub mode: RunMode,
    /// `Scenario::content_hash` of scenario.toml, in hex.
    pub scenario_hash: String,
    /// Every K-th tick is in telemetry.
    pub every: u64,
    /// `--max-ticks`.
    pub max_ticks: Option<u64>,
    pub stop_on_violation: bool,
    /// `--on-loss stop`: a lost member ends the run as a fault.
    pub stop_on_loss: bool,
    /// `csv`, `parquet` or `mcap` (`--telemetry`).
    pub telemetry: String,
    /// The scripted losses (`--lose`) as ticks: (the tick from which the repair applies, the
    /// ids lost after publishing the tick before). audit.json lists the losses as applied.
    pub losses: Vec<(u64, Vec<u32>)>,
}

/// run.json that cannot be used, naming the file and the field.
#[derive(Debug, thiserror::Error)]
pub enum RunRecordError {
    /// The file cannot be read.
    #[error("{path}: {reason}")]
    Read { path: String, reason: String },
    /// Not a run record of this version (malformed JSON, an unknown or missing field, another
    /// format).
    #[error("{path}: {reason} (a tampered or foreign file)")]
    Invalid { path: String, reason: String },
}

impl RunRecord {
    /// The telemetry format by its command-line name.
    pub fn telemetry_format(&self) -> Option<TelemetryFormat> {
        match self.telemetry.as_str() {
            "csv" => Some(TelemetryFormat::Csv),
            "parquet" => Some(TelemetryFormat::Parquet),
            "mcap" => Some(TelemetryFormat::Mcap),
            _ => None,
        }
    }

    /// The command-line name of a telemetry format.
    pub fn telemetry_name(format: TelemetryFormat) -> &'static str {
        match format {
            TelemetryFormat::Csv => "csv",
            TelemetryFormat::Parquet => "parquet",
            TelemetryFormat::Mcap => "mcap",
        }
    }

    /// The content hash as run.json writes it.
    pub fn hash_text(hash: u64) -> String {
        format!("{hash:016x}")
    }

    /// Write `dir/run.json`.
    pub fn write(&self, dir: &Path) -> Result<(), RunDirError> {
        let mut text = serde_json::to_string_pretty(self).unwrap_or_default();
        text.push('\n');
        write_atomic(&dir.join(RUN_RECORD_FILE), text.as_bytes())
    }

    /// Read `dir/run.json`, checking its format and telemetry name.
    pub fn read(dir: &Path) -> Result<Self, RunRecordError> {
        let p = dir.join(RUN_RECORD_FILE);
        let path = p.display().to_string();
        let text = cdm_files::read_input(&p, 1 << 20).map_err(|e| RunRecordError::Read {
            path: path.clone(),
            reason: e.reason(),
        })?;
        let invalid = |reason: String| RunRecordError::Invalid {
            path: path.clone(),
            reason,
        };
        let r: RunRecord = serde_json::from_str(&text).map_err(|e| invalid(e.to_string()))?;
        if r.format != RUN_RECORD_FORMAT {
            return Err(invalid(format!(
                "format {:?}, expected {RUN_RECORD_FORMAT:?}",
                r.format
            )));
        }
        if r.telemetry_format().is_none() {
            return Err(invalid(format!(
                "telemetry {:?}: expected csv, parquet or mcap",
                r.telemetry
            )));
        }
        if r.every == 0 {
            return Err(invalid(
                "every 0: expected a positive number of ticks".into(),
            ));
        }
        Ok(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record() -> RunRecord {
        RunRecord {
            format: RUN_RECORD_FORMAT.into(),
            mode: RunMode::Simulate,
            scenario_hash: RunRecord::hash_text(0x0123_4567_89ab_cdef),
            every: 3,
            max_ticks: Some(900),
            stop_on_violation: false,
            stop_on_loss: false,
            telemetry: "csv".into(),
            losses: vec![(301, vec![7, 9])],
        }
    }

    #[test]
    fn a_record_reads_back_as_written_and_a_bad_one_is_named() {
        let dir = std::env::temp_dir().join(format!("cdm-run-record-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        record().write(&dir).unwrap();
        assert_eq!(RunRecord::read(&dir).unwrap(), record());
        let p = dir.join(RUN_RECORD_FILE);
        let text = std::fs::read_to_string(&p).unwrap();
        std::fs::write(&p, text.replace("\"csv\"", "\"tsv\"")).unwrap();
        let e = RunRecord::read(&dir).unwrap_err().to_string();
        assert!(
            e.contains("run.json") && e.contains("telemetry \"tsv\""),
            "{e}"
        );
        std::fs::write(&p, text.replace("\"every\"", "\"evry\"")).unwrap();
        let e = RunRecord::read(&dir).unwrap_err().to_string();
        assert!(e.contains("run.json") && e.contains("evry"), "{e}");
        std::fs::remove_file(&p).unwrap();
        let e = RunRecord::read(&dir).unwrap_err().to_string();
        assert!(e.contains("run.json"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
