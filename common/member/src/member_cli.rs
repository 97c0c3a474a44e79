//! The command line shared by the `agent` and `leader` binaries.

use crate::member::{run_member, Deadlines, Flight, Kind, Mode};
use crate::options::{timeout, LinkArgs};
use cdm_iox::TeamName;
use std::path::PathBuf;

/// A member's default `--silence-timeout`, seconds (the orchestrator passes a longer one only
/// when its own `--agent-timeout` asks for more patience).
pub const DEFAULT_SILENCE_TIMEOUT_S: f64 = 10.0;

/// Arguments of a member process (`agent` or `leader`).
#[derive(Debug, Clone, clap::Parser)]
#[command(
    version,
    about = "One quadcopter of a continuum-deformation team, as a process"
)]
pub struct MemberArgs {
    /// The team's scenario file (the run directory's scenario.toml, or the same file the
    /// orchestrator was given).
    #[arg(long, value_name = "FILE")]
    pub scenario: PathBuf,
    /// The team to join (the orchestrator's --team).
    #[arg(long)]
    pub team: String,
    /// This quadcopter's id in the scenario.
    #[arg(long)]
    pub id: u32,
    /// Seconds to wait for the team to start (at most 86400).
    #[arg(
        long = "join-timeout",
        allow_negative_numbers = true,
        default_value_t = 300.0
    )]
    pub join_timeout_s: f64,
    /// Seconds without progress mid-run before stopping (at most 86400).
    #[arg(
        long = "silence-timeout",
        allow_negative_numbers = true,
        default_value_t = DEFAULT_SILENCE_TIMEOUT_S
    )]
    pub silence_timeout_s: f64,
    #[command(flatten)]
    pub link: LinkArgs,
    /// Fly in real time on this process's own clock, from the start instant the orchestrator
    /// announces (its `launch --realtime`), with no grant and no barrier.
    #[arg(long)]
    pub realtime: bool,
    /// With --realtime: seconds after which an in-neighbour's newest state is too old (a fault:
    /// reported, and this member holds position).
    #[arg(
        long = "stale-after",
        allow_negative_numbers = true,
        default_value_t = 0.5,
        value_name = "SECONDS"
    )]
    pub stale_after_s: f64,
    /// With --realtime: run this member under SCHED_FIFO at this priority (1-99), so its
    /// wake-ups preempt ordinary processes (needs root, CAP_SYS_NICE or `ulimit -r`).
    #[arg(long = "rt-priority", value_name = "P", value_parser = clap::value_parser!(u8).range(cdm_process::sched::RT_PRIORITIES))]
    pub rt_priority: Option<u8>,
    /// What this member flies (the model, or a MAVLink vehicle: needs --realtime).
    #[command(flatten)]
    pub vehicle: crate::vehicles::VehicleArgs,
    /// With --realtime: write this member's recording (the neighbour states each tick flew on,
    /// for `orchestrator replay`) as DIR/<id>.mcap.
    #[arg(long, value_name = "DIR")]
    pub record: Option<std::path::PathBuf>,
}

/// The whole `main` of a member binary: parse arguments, initialise logging (`RUST_LOG`,
/// default `warn`), run, exit with the member's exit code.
pub fn main(kind: Kind, name: &'static str) -> ! {
    use clap::{CommandFactory, FromArgMatches};
    let parsed = MemberArgs::command()
        .name(name)
        .bin_name(name)
        .about(match kind {
            Kind::Leader => {
                "One primary or secondary leader of a continuum-deformation team, as a process \
                 (followers fly with `agent`). Exit 0 when the team finished its plan, 2 bad \
                 input, 3 the team was stopped or failed."
            }
            Kind::Agent => {
                "One follower of a continuum-deformation team, as a process (leaders fly with \
                 `leader`). Exit 0 when the team finished its plan, 2 bad input, 3 the team \
                 was stopped or failed."
            }
        })
        .try_get_matches()
        .and_then(|m| MemberArgs::from_arg_matches(&m));
    let args = match parsed {
        Ok(a) => a,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            std::process::exit(code);
        }
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    // Plain text when stderr is a file or a pipe, as the orchestrator does.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
    std::process::exit(main_for(kind, args))
}

