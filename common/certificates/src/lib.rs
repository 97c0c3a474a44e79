//! Pre-flight certificates of a scenario: E_max(T) on the exactly linear error dynamics, the
//! largest link delay that keeps the guarantee, a mission phase by phase, the airspace (and
//! what would clear its breaches), the vehicles' limits and downwash, and every single member
//! loss.
//!
//! Layer 6 of the shared crates (see `cdm-model`'s docs): above the engine (the flying parts
//! of a certificate) and `cdm-records` (the audit's safety numbers); below `cdm-simulate`.

pub mod airspace_certificate;
pub mod airspace_suggest;
pub mod certificate;
pub mod certify;
pub mod command_certificate;
pub mod commanded_flight;
pub mod delay;
pub mod linear_certificate;
pub mod losscert;
pub mod mission_certificate;
pub mod vehicle_certificate;
