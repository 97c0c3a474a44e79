//! The airspace around the team, as pure geometry: the geofence (a vertical prism
//! over a simple polygon, between a floor and a ceiling) and the obstacles (axis-aligned boxes
//! and vertical cylinders), with signed distances (negative inside a shape) and the smallest
//! distance from a straight segment to each. The certificate (`airspace_certificate.rs`) and
//! the live audit (`audit.rs`) both measure with these functions.

use serde::{Deserialize, Serialize};

use cdm_math::{Real, Vec2, Vec3};

/// An obstacle's shape: a solid the team must stay clear of.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Shape {
    /// An axis-aligned box from corner `min` to corner `max` (metres).
    Box { min: [Real; 3], max: [Real; 3] },
    /// A vertical cylinder around (x, y) = `center` from `min_z_m` to `max_z_m`.
    Cylinder {
        center: [Real; 2],
        radius_m: Real,
        min_z_m: Real,
        max_z_m: Real,
    },
}

impl Shape {
    /// Signed distance from p to the solid: the distance to it outside, minus the depth inside
    /// (exact for both shapes; convex in p because both shapes are convex).
    pub fn signed_distance(&self, p: &Vec3) -> Real {
        match *self {
            Shape::Box { min, max } => {
                let q: [Real; 3] = std::array::from_fn(|k| (min[k] - p[k]).max(p[k] - max[k]));
                outside_inside(&q)
            }
            Shape::Cylinder {
                center,
                radius_m,
                min_z_m,
                max_z_m,
            } => {
                let radial = (p.x - center[0]).hypot(p.y - center[1]) - radius_m;
                outside_inside(&[radial, (min_z_m - p.z).max(p.z - max_z_m)])
            }
        }
    }

    /// The smallest signed distance from the segment [a, b] to the solid, as a lower bound, and
    /// the path parameter s in [0, 1] (point a + s (b - a)) where it is reached. Along a line the
    /// signed distance of a convex solid is convex, so golden-section search brackets its
    /// minimiser; the distance is 1-Lipschitz in p, so the value at the bracket minus |b - a|
    /// times the bracket's width bounds the minimum from below (no sample can miss a corner).
    pub fn segment_min(&self, a: &Vec3, b: &Vec3) -> (Real, Real) {
        let f = |s: Real| self.signed_distance(&(a + (b - a) * s));
        let phi = 0.5 * (5.0_f64.sqrt() - 1.0);
        let (mut lo, mut hi) = (0.0, 1.0);
        let (mut c, mut d) = (hi - phi, phi);
        let (mut fc, mut fd) = (f(c), f(d));
        for _ in 0..90 {
            if fc <= fd {
                hi = d;
                (d, fd) = (c, fc);
                c = hi - phi * (hi - lo);
                fc = f(c);
            } else {
                lo = c;
                (c, fc) = (d, fd);
                d = lo + phi * (hi - lo);
                fd = f(d);
            }
        }
        let width = (b - a).norm() * (hi - lo);
        // The ends too: a minimum at s = 0 or 1 is reached exactly there.
        let candidates = [
            (f(0.0), 0.0),
            (f(1.0), 1.0),
            (fc - width, c),
            (fd - width, d),
        ];
        candidates
            .into_iter()
            .min_by(|x, y| x.0.total_cmp(&y.0))
            .unwrap_or((Real::NAN, 0.0))
    }
}

/// Signed distance from per-axis slab distances q (positive outside a slab): the norm of the
/// positive parts outside, the largest (negative) one inside.
fn outside_inside(q: &[Real]) -> Real {
    let out: Real = q.iter().map(|v| v.max(0.0).powi(2)).sum::<Real>().sqrt();
    let inside = q
        .iter()
        .copied()
        .fold(Real::NEG_INFINITY, Real::max)
        .min(0.0);
    out + inside
}

/// Which boundary of the airspace a margin is measured to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Boundary {
    /// The geofence's floor (`min_z_m`).
    Floor,
    /// The geofence's ceiling (`max_z_m`).
    Ceiling,
    /// The geofence's side over polygon edge k (0-based: vertex k to vertex k + 1).
    Edge(usize),
    /// Obstacle k (file order).
    Obstacle(usize),
}

/// The geofence: a vertical prism over a simple polygon.
#[derive(Debug, Clone, PartialEq)]
pub struct Fence {
    pub polygon: Vec<Vec2>,
    pub min_z_m: Real,
    pub max_z_m: Real,
}

impl Fence {
    /// Polygon edge k as its two ends.
    pub fn edge(&self, k: usize) -> (Vec2, Vec2) {
        let n = self.polygon.len();
        (self.polygon[k], self.polygon[(k + 1) % n])
    }

