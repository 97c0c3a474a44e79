//! The airspace certificate: every member's ball of radius eps + delta stays inside
//! the geofence and outside every obstacle for all t, proved per phase with no time sampling.
//!
//! The argument (ARCHITECTURE.md, "Geofence and obstacles"): in a phase the primary leaders
//! move r_j(t) = start_j + s(t) (goal_j - start_j), j = 1..3, with one path parameter s(t)
//! rising monotonically from 0 to 1 (eq. 15), and every member's desired position is the same
//! fixed affine combination of them, r_i,HT(t) = sum_j alpha_ij r_j(t) (eq. 13). So
//! r_i,HT(t) = a_i + s(t) (b_i - a_i): over the whole phase (and the hovers at its ends) member
//! i's desired position runs along the straight segment [a_i, b_i], whatever the travel time.
//! Every member is within delta of its desired position (eq. 34: followers by E_max <= delta,
//! leaders track their plan exactly), so its ball of radius eps stays within eps + delta of that
//! segment. The smallest distance from a segment to a box or cylinder is computed from below
//! (`Shape::segment_min`), to the fence's floor and ceiling at the segment's ends (z is linear in
//! s), and to each side of the polygon exactly (2-D segment to segment). A margin is that
//! distance minus eps + delta; a negative margin breaks the certificate.
//!
//! During take-off and landing the team stands on the ground, so the floor bounds a member's
//! centre there, not its ball (a floor at the ground is allowed).

use std::collections::BTreeMap;

use serde::Serialize;

use cdm_math::{Real, Vec2, Vec3};
use cdm_model::airspace::{segments_distance, Boundary, Fence};
use cdm_scenario::Scenario;

/// What a clearance is to: a side of the geofence or an obstacle (`fence`, `obstacle` in JSON).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ClearanceKind {
    Fence,
    Obstacle,
}

/// The smallest margin to one boundary of the airspace: where and who.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Clearance {
    pub kind: ClearanceKind,
    /// The fence's side (`floor`, `ceiling`, `edge K`, K from 1) or the obstacle's name.
    pub name: String,
    /// The ball's distance to the boundary (metres): negative when it reaches inside an
    /// obstacle or beyond the fence by that much.
    pub margin_m: Real,
    pub agent: u32,
    /// When (the first instant of the smallest margin on the phase's path).
    pub t_s: Real,
    /// The phase (`segment 1` without a mission).
    pub phase: String,
}

impl Clearance {
    /// How messages name the boundary: `fence ceiling`, `obstacle "tower"`.
    pub fn label(&self) -> String {
        match self.kind {
            ClearanceKind::Fence => format!("fence {}", self.name),
            ClearanceKind::Obstacle => format!("obstacle {:?}", self.name),
        }
    }

    /// The breach as an UNSAFE reason: `obstacle "tower": member 1 at t = 31.40 s (segment 1),
    /// 2.10 m inside`.
    pub fn reason(&self) -> String {
        let how = match self.kind {
            ClearanceKind::Fence => "beyond it",
            ClearanceKind::Obstacle => "inside",
        };
        format!(
            "{}: member {} at t = {:.2} s ({}), {:.2} m {how}",
            self.label(),
            self.agent,
            self.t_s,
            self.phase,
            -self.margin_m
        )
    }
}

/// The airspace part of `plan`'s certificate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AirspaceCertificate {
    /// The ball around each member's desired path: eps + delta (eq. 38).
    pub radius_m: Real,
    /// Every side of the fence (floor, ceiling, edges in order), then every obstacle in file
    /// order: its smallest margin.
    pub clearances: Vec<Clearance>,
    /// `plan --suggest`: what would clear the breaches.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub suggestion: Option<Suggestion>,
}

/// Why no uniform time scaling is suggested.
pub const NO_TIME_SCALING: &str = "no uniform time scaling clears it: each member's desired path is the same segment per phase whatever the travel times (eqs. 13, 15), and its ball of eps + delta does not depend on them (eq. 38)";

/// What would clear one breached boundary, or all of them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Offsets {
    /// `fence ceiling`, `obstacle "tower"`, or `the whole airspace`.
    pub what: String,
    /// The smallest raise of every height (metres) that clears it, if one exists.
    pub raise_m: Option<Real>,
    /// The smallest descent, if one exists.
    pub lower_m: Option<Real>,
}

