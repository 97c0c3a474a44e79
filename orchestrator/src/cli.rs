//! Command-line interface: the raw arguments as clap parses them; `commands.rs` turns them into
//! each command's options and loads and checks the scenario.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use common::loss::{OnLoss, ScriptedLoss};

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

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Pre-flight certificate: lambda_1(U_D), D_B, D_S, delta, T_threshold; exit 0 SAFE, 1 UNSAFE.
    Plan {
        #[command(flatten)]
        source: Source,
        /// Also write the certificate as JSON.
        #[arg(long, value_name = "FILE")]
        json: Option<PathBuf>,
        /// Fly the plan at travel times LO, LO+STEP, .., HI and draw E_max versus T_total
        /// (fig_deviation_sweep in --out; the paper's Fig. 10).
        #[arg(long, value_name = "LO:HI:STEP", requires = "out")]
        sweep: Option<String>,
        /// Where the sweep's figure and data go.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// Also certify the loss of every single member: fly the plan with each one lost at the
        /// nominal peak deviation (graph repaired) and list the members the team cannot lose
        /// (exit 1 when there is one).
        #[arg(long)]
        losses: bool,
    },
    /// Fly the team with the deterministic in-process engine into a run directory.
    Simulate {
        #[command(flatten)]
        source: Source,
        #[command(flatten)]
        out: OutDir,
        #[command(flatten)]
        run: RunOptions,
    },
    /// Fly the team as processes: one per quadcopter over iceoryx2 shared memory, a shared
    /// lockstep clock, a live safety audit. Exit 0 safe and complete, 1 violation, 2 bad input,
    /// 3 runtime fault.
    Launch {
        #[command(flatten)]
        source: Source,
        /// The run directory (default: runs/<team>).
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// Write every K-th tick to telemetry.csv.
        #[arg(long, value_name = "K", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
        every: u64,
        /// Reuse a non-empty --out directory.
        #[arg(long)]
        force: bool,
        /// The team's name: its services' prefix ([A-Za-z0-9_-], at most 48 characters).
        #[arg(long)]
        team: Option<String>,
        /// Do not start the processes: wait for them to be started by hand.
        #[arg(long)]
        no_spawn: bool,
        /// How many ticks an agent may run ahead of the slowest (1 = strict lockstep). Larger
        /// windows mean fewer wake-ups per tick (BENCHMARKS.md) and more shared memory.
        #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u32).range(1..=4096))]
        window: u32,
        /// Seconds without any agent progress before the team is stopped as faulty.
        #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
        agent_timeout: f64,
        /// Seconds to wait for hand-started processes (--no-spawn) to join.
        #[arg(long, default_value_t = 300.0, allow_negative_numbers = true)]
        join_timeout: f64,
        #[command(flatten)]
        run: RunOptions,
    },
    /// Redraw every figure of a finished run from its telemetry.csv, audit.json and
    /// scenario.toml (SVG and PNG, into the run directory).
    Report {
        /// The run directory.
        #[arg(value_name = "RUN_DIR")]
        dir: PathBuf,
        /// The follower of fig_agent_<id> (default: the one deepest in the graph).
        #[arg(long, value_name = "ID")]
        follow: Option<u32>,
    },
    /// Remove what teams of yours left behind when all their processes died (SIGKILL, a
    /// crash): their iceoryx2 files in /dev/shm. Running teams are never touched. `launch` does
    /// the same before it starts.
    Clean,
    /// Export the plan to the stacks that fly real fleets (Crazyswarm2, Skybrush), scaled into
    /// the target volume and certified again there: exit 0 SAFE, 1 UNSAFE (files written only
    /// with --force), 2 bad input or a plan the target cannot hold.
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

#[derive(Debug, Subcommand)]
pub enum ScenarioCommand {
    /// Write a built-in or generated scenario as a TOML file (after graph synthesis).
    Export {
        /// A built-in scenario name (paper40).
        #[arg(conflicts_with = "n")]
        name: Option<String>,
        /// A generated team of N agents instead.
        #[arg(long)]
        n: Option<usize>,
        /// Output file (default: standard output).
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
    },
}

