//! Command-line interface: the raw arguments as clap parses them; `commands.rs` turns them into
//! each command's options and loads and checks the scenario.

use std::path::PathBuf;

use crate::export_args::{ExportTarget, SourceArgs};
use cdm_engine::loss::{OnLoss, ScriptedLoss};
use cdm_records::telemetry::TelemetryFormat;
use clap::{Args, Parser, Subcommand};

/// Safe continuum deformation of quadcopter teams: plan, simulate and launch a team.
#[derive(Debug, Parser)]
#[command(name = "orchestrator", version, about)]
pub struct Cli {
    /// Print only the result (warnings and errors still go to stderr).
    #[arg(long, global = true)]
    pub quiet: bool,
    #[command(subcommand)]
    pub command: Command,
}

/// Where `--serve` listens when no address is given: loopback only.
pub const DEFAULT_SERVE: &str = "127.0.0.1:8080";

/// A `--serve` address: `HOST:PORT`, or a bare `PORT` on 127.0.0.1.
pub fn serve_addr(text: &str) -> Result<std::net::SocketAddr, String> {
    if let Ok(port) = text.parse::<u16>() {
        return Ok(std::net::SocketAddr::from(([127, 0, 0, 1], port)));
    }
    text.parse().map_err(|_| {
        format!("--serve {text}: expected HOST:PORT (e.g. 127.0.0.1:8080) or a port number")
    })
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Pre-flight certificate: lambda_1(U_D), D_B, D_S, delta, T_threshold. Exit 0 SAFE,
    /// 1 UNSAFE, 2 bad input, 3 a file cannot be written.
    Plan {
        #[command(flatten)]
        source: SourceArgs,
        /// Also write the certificate as JSON.
        #[arg(long, value_name = "FILE")]
        json: Option<PathBuf>,
        /// Fly the plan at travel times LO, LO+STEP, .., HI and draw E_max versus T_total
        /// (fig_deviation_sweep in --out; the paper's Fig. 10).
        #[arg(long, value_name = "LO:HI:STEP", requires = "out")]
        sweep: Option<String>,
        /// Fly the plan at link delays LO, LO+STEP, .., HI milliseconds (rounded to whole
        /// ticks) and draw E_max versus the delay (fig_delay_sweep in --out).
        #[arg(long, value_name = "LO:HI:STEP", requires = "out")]
        sweep_delay: Option<String>,
        /// Where the sweep's figure and data go.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// Also certify the loss of every single member: fly the plan with each one lost at the
        /// nominal peak deviation (graph repaired) and list the members the team cannot lose
        /// (exit 1 when there is one).
        #[arg(long)]
        losses: bool,
        /// With `[geofence]` or `[[obstacle]]`: also report the smallest altitude offset (up and
        /// down) that clears each breached boundary and the whole airspace, and why no uniform
        /// time scaling can. With `[vehicle]` limits: the shortest travel time of each phase
        /// whose commanded speeds and accelerations meet them.
        #[arg(long)]
        suggest: bool,
    },
    /// Fly the team with the deterministic in-process engine into a run directory. Exit 0 safe
    /// and complete, 1 violation, 2 bad input, 3 runtime fault (a control fault, a full disk).
    Simulate {
        #[command(flatten)]
        source: SourceArgs,
        #[command(flatten)]
        out: OutDir,
        #[command(flatten)]
        run: RunOptions,
        /// Steer the team in flight: a JSON list of {at_s, command (hold, resume, land, goto),
        /// goals (goto: the 3 primary leaders' [x, y, z], ascending id), travel_s}; each is
        /// certified at its switch tick and applied only when SAFE. The run directory gets
        /// commands.json (what became of each; readable as such a file again).
        #[arg(long, value_name = "FILE")]
        commands: Option<PathBuf>,
    },
    /// Fly the team as processes: one per quadcopter over iceoryx2 shared memory, a shared
    /// lockstep clock, a live safety audit. Exit 0 safe and complete, 1 violation, 2 bad input,
    /// 3 runtime fault.
    Launch(Box<LaunchArgs>),
    /// Steer a running team (`launch`, lockstep, one host): hold, resume, land, or goto
    /// X,Y,Z X,Y,Z X,Y,Z. The team certifies the new motion and flies it from a switch tick it
    /// announces to every member first. Exit 0 accepted (the switch tick and the certificate's
    /// summary), 1 refused UNSAFE (why), 2 bad input or a command that does not apply now,
    /// 3 no such team, no answer in time, or no tick left.
    #[command(name = "command")]
    Steer(Box<crate::steer_cmd::SteerArgs>),
    /// Fly a finished run (simulate, or launch in lockstep or real time) again from its
    /// directory alone: its scenario, options, commands and losses (and a real-time run's
    /// recordings). Its telemetry and audit.json's safety figures equal the run's byte for byte
    /// (checked: exit 3 when not). With --gains, --t-total, --scenario or --link-* the same
    /// history is flown with that change ("what if"). Exit 0 safe, 1 violation, 2 bad input (a
    /// tampered or foreign file: named, with its first bad record), 3 a real-time recording cut
    /// short.
    Replay(Box<ReplayArgs>),
    /// Replay a finished run in the browser: (re)writes RUN_DIR/replay.html, a self-contained
    /// page that works from file://; with --serve, also serves it until interrupted.
    View {
        /// The run directory.
        #[arg(value_name = "RUN_DIR")]
        dir: PathBuf,
        /// Serve the page on ADDR (HOST:PORT or PORT; a bare --serve is 127.0.0.1:8080).
        #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = DEFAULT_SERVE)]
        serve: Option<String>,
        /// Play the run to Foxglove instead, at its own pace, once a client connects (ADDR:
        /// HOST:PORT or PORT; a bare --foxglove is 127.0.0.1:8765).
        #[command(flatten)]
        foxglove: crate::launch_args::FoxgloveArgs,
    },
    /// Redraw every figure of a finished run from its telemetry.csv, audit.json and
    /// scenario.toml (SVG and PNG, into the run directory).
    Report {
        /// The run directory.
        #[arg(value_name = "RUN_DIR")]
        dir: PathBuf,
        /// The member of fig_agent_<id>, a follower or a leader (default: the follower deepest
        /// in the graph).
        #[arg(long, value_name = "ID")]
        follow: Option<u32>,
        /// Draw only fig_compare instead: this run against OTHER_DIR (a run and its `replay`
        /// with a change) side by side: deviation, separation and containment margin over time.
        #[arg(long, value_name = "OTHER_DIR", conflicts_with = "follow")]
        against: Option<PathBuf>,
    },
    /// Remove what teams of yours left behind when all their processes died (SIGKILL, a
    /// crash): their iceoryx2 files in /dev/shm, and the monitor files of dead iceoryx2 nodes
    /// that name no team. Running teams are never touched. `launch` does the same before it
    /// starts.
    Clean,
    /// Run this machine's share of a team whose orchestrator was started with `launch --hosts K
    /// --listen ENDPOINT`: join it over zenoh, spawn the members it assigns here, and
    /// bridge them to the other hosts. Exit 0 when the team stopped, 2 refused, 3 link lost.
    Host {
        /// The orchestrator's endpoint, in zenoh's form (tls/10.77.0.1:7447).
        #[arg(long, value_name = "ENDPOINT")]
        connect: String,
        /// This host's keys (DIR/host-K of `orchestrator keys new`): mutual TLS, and the host
        /// number is the certificate's.
        #[arg(long, value_name = "DIR")]
        keys: Option<PathBuf>,
        /// Allow a tcp/ endpoint: no authentication, no encryption (a network you trust).
        #[arg(long)]
        insecure: bool,
        /// Join only this team.
        #[arg(long)]
        team: Option<String>,
        /// Be this host of the team (1..K-1; default: the first free one).
        #[arg(long, value_name = "K")]
        host: Option<u32>,
        /// Join only a team flying this scenario (compared by content hash).
        #[arg(long, value_name = "FILE")]
        scenario: Option<PathBuf>,
        /// Seconds to wait for the orchestrator to answer (at most 86400).
        #[arg(long, default_value_t = 60.0, allow_negative_numbers = true)]
        join_timeout: f64,
    },
    /// A team's keys for mutual TLS across hosts: its certificate authority and a certificate
    /// for the orchestrator and for each host, every file readable by its owner only.
    Keys {
        #[command(subcommand)]
        action: KeysCommand,
    },
    /// Export the plan to the stacks that fly real fleets (Crazyswarm2, Skybrush), scaled into
    /// the target volume and certified again there: exit 0 SAFE, 1 UNSAFE (files written only
    /// with --force), 2 bad input or a plan the target cannot hold. Also a run as a ROS 2 bag,
    /// and the scenario on a map (GeoJSON, QGroundControl's .plan).
    Export {
        #[command(subcommand)]
        target: ExportTarget,
    },
    /// Work with scenario files.
    Scenario {
        #[command(subcommand)]
        command: ScenarioCommand,
    },
}

