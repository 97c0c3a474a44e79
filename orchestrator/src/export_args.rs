//! The command-line arguments of `orchestrator export`, and the scenario source every command
//! shares (clap types: the orchestrator's CLI flattens them), each turned into cdm-export's
//! plain values.

use std::path::PathBuf;

use cdm_exit::Failure;
use cdm_export::{ExportError, ExportFrame, ScenarioSource};
use cdm_scenario::Scenario;
use clap::{Args, Subcommand};

#[derive(Debug, Subcommand)]
pub enum ExportTarget {
    /// One <id>.csv of polynomial pieces per quadcopter (Crazyswarm2's uav_trajectory format),
    /// crazyflies.yaml, README.txt, certificate.json, scenario.toml and a top view into --out.
    Crazyswarm2 {
        #[command(flatten)]
        source: SourceArgs,
        /// The output directory (created; our files in it are replaced).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        #[command(flatten)]
        frame: FrameArgs,
    },
    /// A Skybrush show (.skyc: a ZIP holding show.json with Bézier trajectories), with
    /// <stem>.certificate.json and <stem>.scenario.toml beside it. With [origin], the show's
    /// location and orientation; with [vehicle], its validation limits.
    Skybrush {
        #[command(flatten)]
        source: SourceArgs,
        /// The show file to write (e.g. show.skyc).
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        #[command(flatten)]
        frame: FrameArgs,
    },
    /// The scenario on a map (needs [origin]): a GeoJSON FeatureCollection (RFC 7946) of the
    /// geofence, the obstacles, the leaders' planned paths and the ground spots.
    Geojson {
        /// A scenario file, or a run directory (its scenario.toml).
        #[arg(value_name = "RUN_OR_SCENARIO")]
        source: PathBuf,
        /// The .geojson file to write.
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Overwrite --out if it exists.
        #[arg(long)]
        force: bool,
    },
    /// QGroundControl's .plan file (needs [origin]): the geofence as the inclusion polygon,
    /// the obstacles as exclusion polygons and circles, the landing spots as rally points.
    QgcPlan {
        /// A scenario file, or a run directory (its scenario.toml).
        #[arg(value_name = "RUN_OR_SCENARIO")]
        source: PathBuf,
        /// The .plan file to write.
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Overwrite --out if it exists.
        #[arg(long)]
        force: bool,
    },
    /// A finished run (the RUN_DIR of `simulate` or `launch`) as a ROS 2 bag for Foxglove and
    /// `ros2 bag play`: a rosbag2 directory (metadata.yaml and one .mcap) with each member's
    /// PoseStamped, /tf, the formation's markers and each tick's safety margins.
    Rosbag2 {
        /// The run directory (scenario.toml, audit.json, telemetry.csv or telemetry.parquet).
        #[arg(value_name = "RUN_DIR")]
        run: PathBuf,
        /// The bag directory to write.
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Write into --out even when it exists and is not empty (the bag's files are replaced).
        #[arg(long)]
        force: bool,
    },
}

/// Where an exported plan flies: p -> scale p + origin, and the target vehicles' radius.
#[derive(Debug, Args, Clone)]
pub struct FrameArgs {
    /// Multiply every position and goal by S (the paper's team is 300 m wide; a lab is 5 m);
    /// a mission's segment goals and ground heights too.
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
    /// Write the files even when the certificate at the target scale is UNSAFE (exit 1 stays),
    /// or when --out already exists (it is overwritten).
    #[arg(long)]
    pub force: bool,
}

impl FrameArgs {
    pub fn plain(&self) -> ExportFrame {
        ExportFrame {
            scale: self.scale,
            origin: self.origin.clone(),
            eps_m: self.eps,
            force: self.force,
        }
    }
}

/// Which scenario to fly: a file, a built-in, or a generated team (default: built-in paper40).
#[derive(Debug, Args, Clone)]
pub struct SourceArgs {
    /// A scenario file (TOML).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["n", "builtin"])]
    pub scenario: Option<PathBuf>,
    /// A generated team of N members (4..=2000).
    #[arg(long, conflicts_with = "builtin")]
    pub n: Option<usize>,
    /// A built-in scenario (paper40).
    #[arg(long, value_name = "NAME")]
    pub builtin: Option<String>,
    /// Override the scenario's travel time t_total_s.
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    pub t_total: Option<f64>,
}

impl SourceArgs {
    pub fn plain(&self) -> ScenarioSource {
        ScenarioSource {
            scenario: self.scenario.clone(),
            n: self.n,
            builtin: self.builtin.clone(),
            t_total_s: self.t_total,
        }
    }
}

/// Load and fully validate the scenario a command names.
pub fn load(source: &SourceArgs) -> Result<Scenario, Failure> {
    cdm_export::load(&source.plain()).map_err(Failure::bad_input)
}

/// An export's error with its exit code: bad input 2, a fault 3.
pub fn failure(e: ExportError) -> Failure {
    if e.is_bad_input() {
        Failure::bad_input(e)
    } else {
        Failure::fault(e)
    }
}
