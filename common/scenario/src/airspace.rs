//! `[geofence]` and `[[obstacle]]`: the airspace the team may use and what stands in
//! it, as the file gives them, and their checks. The geometry is `cdm_model::airspace`.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};

use super::{ScenarioErrorKind as E, ScenarioFile};
use cdm_math::{Real, Vec2, Vec3};
use cdm_model::airspace::{self_intersection, signed_area2, Fence};
use cdm_model::formation::Formation;

use cdm_model::airspace::Shape;

/// `[geofence]`: the team stays inside the vertical prism over `polygon` (x, y in metres, a
/// simple polygon in either orientation), between `min_z_m` and `max_z_m`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeofenceSpec {
    pub polygon: Vec<[Real; 2]>,
    pub min_z_m: Real,
    pub max_z_m: Real,
}

impl GeofenceSpec {
    /// The fence as geometry.
    pub fn fence(&self) -> Fence {
        Fence {
            polygon: self.polygon.iter().map(|v| Vec2::new(v[0], v[1])).collect(),
            min_z_m: self.min_z_m,
            max_z_m: self.max_z_m,
        }
    }
}

/// `[[obstacle]]`: a named solid the team must not touch. The file gives either a box (`min`,
/// `max`) or a vertical cylinder (`center`, `radius_m`, `min_z_m`, `max_z_m`); read, it is one
/// [`Shape`], so no code re-reads optional fields.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ObstacleTable", into = "ObstacleTable")]
pub struct ObstacleSpec {
    pub name: String,
    pub shape: Shape,
}

impl ObstacleSpec {
    /// Its shape.
    pub fn shape(&self) -> Shape {
        self.shape
    }

    /// How messages name it: `obstacle "tower"`.
    pub fn label(&self) -> String {
        format!("obstacle {:?}", self.name)
    }
}

/// An `[[obstacle]]` table as written (the file's keys).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ObstacleTable {
    name: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    min: Option<[Real; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    max: Option<[Real; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    center: Option<[Real; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    radius_m: Option<Real>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    min_z_m: Option<Real>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    max_z_m: Option<Real>,
}

/// An obstacle table that is neither a box nor a vertical cylinder.
#[derive(Debug, thiserror::Error)]
#[error("obstacle {name:?}: give either `min` and `max` (a box) or `center`, `radius_m`, `min_z_m` and `max_z_m` (a vertical cylinder)")]
pub struct ObstacleShapeError {
    /// The obstacle's name.
    pub name: String,
}

impl TryFrom<ObstacleTable> for ObstacleSpec {
    type Error = ObstacleShapeError;

    fn try_from(t: ObstacleTable) -> Result<Self, ObstacleShapeError> {
        let shape = match t {
            ObstacleTable {
                min: Some(min),
                max: Some(max),
                center: None,
                radius_m: None,
                min_z_m: None,
                max_z_m: None,
                ..
            } => Shape::Box { min, max },
            ObstacleTable {
                min: None,
                max: None,
                center: Some(center),
                radius_m: Some(radius_m),
                min_z_m: Some(min_z_m),
                max_z_m: Some(max_z_m),
                ..
            } => Shape::Cylinder {
                center,
                radius_m,
                min_z_m,
                max_z_m,
            },
            _ => return Err(ObstacleShapeError { name: t.name }),
        };
        Ok(ObstacleSpec {
            name: t.name,
            shape,
        })
    }
}

impl From<ObstacleSpec> for ObstacleTable {
    fn from(o: ObstacleSpec) -> Self {
        let mut t = ObstacleTable {
            name: o.name,
            min: None,
            max: None,
            center: None,
            radius_m: None,
            min_z_m: None,
            max_z_m: None,
        };
        match o.shape {
            Shape::Box { min, max } => (t.min, t.max) = (Some(min), Some(max)),
            Shape::Cylinder {
                center,
                radius_m,
                min_z_m,
                max_z_m,
            } => {
                t.center = Some(center);
                t.radius_m = Some(radius_m);
                t.min_z_m = Some(min_z_m);
                t.max_z_m = Some(max_z_m);
            }
        }
        t
    }
}

/// True when the file has a fence or an obstacle.
pub fn has_airspace(f: &ScenarioFile) -> bool {
    f.geofence.is_some() || !f.obstacles.is_empty()
}

fn bad(what: impl Into<String>, reason: String) -> E {
    E::Airspace {
        what: what.into(),
        reason,
    }
}

fn finite(what: &str, field: String, v: Real) -> Result<(), E> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(bad(
            what,
            format!("`{field}` must be a finite number, got {v}"),
        ))
    }
}

fn below(what: &str, lo: (&str, Real), hi: (&str, Real)) -> Result<(), E> {
    if lo.1 < hi.1 {
        Ok(())
    } else {
        Err(bad(
            what,
            format!("`{}` = {} must be below `{}` = {}", lo.0, lo.1, hi.0, hi.1),
        ))
    }
}

