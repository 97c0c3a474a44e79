//! Leader plans: the quintic of eqs. 15-16 with exact derivatives, the primary leaders' desired
//! trajectories, and every other member's global desired position through its alpha parameters
//! (eqs. 13-14, 23).

use crate::frame::{deformation_eigenvalues, CollinearLeaders, Homogeneous};
use crate::math::{Mat3, Real, Vec3};

/// Which polynomial piece an integration interval lies on. The 3rd and 4th derivatives of s(t)
/// jump at t0 and t0 + T_total (ERRATA 12), so an integrator step must not straddle those
/// instants and evaluates the piece it lies on (one-sided values at the ends).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Segment {
    /// t in [t0, t0 + T_total]: the quintic.
    Motion,
    /// t >= t0 + T_total: s = 1, every derivative 0.
    Hold,
}

/// s(t) = 10 tau^3 - 15 tau^4 + 6 tau^5, tau = t / T_total (eq. 16, ERRATA "values").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quintic {
    pub t_total_s: Real,
}

impl Quintic {
    /// [s, s', s'', s''', s''''] at time t on the given segment.
    pub fn derivatives(&self, t: Real, segment: Segment) -> [Real; 5] {
        if segment == Segment::Hold {
            return [1.0, 0.0, 0.0, 0.0, 0.0];
        }
        let tt = self.t_total_s;
        let tau = (t / tt).clamp(0.0, 1.0);
        let t2 = tau * tau;
        let t3 = t2 * tau;
        [
            t3 * (10.0 - 15.0 * tau + 6.0 * t2),
            t2 * (30.0 - 60.0 * tau + 30.0 * t2) / tt,
            tau * (60.0 - 180.0 * tau + 120.0 * t2) / (tt * tt),
            (60.0 - 360.0 * tau + 360.0 * t2) / (tt * tt * tt),
            (-360.0 + 720.0 * tau) / (tt * tt * tt * tt),
        ]
    }

    /// The segment of an integration interval [t_start, t_end], or `None` when it straddles
    /// T_total and must be split there.
    pub fn segment_of(&self, t_start: Real, t_end: Real) -> Option<Segment> {
        if t_end <= self.t_total_s {
            Some(Segment::Motion)
        } else if t_start >= self.t_total_s {
            Some(Segment::Hold)
        } else {
            None
        }
    }

    /// The time at which s reaches `s_target` in [0, 1] (s is monotone on [0, T_total]).
    pub fn time_of(&self, s_target: Real) -> Real {
        let (mut lo, mut hi) = (0.0, self.t_total_s);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if self.derivatives(mid, Segment::Motion)[0] < s_target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }
}

/// Position and its first four time derivatives.
pub type Derivs = [Vec3; 5];

/// The primary leaders' plan (eq. 15): r_i(t) = r_i0 + (r_ig - r_i0) s(t), i = 1, 2, 3, and
/// the homogeneous transformation they define.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TeamPlan {
    pub quintic: Quintic,
    pub start: [Vec3; 3],
    pub goal: [Vec3; 3],
    homogeneous: Homogeneous,
}

/// Result of scanning a plan for its smallest deformation eigenvalue.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lambda1Min {
    pub lambda1: Real,
    pub s: Real,
    pub t_s: Real,
}

impl TeamPlan {
    /// A plan from the primary leaders' start and goal positions.
    pub fn new(
        t_total_s: Real,
        start: [Vec3; 3],
        goal: [Vec3; 3],
    ) -> Result<Self, CollinearLeaders> {
        Ok(TeamPlan {
            quintic: Quintic { t_total_s },
            start,
            goal,
            homogeneous: Homogeneous::new(&start)?,
        })
    }

    /// Primary leaders' positions at path parameter s.
    pub fn primaries_at_s(&self, s: Real) -> [Vec3; 3] {
        std::array::from_fn(|i| self.start[i] + (self.goal[i] - self.start[i]) * s)
    }

    /// Derivatives 0..4 of each primary leader's desired position (eq. 15).
    pub fn primary_derivs(&self, t: Real, segment: Segment) -> [Derivs; 3] {
        let s = self.quintic.derivatives(t, segment);
        std::array::from_fn(|i| {
            let delta = self.goal[i] - self.start[i];
            [
                self.start[i] + delta * s[0],
                delta * s[1],
                delta * s[2],
                delta * s[3],
                delta * s[4],
            ]
        })
    }

    /// Derivatives 0..4 of r_HT for a member with alpha parameters `alpha` (eq. 13): an affine
    /// combination of the primary leaders' (ERRATA, "useful identities"), so no numerical
    /// differentiation is needed.
    pub fn agent_derivs(&self, alpha: &[Real; 3], t: Real, segment: Segment) -> Derivs {
        combine(alpha, &self.primary_derivs(t, segment))
    }

    /// Q and d at path parameter s (eq. 11).
    pub fn q_d_at_s(&self, s: Real) -> Result<(Mat3, Vec3), CollinearLeaders> {
        self.homogeneous.q_d(&self.primaries_at_s(s))
    }

    /// Eigenvalues of U_D at path parameter s.
    pub fn lambdas_at_s(&self, s: Real) -> Result<[Real; 3], CollinearLeaders> {
        Ok(deformation_eigenvalues(&self.q_d_at_s(s)?.0))
    }

