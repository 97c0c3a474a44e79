//! A pilot taking over is a loss, not a crash, as pure logic over the
//! vehicle's HEARTBEATs.
//!
//! Once the member has seen its vehicle in the mode that flies its setpoints (PX4 OFFBOARD,
//! ArduCopter GUIDED: `flight_mode.rs`) and armed, a HEARTBEAT in any other mode, or disarmed,
//! means someone else has the vehicle: an RC override (PX4 `COM_RC_OVERRIDE` switches "from
//! offboard mode (or any mode) to Position mode if the RC sticks are moved", PX4 user guide,
//! "Offboard Control"), the pilot's mode switch, a ground station's mode change, or an
//! autopilot failsafe (PX4 leaves OFFBOARD for `COM_OBL_RC_ACT` when setpoints stop for
//! `COM_OF_LOSS_T`; ArduPilot's failsafes switch to RTL or LAND). The vehicle then ignores the
//! member's setpoints (PX4 uses offboard setpoints only in OFFBOARD; ArduCopter uses
//! SET_POSITION_TARGET_LOCAL_NED only in GUIDED), so the member's state would no longer be
//! what the formation law flies: the member is lost, naming the mode it saw, and stops sending
//! setpoints (the pilot has the vehicle; the link's streaming thread ends with the fault).
//! Disarmed in flight counts the same.
//!
//! Before the vehicle is first seen engaged (guided and armed) nothing is judged: the member
//! streams a hold while the operator (or `--arm`) switches mode and arms, and a vehicle that is
//! never engaged (a stream-only team whose operator flies another way) is never called lost
//! for its mode. The verdict is sticky: a vehicle switched back to OFFBOARD stays lost, since
//! the team has already repaired around it or stopped.

use crate::arming::VehicleMode;
use crate::flight_mode::FlightMode;
use crate::health::LinkFault;

/// One member's watch over its vehicle's mode and armed state.
#[derive(Debug, Clone, PartialEq)]
pub struct TakeoverWatch {
    agent: u32,
    /// The guided mode the vehicle was seen armed in (from then on it is judged).
    engaged: Option<FlightMode>,
    /// The first verdict (sticky).
    lost: Option<LinkFault>,
    /// The member disarms its landed vehicle (`--disarm-at-end`): nothing is judged any more.
    ended: bool,
}

impl TakeoverWatch {
    /// Member `agent`'s watch, not yet engaged.
    pub fn new(agent: u32) -> Self {
        TakeoverWatch {
            agent,
            engaged: None,
            lost: None,
            ended: false,
        }
    }

    /// The vehicle's HEARTBEAT said `mode`.
    pub fn on_heartbeat(&mut self, mode: VehicleMode) {
        if self.lost.is_some() || self.ended {
            return;
        }
        let now = FlightMode {
            autopilot: mode.autopilot,
            custom_mode: mode.custom_mode,
        };
        let agent = self.agent;
        match self.engaged {
            None if now.is_guided() && mode.armed => self.engaged = Some(now),
            None => {}
            Some(_) if !mode.armed => self.lost = Some(LinkFault::Disarmed { agent, mode: now }),
            Some(was) if !now.is_guided() => {
                self.lost = Some(LinkFault::LeftMode {
                    agent,
                    left: FlightMode::guided_name(was.autopilot),
                    now,
                });
            }
            Some(_) => {}
        }
    }

    /// The member is about to disarm its landed vehicle (`--disarm-at-end`): that disarm, and
    /// PX4 leaving OFFBOARD once disarmed, are the end of the flight, not a loss. A verdict
    /// already reached stays.
    pub fn end(&mut self) {
        self.ended = true;
    }

    /// Whether the vehicle has been seen guided and armed (from then on it is judged).
    pub fn engaged(&self) -> bool {
        self.engaged.is_some()
    }

