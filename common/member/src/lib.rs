//! The member process and the composition root: the loop and CLI that `agent` and `leader` run,
//! joining the runtime (`cdm-runtime`) to the iceoryx2 backend (`cdm-iox`) and to the vehicle
//! (the model, or a MAVLink plant through `cdm-mavlink`).
//!
//! Crates, bottom to top: `cdm-math` (the only one that names nalgebra) -> `cdm-model`,
//! `cdm-scenario` (the paper's math, the scenario; no transport) -> `cdm-runtime` (wire messages, signals,
//! fault injection; no iceoryx2) -> `cdm-iox` (the only library crate that names iceoryx2).

pub mod member;
pub mod member_cli;
pub mod member_error;
mod member_vehicle;
pub mod options;
pub mod template;
pub mod vehicle_origins;
pub mod vehicles;
