//! The command line shared by the `agent` and `leader` binaries.

use std::path::PathBuf;
use std::time::Duration;

use crate::member::{run_member, Deadlines, Kind};
use crate::transport::TeamName;

/// Parsed arguments of a member process.
#[derive(Debug, Clone)]
pub struct MemberArgs {
    pub scenario: PathBuf,
    pub team: String,
    pub id: u32,
    pub join_timeout_s: f64,
    pub silence_timeout_s: f64,
}

/// Run a member process and return its exit code: 0 finished, 2 bad input, 3 runtime fault.
pub fn main_for(kind: Kind, args: MemberArgs) -> i32 {
    let interrupted = crate::signals::install();
    let team = match TeamName::new(&args.team) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: --team: {e}");
            return 2;
        }
    };
    let secs = |s: f64, what: &str| {
        if s.is_finite() && s > 0.0 {
            Ok(Duration::from_secs_f64(s))
        } else {
            Err(format!(
                "error: {what} must be a positive number of seconds, got {s}"
            ))
        }
    };
    let deadlines = match (
        secs(args.join_timeout_s, "--join-timeout"),
        secs(args.silence_timeout_s, "--silence-timeout"),
    ) {
        (Ok(join), Ok(silence)) => Deadlines { join, silence },
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("{e}");
            return 2;
        }
    };
    let span = tracing::info_span!("agent", id = args.id);
    let _g = span.enter();
    match run_member(kind, &args.scenario, &team, args.id, deadlines, interrupted) {
        Ok(f) => {
            tracing::debug!(
                tick = f.tick,
                reason = f.reason,
                "stopped by the orchestrator"
            );
            0
        }
        Err(e) => {
            eprintln!("error: {e}");
            e.exit_code()
        }
    }
}
