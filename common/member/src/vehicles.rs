//! `--vehicles model|mavlink` and the MAVLink options, shared by `orchestrator launch` (which
//! forwards them to the members it spawns) and the hand-started `leader`/`agent`; and the start
//! of a member's MAVLink plant (cdm-mavlink).

use std::net::{IpAddr, Ipv4Addr};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use cdm_mavlink::{
    member_addr, FeedForward, LinkTimeouts, MavlinkPlant, PlantConfig, PlantError, SigningKey,
    VehicleConfig, VehicleFrame, VehicleOrigin, DEFAULT_HEARTBEAT_TIMEOUT,
    DEFAULT_POSITION_TIMEOUT,
};

use crate::member_error::MemberError;
use crate::vehicle_origins::{OriginsError, VehicleOrigins};
use cdm_math::Vec3;
use cdm_mavlink::takeoff::Takeoff;
use cdm_model::formation::Member;
use cdm_model::plan::PhaseKind;
use cdm_scenario::Scenario;

pub use cdm_mavlink::{VehicleReport, DEFAULT_BASE_PORT};

/// A member's vehicle report as audit.json records it (angles in degrees).
pub fn vehicle_figures(r: &VehicleReport) -> cdm_records::audit::VehicleFigures {
    cdm_records::audit::VehicleFigures {
        setpoints_sent: r.setpoints_sent,
        late_setpoints: r.late_setpoints,
        max_setpoint_late_ms: r.max_late_ms,
        attitudes_received: r.attitudes,
        max_abs_roll_deg: r.max_abs_roll_rad.to_degrees(),
        max_abs_pitch_deg: r.max_abs_pitch_rad.to_degrees(),
        last_attitude_deg: r.last_attitude_rad.map(|a| a.map(f64::to_degrees)),
        foreign_packets: r.foreign_packets,
        bad_signatures: r.bad_signatures,
        lowest_battery_pct: r.battery.lowest_pct,
        lowest_battery_v: r.battery.lowest_voltage_v,
        mode: r.mode_name(),
        armed: r.mode.map(|m| m.armed),
    }
}

/// What each member flies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum VehicleKind {
    /// The 12-state quadcopter model (simulation; deterministic).
    #[default]
    Model,
    /// A PX4 or ArduPilot vehicle over MAVLink (UDP): member i listens on H:(P + i).
    Mavlink,
}

/// `--vehicle-feed-forward`: what acceleration and jerk a member publishes with its vehicle's
/// measured position and velocity (cdm-mavlink `setpoint.rs` says why).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum FeedForwardArg {
    /// Those the member commanded (its setpoint's feed-forward).
    #[default]
    Commanded,
    /// Zero (no feed-forward for its out-neighbours).
    Zero,
}

impl From<FeedForwardArg> for FeedForward {
    fn from(a: FeedForwardArg) -> Self {
        match a {
            FeedForwardArg::Commanded => FeedForward::Commanded,
            FeedForwardArg::Zero => FeedForward::Zero,
        }
    }
}

