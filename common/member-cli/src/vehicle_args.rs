//! `--vehicles model|mavlink` and the MAVLink options, shared by `orchestrator launch` (which
//! forwards them to the members it spawns, `Vehicles::member_args`) and the hand-started
//! `leader`/`agent`; checked into cdm-member's `Vehicles` before anything runs.

use std::net::{IpAddr, Ipv4Addr};
use std::path::PathBuf;

use cdm_math::Vec3;
use cdm_mavlink::{
    FeedForward, KeyError, LinkTimeouts, SigningKey, DEFAULT_BASE_PORT, DEFAULT_HEARTBEAT_TIMEOUT,
    DEFAULT_POSITION_TIMEOUT,
};
use cdm_member::vehicles::{MavlinkOptions, Vehicles};

use crate::timeout::{timeout, TimeoutError};

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

/// Why the vehicle options are refused (each names its option).
#[derive(Debug, thiserror::Error)]
pub enum VehicleArgsError {
    /// `--vehicle-origin` is not three finite numbers.
    #[error("--vehicle-origin {0:?}: expected three finite numbers x,y,z (m)")]
    Origin(String),
    /// `--heartbeat-timeout` or `--position-timeout` out of range.
    #[error(transparent)]
    Timeout(#[from] TimeoutError),
    /// MAVLink options without `--vehicles mavlink` (they would silently do nothing).
    #[error("--mavlink-base-port, --mavlink-host, --vehicle-origin, --arm, --heartbeat-timeout, --position-timeout, --mavlink-signing-key, --min-battery, --vehicle-feed-forward, --disarm-at-end and --upload-fence need --vehicles mavlink")]
    NeedsMavlink,
    /// `--vehicles mavlink` in lockstep.
    #[error("--vehicles mavlink needs --realtime (vehicles fly on the wall clock)")]
    NeedsRealtime,
    /// `--disarm-at-end` without `--arm`.
    #[error("--disarm-at-end needs --arm (the member that armed its vehicle disarms it)")]
    DisarmWithoutArm,
    /// `--vehicle-origins`' path cannot be made absolute.
    #[error("--vehicle-origins: {0}")]
    OriginsPath(std::io::Error),
    /// `--mavlink-signing-key`: the key cannot be read (names the file).
    #[error("{0}")]
    SigningKey(KeyError),
    /// `--mavlink-signing-key`'s path cannot be made absolute.
    #[error("--mavlink-signing-key: {0}")]
    SigningKeyPath(std::io::Error),
    /// `--min-battery` outside 1..=99.
    #[error("--min-battery {0}: must be a percentage in 1..=99")]
    MinBattery(u8),
}

impl VehicleArgs {
    /// Checks the options; the error names the option. MAVLink options without
    /// `--vehicles mavlink` are refused (they would silently do nothing), and so is
    /// `--vehicles mavlink` without real time (`realtime`): vehicles fly on the wall clock.
    pub fn validate(&self, realtime: bool) -> Result<Vehicles, VehicleArgsError> {
        let origin = parse_origin(&self.vehicle_origin)?;
        let timeouts = LinkTimeouts {
            heartbeat: timeout("--heartbeat-timeout", self.heartbeat_timeout_s)?,
            position: timeout("--position-timeout", self.position_timeout_s)?,
        };
        match self.vehicles {
            VehicleKind::Model => {
                if *self != (VehicleArgs::default()) {
                    return Err(VehicleArgsError::NeedsMavlink);
                }
                Ok(Vehicles::Model)
            }
            VehicleKind::Mavlink if !realtime => Err(VehicleArgsError::NeedsRealtime),
            VehicleKind::Mavlink if self.disarm_at_end && !self.arm => {
                Err(VehicleArgsError::DisarmWithoutArm)
            }
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
                    .map_err(VehicleArgsError::OriginsPath)?,
                arm: self.arm,
                timeouts,
                signing_key: self
                    .mavlink_signing_key
                    .as_deref()
                    .map(|p| {
                        // Read now, so a bad key is refused before anything starts.
                        let key = SigningKey::load(p).map_err(VehicleArgsError::SigningKey)?;
                        let path =
                            std::path::absolute(p).map_err(VehicleArgsError::SigningKeyPath)?;
                        Ok::<_, VehicleArgsError>((path, key))
                    })
                    .transpose()?,
                min_battery_pct: match self.min_battery {
                    Some(p) if !(1..=99).contains(&p) => {
                        return Err(VehicleArgsError::MinBattery(p))
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

/// `x,y,z` in metres, finite.
fn parse_origin(text: &str) -> Result<Vec3, VehicleArgsError> {
    let bad = || VehicleArgsError::Origin(text.to_owned());
    let parts: Vec<f64> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|_| bad()))
        .collect::<Result<_, _>>()?;
    match parts.as_slice() {
        [x, y, z] if parts.iter().all(|v| v.is_finite()) => Ok(Vec3::new(*x, *y, *z)),
        _ => Err(bad()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

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
        assert_eq!(args(&[]).validate(false).ok(), Some(Vehicles::Model));
        let e = args(&["--arm"]).validate(true).unwrap_err().to_string();
        assert!(e.contains("need --vehicles mavlink"), "{e}");
        let e = args(&["--vehicles", "mavlink"])
            .validate(false)
            .unwrap_err()
            .to_string();
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
        assert_eq!(args(&forwarded).validate(true).ok(), Some(v));
    }

    #[test]
    fn a_bad_origin_is_named() {
        for bad in ["1,2", "1,2,x", "1,2,inf", ""] {
            let e = args(&["--vehicles", "mavlink", "--vehicle-origin", bad])
                .validate(true)
                .unwrap_err()
                .to_string();
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
                    .unwrap_err()
                    .to_string();
                assert!(e.starts_with(flag), "{flag} {bad}: {e}");
            }
            let e = args(&[flag, "2"]).validate(true).unwrap_err().to_string();
            assert!(e.contains("need --vehicles mavlink"), "{e}");
        }
    }
}
