//! What sees each audited tick besides the audit and telemetry, in lockstep and real time
//! alike: the live view (`--serve`, cdm-viewer), the live ROS 2 topics (`--ros2`, cdm-ros2) and
//! Foxglove (`--foxglove`, cdm-foxglove). Each paces itself by the wall clock and never makes
//! the loop wait.

use cdm_foxglove::FoxgloveOptions;
use cdm_math::Vec3;
use cdm_records::audit::{AuditReport, Auditor, CommandSummary};
use cdm_ros2::{Backend, Live, Ros2Options};
use cdm_scenario::Scenario;
use cdm_team::{out, Failure};
use cdm_viewer::live::LiveView;

/// `--ros2` and `--ros2-hz`.
#[derive(Debug, Clone, clap::Args)]
pub struct Ros2Args {
    /// Publish the run live on ROS 2 over MIDDLEWARE (dds: DDS/RTPS as rmw_fastrtps and
    /// rmw_cyclonedds speak it; zenoh: rmw_zenoh's format): the topics of its bag, each
    /// member's pose, /tf, /cdm/formation and /cdm/audit. Output only: nothing is subscribed.
    #[arg(long, value_name = "MIDDLEWARE")]
    pub ros2: Option<Backend>,
    /// With --ros2: ticks published per second of wall time, at most (0.01 to 1000, default 30).
    #[arg(long, value_name = "HZ", allow_negative_numbers = true)]
    pub ros2_hz: Option<f64>,
}

/// `--ros2-hz` when not given.
pub const DEFAULT_ROS2_HZ: f64 = 30.0;

/// `--ros2-hz`'s range: one tick every 100 s at the least (a slower feed is no live view),
/// a thousand a second at the most.
pub const ROS2_HZ_RANGE: std::ops::RangeInclusive<f64> = 0.01..=1000.0;

impl Ros2Args {
    /// The options, or `None` without --ros2; a bad value is bad input naming its flag.
    pub fn options(&self) -> Result<Option<Ros2Options>, Failure> {
        let Some(backend) = self.ros2 else {
            if self.ros2_hz.is_some() {
                return Err(Failure::bad_input("--ros2-hz needs --ros2"));
            }
            return Ok(None);
        };
        let hz = self.ros2_hz.unwrap_or(DEFAULT_ROS2_HZ);
        if !ROS2_HZ_RANGE.contains(&hz) {
            return Err(Failure::bad_input(format!(
                "--ros2-hz must be in [{}, {}], got {hz:e}",
                ROS2_HZ_RANGE.start(),
                ROS2_HZ_RANGE.end()
            )));
        }
        Ok(Some(Ros2Options { backend, hz }))
    }
}

/// `--foxglove` and `--foxglove-hz`.
#[derive(Debug, Clone, clap::Args)]
pub struct FoxgloveArgs {
    /// Serve the run live to Foxglove (its WebSocket protocol) on ADDR (HOST:PORT or PORT; a
    /// bare --foxglove is 127.0.0.1:8765): each member's pose, /tf, the formation as a 3-D
    /// scene, the margins, the verdict and losses. Only loopback unless another address is given.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = cdm_foxglove::DEFAULT_ADDR)]
    pub foxglove: Option<String>,
    /// With --foxglove: ticks published per second of wall time, at most (default 30).
    #[arg(long, value_name = "HZ", allow_negative_numbers = true)]
    pub foxglove_hz: Option<f64>,
}

impl FoxgloveArgs {
    /// The options, or `None` without --foxglove; a bad value is bad input naming its flag.
    pub fn options(&self) -> Result<Option<FoxgloveOptions>, Failure> {
        match &self.foxglove {
            None if self.foxglove_hz.is_some() => {
                Err(Failure::bad_input("--foxglove-hz needs --foxglove"))
            }
            None => Ok(None),
            Some(addr) => FoxgloveOptions::parse(addr, self.foxglove_hz)
                .map(Some)
                .map_err(Failure::bad_input),
        }
    }
}