/// The tables on their own: numbers, the polygon, names, sizes.
pub(super) fn check_tables(f: &ScenarioFile) -> Result<(), E> {
    if let Some(g) = &f.geofence {
        check_fence(g)?;
    }
    let mut names = BTreeSet::new();
    for (k, o) in f.obstacles.iter().enumerate() {
        if o.name.trim().is_empty() {
            return Err(bad(
                format!("obstacle {}", k + 1),
                "`name` must not be empty".into(),
            ));
        }
        if !names.insert(o.name.as_str()) {
            return Err(bad(o.label(), "appears more than once".into()));
        }
        check_shape(&o.label(), &o.shape)?;
    }
    Ok(())
}

fn check_fence(g: &GeofenceSpec) -> Result<(), E> {
    let what = "geofence";
    for (k, v) in g.polygon.iter().enumerate() {
        for (c, x) in v.iter().enumerate() {
            // Vertices counted from 1, as in every other message about the polygon.
            finite(
                what,
                format!("polygon` vertex {} `{}", k + 1, ["x", "y"][c]),
                *x,
            )?;
        }
    }
    finite(what, "min_z_m".into(), g.min_z_m)?;
    finite(what, "max_z_m".into(), g.max_z_m)?;
    below(what, ("min_z_m", g.min_z_m), ("max_z_m", g.max_z_m))?;
    if g.polygon.len() < 3 {
        return Err(bad(
            what,
            format!(
                "`polygon` needs at least 3 vertices, got {}",
                g.polygon.len()
            ),
        ));
    }
    let fence = g.fence();
    let n = fence.polygon.len();
    for k in 0..n {
        let (a, b) = fence.edge(k);
        if a == b {
            return Err(bad(
                what,
                format!(
                    "`polygon` vertices {} and {} are the same point (edge {} has no length; vertices and edges are counted from 1)",
                    k + 1,
                    (k + 1) % n + 1,
                    k + 1
                ),
            ));
        }
    }
    if let Some((i, j)) = self_intersection(&fence.polygon) {
        return Err(bad(
            what,
            format!(
                "`polygon` is self-intersecting: edge {} crosses edge {} (edge K joins vertices K and K + 1, counted from 1)",
                i + 1,
                j + 1
            ),
        ));
    }
    if signed_area2(&fence.polygon) == 0.0 {
        return Err(bad(what, "`polygon` encloses no area".into()));
    }
    Ok(())
}

fn check_shape(what: &str, shape: &Shape) -> Result<(), E> {
    match *shape {
        Shape::Box { min, max } => {
            for c in 0..3 {
                finite(what, format!("min[{c}]"), min[c])?;
                finite(what, format!("max[{c}]"), max[c])?;
            }
            for c in 0..3 {
                below(
                    what,
                    (&format!("min[{c}]"), min[c]),
                    (&format!("max[{c}]"), max[c]),
                )?;
            }
        }
        Shape::Cylinder {
            center,
            radius_m,
            min_z_m,
            max_z_m,
        } => {
            finite(what, "center[0]".into(), center[0])?;
            finite(what, "center[1]".into(), center[1])?;
            finite(what, "radius_m".into(), radius_m)?;
            finite(what, "min_z_m".into(), min_z_m)?;
            finite(what, "max_z_m".into(), max_z_m)?;
            if radius_m <= 0.0 {
                return Err(bad(what, format!("`radius_m` must be > 0, got {radius_m}")));
            }
            below(what, ("min_z_m", min_z_m), ("max_z_m", max_z_m))?;
        }
    }
    Ok(())
}