/// The options of `orchestrator launch` (see [`Command::Launch`]).
#[derive(Debug, Args)]
pub struct LaunchArgs {
    #[command(flatten)]
    pub source: SourceArgs,
    /// The run directory (default: runs/<team>).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Write every K-th tick to the telemetry file (default: every tick up to 40 members, then
    /// every ceil(N / 40)-th: about 40 rows a tick whatever the team's size; printed at the
    /// start).
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    pub every: Option<u64>,
    /// Reuse a non-empty --out directory.
    #[arg(long)]
    pub force: bool,
    /// The team's name: its services' prefix ([A-Za-z0-9_-], at most 48 characters;
    /// default cdm<pid of the orchestrator>).
    #[arg(long)]
    pub team: Option<String>,
    /// Do not start the processes: wait for them to be started by hand.
    #[arg(long)]
    pub no_spawn: bool,
    /// How many ticks a member may run ahead of the slowest (1 = strict lockstep). Larger
    /// windows mean fewer wake-ups per tick (BENCHMARKS.md) and more shared memory. Default:
    /// 1024 up to 250 members, 512 up to 500, 256 above, halved while the team would take more
    /// than half of the free /dev/shm.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub window: Option<u32>,
    /// Seconds without any member progress before the team is stopped as faulty (at most
    /// 86400).
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
    pub agent_timeout: f64,
    /// Seconds to wait for hand-started processes (--no-spawn) to join (at most 86400).
    #[arg(long, default_value_t = 300.0, allow_negative_numbers = true)]
    pub join_timeout: f64,
    /// Serve a live 3-D view of the team while it flies (ADDR: HOST:PORT or PORT; a bare
    /// --serve is 127.0.0.1:8080). Only loopback unless another address is given.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = DEFAULT_SERVE)]
    pub serve: Option<String>,
    /// What the members fly (`--vehicles mavlink`: real or SITL vehicles over MAVLink;
    /// README "Fly real vehicles").
    #[command(flatten)]
    pub vehicle: cdm_member_cli::VehicleArgs,
    #[command(flatten)]
    pub hosts: HostArgs,
    #[command(flatten)]
    pub realtime: crate::launch_args::RealtimeArgs,
    #[command(flatten)]
    pub ros2: crate::launch_args::Ros2Args,
    #[command(flatten)]
    pub foxglove: crate::launch_args::FoxgloveArgs,
    #[command(flatten)]
    pub run: RunOptions,
    /// Steer the team in flight from a file, as `simulate --commands` does (lockstep: the same
    /// run byte for byte); commands.json says what became of each.
    #[arg(long, value_name = "FILE")]
    pub commands: Option<PathBuf>,
    /// What SIGINT or SIGTERM to the orchestrator does: land the team now (certified as
    /// `orchestrator command TEAM land`, then the normal end; a second signal stops at once),
    /// or stop it at once. Default: land with --vehicles mavlink, stop without.
    #[arg(long, value_enum, value_name = "WHAT")]
    pub on_interrupt: Option<OnInterruptArg>,
}

