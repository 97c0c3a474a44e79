//! `leader`: one quadcopter of a team as its own process, a primary or secondary leader: tracks r_HT = Q r_0 + d from its plan (eqs. 5, 13-15).
//!
//! It joins a team created by `orchestrator launch` (or `orchestrator launch --no-spawn`),
//! subscribes only to its in-neighbours' state services, and publishes its own state every tick.

use std::path::PathBuf;

use clap::Parser;
use common::member::Kind;
use common::member_cli::{main_for, MemberArgs};

/// One quadcopter of a continuum-deformation team, as a process.
#[derive(Debug, Parser)]
#[command(name = "leader", version, about)]
struct Args {
    /// The team's scenario file (the run directory's scenario.toml, or the same file the
    /// orchestrator was given).
    #[arg(long, value_name = "FILE")]
    scenario: PathBuf,
    /// The team to join (the orchestrator's --team).
    #[arg(long)]
    team: String,
    /// This quadcopter's id in the scenario.
    #[arg(long)]
    id: u32,
    /// Seconds to wait for the team to start.
    #[arg(long, default_value_t = 300.0)]
    join_timeout: f64,
    /// Seconds without progress mid-run before stopping.
    #[arg(long, default_value_t = 10.0)]
    silence_timeout: f64,
}

fn main() {
    let args = match Args::try_parse() {
        Ok(a) => a,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            std::process::exit(code);
        }
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
    std::process::exit(main_for(
        Kind::Leader,
        MemberArgs {
            scenario: args.scenario,
            team: args.team,
            id: args.id,
            join_timeout_s: args.join_timeout,
            silence_timeout_s: args.silence_timeout,
        },
    ));
}
