//! A Skybrush show: a `.skyc` ZIP holding `show.json` (Skybrush's show specification): every
//! drone `{type: "generic", settings: {trajectory: {version: 1, points, takeoffTime}, lights}}`
//! with each piece as a degree-5 Bézier curve (a quintic is one exactly: `PolyPiece::bezier`),
//! a constant light program, and `settings.validation` from the certificate and the plan. A
//! mission is one show from its first phase to its last (on the ground at both ends with
//! `[takeoff]` and `[landing]`), each hover a constant segment, the limits over every phase. A
//! scenario's `[geofence]` becomes the show's `geofence`.
//!
//! A scenario's `[origin]` and `[vehicle]` (absent: the show's bytes are as without them) go
//! where Skybrush reads them (skybrush-io/skybrush.js, packages/show-format/src/types.ts:
//! `ShowSpecification.environment`, `Location`, `ValidationSettings`):
//! - `environment = {type: "outdoor", location: {origin, orientation}}`: `origin` is
//!   [latitude 1e-7 degree, longitude 1e-7 degree, altitude AMSL in mm], integers, as Skybrush
//!   Studio writes it (skybrush-io/studio-blender, src/modules/sbstudio/model/location.py,
//!   `ShowLocation.json`) and Skybrush Live reads it (skybrush-io/live, src/utils/geography.ts,
//!   `toLonLatFromScaledJSON`); `orientation` is the bearing of the show's +x axis in degrees
//!   from north towards east, which is `[origin] heading_deg`.
//! - `settings.validation`: `maxVelocityXY`, `maxVelocityZ` (down, once `maxVelocityZUp` is
//!   given), `maxVelocityZUp`, `maxAccelerationXY`, `maxAccelerationZ`, as Studio's safety
//!   check writes them (studio-blender, src/modules/sbstudio/model/safety_check.py,
//!   `SafetyCheckParams.as_dict`), from the `[vehicle]` limits; a limit the table leaves out
//!   stays the plan's own peak as before.

use std::io::Write as _;
use std::path::Path;

use base64::Engine as _;
use serde::Serialize;
use zip::write::SimpleFileOptions;

use cdm_certificates::certificate::Certificate;
use cdm_math::{Real, Vec3};
use cdm_records::rundir::write_atomic;
use cdm_scenario::{GeoOrigin, GeofenceSpec};
use cdm_trajectory::{pieces, Cut};

use super::Scaled;
use crate::ExportError;

#[derive(Serialize)]
struct Show {
    version: u32,
    /// With an `[origin]` only.
    #[serde(skip_serializing_if = "Option::is_none")]
    environment: Option<Environment>,
    settings: ShowSettings,
    swarm: Swarm,
    /// The scenario's `[geofence]`, absent without one.
    #[serde(skip_serializing_if = "Option::is_none")]
    geofence: Option<Geofence>,
    meta: Meta,
}

/// A show's geofence as skybrush-server reads it (`show.geofence`, version 1): inclusion
/// polygons in the show's own x, y frame, and the altitude range. Skybrush's polygons have no
/// height, so the scenario's obstacles (boxes and cylinders the team may fly over) have no
/// place here; they are certified at the target scale instead, and written by the Crazyswarm2
/// export.
#[derive(Serialize)]
struct Geofence {
    version: u32,
    enabled: bool,
    #[serde(rename = "minAltitude")]
    min_altitude: Real,
    #[serde(rename = "maxAltitude")]
    max_altitude: Real,
    polygons: Vec<FencePolygon>,
}

#[derive(Serialize)]
struct FencePolygon {
    #[serde(rename = "isInclusion")]
    is_inclusion: bool,
    points: Vec<[Real; 2]>,
}

impl Geofence {
    /// The scenario's fence, already in the target frame (`TargetFrame::apply` moved it).
    fn of(spec: &GeofenceSpec) -> Self {
        Geofence {
            version: 1,
            enabled: true,
            min_altitude: spec.min_z_m,
            max_altitude: spec.max_z_m,
            polygons: vec![FencePolygon {
                is_inclusion: true,
                points: spec.polygon.clone(),
            }],
        }
    }
}

