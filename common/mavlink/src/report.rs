//! What the orchestrator records of a MAVLink member's vehicle (what the team measures
//! on the vehicles appears in audit.json): the stream's late setpoints and the
//! vehicle's ATTITUDE (largest |roll| and |pitch|, the newest). The member publishes it as a
//! [`STATUS_VEHICLE`] message just before each of its pacing reports ([`Reporting`] wraps the
//! member's transport), so the orchestrator has the newest one whatever stops the team; the
//! tracking error against r_HT is the audit's own, from the measured states.

use std::time::Duration;

use cdm_runtime::messages::{ClockMsg, StateMsg, STATUS_FAULT, STATUS_VEHICLE};
use cdm_runtime::seams::MemberTransport;

use crate::arming::{Autopilot, VehicleMode};
use crate::battery::BatteryFigures;
use crate::flight_mode::FlightMode;
use crate::plant::LinkFigures;
use crate::vehicle::Attitude;

/// One member's vehicle figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleReport {
    /// Setpoints sent to the vehicle.
    pub setpoints_sent: u64,
    /// Setpoints sent more than one period after their scheduled instant.
    pub late_setpoints: u64,
    /// The latest a setpoint was sent after its instant (ms).
    pub max_late_ms: f64,
    /// ATTITUDE messages received.
    pub attitudes: u64,
    /// The largest |roll| and |pitch| received (rad).
    pub max_abs_roll_rad: f64,
    pub max_abs_pitch_rad: f64,
    /// The newest (roll, pitch, yaw) in rad, if any ATTITUDE arrived.
    pub last_attitude_rad: Option<[f64; 3]>,
    /// Datagrams and messages that were not the vehicle's, dropped (`LinkCounters`).
    pub foreign_packets: u64,
    /// Frames dropped for their signature (`--mavlink-signing-key`).
    pub bad_signatures: u64,
    /// The lowest SYS_STATUS battery_remaining (%) and voltage (V), if reported.
    pub battery: BatteryFigures,
    /// The last HEARTBEAT's mode and armed state, if any: after a take-over, the mode the
    /// vehicle left for (the report goes out just before the member's fault report).
    pub mode: Option<VehicleMode>,
}

impl VehicleReport {
    /// The figures of a plant's link now.
    pub fn of(link: &LinkFigures) -> Self {
        let r = link.read();
        let (counters, attitude, battery, sends) = (r.counters, r.attitude, r.battery, r.sends);
        VehicleReport {
            setpoints_sent: counters.setpoints_sent,
            late_setpoints: sends.late,
            max_late_ms: sends.max_late_s * 1e3,
            attitudes: counters.attitudes_received,
            max_abs_roll_rad: attitude.max_abs_roll_rad,
            max_abs_pitch_rad: attitude.max_abs_pitch_rad,
            last_attitude_rad: attitude
                .last
                .map(|a: Attitude| [a.roll_rad, a.pitch_rad, a.yaw_rad]),
            foreign_packets: counters.foreign_packets,
            bad_signatures: counters.bad_signatures,
            battery,
            mode: r.mode,
        }
    }

    /// The mode's name as its autopilot names it (`flight_mode.rs`), if a HEARTBEAT came.
    pub fn mode_name(&self) -> Option<String> {
        self.mode.map(|m| {
            FlightMode {
                autopilot: m.autopilot,
                custom_mode: m.custom_mode,
            }
            .to_string()
        })
    }

