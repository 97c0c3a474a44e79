//! `orchestrator export qgc-plan RUN_OR_SCENARIO --out F`: QGroundControl's `.plan` file, so an
//! operator sees the scenario's fence in the ground station they already use. The format is
//! QGroundControl's own JSON, as its developer guide documents it ("Plan File Format",
//! docs.qgroundcontrol.com, qgc-dev-guide/file_formats/plan): `fileType` "Plan", `version` 1,
//! `groundStation`, and
//! - `geoFence` (version 2): `polygons`, each {inclusion, polygon: [[lat, lon], ...] clockwise,
//!   version 1}, the `[geofence]` polygon as the inclusion and each box obstacle's footprint
//!   as an exclusion; `circles`, each {circle: {center: [lat, lon], radius}, inclusion,
//!   version 1}, each cylinder obstacle as an exclusion circle. As on the autopilots, the zones
//!   are columns: the fence's floor and ceiling and the obstacles' heights are not in the file.
//! - `rallyPoints` (version 2): [lat, lon, altitude above home]: the members' landing spots (or
//!   take-off spots), where a vehicle is safe on the ground; none without a `[landing]` or
//!   `[takeoff]`.
//! - `mission` (version 2): `plannedHomePosition` [lat, lon, AMSL] is the `[origin]`;
//!   `firmwareType` 0 (MAV_AUTOPILOT_GENERIC: the same file for PX4 and ArduPilot),
//!   `vehicleType` 2 (MAV_TYPE_QUADROTOR), `hoverSpeed` and `cruiseSpeed` the `[vehicle]`
//!   horizontal speed limit (else the plan's peak), and the one item the format requires: a
//!   take-off (MAV_CMD_NAV_TAKEOFF, 22, frame 3 MAV_FRAME_GLOBAL_RELATIVE_ALT) at home to the
//!   team's lowest start height. The team itself is flown by the orchestrator, not by this
//!   mission.
//!
//! No Rust crate reads or writes the format, so these are serde structs of the documented keys.

use std::path::{Path, PathBuf};

use serde::Serialize;

use cdm_math::Real;
use cdm_records::rundir::write_atomic;
use cdm_scenario::GeoPoint;

use crate::map::{prepare_out, wound, Footprint, Map, MapSource};
use crate::ExportError;

/// What [`export_qgc_plan`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct QgcPlanExport {
    pub out: PathBuf,
    pub file: PathBuf,
    /// Inclusion and exclusion polygons.
    pub polygons: usize,
    pub circles: usize,
    pub rally_points: usize,
    pub bytes: usize,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
struct Plan {
    file_type: &'static str,
    geo_fence: GeoFence,
    ground_station: &'static str,
    mission: Mission,
    rally_points: RallyPoints,
    version: u32,
}

#[derive(Serialize)]
struct GeoFence {
    circles: Vec<CircleFence>,
    polygons: Vec<PolygonFence>,
    version: u32,
}

#[derive(Serialize)]
struct CircleFence {
    circle: Circle,
    inclusion: bool,
    version: u32,
}

#[derive(Serialize)]
struct Circle {
    center: [Real; 2],
    radius: Real,
}

#[derive(Serialize)]
struct PolygonFence {
    inclusion: bool,
    polygon: Vec<[Real; 2]>,
    version: u32,
}