/// The options of `orchestrator replay`.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The run directory to fly again (of `simulate`, a lockstep `launch` or a `replay`).
    #[arg(value_name = "RUN_DIR")]
    pub run: PathBuf,
    /// The replay's run directory (created; refused when it exists and is not empty, unless
    /// --force).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Reuse a non-empty --out directory.
    #[arg(long)]
    pub force: bool,
    /// What if: fly with these gains k1,k2,k3,k4 (eq. 18) instead of the scenario's.
    #[arg(long, value_name = "K1,K2,K3,K4", allow_hyphen_values = true)]
    pub gains: Option<String>,
    /// What if: fly with this travel time instead of the scenario's (the losses and commands
    /// keep their ticks and times).
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    pub t_total: Option<f64>,
    /// What if: fly this scenario file instead of the run's: the same team (the same ids,
    /// roles, graph and comm_hz) with another shape, gains, plan or airspace.
    #[arg(long, value_name = "FILE")]
    pub scenario: Option<PathBuf>,
    /// What if: other links (each flag overrides that key of the run's `[link]`; a real-time
    /// run takes only --link-delay-ms: each neighbour state flown on is as much older or newer).
    #[command(flatten)]
    pub link: cdm_member_cli::LinkArgs,
    /// Do not draw the figures at the end of the replay.
    #[arg(long)]
    pub no_figures: bool,
}

