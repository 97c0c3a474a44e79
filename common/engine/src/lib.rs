//! The deterministic in-process engine: the whole team in one process, stepping the same pure
//! `step` the member processes call, and members lost in flight (scripted losses, the repair).
//!
//! Layer 5 of the shared crates (see `cdm-model`'s docs): above `cdm-model`, `cdm-scenario`
//! and `cdm-records` (a loss is written to the audit); below the certificates and
//! `cdm-simulate`.

pub mod engine;
pub mod loss;
