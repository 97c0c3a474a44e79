//! The member process and the composition root: the run that `agent` and `leader` call
//! (`member::run` with a checked `MemberConfig`), joining the runtime (`cdm-runtime`) to the
//! iceoryx2 backend (`cdm-iox`) and to the vehicle (the model, or a MAVLink plant through
//! `cdm-mavlink`). It neither parses arguments nor prints: the binaries' command line is
//! cdm-member-cli, which maps a `MemberError` to its line and exit code.
//!
//! Crates, bottom to top: `cdm-math` (the only one that names nalgebra) -> `cdm-model`,
//! `cdm-scenario` (the paper's math, the scenario; no transport) -> `cdm-runtime` (wire messages, signals,
//! fault injection; no iceoryx2) -> `cdm-iox` (the only library crate that names iceoryx2).

pub mod member;
pub mod member_error;
mod member_vehicle;
pub mod options;
pub mod vehicle_origins;
pub mod vehicles;
