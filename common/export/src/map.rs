//! The scenario on the Earth, for the map exports (GeoJSON, QGroundControl's plan): its fence,
//! obstacles, the leaders' paths and the ground spots, every point through the scenario's
//! `[origin]` (WGS-84; `GeoOrigin::geodetic`). Pure: a scenario in, geographic shapes out.

use std::path::{Path, PathBuf};

use cdm_math::{Real, Vec3};
use cdm_model::airspace::Shape;
use cdm_model::formation::Role;
use cdm_scenario::{Checks, GeoOrigin, GeoPoint, Scenario};
use cdm_trajectory::team_trajectories;

use crate::{roles, ExportError};

/// Points of a leader's path: enough for a map (a quintic between them bends by centimetres).
const PATH_SAMPLES: usize = 120;
/// Vertices of the polygon drawn for a cylinder (map formats have no circle).
pub(crate) const CIRCLE_VERTICES: usize = 64;

/// A scenario file, or the scenario.toml of a run directory.
#[derive(Debug, Clone, PartialEq)]
pub struct MapSource {
    pub path: PathBuf,
}

impl MapSource {
    /// The scenario and the file it came from: a run directory's scenario.toml (as the run
    /// flew it), or a scenario file (fully validated).
    fn open(&self) -> Result<(Scenario, PathBuf), ExportError> {
        if self.path.is_dir() {
            let file = self.path.join("scenario.toml");
            if !file.is_file() {
                return Err(ExportError::NotARun {
                    path: self.path.clone(),
                });
            }
            Ok((Scenario::load(&file, Checks::Member)?, file))
        } else {
            Ok((Scenario::load(&self.path, Checks::Full)?, self.path.clone()))
        }
    }
}

/// A solid the team must not touch, on the map: its footprint and its heights.
pub(crate) struct MapObstacle {
    pub name: String,
    pub footprint: Footprint,
    /// Heights of its bottom and top, metres above scenario z = 0.
    pub min_z_m: Real,
    pub max_z_m: Real,
}

pub(crate) enum Footprint {
    /// A box's four corners, counter-clockwise seen from above in the scenario's frame.
    Box([GeoPoint; 4]),
    /// A cylinder: its centre and radius.
    Circle { center: GeoPoint, radius_m: Real },
}

/// A member on the ground before take-off or after landing.
pub(crate) struct GroundSpot {
    pub agent: u32,
    /// "takeoff" or "landing".
    pub phase: &'static str,
    pub at: GeoPoint,
    /// Its height above scenario z = 0.
    pub z_m: Real,
}

pub(crate) struct LeaderPath {
    pub agent: u32,
    /// "primary" or "secondary".
    pub role: &'static str,
    pub points: Vec<GeoPoint>,
}

/// Everything a map export draws.
pub(crate) struct Map {
    pub origin: GeoOrigin,
    pub file: PathBuf,
    pub name: String,
    /// The inclusion polygon (in the file's order) and its floor and ceiling.
    pub fence: Option<(Vec<GeoPoint>, Real, Real)>,
    pub obstacles: Vec<MapObstacle>,
    pub leaders: Vec<LeaderPath>,
    pub ground: Vec<GroundSpot>,
    /// The lowest start height of the team above scenario z = 0 (its formation before it
    /// deforms; with a take-off, above its ground spots).
    pub start_z_m: Real,
    /// The largest horizontal speed of any member over the plan, m/s.
    pub peak_speed_xy_m_s: Real,
    /// The `[vehicle]` horizontal speed limit, if the file sets one.
    pub max_speed_xy_m_s: Option<Real>,
}

impl Map {
    /// The map of `source`; `export` names the export in the error of a file without `[origin]`.
    pub fn of(source: &MapSource, export: &'static str) -> Result<Map, ExportError> {
        let (s, file) = source.open()?;
        let Some(origin) = s.file.geo_origin else {
            return Err(ExportError::NoOrigin { export, file });
        };
        let fence = s.file.geofence.as_ref().map(|f| {
            let ring = f
                .polygon
                .iter()
                .map(|v| origin.geodetic(&Vec3::new(v[0], v[1], 0.0)))
                .collect();
            (ring, f.min_z_m, f.max_z_m)
        });
        let obstacles = s
            .file
            .obstacles
            .iter()
            .map(|o| obstacle(&origin, &o.name, o.shape()))
            .collect();
        let (leaders, ground, peak) = paths(&s, &origin);
        let start_z_m = s
            .file
            .agents
            .iter()
            .map(|a| a.position[2])
            .fold(Real::INFINITY, Real::min);
        Ok(Map {
            origin,
            file,
            name: s.file.name.clone(),
            fence,
            obstacles,
            leaders,
            ground,
            start_z_m,
            peak_speed_xy_m_s: peak,
            max_speed_xy_m_s: s.file.vehicle.and_then(|v| v.max_speed_xy_m_s),
        })
    }

