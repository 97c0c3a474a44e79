//! `launch`'s options of the live feeds (`--ros2`, `--foxglove`) and of real time
//! (`--realtime` ...), parsed by clap and validated into cdm-launch's plain option structs.

use cdm_exit::Failure;
use cdm_foxglove::FoxgloveOptions;
use cdm_launch::realtime::RealtimeOptions;
use cdm_ros2::{Backend, Ros2Options};
use cdm_scenario::Scenario;

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

/// The real-time options of `launch`.
#[derive(Debug, Clone, clap::Args)]
pub struct RealtimeArgs {
    /// Fly in real time: every member ticks at comm_hz on its own clock from a start instant
    /// this orchestrator announces, with no grant and no barrier; the orchestrator monitors.
    #[arg(long)]
    pub realtime: bool,
    /// With --realtime: the monitor's audit rate, the telemetry's rows per second (default:
    /// the scenario's comm_hz).
    #[arg(long, value_name = "HZ")]
    pub audit_hz: Option<f64>,
    /// With --realtime: seconds after which a member's newest state is too old (a fault).
    #[arg(
        long,
        value_name = "SECONDS",
        default_value_t = 0.5,
        allow_negative_numbers = true
    )]
    pub stale_after: f64,
    /// With --realtime: the seed of the members' phase offsets in [0, 1/comm_hz); 0 aligns
    /// every member on the start instant.
    #[arg(long, value_name = "SEED", default_value_t = 1)]
    pub phase_seed: u32,
    /// With --realtime: run the orchestrator and every member under SCHED_FIFO at this
    /// priority (1-99), so their wake-ups preempt ordinary processes; needs root,
    /// CAP_SYS_NICE or `ulimit -r` (BENCHMARKS.md: late ticks with and without).
    #[arg(long, value_name = "P", value_parser = clap::value_parser!(u8).range(cdm_process::sched::RT_PRIORITIES))]
    pub rt_priority: Option<u8>,
    /// With --realtime: the members write no recording (the run cannot be replayed); for
    /// measuring what recording costs (BENCHMARKS.md).
    #[arg(long)]
    pub no_recording: bool,
}

impl RealtimeArgs {
    /// The options, or `None` without --realtime; a bad value is bad input naming its flag.
    pub fn options(&self, s: &Scenario) -> Result<Option<RealtimeOptions>, Failure> {
        if !self.realtime {
            if self.audit_hz.is_some() {
                return Err(Failure::bad_input("--audit-hz needs --realtime"));
            }
            if self.rt_priority.is_some() {
                return Err(Failure::bad_input("--rt-priority needs --realtime"));
            }
            if self.no_recording {
                return Err(Failure::bad_input("--no-recording needs --realtime"));
            }
            return Ok(None);
        }
        let audit_hz = self.audit_hz.unwrap_or(s.file.comm_hz);
        if !(audit_hz.is_finite() && audit_hz > 0.0 && audit_hz <= 10_000.0) {
            return Err(Failure::bad_input(format!(
                "--audit-hz must be in (0, 10000], got {audit_hz}"
            )));
        }
        let stale_after = cdm_member_cli::timeout("--stale-after", self.stale_after)
            .map_err(Failure::bad_input)?;
        Ok(Some(RealtimeOptions {
            audit_hz,
            stale_after,
            phase_seed: self.phase_seed,
            rt_priority: self.rt_priority,
            record: !self.no_recording,
        }))
    }
}