/// Run a member process and return its exit code: 0 finished, 2 bad input, 3 runtime fault.
pub fn main_for(kind: Kind, args: MemberArgs) -> i32 {
    let interrupted = cdm_process::signals::install();
    let team = match TeamName::new(&args.team) {
        Ok(t) => t,
        Err(e) => {
            say(&format!("error: --team: {e}"));
            return 2;
        }
    };
    let deadlines = match (
        timeout("--join-timeout", args.join_timeout_s),
        timeout("--silence-timeout", args.silence_timeout_s),
    ) {
        (Ok(join), Ok(silence)) => Deadlines { join, silence },
        (Err(e), _) | (_, Err(e)) => {
            say(&format!("error: {e}"));
            return 2;
        }
    };
    let vehicles = match args.vehicle.validate(args.realtime) {
        Ok(v) => v,
        Err(e) => {
            say(&format!("error: {e}"));
            return 2;
        }
    };
    let mode = match (args.realtime, timeout("--stale-after", args.stale_after_s)) {
        (false, _) => Mode::Lockstep,
        (true, Ok(stale_after)) => Mode::Realtime { stale_after },
        (true, Err(e)) => {
            say(&format!("error: {e}"));
            return 2;
        }
    };
    if let Err(e) = realtime_priority(args.realtime, args.rt_priority) {
        say(&format!("error: member {}: {e}", args.id));
        return 2;
    }
    let span = tracing::info_span!("member", id = args.id);
    let _g = span.enter();
    if args.record.is_some() && !args.realtime {
        say("error: --record needs --realtime (a lockstep flight is replayed without one)");
        return 2;
    }
    let flight = Flight {
        deadlines,
        mode,
        vehicles,
        record: args.record,
    };
    let run = run_member(
        kind,
        &args.scenario,
        &team,
        (args.id, &args.link),
        &flight,
        interrupted,
    );
    match run {
        Ok(f) => stopped(&team, args.id, f),
        Err(e) => {
            say(&format!("error: {e}"));
            e.exit_code()
        }
    }
}

/// `--rt-priority`: only with `--realtime` (lockstep is paced by grants, not by wake-ups on
/// time), applied before the member opens anything so its threads inherit it.
fn realtime_priority(realtime: bool, priority: Option<u8>) -> Result<(), String> {
    match (realtime, priority) {
        (_, None) => Ok(()),
        (false, Some(_)) => Err("--rt-priority needs --realtime".into()),
        (true, Some(p)) => cdm_process::sched::fifo(p).map_err(|e| format!("{e}: {}", e.source)),
    }
}

/// The exit code of a member the orchestrator stopped: 0 only when the team finished its plan.
/// A team stopped for a fault, a silence (members that never joined) or an interruption did not
/// fly, so its members exit 3 and say why, like the orchestrator.
fn stopped(team: &TeamName, id: u32, f: crate::member::Finished) -> i32 {
    use cdm_runtime::messages::StopReason;
    tracing::debug!(
        tick = f.tick,
        reason = f.reason,
        "stopped by the orchestrator"
    );
    let why = match StopReason::from_code(f.reason) {
        StopReason::Finished => return 0,
        StopReason::AgentFault => "an agent failed".to_string(),
        StopReason::AgentSilent => "agents went silent or never joined".to_string(),
        StopReason::Interrupted => "the orchestrator was interrupted".to_string(),
        StopReason::Unknown(c) => format!("reason code {c}"),
    };
    say(&format!(
        "error: agent {id}: team {team} was stopped by its orchestrator at tick {} before the end of the plan: {why} (the orchestrator's audit.json has the details)",
        f.tick
    ));
    3
}

/// Writes one line to stderr with a single write(2): the members of a team share the
/// orchestrator's stderr, and `eprintln!` writes piece by piece, so lines of processes stopping
/// together would interleave mid-line.
fn say(line: &str) {
    use std::io::Write;
    let _ = std::io::stderr().write_all(format!("{line}\n").as_bytes());
}
