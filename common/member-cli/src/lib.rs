//! The command line of the member binaries, `agent` and `leader`: their arguments, checked into
//! cdm-member's `MemberConfig`; logging; the error line and the exit code. One definition for
//! both binaries (each `main` is one call to [`main`]), and the vehicle and link flags
//! (`VehicleArgs`, `LinkArgs`) that `orchestrator launch` flattens into its own and forwards to
//! the members it spawns, so a flag means the same on both sides.
//!
//! A binary-side crate: the libraries under `common/` neither parse arguments nor print.

pub mod link_args;
pub mod member_args;
mod template;
pub mod timeout;
pub mod vehicle_args;

pub use link_args::LinkArgs;
pub use member_args::MemberArgs;
pub use timeout::{timeout, TimeoutError, MAX_TIMEOUT_S};
pub use vehicle_args::{VehicleArgs, VehicleArgsError, VehicleKind};

use cdm_iox::TeamName;
use cdm_member::member::{Binary, Finished, Loaded};

/// The whole `main` of a member binary: parse arguments, initialise logging (`RUST_LOG`,
/// default `warn`), run, exit with the member's exit code. Started as `NAME --template FILE
/// ROOM` by a launch, it is instead the team's member template ([`template::serve`]).
pub fn main(binary: Binary) -> ! {
    let mut raw = std::env::args_os().skip(1);
    if raw.next().is_some_and(|a| a == cdm_member::template::FLAG) {
        init_tracing();
        let file = std::path::PathBuf::from(raw.next().unwrap_or_default());
        std::process::exit(template::serve(&file));
    }
    let args = match parse(binary, std::env::args_os()) {
        Ok(a) => a,
        Err(e) => std::process::exit(print_parse_error(&e)),
    };
    init_tracing();
    std::process::exit(main_for(binary, args))
}

/// A member's arguments (`args` starts with the program's name), as its binary reads them.
fn parse<I, T>(binary: Binary, args: I) -> Result<MemberArgs, clap::Error>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    use clap::{CommandFactory, FromArgMatches};
    let name = binary.name();
    MemberArgs::command()
        .name(name)
        .bin_name(name)
        .about(match binary {
            Binary::Leader => {
                "One primary or secondary leader of a continuum-deformation team, as a process \
                 (followers fly with `agent`). Exit 0 when the team finished its plan, 2 bad \
                 input, 3 the team was stopped or failed."
            }
            Binary::Agent => {
                "One follower of a continuum-deformation team, as a process (leaders fly with \
                 `leader`). Exit 0 when the team finished its plan, 2 bad input, 3 the team \
                 was stopped or failed."
            }
        })
        .try_get_matches_from(args)
        .and_then(|m| MemberArgs::from_arg_matches(&m))
}

/// Prints a parse error (or `--help`, `--version`) as clap does; returns the exit code.
fn print_parse_error(e: &clap::Error) -> i32 {
    let _ = e.print();
    if e.use_stderr() {
        2
    } else {
        0
    }
}

/// Logging to stderr, `RUST_LOG` (default `warn`); plain text when stderr is a file or a pipe,
/// as the orchestrator does.
fn init_tracing() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}

/// Run a member process and return its exit code: 0 finished, 2 bad input, 3 runtime fault.
pub fn main_for(binary: Binary, args: MemberArgs) -> i32 {
    main_with(binary, args, None)
}

/// [`main_for`] with the scenario already loaded (by the member template): used when
/// `--scenario` names the file it was loaded from.
fn main_with(binary: Binary, args: MemberArgs, loaded: Option<&Loaded>) -> i32 {
    let interrupted = cdm_process::signals::install();
    let (id, priority) = (args.id, args.rt_priority);
    let config = match args.config(binary) {
        Ok(c) => c,
        Err(e) => {
            say(&format!("error: {e}"));
            return 2;
        }
    };
    if let Err(e) = member_args::realtime_priority(id, priority) {
        say(&format!("error: {e}"));
        return 2;
    }
    let span = tracing::info_span!("member", id);
    let _g = span.enter();
    match cdm_member::member::run_loaded(&config, loaded, interrupted) {
        Ok(f) => stopped(&config.team, id, f),
        Err(e) => {
            say(&format!("error: {e}"));
            e.exit_code()
        }
    }
}

/// The exit code of a member the orchestrator stopped: 0 only when the team finished its plan.
/// A team stopped for a fault, a silence (members that never joined) or an interruption did not
/// fly, so its members exit 3 and say why, like the orchestrator.
fn stopped(team: &TeamName, id: u32, f: Finished) -> i32 {
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