    /// Whether the point (x, y) is inside the polygon (even-odd rule; points on an edge may
    /// fall either way, which only a margin of exactly 0 could notice).
    pub fn contains_xy(&self, p: &Vec2) -> bool {
        let n = self.polygon.len();
        let mut inside = false;
        for k in 0..n {
            let (a, b) = self.edge(k);
            if (a.y > p.y) != (b.y > p.y) {
                let x = a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x);
                if p.x < x {
                    inside = !inside;
                }
            }
        }
        inside
    }

    /// Whether p is inside the prism (between floor and ceiling, inside the polygon).
    pub fn contains(&self, p: &Vec3) -> bool {
        p.z >= self.min_z_m && p.z <= self.max_z_m && self.contains_xy(&p.xy())
    }

    /// The point's distance inside the prism to each boundary (negative beyond it): floor,
    /// ceiling, then the side nearest the point (+ inside the polygon, - outside). The audit's
    /// per-tick measure.
    pub fn margins_at(&self, p: &Vec3) -> [(Boundary, Real); 3] {
        let xy = p.xy();
        let (k, d) = (0..self.polygon.len())
            .map(|k| {
                let (a, b) = self.edge(k);
                (k, crate::geometry::segment_distance(&xy, &a, &b))
            })
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .unwrap_or((0, Real::NAN));
        let side = if self.contains_xy(&xy) { d } else { -d };
        [
            (Boundary::Floor, p.z - self.min_z_m),
            (Boundary::Ceiling, self.max_z_m - p.z),
            (Boundary::Edge(k), side),
        ]
    }
}