/// `plan --suggest`'s answer.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Suggestion {
    /// One row per breached boundary (each on its own), then the whole airspace at once,
    /// re-validated and re-certified.
    pub offsets: Vec<Offsets>,
    /// Always `None` (module docs); `time_scaling_note` says why.
    pub time_scale: Option<Real>,
    pub time_scaling_note: &'static str,
    /// Offsets that cleared the margins but were refused when the shifted plan was validated
    /// again (a member below its take-off ground, a start outside the fence), and why.
    pub notes: Vec<String>,
}

impl AirspaceCertificate {
    /// The fence's smallest margin (its worst side), if there is a fence.
    pub fn fence(&self) -> Option<&Clearance> {
        (self.clearances.iter())
            .filter(|c| c.kind == ClearanceKind::Fence)
            .min_by(|a, b| a.margin_m.total_cmp(&b.margin_m))
    }

    /// The UNSAFE reasons: one per boundary breached.
    pub fn reasons(&self) -> Vec<String> {
        (self.clearances.iter())
            .filter(|c| c.margin_m.is_nan() || c.margin_m < 0.0)
            .map(Clearance::reason)
            .collect()
    }
}

/// One member's desired path over one phase: the segment [a, b] (module docs).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Track {
    pub index: usize,
    pub phase: usize,
    pub a: Vec3,
    pub b: Vec3,
    /// Take-off or landing: the floor bounds the centre (module docs).
    pub ground: bool,
}

/// Every member's path in every phase, with every height above the ground raised by `dz_m`
/// (`plan --suggest`; 0 for the plan itself): a take-off's ground spots and a landing's stay.
pub(crate) fn tracks(s: &Scenario, dz_m: Real) -> Vec<Track> {
    use cdm_model::plan::PhaseKind;
    let up = Vec3::new(0.0, 0.0, dz_m);
    let mut out = Vec::new();
    for (phase, p) in s.plan.phases().iter().enumerate() {
        let (lift_a, lift_b) = match p.kind {
            PhaseKind::Takeoff => (Vec3::zeros(), up),
            PhaseKind::Landing => (up, Vec3::zeros()),
            PhaseKind::Segment(_) => (up, up),
        };
        for (index, m) in s.formation.members.iter().enumerate() {
            let w = m.alpha;
            let a = p.start[0] * w[0] + p.start[1] * w[1] + p.start[2] * w[2];
            let b = p.goal[0] * w[0] + p.goal[1] * w[1] + p.goal[2] * w[2];
            out.push(Track {
                index,
                phase,
                a: a + lift_a,
                b: b + lift_b,
                ground: p.kind.is_ground(),
            });
        }
    }
    out
}

/// The smallest margin found so far for one boundary: its value, the track and the path
/// parameter where it is reached.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Worst {
    pub margin_m: Real,
    pub track: usize,
    pub s: Real,
}

/// The smallest margin of every boundary over `tracks`, for balls of `radius_m`.
pub(crate) fn worst_margins(
    s: &Scenario,
    tracks: &[Track],
    radius_m: Real,
) -> BTreeMap<Boundary, Worst> {
    let fence = s.file.geofence.as_ref().map(|g| g.fence());
    let mut worst: BTreeMap<Boundary, Worst> = BTreeMap::new();
    let mut note = |b: Boundary, margin_m: Real, track: usize, s: Real| {
        let w = worst.entry(b).or_insert(Worst {
            margin_m: Real::INFINITY,
            track,
            s,
        });
        // NaN wins: a margin that cannot be computed must not pass.
        if margin_m < w.margin_m || (margin_m.is_nan() && !w.margin_m.is_nan()) {
            *w = Worst { margin_m, track, s };
        }
    };
    for (k, t) in tracks.iter().enumerate() {
        if let Some(f) = &fence {
            let floor_r = if t.ground { 0.0 } else { radius_m };
            let (low, s_low) = if t.a.z <= t.b.z {
                (t.a.z, 0.0)
            } else {
                (t.b.z, 1.0)
            };
            let (high, s_high) = if t.a.z >= t.b.z {
                (t.a.z, 0.0)
            } else {
                (t.b.z, 1.0)
            };
            note(Boundary::Floor, low - f.min_z_m - floor_r, k, s_low);
            note(Boundary::Ceiling, f.max_z_m - high - radius_m, k, s_high);
            for (e, (d, s)) in side_distances(f, &t.a.xy(), &t.b.xy())
                .into_iter()
                .enumerate()
            {
                note(Boundary::Edge(e), d - radius_m, k, s);
            }
        }
        for (o, obstacle) in s.file.obstacles.iter().enumerate() {
            let (d, s) = obstacle.shape.segment_min(&t.a, &t.b);
            note(Boundary::Obstacle(o), d - radius_m, k, s);
        }
    }
    worst
}

