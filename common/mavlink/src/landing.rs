//! `--disarm-at-end`: after a mission that ends with a landing, each member lands its vehicle
//! with the autopilot's own landing and sees it disarmed, as a pure state machine over a
//! passed-in clock.
//!
//! The plan's landing brings every member's setpoint down to its ground spot (a vertical
//! descent, `plan.rs`). Once that phase is over (the plant says so: [`LandingSequence::order`]),
//! the member sends MAV_CMD_NAV_LAND, which PX4 and ArduCopter both answer by switching to their
//! Land mode at the vehicle's position (PX4 user guide, "Land Mode": "can be triggered using the
//! MAV_CMD_NAV_LAND MAVLink command"; the vehicle descends at MPC_LAND_SPEED, and ArduCopter at
//! LAND_SPEED), retried until a COMMAND_ACK accepts it. The vehicle is then a few centimetres
//! above its spot at most, so its own land detector finishes the touchdown; EXTENDED_SYS_STATE's
//! `landed_state` says when it is ON_GROUND. Both autopilots then disarm by themselves by
//! default (PX4 after COM_DISARM_LAND; ArduCopter's Land mode on touchdown). If the HEARTBEAT
//! still shows the vehicle armed once it is on the ground, the member sends
//! MAV_CMD_COMPONENT_ARM_DISARM with param1 = 0 and param2 = 0, never the force value 21196:
//! both autopilots refuse that disarm unless landed (ArduPilot dev guide, "Arming and
//! Disarming": "disarm the vehicle (may fail if not landed)"), so the autopilot's own land
//! check stands behind the member's. The whole landing has a deadline, [`LANDING_DEADLINE`],
//! within the team's 10 s on the ground after the landing (`plan::LANDING_SETTLE_S`), so a
//! landing that fails is a named loss of the flight, not something found after it.
//!
//! Once the landing is ordered the vehicle leaving OFFBOARD/GUIDED for its Land mode, and
//! disarming, are the flight's end, not a pilot's take-over (`takeover.rs`).

use std::time::Duration;

use mavlink::dialects::common::{MavLandedState, MavResult};

use crate::arming::{ArmAction, Retries, Retry, VehicleMode, MAX_REQUESTS};

/// How long the landing may take from its order to a disarmed vehicle: the autopilot's Land
/// mode from a few centimetres up, its land detector (PX4 needs about a second of low thrust),
/// its auto-disarm (PX4's COM_DISARM_LAND) or the member's disarm; below the plan's 10 s on the
/// ground after the landing.
pub const LANDING_DEADLINE: Duration = Duration::from_secs(8);

/// Why the landing at the end failed (names the member).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum LandingError {
    #[error("agent {agent}: landing: no COMMAND_ACK to {MAX_REQUESTS} MAV_CMD_NAV_LAND")]
    NoAck { agent: u32 },
    #[error("agent {agent}: landing refused: MAV_CMD_NAV_LAND answered {result:?}")]
    Refused { agent: u32, result: MavResult },
    #[error("agent {agent}: landing: the vehicle is on the ground but did not disarm after {MAX_REQUESTS} MAV_CMD_COMPONENT_ARM_DISARM")]
    DisarmRefused { agent: u32 },
    #[error("agent {agent}: landing: not on the ground and disarmed {deadline_s} s after MAV_CMD_NAV_LAND (landed_state {landed:?}, armed {armed})")]
    Deadline {
        agent: u32,
        deadline_s: u64,
        landed: Option<MavLandedState>,
        armed: bool,
    },
}

/// Where the landing at the end is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LandingStage {
    /// The plan's landing is not over yet.
    Flying,
    /// Sending MAV_CMD_NAV_LAND until it is acknowledged.
    Ordering,
    /// Accepted: waiting for EXTENDED_SYS_STATE to say ON_GROUND.
    Descending,
    /// On the ground and still armed: sending the disarm.
    Disarming,
    /// The HEARTBEAT shows the vehicle disarmed.
    Disarmed,
}

/// One member's landing at the end.
#[derive(Debug, Clone, PartialEq)]
pub struct LandingSequence {
    agent: u32,
    stage: LandingStage,
    ordered_at: Option<Duration>,
    retries: Retries,
}