impl ReplayArgs {
    /// Whether anything is changed: then the replay is expected to differ from the run.
    pub fn what_if(&self) -> bool {
        let l = &self.link;
        self.gains.is_some()
            || self.t_total.is_some()
            || self.scenario.is_some()
            || l.link_delay_ms.is_some()
            || l.link_jitter_ms.is_some()
            || l.link_loss.is_some()
            || l.seed.is_some()
    }
}

#[derive(Debug, Subcommand)]
pub enum ScenarioCommand {
    /// Write a built-in or generated scenario as a TOML file (after graph synthesis).
    Export {
        /// A built-in scenario name (paper40, the default).
        #[arg(conflicts_with = "n")]
        name: Option<String>,
        /// A generated team of N members instead (4..=2000).
        #[arg(long)]
        n: Option<usize>,
        /// Output file (default: standard output); an existing file is replaced.
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
    },
}

/// Where a run goes.
#[derive(Debug, Args, Clone)]
pub struct OutDir {
    /// The run directory (created; refused when it exists and is not empty, unless --force).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Write every K-th tick to the telemetry file (default: every tick up to 40 members, then
    /// every ceil(N / 40)-th: about 40 rows a tick whatever the team's size; printed at the
    /// start).
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    pub every: Option<u64>,
    /// Reuse a non-empty --out directory.
    #[arg(long)]
    pub force: bool,
}

// The default `--every` lives beside the telemetry writers, where the Python package's
// `simulate` finds it too.
pub use cdm_team::telemetry::{every_or_default, DEFAULT_ROWS_PER_TICK};

/// The line that says, before a run, which ticks its telemetry keeps.
pub fn every_line(every: Option<u64>, members: usize) -> String {
    let k = every_or_default(every, members);
    let which = match k {
        1 => "every tick".to_string(),
        k => format!("one tick in {k}"),
    };
    match every {
        Some(_) => format!("telemetry: {which} (--every)"),
        None => format!(
            "telemetry: {which} (the default for {members} members, about \
             {DEFAULT_ROWS_PER_TICK} rows a tick; --every K to choose)"
        ),
    }
}

/// `orchestrator keys`.
#[derive(Debug, Subcommand)]
pub enum KeysCommand {
    /// Create a team's keys in DIR (new or empty): DIR/authority (keep it; never copy it to a
    /// host), DIR/orchestrator (to the orchestrator's machine), DIR/host-1.. (one to each host).
    New {
        dir: PathBuf,
        /// How many host daemons get a certificate (hosts 1..=N).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=63))]
        daemons: u32,
    },
    /// Add the next host's certificate to the team whose keys are in DIR.
    AddHost { dir: PathBuf },
}

