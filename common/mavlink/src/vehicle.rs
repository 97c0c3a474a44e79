//! [`MavlinkVehicle`]: one member's view of its vehicle, without I/O. Messages from the vehicle
//! and the caller's clock go in; measured state, faults and the messages to send come out. The
//! socket is `udp::UdpLink`'s.

use std::time::Duration;

use mavlink::dialects::common::{MavAutopilot, MavMessage, MavModeFlag};
use mavlink::MavHeader;

use crate::arming::{ArmAction, ArmError, ArmSequence, ArmStage, Autopilot, VehicleMode};
use crate::battery::{BatteryFigures, BatteryWatch};
use crate::fence::{FenceError, FenceItem, FenceUpload};
use crate::flight_ends::{EndsError, FlightEnds};
use crate::global::{self, VehicleFrame};
use crate::health::{LinkFault, LinkHealth, LinkTimeouts};
use crate::messages::{self, Setpoint, Target};
use crate::ned::{from_f32, ned_to_enu_vector};
use crate::takeoff::Takeoff;
use crate::takeover::TakeoverWatch;
use cdm_math::{Real, Vec3};

/// The member sends its own HEARTBEAT this often (MAVLink's 1 Hz convention).
pub const HEARTBEAT_INTERVAL: Duration = Duration::from_secs(1);

/// How one member's link is set up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleConfig {
    /// The member's id (named in every fault).
    pub agent: u32,
    /// Local NED about `--vehicle-origin`, or latitude and longitude through the scenario's
    /// `[origin]` (`global.rs`).
    pub frame: VehicleFrame,
    /// `--arm`: switch mode and arm once the team is ready; otherwise stream only.
    pub arm: bool,
    /// How long to wait for the vehicle's first HEARTBEAT and position.
    pub connect_deadline: Duration,
    /// `--heartbeat-timeout` and `--position-timeout`: how long a stream may be silent.
    pub timeouts: LinkTimeouts,
    /// `--min-battery`: below this SYS_STATUS battery_remaining (%) the vehicle is lost.
    pub min_battery_pct: Option<u8>,
    /// With `--arm`, when the mission starts with a take-off: an ArduPilot vehicle takes off to
    /// this altitude before the team flies (`takeoff.rs`).
    pub takeoff: Option<Takeoff>,
    /// `--disarm-at-end`: land and disarm the vehicle once the plan's landing is over
    /// (`landing.rs`).
    pub disarm_at_end: bool,
}

/// The vehicle's measured state in scenario coordinates (LOCAL_POSITION_NED converted). The
/// message carries no acceleration or higher derivatives: a member publishing this state sets
/// them to zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredState {
    pub position: Vec3,
    pub velocity: Vec3,
    /// The vehicle's own timestamp (ms since its boot).
    pub time_boot_ms: u32,
    /// When it arrived, on the caller's clock.
    pub received_at: Duration,
}

/// The vehicle's last ATTITUDE (radians, the vehicle's NED body convention), kept for the
/// audit's record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attitude {
    pub roll_rad: Real,
    pub pitch_rad: Real,
    pub yaw_rad: Real,
    pub time_boot_ms: u32,
}

/// What the audit records of a vehicle's ATTITUDE messages: the largest tilts and the newest.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AttitudeFigures {
    /// The largest |roll| and |pitch| received (rad).
    pub max_abs_roll_rad: Real,
    pub max_abs_pitch_rad: Real,
    /// The newest ATTITUDE, if any.
    pub last: Option<Attitude>,
}

impl AttitudeFigures {
    fn on_attitude(&mut self, a: Attitude) {
        // A NaN from a broken sender must not hide the extremes (max ignores NaN).
        self.max_abs_roll_rad = self.max_abs_roll_rad.max(a.roll_rad.abs());
        self.max_abs_pitch_rad = self.max_abs_pitch_rad.max(a.pitch_rad.abs());
        self.last = Some(a);
    }
}

/// Message counts, for summaries and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkCounters {
    pub heartbeats_received: u64,
    pub positions_received: u64,
    pub attitudes_received: u64,
    /// Messages before the vehicle's first HEARTBEAT, and the vehicle's messages of a type the
    /// member does not use.
    pub ignored: u64,
    /// What was not the vehicle's and was dropped: datagrams from another address than the
    /// vehicle's (not even decoded), oversized datagrams, and messages of another system or
    /// component (a ground station, a spoofer, a gimbal).
    pub foreign_packets: u64,
    /// With a signing key: frames dropped unsigned, signed with another key, or replayed.
    pub bad_signatures: u64,
    pub setpoints_sent: u64,
    pub heartbeats_sent: u64,
    pub commands_sent: u64,
}

