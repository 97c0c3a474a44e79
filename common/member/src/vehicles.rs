//! What each member flies (the model, or a MAVLink vehicle with its options, validated by the
//! binaries' command line), the options a spawned member is given to fly the same, and the
//! start of a member's MAVLink plant (cdm-mavlink).

use std::net::IpAddr;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use cdm_mavlink::{
    member_addr, FeedForward, LinkTimeouts, MavlinkPlant, PlantConfig, PlantError, SigningKey,
    VehicleConfig, VehicleFrame, VehicleOrigin,
};

use crate::member_error::{CheckError, MemberError};
use crate::vehicle_origins::{OriginsError, VehicleOrigins};
use cdm_math::Vec3;
use cdm_mavlink::takeoff::Takeoff;
use cdm_model::formation::Member;
use cdm_model::plan::PhaseKind;
use cdm_scenario::Scenario;

pub use cdm_mavlink::VehicleReport;

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
