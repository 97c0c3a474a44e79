//! Safety conditions of Sec. VI: D_B, D_S, delta_max (eq. 35), delta <-> lambda_CD,min
//! (eq. 38), the containment prism of Theorem 3, and separations.

use crate::formation::{Formation, Role};
use crate::geometry::signed_boundary_distance;
use cdm_math::{Real, Vec3};

/// delta_max = min{ (D_B - 2 eps) / 2, D_S - eps } (eq. 35).
pub fn delta_max(d_b_m: Real, d_s_m: Real, eps_m: Real) -> Real {
    (0.5 * (d_b_m - 2.0 * eps_m)).min(d_s_m - eps_m)
}

/// delta = lambda_CD,min (delta_max + eps) - eps (eq. 38 solved for delta).
pub fn delta_from_lambda(lambda_cd_min: Real, delta_max_m: Real, eps_m: Real) -> Real {
    lambda_cd_min * (delta_max_m + eps_m) - eps_m
}

/// lambda_CD,min = (delta + eps) / (delta_max + eps) (eq. 38).
pub fn lambda_from_delta(delta_m: Real, delta_max_m: Real, eps_m: Real) -> Real {
    (delta_m + eps_m) / (delta_max_m + eps_m)
}

/// D_B: the smallest distance between any two members at t0 (Sec. VI-A).
pub fn d_b(formation: &Formation) -> Real {
    let pos: Vec<Vec3> = formation.members.iter().map(|m| m.position).collect();
    min_separation(&pos).0
}

/// D_S: the smallest distance of a follower to the leading polygon's boundary at t0 (Sec. VI-A,
/// ERRATA 9: the polygon of all leaders). Infinite when there are no followers.
pub fn d_s(formation: &Formation) -> Real {
    let poly = formation.polygon_points();
    formation
        .members
        .iter()
        .filter(|m| m.role == Role::Follower)
        .map(|m| signed_boundary_distance(&m.planar, &poly))
        .fold(Real::INFINITY, Real::min)
}

/// The smallest distance between two points and the pair's indices (sweep along x: sort, then
/// compare only points closer in x than the best so far; ties resolve to the lowest indices).
pub fn min_separation(pos: &[Vec3]) -> (Real, usize, usize) {
    let mut order = Vec::new();
    sort_by_x(pos, &mut order);
    min_separation_sorted(pos, &order)
}

/// Sorts `order` to the indices of `pos` by x, then index (a total order: the result does not
/// depend on where it starts). A per-tick caller passes last tick's order back: the team moves
/// little in a tick, so it is nearly sorted and insertion sort finishes in about N steps (the
/// audit sorted afresh twice per tick, about 5 % of `launch`'s orchestrator at N = 40).
pub fn sort_by_x(pos: &[Vec3], order: &mut Vec<usize>) {
    let after = |a: usize, b: usize| pos[a].x.total_cmp(&pos[b].x).then(a.cmp(&b)).is_gt();
    if order.len() != pos.len() {
        order.clear();
        order.extend(0..pos.len());
        order.sort_by(|&a, &b| pos[a].x.total_cmp(&pos[b].x).then(a.cmp(&b)));
        return;
    }
    for i in 1..order.len() {
        let mut j = i;
        while j > 0 && after(order[j - 1], order[j]) {
            order.swap(j - 1, j);
            j -= 1;
        }
    }
}

/// [`min_separation`] with `order` from [`sort_by_x`].
pub fn min_separation_sorted(pos: &[Vec3], order: &[usize]) -> (Real, usize, usize) {
    let mut best = (Real::INFINITY, 0, 0);
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if pos[j].x - pos[i].x > best.0 {
                break;
            }
            let d = (pos[j] - pos[i]).norm();
            let pair = (i.min(j), i.max(j));
            if d < best.0 || (d == best.0 && pair < (best.1, best.2)) {
                best = (d, pair.0, pair.1);
            }
        }
    }
    best
}