/// Samples of a track that leaves the polygon, to measure how far out it goes (whether it
/// leaves is exact: an end outside or an edge crossed).
const OUTSIDE_SAMPLES: usize = 1000;

/// The signed distance (positive inside the polygon) of the horizontal track [a, b] to each
/// side, and where along the track it is smallest. A track inside the polygon: its exact
/// distance to each edge. A track that leaves it: minus the deepest excursion, charged to the
/// edge nearest the deepest point (measured on samples; the breach itself is certain).
fn side_distances(f: &Fence, a: &Vec2, b: &Vec2) -> Vec<(Real, Real)> {
    let mut out: Vec<(Real, Real)> = (0..f.polygon.len())
        .map(|k| {
            let (c, d) = f.edge(k);
            segments_distance(a, b, &c, &d)
        })
        .collect();
    let leaves = !f.contains_xy(a) || out.iter().any(|x| x.0 <= 0.0);
    if !leaves {
        return out;
    }
    for x in out.iter_mut().filter(|x| x.0 <= 0.0) {
        // Crossed or touched: at least on the wall.
        x.0 = 0.0;
    }
    for k in 0..=OUTSIDE_SAMPLES {
        let s = k as Real / OUTSIDE_SAMPLES as Real;
        let p = a + (b - a) * s;
        if f.contains_xy(&p) {
            continue;
        }
        let (e, d) = (0..f.polygon.len())
            .map(|e| {
                let (c, d) = f.edge(e);
                (e, cdm_model::geometry::segment_distance(&p, &c, &d))
            })
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .unwrap_or((0, Real::NAN));
        if -d < out[e].0 {
            out[e] = (-d, s);
        }
    }
    out
}

/// The airspace certificate of `s` for balls of eps + delta; `None` without a fence or
/// obstacles.
pub fn certify_airspace(s: &Scenario, delta_m: Real) -> Option<AirspaceCertificate> {
    if !cdm_scenario::has_airspace(&s.file) {
        return None;
    }
    // Without a positive delta the plan is UNSAFE already (eq. 38); measure the eps balls.
    let radius_m = s.file.eps_m + delta_m.max(0.0);
    let tracks = tracks(s, 0.0);
    let worst = worst_margins(s, &tracks, radius_m);
    let clearances = worst
        .iter()
        .map(|(b, w)| clearance(s, &tracks, *b, w))
        .collect();
    Some(AirspaceCertificate {
        radius_m,
        clearances,
        suggestion: None,
    })
}

/// One boundary's smallest margin, named, with its member, instant and phase.
pub(crate) fn clearance(s: &Scenario, tracks: &[Track], b: Boundary, w: &Worst) -> Clearance {
    let (kind, name) = match b {
        Boundary::Floor => (ClearanceKind::Fence, "floor".to_string()),
        Boundary::Ceiling => (ClearanceKind::Fence, "ceiling".to_string()),
        Boundary::Edge(k) => (ClearanceKind::Fence, format!("edge {}", k + 1)),
        Boundary::Obstacle(k) => (ClearanceKind::Obstacle, s.file.obstacles[k].name.clone()),
    };
    let t = &tracks[w.track];
    let p = &s.plan.phases()[t.phase];
    Clearance {
        kind,
        name,
        margin_m: w.margin_m,
        agent: s.formation.members[t.index].id,
        t_s: p.t_start_s + time_of(p, w.s),
        phase: p.kind.name(),
    }
}

