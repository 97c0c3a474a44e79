//! The two ends of a mission flown on a vehicle, as one member's pure logic: ArduCopter's
//! take-off once armed (`takeoff.rs`) and, with `--disarm-at-end`, the landing and disarm at
//! the end (`landing.rs`). [`crate::vehicle::MavlinkVehicle`] feeds it the vehicle's
//! COMMAND_ACKs, EXTENDED_SYS_STATE and HEARTBEATs and sends the commands it returns.

use std::time::Duration;

use mavlink::dialects::common::{MavCmd, MavLandedState, MavResult};

use crate::arming::{ArmAction, Autopilot, VehicleMode};
use crate::landing::{LandingError, LandingSequence, LandingStage};
use crate::messages::Setpoint;
use crate::takeoff::{Takeoff, TakeoffError, TakeoffSequence, TakeoffStage};
use cdm_math::Real;

/// Why a take-off or a landing failed (each names the member).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum EndsError {
    #[error(transparent)]
    Takeoff(#[from] TakeoffError),
    #[error(transparent)]
    Landing(#[from] LandingError),
}

/// One member's take-off and landing.
#[derive(Debug, Clone, PartialEq)]
pub struct FlightEnds {
    takeoff: Option<(Takeoff, TakeoffSequence)>,
    /// The take-off floor has been released (`Takeoff::floor`).
    floor_released: bool,
    landing: Option<LandingSequence>,
    /// The vehicle's last EXTENDED_SYS_STATE landed_state, if it sends one.
    landed: Option<MavLandedState>,
}

impl FlightEnds {
    /// Member `agent`'s: a take-off when its mission starts with one (`--arm`), a landing with
    /// `--disarm-at-end`.
    pub fn new(agent: u32, takeoff: Option<Takeoff>, disarm_at_end: bool) -> Self {
        FlightEnds {
            takeoff: takeoff.map(|t| (t, TakeoffSequence::new(agent, t))),
            floor_released: false,
            landing: disarm_at_end.then(|| LandingSequence::new(agent)),
            landed: None,
        }
    }

    /// A COMMAND_ACK from the vehicle at `now`.
    pub fn on_ack(
        &mut self,
        now: Duration,
        command: MavCmd,
        result: MavResult,
    ) -> Result<(), EndsError> {
        match command {
            MavCmd::MAV_CMD_NAV_TAKEOFF => {
                if let Some((_, seq)) = &mut self.takeoff {
                    seq.on_ack(now, result)?;
                }
            }
            MavCmd::MAV_CMD_NAV_LAND => {
                if let Some(l) = &mut self.landing {
                    l.on_land_ack(result)?;
                }
            }
            // Arming and disarming are confirmed by the HEARTBEAT, not the ACK.
            _ => {}
        }
        Ok(())
    }

    /// An EXTENDED_SYS_STATE's landed_state.
    pub fn on_landed_state(&mut self, landed: MavLandedState) {
        self.landed = Some(landed);
    }

    /// The setpoint to send: held at the take-off altitude while an ArduPilot vehicle takes off
    /// and the plan is below it (`Takeoff::floor`), otherwise `sp`.
    pub fn floored(&mut self, sp: &Setpoint, mode: Option<&VehicleMode>) -> Setpoint {
        match &self.takeoff {
            Some((t, _)) if is_ardupilot(mode) => t.floor(sp, &mut self.floor_released),
            _ => *sp,
        }
    }

    /// One tick once the vehicle is armed (`--arm`): the command to send now, if any, with how
    /// many times it was sent (its COMMAND_LONG confirmation).
    pub fn on_tick(
        &mut self,
        now: Duration,
        mode: Option<VehicleMode>,
        height_z_m: Option<Real>,
    ) -> Result<Option<(ArmAction, u32)>, EndsError> {
        if let Some((_, seq)) = &mut self.takeoff {
            if let Some(a) = seq.on_tick(now, mode, height_z_m)? {
                return Ok(Some((a, seq.requests())));
            }
        }
        let Some(l) = &mut self.landing else {
            return Ok(None);
        };
        let action = l.on_tick(now, mode, self.landed)?;
        Ok(action.map(|a| (a, l.requests())))
    }

    /// The plan's landing is over at `now`: with `--disarm-at-end`, land and disarm. Returns
    /// whether a landing was ordered (the vehicle leaving its guided mode and disarming are the
    /// flight's end from then on).
    pub fn order_landing(&mut self, now: Duration) -> bool {
        match &mut self.landing {
            Some(l) => {
                l.order(now);
                true
            }
            None => false,
        }
    }

    /// Whether the team may fly: for an ArduPilot vehicle whose mission takes off, once it is
    /// at its take-off altitude.
    pub fn airborne(&self, mode: Option<&VehicleMode>) -> bool {
        match &self.takeoff {
            Some((_, seq)) if is_ardupilot(mode) => seq.stage() == TakeoffStage::Airborne,
            _ => true,
        }
    }

    /// Whether the landing at the end is done or never started: false only while a landing
    /// ordered (`--disarm-at-end`, the plan over) has not yet seen the vehicle disarmed.
    pub fn landed_or_not_landing(&self) -> bool {
        self.landing
            .as_ref()
            .is_none_or(|l| matches!(l.stage(), LandingStage::Flying | LandingStage::Disarmed))
    }
}

fn is_ardupilot(mode: Option<&VehicleMode>) -> bool {
    mode.is_some_and(|m| m.autopilot == Autopilot::ArduPilot)
}
