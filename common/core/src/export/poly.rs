//! Each member's desired trajectory as an exact polynomial. The primary leaders fly
//! r_j(t) = r_j0 + (r_jg - r_j0) s(t) (eq. 15) with the quintic s of eq. 16, and every other
//! member's r_HT(t) = sum_j alpha_ij r_j,HT(t) (eq. 13), so r_HT(t) = a + b s(t) with
//! a = sum_j alpha_ij r_j0 and b = sum_j alpha_ij (r_jg - r_j0): a polynomial of degree 5 in t on
//! [0, T_total], held at its end afterwards (`plan::Segment::Hold`). It is exported exactly,
//! not fitted.

use crate::math::{Real, Vec3};
use crate::plan::TeamPlan;

/// Degree of every exported polynomial piece.
pub const DEGREE: usize = 5;

/// s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 (eq. 16), coefficients in increasing powers of tau.
const S_OF_TAU: [Real; DEGREE + 1] = [0.0, 0.0, 0.0, 10.0, -15.0, 6.0];

/// Largest value of s'(t) on [0, T_total], times T_total: s'(tau) = 30 tau^2 (1 - tau)^2 peaks
/// at tau = 1/2 with 30 / 16.
const S_PRIME_MAX_TIMES_T: Real = 30.0 / 16.0;

/// Binomial coefficient C(n, k) for the small n of a quintic.
fn binomial(n: usize, k: usize) -> Real {
    (0..k).fold(1.0, |acc, i| acc * (n - i) as Real / (i + 1) as Real)
}

/// One member's r_HT(t) = a + b s(t / T_total).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AgentTrajectory {
    pub id: u32,
    pub a: Vec3,
    pub b: Vec3,
    pub t_total_s: Real,
}

impl AgentTrajectory {
    /// The trajectory of a member with alpha parameters `alpha` (eqs. 13-14) under `plan`.
    pub fn new(plan: &TeamPlan, id: u32, alpha: &[Real; 3]) -> Self {
        let mut a = Vec3::zeros();
        let mut b = Vec3::zeros();
        for ((start, goal), w) in plan.start.iter().zip(&plan.goal).zip(alpha) {
            a += start * *w;
            b += (goal - start) * *w;
        }
        AgentTrajectory {
            id,
            a,
            b,
            t_total_s: plan.quintic.t_total_s,
        }
    }

    /// r_HT(t), with t clamped to [0, T_total] (rest before the start, hold after the end).
    pub fn position(&self, t_s: Real) -> Vec3 {
        let tau = (t_s / self.t_total_s).clamp(0.0, 1.0);
        let s = S_OF_TAU.iter().rev().fold(0.0, |acc, c| acc * tau + c);
        self.a + self.b * s
    }

    /// The piece on [t0, t0 + duration] in increasing powers of the time local to the piece:
    /// s re-expanded around tau0 = t0 / T_total by the binomial theorem, then scaled from tau to
    /// seconds. Exact up to rounding: no fitting.
    pub fn piece(&self, t0_s: Real, duration_s: Real) -> Piece {
        let tt = self.t_total_s;
        let tau0 = t0_s / tt;
        let mut coeffs = [Vec3::zeros(); DEGREE + 1];
        for (m, c) in coeffs.iter_mut().enumerate() {
            let shifted: Real = (m..=DEGREE)
                .map(|k| S_OF_TAU[k] * binomial(k, m) * tau0.powi((k - m) as i32))
                .sum();
            *c = self.b * (shifted / tt.powi(m as i32));
        }
        coeffs[0] += self.a;
        Piece {
            t0_s,
            duration_s,
            coeffs,
        }
    }

    /// The largest horizontal and vertical speed of the plan: |b| s'_max per component group.
    pub fn max_speeds(&self) -> (Real, Real) {
        let k = S_PRIME_MAX_TIMES_T / self.t_total_s;
        (self.b.xy().norm() * k, self.b.z.abs() * k)
    }

