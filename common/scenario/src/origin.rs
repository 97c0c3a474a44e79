//! `[origin]`: where the scenario's frame sits on the Earth. The scenario stays in metres; the
//! table anchors its (0, 0, 0) at a latitude, longitude and altitude and turns its +x axis to a
//! bearing, so a point of the scenario has a WGS-84 position and a GPS fix a scenario point.
//!
//! The local frame is the tangent plane at the origin (east, north, up on the WGS-84 ellipsoid),
//! turned about up by the heading. It is a rigid motion of Earth-centred, Earth-fixed
//! coordinates, so a distance between two scenario points (what the certificate proves about
//! separation) is their true distance in space. The conversions are `map_3d`'s (a port of
//! pymap3d's tangent-plane routines: geodetic <-> ECEF <-> ENU on the WGS-84 ellipsoid).
//!
//! `alt_m` is taken as the height of scenario z = 0 and every altitude is that height plus the
//! geodetic height difference on the ellipsoid: the geoid's slope over a team is not modelled
//! (the geoid undulation changes by well under a metre over 5 km in most places).

use serde::{Deserialize, Serialize};

use super::ScenarioErrorKind as E;
use crate::fields::finite;
use cdm_math::{Real, Vec3};

/// `[origin]` as the file gives it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeoOrigin {
    /// Latitude of scenario (0, 0, 0), degrees north, WGS-84.
    pub lat_deg: Real,
    /// Longitude of scenario (0, 0, 0), degrees east, WGS-84.
    pub lon_deg: Real,
    /// Altitude of scenario z = 0, metres above mean sea level.
    pub alt_m: Real,
    /// The bearing of the scenario's +x axis, degrees clockwise from north (90: +x east, +y
    /// north, the scenario is east-north-up).
    pub heading_deg: Real,
}

/// A WGS-84 position: degrees, and metres above mean sea level.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GeoPoint {
    pub lat_deg: Real,
    pub lon_deg: Real,
    pub alt_m: Real,
}

impl GeoOrigin {
    /// The first field that makes it unusable: latitude outside [-90, 90], longitude outside
    /// [-180, 180], anything not finite.
    pub(crate) fn check(&self) -> Result<(), E> {
        finite("origin.lat_deg", self.lat_deg)?;
        finite("origin.lon_deg", self.lon_deg)?;
        finite("origin.alt_m", self.alt_m)?;
        finite("origin.heading_deg", self.heading_deg)?;
        let range = |field: &str, v: Real, max: Real| {
            if v.abs() > max {
                return Err(E::Invalid {
                    field: field.into(),
                    reason: format!("must be in [-{max}, {max}] degrees, got {v}"),
                });
            }
            Ok(())
        };
        range("origin.lat_deg", self.lat_deg, 90.0)?;
        range("origin.lon_deg", self.lon_deg, 180.0)
    }

    /// A scenario vector (velocity, offset) in east, north, up: turned by the heading.
    /// +x points along the bearing h, +y 90 degrees to its left (the frame stays right-handed):
    /// x = (sin h, cos h), y = (-cos h, sin h) in (east, north).
    pub fn enu_of(&self, v: &Vec3) -> Vec3 {
        let (s, c) = self.heading_deg.to_radians().sin_cos();
        Vec3::new(v.x * s - v.y * c, v.x * c + v.y * s, v.z)
    }

    /// An east, north, up vector in the scenario's axes (the inverse of [`Self::enu_of`]).
    pub fn scenario_of(&self, enu: &Vec3) -> Vec3 {
        let (s, c) = self.heading_deg.to_radians().sin_cos();
        Vec3::new(enu.x * s + enu.y * c, -enu.x * c + enu.y * s, enu.z)
    }

    /// The WGS-84 position of scenario point `p`.
    pub fn geodetic(&self, p: &Vec3) -> GeoPoint {
        let enu = self.enu_of(p);
        let (lat, lon, alt) = map_3d::enu2geodetic(
            enu.x,
            enu.y,
            enu.z,
            self.lat_deg.to_radians(),
            self.lon_deg.to_radians(),
            self.alt_m,
            map_3d::Ellipsoid::WGS84,
        );
        GeoPoint {
            lat_deg: lat.to_degrees(),
            lon_deg: wrap_lon_deg(lon.to_degrees()),
            alt_m: alt,
        }
    }

    /// The scenario point at WGS-84 position `g`.
    pub fn local(&self, g: &GeoPoint) -> Vec3 {
        let (e, n, u) = map_3d::geodetic2enu(
            g.lat_deg.to_radians(),
            g.lon_deg.to_radians(),
            g.alt_m,
            self.lat_deg.to_radians(),
            self.lon_deg.to_radians(),
            self.alt_m,
            map_3d::Ellipsoid::WGS84,
        );
        self.scenario_of(&Vec3::new(e, n, u))
    }
}