/// The command-line options (flattened into the member binaries and `orchestrator launch`).
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct VehicleArgs {
    /// What each member flies: `model` (simulated) or `mavlink` (a real or SITL vehicle; needs
    /// the wall clock: `orchestrator launch --realtime`).
    #[arg(long, value_enum, default_value_t = VehicleKind::Model)]
    pub vehicles: VehicleKind,
    /// MAVLink: member i (scenario order, from 0) listens on UDP port P + i (PX4 multi-vehicle
    /// SITL's offboard ports start at 14540).
    #[arg(long, value_name = "P", default_value_t = DEFAULT_BASE_PORT)]
    pub mavlink_base_port: u16,
    /// MAVLink: the address the members listen on.
    #[arg(long, value_name = "H", default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    pub mavlink_host: IpAddr,
    /// MAVLink: the scenario point (ENU, m) of the vehicles' NED origin, `x,y,z`.
    #[arg(
        long,
        value_name = "X,Y,Z",
        default_value = "0,0,0",
        allow_hyphen_values = true
    )]
    pub vehicle_origin: String,
    /// MAVLink: each vehicle's own NED origin (PX4 multi-vehicle SITL: its spawn point), from a
    /// TOML file of `[[vehicle]]` tables with `id` and `origin = [x, y, z]` (scenario ENU, m),
    /// one per member; instead of --vehicle-origin.
    #[arg(long, value_name = "FILE", conflicts_with = "vehicle_origin")]
    pub vehicle_origins: Option<PathBuf>,
    /// MAVLink: switch each vehicle to OFFBOARD (PX4) / GUIDED (ArduPilot) and arm it once it
    /// is heard; without it the members only stream setpoints and the operator arms.
    #[arg(long)]
    pub arm: bool,
    /// MAVLink: seconds without a HEARTBEAT before a vehicle is lost. Autopilots beat at 1 Hz,
    /// so this is a number of missed heartbeats (the default: three).
    #[arg(
        long = "heartbeat-timeout",
        value_name = "SECONDS",
        allow_negative_numbers = true,
        default_value_t = DEFAULT_HEARTBEAT_TIMEOUT.as_secs_f64()
    )]
    pub heartbeat_timeout_s: f64,
    /// MAVLink: seconds without a LOCAL_POSITION_NED before a vehicle is lost; several periods
    /// of the vehicle's position stream (the default is 15 of PX4's 30 Hz onboard stream).
    #[arg(
        long = "position-timeout",
        value_name = "SECONDS",
        allow_negative_numbers = true,
        default_value_t = DEFAULT_POSITION_TIMEOUT.as_secs_f64()
    )]
    pub position_timeout_s: f64,
    /// MAVLink: sign every frame sent and take only frames signed with this key (MAVLink 2
    /// message signing); a file readable by its owner only, holding the 32-byte key as 64
    /// hexadecimal digits. Unsigned, wrongly signed and replayed frames are dropped and counted
    /// (audit.json `vehicles.<id>.bad_signatures`).
    #[arg(long, value_name = "FILE")]
    pub mavlink_signing_key: Option<PathBuf>,
    /// MAVLink: a vehicle whose SYS_STATUS battery falls below PCT % (1..=99) is lost, after one
    /// warning at PCT + 10 %. Without it the battery is only recorded (audit.json `vehicles`).
    #[arg(long, value_name = "PCT")]
    pub min_battery: Option<u8>,
    /// MAVLink: the acceleration and jerk each member publishes with its vehicle's measured
    /// position and velocity, the feed-forward its out-neighbours fly: those it commanded (its
    /// setpoint's), or zero.
    #[arg(long, value_enum, default_value_t = FeedForwardArg::Commanded)]
    pub vehicle_feed_forward: FeedForwardArg,
    /// MAVLink: after a mission that ends with a landing, each member lands its vehicle
    /// (MAV_CMD_NAV_LAND), waits for it on the ground (EXTENDED_SYS_STATE) and disarmed (by the
    /// autopilot or a MAV_CMD_COMPONENT_ARM_DISARM it sends, never forced), within 8 s. Needs
    /// --arm and a scenario with [landing].
    #[arg(long)]
    pub disarm_at_end: bool,
    /// MAVLink: before arming, each member uploads the scenario's [geofence] polygon and
    /// [[obstacle]]s to its vehicle's own geofence (the mission protocol, mission_type FENCE),
    /// reads it back and compares; its vehicle reports ready only then, so nothing arms until
    /// every fence is in place, and a vehicle that refuses is named. Needs an [origin].
    #[arg(long)]
    pub upload_fence: bool,
}