/// The instant a phase's path parameter reaches s: its ends exactly (s is flat there, and a
/// bisection on s would land microseconds off), otherwise by the quintic's inverse.
fn time_of(p: &cdm_model::plan::Phase, s: Real) -> Real {
    if s <= 0.0 {
        0.0
    } else if s >= 1.0 {
        p.duration_s()
    } else {
        p.time_of(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_model::airspace::Shape;
    use cdm_scenario::{paper40, Checks, ObstacleSpec};

    fn paper40_with(obstacles: Vec<ObstacleSpec>) -> Scenario {
        let mut f = paper40();
        f.obstacles = obstacles;
        Scenario::from_file(f, "t", Checks::Member).unwrap()
    }

    /// A box touched by 1 mm and missed by 1 mm: the verdict flips, and the margin is the gap.
    #[test]
    fn a_box_just_touched_and_just_missed() {
        let s = paper40_with(Vec::new());
        let tracks = tracks(&s, 0.0);
        // Member 1 (primary) flies (360, 0, 900) -> (224, 434, 560); a box below its goal, its
        // top `gap` below the ball of radius r around the goal.
        let r = 5.0;
        let goal = tracks[0].b;
        for gap in [1e-3, -1e-3] {
            let top = goal.z - r - gap;
            let o = ObstacleSpec {
                name: "block".into(),
                shape: Shape::Box {
                    min: [goal.x - 1.0, goal.y - 1.0, top - 10.0],
                    max: [goal.x + 1.0, goal.y + 1.0, top],
                },
            };
            let s = paper40_with(vec![o]);
            let w = worst_margins(&s, &tracks, r)[&Boundary::Obstacle(0)];
            assert!((w.margin_m - gap).abs() < 1e-9, "gap {gap}: {w:?}");
            assert_eq!((w.track, w.s), (0, 1.0));
            let c = certify_airspace(&s, r - s.file.eps_m).unwrap();
            assert_eq!(c.reasons().is_empty(), gap > 0.0, "{:?}", c.reasons());
        }
    }

    /// The leading polygon's corner (primary leader 1) sweeps past a box's vertical edge
    /// between two ticks: every tick's ball of radius r is clear of the box, the path's is not
    /// (by 0.1 mm), and the certificate finds it because it measures the path, not samples.
    #[test]
    fn a_moving_prism_clips_a_box_corner_between_samples() {
        let s = paper40_with(Vec::new());
        let tracks = tracks(&s, 0.0);
        let (a, b) = (tracks[0].a, tracks[0].b);
        let phase = s.plan.phases()[0];
        let at_tick = |k: u64| {
            let t = k as Real * s.dt_s();
            a + (b - a)
                * phase
                    .quintic
                    .derivatives(t, cdm_model::plan::Segment::Motion)[0]
        };
        // Half way between ticks 10000 and 10001 (t = 100 s, the fastest instant).
        let mid = (at_tick(10_000) + at_tick(10_001)) * 0.5;
        let u = (b - a).xy().normalize();
        let n = Vec2::new(u.y, -u.x);
        let (r, clip) = (0.5, 1e-4);
        let corner = mid.xy() + n * (r - clip);
        // The box lies beyond the line through its corner across n: the corner is its point
        // nearest the path.
        let span = |c: Real, sign: Real| {
            if sign > 0.0 {
                [c, c + 50.0]
            } else {
                [c - 50.0, c]
            }
        };
        let (x, y) = (span(corner.x, n.x), span(corner.y, n.y));
        let shape = Shape::Box {
            min: [x[0], y[0], mid.z - 50.0],
            max: [x[1], y[1], mid.z + 50.0],
        };
        let s = paper40_with(vec![ObstacleSpec {
            name: "corner".into(),
            shape,
        }]);
        let ticks = (0..=s.last_tick())
            .map(|k| shape.signed_distance(&at_tick(k)) - r)
            .fold(Real::INFINITY, Real::min);
        assert!(ticks > 0.0, "a tick sees the clip: {ticks}");
        let w = worst_margins(&s, &tracks, r)[&Boundary::Obstacle(0)];
        assert!((w.margin_m + clip).abs() < 1e-9, "{w:?}");
        assert_eq!(tracks[w.track].index, 0);
        let c = clearance(&s, &tracks, Boundary::Obstacle(0), &w);
        assert!((c.t_s - 100.005).abs() < 1e-3, "{c:?}");
    }
}