impl LandingSequence {
    pub fn new(agent: u32) -> Self {
        LandingSequence {
            agent,
            stage: LandingStage::Flying,
            ordered_at: None,
            retries: Retries::default(),
        }
    }

    pub fn stage(&self) -> LandingStage {
        self.stage
    }

    /// Requests sent in the current stage.
    pub fn requests(&self) -> u32 {
        self.retries.sent()
    }

    /// The plan's landing is over at `now`: land (once; later calls change nothing).
    pub fn order(&mut self, now: Duration) {
        if self.stage == LandingStage::Flying {
            self.enter(LandingStage::Ordering);
            self.ordered_at = Some(now);
        }
    }

    /// The vehicle answered MAV_CMD_NAV_LAND with `result`: ACCEPTED (or IN_PROGRESS) and the
    /// descent is the autopilot's; anything else is its refusal, named.
    pub fn on_land_ack(&mut self, result: MavResult) -> Result<(), LandingError> {
        if self.stage != LandingStage::Ordering {
            return Ok(());
        }
        match result {
            MavResult::MAV_RESULT_ACCEPTED | MavResult::MAV_RESULT_IN_PROGRESS => {
                self.enter(LandingStage::Descending);
                Ok(())
            }
            result => Err(LandingError::Refused {
                agent: self.agent,
                result,
            }),
        }
    }

    /// One step at `now`: `mode` the last HEARTBEAT, `landed` the last EXTENDED_SYS_STATE's
    /// landed_state. Returns the command to send now, if any.
    pub fn on_tick(
        &mut self,
        now: Duration,
        mode: Option<VehicleMode>,
        landed: Option<MavLandedState>,
    ) -> Result<Option<ArmAction>, LandingError> {
        let (Some(mode), Some(ordered_at)) = (mode, self.ordered_at) else {
            return Ok(None);
        };
        if self.stage == LandingStage::Disarmed {
            return Ok(None);
        }
        // Disarmed by the autopilot (its auto-disarm after landing) or by the member.
        if !mode.armed {
            self.enter(LandingStage::Disarmed);
            return Ok(None);
        }
        if now.saturating_sub(ordered_at) > LANDING_DEADLINE {
            return Err(LandingError::Deadline {
                agent: self.agent,
                deadline_s: LANDING_DEADLINE.as_secs(),
                landed,
                armed: mode.armed,
            });
        }
        let agent = self.agent;
        match self.stage {
            LandingStage::Ordering => match self.retries.next(now) {
                Retry::Wait => Ok(None),
                Retry::Send => Ok(Some(ArmAction::Land)),
                Retry::Exhausted => Err(LandingError::NoAck { agent }),
            },
            LandingStage::Descending
                if landed == Some(MavLandedState::MAV_LANDED_STATE_ON_GROUND) =>
            {
                self.enter(LandingStage::Disarming);
                self.on_tick(now, Some(mode), landed)
            }
            LandingStage::Disarming => match self.retries.next(now) {
                Retry::Wait => Ok(None),
                Retry::Send => Ok(Some(ArmAction::Disarm)),
                Retry::Exhausted => Err(LandingError::DisarmRefused { agent }),
            },
            LandingStage::Flying | LandingStage::Descending | LandingStage::Disarmed => Ok(None),
        }
    }