/// Every member starts inside the fence and outside every obstacle (its `start`: the ground
/// spot below it with a take-off). Touching is left to the certificate (its ball, eps + delta).
pub(super) fn check_starts(f: &ScenarioFile, formation: &Formation) -> Result<(), E> {
    let fence = f.geofence.as_ref().map(GeofenceSpec::fence);
    // Every member process runs this over the whole team at start-up: the position's text is
    // built only for an error (formatting it eagerly was O(N) per member, O(N^2) per launch).
    let at = |p: &Vec3| format!("[{:.3}, {:.3}, {:.3}]", p.x, p.y, p.z);
    for m in &formation.members {
        let p = m.start;
        if let Some(fence) = &fence {
            if !fence.contains(&p) {
                let side = if p.z < fence.min_z_m {
                    "below its floor"
                } else if p.z > fence.max_z_m {
                    "above its ceiling"
                } else {
                    "outside its polygon"
                };
                return Err(bad(
                    "geofence",
                    format!("agent {} starts {side} at {}", m.id, at(&p)),
                ));
            }
        }
        for o in &f.obstacles {
            if o.shape.signed_distance(&p) < 0.0 {
                return Err(bad(
                    o.label(),
                    format!("agent {} starts inside it at {}", m.id, at(&p)),
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{paper40, Checks, Scenario};

    /// paper40 (start z 900-1197 m, goals at 560 m) with a fence and obstacles appended in TOML.
    fn with_tables(tables: &str) -> Result<Scenario, crate::ScenarioError> {
        let f = paper40();
        let text = format!("{}\n{tables}", toml::to_string(&f).unwrap());
        Scenario::parse(&text, "t.toml", Checks::Member)
    }

    /// The refusal's text, or "" when `tables` are accepted.
    fn refusal(tables: &str) -> String {
        with_tables(tables)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    }

    const FENCE: &str = "[geofence]\npolygon = [[-300.0, -200.0], [500.0, -200.0], [500.0, 600.0], [-300.0, 600.0]]\nmin_z_m = 0.0\nmax_z_m = 1500.0\n";

    #[test]
    fn tables_round_trip_and_absent_tables_leave_the_file_alone() {
        let plain = Scenario::from_file(paper40(), "p", Checks::Member).unwrap();
        assert!(!plain.to_json().contains("geofence") && !plain.to_json().contains("obstacle"));
        let s = with_tables(&format!(
            "{FENCE}[[obstacle]]\nname = \"tower\"\nmin = [400.0, 400.0, 0.0]\nmax = [450.0, 450.0, 100.0]\n\
             [[obstacle]]\nname = \"mast\"\ncenter = [-250.0, 500.0]\nradius_m = 5.0\nmin_z_m = 0.0\nmax_z_m = 50.0\n"
        ))
        .unwrap();
        assert_eq!(
            s.file.obstacles[1].shape(),
            Shape::Cylinder {
                center: [-250.0, 500.0],
                radius_m: 5.0,
                min_z_m: 0.0,
                max_z_m: 50.0
            }
        );
        let back = Scenario::parse(&s.to_toml(), "back.toml", Checks::Member).unwrap();
        let json = Scenario::parse_json(&s.to_json(), "back.json", Checks::Member).unwrap();
        assert_eq!(back.file, s.file);
        assert_eq!(json.content_hash(), s.content_hash());
        assert_ne!(s.content_hash(), plain.content_hash());
    }

    #[test]
    fn bad_tables_are_refused_naming_the_fence_or_the_obstacle() {
        let obstacle = |body: &str| format!("[[obstacle]]\nname = \"tower\"\n{body}\n");
        let cases: Vec<(String, &str)> = vec![
            (
                "[geofence]\npolygon = [[0.0, 0.0], [1.0, 0.0]]\nmin_z_m = 0.0\nmax_z_m = 9.0\n".into(),
                "geofence: `polygon` needs at least 3 vertices, got 2",
            ),
            (
                "[geofence]\npolygon = [[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]\nmin_z_m = 0.0\nmax_z_m = 9.0\n".into(),
                "geofence: `polygon` is self-intersecting: edge 1 crosses edge 3",
            ),
            (
                FENCE.replace("max_z_m = 1500.0", "max_z_m = -1.0"),
                "geofence: `min_z_m` = 0 must be below `max_z_m` = -1",
            ),
            (
                FENCE.replace("500.0, 600.0", "nan, 600.0"),
                "geofence: `polygon` vertex 3 `x` must be a finite number, got NaN",
            ),
            (
                FENCE.replace("max_z_m = 1500.0", "max_z_m = 1000.0"),
                "geofence: agent 2 starts above its ceiling at [72.000, 108.000, 1008.000]",
            ),
            (
                obstacle("min = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nradius_m = 2.0"),
                "obstacle \"tower\": give either `min` and `max` (a box) or",
            ),
            (
                obstacle("center = [0.0, 0.0]\nradius_m = 0.0\nmin_z_m = 0.0\nmax_z_m = 1.0"),
                "obstacle \"tower\": `radius_m` must be > 0, got 0",
            ),
            (
                obstacle("min = [0.0, 0.0, 5.0]\nmax = [1.0, 1.0, 1.0]"),
                "obstacle \"tower\": `min[2]` = 5 must be below `max[2]` = 1",
            ),
            (
                obstacle("min = [0.0, 0.0, 0.0]\nmax = [1.0, inf, 1.0]"),
                "obstacle \"tower\": `max[1]` must be a finite number, got inf",
            ),
            (
                obstacle("min = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]").repeat(2),
                "obstacle \"tower\": appears more than once",
            ),
            (
                // Agent 1 starts at (360, 0, 900).
                obstacle("center = [360.0, 1.0]\nradius_m = 2.0\nmin_z_m = 800.0\nmax_z_m = 950.0"),
                "obstacle \"tower\": agent 1 starts inside it at [360.000, 0.000, 900.000]",
            ),
        ];
        for (tables, want) in cases {
            let got = refusal(&tables);
            assert!(got.contains(want), "{tables}\nwant {want:?}\ngot  {got:?}");
        }
    }

    /// With a take-off, a member starts on the ground spot below it: a fence whose floor is
    /// above the ground refuses it, one whose floor is the ground accepts it.
    #[test]
    fn a_take_off_starts_on_the_ground() {
        let take_off = "[takeoff]\nground_z_m = 0.0\nt_s = 60.0\n";
        let raised = FENCE.replace("min_z_m = 0.0", "min_z_m = 10.0");
        let got = refusal(&format!("{take_off}{raised}"));
        assert!(
            got.contains("geofence: agent 1 starts below its floor at [360.000, 0.000, 0.000]"),
            "{got}"
        );
        assert!(with_tables(&format!("{take_off}{FENCE}")).is_ok());
    }
}