    /// As a message: `tick` = setpoints sent, `state` = [late setpoints, max lateness ms,
    /// attitudes, max |roll|, max |pitch|, last roll, pitch, yaw (NaN without one), foreign
    /// packets, bad signatures, lowest battery %, lowest battery V (NaN: none reported)];
    /// the mode in the fault fields, unused by a report: `fault_code` = custom_mode,
    /// `fault_peer` = [`MODE_PRESENT`] | armed ([`MODE_ARMED`]) | MAV_AUTOPILOT (low byte).
    /// Counts up to 2^53 are exact in an f64.
    pub fn to_msg(&self, id: u32, hash: u64) -> StateMsg {
        let mut f = [0.0; 12];
        f[0] = self.late_setpoints as f64;
        f[1] = self.max_late_ms;
        f[2] = self.attitudes as f64;
        f[3] = self.max_abs_roll_rad;
        f[4] = self.max_abs_pitch_rad;
        let last = self.last_attitude_rad.unwrap_or([f64::NAN; 3]);
        f[5..8].copy_from_slice(&last);
        f[8] = self.foreign_packets as f64;
        f[9] = self.bad_signatures as f64;
        f[10] = self.battery.lowest_pct.map_or(f64::NAN, f64::from);
        f[11] = self.battery.lowest_voltage_v.unwrap_or(f64::NAN);
        let (fault_code, fault_peer) = self.mode.map_or((0, 0), |m| {
            let armed = if m.armed { MODE_ARMED } else { 0 };
            (
                m.custom_mode,
                MODE_PRESENT | armed | autopilot_code(m.autopilot),
            )
        });
        StateMsg {
            status: STATUS_VEHICLE,
            fault_code,
            fault_peer,
            ..StateMsg::ok(self.setpoints_sent, hash, id, f)
        }
    }

    /// Reads a vehicle report back: the member's id and its figures (`None`: not one).
    pub fn from_msg(m: &StateMsg) -> Option<(u32, Self)> {
        if m.status != STATUS_VEHICLE {
            return None;
        }
        let f = &m.state;
        let last = [f[5], f[6], f[7]];
        Some((
            m.id,
            VehicleReport {
                setpoints_sent: m.tick,
                late_setpoints: f[0] as u64,
                max_late_ms: f[1],
                attitudes: f[2] as u64,
                max_abs_roll_rad: f[3],
                max_abs_pitch_rad: f[4],
                last_attitude_rad: last.iter().all(|v| v.is_finite()).then_some(last),
                foreign_packets: f[8] as u64,
                bad_signatures: f[9] as u64,
                battery: BatteryFigures {
                    // Whole percents in 0..=100 by construction.
                    lowest_pct: f[10].is_finite().then(|| f[10].clamp(0.0, 100.0) as u8),
                    lowest_voltage_v: f[11].is_finite().then_some(f[11]),
                },
                mode: (m.fault_peer & MODE_PRESENT != 0).then(|| VehicleMode {
                    autopilot: autopilot_of_code(m.fault_peer & 0xff),
                    custom_mode: m.fault_code,
                    armed: m.fault_peer & MODE_ARMED != 0,
                }),
            },
        ))
    }
}

/// A vehicle report's `fault_peer` bit: a mode is present.
pub const MODE_PRESENT: u32 = 1 << 31;
/// A vehicle report's `fault_peer` bit: the vehicle is armed.
pub const MODE_ARMED: u32 = 1 << 30;

/// MAV_AUTOPILOT's number (common.xml): 12 PX4, 3 ArduPilot.
fn autopilot_code(a: Autopilot) -> u32 {
    match a {
        Autopilot::Px4 => 12,
        Autopilot::ArduPilot => 3,
        Autopilot::Other(n) => n & 0xff,
    }
}

fn autopilot_of_code(n: u32) -> Autopilot {
    match n {
        12 => Autopilot::Px4,
        3 => Autopilot::ArduPilot,
        other => Autopilot::Other(other),
    }
}

/// A member's transport that publishes its vehicle report just before each pacing report (the
/// same publisher keeps the order: the orchestrator has the report once it has the pacing).
#[derive(Debug)]
pub struct Reporting<'t, T> {
    inner: &'t mut T,
    link: LinkFigures,
    id: u32,
    hash: u64,
}

impl<'t, T: MemberTransport> Reporting<'t, T> {
    /// Wraps member `id`'s transport (scenario `hash`), reporting `link`.
    pub fn new(inner: &'t mut T, link: LinkFigures, id: u32, hash: u64) -> Self {
        Reporting {
            inner,
            link,
            id,
            hash,
        }
    }

