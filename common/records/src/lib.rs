//! What a run leaves behind and how it is read back: the run directory (scenario.toml,
//! telemetry.csv, audit.json, written through `cdm-files`), the telemetry writers, the safety
//! audit fed tick by tick (and the airspace's and the vehicles' limits'), the recorder every flown tick goes through, the
//! loss log and the margins a tick's positions give.
//!
//! Layer 4 of the shared crates (see `cdm-model`'s docs): above `cdm-model`, `cdm-scenario` and
//! `cdm-files`; below the engine, the certificates and `cdm-simulate`.

pub mod airspace_audit;
pub mod audit;
pub mod commands;
pub mod limit_audit;
pub mod loss_log;
pub mod margins;
pub mod record;
pub mod run_record;
pub mod rundir;
pub mod telemetry;