    /// The altitude above mean sea level of scenario height `z_m` (at the origin: the tangent
    /// plane's drop below the ellipsoid is 2 cm at 500 m, 2 m at 5 km).
    pub fn alt_m(&self, z_m: Real) -> Real {
        self.origin.alt_m + z_m
    }

    /// A circle of the scenario as a polygon that contains it: `CIRCLE_VERTICES` vertices at
    /// radius r / cos(pi / n), so every side touches the circle from outside.
    pub fn circle_ring(&self, center: &GeoPoint, radius_m: Real) -> Vec<GeoPoint> {
        let c = self.origin.local(center);
        let n = CIRCLE_VERTICES;
        let r = radius_m / (std::f64::consts::PI / n as Real).cos();
        (0..n)
            .map(|k| {
                let a = 2.0 * std::f64::consts::PI * k as Real / n as Real;
                self.origin
                    .geodetic(&Vec3::new(c.x + r * a.cos(), c.y + r * a.sin(), 0.0))
            })
            .collect()
    }
}

fn obstacle(origin: &GeoOrigin, name: &str, shape: Shape) -> MapObstacle {
    let at = |x: Real, y: Real| origin.geodetic(&Vec3::new(x, y, 0.0));
    let (footprint, min_z_m, max_z_m) = match shape {
        Shape::Box { min, max } => (
            Footprint::Box([
                at(min[0], min[1]),
                at(max[0], min[1]),
                at(max[0], max[1]),
                at(min[0], max[1]),
            ]),
            min[2],
            max[2],
        ),
        Shape::Cylinder {
            center,
            radius_m,
            min_z_m,
            max_z_m,
        } => (
            Footprint::Circle {
                center: at(center[0], center[1]),
                radius_m,
            },
            min_z_m,
            max_z_m,
        ),
    };
    MapObstacle {
        name: name.to_string(),
        footprint,
        min_z_m,
        max_z_m,
    }
}

/// The leaders' planned paths, the ground spots, and the team's peak horizontal speed.
fn paths(s: &Scenario, origin: &GeoOrigin) -> (Vec<LeaderPath>, Vec<GroundSpot>, Real) {
    let trajs = team_trajectories(s);
    let end_s = s.plan.end_s();
    let mut leaders = Vec::new();
    let mut ground = Vec::new();
    let mut peak: Real = 0.0;
    for (t, role) in trajs.iter().zip(roles(s)) {
        peak = peak.max(t.max_speeds().0);
        if role.is_leader() {
            leaders.push(LeaderPath {
                agent: t.id,
                role: if role == Role::Primary {
                    "primary"
                } else {
                    "secondary"
                },
                points: (0..=PATH_SAMPLES)
                    .map(|k| origin.geodetic(&t.position(end_s * k as Real / PATH_SAMPLES as Real)))
                    .collect(),
            });
        }
        for (phase, when, on) in [
            ("takeoff", 0.0, s.file.takeoff.is_some()),
            ("landing", end_s, s.file.landing.is_some()),
        ] {
            if on {
                let p = t.position(when);
                ground.push(GroundSpot {
                    agent: t.id,
                    phase,
                    at: origin.geodetic(&p),
                    z_m: p.z,
                });
            }
        }
    }
    (leaders, ground, peak)
}

/// Twice the signed area of a ring in (longitude, latitude): positive counter-clockwise.
pub(crate) fn signed_area(ring: &[GeoPoint]) -> Real {
    let n = ring.len();
    (0..n)
        .map(|i| {
            let (a, b) = (&ring[i], &ring[(i + 1) % n]);
            a.lon_deg * b.lat_deg - b.lon_deg * a.lat_deg
        })
        .sum()
}

/// `ring` in the winding asked for (counter-clockwise when `ccw`), seen in (longitude,
/// latitude).
pub(crate) fn wound(mut ring: Vec<GeoPoint>, ccw: bool) -> Vec<GeoPoint> {
    if (signed_area(&ring) > 0.0) != ccw {
        ring.reverse();
    }
    ring
}

/// The out path's directory created, for a single-file export.
pub(crate) fn prepare_out(out: &Path, force: bool) -> Result<(), ExportError> {
    crate::refuse_existing(out, force)?;
    crate::beside(out).map(|_| ())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(lon: Real, lat: Real) -> GeoPoint {
        GeoPoint {
            lat_deg: lat,
            lon_deg: lon,
            alt_m: 0.0,
        }
    }

    #[test]
    fn rings_are_wound_as_asked() {
        let ccw = vec![p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)];
        assert!(signed_area(&ccw) > 0.0);
        assert!(signed_area(&wound(ccw.clone(), false)) < 0.0);
        assert!(signed_area(&wound(ccw.clone(), true)) > 0.0);
        let cw: Vec<_> = ccw.iter().rev().copied().collect();
        assert!(signed_area(&wound(cw, true)) > 0.0);
    }
}