/// The live feeds of a launch.
#[derive(Default)]
pub struct Feeds {
    pub view: Option<LiveView>,
    pub ros2: Option<Live>,
    pub foxglove: Option<cdm_foxglove::FoxgloveLive>,
}

impl Feeds {
    /// Starts what `--serve` and `--ros2` ask for, before the team: a bad address or a bad
    /// ROS 2 environment stops nothing (exit 2). `commands`: the run's commands, decided before
    /// the flight (`--commands`): the live view marks each from its switch tick on, the live
    /// ROS 2 topics send each with the first tick at or after its switch.
    pub fn start(
        s: &Scenario,
        serve: Option<std::net::SocketAddr>,
        ros2: Option<&Ros2Options>,
        foxglove: Option<&FoxgloveOptions>,
        commands: &[CommandSummary],
        quiet: bool,
    ) -> Result<Self, Failure> {
        let view = match serve {
            Some(addr) => {
                let auditor = Auditor::new(s);
                let mut view = LiveView::start(&addr.to_string(), s, auditor.numbers())
                    .map_err(Failure::bad_input)?;
                for c in commands {
                    view.command(c);
                }
                if !quiet {
                    out!("live view: http://{}/", view.addr());
                }
                Some(view)
            }
            None => None,
        };
        let ros2 = match ros2 {
            Some(o) => {
                let live = Live::start_commanded(o, s, commands.to_vec());
                Some(live.map_err(Failure::bad_input)?)
            }
            None => None,
        };
        let foxglove = match foxglove {
            Some(o) => {
                let f = cdm_foxglove::FoxgloveLive::start(o, s).map_err(Failure::bad_input)?;
                if !quiet {
                    out!("foxglove: ws://{}", f.addr());
                }
                Some(f)
            }
            None => None,
        };
        Ok(Feeds {
            view,
            ros2,
            foxglove,
        })
    }

    /// A command given to the team in flight (`orchestrator command`): the live view marks it
    /// (the live ROS 2 topics carry only the commands known at their start).
    pub fn command(&mut self, c: &CommandSummary) {
        if let Some(v) = self.view.as_mut() {
            v.command(c);
        }
    }

    /// One audited tick: offered to each feed (`flying(k)` false for a member lost by then).
    pub fn tick(
        &mut self,
        tick: u64,
        t_s: f64,
        (pos, ht): (&[Vec3], &[Vec3]),
        flying: impl Fn(usize) -> bool,
        report: &AuditReport,
    ) {
        if let Some(v) = self.view.as_mut() {
            v.tick(tick, t_s, (pos, ht), &flying, report);
        }
        if let Some(r) = self.ros2.as_mut() {
            r.tick(tick, t_s, (pos, ht), &flying);
        }
        if let Some(f) = self.foxglove.as_mut() {
            f.tick(tick, t_s, (pos, ht), &flying, report.verdict);
        }
    }

    /// The run is over: the page gets its verdict, the ROS 2 topics their last messages,
    /// Foxglove the final verdict before its server closes (the view keeps serving until the
    /// caller drops it).
    pub fn finish(&mut self, report: &AuditReport, quiet: bool) {
        if let Some(f) = self.foxglove.take() {
            let s = f.finish(report.verdict);
            if !quiet {
                let unfinished = if s.unfinished {
                    "; still publishing when the launch ended"
                } else {
                    ""
                };
                out!(
                    "  foxglove (ws://{}): {} ticks published, {} dropped (queue full){unfinished}",
                    s.addr,
                    s.ticks,
                    s.dropped
                );
            }
        }
        if let Some(v) = &self.view {
            v.finish(report);
        }
        if let Some(r) = self.ros2.take() {
            let s = r.finish();
            let failed = match &s.first_error {
                Some(e) => format!(", {} messages refused (first: {e})", s.failed),
                None => String::new(),
            };
            let unfinished = if s.unfinished {
                "; still publishing when the launch ended"
            } else {
                ""
            };
            if !quiet {
                out!(
                    "  ros2 ({}): {} ticks published, {} dropped (queue full){failed}{unfinished}",
                    s.backend,
                    s.ticks,
                    s.dropped
                );
            }
        }
    }
}