#[derive(Serialize)]
struct RallyPoints {
    points: Vec<[Real; 3]>,
    version: u32,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
struct Mission {
    cruise_speed: Real,
    firmware_type: u32,
    global_plan_altitude_mode: u32,
    hover_speed: Real,
    items: Vec<SimpleItem>,
    planned_home_position: [Real; 3],
    vehicle_type: u32,
    version: u32,
}

#[derive(Serialize)]
struct SimpleItem {
    #[serde(rename = "AMSLAltAboveTerrain")]
    amsl_alt_above_terrain: Option<Real>,
    #[serde(rename = "Altitude")]
    altitude: Real,
    #[serde(rename = "AltitudeMode")]
    altitude_mode: u32,
    #[serde(rename = "autoContinue")]
    auto_continue: bool,
    command: u32,
    #[serde(rename = "doJumpId")]
    do_jump_id: u32,
    frame: u32,
    params: [Option<Real>; 7],
    #[serde(rename = "type")]
    kind: &'static str,
}

/// MAV_CMD_NAV_TAKEOFF.
const NAV_TAKEOFF: u32 = 22;
/// MAV_FRAME_GLOBAL_RELATIVE_ALT: altitudes above home.
const FRAME_RELATIVE_ALT: u32 = 3;
/// QGroundControl's altitude mode "relative to launch".
const ALTITUDE_RELATIVE: u32 = 1;

/// Write the plan of `source` to `out` (not over an existing file unless `force`).
pub fn export_qgc_plan(
    source: &MapSource,
    out: &Path,
    force: bool,
) -> Result<QgcPlanExport, ExportError> {
    let map = Map::of(source, "qgc-plan")?;
    prepare_out(out, force)?;
    let plan = plan(&map);
    let text = serde_json::to_string_pretty(&plan).map_err(|source| ExportError::Json {
        what: "QGroundControl plan",
        source,
    })?;
    write_atomic(out, text.as_bytes())?;
    Ok(QgcPlanExport {
        out: out.to_path_buf(),
        file: map.file.clone(),
        polygons: plan.geo_fence.polygons.len(),
        circles: plan.geo_fence.circles.len(),
        rally_points: plan.rally_points.points.len(),
        bytes: text.len(),
    })
}

fn lat_lon(p: &GeoPoint) -> [Real; 2] {
    [p.lat_deg, p.lon_deg]
}

/// QGroundControl's polygons are clockwise.
fn clockwise(ring: Vec<GeoPoint>, inclusion: bool) -> PolygonFence {
    PolygonFence {
        inclusion,
        polygon: wound(ring, false).iter().map(lat_lon).collect(),
        version: 1,
    }
}

fn plan(map: &Map) -> Plan {
    let mut polygons = Vec::new();
    let mut circles = Vec::new();
    if let Some((ring, _, _)) = &map.fence {
        polygons.push(clockwise(ring.clone(), true));
    }
    for o in &map.obstacles {
        match &o.footprint {
            Footprint::Box(corners) => polygons.push(clockwise(corners.to_vec(), false)),
            Footprint::Circle { center, radius_m } => circles.push(CircleFence {
                circle: Circle {
                    center: lat_lon(center),
                    radius: *radius_m,
                },
                inclusion: false,
                version: 1,
            }),
        }
    }
    let landing = map.ground.iter().any(|g| g.phase == "landing");
    let rally = map
        .ground
        .iter()
        .filter(|g| (g.phase == "landing") == landing)
        .map(|g| [g.at.lat_deg, g.at.lon_deg, g.z_m])
        .collect();
    let home = map.origin;
    let speed = map.max_speed_xy_m_s.unwrap_or(map.peak_speed_xy_m_s);
    let climb = map.start_z_m.max(0.0);
    Plan {
        file_type: "Plan",
        geo_fence: GeoFence {
            circles,
            polygons,
            version: 2,
        },
        ground_station: "cdm orchestrator",
        mission: Mission {
            cruise_speed: speed,
            firmware_type: 0,
            global_plan_altitude_mode: ALTITUDE_RELATIVE,
            hover_speed: speed,
            items: vec![SimpleItem {
                amsl_alt_above_terrain: None,
                altitude: climb,
                altitude_mode: ALTITUDE_RELATIVE,
                auto_continue: true,
                command: NAV_TAKEOFF,
                do_jump_id: 1,
                frame: FRAME_RELATIVE_ALT,
                params: [
                    Some(0.0),
                    Some(0.0),
                    Some(0.0),
                    None,
                    Some(home.lat_deg),
                    Some(home.lon_deg),
                    Some(climb),
                ],
                kind: "SimpleItem",
            }],
            planned_home_position: [home.lat_deg, home.lon_deg, home.alt_m],
            vehicle_type: 2,
            version: 2,
        },
        rally_points: RallyPoints {
            points: rally,
            version: 2,
        },
        version: 1,
    }
}