    /// `Err` once the vehicle left the guided mode or disarmed after it was engaged.
    pub fn check(&self) -> Result<(), LinkFault> {
        self.lost.map_or(Ok(()), Err)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arming::Autopilot;

    const OFFBOARD: u32 = 6 << 16;
    const POSCTL: u32 = 3 << 16;
    const AUTO_RTL: u32 = (4 << 16) | (5 << 24);

    fn px4(custom_mode: u32, armed: bool) -> VehicleMode {
        VehicleMode {
            autopilot: Autopilot::Px4,
            custom_mode,
            armed,
        }
    }

    fn copter(custom_mode: u32, armed: bool) -> VehicleMode {
        VehicleMode {
            autopilot: Autopilot::ArduPilot,
            custom_mode,
            armed,
        }
    }

    #[test]
    fn nothing_is_judged_before_the_vehicle_is_guided_and_armed() {
        let mut w = TakeoverWatch::new(7);
        // Streaming a hold before the start: POSCTL, disarmed; then OFFBOARD but not armed yet
        // (--arm's order), then disarmed in POSCTL again (an operator's retry).
        for m in [
            px4(POSCTL, false),
            px4(OFFBOARD, false),
            px4(POSCTL, false),
            px4(POSCTL, true),
        ] {
            w.on_heartbeat(m);
            assert_eq!(w.check(), Ok(()), "{m:?}");
        }
        assert!(!w.engaged());
        w.on_heartbeat(px4(OFFBOARD, true));
        assert!(w.engaged());
        for _ in 0..100 {
            w.on_heartbeat(px4(OFFBOARD, true));
        }
        assert_eq!(w.check(), Ok(()));
    }

    #[test]
    fn leaving_offboard_after_the_start_is_a_loss_naming_the_new_mode() {
        let mut w = TakeoverWatch::new(7);
        w.on_heartbeat(px4(OFFBOARD, true));
        w.on_heartbeat(px4(POSCTL, true));
        let fault = w.check().unwrap_err();
        assert_eq!(
            fault,
            LinkFault::LeftMode {
                agent: 7,
                left: "OFFBOARD",
                now: FlightMode {
                    autopilot: Autopilot::Px4,
                    custom_mode: POSCTL
                }
            }
        );
        let text = fault.to_string();
        assert!(
            text.starts_with("agent 7: vehicle lost: it left OFFBOARD: now POSCTL"),
            "{text}"
        );
        // Sticky: back in OFFBOARD it stays lost, naming the mode it first left for.
        w.on_heartbeat(px4(OFFBOARD, true));
        w.on_heartbeat(px4(AUTO_RTL, true));
        assert_eq!(w.check(), Err(fault));
    }

    #[test]
    fn an_autopilot_failsafe_names_its_mode() {
        let mut w = TakeoverWatch::new(3);
        w.on_heartbeat(px4(OFFBOARD, true));
        w.on_heartbeat(px4(AUTO_RTL, true));
        let text = w.check().unwrap_err().to_string();
        assert!(text.contains("it left OFFBOARD: now AUTO.RTL"), "{text}");
    }

    #[test]
    fn disarmed_in_flight_is_a_loss() {
        let mut w = TakeoverWatch::new(5);
        w.on_heartbeat(px4(OFFBOARD, true));
        w.on_heartbeat(px4(OFFBOARD, false));
        let fault = w.check().unwrap_err();
        assert!(matches!(fault, LinkFault::Disarmed { agent: 5, .. }));
        let text = fault.to_string();
        assert!(
            text.starts_with("agent 5: vehicle lost: disarmed in flight (in OFFBOARD)"),
            "{text}"
        );
    }

    #[test]
    fn arducopter_leaving_guided_names_its_mode() {
        let mut w = TakeoverWatch::new(2);
        w.on_heartbeat(copter(4, true));
        w.on_heartbeat(copter(4, true));
        assert_eq!(w.check(), Ok(()));
        w.on_heartbeat(copter(5, true));
        let text = w.check().unwrap_err().to_string();
        assert!(
            text.starts_with("agent 2: vehicle lost: it left GUIDED: now LOITER"),
            "{text}"
        );
    }
}
