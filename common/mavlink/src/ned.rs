//! The one place that converts between the scenario's frame and the vehicle's.
//!
//! The scenario is ENU (x east, y north, z up, metres); MAVLink's LOCAL_POSITION_NED and
//! SET_POSITION_TARGET_LOCAL_NED are NED (x north, y east, z down) relative to the vehicle's
//! local origin. A point is converted after subtracting `--vehicle-origin` (the scenario
//! coordinates of the vehicle's NED origin); velocities and accelerations are only rotated.

use cdm_math::{Real, Vec3};

/// The scenario coordinates (ENU, metres) of a vehicle's local NED origin (`--vehicle-origin`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VehicleOrigin(pub Vec3);

/// An ENU vector (velocity, acceleration) as NED: north = y, east = x, down = -z.
pub fn enu_to_ned_vector(v: &Vec3) -> Vec3 {
    Vec3::new(v.y, v.x, -v.z)
}

/// A NED vector as ENU: east = y, north = x, up = -z (the map is its own inverse).
pub fn ned_to_enu_vector(v: &Vec3) -> Vec3 {
    Vec3::new(v.y, v.x, -v.z)
}

impl VehicleOrigin {
    /// A scenario point as the vehicle's local NED position.
    pub fn enu_to_ned(&self, p: &Vec3) -> Vec3 {
        enu_to_ned_vector(&(p - self.0))
    }

    /// A local NED position as a scenario point.
    pub fn ned_to_enu(&self, p: &Vec3) -> Vec3 {
        ned_to_enu_vector(p) + self.0
    }
}

/// MAVLink carries f32: the nearest single-precision values of a vector.
pub fn to_f32(v: &Vec3) -> [f32; 3] {
    // Narrowing is the wire format's choice (f32 fields); metres and m/s fit with ~1e-7 relative error.
    [v.x as f32, v.y as f32, v.z as f32]
}

/// A vector from three MAVLink f32 fields.
pub fn from_f32(x: f32, y: f32, z: f32) -> Vec3 {
    Vec3::new(Real::from(x), Real::from(y), Real::from(z))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn east_north_up_becomes_north_east_down() {
        let o = VehicleOrigin::default();
        // 1 m east, 2 m north, 3 m up.
        assert_eq!(
            o.enu_to_ned(&Vec3::new(1.0, 2.0, 3.0)),
            Vec3::new(2.0, 1.0, -3.0)
        );
        assert_eq!(
            o.ned_to_enu(&Vec3::new(2.0, 1.0, -3.0)),
            Vec3::new(1.0, 2.0, 3.0)
        );
    }

    #[test]
    fn origin_is_subtracted_from_points_only() {
        let o = VehicleOrigin(Vec3::new(10.0, 20.0, 1.0));
        assert_eq!(
            o.enu_to_ned(&Vec3::new(12.0, 21.0, 4.0)),
            Vec3::new(1.0, 2.0, -3.0)
        );
        assert_eq!(
            o.ned_to_enu(&Vec3::new(1.0, 2.0, -3.0)),
            Vec3::new(12.0, 21.0, 4.0)
        );
        // A velocity does not depend on where the origin is.
        assert_eq!(
            enu_to_ned_vector(&Vec3::new(0.5, -1.0, 2.0)),
            Vec3::new(-1.0, 0.5, -2.0)
        );
    }

    #[test]
    fn round_trip_restores_the_point() {
        let o = VehicleOrigin(Vec3::new(-3.25, 7.5, 0.125));
        for p in [
            Vec3::new(0.1, -0.2, 0.3),
            Vec3::new(1e3, -1e3, 50.0),
            Vec3::zeros(),
        ] {
            // Subtracting and adding the origin back rounds at most once per component.
            assert!((o.ned_to_enu(&o.enu_to_ned(&p)) - p).amax() <= 1e-12);
            assert_eq!(ned_to_enu_vector(&enu_to_ned_vector(&p)), p);
        }
    }

    #[test]
    fn f32_fields_round_trip_within_single_precision() {
        let v = Vec3::new(1.1, -2.2, 3.3);
        let [x, y, z] = to_f32(&v);
        assert!((from_f32(x, y, z) - v).norm() < 1e-6);
    }
}
