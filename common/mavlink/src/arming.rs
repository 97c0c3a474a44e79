//! `--arm`: the mode change and the arm command as a pure state machine over a passed-in clock.
//!
//! PX4 accepts OFFBOARD only while a setpoint stream is already arriving (and leaves it when
//! the stream stops), so the sequence is: stream setpoints for [`STREAM_BEFORE_MODE`], request
//! OFFBOARD (PX4) or GUIDED (ArduPilot) with MAV_CMD_DO_SET_MODE until the HEARTBEAT shows it,
//! then MAV_CMD_COMPONENT_ARM_DISARM until the HEARTBEAT shows the vehicle armed. Each request
//! is repeated every [`RETRY_INTERVAL`], at most [`MAX_REQUESTS`] times. Without `--arm` the
//! member only streams and the operator switches mode and arms.

use std::time::Duration;

/// How long setpoints stream before the mode change is requested (PX4 wants > 2 Hz "for a
/// while"; one second of comm_hz setpoints is comfortably more).
pub const STREAM_BEFORE_MODE: Duration = Duration::from_secs(1);
/// Time between two requests of the same step (a COMMAND_LONG over UDP can be lost).
pub const RETRY_INTERVAL: Duration = Duration::from_secs(1);
/// Requests per step before the member gives up.
pub const MAX_REQUESTS: u32 = 5;

/// PX4's main mode number of OFFBOARD (px4_custom_mode.h: PX4_CUSTOM_MAIN_MODE_OFFBOARD).
pub const PX4_MAIN_MODE_OFFBOARD: u32 = 6;
/// ArduCopter's mode number of GUIDED (ArduCopter/mode.h: Mode::Number::GUIDED).
pub const ARDUCOPTER_MODE_GUIDED: u32 = 4;

/// The flight stacks the sequence knows, from HEARTBEAT.autopilot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Autopilot {
    Px4,
    ArduPilot,
    /// Any other MAV_AUTOPILOT value (its number): streaming works, `--arm` does not.
    Other(u32),
}

impl Autopilot {
    /// The DO_SET_MODE custom mode and sub mode (param2, param3) of the mode that follows
    /// external position targets, or `None` for an unknown stack.
    pub fn guided_mode(self) -> Option<(u32, u32)> {
        match self {
            Autopilot::Px4 => Some((PX4_MAIN_MODE_OFFBOARD, 0)),
            Autopilot::ArduPilot => Some((ARDUCOPTER_MODE_GUIDED, 0)),
            Autopilot::Other(_) => None,
        }
    }

    /// Whether HEARTBEAT.custom_mode shows that mode. PX4 packs its main mode in bits 16..24
    /// of custom_mode (px4_custom_mode union); ArduPilot sends the mode number itself.
    pub fn in_guided_mode(self, custom_mode: u32) -> bool {
        match self {
            Autopilot::Px4 => (custom_mode >> 16) & 0xff == PX4_MAIN_MODE_OFFBOARD,
            Autopilot::ArduPilot => custom_mode == ARDUCOPTER_MODE_GUIDED,
            Autopilot::Other(_) => false,
        }
    }
}

/// What the vehicle's last HEARTBEAT said.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VehicleMode {
    pub autopilot: Autopilot,
    pub custom_mode: u32,
    pub armed: bool,
}

/// A command the member must send now (COMMAND_LONG: `messages::command`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ArmAction {
    /// MAV_CMD_DO_SET_MODE with the custom-mode flag, `custom_mode` and `sub_mode`.
    SetMode { custom_mode: u32, sub_mode: u32 },
    /// MAV_CMD_COMPONENT_ARM_DISARM with param1 = 1 (arm).
    Arm,
    /// MAV_CMD_NAV_TAKEOFF with param7 = `altitude_m` above home (ArduCopter, `takeoff.rs`).
    Takeoff { altitude_m: f32 },
    /// MAV_CMD_NAV_LAND at the vehicle's position (`--disarm-at-end`: `landing.rs`).
    Land,
    /// MAV_CMD_COMPONENT_ARM_DISARM with param1 = 0 and param2 = 0, never forced
    /// (`--disarm-at-end`: `landing.rs`).
    Disarm,
}

/// Why `--arm` failed. Every variant names the member (by id).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ArmError {
    #[error("agent {agent}: --arm does not know autopilot MAV_AUTOPILOT {autopilot} (PX4 and ArduPilot only); switch mode and arm by hand without --arm")]
    UnknownAutopilot { agent: u32, autopilot: u32 },
    #[error("agent {agent}: the vehicle did not enter OFFBOARD/GUIDED after {MAX_REQUESTS} MAV_CMD_DO_SET_MODE requests")]
    ModeRefused { agent: u32 },
    #[error("agent {agent}: the vehicle did not arm after {MAX_REQUESTS} MAV_CMD_COMPONENT_ARM_DISARM requests")]
    ArmRefused { agent: u32 },
}

