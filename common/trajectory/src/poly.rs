//! Each member's desired trajectory as an exact chain of polynomials. In each phase of the plan
//! (the paper's one manoeuvre, or a mission's take-off, segments and landing) the primary leaders
//! fly r_j(t) = r_j0 + (r_jg - r_j0) s(t - t_start) (eq. 15) with the quintic s of eq. 16, and
//! every other member's r_HT(t) = sum_j alpha_ij r_j,HT(t) (eq. 13), so on phase k
//! r_HT(t) = a_k + b_k s_k(t - t_start_k) with a_k = sum_j alpha_ij r_j0 and
//! b_k = sum_j alpha_ij (r_jg - r_j0): a polynomial of degree 5 in t, held at its end until the
//! next phase starts (`plan::Segment::Hold`). It is exported exactly, not fitted, and a piece
//! never straddles a phase's start or end.

use cdm_math::{Real, Vec3};
use cdm_model::plan::TeamPlan;

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

/// One phase of one member: r_HT(t) = a + b s((t - t_start) / T) on [t_start, t_start + T].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    pub t_start_s: Real,
    pub t_total_s: Real,
    pub a: Vec3,
    pub b: Vec3,
}

impl Motion {
    /// The instant the motion ends (at rest at a + b).
    pub fn t_end_s(&self) -> Real {
        self.t_start_s + self.t_total_s
    }

    /// r_HT(t), with the time clamped to the motion (rest before it, hold after it).
    pub fn position(&self, t_s: Real) -> Vec3 {
        // `t - 0.0` is `t`: a one-phase plan evaluates the same numbers as before missions.
        let tau = ((t_s - self.t_start_s) / self.t_total_s).clamp(0.0, 1.0);
        let s = S_OF_TAU.iter().rev().fold(0.0, |acc, c| acc * tau + c);
        self.a + self.b * s
    }

    /// The piece on [t0, t0 + duration] (inside the motion) in increasing powers of the time
    /// local to the piece: s re-expanded around tau0 = (t0 - t_start) / T by the binomial
    /// theorem, then scaled from tau to seconds. Exact up to rounding: no fitting.
    pub fn piece(&self, t0_s: Real, duration_s: Real) -> PolyPiece {
        let tt = self.t_total_s;
        let tau0 = (t0_s - self.t_start_s) / tt;
        let mut coeffs = [Vec3::zeros(); DEGREE + 1];
        for (m, c) in coeffs.iter_mut().enumerate() {
            let shifted: Real = (m..=DEGREE)
                .map(|k| S_OF_TAU[k] * binomial(k, m) * tau0.powi((k - m) as i32))
                .sum();
            *c = self.b * (shifted / tt.powi(m as i32));
        }
        coeffs[0] += self.a;
        PolyPiece {
            t0_s,
            duration_s,
            coeffs,
        }
    }
}

/// One member's r_HT(t) over the whole plan: its motions in flight order (one per phase), held
/// between them; the chain ends with the last motion.
#[derive(Debug, Clone, PartialEq)]
pub struct AgentTrajectory {
    pub id: u32,
    pub motions: Vec<Motion>,
}

/// How a chain is cut into pieces. Hovers between motions are constant pieces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Cut {
    /// The longest motion in `n` equal pieces, every other motion k in ceil(n T_k / T_longest)
    /// (at least 1), each hover in one piece (a Crazyflie: memory counts pieces, not seconds).
    Count(usize),
    /// Every motion and every hover in the fewest equal pieces of at most this many seconds (a
    /// Skybrush segment).
    MaxDuration(Real),
}

impl AgentTrajectory {
    /// The trajectory of a member with alpha parameters `alpha` (eqs. 13-14) under `plan`: one
    /// motion per phase.
    pub fn new(plan: &TeamPlan, id: u32, alpha: &[Real; 3]) -> Self {
        let motions = plan
            .phases()
            .iter()
            .map(|p| {
                let mut a = Vec3::zeros();
                let mut b = Vec3::zeros();
                for ((start, goal), w) in p.start.iter().zip(&p.goal).zip(alpha) {
                    a += start * *w;
                    b += (goal - start) * *w;
                }
                Motion {
                    t_start_s: p.t_start_s,
                    t_total_s: p.quintic.t_total_s,
                    a,
                    b,
                }
            })
            .collect();
        AgentTrajectory { id, motions }
    }

    /// The end of the chain: the last motion's end (the first starts at t = 0).
    pub fn duration_s(&self) -> Real {
        self.motions.last().map_or(0.0, Motion::t_end_s)
    }

    /// r_HT(t) on the motion under way at t or the hover after it; clamped outside the chain.
    pub fn position(&self, t_s: Real) -> Vec3 {
        let k = self
            .motions
            .iter()
            .rposition(|m| m.t_start_s <= t_s)
            .unwrap_or(0);
        self.motions
            .get(k)
            .map_or(Vec3::zeros(), |m| m.position(t_s))
    }

