//! ArduCopter's take-off before the team flies, as a pure state machine over a passed-in clock.
//!
//! PX4 climbs under OFFBOARD setpoints from the ground (PX4's ROS 2 offboard example: stream
//! setpoints, switch to Offboard, arm, and the vehicle ascends to the setpoint): a mission's
//! take-off phase is flown as it is, and nothing here applies to a PX4. ArduCopter in GUIDED
//! does not fly position targets while it is landed until a take-off has started: it runs its
//! ground handling until `auto_armed`, which `Mode::do_user_takeoff` (ArduCopter takeoff.cpp,
//! MAV_CMD_NAV_TAKEOFF) sets; that command is refused unless the vehicle is armed, landed, in a
//! mode with a user take-off and asked to climb ("can't takeoff downwards"), and ArduCopter
//! answers it with a COMMAND_ACK (ACCEPTED, or FAILED). So when the mission starts with a
//! take-off, a member whose vehicle is an ArduPilot, once armed in GUIDED (`arming.rs`), sends
//! MAV_CMD_NAV_TAKEOFF with param7 = [`Takeoff::altitude_m`] (metres above home, where it
//! armed: the member's ground spot; ArduPilot dev guide, "Copter Commands in Guided Mode"),
//! retried until a COMMAND_ACK comes, waits for the climb (a deadline), and answers the team's
//! arm order only once its vehicle reports that height. Until the plan's own take-off passes
//! that height the member's setpoints are held at it ([`Takeoff::floor`]): the take-off phase
//! rises vertically above each ground spot, so the floor moves no member sideways, and it is
//! at most half the tracking bound delta above the plan, so the audit's tracking check (eq. 34)
//! keeps the other half for the vehicle's own error.

use std::time::Duration;

use mavlink::dialects::common::MavResult;

use cdm_math::{Real, Vec3};

use crate::arming::{ArmAction, Autopilot, Retries, Retry, VehicleMode, MAX_REQUESTS};
use crate::messages::Setpoint;

/// The highest take-off altitude above the ground (m): the plan's own take-off does the rest.
pub const TAKEOFF_ALT_MAX_M: Real = 1.0;
/// The vehicle is airborne once within this fraction of the take-off altitude below it.
pub const CLIMB_TOLERANCE: Real = 0.1;
/// The climb's deadline, from the ACK (ArduCopter climbs at its WPNAV_SPEED_UP, 2.5 m/s by
/// default: a metre takes under a second; the rest is room for a slow vehicle).
pub const CLIMB_DEADLINE: Duration = Duration::from_secs(10);

/// A member's take-off: the ground's height (scenario z, where the member starts) and the
/// altitude above it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Takeoff {
    pub ground_z_m: Real,
    pub altitude_m: Real,
}

impl Takeoff {
    /// The take-off of a member starting on the ground at `start` whose take-off phase ends at
    /// `top`, in a team whose tracking bound is `delta_m`: the lowest of [`TAKEOFF_ALT_MAX_M`],
    /// half of delta, and the phase's own climb.
    pub fn new(start: Vec3, top: Vec3, delta_m: Real) -> Self {
        Takeoff {
            ground_z_m: start.z,
            altitude_m: TAKEOFF_ALT_MAX_M.min(0.5 * delta_m).min(top.z - start.z),
        }
    }

    /// The setpoint with its height held at the take-off altitude (at rest vertically) while
    /// the plan is below it. `released` latches once the plan reaches the altitude: the floor
    /// then never applies again (the landing goes down to the ground).
    pub fn floor(&self, sp: &Setpoint, released: &mut bool) -> Setpoint {
        let top = self.ground_z_m + self.altitude_m;
        if *released || sp.position.z >= top {
            *released = true;
            return *sp;
        }
        let mut held = *sp;
        held.position.z = top;
        held.velocity.z = 0.0;
        held.acceleration.z = 0.0;
        held.jerk.z = 0.0;
        held
    }
}

/// Why the take-off failed (each names the member).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum TakeoffError {
    #[error("agent {agent}: take-off: no COMMAND_ACK to {MAX_REQUESTS} MAV_CMD_NAV_TAKEOFF (to {altitude_m:.2} m)")]
    NoAck { agent: u32, altitude_m: Real },
    #[error("agent {agent}: take-off refused: MAV_CMD_NAV_TAKEOFF (to {altitude_m:.2} m) answered {result:?}")]
    Refused {
        agent: u32,
        altitude_m: Real,
        result: MavResult,
    },
    #[error("agent {agent}: take-off: the vehicle did not reach {altitude_m:.2} m within {deadline_s} s of its ACK (at {height_m:.2} m)")]
    NoClimb {
        agent: u32,
        altitude_m: Real,
        deadline_s: u64,
        height_m: Real,
    },
}

