//! Continuum deformation of quadcopter teams over moving frames: the paper's math (pure, no I/O),
//! scenario files, the deterministic in-process engine, and the iceoryx2 transport.
//!
//! Layers, bottom to top: `math` -> `frame`, `plan`, `formation`, `graph`, `gains`, `safety`,
//! `dynamics`, `control` (pure) -> `step` (one agent's tick) -> `scenario` (files, validation,
//! built-ins) -> `engine`, `telemetry`, `audit` -> `messages` (repr(C) wire types) -> `transport`
//! (the only module that names iceoryx2).

pub mod audit;
pub mod control;
pub mod dynamics;
pub mod engine;
pub mod fault_inject;
pub mod formation;
pub mod frame;
pub mod gains;
pub mod geometry;
pub mod graph;
pub mod linear_certificate;
pub mod math;
pub mod member;
pub mod member_cli;
pub mod messages;
pub mod plan;
pub mod rundir;
pub mod safety;
pub mod scenario;
pub mod signals;
pub mod simulate;
pub mod step;
pub mod telemetry;
pub mod transport;