/// The smallest distance between the 2-D segments [a, b] and [c, d], and the parameter s on
/// [a, b] where it is reached (0 when they cross, at the crossing).
pub fn segments_distance(a: &Vec2, b: &Vec2, c: &Vec2, d: &Vec2) -> (Real, Real) {
    if let Some(s) = crossing(a, b, c, d) {
        return (0.0, s);
    }
    let on_ab = |p: &Vec2| {
        let ab = b - a;
        let len2 = ab.dot(&ab);
        let s = if len2 > 0.0 {
            ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        ((p - (a + ab * s)).norm(), s)
    };
    let ends_ab = [
        (crate::geometry::segment_distance(a, c, d), 0.0),
        (crate::geometry::segment_distance(b, c, d), 1.0),
    ];
    [on_ab(c), on_ab(d), ends_ab[0], ends_ab[1]]
        .into_iter()
        .min_by(|x, y| x.0.total_cmp(&y.0))
        .unwrap_or((Real::NAN, 0.0))
}

/// Where [a, b] meets [c, d] (parameter on [a, b]), touching and collinear overlap included.
pub fn crossing(a: &Vec2, b: &Vec2, c: &Vec2, d: &Vec2) -> Option<Real> {
    use crate::geometry::orient;
    let (o1, o2) = (orient(a, b, c), orient(a, b, d));
    let (o3, o4) = (orient(c, d, a), orient(c, d, b));
    let ab = b - a;
    let len2 = ab.dot(&ab);
    let param = |p: &Vec2| {
        if len2 > 0.0 {
            ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
        return Some(o3 / (o3 - o4));
    }
    // Touching: an end of one segment lies on the other.
    let on = |p: &Vec2, q: &Vec2, r: &Vec2, o: Real| o == 0.0 && (r - p).dot(&(r - q)) <= 0.0;
    if on(a, b, c, o1) {
        return Some(param(c));
    }
    if on(a, b, d, o2) {
        return Some(param(d));
    }
    if on(c, d, a, o3) {
        return Some(0.0);
    }
    if on(c, d, b, o4) {
        return Some(1.0);
    }
    None
}

/// The first pair of polygon edges that cross (not counting the shared vertex of neighbours),
/// as 0-based edge indices, or `None` for a simple polygon.
pub fn self_intersection(polygon: &[Vec2]) -> Option<(usize, usize)> {
    let n = polygon.len();
    let edge = |k: usize| (polygon[k], polygon[(k + 1) % n]);
    for i in 0..n {
        for j in i + 1..n {
            let (a, b) = edge(i);
            let (c, d) = edge(j);
            let neighbours = j == i + 1 || (i == 0 && j == n - 1);
            if neighbours {
                // They share one vertex; they may only meet there: folding back onto each
                // other (collinear, pointing back) is a crossing.
                let (p, q, shared) = if j == i + 1 { (a, d, b) } else { (b, c, a) };
                let folded = crate::geometry::orient(&p, &shared, &q) == 0.0
                    && (p - shared).dot(&(q - shared)) > 0.0;
                if folded {
                    return Some((i, j));
                }
            } else if crossing(&a, &b, &c, &d).is_some() {
                return Some((i, j));
            }
        }
    }
    None
}

/// Twice the polygon's signed area (shoelace; positive counter-clockwise).
pub fn signed_area2(polygon: &[Vec2]) -> Real {
    let n = polygon.len();
    (0..n).map(|k| polygon[k].perp(&polygon[(k + 1) % n])).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_box() -> Shape {
        Shape::Box {
            min: [0.0, 0.0, 0.0],
            max: [1.0, 1.0, 1.0],
        }
    }

    #[test]
    fn box_and_cylinder_signed_distances() {
        let b = unit_box();
        assert_eq!(b.signed_distance(&Vec3::new(0.5, 0.5, 0.5)), -0.5);
        assert_eq!(b.signed_distance(&Vec3::new(3.0, 0.5, 0.5)), 2.0);
        // Beyond a corner: the distance to the corner.
        let d = b.signed_distance(&Vec3::new(2.0, 2.0, 2.0));
        assert!((d - 3.0_f64.sqrt()).abs() < 1e-15);
        let c = Shape::Cylinder {
            center: [0.0, 0.0],
            radius_m: 2.0,
            min_z_m: 0.0,
            max_z_m: 10.0,
        };
        assert_eq!(c.signed_distance(&Vec3::new(5.0, 0.0, 5.0)), 3.0);
        assert_eq!(c.signed_distance(&Vec3::new(0.0, 0.0, 9.0)), -1.0);
        assert_eq!(c.signed_distance(&Vec3::new(0.0, 0.0, 13.0)), 3.0);
        let rim = c.signed_distance(&Vec3::new(5.0, 0.0, 14.0));
        assert!((rim - 5.0).abs() < 1e-15);
    }

    /// A segment passing a box's edge diagonally: the closest point is between its ends, where
    /// no sample at the ends would see it.
    #[test]
    fn segment_minimum_between_the_ends() {
        let b = unit_box();
        // The line x - y = off (z = 0.5) passes the box's vertical edge at x = 1, y = 0.
        for &gap in &[1e-3, -1e-3] {
            let off = 1.0 + gap * std::f64::consts::SQRT_2;
            let a = Vec3::new(off - 10.0, -10.0, 0.5);
            let e = Vec3::new(off + 10.0, 10.0, 0.5);
            // Inside, the deepest point is half way between the faces x = 1 and y = 0.
            let want = if gap > 0.0 {
                gap
            } else {
                gap / std::f64::consts::SQRT_2
            };
            let (d, s) = b.segment_min(&a, &e);
            assert!((d - want).abs() < 1e-9, "gap {gap}: {d}");
            assert!((s - 0.5).abs() < 1e-3, "{s}");
            assert!(b.signed_distance(&a) > 5.0 && b.signed_distance(&e) > 5.0);
        }
    }

    #[test]
    fn polygons_simple_or_not() {
        let sq = [
            Vec2::new(0.0, 0.0),
            Vec2::new(4.0, 0.0),
            Vec2::new(4.0, 4.0),
            Vec2::new(0.0, 4.0),
        ];
        assert_eq!(self_intersection(&sq), None);
        assert_eq!(signed_area2(&sq), 32.0);
        let bow = [sq[0], sq[2], sq[1], sq[3]];
        assert_eq!(self_intersection(&bow), Some((0, 2)));
        let folded = [sq[0], sq[1], Vec2::new(2.0, 0.0), sq[3]];
        assert!(self_intersection(&folded).is_some());
        let fence = Fence {
            polygon: sq.to_vec(),
            min_z_m: 0.0,
            max_z_m: 10.0,
        };
        assert!(fence.contains(&Vec3::new(1.0, 1.0, 5.0)));
        assert!(!fence.contains(&Vec3::new(5.0, 1.0, 5.0)));
        assert!(!fence.contains(&Vec3::new(1.0, 1.0, 11.0)));
        let m = fence.margins_at(&Vec3::new(1.0, 3.5, 9.0));
        assert_eq!(
            m,
            [
                (Boundary::Floor, 9.0),
                (Boundary::Ceiling, 1.0),
                (Boundary::Edge(2), 0.5)
            ]
        );
        assert_eq!(
            fence.margins_at(&Vec3::new(6.0, 2.0, 1.0))[2],
            (Boundary::Edge(1), -2.0)
        );
    }

    #[test]
    fn segment_to_segment_in_the_plane() {
        let p = |x, y| Vec2::new(x, y);
        let (d, s) = segments_distance(&p(0.0, 0.0), &p(4.0, 0.0), &p(1.0, 1.0), &p(3.0, 2.0));
        assert_eq!((d, s), (1.0, 0.25));
        let (d, s) = segments_distance(&p(0.0, 0.0), &p(4.0, 0.0), &p(3.0, -1.0), &p(3.0, 1.0));
        assert_eq!((d, s), (0.0, 0.75));
    }
}