    fn enter(&mut self, stage: LandingStage) {
        self.stage = stage;
        self.retries = Retries::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arming::Autopilot;

    const ON_GROUND: Option<MavLandedState> = Some(MavLandedState::MAV_LANDED_STATE_ON_GROUND);
    const IN_AIR: Option<MavLandedState> = Some(MavLandedState::MAV_LANDED_STATE_IN_AIR);

    fn s(v: f64) -> Duration {
        Duration::from_secs_f64(v)
    }

    fn px4(armed: bool) -> Option<VehicleMode> {
        Some(VehicleMode {
            autopilot: Autopilot::Px4,
            custom_mode: 6 << 16,
            armed,
        })
    }

    #[test]
    fn nothing_before_the_order_then_land_acked_on_ground_disarmed() {
        let mut l = LandingSequence::new(3);
        assert_eq!(l.on_tick(s(1.0), px4(true), ON_GROUND), Ok(None));
        assert_eq!(l.stage(), LandingStage::Flying);
        l.order(s(2.0));
        assert_eq!(
            l.on_tick(s(2.0), px4(true), IN_AIR),
            Ok(Some(ArmAction::Land))
        );
        assert_eq!(l.on_tick(s(2.5), px4(true), IN_AIR), Ok(None));
        assert_eq!(
            l.on_tick(s(3.0), px4(true), IN_AIR),
            Ok(Some(ArmAction::Land))
        );
        assert_eq!(l.on_land_ack(MavResult::MAV_RESULT_ACCEPTED), Ok(()));
        assert_eq!(l.stage(), LandingStage::Descending);
        // In the air: no disarm (it would be refused anyway).
        assert_eq!(l.on_tick(s(3.5), px4(true), IN_AIR), Ok(None));
        // On the ground and still armed: the disarm, resent until the HEARTBEAT shows it.
        assert_eq!(
            l.on_tick(s(4.0), px4(true), ON_GROUND),
            Ok(Some(ArmAction::Disarm))
        );
        assert_eq!(l.on_tick(s(4.5), px4(true), ON_GROUND), Ok(None));
        assert_eq!(
            l.on_tick(s(5.0), px4(true), ON_GROUND),
            Ok(Some(ArmAction::Disarm))
        );
        assert_eq!(l.on_tick(s(5.2), px4(false), ON_GROUND), Ok(None));
        assert_eq!(l.stage(), LandingStage::Disarmed);
        // Done for good: later ticks send nothing, past the deadline too.
        assert_eq!(l.on_tick(s(30.0), px4(false), ON_GROUND), Ok(None));
    }

    #[test]
    fn an_autopilot_that_disarms_itself_needs_no_disarm() {
        let mut l = LandingSequence::new(3);
        l.order(s(0.0));
        assert_eq!(
            l.on_tick(s(0.0), px4(true), IN_AIR),
            Ok(Some(ArmAction::Land))
        );
        assert_eq!(l.on_land_ack(MavResult::MAV_RESULT_ACCEPTED), Ok(()));
        assert_eq!(l.on_tick(s(1.0), px4(false), ON_GROUND), Ok(None));
        assert_eq!(l.stage(), LandingStage::Disarmed);
    }

    #[test]
    fn refusals_silence_and_the_deadline_are_named() {
        let mut l = LandingSequence::new(7);
        l.order(s(0.0));
        let _ = l.on_tick(s(0.0), px4(true), IN_AIR);
        let e = l.on_land_ack(MavResult::MAV_RESULT_DENIED).unwrap_err();
        assert!(e.to_string().starts_with("agent 7: landing refused"), "{e}");
        // No ACK at all.
        let mut l = LandingSequence::new(7);
        l.order(s(0.0));
        let mut t = 0.0;
        let e = loop {
            if let Err(e) = l.on_tick(s(t), px4(true), IN_AIR) {
                break e;
            }
            t += 0.25;
        };
        assert_eq!(e, LandingError::NoAck { agent: 7 });
        // Accepted but never on the ground: the deadline names what the vehicle said.
        let mut l = LandingSequence::new(7);
        l.order(s(0.0));
        let _ = l.on_tick(s(0.0), px4(true), IN_AIR);
        assert!(l.on_land_ack(MavResult::MAV_RESULT_ACCEPTED).is_ok());
        assert_eq!(l.on_tick(s(8.0), px4(true), IN_AIR), Ok(None));
        let e = l.on_tick(s(8.1), px4(true), IN_AIR).unwrap_err();
        assert!(
            e.to_string()
                .contains("landed_state Some(MAV_LANDED_STATE_IN_AIR), armed true"),
            "{e}"
        );
        // On the ground, every disarm refused.
        let mut l = LandingSequence::new(7);
        l.order(s(0.0));
        let _ = l.on_tick(s(0.0), px4(true), IN_AIR);
        assert!(l.on_land_ack(MavResult::MAV_RESULT_ACCEPTED).is_ok());
        let mut t = 0.5;
        let e = loop {
            if let Err(e) = l.on_tick(s(t), px4(true), ON_GROUND) {
                break e;
            }
            t += 0.25;
        };
        assert_eq!(e, LandingError::DisarmRefused { agent: 7 });
        assert_eq!(l.requests(), MAX_REQUESTS);
    }
}