    /// The largest horizontal and vertical speed of the plan: |b_k| s'_max per component group,
    /// the largest over the motions (hovers are at rest).
    pub fn max_speeds(&self) -> (Real, Real) {
        self.motions.iter().fold((0.0, 0.0), |(vxy, vz), m| {
            let k = S_PRIME_MAX_TIMES_T / m.t_total_s;
            (
                Real::max(vxy, m.b.xy().norm() * k),
                Real::max(vz, m.b.z.abs() * k),
            )
        })
    }

    /// The lowest and highest z of the plan: on each motion r_HT is a + b s with s monotone from
    /// 0 to 1, so its extremes are at the motions' ends (and the hovers stay there).
    pub fn z_range(&self) -> (Real, Real) {
        self.motions
            .iter()
            .fold((Real::INFINITY, Real::NEG_INFINITY), |(lo, hi), m| {
                let (z0, z1) = (m.a.z, m.a.z + m.b.z);
                (lo.min(z0).min(z1), hi.max(z0).max(z1))
            })
    }
}

/// One polynomial piece: position = sum_m coeffs[m] u^m for the local time u in [0, duration].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolyPiece {
    pub t0_s: Real,
    pub duration_s: Real,
    pub coeffs: [Vec3; DEGREE + 1],
}

impl PolyPiece {
    /// A hover: `at` for the whole piece.
    pub fn constant(t0_s: Real, duration_s: Real, at: Vec3) -> Self {
        let mut coeffs = [Vec3::zeros(); DEGREE + 1];
        coeffs[0] = at;
        PolyPiece {
            t0_s,
            duration_s,
            coeffs,
        }
    }

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

/// Equal pieces of `total_s` seconds under `cut` (`longest_s`: the longest motion's duration).
fn count_of(cut: Cut, total_s: Real, longest_s: Real, hover: bool) -> usize {
    match cut {
        Cut::Count(_) if hover => 1,
        // T_longest / T_longest is 1 exactly: a one-phase plan gets exactly n.
        Cut::Count(n) => ((n as Real * (total_s / longest_s)).ceil() as usize).max(1),
        Cut::MaxDuration(max_s) => ((total_s / max_s).ceil() as usize).max(1),
    }
}

/// The chain cut by `cut` into pieces in time order covering [0, duration]: each motion in
/// equal pieces, each hover between motions in constant ones; no piece straddles a motion's
/// start or end (where s''' jumps).
pub fn pieces(traj: &AgentTrajectory, cut: Cut) -> Vec<PolyPiece> {
    let longest_s = traj
        .motions
        .iter()
        .map(|m| m.t_total_s)
        .fold(0.0, Real::max);
    let mut out = Vec::new();
    let mut covered_s = 0.0;
    let mut at_rest: Option<Vec3> = None;
    for m in &traj.motions {
        let hover_s = m.t_start_s - covered_s;
        if hover_s > 0.0 {
            // Held where the previous motion ended (s = 1), or at the first one's start.
            let at = at_rest.unwrap_or(m.a);
            let n = count_of(cut, hover_s, longest_s, true);
            let d = hover_s / n as Real;
            out.extend((0..n).map(|k| PolyPiece::constant(covered_s + k as Real * d, d, at)));
        }
        let n = count_of(cut, m.t_total_s, longest_s, false);
        let d = m.t_total_s / n as Real;
        out.extend((0..n).map(|k| m.piece(m.t_start_s + k as Real * d, d)));
        covered_s = m.t_end_s();
        at_rest = Some(m.a + m.b);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_scenario::Scenario;

    /// The paper's Sec. VII leaders over its 200 s plan.
    fn paper_plan() -> TeamPlan {
        Scenario::builtin("paper40")
            .expect("the paper's scenario is valid")
            .plan
    }

    #[test]
    fn pieces_reproduce_the_plan() {
        let plan = paper_plan();
        let alpha = [0.2, 0.5, 0.3];
        let traj = AgentTrajectory::new(&plan, 9, &alpha);
        for count in [1, 3, 7, 31] {
            let ps = pieces(&traj, Cut::Count(count));
            assert_eq!(ps.len(), count);
            for p in &ps {
                for k in 0..=20 {
                    let u = p.duration_s * k as Real / 20.0;
                    let t = p.t0_s + u;
                    let want = plan.agent_derivs(&alpha, t, plan.piece_at(t))[0];
                    assert!((p.eval(u) - want).norm() < 1e-9, "count={count} t={t}");
                }
            }
        }
        let m = traj.motions[0];
        assert_eq!(traj.motions.len(), 1);
        assert_eq!(traj.position(250.0), m.a + m.b);
        assert_eq!(traj.position(-1.0), m.a);
        assert_eq!(traj.duration_s(), 200.0);
    }

    /// A mission (take-off, two segments, landing, hovers between): the chained pieces are the
    /// plan's r_HT to 1e-9 relative at many instants, phase boundaries and hovers included, and
    /// no piece straddles a phase's start or end.
    #[test]
    fn chained_pieces_reproduce_a_mission() {
        let s = Scenario::builtin("paper40-mission").unwrap();
        let plan = &s.plan;
        let phases = plan.phases();
        assert_eq!(phases.len(), 4);
        let mut bounds: Vec<Real> = phases
            .iter()
            .flat_map(|p| [p.t_start_s, p.t_end_s()])
            .collect();
        bounds.dedup();
        for m in &s.formation.members {
            let traj = AgentTrajectory::new(plan, m.id, &m.alpha);
            assert_eq!(traj.duration_s(), plan.end_s());
            let close = |got: Vec3, t: Real| {
                let want = plan.agent_derivs(&m.alpha, t, plan.piece_at(t))[0];
                let err = (got - want).norm();
                assert!(
                    err <= 1e-9 * want.norm().max(1.0),
                    "agent {} t={t} err={err}",
                    m.id
                );
            };
            for cut in [Cut::Count(1), Cut::Count(4), Cut::MaxDuration(60.0)] {
                let ps = pieces(&traj, cut);
                // 4 motions and 3 hovers of 5 s at least.
                assert!(ps.len() >= 7, "{cut:?}");
                let mut end = 0.0;
                for p in &ps {
                    assert!((p.t0_s - end).abs() < 1e-9, "{cut:?}: gap at {end}");
                    end = p.t0_s + p.duration_s;
                    let inside = |b: Real| p.t0_s + 1e-9 < b && b < end - 1e-9;
                    assert!(!bounds.iter().any(|&b| inside(b)), "{cut:?}: straddles");
                    if let Cut::MaxDuration(max) = cut {
                        assert!(p.duration_s <= max + 1e-9);
                    }
                    for k in 0..=10 {
                        let u = p.duration_s * k as Real / 10.0;
                        close(p.eval(u), p.t0_s + u);
                    }
                }
                assert!((end - plan.end_s()).abs() < 1e-9);
            }
            for k in 0..=3000 {
                let t = plan.end_s() * k as Real / 3000.0;
                close(traj.position(t), t);
            }
            for &b in &bounds {
                close(traj.position(b), b);
            }
            // On the ground at both ends.
            assert_eq!(traj.position(0.0).z, 0.0);
            assert!(traj.position(plan.end_s()).z.abs() < 1e-9);
            assert!(traj.z_range().0.abs() < 1e-9);
        }
    }

    #[test]
    fn bezier_ends_and_curve_match() {
        let plan = paper_plan();
        let traj = AgentTrajectory::new(&plan, 1, &[1.0, 0.0, 0.0]);
        let p = traj.motions[0].piece(40.0, 50.0);
        let cp = p.bezier();
        assert!((cp[0] - p.eval(0.0)).norm() < 1e-9);
        assert!((cp[5] - p.eval(50.0)).norm() < 1e-9);
        // de Casteljau at v = 0.3 against the power basis.
        let mut pts = cp.to_vec();
        while pts.len() > 1 {
            pts = pts.windows(2).map(|w| w[0] * 0.7 + w[1] * 0.3).collect();
        }
        assert!((pts[0] - p.eval(15.0)).norm() < 1e-9);
        // A hover is a constant curve: every control point is the point.
        let h = PolyPiece::constant(3.0, 5.0, Vec3::new(1.0, 2.0, 3.0));
        assert!(h.bezier().iter().all(|c| *c == Vec3::new(1.0, 2.0, 3.0)));
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

    /// Over a mission: the fastest and the highest of all its phases.
    #[test]
    fn speeds_and_altitudes_cover_every_phase() {
        let s = Scenario::builtin("paper40-mission").unwrap();
        let m = &s.formation.members[0];
        let traj = AgentTrajectory::new(&s.plan, m.id, &m.alpha);
        let (vxy, vz) = traj.max_speeds();
        let (mut sxy, mut sz, mut top): (Real, Real, Real) = (0.0, 0.0, 0.0);
        let h = 1e-3;
        for k in 1..20000 {
            let t = s.plan.end_s() * k as Real / 20000.0;
            let v = (traj.position(t + h) - traj.position(t - h)) / (2.0 * h);
            sxy = sxy.max(v.xy().norm());
            sz = sz.max(v.z.abs());
            top = top.max(traj.position(t).z);
        }
        assert!(sxy <= vxy * (1.0 + 1e-6) && sxy > 0.99 * vxy, "{sxy} {vxy}");
        assert!(sz <= vz * (1.0 + 1e-6) && sz > 0.99 * vz, "{sz} {vz}");
        assert!(top <= traj.z_range().1 + 1e-9 && top > traj.z_range().1 - 1e-3);
    }
}
