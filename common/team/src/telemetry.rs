//! The run's telemetry file in the format `--telemetry` names: telemetry.csv (common) or
//! telemetry.parquet (crate cdm-parquet, behind the default `parquet` feature).

use cdm_core::rundir::{RunDir, RunDirError};
use cdm_core::telemetry::{TelemetryFormat, TelemetrySink};

use crate::Failure;

/// Refuse a format this build cannot write, before anything is created.
pub fn check_available(format: TelemetryFormat) -> Result<(), Failure> {
    if format == TelemetryFormat::Parquet && !cfg!(feature = "parquet") {
        return Err(Failure::bad_input(
            "--telemetry parquet: this orchestrator was built without its `parquet` feature \
             (build with default features)",
        ));
    }
    Ok(())
}

/// Open the run's telemetry file for streaming, keeping every `every`-th tick.
pub fn open(
    dir: &RunDir,
    format: TelemetryFormat,
    every: u64,
) -> Result<Box<dyn TelemetrySink>, RunDirError> {
    // A reused (--force) directory may hold the other format's file from an earlier run: it is
    // one of the tool's files, and `report` must not read it for this run.
    for other in [TelemetryFormat::Csv, TelemetryFormat::Parquet] {
        let p = dir.path().join(other.file_name());
        if other != format && p.exists() {
            std::fs::remove_file(&p).map_err(|source| RunDirError::Io { path: p, source })?;
        }
    }
    match format {
        TelemetryFormat::Csv => Ok(Box::new(dir.telemetry(every)?)),
        TelemetryFormat::Parquet => open_parquet(dir, every),
    }
}

#[cfg(feature = "parquet")]
fn open_parquet(dir: &RunDir, every: u64) -> Result<Box<dyn TelemetrySink>, RunDirError> {
    let path = dir.path().join(TelemetryFormat::Parquet.file_name());
    cdm_parquet::ParquetTelemetryWriter::create(&path, every)
        .map(|w| Box::new(w) as Box<dyn TelemetrySink>)
        .map_err(|e| RunDirError::Io {
            path,
            source: std::io::Error::other(e),
        })
}

#[cfg(not(feature = "parquet"))]
fn open_parquet(dir: &RunDir, _every: u64) -> Result<Box<dyn TelemetrySink>, RunDirError> {
    Err(RunDirError::Io {
        path: dir.path().join(TelemetryFormat::Parquet.file_name()),
        source: std::io::Error::other("built without the `parquet` feature"),
    })
}