/// Where the sequence is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArmStage {
    /// No `--arm`: stream only, the operator does the rest.
    StreamOnly,
    /// Waiting for the team to be ready and the stream to have run long enough.
    Streaming,
    /// Requesting OFFBOARD / GUIDED.
    RequestingMode,
    /// Requesting arming.
    RequestingArm,
    /// In the guided mode and armed.
    Armed,
}

/// The `--arm` sequence of one member.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmSequence {
    agent: u32,
    stage: ArmStage,
    /// The current stage's requests.
    retries: Retries,
}

impl ArmSequence {
    /// The sequence of member `agent`: with `arm` false it never sends anything.
    pub fn new(agent: u32, arm: bool) -> Self {
        let stage = if arm {
            ArmStage::Streaming
        } else {
            ArmStage::StreamOnly
        };
        ArmSequence {
            agent,
            stage,
            retries: Retries::default(),
        }
    }

    /// The current stage.
    pub fn stage(&self) -> ArmStage {
        self.stage
    }

    /// Requests sent in the current stage (the last action returned was number `requests()`).
    pub fn requests(&self) -> u32 {
        self.retries.sent()
    }

    /// One step at `now`. `mode` is the vehicle's last HEARTBEAT (`None` before the first),
    /// `streamed` how long setpoints have been streaming, `team_ready` whether every vehicle of
    /// the team reports ready. Returns the command to send now, if any.
    pub fn on_tick(
        &mut self,
        now: Duration,
        mode: Option<VehicleMode>,
        streamed: Duration,
        team_ready: bool,
    ) -> Result<Option<ArmAction>, ArmError> {
        let Some(mode) = mode else {
            return Ok(None);
        };
        // The vehicle may reach a stage on its own (an operator, a retried command): follow it.
        let in_mode = mode.autopilot.in_guided_mode(mode.custom_mode);
        match self.stage {
            ArmStage::StreamOnly | ArmStage::Armed => Ok(None),
            ArmStage::Streaming => {
                if team_ready && streamed >= STREAM_BEFORE_MODE {
                    self.enter(ArmStage::RequestingMode);
                    return self.on_tick(now, Some(mode), streamed, team_ready);
                }
                Ok(None)
            }
            ArmStage::RequestingMode if in_mode => {
                self.enter(ArmStage::RequestingArm);
                self.on_tick(now, Some(mode), streamed, team_ready)
            }
            ArmStage::RequestingMode => {
                let Some((custom_mode, sub_mode)) = mode.autopilot.guided_mode() else {
                    let autopilot = match mode.autopilot {
                        Autopilot::Other(n) => n,
                        _ => 0,
                    };
                    return Err(ArmError::UnknownAutopilot {
                        agent: self.agent,
                        autopilot,
                    });
                };
                let refused = ArmError::ModeRefused { agent: self.agent };
                self.request(
                    now,
                    ArmAction::SetMode {
                        custom_mode,
                        sub_mode,
                    },
                    refused,
                )
            }
            ArmStage::RequestingArm if mode.armed && in_mode => {
                self.enter(ArmStage::Armed);
                Ok(None)
            }
            ArmStage::RequestingArm => {
                let refused = ArmError::ArmRefused { agent: self.agent };
                self.request(now, ArmAction::Arm, refused)
            }
        }
    }

    fn enter(&mut self, stage: ArmStage) {
        self.stage = stage;
        self.retries = Retries::default();
    }

    /// Send `action` if the last request is [`RETRY_INTERVAL`] old (or there was none); fail
    /// with `refused` once [`MAX_REQUESTS`] went unanswered.
    fn request(
        &mut self,
        now: Duration,
        action: ArmAction,
        refused: ArmError,
    ) -> Result<Option<ArmAction>, ArmError> {
        match self.retries.next(now) {
            Retry::Wait => Ok(None),
            Retry::Send => Ok(Some(action)),
            Retry::Exhausted => Err(refused),
        }
    }
}

/// What [`Retries::next`] says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Retry {
    /// The last request is younger than [`RETRY_INTERVAL`].
    Wait,
    /// Send the request now (counted).
    Send,
    /// [`MAX_REQUESTS`] went unanswered: give up.
    Exhausted,
}

/// One command's requests under MAVLink's command protocol: a COMMAND_LONG over UDP can be lost,
/// so it is sent again every [`RETRY_INTERVAL`] until answered, [`MAX_REQUESTS`] times at most.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Retries {
    last: Option<Duration>,
    sent: u32,
}

impl Retries {
    /// Whether to send the request at `now`.
    pub fn next(&mut self, now: Duration) -> Retry {
        let due = self
            .last
            .is_none_or(|t| now.saturating_sub(t) >= RETRY_INTERVAL);
        if !due {
            return Retry::Wait;
        }
        if self.sent >= MAX_REQUESTS {
            return Retry::Exhausted;
        }
        self.sent += 1;
        self.last = Some(now);
        Retry::Send
    }

