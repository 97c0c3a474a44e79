//! Flying in global coordinates: a scenario with an `[origin]` anchors every point on the Earth,
//! so its members command latitude, longitude and altitude and read the vehicle's GPS fix, as
//! PX4 and ArduPilot document for offboard/guided control outdoors; no vehicle's local origin is
//! needed. Without an origin the members fly local NED (`ned.rs`, indoors).
//!
//! Out: SET_POSITION_TARGET_GLOBAL_INT in MAV_FRAME_GLOBAL (latitude and longitude in 1e-7
//! degree, about 1 cm; altitude above mean sea level; MAVLink's 2024 name for the deprecated
//! MAV_FRAME_GLOBAL_INT, and the frame PX4's offboard guide has accepted for this message since
//! v1.12), velocity feed-forward in north, east, down. In: GLOBAL_POSITION_INT (latitude and longitude in 1e-7 degree, altitude
//! AMSL in mm, velocity north, east, down in cm/s). Vectors are turned between the scenario's
//! axes and north-east-down at the origin: 5 km from it the local north differs by 5 km / R,
//! under 0.05 degree, which the feed-forward does not notice.

use mavlink::dialects::common::{
    MavFrame, MavMessage, PositionTargetTypemask, GLOBAL_POSITION_INT_DATA,
    SET_POSITION_TARGET_GLOBAL_INT_DATA,
};

use crate::health::PositionStream;
use crate::messages::{Setpoint, Target, SETPOINT_TYPE_MASK};
use crate::ned::{enu_to_ned_vector, ned_to_enu_vector, to_f32, VehicleOrigin};
use cdm_math::{Real, Vec3};
use cdm_scenario::{GeoOrigin, GeoPoint};

/// SET_POSITION_TARGET_GLOBAL_INT's type_mask: position and velocity feed-forward; yaw, yaw
/// rate and acceleration ignored (3520). PX4's offboard guide lists position, velocity, and
/// position with velocity feed-forward for this message (an acceleration there would be read
/// as thrust), where the local message also takes acceleration feed-forward.
pub const GLOBAL_TYPE_MASK: PositionTargetTypemask = PositionTargetTypemask::from_bits_truncate(
    SETPOINT_TYPE_MASK.bits()
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE.bits()
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE.bits()
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE.bits(),
);

/// 1e-7 degree: MAVLink's integer latitude and longitude unit.
const DEG_E7: Real = 1e7;

/// Which frame a member flies its vehicle in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VehicleFrame {
    /// Local NED about the vehicle's origin (`--vehicle-origin(s)`; no `[origin]`).
    Local(VehicleOrigin),
    /// Latitude, longitude and altitude AMSL through the scenario's `[origin]`.
    Global(GeoOrigin),
}

impl VehicleFrame {
    /// The position message a vehicle in this frame flies on.
    pub fn position_stream(&self) -> PositionStream {
        match self {
            VehicleFrame::Local(_) => PositionStream::LocalNed,
            VehicleFrame::Global(_) => PositionStream::GlobalInt,
        }
    }
}

impl Default for VehicleFrame {
    fn default() -> Self {
        VehicleFrame::Local(VehicleOrigin::default())
    }
}

/// SET_POSITION_TARGET_GLOBAL_INT for `sp` (scenario coordinates) through `origin`.
pub fn position_target(
    target: Target,
    time_boot_ms: u32,
    origin: &GeoOrigin,
    sp: &Setpoint,
) -> MavMessage {
    let g = origin.geodetic(&sp.position);
    let [vx, vy, vz] = to_f32(&enu_to_ned_vector(&origin.enu_of(&sp.velocity)));
    let [afx, afy, afz] = to_f32(&enu_to_ned_vector(&origin.enu_of(&sp.acceleration)));
    MavMessage::SET_POSITION_TARGET_GLOBAL_INT(SET_POSITION_TARGET_GLOBAL_INT_DATA {
        time_boot_ms,
        lat_int: e7(g.lat_deg),
        lon_int: e7(g.lon_deg),
        // f32 altitude: a 24-bit mantissa keeps 0.1 mm at 1 km AMSL.
        alt: g.alt_m as f32,
        vx,
        vy,
        vz,
        afx,
        afy,
        afz,
        yaw: 0.0,
        yaw_rate: 0.0,
        type_mask: GLOBAL_TYPE_MASK,
        target_system: target.system,
        target_component: target.component,
        coordinate_frame: MavFrame::MAV_FRAME_GLOBAL,
    })
}

