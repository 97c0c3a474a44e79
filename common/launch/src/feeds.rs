//! What sees each audited tick besides the audit and telemetry, in lockstep and real time
//! alike: the live view (`--serve`, cdm-viewer), the live ROS 2 topics (`--ros2`, cdm-ros2) and
//! Foxglove (`--foxglove`, cdm-foxglove). Each paces itself by the wall clock and never makes
//! the loop wait.

use cdm_foxglove::FoxgloveOptions;
use cdm_math::Vec3;
use cdm_records::audit::{AuditReport, Auditor, CommandSummary};
use cdm_ros2::{Live, Ros2Options};
use cdm_scenario::Scenario;
use cdm_team::notices::NoticeSink;
use cdm_team::Failure;
use cdm_viewer::live::LiveView;

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
        notices: &dyn NoticeSink,
    ) -> Result<Self, Failure> {
        let view = match serve {
            Some(addr) => {
                let auditor = Auditor::new(s);
                let mut view = LiveView::start(&addr.to_string(), s, auditor.numbers())
                    .map_err(Failure::bad_input)?;
                for c in commands {
                    view.command(c);
                }
                notices.notice(&format_args!("live view: http://{}/", view.addr()));
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
                notices.notice(&format_args!("foxglove: ws://{}", f.addr()));
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

    /// A command given to the team in flight (`orchestrator command`): the live view marks it,
    /// the live ROS 2 topics send it with the first tick at or after its switch.
    pub fn command(&mut self, c: &CommandSummary) {
        if let Some(v) = self.view.as_mut() {
            v.command(c);
        }
        if let Some(r) = self.ros2.as_mut() {
            r.command(c);
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
    pub fn finish(&mut self, report: &AuditReport, notices: &dyn NoticeSink) {
        if let Some(f) = self.foxglove.take() {
            let s = f.finish(report.verdict);
            let unfinished = unfinished(s.unfinished);
            notices.notice(&format_args!(
                "  foxglove (ws://{}): {} ticks published, {} dropped (queue full){unfinished}",
                s.addr, s.ticks, s.dropped
            ));
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
            let unfinished = unfinished(s.unfinished);
            notices.notice(&format_args!(
                "  ros2 ({}): {} ticks published, {} dropped (queue full){failed}{unfinished}",
                s.backend, s.ticks, s.dropped
            ));
        }
    }
}

/// The end of a feed's summary line when it was still publishing as the launch ended.
fn unfinished(still_publishing: bool) -> &'static str {
    if still_publishing {
        "; still publishing when the launch ended"
    } else {
        ""
    }
}
