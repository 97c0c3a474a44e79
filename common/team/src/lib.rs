//! Running one team's processes: spawning members and watching them (`team`), the losses a
//! launch scripts and repairs (`loss`), the telemetry sink, the notices a run hands its binary, and the failure
//! type every orchestrator command ends with (an error and its exit code).

/// `println!` that never panics: a closed or full stdout (`plan | head -1`, `launch >
/// /dev/full`) must not stop a command before its files are complete. What cannot be printed is
/// dropped; the run's outcome still decides the exit code.
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

pub mod errors;
mod failure;
pub mod loss;
pub mod member_priority;
pub mod notices;
pub mod team;
pub mod telemetry;
pub mod telemetry_thread;
pub mod template;

pub use failure::{BoxError, Exit, Failure};