/// Where the take-off is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TakeoffStage {
    /// Not armed in GUIDED yet (or not an ArduPilot: never leaves this stage).
    Waiting,
    /// Sending MAV_CMD_NAV_TAKEOFF until it is acknowledged.
    Requesting,
    /// Accepted: climbing to the altitude (since the ACK, on the caller's clock).
    Climbing { since: Duration },
    /// At the altitude: the team may fly.
    Airborne,
}

/// One member's take-off.
#[derive(Debug, Clone, PartialEq)]
pub struct TakeoffSequence {
    agent: u32,
    takeoff: Takeoff,
    stage: TakeoffStage,
    retries: Retries,
}

impl TakeoffSequence {
    pub fn new(agent: u32, takeoff: Takeoff) -> Self {
        TakeoffSequence {
            agent,
            takeoff,
            stage: TakeoffStage::Waiting,
            retries: Retries::default(),
        }
    }

    pub fn stage(&self) -> TakeoffStage {
        self.stage
    }

    /// Requests sent so far (the last action returned was number `requests()`).
    pub fn requests(&self) -> u32 {
        self.retries.sent()
    }

    /// The vehicle answered MAV_CMD_NAV_TAKEOFF at `now` with `result`. ACCEPTED (or
    /// IN_PROGRESS) starts the climb; anything else is the vehicle's refusal, named.
    pub fn on_ack(&mut self, now: Duration, result: MavResult) -> Result<(), TakeoffError> {
        if self.stage != TakeoffStage::Requesting {
            return Ok(()); // a late duplicate of an answered request
        }
        match result {
            MavResult::MAV_RESULT_ACCEPTED | MavResult::MAV_RESULT_IN_PROGRESS => {
                self.stage = TakeoffStage::Climbing { since: now };
                Ok(())
            }
            result => Err(TakeoffError::Refused {
                agent: self.agent,
                altitude_m: self.takeoff.altitude_m,
                result,
            }),
        }
    }

    /// One step at `now`: `mode` the last HEARTBEAT, `height_z_m` the measured height
    /// (scenario z). Returns the command to send now, if any.
    pub fn on_tick(
        &mut self,
        now: Duration,
        mode: Option<VehicleMode>,
        height_z_m: Option<Real>,
    ) -> Result<Option<ArmAction>, TakeoffError> {
        let (Some(mode), Some(z)) = (mode, height_z_m) else {
            return Ok(None);
        };
        let above_m = z - self.takeoff.ground_z_m;
        let altitude_m = self.takeoff.altitude_m;
        match self.stage {
            TakeoffStage::Airborne => Ok(None),
            TakeoffStage::Waiting => {
                let guided = mode.autopilot == Autopilot::ArduPilot
                    && mode.autopilot.in_guided_mode(mode.custom_mode);
                if guided && mode.armed {
                    self.stage = TakeoffStage::Requesting;
                    return self.request(now);
                }
                Ok(None)
            }
            TakeoffStage::Requesting => self.request(now),
            TakeoffStage::Climbing { .. } if above_m >= altitude_m * (1.0 - CLIMB_TOLERANCE) => {
                self.stage = TakeoffStage::Airborne;
                Ok(None)
            }
            TakeoffStage::Climbing { since } if now.saturating_sub(since) > CLIMB_DEADLINE => {
                Err(TakeoffError::NoClimb {
                    agent: self.agent,
                    altitude_m,
                    deadline_s: CLIMB_DEADLINE.as_secs(),
                    height_m: above_m,
                })
            }
            TakeoffStage::Climbing { .. } => Ok(None),
        }
    }

