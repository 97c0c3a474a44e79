//! What sees each audited tick besides the audit and telemetry, in lockstep and real time
//! alike: the live view (`--serve`, cdm-viewer), the live ROS 2 topics (`--ros2`, cdm-ros2) and
//! Foxglove (`--foxglove`, cdm-foxglove). Each paces itself by the wall clock and never makes
//! the loop wait.

use crate::launch_error::LaunchError;
use crate::notice::LaunchNotice;
use cdm_foxglove::FoxgloveOptions;
use cdm_math::Vec3;
use cdm_records::audit::{AuditReport, Auditor, CommandSummary};
use cdm_ros2::{Live, Ros2Options};
use cdm_scenario::Scenario;
use cdm_team::notices::NoticeSink;
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
    ) -> Result<Self, LaunchError> {
        let view = match serve {
            Some(addr) => {
                let auditor = Auditor::new(s);
                let mut view = LiveView::start(&addr.to_string(), s, auditor.numbers())?;
                for c in commands {
                    view.command(c);
                }
                notices.notice(&LaunchNotice::LiveView {
                    addr: view.addr().to_owned(),
                });
                Some(view)
            }
            None => None,
        };
        let ros2 = match ros2 {
            Some(o) => {
                let live = Live::start_commanded(o, s, commands.to_vec());
                Some(live?)
            }
            None => None,
        };
        let foxglove = match foxglove {
            Some(o) => {
                let f = cdm_foxglove::FoxgloveLive::start(o, s)?;
                notices.notice(&LaunchNotice::Foxglove { addr: f.addr() });
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
            notices.notice(&LaunchNotice::FoxgloveDone(f.finish(report.verdict)));
        }
        if let Some(v) = &self.view {
            v.finish(report);
        }
        if let Some(r) = self.ros2.take() {
            notices.notice(&LaunchNotice::Ros2Done(r.finish()));
        }
    }
}