/// Why the link to a member's vehicle failed (each variant's source names the member).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum VehicleError {
    #[error(transparent)]
    Link(#[from] LinkFault),
    #[error(transparent)]
    Arm(#[from] ArmError),
    /// A take-off or a landing failed.
    #[error(transparent)]
    Ends(#[from] EndsError),
    /// `--upload-fence`: the vehicle refused the fence, or holds another, or stayed silent.
    #[error(transparent)]
    Fence(#[from] FenceError),
}

/// One member's MAVLink vehicle, as pure logic.
#[derive(Debug, Clone)]
pub struct MavlinkVehicle {
    config: VehicleConfig,
    health: LinkHealth,
    arm: ArmSequence,
    /// The autopilot this link locked onto (system and component of its first HEARTBEAT).
    target: Option<Target>,
    mode: Option<VehicleMode>,
    state: Option<MeasuredState>,
    attitude: AttitudeFigures,
    battery: BatteryWatch,
    takeover: TakeoverWatch,
    last_heartbeat_sent: Option<Duration>,
    stream_started: Option<Duration>,
    counters: LinkCounters,
    /// ArduCopter's take-off and `--disarm-at-end`'s landing.
    ends: FlightEnds,
    /// A take-off or landing failure seen in a COMMAND_ACK, reported at the next tick.
    ends_fault: Option<EndsError>,
    /// `--upload-fence`: the fence to put on the vehicle before it reports ready.
    fence: Option<FenceUpload>,
}

impl MavlinkVehicle {
    /// A link whose clock starts now (`Duration::ZERO` on the caller's clock).
    pub fn new(config: VehicleConfig) -> Self {
        MavlinkVehicle {
            config,
            health: LinkHealth::new(
                config.agent,
                config.connect_deadline,
                config.timeouts,
                config.frame.position_stream(),
            ),
            arm: ArmSequence::new(config.agent, config.arm),
            target: None,
            mode: None,
            state: None,
            attitude: AttitudeFigures::default(),
            battery: BatteryWatch::new(config.agent, config.min_battery_pct),
            takeover: TakeoverWatch::new(config.agent),
            last_heartbeat_sent: None,
            stream_started: None,
            counters: LinkCounters::default(),
            ends: FlightEnds::new(config.agent, config.takeoff, config.disarm_at_end),
            ends_fault: None,
            fence: None,
        }
    }

    /// `--upload-fence`: upload `items` as the vehicle's geofence and read them back before it
    /// reports ready (so before anything arms).
    pub fn upload_fence(&mut self, items: Vec<FenceItem>) {
        self.fence = Some(FenceUpload::new(self.config.agent, items));
    }

    /// A message arrived at `now`. Returns whether it came from the vehicle this link follows
    /// (the socket replies to where such messages come from, not to any other sender).
    pub fn on_message(&mut self, now: Duration, header: &MavHeader, msg: &MavMessage) -> bool {
        if let MavMessage::HEARTBEAT(hb) = msg {
            // Lock onto the first autopilot heard; ground stations and companions also beat.
            // MAVLink 2 system ids are one byte on the wire; the header type is wider.
            if let (None, Ok(system)) = (self.target, u8::try_from(header.system_id)) {
                if hb.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID {
                    self.target = Some(Target {
                        system,
                        component: header.component_id,
                    });
                }
            }
        }
        let Some(t) = self.target else {
            // Not locked yet (positions stream faster than the 1 Hz HEARTBEAT that locks).
            self.counters.ignored += 1;
            return false;
        };
        if u32::from(t.system) != header.system_id || t.component != header.component_id {
            self.counters.foreign_packets += 1;
            return false;
        }
        if self.fence.as_mut().is_some_and(|f| f.on_message(t, msg)) {
            return true;
        }
        match msg {
            MavMessage::HEARTBEAT(hb) if hb.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID => {
                self.on_heartbeat(now, hb);
            }
            MavMessage::LOCAL_POSITION_NED(p) if self.local().is_some() => {
                let origin = self.local().unwrap_or_default();
                let position = origin.ned_to_enu(&from_f32(p.x, p.y, p.z));
                let velocity = ned_to_enu_vector(&from_f32(p.vx, p.vy, p.vz));
                self.on_position(now, position, velocity, p.time_boot_ms);
            }
            // Outdoors the GPS fix is the position (PX4 and ArduPilot stream both).
            MavMessage::GLOBAL_POSITION_INT(p) => {
                let VehicleFrame::Global(origin) = self.config.frame else {
                    self.counters.ignored += 1;
                    return false;
                };
                let (position, velocity) = global::measured(&origin, p);
                self.on_position(now, position, velocity, p.time_boot_ms);
            }
            MavMessage::SYS_STATUS(st) => {
                self.battery
                    .on_sys_status(st.battery_remaining, st.voltage_battery);
            }
            MavMessage::COMMAND_ACK(a) => {
                if let Err(e) = self.ends.on_ack(now, a.command, a.result) {
                    self.ends_fault.get_or_insert(e);
                }
            }
            MavMessage::EXTENDED_SYS_STATE(e) => self.ends.on_landed_state(e.landed_state),
            MavMessage::ATTITUDE(a) => {
                self.counters.attitudes_received += 1;
                self.attitude.on_attitude(Attitude {
                    roll_rad: Real::from(a.roll),
                    pitch_rad: Real::from(a.pitch),
                    yaw_rad: Real::from(a.yaw),
                    time_boot_ms: a.time_boot_ms,
                });
            }
            _ => {
                self.counters.ignored += 1;
                return false;
            }
        }
        true
    }

    /// The autopilot's HEARTBEAT: alive, its state, its mode.
    fn on_heartbeat(&mut self, now: Duration, hb: &mavlink::dialects::common::HEARTBEAT_DATA) {
        self.counters.heartbeats_received += 1;
        self.health.on_heartbeat(now);
        self.battery.on_system_status(hb.system_status);
        let mode = VehicleMode {
            autopilot: autopilot_of(hb.autopilot),
            custom_mode: hb.custom_mode,
            armed: hb
                .base_mode
                .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED),
        };
        self.mode = Some(mode);
        self.takeover.on_heartbeat(mode);
    }

    /// The vehicle's local NED origin, when it flies local NED.
    fn local(&self) -> Option<crate::ned::VehicleOrigin> {
        match self.config.frame {
            VehicleFrame::Local(o) => Some(o),
            VehicleFrame::Global(_) => None,
        }
    }

    /// A measured position (in the frame this link flies) arrived at `now`.
    fn on_position(&mut self, now: Duration, position: Vec3, velocity: Vec3, time_boot_ms: u32) {
        self.counters.positions_received += 1;
        self.health.on_position(now);
        self.state = Some(MeasuredState {
            position,
            velocity,
            time_boot_ms,
            received_at: now,
        });
    }

    /// One tick at `now`: check the link, then return what to send once the vehicle is known
    /// (a HEARTBEAT when one is due, the setpoint, an `--arm` command when one is due).
    /// `team_ready` says every vehicle of the team reports ready (gates `--arm`). Once the
    /// vehicle is lost (silent, taken over, its battery or failsafe) every tick is that fault
    /// and nothing is sent: a vehicle a pilot has taken gets no more setpoints.
    pub fn on_tick(
        &mut self,
        now: Duration,
        setpoint: Option<&Setpoint>,
        team_ready: bool,
    ) -> Result<Vec<MavMessage>, VehicleError> {
        self.health.check(now)?;
        // Before the battery: an autopilot failsafe both reports MAV_STATE_CRITICAL and
        // switches mode, and the mode says more (RTL, LAND).
        self.takeover.check()?;
        self.battery.check()?;
        let mut out = Vec::with_capacity(3);
        // Nothing to say before the vehicle is known: there is no one to address.
        let Some(target) = self.target else {
            return Ok(out);
        };
        let heartbeat_due = self
            .last_heartbeat_sent
            .is_none_or(|t| now.saturating_sub(t) >= HEARTBEAT_INTERVAL);
        if heartbeat_due {
            self.last_heartbeat_sent = Some(now);
            self.counters.heartbeats_sent += 1;
            out.push(messages::heartbeat());
        }
        if let Some(f) = &mut self.fence {
            out.extend(f.on_tick(now, target)?);
        }
        if let Some(sp) = setpoint {
            let started = *self.stream_started.get_or_insert(now);
            // time_boot_ms is the member's milliseconds since the link started (wraps after 49 days).
            let ms = u32::try_from(now.as_millis() % (1 << 32)).unwrap_or(0);
            let sp = self.ends.floored(sp, self.mode.as_ref());
            out.push(match &self.config.frame {
                VehicleFrame::Local(origin) => messages::position_target(target, ms, origin, &sp),
                VehicleFrame::Global(origin) => global::position_target(target, ms, origin, &sp),
            });
            self.counters.setpoints_sent += 1;
            let streamed = now.saturating_sub(started);
            for (action, sent) in self.commands(now, streamed, team_ready)? {
                let confirmation = u8::try_from(sent.saturating_sub(1)).unwrap_or(u8::MAX);
                out.push(messages::command(target, action, confirmation));
                self.counters.commands_sent += 1;
            }
        }
        Ok(out)
    }

    /// The commands due now, each with how many times it was sent: `--arm`'s, then once armed
    /// the take-off's or the landing's (`flight_ends.rs`).
    fn commands(
        &mut self,
        now: Duration,
        streamed: Duration,
        team_ready: bool,
    ) -> Result<Vec<(ArmAction, u32)>, VehicleError> {
        let mut due = Vec::new();
        if let Some(action) = self.arm.on_tick(now, self.mode, streamed, team_ready)? {
            due.push((action, self.arm.requests()));
        }
        if let Some(e) = self.ends_fault {
            return Err(e.into());
        }
        if self.arm.stage() == ArmStage::Armed {
            let height = self.state.map(|m| m.position.z);
            due.extend(self.ends.on_tick(now, self.mode, height)?);
        }
        Ok(due)
    }

    /// The plan's landing is over at `now`: with `--disarm-at-end`, land and disarm. The
    /// vehicle leaving its guided mode for its Land mode, and disarming, are the flight's end
    /// from then on, not a take-over.
    pub fn on_landing_over(&mut self, now: Duration) {
        if self.ends.order_landing(now) {
            self.takeover.end();
        }
    }

    /// Whether the team may fly: armed in the guided mode (`--arm`) and, for an ArduPilot
    /// vehicle whose mission takes off, at its take-off altitude (`takeoff.rs`).
    pub fn ready_to_fly(&self) -> bool {
        self.arm.stage() == ArmStage::Armed && self.ends.airborne(self.mode.as_ref())
    }

    /// Whether there is nothing more to wait for at the end: false only while a landing
    /// `--disarm-at-end` ordered has not yet seen the vehicle disarmed.
    pub fn landing_done(&self) -> bool {
        self.ends.landed_or_not_landing()
    }

    /// Whether the vehicle has been heard (HEARTBEAT and position): it reports ready.
    pub fn ready(&self) -> bool {
        self.health.connected() && self.fence.as_ref().is_none_or(FenceUpload::done)
    }

    /// The last measured state, if any.
    pub fn state(&self) -> Option<&MeasuredState> {
        self.state.as_ref()
    }

    /// The last attitude, if any.
    pub fn attitude(&self) -> Option<&Attitude> {
        self.attitude.last.as_ref()
    }

    /// The attitude's extremes and newest value.
    pub fn attitude_figures(&self) -> AttitudeFigures {
        self.attitude
    }

    /// The lowest battery figures reported.
    pub fn battery_figures(&self) -> BatteryFigures {
        self.battery.figures()
    }

    /// A battery warning not yet logged (`--min-battery`), taken once.
    pub fn take_warning(&mut self) -> Option<String> {
        self.battery.take_warning()
    }

    /// The last HEARTBEAT's mode and armed state, if any.
    pub fn mode(&self) -> Option<&VehicleMode> {
        self.mode.as_ref()
    }

    /// Where `--arm` is.
    pub fn arm_stage(&self) -> ArmStage {
        self.arm.stage()
    }

    /// The autopilot the link locked onto.
    pub fn target(&self) -> Option<Target> {
        self.target
    }

    /// A datagram dropped unread: from another address than the vehicle's, or too large to be
    /// one of its (the socket's decision, counted here with the rest of what is not the
    /// vehicle's).
    pub fn on_foreign_datagram(&mut self) {
        self.counters.foreign_packets += 1;
    }

    /// A frame dropped for its signature (`--mavlink-signing-key`): unsigned, signed with
    /// another key, or replayed; the socket's decision, counted here.
    pub fn on_bad_signature(&mut self) {
        self.counters.bad_signatures += 1;
    }

    /// Message counts so far.
    pub fn counters(&self) -> &LinkCounters {
        &self.counters
    }

    /// The member's id.
    pub fn agent(&self) -> u32 {
        self.config.agent
    }
}

fn autopilot_of(a: MavAutopilot) -> Autopilot {
    match a {
        MavAutopilot::MAV_AUTOPILOT_PX4 => Autopilot::Px4,
        MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA => Autopilot::ArduPilot,
        other => Autopilot::Other(other as u32),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::common::{
        MavState, MavType, ATTITUDE_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA,
    };

    const VEHICLE: MavHeader = MavHeader {
        system_id: 3,
        component_id: 1,
        sequence: 0,
    };

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn config(arm: bool) -> VehicleConfig {
        VehicleConfig {
            agent: 12,
            frame: VehicleFrame::Local(crate::ned::VehicleOrigin(Vec3::new(10.0, 20.0, 0.0))),
            arm,
            connect_deadline: ms(5000),
            timeouts: LinkTimeouts::default(),
            min_battery_pct: None,
            takeoff: None,
            disarm_at_end: false,
        }
    }

    fn heartbeat(autopilot: MavAutopilot, custom_mode: u32, armed: bool) -> MavMessage {
        let base_mode = if armed {
            MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
        } else {
            MavModeFlag::empty()
        };
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot,
            base_mode,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        })
    }

    fn position(n: f32, e: f32, d: f32) -> MavMessage {
        MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
            time_boot_ms: 99,
            x: n,
            y: e,
            z: d,
            vx: 1.0,
            vy: 0.0,
            vz: -0.5,
        })
    }

    fn hover() -> Setpoint {
        Setpoint {
            position: Vec3::new(10.0, 20.0, 2.0),
            velocity: Vec3::zeros(),
            acceleration: Vec3::zeros(),
            jerk: Vec3::zeros(),
        }
    }

    fn heard(v: &mut MavlinkVehicle, now: Duration) {
        v.on_message(
            now,
            &VEHICLE,
            &heartbeat(MavAutopilot::MAV_AUTOPILOT_PX4, 0, false),
        );
        v.on_message(now, &VEHICLE, &position(1.0, 2.0, -3.0));
    }

    #[test]
    fn measured_state_is_in_scenario_coordinates() {
        let mut v = MavlinkVehicle::new(config(false));
        heard(&mut v, ms(10));
        let s = v.state().unwrap();
        assert_eq!(s.position, Vec3::new(12.0, 21.0, 3.0));
        assert_eq!(s.velocity, Vec3::new(0.0, 1.0, 0.5));
        assert!(v.ready());
        v.on_message(
            ms(11),
            &VEHICLE,
            &MavMessage::ATTITUDE(ATTITUDE_DATA {
                yaw: 0.5,
                ..ATTITUDE_DATA::default()
            }),
        );
        assert_eq!(v.attitude().unwrap().yaw_rad, 0.5);
        v.on_message(
            ms(12),
            &VEHICLE,
            &MavMessage::ATTITUDE(ATTITUDE_DATA {
                roll: -0.25,
                pitch: 0.125,
                ..ATTITUDE_DATA::default()
            }),
        );
        let f = v.attitude_figures();
        assert_eq!((f.max_abs_roll_rad, f.max_abs_pitch_rad), (0.25, 0.125));
        assert_eq!(f.last.unwrap().yaw_rad, 0.0);
    }

    #[test]
    fn only_the_autopilot_is_followed() {
        let mut v = MavlinkVehicle::new(config(false));
        let gcs = MavHeader {
            system_id: 255,
            component_id: 190,
            sequence: 0,
        };
        // A ground station's heartbeat and position are not the vehicle's.
        let gcs_beat = heartbeat(MavAutopilot::MAV_AUTOPILOT_INVALID, 0, false);
        assert!(!v.on_message(ms(1), &gcs, &gcs_beat));
        assert!(!v.on_message(ms(1), &gcs, &position(5.0, 5.0, 5.0)));
        assert_eq!(v.target(), None);
        heard(&mut v, ms(2));
        assert!(!v.on_message(ms(3), &gcs, &position(5.0, 5.0, 5.0)));
        assert_eq!(
            v.target(),
            Some(Target {
                system: 3,
                component: 1
            })
        );
        assert_eq!(v.state().unwrap().position, Vec3::new(12.0, 21.0, 3.0));
        // Before the lock: not counted as foreign (the vehicle's own positions come first).
        assert_eq!(v.counters().ignored, 2);
        assert_eq!(v.counters().foreign_packets, 1);
        // The vehicle's system id from another component (a gimbal, a spoofer): not its.
        let other = MavHeader {
            system_id: 3,
            component_id: 154,
            sequence: 0,
        };
        assert!(!v.on_message(ms(4), &other, &position(9.0, 9.0, 9.0)));
        assert_eq!(v.state().unwrap().position, Vec3::new(12.0, 21.0, 3.0));
        assert_eq!(v.counters().foreign_packets, 2);
    }

    #[test]
    fn setpoints_every_tick_heartbeat_once_a_second() {
        let mut v = MavlinkVehicle::new(config(false));
        // Before the vehicle is heard there is no one to address.
        assert!(v.on_tick(ms(0), Some(&hover()), false).unwrap().is_empty());
        let mut setpoints = 0;
        let mut beats = 0;
        for k in 1..=100u64 {
            let now = ms(20 * k);
            heard(&mut v, now);
            for m in v.on_tick(now, Some(&hover()), true).unwrap() {
                match m {
                    MavMessage::SET_POSITION_TARGET_LOCAL_NED(_) => setpoints += 1,
                    MavMessage::HEARTBEAT(_) => beats += 1,
                    other => panic!("unexpected {other:?} without --arm"),
                }
            }
        }
        assert_eq!(setpoints, 100);
        assert_eq!(beats, 2); // at 0.02 s (first tick with a target) and 1.02 s
    }

    #[test]
    fn a_silent_vehicle_is_a_fault_naming_the_agent() {
        let mut v = MavlinkVehicle::new(config(false));
        heard(&mut v, ms(100));
        v.on_tick(ms(600), Some(&hover()), true).unwrap();
        let err = v.on_tick(ms(601), Some(&hover()), true).unwrap_err();
        assert!(matches!(
            err,
            VehicleError::Link(LinkFault::PositionLost { agent: 12, .. })
        ));
        assert!(err.to_string().contains("agent 12"));
    }

    #[test]
    fn a_vehicle_in_global_coordinates_is_awaited_by_global_position_int() {
        let mut cfg = config(false);
        cfg.frame = VehicleFrame::Global(cdm_scenario::GeoOrigin {
            lat_deg: 47.0,
            lon_deg: 8.0,
            alt_m: 400.0,
            heading_deg: 90.0,
        });
        let mut v = MavlinkVehicle::new(cfg);
        // A LOCAL_POSITION_NED is no position for it: only the HEARTBEAT counts.
        heard(&mut v, ms(100));
        let err = v.on_tick(ms(5001), None, true).unwrap_err();
        let said = err.to_string();
        assert!(
            said.contains("agent 12") && said.contains("a HEARTBEAT and a GLOBAL_POSITION_INT"),
            "{said}"
        );
    }

    #[test]
    fn arm_sends_offboard_then_arm_as_command_long() {
        let mut v = MavlinkVehicle::new(config(true));
        let mut commands = Vec::new();
        for k in 0..=150u64 {
            let now = ms(20 * k);
            // The fake PX4 obeys: OFFBOARD once asked, armed once asked.
            let offboard = commands.iter().any(|c| matches!(c, MavMessage::COMMAND_LONG(d) if d.command == mavlink::dialects::common::MavCmd::MAV_CMD_DO_SET_MODE));
            let armed = commands.len() > 1;
            let mode = if offboard { 6 << 16 } else { 0 };
            v.on_message(
                now,
                &VEHICLE,
                &heartbeat(MavAutopilot::MAV_AUTOPILOT_PX4, mode, armed),
            );
            v.on_message(now, &VEHICLE, &position(1.0, 2.0, -3.0));
            let out = v.on_tick(now, Some(&hover()), true).unwrap();
            commands.extend(
                out.into_iter()
                    .filter(|m| matches!(m, MavMessage::COMMAND_LONG(_))),
            );
        }
        assert_eq!(commands.len(), 2, "{commands:?}");
        assert_eq!(v.arm_stage(), ArmStage::Armed);
    }

    #[test]
    fn arms_a_vehicle_that_beats_once_a_second() {
        // PX4's defaults: HEARTBEAT at 1 Hz (here 0.9 s late once), positions at 30 Hz; the
        // member ticks at 50 Hz. The link stays up through the whole sequence.
        let mut v = MavlinkVehicle::new(config(true));
        let (mut offboard, mut armed) = (false, false);
        let mut next_beat = 0u64;
        for k in 0..=500u64 {
            let now_ms = 20 * k;
            let now = ms(now_ms);
            if now_ms >= next_beat {
                let mode = if offboard { 6 << 16 } else { 0 };
                let beat = heartbeat(MavAutopilot::MAV_AUTOPILOT_PX4, mode, armed);
                v.on_message(now, &VEHICLE, &beat);
                next_beat += if k == 150 { 1900 } else { 1000 };
            }
            if now_ms % 33 < 20 {
                v.on_message(now, &VEHICLE, &position(1.0, 2.0, -3.0));
            }
            for m in v.on_tick(now, Some(&hover()), true).unwrap() {
                if let MavMessage::COMMAND_LONG(c) = m {
                    use mavlink::dialects::common::MavCmd;
                    offboard |= c.command == MavCmd::MAV_CMD_DO_SET_MODE;
                    armed |= c.command == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM && offboard;
                }
            }
        }
        assert_eq!(v.arm_stage(), ArmStage::Armed);
    }

    /// A fake PX4 on the fake clock: HEARTBEAT at 1 Hz, positions at 50 Hz, obeying `--arm`;
    /// from `switch_ms` on its HEARTBEAT says `after` (mode, armed). Returns the first fault,
    /// when it came, and the setpoints sent from `switch_ms` on.
    fn fly_until_lost(switch_ms: u64, after: (u32, bool)) -> (u64, VehicleError, u32) {
        let mut v = MavlinkVehicle::new(config(true));
        let (mut offboard, mut armed) = (false, false);
        let mut after_switch = 0;
        for k in 0..=1000u64 {
            let now_ms = 20 * k;
            let now = ms(now_ms);
            if now_ms % 1000 == 0 {
                let (mode, armed_now) = if now_ms >= switch_ms {
                    after
                } else {
                    (if offboard { 6 << 16 } else { 3 << 16 }, armed)
                };
                let beat = heartbeat(MavAutopilot::MAV_AUTOPILOT_PX4, mode, armed_now);
                v.on_message(now, &VEHICLE, &beat);
            }
            v.on_message(now, &VEHICLE, &position(1.0, 2.0, -3.0));
            let out = match v.on_tick(now, Some(&hover()), true) {
                Ok(out) => out,
                Err(e) => {
                    // Sticky: every later tick is the same fault, and sends nothing.
                    assert_eq!(v.on_tick(ms(now_ms + 20), Some(&hover()), true), Err(e));
                    return (now_ms, e, after_switch);
                }
            };
            for m in out {
                match m {
                    MavMessage::COMMAND_LONG(c) => {
                        use mavlink::dialects::common::MavCmd;
                        offboard |= c.command == MavCmd::MAV_CMD_DO_SET_MODE;
                        armed |= c.command == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM && offboard;
                    }
                    MavMessage::SET_POSITION_TARGET_LOCAL_NED(_) if now_ms >= switch_ms => {
                        after_switch += 1;
                    }
                    _ => {}
                }
            }
        }
        panic!("never lost");
    }

    #[test]
    fn a_vehicle_switched_out_of_offboard_is_lost_naming_the_mode() {
        // Armed in OFFBOARD by 4 s; the pilot switches to POSCTL at 6.5 s, which the 7 s
        // HEARTBEAT shows: that tick is the loss, and no setpoint goes out on it or after.
        let (at, e, sent) = fly_until_lost(6500, (3 << 16, true));
        assert_eq!(at, 7000);
        // Sent between the switch and the HEARTBEAT that shows it (the member cannot know).
        assert_eq!(sent, 25);
        assert!(
            matches!(e, VehicleError::Link(LinkFault::LeftMode { agent: 12, .. })),
            "{e:?}"
        );
        assert!(
            e.to_string()
                .starts_with("agent 12: vehicle lost: it left OFFBOARD: now POSCTL"),
            "{e}"
        );
    }

    #[test]
    fn a_vehicle_disarmed_in_flight_is_lost() {
        let (at, e, _) = fly_until_lost(8000, (6 << 16, false));
        assert_eq!(at, 8000);
        assert!(
            e.to_string()
                .starts_with("agent 12: vehicle lost: disarmed in flight (in OFFBOARD"),
            "{e}"
        );
    }

    #[test]
    fn a_vehicle_never_engaged_is_never_lost_for_its_mode() {
        // Without --arm and no operator: POSCTL, disarmed, then armed in POSCTL, all flight.
        let mut v = MavlinkVehicle::new(config(false));
        for k in 0..=500u64 {
            let now = ms(20 * k);
            let armed = k > 250;
            if k % 50 == 0 {
                let beat = heartbeat(MavAutopilot::MAV_AUTOPILOT_PX4, 3 << 16, armed);
                v.on_message(now, &VEHICLE, &beat);
            }
            v.on_message(now, &VEHICLE, &position(1.0, 2.0, -3.0));
            assert!(v.on_tick(now, Some(&hover()), true).is_ok(), "tick {k}");
        }
    }
    /// A fake ArduCopter on the fake clock, resting on the ground at NED z = 0 (scenario z 0
    /// with this origin): HEARTBEAT at 1 Hz, positions and EXTENDED_SYS_STATE at 50 Hz; it obeys
    /// GUIDED and arming, ACKs NAV_TAKEOFF and climbs at 2.5 m/s, ACKs NAV_LAND and descends,
    /// then disarms itself on the ground. The member (`--arm --disarm-at-end`, a take-off to
    /// 0.35 m): not ready to fly before the climb, then ready; the landing ordered at 20 s ends
    /// disarmed with no take-over loss for LAND mode or the disarm.
    #[test]
    fn an_ardupilot_takes_off_on_command_and_lands_and_disarms_at_the_end() {
        use mavlink::dialects::common::{
            MavCmd, MavLandedState, MavResult, COMMAND_ACK_DATA, EXTENDED_SYS_STATE_DATA,
        };
        let mut c = config(true);
        c.takeoff = Some(Takeoff {
            ground_z_m: 0.0,
            altitude_m: 0.35,
        });
        c.disarm_at_end = true;
        let mut v = MavlinkVehicle::new(c);
        let (mut mode, mut armed, mut z_up) = (0u32, false, 0.0f32);
        let mut target_up: Option<f32> = None;
        let (mut acks, mut ready_at) = (Vec::new(), None);
        for k in 0..=1500u64 {
            let now = ms(20 * k);
            if k % 50 == 0 {
                let beat = heartbeat(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA, mode, armed);
                v.on_message(now, &VEHICLE, &beat);
            }
            for ack in acks.drain(..) {
                v.on_message(now, &VEHICLE, &ack);
            }
            if let Some(t) = target_up {
                // Climb (or descend) at 2.5 m/s towards the target height.
                z_up = (z_up + (t - z_up).clamp(-0.05, 0.05)).max(0.0);
            }
            let landed_state = if z_up <= 0.0 {
                MavLandedState::MAV_LANDED_STATE_ON_GROUND
            } else {
                MavLandedState::MAV_LANDED_STATE_IN_AIR
            };
            if armed && mode == 9 && z_up <= 0.0 {
                armed = false; // ArduCopter's LAND disarms at touchdown
            }
            let ext = EXTENDED_SYS_STATE_DATA {
                landed_state,
                ..EXTENDED_SYS_STATE_DATA::default()
            };
            v.on_message(now, &VEHICLE, &MavMessage::EXTENDED_SYS_STATE(ext));
            v.on_message(now, &VEHICLE, &position(20.0, 10.0, -z_up));
            if k == 1000 {
                v.on_landing_over(now);
            }
            let out = v.on_tick(now, Some(&hover()), true).expect("no fault");
            if v.ready_to_fly() && ready_at.is_none() {
                ready_at = Some((k, z_up));
            }
            for m in out {
                let MavMessage::COMMAND_LONG(cmd) = m else {
                    continue;
                };
                let result = MavResult::MAV_RESULT_ACCEPTED;
                match cmd.command {
                    MavCmd::MAV_CMD_DO_SET_MODE => mode = cmd.param2 as u32,
                    MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => armed = cmd.param1 == 1.0,
                    MavCmd::MAV_CMD_NAV_TAKEOFF => target_up = Some(cmd.param7),
                    MavCmd::MAV_CMD_NAV_LAND => (mode, target_up) = (9, Some(-1.0)),
                    _ => {}
                }
                let ack = COMMAND_ACK_DATA {
                    command: cmd.command,
                    result,
                    ..COMMAND_ACK_DATA::default()
                };
                acks.push(MavMessage::COMMAND_ACK(ack));
            }
        }
        let (k, z) = ready_at.expect("ready to fly after the take-off");
        assert!(z >= 0.9 * 0.35, "ready at tick {k} at {z} m");
        assert!(!armed && v.landing_done(), "not landed and disarmed");
        assert_eq!(v.arm_stage(), ArmStage::Armed);
    }
}
