//! The command line shared by the `agent` and `leader` binaries.

use crate::member::{run_member, Deadlines, Flight, Kind, Loaded, Mode};
use crate::options::{timeout, LinkArgs};
use crate::template::{ForkReply, ForkRequest};
use cdm_iox::TeamName;
use std::ffi::OsString;
use std::io::{BufRead, Write};
use std::os::unix::ffi::OsStringExt;
use std::path::Path;
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
/// default `warn`), run, exit with the member's exit code. Started as `NAME --template FILE
/// ROOM` by a launch, it is instead the team's member template ([`serve_template`]).
pub fn main(kind: Kind, name: &'static str) -> ! {
    let mut raw = std::env::args_os().skip(1);
    if raw.next().is_some_and(|a| a == crate::template::FLAG) {
        init_tracing();
        let file = PathBuf::from(raw.next().unwrap_or_default());
        std::process::exit(serve_template(&file));
    }
    let args = match parse(kind, name, std::env::args_os()) {
        Ok(a) => a,
        Err(e) => std::process::exit(print_parse_error(&e)),
    };
    init_tracing();
    std::process::exit(main_for(kind, args))
}

/// A member's arguments (`args` starts with the program's name), as its binary reads them.
fn parse<I, T>(kind: Kind, name: &'static str, args: I) -> Result<MemberArgs, clap::Error>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    use clap::{CommandFactory, FromArgMatches};
    MemberArgs::command()
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

/// Serves fork requests on stdin until it ends; returns the exit code (0, or 2 when the
/// scenario cannot be loaded, 3 when the pipes fail).
pub fn serve_template(scenario: &Path) -> i32 {
    let loaded = match Loaded::load(scenario) {
        Ok(l) => l,
        Err(e) => {
            say(&format!("error: member template: {e}"));
            return e.exit_code();
        }
    };
    let mut input = std::io::stdin().lock();
    let mut frame = Vec::new();
    loop {
        frame.clear();
        match input.read_until(0, &mut frame) {
            Ok(0) => return 0,
            Ok(_) => {}
            Err(e) => {
                say(&format!("error: member template: reading a request: {e}"));
                return 3;
            }
        }
        let reply = match postcard::from_bytes_cobs::<ForkRequest>(&mut frame) {
            Ok(r) => fork_one(r, &loaded),
            Err(e) => ForkReply::Failed {
                errno: None,
                why: format!("a malformed request: {e}"),
            },
        };
        let sent = postcard::to_stdvec_cobs(&reply)
            .map_err(|e| e.to_string())
            .and_then(|b| {
                let mut out = std::io::stdout().lock();
                out.write_all(&b)
                    .and_then(|()| out.flush())
                    .map_err(|e| e.to_string())
            });
        if let Err(e) = sent {
            say(&format!("error: member template: answering a request: {e}"));
            return 3;
        }
    }
}

fn fork_one(r: ForkRequest, loaded: &Loaded) -> ForkReply {
    match cdm_process::fork::fork_detached(|| member(r, loaded)) {
        Ok(pid) => ForkReply::Forked(pid),
        Err(e) => ForkReply::Failed {
            errno: e.raw_os_error(),
            why: e.to_string(),
        },
    }
}

/// The forked member: standard input and output on /dev/null (as a spawned member's), its
/// command line and name as if started from its binary, then the binary's own `main`.
fn member(r: ForkRequest, loaded: &Loaded) -> i32 {
    null_stdio();
    let kind = if r.leader { Kind::Leader } else { Kind::Agent };
    let name = match kind {
        Kind::Leader => "leader",
        Kind::Agent => "agent",
    };
    let args: Vec<OsString> = std::iter::once(OsString::from(name))
        .chain(r.args.into_iter().map(OsString::from_vec))
        .collect();
    // Best effort: only `ps` and tools that find a member by its arguments see them.
    let _ = cdm_process::fork::set_cmdline(&args);
    cdm_process::fork::set_name(name);
    match parse(kind, name, args) {
        Ok(a) => main_with(kind, a, Some(loaded)),
        Err(e) => print_parse_error(&e),
    }
}

/// Points file descriptors 0 and 1 at /dev/null (the template's are its pipes).
fn null_stdio() {
    // SAFETY: open/dup2/close on descriptors of our own; the path is NUL-terminated.
    unsafe {
        let fd = libc::open(c"/dev/null".as_ptr(), libc::O_RDWR);
        if fd >= 0 {
            libc::dup2(fd, 0);
            libc::dup2(fd, 1);
            if fd > 1 {
                libc::close(fd);
            }
        }
    }
}

/// Run a member process and return its exit code: 0 finished, 2 bad input, 3 runtime fault.
pub fn main_for(kind: Kind, args: MemberArgs) -> i32 {
    main_with(kind, args, None)
}

/// [`main_for`] with the scenario already loaded (by the member template): used when
/// `--scenario` names the file it was loaded from.
fn main_with(kind: Kind, args: MemberArgs, loaded: Option<&Loaded>) -> i32 {
    let interrupted = cdm_process::signals::install();
    let team = match TeamName::new(&args.team) {
        Ok(t) => t,
        Err(e) => {
            say(&format!("error: --team: {e}"));
            return 2;
        }
    };
    let (deadlines, vehicles, mode) = match checked(&args) {
        Ok(c) => c,
        Err(e) => {
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
    let own;
    let loaded = match loaded.filter(|l| l.path == args.scenario) {
        Some(l) => l,
        None => match Loaded::load(&args.scenario) {
            Ok(l) => {
                own = l;
                &own
            }
            Err(e) => {
                say(&format!("error: {e}"));
                return e.exit_code();
            }
        },
    };
    let run = run_member(
        kind,
        loaded,
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

/// The deadlines, vehicles and mode the arguments ask for, each checked (the error names the
/// option).
fn checked(args: &MemberArgs) -> Result<(Deadlines, crate::vehicles::Vehicles, Mode), String> {
    let deadlines = Deadlines {
        join: timeout("--join-timeout", args.join_timeout_s)?,
        silence: timeout("--silence-timeout", args.silence_timeout_s)?,
    };
    let vehicles = args.vehicle.validate(args.realtime)?;
    let mode = match args.realtime {
        false => Mode::Lockstep,
        true => Mode::Realtime {
            stale_after: timeout("--stale-after", args.stale_after_s)?,
        },
    };
    Ok((deadlines, vehicles, mode))
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
