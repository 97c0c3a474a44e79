//! Continuum deformation of quadcopter teams as pure functions: no file system, no libc, no
//! transport, no clock. Everything above it (scenario files, run records, the engine,
//! certificates, the processes) calls into it.
//!
//! Layers of the shared crates, bottom to top (a crate only depends on crates below it):
//! 1. `cdm-math` (the numeric facade) and `cdm-files` (bounded reads, safe writes);
//! 2. `cdm-model` (this crate): `frame`, `plan`, `geometry`, `airspace`, `formation`, `graph`,
//!    `repair`, `gains`, `safety`, `dynamics`, `guard`, `limits`, `control` -> `step` (one member's
//!    tick), `link` (imperfect links), `outcome` (typed verdicts and causes);
//! 3. `cdm-scenario` (files, validation, built-ins);
//! 4. `cdm-trajectory` (the plan's exact pieces for fleets) and `cdm-records` (run directory,
//!    telemetry, audit, tick recorder, loss log, margins);
//! 5. `cdm-engine` (the whole team in one process, losses in flight);
//! 6. `cdm-certificates` (linear, delay, mission, airspace, suggestions, losses);
//! 7. `cdm-simulate` (a flight into a run directory, the pre-flight certificate).

pub mod airspace;
pub mod control;
pub mod dynamics;
pub mod formation;
pub mod frame;
pub mod gains;
pub mod geometry;
pub mod graph;
pub mod guard;
pub mod limits;
pub mod link;
pub mod outcome;
pub mod plan;
pub mod repair;
pub mod safety;
pub mod steer;
pub mod step;
pub mod stop;