impl Default for VehicleArgs {
    fn default() -> Self {
        VehicleArgs {
            vehicles: VehicleKind::Model,
            mavlink_base_port: DEFAULT_BASE_PORT,
            mavlink_host: IpAddr::V4(Ipv4Addr::LOCALHOST),
            vehicle_origin: "0,0,0".into(),
            vehicle_origins: None,
            arm: false,
            heartbeat_timeout_s: DEFAULT_HEARTBEAT_TIMEOUT.as_secs_f64(),
            position_timeout_s: DEFAULT_POSITION_TIMEOUT.as_secs_f64(),
            mavlink_signing_key: None,
            min_battery: None,
            vehicle_feed_forward: FeedForwardArg::Commanded,
            disarm_at_end: false,
            upload_fence: false,
        }
    }
}

/// The MAVLink options, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct MavlinkOptions {
    pub base_port: u16,
    pub host: IpAddr,
    /// `--vehicle-origin`: one origin for every vehicle.
    pub origin: Vec3,
    /// `--vehicle-origins`: each vehicle's own (an absolute path; read against the scenario).
    pub origins: Option<PathBuf>,
    pub arm: bool,
    /// `--heartbeat-timeout` and `--position-timeout`.
    pub timeouts: LinkTimeouts,
    /// `--mavlink-signing-key`: its absolute path (passed on to spawned members, which read the
    /// key themselves, so it is never on a command line) and the key read from it.
    pub signing_key: Option<(PathBuf, SigningKey)>,
    /// `--min-battery`.
    pub min_battery_pct: Option<u8>,
    /// `--vehicle-feed-forward`.
    pub feed_forward: FeedForward,
    /// `--disarm-at-end`.
    pub disarm_at_end: bool,
    /// `--upload-fence`.
    pub upload_fence: bool,
}

/// What each member flies, validated.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Vehicles {
    #[default]
    Model,
    Mavlink(MavlinkOptions),
}

impl VehicleArgs {
    /// Checks the options; the error names the option. MAVLink options without
    /// `--vehicles mavlink` are refused (they would silently do nothing), and so is
    /// `--vehicles mavlink` without real time (`realtime`): vehicles fly on the wall clock.
    pub fn validate(&self, realtime: bool) -> Result<Vehicles, String> {
        let origin = parse_origin(&self.vehicle_origin)?;
        let timeouts = LinkTimeouts {
            heartbeat: crate::options::timeout("--heartbeat-timeout", self.heartbeat_timeout_s)?,
            position: crate::options::timeout("--position-timeout", self.position_timeout_s)?,
        };
        match self.vehicles {
            VehicleKind::Model => {
                if *self != (VehicleArgs::default()) {
                    return Err("--mavlink-base-port, --mavlink-host, --vehicle-origin, --arm, --heartbeat-timeout, --position-timeout, --mavlink-signing-key, --min-battery, --vehicle-feed-forward, --disarm-at-end and --upload-fence need --vehicles mavlink".into());
                }
                Ok(Vehicles::Model)
            }
            VehicleKind::Mavlink if !realtime => {
                Err("--vehicles mavlink needs --realtime (vehicles fly on the wall clock)".into())
            }
            VehicleKind::Mavlink if self.disarm_at_end && !self.arm => Err(
                "--disarm-at-end needs --arm (the member that armed its vehicle disarms it)".into(),
            ),
            VehicleKind::Mavlink => Ok(Vehicles::Mavlink(MavlinkOptions {
                base_port: self.mavlink_base_port,
                host: self.mavlink_host,
                origin,
                // Absolute: spawned members may not share this process's working directory.
                origins: self
                    .vehicle_origins
                    .as_deref()
                    .map(std::path::absolute)
                    .transpose()
                    .map_err(|e| format!("--vehicle-origins: {e}"))?,
                arm: self.arm,
                timeouts,
                signing_key: self
                    .mavlink_signing_key
                    .as_deref()
                    .map(|p| {
                        // Read now, so a bad key is refused before anything starts.
                        let key = SigningKey::load(p).map_err(|e| e.to_string())?;
                        let path = std::path::absolute(p)
                            .map_err(|e| format!("--mavlink-signing-key: {e}"))?;
                        Ok::<_, String>((path, key))
                    })
                    .transpose()?,
                min_battery_pct: match self.min_battery {
                    Some(p) if !(1..=99).contains(&p) => {
                        return Err(format!("--min-battery {p}: must be a percentage in 1..=99"))
                    }
                    other => other,
                },
                feed_forward: self.vehicle_feed_forward.into(),
                disarm_at_end: self.disarm_at_end,
                upload_fence: self.upload_fence,
            })),
        }
    }
}

