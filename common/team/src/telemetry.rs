//! The run's telemetry file in the format `--telemetry` names: telemetry.csv (common),
//! telemetry.parquet (crate cdm-parquet, behind the default `parquet` feature), or telemetry.csv
//! with the run as a ROS 2 bag beside it, `rosbag2/` (crate cdm-rosbag, behind the default
//! `rosbag` feature).

use std::io;
use std::path::Path;

use cdm_records::rundir::{RunDir, RunDirError};
use cdm_records::telemetry::{TelemetryFormat, TelemetrySink};
use cdm_scenario::Scenario;

/// Rows a tick the default `--every` keeps at most: a team of N members writes every
/// ceil(N / 40)-th tick, so a default run's telemetry grows with its length, not its team
/// (about 2 million rows for the longest built-in plans; docs/src/benchmarks/telemetry.md).
pub const DEFAULT_ROWS_PER_TICK: u64 = 40;

/// `--every`, or its default for a team of `members`.
pub fn every_or_default(every: Option<u64>, members: usize) -> u64 {
    every.unwrap_or_else(|| (members as u64).div_ceil(DEFAULT_ROWS_PER_TICK).max(1))
}

/// A `--telemetry` format this build cannot write (the operator's input: exit 2).
#[derive(Debug, thiserror::Error)]
#[error(
    "--telemetry {option}: this orchestrator was built without its `{feature}` feature \
     (build with default features)"
)]
pub struct FormatNotBuilt {
    /// The value of `--telemetry`.
    option: &'static str,
    /// The cargo feature that writes it.
    feature: &'static str,
}

/// Refuse a format this build cannot write, before anything is created.
pub fn check_available(format: TelemetryFormat) -> Result<(), FormatNotBuilt> {
    let (option, feature, built) = match format {
        TelemetryFormat::Csv => return Ok(()),
        TelemetryFormat::Parquet => ("parquet", "parquet", cfg!(feature = "parquet")),
        TelemetryFormat::Mcap => ("mcap", "rosbag", cfg!(feature = "rosbag")),
    };
    if built {
        return Ok(());
    }
    Err(FormatNotBuilt { option, feature })
}

/// The bag's directory in a run directory (`--telemetry mcap`).
pub const BAG_DIR: &str = "rosbag2";

/// Open the run's telemetry file for streaming, keeping every `every`-th tick (`s`: the
/// scenario flown, whose team and limits the bag's messages show).
pub fn open(
    dir: &RunDir,
    format: TelemetryFormat,
    every: u64,
    s: &Scenario,
) -> Result<Box<dyn TelemetrySink + Send>, RunDirError> {
    // A reused (--force) directory may hold the other format's file from an earlier run: it is
    // one of the tool's files, and `report` must not read it for this run.
    for other in [TelemetryFormat::Csv, TelemetryFormat::Parquet] {
        let p = dir.path().join(other.file_name());
        if other.file_name() != format.file_name() && p.exists() {
            std::fs::remove_file(&p).map_err(|source| RunDirError::Io { path: p, source })?;
        }
    }
    if format != TelemetryFormat::Mcap {
        remove_bag(&dir.path().join(BAG_DIR))?;
    }
    match format {
        TelemetryFormat::Csv => Ok(Box::new(dir.telemetry(every)?)),
        TelemetryFormat::Parquet => open_parquet(dir, every),
        TelemetryFormat::Mcap => open_bag(dir, every, s),
    }
}

/// An earlier run's bag in a reused directory: its files, and the directory once empty.
fn remove_bag(bag: &Path) -> Result<(), RunDirError> {
    // The reserve is the room the bag keeps free while written (cdm-rosbag `room.rs`), left
    // behind by a run that was killed.
    let files = [
        bag.join("metadata.yaml"),
        bag.join(format!("{BAG_DIR}_0.mcap")),
        bag.join(format!(".{BAG_DIR}_0.mcap.reserve")),
    ];
    for p in files {
        if p.exists() {
            std::fs::remove_file(&p).map_err(|source| RunDirError::Io { path: p, source })?;
        }
    }
    let _ = std::fs::remove_dir(bag);
    Ok(())
}

/// Two sinks fed the same ticks: telemetry.csv and the bag.
#[cfg(feature = "rosbag")]
struct Both<A, B>(A, B);

#[cfg(feature = "rosbag")]
impl<A: TelemetrySink, B: TelemetrySink> TelemetrySink for Both<A, B> {
    fn keeps(&self, tick: u64) -> bool {
        self.0.keeps(tick)
    }

    /// The table's tick reaches its file before the bag is given it: the bag never holds a
    /// tick the table lost to a full disk, and a bag that meets a full disk ends on this tick,
    /// which the table has whole.
    fn write_tick(&mut self, rows: &[cdm_records::telemetry::Row]) -> io::Result<()> {
        self.0.write_tick(rows)?;
        if rows.first().is_some_and(|r| self.0.keeps(r.tick)) {
            self.0.flush()?;
        }
        self.1.write_tick(rows)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.0.flush()?;
        self.1.flush()
    }

    fn finish(&mut self) -> io::Result<()> {
        let table = self.0.finish();
        let bag = self.1.finish();
        table.and(bag)
    }
}

#[cfg(feature = "rosbag")]
fn open_bag(
    dir: &RunDir,
    every: u64,
    s: &Scenario,
) -> Result<Box<dyn TelemetrySink + Send>, RunDirError> {
    let table = dir.telemetry(every)?;
    let path = dir.path().join(BAG_DIR);
    // A commanded run's commands.json is written before its telemetry opens.
    let commands =
        cdm_records::commands::read_commands(dir.path()).map_err(|e| RunDirError::Io {
            path: dir.path().join(cdm_records::commands::COMMANDS_FILE),
            source: io::Error::other(e),
        })?;
    let bag = cdm_rosbag::BagSink::with_commands(&path, s, every, commands).map_err(|e| {
        RunDirError::Io {
            path,
            source: io::Error::other(e),
        }
    })?;
    Ok(Box::new(Both(table, bag)))
}

#[cfg(not(feature = "rosbag"))]
fn open_bag(
    dir: &RunDir,
    _every: u64,
    _s: &Scenario,
) -> Result<Box<dyn TelemetrySink + Send>, RunDirError> {
    Err(RunDirError::Io {
        path: dir.path().join(BAG_DIR),
        source: io::Error::other("built without the `rosbag` feature"),
    })
}

#[cfg(feature = "parquet")]
fn open_parquet(dir: &RunDir, every: u64) -> Result<Box<dyn TelemetrySink + Send>, RunDirError> {
    let path = dir.path().join(TelemetryFormat::Parquet.file_name());
    cdm_parquet::ParquetTelemetryWriter::create(&path, every)
        .map(|w| Box::new(w) as Box<dyn TelemetrySink + Send>)
        .map_err(|e| RunDirError::Io {
            path,
            source: std::io::Error::other(e),
        })
}

#[cfg(not(feature = "parquet"))]
fn open_parquet(dir: &RunDir, _every: u64) -> Result<Box<dyn TelemetrySink + Send>, RunDirError> {
    Err(RunDirError::Io {
        path: dir.path().join(TelemetryFormat::Parquet.file_name()),
        source: std::io::Error::other("built without the `parquet` feature"),
    })
}