#[derive(Serialize)]
struct Environment {
    #[serde(rename = "type")]
    kind: &'static str,
    location: Location,
}

#[derive(Serialize)]
struct Location {
    /// [lat 1e-7 deg, lon 1e-7 deg, AMSL mm].
    origin: [i64; 3],
    /// Degrees from north towards east.
    orientation: Real,
}

impl Location {
    fn of(o: &GeoOrigin) -> Self {
        Location {
            origin: [
                (o.lat_deg * 1e7).round() as i64,
                (o.lon_deg * 1e7).round() as i64,
                (o.alt_m * 1e3).round() as i64,
            ],
            orientation: o.heading_deg,
        }
    }
}

#[derive(Serialize)]
struct ShowSettings {
    validation: Validation,
}

/// Limits Skybrush checks the show against.
#[derive(Serialize, Debug, Clone, PartialEq)]
pub struct Validation {
    /// 2 eps: the certificate keeps the balls of radius eps apart (Sec. VI).
    #[serde(rename = "minDistance")]
    pub min_distance: Real,
    #[serde(rename = "maxVelocityXY")]
    pub max_velocity_xy: Real,
    #[serde(rename = "maxVelocityZ")]
    pub max_velocity_z: Real,
    #[serde(rename = "maxAltitude")]
    pub max_altitude: Real,
    #[serde(rename = "maxVelocityZUp", skip_serializing_if = "Option::is_none")]
    pub max_velocity_z_up: Option<Real>,
    #[serde(rename = "maxAccelerationXY", skip_serializing_if = "Option::is_none")]
    pub max_acceleration_xy: Option<Real>,
    #[serde(rename = "maxAccelerationZ", skip_serializing_if = "Option::is_none")]
    pub max_acceleration_z: Option<Real>,
}

/// Where a show sits on the Earth and what Skybrush validates it against.
#[derive(Debug, Clone, PartialEq)]
pub struct ShowFrame {
    /// The scenario's `[origin]`: the show's (0, 0, 0) and the bearing of its +x axis.
    pub location: Option<GeoOrigin>,
    pub validation: Validation,
}

/// The show's frame and limits as [`write`] puts them in show.json.
pub fn frame(sc: &Scaled, cert: &Certificate) -> ShowFrame {
    ShowFrame {
        location: sc.scenario.file.geo_origin,
        validation: validation(sc, cert),
    }
}

/// The plan's own peaks, replaced by the `[vehicle]` limits the file sets.
fn validation(sc: &Scaled, cert: &Certificate) -> Validation {
    let (mut vxy, mut vz, mut zmax) = (0.0, 0.0, Real::NEG_INFINITY);
    for t in &sc.trajs {
        let (a, b) = t.max_speeds();
        vxy = Real::max(vxy, a);
        vz = Real::max(vz, b);
        zmax = zmax.max(t.z_range().1);
    }
    let v = sc.scenario.file.vehicle.unwrap_or_default();
    // maxVelocityZ limits both ways until maxVelocityZUp is given: a table with only a descent
    // limit keeps the climb at the plan's peak.
    let up = v.max_speed_up_m_s.or(v.max_speed_down_m_s.map(|_| vz));
    Validation {
        min_distance: 2.0 * cert.numbers.eps_m,
        max_velocity_xy: v.max_speed_xy_m_s.unwrap_or(vxy),
        max_velocity_z: v.max_speed_down_m_s.unwrap_or(vz),
        max_altitude: zmax,
        max_velocity_z_up: up,
        max_acceleration_xy: v.max_accel_xy_m_s2,
        max_acceleration_z: v.max_accel_z_m_s2,
    }
}

#[derive(Serialize)]
struct Swarm {
    drones: Vec<Drone>,
}

#[derive(Serialize)]
struct Drone {
    #[serde(rename = "type")]
    kind: &'static str,
    settings: DroneSettings,
}

#[derive(Serialize)]
struct DroneSettings {
    name: String,
    home: [Real; 3],
    trajectory: Trajectory,
    lights: Lights,
}