/// `launch` across hosts.
#[derive(Debug, Args, Clone)]
pub struct HostArgs {
    /// Split the team over K hosts: this one and K - 1 `orchestrator host` daemons.
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub hosts: u32,
    /// Where the daemons connect, in zenoh's form (tls/10.77.0.1:7447); needed with --hosts.
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Option<String>,
    /// The orchestrator's keys (DIR/orchestrator of `orchestrator keys new`), for a tls/
    /// endpoint: mutual TLS, each daemon bound to its host number by its certificate.
    #[arg(long, value_name = "DIR")]
    pub keys: Option<PathBuf>,
    /// Allow a tcp/ endpoint: no authentication, no encryption (a network you trust).
    #[arg(long)]
    pub insecure: bool,
    /// Seconds of silence on a host link before it counts as lost (at most 86400).
    #[arg(long, default_value_t = 3.0, allow_negative_numbers = true)]
    pub link_timeout: f64,
}

/// Options shared by `simulate` and `launch`.
#[derive(Debug, Args, Clone)]
pub struct RunOptions {
    #[command(flatten)]
    pub link: cdm_member_cli::LinkArgs,
    /// End the run at the tick of its first safety violation (telemetry kept, exit 1).
    #[arg(long)]
    pub stop_on_violation: bool,
    /// Fly only ticks 0..=K of the plan, that is K + 1 ticks (a shorter run of the same
    /// scenario).
    #[arg(long, value_name = "K")]
    pub max_ticks: Option<u64>,
    /// Do not draw the figures at the end of the run.
    #[arg(long)]
    pub no_figures: bool,
    /// The member of fig_agent_<id>, a follower or a leader (default: the follower deepest in
    /// the graph); checked before the flight.
    #[arg(long, value_name = "ID")]
    pub follow: Option<u32>,
    /// Telemetry file format: telemetry.csv or telemetry.parquet (same columns and values), or
    /// mcap: telemetry.csv and the run as a ROS 2 bag written during the run (rosbag2/: the
    /// messages of `export rosbag2`).
    #[arg(long, value_name = "FORMAT", default_value = "csv", value_parser = telemetry_format())]
    pub telemetry: TelemetryFormat,
    /// Lose member ID once it has published its state of time SECONDS (repeatable). With
    /// `--on-loss repair` its readers switch to new triangles and the team flies on.
    #[arg(long, value_name = "ID@SECONDS")]
    pub lose: Vec<ScriptedLoss>,
    /// What losing a member does: repair the graph and fly on, or stop the run as a fault
    /// (exit 3).
    #[arg(long, value_enum, default_value_t = OnLossArg::Repair)]
    pub on_loss: OnLossArg,
}

/// `--telemetry csv|parquet|mcap` (the format type lives in cdm-records, which has no clap).
fn telemetry_format() -> impl clap::builder::TypedValueParser<Value = TelemetryFormat> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(["csv", "parquet", "mcap"]).map(|s| match s.as_str() {
        "parquet" => TelemetryFormat::Parquet,
        "mcap" => TelemetryFormat::Mcap,
        _ => TelemetryFormat::Csv,
    })
}

/// `--on-interrupt`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OnInterruptArg {
    Stop,
    Land,
}

/// `--on-loss`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OnLossArg {
    Repair,
    Stop,
}

impl From<OnLossArg> for OnLoss {
    fn from(a: OnLossArg) -> Self {
        match a {
            OnLossArg::Repair => OnLoss::Repair,
            OnLossArg::Stop => OnLoss::Stop,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_every_keeps_about_40_rows_a_tick_and_an_explicit_one_wins() {
        let default = |n| every_or_default(None, n);
        assert_eq!([default(4), default(40), default(41)], [1, 1, 2]);
        assert_eq!([default(100), default(250), default(1000)], [3, 7, 25]);
        assert_eq!(every_or_default(Some(1), 1000), 1);
        assert_eq!(every_or_default(Some(7), 10), 7);
        assert!(every_line(None, 1000).starts_with("telemetry: one tick in 25 (the default"));
        assert_eq!(every_line(Some(1), 1000), "telemetry: every tick (--every)");
    }
}