    /// Requests sent so far.
    pub fn sent(&self) -> u32 {
        self.sent
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PX4_OFFBOARD: u32 = PX4_MAIN_MODE_OFFBOARD << 16;
    const PX4_POSCTL: u32 = 3 << 16;

    fn s(v: f64) -> Duration {
        Duration::from_secs_f64(v)
    }

    fn px4(custom_mode: u32, armed: bool) -> Option<VehicleMode> {
        Some(VehicleMode {
            autopilot: Autopilot::Px4,
            custom_mode,
            armed,
        })
    }

    #[test]
    fn without_arm_nothing_is_ever_sent() {
        let mut seq = ArmSequence::new(3, false);
        for k in 0..100 {
            let t = s(f64::from(k) * 0.1);
            assert_eq!(seq.on_tick(t, px4(PX4_POSCTL, false), t, true), Ok(None));
        }
        assert_eq!(seq.stage(), ArmStage::StreamOnly);
    }

    #[test]
    fn px4_streams_first_then_offboard_then_arms() {
        let mut seq = ArmSequence::new(3, true);
        let v = px4(PX4_POSCTL, false);
        // No request before the stream has run for a second, nor before the team is ready.
        assert_eq!(seq.on_tick(s(0.5), v, s(0.5), true), Ok(None));
        assert_eq!(seq.on_tick(s(1.2), v, s(1.2), false), Ok(None));
        assert_eq!(
            seq.on_tick(s(1.3), v, s(1.3), true),
            Ok(Some(ArmAction::SetMode {
                custom_mode: 6,
                sub_mode: 0
            }))
        );
        // Not repeated before the retry interval.
        assert_eq!(seq.on_tick(s(1.5), v, s(1.5), true), Ok(None));
        // The HEARTBEAT shows OFFBOARD: the arm command follows at once.
        let off = px4(PX4_OFFBOARD, false);
        assert_eq!(
            seq.on_tick(s(1.6), off, s(1.6), true),
            Ok(Some(ArmAction::Arm))
        );
        assert_eq!(seq.stage(), ArmStage::RequestingArm);
        assert_eq!(
            seq.on_tick(s(1.7), px4(PX4_OFFBOARD, true), s(1.7), true),
            Ok(None)
        );
        assert_eq!(seq.stage(), ArmStage::Armed);
    }

    #[test]
    fn ardupilot_asks_for_guided() {
        let mut seq = ArmSequence::new(0, true);
        let v = Some(VehicleMode {
            autopilot: Autopilot::ArduPilot,
            custom_mode: 0, // STABILIZE
            armed: false,
        });
        assert_eq!(
            seq.on_tick(s(2.0), v, s(2.0), true),
            Ok(Some(ArmAction::SetMode {
                custom_mode: 4,
                sub_mode: 0
            }))
        );
    }

    #[test]
    fn a_refused_mode_change_is_retried_then_named() {
        let mut seq = ArmSequence::new(9, true);
        let v = px4(PX4_POSCTL, false);
        let mut sent = 0;
        let mut t = 1.0;
        let err = loop {
            match seq.on_tick(s(t), v, s(t), true) {
                Ok(Some(_)) => sent += 1,
                Ok(None) => {}
                Err(e) => break e,
            }
            t += 0.25;
            assert!(t < 60.0, "the sequence never gave up");
        };
        assert_eq!(sent, MAX_REQUESTS);
        assert_eq!(err, ArmError::ModeRefused { agent: 9 });
        assert!(err.to_string().starts_with("agent 9:"));
    }

    #[test]
    fn unknown_autopilot_is_refused_for_arm() {
        let mut seq = ArmSequence::new(1, true);
        let v = Some(VehicleMode {
            autopilot: Autopilot::Other(8),
            custom_mode: 0,
            armed: false,
        });
        assert_eq!(
            seq.on_tick(s(2.0), v, s(2.0), true),
            Err(ArmError::UnknownAutopilot {
                agent: 1,
                autopilot: 8
            })
        );
    }

    #[test]
    fn no_heartbeat_means_no_request() {
        let mut seq = ArmSequence::new(1, true);
        assert_eq!(seq.on_tick(s(5.0), None, s(5.0), true), Ok(None));
        assert_eq!(seq.stage(), ArmStage::Streaming);
    }

    #[test]
    fn px4_main_mode_is_read_from_bits_16_to_24() {
        assert!(Autopilot::Px4.in_guided_mode(0x0006_0000));
        assert!(!Autopilot::Px4.in_guided_mode(0x0003_0000));
        assert!(!Autopilot::Px4.in_guided_mode(6));
        assert!(Autopilot::ArduPilot.in_guided_mode(4));
    }
}