/// A GLOBAL_POSITION_INT as the scenario's position and velocity.
pub fn measured(origin: &GeoOrigin, p: &GLOBAL_POSITION_INT_DATA) -> (Vec3, Vec3) {
    let g = GeoPoint {
        lat_deg: Real::from(p.lat) / DEG_E7,
        lon_deg: Real::from(p.lon) / DEG_E7,
        alt_m: Real::from(p.alt) / 1000.0,
    };
    let v_ned = Vec3::new(Real::from(p.vx), Real::from(p.vy), Real::from(p.vz)) / 100.0;
    (
        origin.local(&g),
        origin.scenario_of(&ned_to_enu_vector(&v_ned)),
    )
}

/// Degrees as MAVLink's 1e-7 degree integers (rounded; |degrees| <= 180 fits in i32).
fn e7(deg: Real) -> i32 {
    (deg * DEG_E7).round() as i32
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::{MavHeader, MavlinkReader};

    fn origin() -> GeoOrigin {
        GeoOrigin {
            lat_deg: 47.397742,
            lon_deg: 8.545594,
            alt_m: 488.0,
            heading_deg: 90.0,
        }
    }

    fn round_trip(msg: &MavMessage) -> MavMessage {
        let mut bytes = Vec::new();
        let header = MavHeader::default();
        mavlink::write_v2_msg(&mut bytes, header, msg).expect("encode");
        let mut reader = MavlinkReader::new(bytes.as_slice());
        reader.read_any_message::<MavMessage>().expect("decode").1
    }

    #[test]
    fn a_setpoint_goes_out_as_latitude_longitude_and_altitude() {
        let o = origin();
        let sp = Setpoint {
            position: Vec3::new(100.0, 200.0, 10.0),
            velocity: Vec3::new(1.0, 2.0, 0.5),
            acceleration: Vec3::new(0.0, 0.0, 1.0),
            jerk: Vec3::zeros(),
        };
        let target = Target {
            system: 1,
            component: 1,
        };
        let MavMessage::SET_POSITION_TARGET_GLOBAL_INT(d) =
            round_trip(&position_target(target, 7, &o, &sp))
        else {
            panic!("wrong message type");
        };
        let g = o.geodetic(&sp.position);
        assert_eq!((d.lat_int, d.lon_int), (e7(g.lat_deg), e7(g.lon_deg)));
        assert!((Real::from(d.alt) - g.alt_m).abs() < 1e-4);
        // Heading 90: scenario x east, y north; NED = (north, east, down).
        assert_eq!((d.vx, d.vy, d.vz), (2.0, 1.0, -0.5));
        assert_eq!((d.afx, d.afy, d.afz), (0.0, 0.0, -1.0));
        assert_eq!(d.coordinate_frame, MavFrame::MAV_FRAME_GLOBAL);
        assert_eq!(d.type_mask.bits(), 3520);
    }

    #[test]
    fn a_gps_fix_comes_back_to_the_scenario_point_within_a_centimetre() {
        let o = GeoOrigin {
            heading_deg: 30.0,
            ..origin()
        };
        for p in [Vec3::new(0.0, 0.0, 0.0), Vec3::new(3000.0, -4000.0, 120.0)] {
            let g = o.geodetic(&p);
            let fix = GLOBAL_POSITION_INT_DATA {
                lat: e7(g.lat_deg),
                lon: e7(g.lon_deg),
                alt: (g.alt_m * 1000.0).round() as i32,
                // 1 m/s north, 2 m/s east, 0.5 m/s up.
                vx: 100,
                vy: 200,
                vz: -50,
                ..GLOBAL_POSITION_INT_DATA::default()
            };
            let (pos, vel) = measured(&o, &fix);
            // 1e-7 degree is 1.1 cm of latitude.
            assert!((pos - p).norm() < 0.01, "{p:?} -> {pos:?}");
            let enu = o.enu_of(&vel);
            assert!((enu - Vec3::new(2.0, 1.0, 0.5)).norm() < 1e-12, "{enu:?}");
        }
    }
}