impl Vehicles {
    /// The options a spawned member needs to fly the same vehicles (none for the model).
    pub fn member_args(&self) -> Vec<String> {
        let Vehicles::Mavlink(o) = self else {
            return Vec::new();
        };
        let mut a = vec![
            "--vehicles".into(),
            "mavlink".into(),
            "--mavlink-base-port".into(),
            o.base_port.to_string(),
            "--mavlink-host".into(),
            o.host.to_string(),
        ];
        match &o.origins {
            Some(file) => a.extend(["--vehicle-origins".into(), file.display().to_string()]),
            None => a.extend([
                "--vehicle-origin".into(),
                format!("{},{},{}", o.origin.x, o.origin.y, o.origin.z),
            ]),
        }
        if o.arm {
            a.push("--arm".into());
        }
        // Seconds as the shortest text that parses back to the same value.
        a.extend([
            "--heartbeat-timeout".into(),
            o.timeouts.heartbeat.as_secs_f64().to_string(),
            "--position-timeout".into(),
            o.timeouts.position.as_secs_f64().to_string(),
        ]);
        if let Some((path, _)) = &o.signing_key {
            a.extend(["--mavlink-signing-key".into(), path.display().to_string()]);
        }
        if let Some(pct) = o.min_battery_pct {
            a.extend(["--min-battery".into(), pct.to_string()]);
        }
        if o.feed_forward == FeedForward::Zero {
            a.extend(["--vehicle-feed-forward".into(), "zero".into()]);
        }
        if o.disarm_at_end {
            a.push("--disarm-at-end".into());
        }
        if o.upload_fence {
            a.push("--upload-fence".into());
        }
        a
    }
}

impl Vehicles {
    /// Checks the options against the scenario: `--vehicle-origins` must give every member an
    /// origin (the error names the file, the line and the member); `--disarm-at-end` needs a
    /// mission that ends with a landing.
    pub fn check(&self, s: &Scenario) -> Result<(), CheckError> {
        let Vehicles::Mavlink(o) = self else {
            return Ok(());
        };
        let local_origin = o.origins.is_some() || o.origin != Vec3::zeros();
        if s.file.geo_origin.is_some() && local_origin {
            return Err(CheckError::LocalOriginOutdoors);
        }
        if let Some(file) = &o.origins {
            VehicleOrigins::load(file, &member_ids(s))?;
        }
        let lands = s
            .plan
            .phases()
            .last()
            .is_some_and(|p| p.kind == PhaseKind::Landing);
        if o.disarm_at_end && !lands {
            return Err(CheckError::DisarmWithoutLanding);
        }
        if o.upload_fence && s.file.geo_origin.is_none() {
            return Err(CheckError::FenceWithoutOrigin);
        }
        if o.upload_fence && s.file.geofence.is_none() && s.file.obstacles.is_empty() {
            return Err(CheckError::NoFence);
        }
        Ok(())
    }
}

/// Why the MAVLink options do not fit the scenario.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    #[error(transparent)]
    Origins(#[from] OriginsError),
    /// `--disarm-at-end` on a scenario that does not end on the ground.
    #[error("--disarm-at-end: the scenario has no [landing] (the vehicles would be disarmed in the air)")]
    DisarmWithoutLanding,
    /// `--vehicle-origin(s)` on a scenario with an `[origin]`, whose vehicles fly in global
    /// coordinates and have no use for a local origin.
    #[error("--vehicle-origin and --vehicle-origins are for local NED; the scenario has an [origin], so its vehicles fly latitude and longitude (leave them out)")]
    LocalOriginOutdoors,
    /// `--upload-fence` without an `[origin]`: fence items are latitudes and longitudes.
    #[error("--upload-fence: the scenario has no [origin] (a vehicle's fence is in latitude and longitude)")]
    FenceWithoutOrigin,
    /// `--upload-fence` with nothing to upload.
    #[error(
        "--upload-fence: the scenario has no [geofence] and no [[obstacle]] (nothing to upload)"
    )]
    NoFence,
}

