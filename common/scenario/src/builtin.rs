//! Built-in scenarios: `paper40` (Sec. VII) and generated teams of any size.

use super::{AgentSpec, GroundSpec, ScenarioFile, SegmentSpec};
use cdm_math::{vec3, Real, Vec2, Vec3};
use cdm_model::formation::Role;
use cdm_model::frame::Frame;
use cdm_model::geometry::{convex_hull, signed_boundary_distance};

/// The largest team the tools accept (file or `--n`).
pub const MAX_AGENTS: usize = 2000;

/// The paper's primary leaders: start and goal (Sec. VII-A).
const PRIMARY_START: [[Real; 3]; 3] = [
    [360.0, 0.0, 900.0],
    [72.0, 108.0, 1008.0],
    [108.0, -72.0, 1080.0],
];
const PRIMARY_GOAL: [[Real; 3]; 3] = [
    [224.0, 434.0, 560.0],
    [126.0, 224.0, 560.0],
    [322.0, 224.0, 560.0],
];
/// The paper's secondary leaders (Sec. VII-B), 0.47-0.64 m off the primaries' plane as printed.
const SECONDARY_START: [[Real; 3]; 3] = [
    [-72.0, 117.6, 1084.0],
    [-198.0, 37.0, 1197.0],
    [-36.0, -62.0, 1156.0],
];
/// Followers per unit of scale: the paper's 34.
const PAPER_FOLLOWERS: usize = 34;
/// The paper's gains (Sec. VII-D).
pub const PAPER_GAINS: [Real; 4] = [8.0, 24.0, 51.5625, 23.4375];

/// The paper's 40-member collective descent: 3 primary + 3 secondary leaders and goals from
/// Sec. VII, 34 followers placed inside the leading hexagon by `place_followers` (the paper's
/// Fig. 7 gives no coordinates).
pub fn paper40() -> ScenarioFile {
    let mut f = generated_unchecked(40);
    f.name = "paper40".into();
    // The secondary leaders exactly as printed: validation projects them (ERRATA 10).
    for (a, p) in f.agents[3..6].iter_mut().zip(SECONDARY_START) {
        a.position = p;
    }
    f
}

/// paper40 as a whole flight: take off from the ground (z = 0) below the paper's start
/// formation, fly the paper's descent (segment 1), hover, turn the team by 30 degrees about the
/// vertical through its centre while moving 60 m west, 120 m south and 60 m down (segment 2, a
/// rigid motion of segment 1's goals, so it deforms no more than the paper's descent), hover,
/// and land below the final formation.
pub fn paper40_mission() -> ScenarioFile {
    let mut f = paper40();
    f.name = "paper40-mission".into();
    f.takeoff = Some(GroundSpec {
        ground_z_m: 0.0,
        t_s: MISSION_TAKEOFF_S,
        hold_s: Some(5.0),
    });
    f.segments = vec![SegmentSpec {
        hold_s: Some(5.0),
        t_s: 150.0,
        goals: vec![
            [94.0, 295.2, 500.0],
            [114.1, 64.4, 500.0],
            [283.9, 162.4, 500.0],
        ],
    }];
    f.landing = Some(GroundSpec {
        ground_z_m: 0.0,
        t_s: MISSION_LANDING_S,
        hold_s: Some(5.0),
    });
    f
}

/// paper40-mission's climb and descent times (about a kilometre up, half of one down).
const MISSION_TAKEOFF_S: Real = 200.0;
const MISSION_LANDING_S: Real = 150.0;

/// A generated team of `n` members (4 <= n <= MAX_AGENTS) flying a manoeuvre of the paper's kind:
/// the paper's primary leaders and goals, the paper's secondary leaders when n >= 10, followers
/// on a hexagonal lattice inside the leading polygon. Beyond 34 followers each configuration is
/// scaled about its own centroid by sqrt(n_f / 34) so that spacing stays as in the paper, and
/// T_total grows by the square root of that scale (deviations grow with the deformation's size
/// and fall as 1 / T_total^2, Sec. VII-D).
pub fn generated(n: usize) -> Result<ScenarioFile, TeamSizeError> {
    if n < 4 {
        return Err(TeamSizeError::TooFew { n });
    }
    if n > super::MAX_AGENTS {
        return Err(TeamSizeError::TooMany { n });
    }
    Ok(generated_unchecked(n))
}

/// A generated team's size out of range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum TeamSizeError {
    /// Fewer than 3 primary leaders and a follower.
    #[error("must be at least 4 (3 primary leaders and a follower), got {n}")]
    TooFew { n: usize },
    /// More than [`MAX_AGENTS`].
    #[error("must be at most {}, got {n}", MAX_AGENTS)]
    TooMany { n: usize },
}