    /// The smallest lambda_1(U_D) over the whole plan and when it happens. U_D depends on t only
    /// through s, so the scan is over s in [0, 1]: a dense grid, then golden-section refinement.
    /// Fails when the primary leaders become collinear anywhere on the way.
    pub fn lambda1_min(&self) -> Result<Lambda1Min, CollinearLeaders> {
        const GRID: usize = 2000;
        let mut best = (Real::INFINITY, 0.0);
        for k in 0..=GRID {
            let s = k as Real / GRID as Real;
            let l = self.lambdas_at_s(s)?[0];
            if l < best.0 {
                best = (l, s);
            }
        }
        let h = 1.0 / GRID as Real;
        let (mut a, mut b) = ((best.1 - h).max(0.0), (best.1 + h).min(1.0));
        let phi = 0.5 * (5.0_f64.sqrt() - 1.0);
        for _ in 0..80 {
            let c = b - phi * (b - a);
            let d = a + phi * (b - a);
            if self.lambdas_at_s(c)?[0] < self.lambdas_at_s(d)?[0] {
                b = d;
            } else {
                a = c;
            }
        }
        let s = 0.5 * (a + b);
        let l = self.lambdas_at_s(s)?[0];
        let (lambda1, s) = if l < best.0 { (l, s) } else { best };
        Ok(Lambda1Min {
            lambda1,
            s,
            t_s: self.quintic.time_of(s),
        })
    }
}

/// sum_j alpha_j * derivs_j, component by component.
pub fn combine(alpha: &[Real; 3], d: &[Derivs; 3]) -> Derivs {
    std::array::from_fn(|k| d[0][k] * alpha[0] + d[1][k] * alpha[1] + d[2][k] * alpha[2])
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn paper_plan(t_total_s: Real) -> TeamPlan {
        TeamPlan::new(
            t_total_s,
            [
                Vec3::new(360.0, 0.0, 900.0),
                Vec3::new(72.0, 108.0, 1008.0),
                Vec3::new(108.0, -72.0, 1080.0),
            ],
            [
                Vec3::new(224.0, 434.0, 560.0),
                Vec3::new(126.0, 224.0, 560.0),
                Vec3::new(322.0, 224.0, 560.0),
            ],
        )
        .unwrap()
    }

    #[test]
    fn quintic_boundary_conditions_and_derivatives() {
        let q = Quintic { t_total_s: 50.0 };
        let a = q.derivatives(0.0, Segment::Motion);
        let b = q.derivatives(50.0, Segment::Motion);
        assert_eq!(&a[..3], &[0.0, 0.0, 0.0]);
        assert!((b[0] - 1.0).abs() < 1e-15 && b[1].abs() < 1e-15 && b[2].abs() < 1e-15);
        // Finite differences: each derivative is the slope of the previous one.
        for &t in &[3.0, 17.5, 31.0, 49.0] {
            let h = 1e-4;
            let p = q.derivatives(t + h, Segment::Motion);
            let m = q.derivatives(t - h, Segment::Motion);
            let c = q.derivatives(t, Segment::Motion);
            for k in 0..4 {
                let fd = (p[k] - m[k]) / (2.0 * h);
                assert!(
                    (fd - c[k + 1]).abs() < 1e-7 * (1.0 + c[k + 1].abs()),
                    "k={k} t={t}"
                );
            }
        }
        assert_eq!(
            q.derivatives(10.0, Segment::Hold),
            [1.0, 0.0, 0.0, 0.0, 0.0]
        );
        assert_eq!(q.segment_of(49.99, 50.0), Some(Segment::Motion));
        assert_eq!(q.segment_of(50.0, 50.01), Some(Segment::Hold));
        assert_eq!(q.segment_of(49.995, 50.005), None);
    }

    #[test]
    fn paper_lambda1_minimum() {
        let plan = paper_plan(200.0);
        let m = plan.lambda1_min().unwrap();
        assert!((m.lambda1 - 0.5431).abs() < 5e-4, "{m:?}");
        assert!((m.t_s / 200.0 - 0.586).abs() < 0.01, "{m:?}");
        // One eigenvalue is exactly 1 at every instant (Sec. VI-A).
        for k in 0..=100 {
            let l = plan.lambdas_at_s(k as Real / 100.0).unwrap();
            assert!(l.iter().any(|v| (v - 1.0).abs() < 1e-9), "{l:?}");
        }
        let end = plan.lambdas_at_s(1.0).unwrap();
        for (v, e) in end.iter().zip([0.6845, 0.9958, 1.0]) {
            assert!((v - e).abs() < 5e-4, "{end:?}");
        }
    }

    #[test]
    fn affine_combination_reproduces_q_d() {
        let plan = paper_plan(100.0);
        // An arbitrary in-plane point: alpha sums to 1.
        let alpha = [0.2, 0.5, 0.3];
        let p0 = combine(&alpha, &plan.primary_derivs(0.0, Segment::Motion))[0];
        for &t in &[0.0, 40.0, 100.0] {
            let s = plan.quintic.derivatives(t, Segment::Motion)[0];
            let (q, d) = plan.q_d_at_s(s).unwrap();
            let via_alpha = plan.agent_derivs(&alpha, t, Segment::Motion)[0];
            assert!((q * p0 + d - via_alpha).norm() < 1e-9);
        }
    }
}