    /// Before each pacing report, and before a fault report (a lost vehicle's, so the audit has
    /// the mode it left for).
    fn report_before(&mut self, msg: &StateMsg) -> Result<(), T::Error> {
        if msg.is_pacing() || msg.status == STATUS_FAULT {
            let r = VehicleReport::of(&self.link).to_msg(self.id, self.hash);
            self.inner.publish_quietly(r)?;
        }
        Ok(())
    }
}

impl<T: MemberTransport> MemberTransport for Reporting<'_, T> {
    type Error = T::Error;

    fn publish(&mut self, msg: StateMsg) -> Result<usize, Self::Error> {
        self.report_before(&msg)?;
        self.inner.publish(msg)
    }

    fn publish_quietly(&mut self, msg: StateMsg) -> Result<usize, Self::Error> {
        self.report_before(&msg)?;
        self.inner.publish_quietly(msg)
    }

    fn notify_readers(&mut self) -> Result<(), Self::Error> {
        self.inner.notify_readers()
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        self.inner.flush()
    }

    fn receive_neighbors(&mut self, f: impl FnMut(StateMsg)) -> Result<usize, Self::Error> {
        self.inner.receive_neighbors(f)
    }

    fn latest_clock(&mut self) -> Result<Option<ClockMsg>, Self::Error> {
        self.inner.latest_clock()
    }

    fn wait(&mut self, timeout: Duration) -> Result<bool, Self::Error> {
        self.inner.wait(timeout)
    }

    fn orchestrator_alive(&self) -> bool {
        self.inner.orchestrator_alive()
    }

    fn receive_clock(&mut self, f: impl FnMut(ClockMsg)) -> Result<usize, Self::Error> {
        self.inner.receive_clock(f)
    }

    fn connect(&mut self, subscribe: &[u32], notify: &[u32]) -> Result<bool, Self::Error> {
        self.inner.connect(subscribe, notify)
    }

    fn hand_over(&mut self) -> Result<bool, Self::Error> {
        self.inner.hand_over()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_report_round_trips_and_is_not_a_state() {
        let r = VehicleReport {
            setpoints_sent: 250,
            late_setpoints: 3,
            max_late_ms: 41.5,
            attitudes: 240,
            max_abs_roll_rad: 0.2,
            max_abs_pitch_rad: 0.1,
            last_attitude_rad: Some([0.01, -0.02, 1.5]),
            foreign_packets: 12_345,
            bad_signatures: 678,
            battery: BatteryFigures {
                lowest_pct: Some(42),
                lowest_voltage_v: Some(15.25),
            },
            mode: Some(VehicleMode {
                autopilot: Autopilot::Px4,
                custom_mode: 3 << 16,
                armed: true,
            }),
        };
        let m = r.to_msg(7, 9);
        assert_eq!(VehicleReport::from_msg(&m), Some((7, r)));
        assert!(!m.is_pacing());
        assert!(matches!(
            m.status(),
            cdm_runtime::messages::AgentStatus::Fault { .. }
        ));
        assert_eq!(r.mode_name().as_deref(), Some("POSCTL"));
        let none = VehicleReport {
            last_attitude_rad: None,
            mode: None,
            ..r
        };
        assert_eq!(none.mode_name(), None);
        let copter = VehicleReport {
            mode: Some(VehicleMode {
                autopilot: Autopilot::ArduPilot,
                custom_mode: 6,
                armed: false,
            }),
            ..r
        };
        let back = VehicleReport::from_msg(&copter.to_msg(7, 9));
        assert_eq!(back, Some((7, copter)));
        assert_eq!(copter.mode_name().as_deref(), Some("RTL"));
        assert_eq!(VehicleReport::from_msg(&none.to_msg(7, 9)), Some((7, none)));
        assert_eq!(
            VehicleReport::from_msg(&StateMsg::ok(1, 9, 7, [0.0; 12])),
            None
        );
    }
}