fn member_ids(s: &Scenario) -> Vec<u32> {
    s.formation.members.iter().map(|m| m.id).collect()
}

/// Member `me`'s vehicle origin: its entry of `--vehicle-origins`, or `--vehicle-origin`.
fn origin_of(s: &Scenario, me: &Member, o: &MavlinkOptions) -> Result<Vec3, OriginsError> {
    let Some(file) = &o.origins else {
        return Ok(o.origin);
    };
    let origins = VehicleOrigins::load(file, &member_ids(s))?;
    Ok(origins.of(me.id).unwrap_or(o.origin))
}

/// `x,y,z` in metres, finite.
fn parse_origin(text: &str) -> Result<Vec3, String> {
    let bad = || format!("--vehicle-origin {text:?}: expected three finite numbers x,y,z (m)");
    let parts: Vec<f64> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|_| bad()))
        .collect::<Result<_, _>>()?;
    match parts.as_slice() {
        [x, y, z] if parts.iter().all(|v| v.is_finite()) => Ok(Vec3::new(*x, *y, *z)),
        _ => Err(bad()),
    }
}

/// Binds member `me`'s port (`H:(P + i)`, i its index in scenario order) and waits for its
/// vehicle to be heard, within `connect` (the member's join timeout). With `--arm` the vehicle
/// is armed later, on the team's order (`cdm_mavlink::team_arm`).
pub fn connect<'a>(
    s: &'a Scenario,
    me: &Member,
    o: &MavlinkOptions,
    connect: Duration,
    interrupted: &AtomicBool,
) -> Result<MavlinkPlant<'a>, MemberError> {
    // With an [origin] the vehicles fly latitude and longitude; otherwise local NED.
    let frame = match s.file.geo_origin {
        Some(g) => VehicleFrame::Global(g),
        None => VehicleFrame::Local(VehicleOrigin(origin_of(s, me, o)?)),
    };
    let index = s
        .formation
        .members
        .iter()
        .position(|m| m.id == me.id)
        .unwrap_or(0);
    let index = u32::try_from(index).unwrap_or(u32::MAX);
    let config = PlantConfig {
        vehicle: VehicleConfig {
            agent: me.id,
            frame,
            arm: o.arm,
            connect_deadline: connect,
            timeouts: o.timeouts,
            min_battery_pct: o.min_battery_pct,
            takeoff: takeoff_of(s, me, o.arm),
            disarm_at_end: o.disarm_at_end,
        },
        bind: member_addr(me.id, o.host, o.base_port, index).map_err(PlantError::from)?,
        signing: o.signing_key.as_ref().map(|(_, key)| *key),
        period: Duration::from_secs_f64(s.dt_s()),
        feed_forward: o.feed_forward,
        fence: match (o.upload_fence, &s.file.geo_origin) {
            (true, Some(origin)) => Some(cdm_mavlink::fence::fence_items(
                origin,
                s.file.geofence.as_ref(),
                &s.file.obstacles,
            )),
            _ => None,
        },
    };
    Ok(MavlinkPlant::connect(
        config,
        s.step_config(),
        &s.plan,
        me,
        interrupted,
    )?)
}