/// The containment prism of Theorem 3 at one instant: bases are copies of the leading polygon
/// at +-(delta + eps) along e3, side faces through the polygon's edges.
#[derive(Debug, Clone)]
pub struct Prism {
    vertices: Vec<Vec3>,
    normal: Vec3,
    inward: Vec<Vec3>,
    pub half_height_m: Real,
}

impl Prism {
    /// The prism over the polygon with these vertices (counter-clockwise about `normal`).
    pub fn new(vertices: Vec<Vec3>, normal: Vec3, half_height_m: Real) -> Self {
        let n = vertices.len();
        let inward = (0..n)
            .map(|k| {
                let edge = vertices[(k + 1) % n] - vertices[k];
                normal.cross(&edge).normalize()
            })
            .collect();
        Prism {
            vertices,
            normal,
            inward,
            half_height_m,
        }
    }

    /// Signed distance of p to the side faces (positive inside).
    pub fn side_distance(&self, p: &Vec3) -> Real {
        self.inward
            .iter()
            .zip(&self.vertices)
            .map(|(nrm, v)| (p - v).dot(nrm))
            .fold(Real::INFINITY, Real::min)
    }

    /// Signed distance of p along e3 from the polygon's plane.
    pub fn height(&self, p: &Vec3) -> Real {
        (p - self.vertices[0]).dot(&self.normal)
    }

    /// Inside the side faces and between the bases.
    pub fn contains(&self, p: &Vec3) -> bool {
        self.side_distance(p) >= 0.0 && self.height(p).abs() <= self.half_height_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_delta_values() {
        let dm = delta_max(19.2603, 14.6168, 1.5);
        assert!((dm - 8.1302).abs() < 5e-5, "{dm}");
        let d = delta_from_lambda(0.54, dm, 1.5);
        assert!((d - 3.7003).abs() < 5e-5, "{d}");
        assert!((lambda_from_delta(d, dm, 1.5) - 0.54).abs() < 1e-12);
    }

    #[test]
    fn min_separation_matches_brute_force() {
        let pos: Vec<Vec3> = (0..60)
            .map(|k| {
                let k = k as Real;
                Vec3::new((k * 7.3) % 13.0, (k * 3.1) % 11.0, (k * 1.7) % 5.0)
            })
            .collect();
        let mut brute = Real::INFINITY;
        for i in 0..pos.len() {
            for j in i + 1..pos.len() {
                brute = brute.min((pos[i] - pos[j]).norm());
            }
        }
        assert_eq!(min_separation(&pos).0, brute);
    }

    #[test]
    fn sorting_from_last_order_gives_the_fresh_order() {
        let mut pos: Vec<Vec3> = (0..50)
            .map(|k| Vec3::new(((k * 37) % 11) as Real, k as Real, 0.0))
            .collect();
        let mut order = Vec::new();
        for step in 0..20 {
            for (k, p) in pos.iter_mut().enumerate() {
                p.x += (((k * 7 + step * 3) % 5) as Real - 2.0) * 0.3;
            }
            sort_by_x(&pos, &mut order);
            let mut fresh: Vec<usize> = (0..pos.len()).collect();
            fresh.sort_by(|&a, &b| pos[a].x.total_cmp(&pos[b].x).then(a.cmp(&b)));
            assert_eq!(order, fresh, "step {step}");
        }
        pos.truncate(10);
        sort_by_x(&pos, &mut order);
        assert_eq!(order.len(), 10);
    }

    #[test]
    fn prism_membership() {
        let v = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(0.0, 10.0, 0.0),
        ];
        let p = Prism::new(v, Vec3::z(), 2.0);
        assert!(p.contains(&Vec3::new(2.0, 2.0, 1.0)));
        assert!(!p.contains(&Vec3::new(2.0, 2.0, 3.0)));
        assert!(!p.contains(&Vec3::new(-1.0, 2.0, 0.0)));
        assert!((p.side_distance(&Vec3::new(2.0, 3.0, 0.0)) - 2.0).abs() < 1e-12);
    }
}