fn generated_unchecked(n: usize) -> ScenarioFile {
    let n_secondary = if n >= 10 { 3 } else { 0 };
    let n_followers = n - 3 - n_secondary;
    let scale = (n_followers as Real / PAPER_FOLLOWERS as Real)
        .sqrt()
        .max(1.0);
    let mut agents = leaders(n, n_secondary, scale);
    let prim: Vec<Vec3> = agents.iter().take(3).map(|a| vec3(a.position)).collect();
    // The paper's primaries are never collinear; fall back to an identity frame defensively.
    let frame = Frame::new(&prim[0], &prim[1], &prim[2]).unwrap_or(Frame {
        origin: Vec3::zeros(),
        e1: Vec3::x(),
        e2: Vec3::y(),
        e3: Vec3::z(),
        rho1: 0.0,
    });
    let leaders_2d: Vec<Vec2> = agents
        .iter()
        .map(|a| {
            let (g, b, _) = frame.coords(&vec3(a.position));
            Vec2::new(g, b)
        })
        .collect();
    // Generated secondaries sit exactly on the primaries' plane.
    for (a, p) in agents.iter_mut().zip(&leaders_2d).skip(3) {
        let q = frame.point(p.x, p.y);
        a.position = [q.x, q.y, q.z];
    }
    let hull = convex_hull(&leaders_2d);
    let polygon: Vec<Vec2> = hull.iter().map(|&k| leaders_2d[k]).collect();
    let first_id = agents.len() as u32 + 1;
    for (k, p) in place_followers(&polygon, n_followers).iter().enumerate() {
        let q = frame.point(p.x, p.y);
        agents.push(AgentSpec {
            id: first_id + k as u32,
            role: Role::Follower,
            position: [q.x, q.y, q.z],
            goal: None,
            in_neighbors: None,
        });
    }
    ScenarioFile {
        name: format!("generated{n}"),
        t_total_s: (200.0 * scale.sqrt()).round(),
        eps_m: 1.5,
        comm_hz: 100.0,
        gains: PAPER_GAINS,
        lambda_cd_min: None,
        delta_m: None,
        substeps: None,
        weight_floor: None,
        plane_tolerance_m: None,
        link: None,
        geo_origin: None,
        takeoff: None,
        segments: Vec::new(),
        landing: None,
        geofence: None,
        obstacles: Vec::new(),
        vehicle: None,
        agents,
    }
}

/// The paper's primary leaders (with goals) and `n_secondary` of its secondary leaders, each
/// configuration scaled by `scale` about its centroid; room for `n` agents.
fn leaders(n: usize, n_secondary: usize, scale: Real) -> Vec<AgentSpec> {
    let centroid = |ps: &[[Real; 3]; 3]| (vec3(ps[0]) + vec3(ps[1]) + vec3(ps[2])) / 3.0;
    let (c0, cg) = (centroid(&PRIMARY_START), centroid(&PRIMARY_GOAL));
    let scaled = |p: [Real; 3], c: &Vec3| {
        let q = c + (vec3(p) - c) * scale;
        [q.x, q.y, q.z]
    };
    let mut agents = Vec::with_capacity(n);
    for k in 0..3 {
        agents.push(AgentSpec {
            id: k as u32 + 1,
            role: Role::Primary,
            position: scaled(PRIMARY_START[k], &c0),
            goal: Some(scaled(PRIMARY_GOAL[k], &cg)),
            in_neighbors: None,
        });
    }
    for (k, p) in SECONDARY_START.iter().take(n_secondary).enumerate() {
        agents.push(AgentSpec {
            id: k as u32 + 4,
            role: Role::Secondary,
            position: scaled(*p, &c0),
            goal: None,
            in_neighbors: None,
        });
    }
    agents
}

/// `n` points on a hexagonal lattice inside a convex polygon, at least 0.8 spacing from its
/// boundary, spacing as large as fits; the `n` lattice points nearest the polygon's centroid
/// (distance, then angle: deterministic).
pub fn place_followers(polygon: &[Vec2], n: usize) -> Vec<Vec2> {
    if n == 0 || polygon.len() < 3 {
        return Vec::new();
    }
    let centroid = polygon.iter().fold(Vec2::zeros(), |a, p| a + p) / polygon.len() as Real;
    let extent = polygon
        .iter()
        .map(|p| (p - centroid).norm())
        .fold(0.0, Real::max);
    let lattice = |h: Real| -> Vec<Vec2> {
        let rows = (extent / (h * 0.866)).ceil() as i64 + 1;
        let cols = (extent / h).ceil() as i64 + 1;
        let mut pts = Vec::new();
        for r in -rows..=rows {
            for c in -cols..=cols {
                let x = centroid.x + (c as Real + 0.5 * (r.rem_euclid(2)) as Real) * h;
                let y = centroid.y + r as Real * h * 0.866_025_403_784_438_6;
                let p = Vec2::new(x, y);
                if signed_boundary_distance(&p, polygon) >= 0.8 * h {
                    pts.push(p);
                }
            }
        }
        pts
    };
    // A lower bound on the spacing at which n points surely fit, without a huge lattice.
    let mut lo = extent / (6.0 * (n as Real).sqrt() + 6.0);
    let mut best = lattice(lo);
    for _ in 0..20 {
        if best.len() >= n {
            break;
        }
        lo *= 0.5;
        best = lattice(lo);
    }
    let mut hi = extent;
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        let pts = lattice(mid);
        if pts.len() >= n {
            lo = mid;
            best = pts;
        } else {
            hi = mid;
        }
    }
    best.sort_by(|a, b| {
        let (da, db) = ((a - centroid).norm(), (b - centroid).norm());
        da.total_cmp(&db).then(
            (a.y - centroid.y)
                .atan2(a.x - centroid.x)
                .total_cmp(&(b.y - centroid.y).atan2(b.x - centroid.x)),
        )
    });
    best.truncate(n);
    best
}