    /// The command, again while unanswered (`arming::Retries`), until [`MAX_REQUESTS`] fail.
    fn request(&mut self, now: Duration) -> Result<Option<ArmAction>, TakeoffError> {
        match self.retries.next(now) {
            Retry::Wait => Ok(None),
            // COMMAND_LONG params are f32: a take-off altitude of a metre or so is exact enough.
            Retry::Send => Ok(Some(ArmAction::Takeoff {
                altitude_m: self.takeoff.altitude_m as f32,
            })),
            Retry::Exhausted => Err(TakeoffError::NoAck {
                agent: self.agent,
                altitude_m: self.takeoff.altitude_m,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GUIDED: u32 = crate::arming::ARDUCOPTER_MODE_GUIDED;

    fn s(v: f64) -> Duration {
        Duration::from_secs_f64(v)
    }

    fn ardu(armed: bool) -> Option<VehicleMode> {
        Some(VehicleMode {
            autopilot: Autopilot::ArduPilot,
            custom_mode: GUIDED,
            armed,
        })
    }

    fn takeoff() -> Takeoff {
        Takeoff::new(Vec3::new(0.0, 0.0, 10.0), Vec3::new(0.0, 0.0, 15.0), 4.0)
    }

    #[test]
    fn the_altitude_is_a_metre_at_most_half_delta_and_the_phase_top_when_lower() {
        assert_eq!(takeoff().altitude_m, 1.0);
        let start = Vec3::new(0.0, 0.0, 10.0);
        let low = Takeoff::new(start, Vec3::new(0.0, 0.0, 10.5), 4.0);
        assert_eq!(low.altitude_m, 0.5);
        let tight = Takeoff::new(start, Vec3::new(0.0, 0.0, 15.0), 0.6);
        assert_eq!(tight.altitude_m, 0.3);
    }

    #[test]
    fn takeoff_is_sent_once_armed_in_guided_acked_and_the_climb_awaited() {
        let mut seq = TakeoffSequence::new(4, takeoff());
        assert_eq!(seq.on_tick(s(1.0), ardu(false), Some(10.0)), Ok(None));
        assert_eq!(seq.stage(), TakeoffStage::Waiting);
        let cmd = Some(ArmAction::Takeoff { altitude_m: 1.0 });
        assert_eq!(seq.on_tick(s(2.0), ardu(true), Some(10.0)), Ok(cmd));
        // Not again within the retry interval; resent after it while unanswered.
        assert_eq!(seq.on_tick(s(2.5), ardu(true), Some(10.0)), Ok(None));
        assert_eq!(seq.on_tick(s(3.0), ardu(true), Some(10.0)), Ok(cmd));
        assert_eq!(seq.on_ack(s(3.1), MavResult::MAV_RESULT_ACCEPTED), Ok(()));
        assert_eq!(seq.stage(), TakeoffStage::Climbing { since: s(3.1) });
        // No more commands while climbing; airborne within 10 % below the altitude.
        assert_eq!(seq.on_tick(s(4.0), ardu(true), Some(10.5)), Ok(None));
        assert_eq!(seq.stage(), TakeoffStage::Climbing { since: s(3.1) });
        assert_eq!(seq.on_tick(s(4.1), ardu(true), Some(10.95)), Ok(None));
        assert_eq!(seq.stage(), TakeoffStage::Airborne);
        assert_eq!(seq.requests(), 2);
    }

    #[test]
    fn px4_never_gets_a_takeoff_command() {
        let mut seq = TakeoffSequence::new(4, takeoff());
        let px4 = Some(VehicleMode {
            autopilot: Autopilot::Px4,
            custom_mode: 6 << 16,
            armed: true,
        });
        assert_eq!(seq.on_tick(s(2.0), px4, Some(10.0)), Ok(None));
        assert_eq!(seq.stage(), TakeoffStage::Waiting);
    }

    #[test]
    fn no_ack_a_refusal_and_a_stalled_climb_are_named() {
        // Never answered: MAX_REQUESTS commands, a second apart, then the error.
        let mut seq = TakeoffSequence::new(4, takeoff());
        let mut t = 2.0;
        let err = loop {
            if let Err(e) = seq.on_tick(s(t), ardu(true), Some(10.0)) {
                break e;
            }
            t += 0.25;
            assert!(t < 60.0, "never gave up");
        };
        assert_eq!(seq.requests(), MAX_REQUESTS);
        assert!(matches!(err, TakeoffError::NoAck { agent: 4, .. }), "{err}");
        assert!(err
            .to_string()
            .starts_with("agent 4: take-off: no COMMAND_ACK"));
        // Refused (ArduCopter's FAILED when it is not landed, or asked to climb downwards).
        let mut seq = TakeoffSequence::new(4, takeoff());
        assert!(seq.on_tick(s(2.0), ardu(true), Some(10.0)).is_ok());
        let err = seq
            .on_ack(s(2.1), MavResult::MAV_RESULT_FAILED)
            .unwrap_err();
        assert!(
            err.to_string().contains("answered MAV_RESULT_FAILED"),
            "{err}"
        );
        // Accepted, but the climb stalls below the altitude past the deadline.
        let mut seq = TakeoffSequence::new(4, takeoff());
        assert!(seq.on_tick(s(2.0), ardu(true), Some(10.0)).is_ok());
        assert!(seq.on_ack(s(2.2), MavResult::MAV_RESULT_ACCEPTED).is_ok());
        assert!(seq.on_tick(s(12.2), ardu(true), Some(10.3)).is_ok());
        let err = seq.on_tick(s(12.3), ardu(true), Some(10.3)).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("agent 4: take-off: the vehicle did not reach 1.00 m within 10 s"),
            "{err}"
        );
    }

    #[test]
    fn the_floor_holds_until_the_plan_reaches_the_altitude_then_never_again() {
        let t = takeoff();
        let mut released = false;
        let mut sp = crate::setpoint::hold_at(Vec3::new(1.0, 2.0, 10.0));
        sp.velocity.z = 0.3;
        let held = t.floor(&sp, &mut released);
        assert_eq!(held.position, Vec3::new(1.0, 2.0, 11.0));
        assert_eq!(held.velocity.z, 0.0);
        sp.position.z = 11.2;
        assert_eq!(t.floor(&sp, &mut released), sp);
        sp.position.z = 10.0; // the landing
        assert_eq!(t.floor(&sp, &mut released), sp);
    }
}
