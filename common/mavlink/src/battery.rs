//! The vehicle's battery and its own failsafe, as pure logic.
//!
//! - SYS_STATUS carries `battery_remaining` (%, -1 when the autopilot does not know) and
//!   `voltage_battery` (mV, `u16::MAX` when unknown); PX4 streams it at 5 Hz on an onboard link
//!   (`mavlink_main.cpp`, onboard mode), ArduPilot in its extended-status stream. The lowest of
//!   each is recorded for audit.json; with `--min-battery PCT` a vehicle below PCT is lost,
//!   after one warning at PCT + [`WARN_MARGIN_PCT`].
//! - HEARTBEAT's `system_status` is the autopilot's own verdict: MAV_STATE_CRITICAL ("a
//!   non-normal flight mode (failsafe)"), MAV_STATE_EMERGENCY ("lost control ... mayday") and
//!   MAV_STATE_FLIGHT_TERMINATION mean the vehicle no longer flies the member's setpoints as
//!   asked, so it is lost, naming the state.

use mavlink::dialects::common::MavState;

use crate::health::LinkFault;

/// The warning comes this many percent above `--min-battery`.
pub const WARN_MARGIN_PCT: u8 = 10;

/// What the audit records of a vehicle's battery.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BatteryFigures {
    /// The lowest `battery_remaining` reported (%), if the autopilot reported one.
    pub lowest_pct: Option<u8>,
    /// The lowest `voltage_battery` reported (V), if any.
    pub lowest_voltage_v: Option<f64>,
}

/// One vehicle's battery and failsafe state.
#[derive(Debug, Clone, PartialEq)]
pub struct BatteryWatch {
    agent: u32,
    min_pct: Option<u8>,
    figures: BatteryFigures,
    last_pct: Option<u8>,
    warned: bool,
    warning: Option<String>,
    failsafe: Option<&'static str>,
}

impl BatteryWatch {
    /// Member `agent`'s watch; `min_pct` is `--min-battery`.
    pub fn new(agent: u32, min_pct: Option<u8>) -> Self {
        BatteryWatch {
            agent,
            min_pct,
            figures: BatteryFigures::default(),
            last_pct: None,
            warned: false,
            warning: None,
            failsafe: None,
        }
    }

    /// A SYS_STATUS: `remaining` (%, negative: unknown) and `voltage_mv` (`u16::MAX`: unknown).
    pub fn on_sys_status(&mut self, remaining: i8, voltage_mv: u16) {
        if voltage_mv != u16::MAX {
            let v = f64::from(voltage_mv) / 1e3;
            let low = self.figures.lowest_voltage_v.get_or_insert(v);
            *low = low.min(v);
        }
        let Ok(pct) = u8::try_from(remaining) else {
            return;
        };
        let pct = pct.min(100);
        self.last_pct = Some(pct);
        let low = self.figures.lowest_pct.get_or_insert(pct);
        *low = (*low).min(pct);
        if let Some(min) = self.min_pct {
            if !self.warned && pct <= min.saturating_add(WARN_MARGIN_PCT) && pct >= min {
                self.warned = true;
                self.warning = Some(format!(
                    "agent {}: battery at {pct} %: the vehicle is lost below --min-battery {min} %",
                    self.agent
                ));
            }
        }
    }

    /// A HEARTBEAT's `system_status`.
    pub fn on_system_status(&mut self, state: MavState) {
        let name = match state {
            MavState::MAV_STATE_CRITICAL => "MAV_STATE_CRITICAL (a failsafe)",
            MavState::MAV_STATE_EMERGENCY => "MAV_STATE_EMERGENCY",
            MavState::MAV_STATE_FLIGHT_TERMINATION => "MAV_STATE_FLIGHT_TERMINATION",
            _ => return,
        };
        self.failsafe.get_or_insert(name);
    }

    /// The warning not yet taken, if any (the caller logs it once).
    pub fn take_warning(&mut self) -> Option<String> {
        self.warning.take()
    }

    /// `Err` once the autopilot reported a failsafe, or the battery fell below `--min-battery`.
    pub fn check(&self) -> Result<(), LinkFault> {
        let agent = self.agent;
        if let Some(state) = self.failsafe {
            return Err(LinkFault::Failsafe { agent, state });
        }
        match (self.last_pct, self.min_pct) {
            (Some(pct), Some(min)) if pct < min => Err(LinkFault::BatteryLow { agent, pct, min }),
            _ => Ok(()),
        }
    }

    /// The lowest figures so far.
    pub fn figures(&self) -> BatteryFigures {
        self.figures
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_draining_battery_warns_once_then_loses_the_vehicle_naming_the_limit() {
        let mut b = BatteryWatch::new(7, Some(20));
        b.on_sys_status(40, 16_000);
        assert_eq!(b.take_warning(), None);
        assert!(b.check().is_ok());
        b.on_sys_status(30, 15_500);
        let w = b.take_warning().expect("a warning at 30 %");
        assert!(w.starts_with("agent 7: battery at 30 %"), "{w}");
        b.on_sys_status(25, 15_000);
        assert_eq!(b.take_warning(), None, "warned once");
        b.on_sys_status(20, 14_800);
        assert!(b.check().is_ok(), "at the limit is not below it");
        b.on_sys_status(19, 14_700);
        let e = b.check().unwrap_err().to_string();
        assert_eq!(
            e,
            "agent 7: vehicle lost: battery at 19 % (below --min-battery 20 %)"
        );
        // Unknown values are not figures.
        b.on_sys_status(-1, u16::MAX);
        assert_eq!(b.figures().lowest_pct, Some(19));
        assert_eq!(b.figures().lowest_voltage_v, Some(14.7));
    }

    #[test]
    fn without_a_minimum_a_low_battery_is_recorded_only_and_a_failsafe_is_a_loss() {
        let mut b = BatteryWatch::new(3, None);
        b.on_sys_status(5, 13_000);
        assert!(b.check().is_ok());
        assert_eq!(b.take_warning(), None);
        b.on_system_status(MavState::MAV_STATE_ACTIVE);
        assert!(b.check().is_ok());
        b.on_system_status(MavState::MAV_STATE_CRITICAL);
        b.on_system_status(MavState::MAV_STATE_EMERGENCY);
        assert_eq!(
            b.check().unwrap_err().to_string(),
            "agent 3: vehicle lost: its autopilot reports MAV_STATE_CRITICAL (a failsafe)"
        );
    }
}
