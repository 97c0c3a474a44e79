//! Continuum deformation of quadcopter teams over moving frames, with no I/O beyond reading a
//! scenario and writing a run directory: the paper's math, scenario files, the deterministic
//! whole-team engine, the audit and the telemetry. No iceoryx2, clap or tracing-subscriber: a
//! library on its own.
//!
//! Layers, bottom to top: `math` (the cdm-math crate) -> `frame`, `plan`, `formation`, `graph`,
//! `gains`, `safety`, `dynamics`, `control` (pure) -> `step` (one member's tick), `link` (imperfect
//! links) -> `scenario` (files, validation, built-ins) -> `engine`, `telemetry`, `audit`,
//! `simulate`, `delay` (the certificate against link delay), `rundir`; `export` (pure: the plan's
//! exact pieces for Crazyswarm2 and Skybrush).

/// The numeric facade, re-exported so `crate::math::Vec3` reads as before the split.
pub use cdm_math as math;

pub mod airspace;
pub mod airspace_audit;
pub mod airspace_certificate;
pub mod airspace_suggest;
pub mod audit;
pub mod control;
pub mod delay;
pub mod dynamics;
pub mod engine;
pub mod export;
pub mod files;
pub mod formation;
pub mod frame;
pub mod gains;
pub mod geometry;
pub mod graph;
pub mod guard;
pub mod linear_certificate;
pub mod link;
pub mod loss;
pub mod loss_log;
pub mod losscert;
pub mod margins;
pub mod mission_certificate;
pub mod outcome;
pub mod plan;
pub mod record;
pub mod repair;
pub mod rundir;
pub mod safety;
pub mod scenario;
pub mod simulate;
pub mod step;
pub mod telemetry;