/// A longitude in (-180, 180] degrees.
fn wrap_lon_deg(lon: Real) -> Real {
    let w = (lon + 180.0).rem_euclid(360.0) - 180.0;
    if w == -180.0 {
        180.0
    } else {
        w
    }
}

/// `[origin]`'s checks (the loader's `check_numbers` calls this).
pub(crate) fn check_table(f: &super::ScenarioFile) -> Result<(), E> {
    f.geo_origin.as_ref().map_or(Ok(()), GeoOrigin::check)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// PX4's SITL home (47.397742 N, 8.545594 E, 488 m).
    fn zurich(heading_deg: Real) -> GeoOrigin {
        GeoOrigin {
            lat_deg: 47.397742,
            lon_deg: 8.545594,
            alt_m: 488.0,
            heading_deg,
        }
    }

    #[test]
    fn the_heading_turns_the_axes_clockwise_from_north() {
        let x = Vec3::new(1.0, 0.0, 0.0);
        let y = Vec3::new(0.0, 1.0, 0.0);
        // 0: +x north, +y west; 90: +x east, +y north.
        assert!((zurich(0.0).enu_of(&x) - Vec3::new(0.0, 1.0, 0.0)).norm() < 1e-15);
        assert!((zurich(0.0).enu_of(&y) - Vec3::new(-1.0, 0.0, 0.0)).norm() < 1e-15);
        assert!((zurich(90.0).enu_of(&x) - x).norm() < 1e-15);
        assert!((zurich(90.0).enu_of(&y) - y).norm() < 1e-15);
        let o = zurich(33.0);
        let v = Vec3::new(3.0, -4.0, 5.0);
        assert!((o.scenario_of(&o.enu_of(&v)) - v).norm() < 1e-12);
    }

    #[test]
    fn a_point_north_of_the_origin_has_a_greater_latitude() {
        let o = zurich(0.0);
        let g = o.geodetic(&Vec3::new(1000.0, 0.0, 10.0));
        assert!(g.lat_deg > o.lat_deg);
        assert!((g.lon_deg - o.lon_deg).abs() < 1e-9);
        // 1 km north is about 1/111.2 of a degree here; the tangent plane rises above the
        // ellipsoid by about d^2 / 2R = 0.08 m at 1 km.
        assert!((g.lat_deg - o.lat_deg - 1000.0 / 111_200.0).abs() < 1e-4);
        assert!((g.alt_m - 498.078).abs() < 1e-3, "{}", g.alt_m);
        let back = o.local(&g);
        assert!(
            (back - Vec3::new(1000.0, 0.0, 10.0)).norm() < 1e-6,
            "{back:?}"
        );
    }

    #[test]
    fn round_trips_over_five_kilometres_within_a_micrometre() {
        for h in [0.0, 37.5, 90.0, 271.0] {
            let o = zurich(h);
            for p in [
                Vec3::new(5000.0, 0.0, 0.0),
                Vec3::new(-2500.0, 4330.0, 120.0),
                Vec3::new(3535.5, -3535.5, -20.0),
            ] {
                let back = o.local(&o.geodetic(&p));
                assert!((back - p).norm() < 1e-6, "heading {h}: {p:?} -> {back:?}");
            }
        }
    }

    #[test]
    fn the_antimeridian_wraps() {
        let o = GeoOrigin {
            lat_deg: 0.0,
            lon_deg: 180.0,
            alt_m: 0.0,
            heading_deg: 90.0,
        };
        let g = o.geodetic(&Vec3::new(1000.0, 0.0, 0.0));
        assert!(g.lon_deg < -179.99 && g.lon_deg > -180.0, "{}", g.lon_deg);
        assert!((o.local(&g) - Vec3::new(1000.0, 0.0, 0.0)).norm() < 1e-6);
    }

    #[test]
    fn bad_origins_name_the_field() {
        let cases = [
            (
                GeoOrigin {
                    lat_deg: 90.5,
                    ..zurich(0.0)
                },
                "origin.lat_deg",
            ),
            (
                GeoOrigin {
                    lon_deg: -181.0,
                    ..zurich(0.0)
                },
                "origin.lon_deg",
            ),
            (
                GeoOrigin {
                    alt_m: Real::NAN,
                    ..zurich(0.0)
                },
                "origin.alt_m",
            ),
            (zurich(Real::INFINITY), "origin.heading_deg"),
        ];
        for (o, field) in cases {
            let e = o.check().unwrap_err().to_string();
            assert!(e.contains(field), "{field}: {e}");
        }
        assert!(zurich(-45.0).check().is_ok());
    }
}