/// With `--arm`, when the mission starts with a take-off: member `me`'s take-off on an
/// ArduPilot vehicle (cdm-mavlink `takeoff.rs`), from its ground spot towards where the take-off
/// phase ends (its reference position), at most half the scenario's tracking bound delta.
fn takeoff_of(s: &Scenario, me: &Member, arm: bool) -> Option<Takeoff> {
    let first = s.plan.phases().first()?;
    let delta_m = cdm_records::audit::SafetyNumbers::of(s).delta_m;
    (arm && first.kind == PhaseKind::Takeoff).then(|| Takeoff::new(me.start, me.position, delta_m))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(extra: &[&str]) -> VehicleArgs {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct A {
            #[command(flatten)]
            v: VehicleArgs,
        }
        let mut argv = vec!["x"];
        argv.extend_from_slice(extra);
        A::try_parse_from(argv).expect("parses").v
    }

    #[test]
    fn the_model_is_the_default_and_mavlink_options_need_mavlink() {
        assert_eq!(args(&[]).validate(false), Ok(Vehicles::Model));
        let e = args(&["--arm"]).validate(true).unwrap_err();
        assert!(e.contains("need --vehicles mavlink"), "{e}");
        let e = args(&["--vehicles", "mavlink"])
            .validate(false)
            .unwrap_err();
        assert!(e.contains("needs --realtime"), "{e}");
    }

    #[test]
    fn mavlink_options_round_trip_through_a_spawned_members_arguments() {
        let v = args(&[
            "--vehicles",
            "mavlink",
            "--mavlink-base-port",
            "15000",
            "--vehicle-origin",
            "-1.5,2,0.25",
            "--arm",
            "--heartbeat-timeout",
            "4.25",
            "--position-timeout",
            "0.1",
            "--vehicle-feed-forward",
            "zero",
            "--disarm-at-end",
        ])
        .validate(true)
        .expect("valid");
        let Vehicles::Mavlink(o) = &v else {
            panic!("{v:?}")
        };
        assert_eq!(o.origin, Vec3::new(-1.5, 2.0, 0.25));
        assert_eq!((o.base_port, o.arm), (15000, true));
        assert_eq!(o.feed_forward, FeedForward::Zero);
        assert!(o.disarm_at_end);
        assert_eq!(
            o.timeouts,
            LinkTimeouts {
                heartbeat: Duration::from_millis(4250),
                position: Duration::from_millis(100),
            }
        );
        let forwarded: Vec<String> = v.member_args();
        let forwarded: Vec<&str> = forwarded.iter().map(String::as_str).collect();
        assert_eq!(args(&forwarded).validate(true), Ok(v));
    }

    #[test]
    fn a_bad_origin_is_named() {
        for bad in ["1,2", "1,2,x", "1,2,inf", ""] {
            let e = args(&["--vehicles", "mavlink", "--vehicle-origin", bad])
                .validate(true)
                .unwrap_err();
            assert!(e.starts_with("--vehicle-origin"), "{e}");
        }
    }

    #[test]
    fn the_link_timeouts_default_to_three_missed_heartbeats_and_half_a_second() {
        let v = args(&["--vehicles", "mavlink"])
            .validate(true)
            .expect("valid");
        let Vehicles::Mavlink(o) = &v else {
            panic!("{v:?}")
        };
        assert_eq!(o.timeouts, LinkTimeouts::default());
        assert_eq!(o.feed_forward, FeedForward::Commanded);
        let forwarded = v.member_args();
        assert!(!forwarded.iter().any(|a| a == "--vehicle-feed-forward"));
        let at = |flag: &str| {
            let i = forwarded.iter().position(|a| a == flag).expect(flag);
            forwarded[i + 1].clone()
        };
        assert_eq!(at("--heartbeat-timeout"), "3");
        assert_eq!(at("--position-timeout"), "0.5");
    }

    #[test]
    fn a_bad_link_timeout_is_named() {
        for flag in ["--heartbeat-timeout", "--position-timeout"] {
            for bad in ["0", "-1", "nan", "inf", "1e9"] {
                let e = args(&["--vehicles", "mavlink", flag, bad])
                    .validate(true)
                    .unwrap_err();
                assert!(e.starts_with(flag), "{flag} {bad}: {e}");
            }
            let e = args(&[flag, "2"]).validate(true).unwrap_err();
            assert!(e.contains("need --vehicles mavlink"), "{e}");
        }
    }
}
