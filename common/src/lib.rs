//! The facade every binary uses: the old module paths (`common::plan`, `common::transport`, ...)
//! re-exported from the crates under `common/`, plus the member process's loop and CLI, which
//! join the runtime to the iceoryx2 backend.
//!
//! Crates, bottom to top: `cdm-math` (the only one that names nalgebra) -> `cdm-core` (math
//! through the engine and the audit; no I/O crates) -> `cdm-runtime` (wire messages, signals,
//! fault injection; no iceoryx2) -> `cdm-iox` (the only library crate that names iceoryx2).

pub use cdm_core::{
    audit, control, delay, dynamics, engine, export, files, formation, frame, gains, geometry,
    graph, linear_certificate, link, loss, loss_log, losscert, math, outcome, plan, record, repair,
    rundir, safety, scenario, simulate, step, telemetry,
};
pub use cdm_iox as transport;
pub use cdm_runtime::{
    fault_inject, member_core, member_loop, member_loss, messages, realtime, realtime_loop,
    realtime_monitor, sched, seams, signals, team_core, team_fault, team_loss, team_realtime,
};

pub mod member;
pub mod member_cli;
mod member_vehicle;
pub mod options;
pub mod vehicle_origins;
pub mod vehicles;