    /// The highest and lowest z of the plan: r_HT is a + b s with s monotone from 0 to 1, so
    /// its extremes are at the ends.
    pub fn z_range(&self) -> (Real, Real) {
        let (z0, z1) = (self.a.z, self.a.z + self.b.z);
        (z0.min(z1), z0.max(z1))
    }
}

/// One polynomial piece: position = sum_m coeffs[m] u^m for the local time u in [0, duration].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Piece {
    pub t0_s: Real,
    pub duration_s: Real,
    pub coeffs: [Vec3; DEGREE + 1],
}

impl Piece {
    /// The position at local time `u_s` (Horner, double precision).
    pub fn eval(&self, u_s: Real) -> Vec3 {
        self.coeffs
            .iter()
            .rev()
            .fold(Vec3::zeros(), |acc, c| acc * u_s + c)
    }

    /// The control points of the same curve as a degree-5 Bézier curve over the piece: with
    /// v = u / duration and a_m = coeffs[m] duration^m, P_i = sum_{m <= i} C(i, m) / C(5, m) a_m
    /// (the power-to-Bernstein basis change). P_0 is the start and P_5 the end of the piece.
    pub fn bezier(&self) -> [Vec3; DEGREE + 1] {
        let d = self.duration_s;
        let scaled: [Vec3; DEGREE + 1] = std::array::from_fn(|m| self.coeffs[m] * d.powi(m as i32));
        std::array::from_fn(|i| {
            (0..=i).fold(Vec3::zeros(), |acc, m| {
                acc + scaled[m] * (binomial(i, m) / binomial(DEGREE, m))
            })
        })
    }
}

/// The plan cut into `count` pieces of equal duration T_total / count.
pub fn pieces(traj: &AgentTrajectory, count: usize) -> Vec<Piece> {
    let d = traj.t_total_s / count as Real;
    (0..count).map(|k| traj.piece(k as Real * d, d)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's Sec. VII leaders over a 200 s plan (the plan tests' own team).
    fn paper_plan() -> TeamPlan {
        crate::plan::tests::paper_plan(200.0)
    }

    #[test]
    fn pieces_reproduce_the_plan() {
        let plan = paper_plan();
        let alpha = [0.2, 0.5, 0.3];
        let traj = AgentTrajectory::new(&plan, 9, &alpha);
        for count in [1, 3, 7, 31] {
            let ps = pieces(&traj, count);
            for p in &ps {
                for k in 0..=20 {
                    let u = p.duration_s * k as Real / 20.0;
                    let t = p.t0_s + u;
                    let want = plan.agent_derivs(&alpha, t, plan.piece_at(t))[0];
                    assert!((p.eval(u) - want).norm() < 1e-9, "count={count} t={t}");
                }
            }
        }
        assert_eq!(traj.position(250.0), traj.a + traj.b);
        assert_eq!(traj.position(-1.0), traj.a);
    }

    #[test]
    fn bezier_ends_and_curve_match() {
        let plan = paper_plan();
        let traj = AgentTrajectory::new(&plan, 1, &[1.0, 0.0, 0.0]);
        let p = traj.piece(40.0, 50.0);
        let cp = p.bezier();
        assert!((cp[0] - p.eval(0.0)).norm() < 1e-9);
        assert!((cp[5] - p.eval(50.0)).norm() < 1e-9);
        // de Casteljau at v = 0.3 against the power basis.
        let mut pts = cp.to_vec();
        while pts.len() > 1 {
            pts = pts.windows(2).map(|w| w[0] * 0.7 + w[1] * 0.3).collect();
        }
        assert!((pts[0] - p.eval(15.0)).norm() < 1e-9);
    }

    #[test]
    fn speeds_and_altitudes() {
        let plan = paper_plan();
        let traj = AgentTrajectory::new(&plan, 1, &[1.0, 0.0, 0.0]);
        let (vxy, vz) = traj.max_speeds();
        let h = 1e-4;
        let v = (traj.position(100.0 + h) - traj.position(100.0 - h)) / (2.0 * h);
        assert!((v.xy().norm() - vxy).abs() < 1e-6 && (v.z.abs() - vz).abs() < 1e-6);
        assert_eq!(traj.z_range(), (560.0, 900.0));
    }
}
