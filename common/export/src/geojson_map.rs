//! `orchestrator export geojson RUN_OR_SCENARIO --out F`: the scenario on a map, as an RFC 7946
//! FeatureCollection written by georust's `geojson` crate: positions are [longitude, latitude]
//! (WGS-84, RFC 7946 Sec. 3.1.1), with the altitude in metres AMSL as a third number for the
//! leaders' paths and ground spots; polygons are closed rings, exterior rings counter-clockwise
//! (the right-hand rule, Sec. 3.1.6). Features, each with `kind` in its properties:
//! - `geofence`: the `[geofence]` polygon, `min_alt_m` and `max_alt_m` its floor and ceiling;
//! - `obstacle`: a box's footprint, or a cylinder's as the 64-gon that contains it (GeoJSON has
//!   no circle; `center` and `radius_m` give the circle itself), with its heights;
//! - `leader_path`: each leader's planned path r_HT(t), take-off to landing, 121 points;
//! - `ground_spot`: each member's spot on the ground before take-off and after landing.
//!
//! Altitudes of flat things (a fence's ceiling, an obstacle's top) are `[origin] alt_m` plus
//! the scenario height; points are geodetic through the tangent plane.

use std::path::{Path, PathBuf};

use geojson::{Feature, FeatureCollection, Geometry, GeometryValue, JsonObject, Position};
use serde_json::json;

use cdm_math::Real;
use cdm_records::rundir::write_atomic;
use cdm_scenario::GeoPoint;

use crate::map::{prepare_out, wound, Footprint, Map, MapSource};
use crate::ExportError;

/// What [`export_geojson`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct GeoJsonExport {
    pub out: PathBuf,
    /// The scenario file the map is of.
    pub file: PathBuf,
    pub fences: usize,
    pub obstacles: usize,
    pub leader_paths: usize,
    pub ground_spots: usize,
    pub bytes: usize,
}

/// Write the map of `source` to `out` (not over an existing file unless `force`).
pub fn export_geojson(
    source: &MapSource,
    out: &Path,
    force: bool,
) -> Result<GeoJsonExport, ExportError> {
    let map = Map::of(source, "geojson")?;
    prepare_out(out, force)?;
    let collection = collection(&map);
    let text = serde_json::to_string_pretty(&collection).map_err(|source| ExportError::Json {
        what: "GeoJSON",
        source,
    })?;
    write_atomic(out, text.as_bytes())?;
    Ok(GeoJsonExport {
        out: out.to_path_buf(),
        file: map.file.clone(),
        fences: usize::from(map.fence.is_some()),
        obstacles: map.obstacles.len(),
        leader_paths: map.leaders.len(),
        ground_spots: map.ground.len(),
        bytes: text.len(),
    })
}

fn lon_lat(p: &GeoPoint) -> Position {
    Position::from([p.lon_deg, p.lat_deg])
}

fn lon_lat_alt(p: &GeoPoint) -> Position {
    Position::from([p.lon_deg, p.lat_deg, p.alt_m])
}

/// A closed, counter-clockwise exterior ring.
fn polygon(ring: Vec<GeoPoint>) -> GeometryValue {
    let mut coords: Vec<Position> = wound(ring, true).iter().map(lon_lat).collect();
    if let Some(first) = coords.first().cloned() {
        coords.push(first);
    }
    GeometryValue::Polygon {
        coordinates: vec![coords],
    }
}

fn feature(value: GeometryValue, properties: serde_json::Value) -> Feature {
    let properties: Option<JsonObject> = match properties {
        serde_json::Value::Object(o) => Some(o),
        _ => None,
    };
    Feature {
        bbox: None,
        geometry: Some(Geometry::new(value)),
        id: None,
        properties,
        foreign_members: None,
    }
}

fn collection(map: &Map) -> FeatureCollection {
    let heights = |min_z: Real, max_z: Real| {
        json!({
            "min_z_m": min_z,
            "max_z_m": max_z,
            "min_alt_m": map.alt_m(min_z),
            "max_alt_m": map.alt_m(max_z),
        })
    };
    let with = |mut base: serde_json::Value, more: serde_json::Value| {
        if let (Some(b), serde_json::Value::Object(m)) = (base.as_object_mut(), more) {
            b.extend(m);
        }
        base
    };
    let mut features = Vec::new();
    if let Some((ring, min_z, max_z)) = &map.fence {
        features.push(feature(
            polygon(ring.clone()),
            with(
                json!({"kind": "geofence", "name": map.name}),
                heights(*min_z, *max_z),
            ),
        ));
    }
    for o in &map.obstacles {
        let (value, shape) = match &o.footprint {
            Footprint::Box(corners) => (polygon(corners.to_vec()), json!({"shape": "box"})),
            Footprint::Circle { center, radius_m } => (
                polygon(map.circle_ring(center, *radius_m)),
                json!({
                    "shape": "cylinder",
                    "center": [center.lon_deg, center.lat_deg],
                    "radius_m": radius_m,
                }),
            ),
        };
        let props = with(
            with(json!({"kind": "obstacle", "name": o.name}), shape),
            heights(o.min_z_m, o.max_z_m),
        );
        features.push(feature(value, props));
    }
    for l in &map.leaders {
        features.push(feature(
            GeometryValue::LineString {
                coordinates: l.points.iter().map(lon_lat_alt).collect(),
            },
            json!({"kind": "leader_path", "agent": l.agent, "role": l.role}),
        ));
    }
    for g in &map.ground {
        features.push(feature(
            GeometryValue::Point {
                coordinates: lon_lat_alt(&g.at),
            },
            json!({"kind": "ground_spot", "agent": g.agent, "phase": g.phase, "z_m": g.z_m}),
        ));
    }
    FeatureCollection::new(features)
}