/// `points`: [t, end point, inner control points]; the first has no control points.
#[derive(Serialize)]
struct Trajectory {
    version: u32,
    points: Vec<(Real, [Real; 3], Vec<[Real; 3]>)>,
    #[serde(rename = "takeoffTime")]
    takeoff_time: Real,
}

#[derive(Serialize)]
struct Lights {
    version: u32,
    data: String,
}

#[derive(Serialize)]
struct Meta {
    title: String,
}

fn arr(v: Vec3) -> [Real; 3] {
    [v.x, v.y, v.z]
}

/// The constant light program in Skybrush's light bytecode (pyledctrl `CommandCode`):
/// SET_COLOR (0x04) r g b, a duration in frames at 50 fps as a varuint, then END (0x00).
fn constant_light(rgb: [u8; 3], seconds: Real) -> Vec<u8> {
    let mut frames = (seconds * 50.0)
        .ceil()
        .clamp(0.0, (1u64 << 28) as Real - 1.0) as u64;
    let mut code = vec![0x04, rgb[0], rgb[1], rgb[2]];
    loop {
        let low = (frames & 0x7f) as u8;
        frames >>= 7;
        if frames == 0 {
            code.push(low);
            break;
        }
        code.push(low | 0x80);
    }
    code.push(0x00);
    code
}

fn show(sc: &Scaled, cut: Cut, cert: &Certificate) -> Show {
    let t_total = sc.duration_s;
    let light =
        base64::engine::general_purpose::STANDARD.encode(constant_light([255, 255, 255], t_total));
    let drones = sc
        .trajs
        .iter()
        .map(|t| {
            let start = t.position(0.0);
            let mut points = vec![(0.0, arr(start), Vec::new())];
            for p in pieces(t, cut) {
                let cp = p.bezier();
                points.push((
                    p.t0_s + p.duration_s,
                    arr(cp[5]),
                    cp[1..5].iter().map(|c| arr(*c)).collect(),
                ));
            }
            Drone {
                kind: "generic",
                settings: DroneSettings {
                    name: format!("cdm-{}", t.id),
                    home: arr(start),
                    trajectory: Trajectory {
                        version: 1,
                        points,
                        takeoff_time: 0.0,
                    },
                    lights: Lights {
                        version: 1,
                        data: light.clone(),
                    },
                },
            }
        })
        .collect();
    Show {
        version: 1,
        environment: sc.scenario.file.geo_origin.as_ref().map(|o| Environment {
            kind: "outdoor",
            location: Location::of(o),
        }),
        settings: ShowSettings {
            validation: validation(sc, cert),
        },
        swarm: Swarm { drones },
        geofence: sc.scenario.file.geofence.as_ref().map(Geofence::of),
        meta: Meta {
            title: format!(
                "{} (continuum deformation, scale {}, certificate {})",
                sc.scenario.file.name, sc.frame.scale, cert.verdict
            ),
        },
    }
}

pub fn write(out: &Path, sc: &Scaled, cut: Cut, cert: &Certificate) -> Result<(), ExportError> {
    let json = serde_json::to_vec(&show(sc, cut, cert)).map_err(|source| ExportError::Json {
        what: "show.json",
        source,
    })?;
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts = SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .unix_permissions(0o644);
    let fail = |source: zip::result::ZipError| ExportError::Zip {
        file: out.to_path_buf(),
        source,
    };
    zip.start_file("show.json", opts).map_err(fail)?;
    zip.write_all(&json)
        .map_err(|e| fail(zip::result::ZipError::Io(e)))?;
    let bytes = zip.finish().map_err(fail)?.into_inner();
    Ok(write_atomic(out, &bytes)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_program_is_set_color_then_end() {
        // 200 s = 10000 frames = 0x2710: varuint 0x90 0x4e.
        assert_eq!(
            constant_light([1, 2, 3], 200.0),
            vec![0x04, 1, 2, 3, 0x90, 0x4e, 0x00]
        );
        assert_eq!(
            constant_light([0, 0, 0], 1.0),
            vec![0x04, 0, 0, 0, 50, 0x00]
        );
    }
}