#[derive(Debug, Subcommand)]
pub enum ExportTarget {
    /// One <id>.csv of polynomial pieces per quadcopter (Crazyswarm2's uav_trajectory format),
    /// crazyflies.yaml, README.txt, certificate.json, scenario.toml and a top view into --out.
    Crazyswarm2 {
        #[command(flatten)]
        source: Source,
        /// The output directory (created; our files in it are replaced).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        #[command(flatten)]
        frame: ExportFrame,
    },
    /// A Skybrush show (.skyc: a ZIP holding show.json with Bézier trajectories), with
    /// <stem>.certificate.json and <stem>.scenario.toml beside it.
    Skybrush {
        #[command(flatten)]
        source: Source,
        /// The show file to write (e.g. show.skyc).
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        #[command(flatten)]
        frame: ExportFrame,
    },
}

/// Where an exported plan flies: p -> scale p + origin, and the target vehicles' radius.
#[derive(Debug, Args, Clone)]
pub struct ExportFrame {
    /// Multiply every position and goal by S (the paper's team is 300 m wide; a lab is 5 m).
    #[arg(
        long,
        value_name = "S",
        default_value_t = 1.0,
        allow_negative_numbers = true
    )]
    pub scale: f64,
    /// Then add X,Y,Z metres (default 0,0,0).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub origin: Option<String>,
    /// The radius of the target vehicles' ball, metres (0.1 for a Crazyflie).
    #[arg(
        long,
        value_name = "METRES",
        default_value_t = 0.1,
        allow_negative_numbers = true
    )]
    pub eps: f64,
    /// Write the files even when the certificate at the target scale is UNSAFE (exit 1 stays).
    #[arg(long)]
    pub force: bool,
}

/// Which scenario to fly: a file, a built-in, or a generated team (default: built-in paper40).
#[derive(Debug, Args, Clone)]
pub struct Source {
    /// A scenario file (TOML).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["n", "builtin"])]
    pub scenario: Option<PathBuf>,
    /// A generated team of N agents (4..=2000).
    #[arg(long, conflicts_with = "builtin")]
    pub n: Option<usize>,
    /// A built-in scenario (paper40).
    #[arg(long, value_name = "NAME")]
    pub builtin: Option<String>,
    /// Override the scenario's travel time t_total_s.
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    pub t_total: Option<f64>,
}

/// Where a run goes.
#[derive(Debug, Args, Clone)]
pub struct OutDir {
    /// The run directory (created; refused when it exists and is not empty, unless --force).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Write every K-th tick to telemetry.csv.
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub every: u64,
    /// Reuse a non-empty --out directory.
    #[arg(long)]
    pub force: bool,
}

/// Options shared by `simulate` and `launch`.
#[derive(Debug, Args, Clone)]
pub struct RunOptions {
    /// End the run at the tick of its first safety violation (telemetry kept, exit 1).
    #[arg(long)]
    pub stop_on_violation: bool,
    /// Fly only ticks 0..=K of the plan (a shorter run of the same scenario).
    #[arg(long, value_name = "K")]
    pub max_ticks: Option<u64>,
    /// Do not draw the figures at the end of the run.
    #[arg(long)]
    pub no_figures: bool,
    /// The follower of fig_agent_<id> (default: the one deepest in the graph).
    #[arg(long, value_name = "ID")]
    pub follow: Option<u32>,
    /// Lose member ID once it has published its state of time SECONDS (repeatable). With
    /// `--on-loss repair` its readers switch to new triangles and the team flies on.
    #[arg(long, value_name = "ID@SECONDS")]
    pub lose: Vec<ScriptedLoss>,
    /// What losing a member does: repair the graph and fly on, or stop the run as a fault
    /// (exit 3).
    #[arg(long, value_enum, default_value_t = OnLossArg::Repair)]
    pub on_loss: OnLossArg,
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
