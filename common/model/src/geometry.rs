//! Planar geometry on the leaders' plane: barycentric weights (eqs. 14, 18), the leading
//! convex polygon, and distances to its boundary (D_S, Sec. VI-A).

use cdm_math::{Real, Vec2};

/// Barycentric coordinates of p in the triangle (a, b, c): the solution of eqs. 14/18,
/// [a b c; 1 1 1] w = [p; 1]. `None` when the triangle is degenerate.
pub fn barycentric(p: &Vec2, a: &Vec2, b: &Vec2, c: &Vec2) -> Option<[Real; 3]> {
    let det = (b - a).perp(&(c - a));
    if det.abs() <= 1e-12 * (b - a).norm() * (c - a).norm() || !det.is_finite() {
        return None;
    }
    let wb = (p - a).perp(&(c - a)) / det;
    let wc = (b - a).perp(&(p - a)) / det;
    Some([1.0 - wb - wc, wb, wc])
}

/// Twice the signed area of (a, b, c): positive when counter-clockwise.
pub fn orient(a: &Vec2, b: &Vec2, c: &Vec2) -> Real {
    (b - a).perp(&(c - a))
}

/// Indices of the convex hull of `pts`, counter-clockwise, without collinear points
/// (Andrew's monotone chain; ties broken by index, so the result is deterministic).
pub fn convex_hull(pts: &[Vec2]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..pts.len()).collect();
    idx.sort_by(|&i, &j| {
        pts[i]
            .x
            .total_cmp(&pts[j].x)
            .then(pts[i].y.total_cmp(&pts[j].y))
            .then(i.cmp(&j))
    });
    if idx.len() < 3 {
        return idx;
    }
    let mut hull: Vec<usize> = Vec::with_capacity(2 * idx.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &usize>> = if pass == 0 {
            Box::new(idx.iter())
        } else {
            Box::new(idx.iter().rev())
        };
        for &i in iter {
            while hull.len() >= start + 2
                && orient(
                    &pts[hull[hull.len() - 2]],
                    &pts[hull[hull.len() - 1]],
                    &pts[i],
                ) <= 0.0
            {
                hull.pop();
            }
            hull.push(i);
        }
        hull.pop();
    }
    hull
}

/// Distance from p to the segment [a, b].
pub fn segment_distance(p: &Vec2, a: &Vec2, b: &Vec2) -> Real {
    let ab = b - a;
    let len2 = ab.dot(&ab);
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).norm()
}

/// Signed distance of p to the boundary of a convex counter-clockwise polygon: positive inside,
/// negative outside (the minimum over edges of the signed distance to the edge's line).
pub fn signed_boundary_distance(p: &Vec2, polygon: &[Vec2]) -> Real {
    let n = polygon.len();
    let mut best = Real::INFINITY;
    for k in 0..n {
        let a = &polygon[k];
        let b = &polygon[(k + 1) % n];
        let edge = b - a;
        let len = edge.norm();
        if len <= 0.0 {
            continue;
        }
        let d = edge.perp(&(p - a)) / len;
        best = best.min(d);
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn barycentric_of_centroid_and_outside() {
        let (a, b, c) = (
            Vec2::new(0.0, 0.0),
            Vec2::new(3.0, 0.0),
            Vec2::new(0.0, 3.0),
        );
        let w = barycentric(&Vec2::new(1.0, 1.0), &a, &b, &c).unwrap();
        assert!(w.iter().all(|x| (x - 1.0 / 3.0).abs() < 1e-12));
        let w = barycentric(&Vec2::new(4.0, 4.0), &a, &b, &c).unwrap();
        assert!(w[0] < 0.0);
        assert!(barycentric(&a, &a, &b, &Vec2::new(6.0, 0.0)).is_none());
    }

    #[test]
    fn hull_drops_interior_and_collinear_points() {
        let pts = [
            Vec2::new(0.0, 0.0),
            Vec2::new(2.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(2.0, 2.0),
            Vec2::new(0.0, 2.0),
            Vec2::new(1.0, 1.0),
        ];
        let h = convex_hull(&pts);
        assert_eq!(h, vec![0, 1, 3, 4]);
        let poly: Vec<Vec2> = h.iter().map(|&i| pts[i]).collect();
        assert!((signed_boundary_distance(&Vec2::new(1.0, 0.5), &poly) - 0.5).abs() < 1e-12);
        assert!(signed_boundary_distance(&Vec2::new(3.0, 1.0), &poly) < 0.0);
    }
}
