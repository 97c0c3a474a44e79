//! A tick's safety margins read from positions alone (actual r_i and desired r_i,HT, in member
//! order), as the figures, the viewer and the ROS 2 bag draw them: D_B(t), D_S(t), the largest
//! follower deviation and lambda_1(U_D). The live audit (`audit.rs`) checks the same conditions
//! against their limits; these are the numbers behind it, for readers of a run.

use cdm_math::{Real, Vec3};
use cdm_model::frame::deformation_eigenvalues;
use cdm_model::safety::{min_separation, Prism};
use cdm_scenario::Scenario;

/// Eigenvalues of U_D at time t, exactly as the audit computes them (eq. 37).
pub fn lambdas_at(s: &Scenario, t: Real) -> [Real; 3] {
    s.plan
        .q_d_at(t)
        .map_or([0.0; 3], |(q, _)| deformation_eigenvalues(&q))
}

/// D_S(t): the smallest signed distance of a follower (member indices `followers`) to the sides
/// of Theorem 3's prism over the leaders' desired polygon, as the audit builds it (infinite
/// without a polygon). Only living members (`alive`) count: a lost one has left the team.
pub fn boundary_distance(
    s: &Scenario,
    followers: &[usize],
    half_height_m: Real,
    pos: &[Vec3],
    ht: &[Vec3],
    alive: &[bool],
) -> Real {
    let verts: Vec<Vec3> = s.formation.polygon.iter().map(|&k| ht[k]).collect();
    if verts.len() < 3 {
        return Real::INFINITY;
    }
    let normal = (verts[1] - verts[0])
        .cross(&(verts[2] - verts[0]))
        .normalize();
    let prism = Prism::new(verts, normal, half_height_m);
    followers
        .iter()
        .filter(|&&k| alive[k])
        .map(|&k| prism.side_distance(&pos[k]))
        .fold(Real::INFINITY, Real::min)
}

/// D_B(t) over the living members only (a lost member has no rows after its loss).
pub fn living_separation(pos: &[Vec3], alive: &[bool]) -> (Real, usize, usize) {
    if alive.iter().all(|&a| a) {
        return min_separation(pos);
    }
    let living: Vec<usize> = (0..pos.len()).filter(|&k| alive[k]).collect();
    let at: Vec<Vec3> = living.iter().map(|&k| pos[k]).collect();
    let (d, a, b) = min_separation(&at);
    (
        d,
        living.get(a).copied().unwrap_or(a),
        living.get(b).copied().unwrap_or(b),
    )
}

/// The largest deviation |r - r_HT| (eq. 13) of a living follower (0 without followers).
pub fn max_deviation(followers: &[usize], pos: &[Vec3], ht: &[Vec3], alive: &[bool]) -> Real {
    followers
        .iter()
        .filter(|&&k| alive[k])
        .map(|&k| (pos[k] - ht[k]).norm())
        .fold(0.0, Real::max)
}
