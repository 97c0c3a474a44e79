//! A Skybrush show: a `.skyc` ZIP holding `show.json` (Skybrush's show specification): every
//! drone `{type: "generic", settings: {trajectory: {version: 1, points, takeoffTime}, lights}}`
//! with each piece as a degree-5 Bézier curve (a quintic is one exactly: `PolyPiece::bezier`),
//! a constant light program, and `settings.validation` from the certificate and the plan. A
//! mission is one show from its first phase to its last (on the ground at both ends with
//! `[takeoff]` and `[landing]`), each hover a constant segment, the limits over every phase. A
//! scenario's `[geofence]` becomes the show's `geofence`.

use std::io::Write as _;
use std::path::Path;

use base64::Engine as _;
use serde::Serialize;
use zip::write::SimpleFileOptions;

use cdm_certificates::certificate::Certificate;
use cdm_math::{Real, Vec3};
use cdm_records::rundir::write_atomic;
use cdm_scenario::GeofenceSpec;
use cdm_trajectory::{pieces, Cut};

use super::Scaled;
use cdm_team::Failure;

#[derive(Serialize)]
struct Show {
    version: u32,
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
struct ShowSettings {
    validation: Validation,
}

/// Limits Skybrush checks the show against.
#[derive(Serialize)]
struct Validation {
    /// 2 eps: the certificate keeps the balls of radius eps apart (Sec. VI).
    #[serde(rename = "minDistance")]
    min_distance: Real,
    #[serde(rename = "maxVelocityXY")]
    max_velocity_xy: Real,
    #[serde(rename = "maxVelocityZ")]
    max_velocity_z: Real,
    #[serde(rename = "maxAltitude")]
    max_altitude: Real,
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
    let (mut vxy, mut vz, mut zmax) = (0.0, 0.0, Real::NEG_INFINITY);
    for t in &sc.trajs {
        let (a, b) = t.max_speeds();
        vxy = Real::max(vxy, a);
        vz = Real::max(vz, b);
        zmax = zmax.max(t.z_range().1);
    }
    Show {
        version: 1,
        settings: ShowSettings {
            validation: Validation {
                min_distance: 2.0 * cert.numbers.eps_m,
                max_velocity_xy: vxy,
                max_velocity_z: vz,
                max_altitude: zmax,
            },
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

pub fn write(out: &Path, sc: &Scaled, cut: Cut, cert: &Certificate) -> Result<(), Failure> {
    let json = serde_json::to_vec(&show(sc, cut, cert)).map_err(Failure::fault)?;
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts = SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .unix_permissions(0o644);
    let fail = |source: zip::result::ZipError| {
        Failure::fault(cdm_team::errors::CommandError::Zip {
            file: out.to_path_buf(),
            source,
        })
    };
    zip.start_file("show.json", opts).map_err(fail)?;
    zip.write_all(&json)
        .map_err(|e| fail(zip::result::ZipError::Io(e)))?;
    let bytes = zip.finish().map_err(fail)?.into_inner();
    write_atomic(out, &bytes).map_err(Failure::bad_input)
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
