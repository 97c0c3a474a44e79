//! Running one team's processes: spawning members and watching them (`team`), the losses a
//! launch scripts and repairs (`loss`), the telemetry sink, and the notices a run hands its
//! binary.

pub mod loss;
pub mod member_priority;
pub mod notices;
pub mod team;
pub mod telemetry;
pub mod telemetry_thread;
pub mod template;
