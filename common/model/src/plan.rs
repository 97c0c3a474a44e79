//! Leader plans: the quintic of eqs. 15-16 with exact derivatives, the primary leaders' desired
//! trajectories, and every other member's global desired position through its alpha parameters
//! (eqs. 13-14, 23).

use crate::frame::{deformation_eigenvalues, CollinearLeaders, Homogeneous};
use crate::stop::StopProfile;
use cdm_math::{Mat3, Real, Vec3};

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

/// How long a mission that lands goes on after its leaders touch down: the followers' error
/// decays at least as e^(-0.585 t) with the paper's gains (their slowest pole), so 10 s take a
/// 0.3 m lag to under a millimetre.
pub const LANDING_SETTLE_S: Real = 10.0;

/// Position and its first four time derivatives.
pub type Derivs = [Vec3; 5];

/// What a phase of a mission is. A scenario without mission tables has one phase,
/// `Segment(1)`: the paper's single manoeuvre.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PhaseKind {
    /// Every member rises vertically from the ground below its start position.
    Takeoff,
    /// A continuum deformation between two waypoints of the primary leaders, numbered from 1 in
    /// flight order (1 is the agents' own `goal`).
    Segment(u32),
    /// Every member descends vertically to the ground below its final position.
    Landing,
}

impl PhaseKind {
    /// `takeoff`, `segment N`, `landing`: how messages and `--json` name it.
    pub fn name(&self) -> String {
        match self {
            PhaseKind::Takeoff => "takeoff".into(),
            PhaseKind::Segment(n) => format!("segment {n}"),
            PhaseKind::Landing => "landing".into(),
        }
    }

    /// Take-off and landing: homogeneous transformations that flatten the team onto the ground,
    /// where the deformation bound of eq. 37 is not the safety argument (ARCHITECTURE.md).
    pub fn is_ground(&self) -> bool {
        !matches!(self, PhaseKind::Segment(_))
    }
}

/// How a phase's path parameter s runs from 0 to 1 (eq. 15 holds with any s(t): the leaders
/// stay on the straight segment from `start` to `goal`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Scaling {
    /// Eq. 16's quintic over `quintic.t_total_s`, rest to rest.
    #[default]
    RestToRest,
    /// Eq. 16's quintic, but the phase ends `until_s` into it: a command switched the team to
    /// another motion there (the next phase carries on from the same position, velocity and
    /// acceleration).
    Cut { until_s: Real },
    /// The leaders brought to rest from moving (`stop.rs`), in units of the segment it stops;
    /// this phase's `start`..`goal` is the part flown, s = (S - s0) / `stop.distance()`.
    Stop(StopProfile),
}

/// The largest s' (1/s) and |s''| (1/s^2) over a phase's motion, and about when (seconds into
/// the phase; 0 for a stop, whose extremes are usually at the switch).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeakRates {
    pub speed: Real,
    pub speed_at_s: Real,
    pub accel: Real,
    pub accel_at_s: Real,
}

/// One phase: the primary leaders move from `start` to `goal` on the quintic of eq. 15, rest to
/// rest, from `t_start_s` (or as `scaling` says); before it (after the previous phase) they
/// hover.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Phase {
    pub kind: PhaseKind,
    pub t_start_s: Real,
    pub quintic: Quintic,
    pub start: [Vec3; 3],
    pub goal: [Vec3; 3],
    pub scaling: Scaling,
}

impl Phase {
    /// A phase on eq. 16's quintic, rest to rest.
    pub fn rest_to_rest(
        kind: PhaseKind,
        t_start_s: Real,
        t_s: Real,
        start: [Vec3; 3],
        goal: [Vec3; 3],
    ) -> Phase {
        Phase {
            kind,
            t_start_s,
            quintic: Quintic { t_total_s: t_s },
            start,
            goal,
            scaling: Scaling::RestToRest,
        }
    }

    /// How long the phase's motion lasts.
    pub fn duration_s(&self) -> Real {
        match self.scaling {
            Scaling::RestToRest => self.quintic.t_total_s,
            Scaling::Cut { until_s } => until_s,
            Scaling::Stop(stop) => stop.t_s,
        }
    }

    /// The instant the phase's motion ends (its leaders at rest at `goal`, unless cut).
    pub fn t_end_s(&self) -> Real {
        self.t_start_s + self.duration_s()
    }

    /// The largest s' and |s''| over the phase's motion, with the time into the phase of each
    /// (the vehicle limits of `limits.rs` are |measure(D_i)| times these). Exact for a
    /// rest-to-rest phase (the quintic's closed forms) and for a stop (its cubic's extremes);
    /// a cut phase flies part of its quintic, so the whole quintic's peaks bound it.
    pub fn peak_rates(&self) -> PeakRates {
        let t = self.quintic.t_total_s;
        match self.scaling {
            Scaling::RestToRest | Scaling::Cut { .. } => PeakRates {
                speed: crate::limits::PEAK_SPEED_TIMES_T / t,
                speed_at_s: 0.5 * t,
                accel: crate::limits::PEAK_ACCEL_TIMES_T2 / (t * t),
                accel_at_s: crate::limits::TAU_PEAK_ACCEL * t,
            },
            Scaling::Stop(stop) => {
                let span = stop.distance();
                PeakRates {
                    speed: stop.peak_speed() / span,
                    speed_at_s: 0.0,
                    accel: stop.peak_acceleration() / span,
                    accel_at_s: 0.0,
                }
            }
        }
    }

    /// The derivatives 0..4 of s, `tau` seconds into the phase on `segment`.
    pub fn s_derivatives(&self, tau: Real, segment: Segment) -> [Real; 5] {
        match self.scaling {
            Scaling::RestToRest => self.quintic.derivatives(tau, segment),
            Scaling::Cut { until_s } => match segment {
                Segment::Motion => self.quintic.derivatives(tau.min(until_s), segment),
                // Never flown: a cut phase is always followed by the motion it was cut for.
                Segment::Hold => {
                    let s = self.quintic.derivatives(until_s, Segment::Motion)[0];
                    [s, 0.0, 0.0, 0.0, 0.0]
                }
            },
            Scaling::Stop(stop) => {
                if segment == Segment::Hold {
                    return [1.0, 0.0, 0.0, 0.0, 0.0];
                }
                let span = stop.distance();
                stop.derivatives(tau).map(|d| d / span)
            }
        }
    }

    /// The time into the phase at which s reaches `s_target` in [0, 1] (s is monotone).
    pub fn time_of(&self, s_target: Real) -> Real {
        if let Scaling::RestToRest = self.scaling {
            return self.quintic.time_of(s_target);
        }
        let (mut lo, mut hi) = (0.0, self.duration_s());
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if self.s_derivatives(mid, Segment::Motion)[0] < s_target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// Primary leaders' positions at this phase's path parameter s.
    pub fn primaries_at_s(&self, s: Real) -> [Vec3; 3] {
        std::array::from_fn(|i| self.start[i] + (self.goal[i] - self.start[i]) * s)
    }

    /// Derivatives 0..4 of each primary leader's desired position (eq. 15) at mission time t.
    fn primary_derivs(&self, t: Real, segment: Segment) -> [Derivs; 3] {
        // `t - 0.0` is `t` exactly: a one-phase plan evaluates the very same numbers as before
        // missions existed (the golden telemetry pins it).
        let s = self.s_derivatives(t - self.t_start_s, segment);
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
}

/// Where an instant or an integration interval lies: which phase, and whether in its motion or
/// in the hover after it (ERRATA 12: s''' and s'''' jump at every phase's start and end).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Piece {
    pub phase: usize,
    pub segment: Segment,
}

/// The primary leaders' plan (eq. 15): r_i(t) = r_i0 + (r_ig - r_i0) s(t), i = 1, 2, 3, and
/// the homogeneous transformation they define; a mission chains several such phases.
#[derive(Debug, Clone, PartialEq)]
pub struct TeamPlan {
    /// Segment 1 (the agents' own `goal` and `t_total_s`): its quintic, start and goal.
    pub quintic: Quintic,
    pub start: [Vec3; 3],
    pub goal: [Vec3; 3],
    homogeneous: Homogeneous,
    /// Every phase in flight order, starting at t = 0 (one phase without mission tables).
    phases: Vec<Phase>,
    /// A commanded team that ends hovering flies on at least until then (the flight it was
    /// launched for).
    end_not_before_s: Real,
    /// A commanded plan: the smallest lambda_1(U_D) of the plan the team was launched with
    /// (`None`: this plan is the launched one). The team keeps the safety numbers it was
    /// certified with (eqs. 37-38) through every command: each command is certified against
    /// them, and the audit holds the flight to them.
    launched_lambda1: Option<Lambda1Min>,
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
        let quintic = Quintic { t_total_s };
        Ok(TeamPlan {
            quintic,
            start,
            goal,
            homogeneous: Homogeneous::new(&start)?,
            phases: vec![Phase::rest_to_rest(
                PhaseKind::Segment(1),
                0.0,
                t_total_s,
                start,
                goal,
            )],
            end_not_before_s: 0.0,
            launched_lambda1: None,
        })
    }

    /// The same reference formation (segment 1's start) flying `phases` instead (a mission:
    /// `scenario/mission.rs` builds and checks them).
    pub fn with_phases(mut self, phases: Vec<Phase>) -> Self {
        self.phases = phases;
        self
    }

    /// The same plan, hovering after its last phase until at least `t_s` unless it lands.
    pub fn hovering_until(mut self, t_s: Real) -> Self {
        self.end_not_before_s = t_s;
        self
    }

    /// The same plan, to be commanded: it remembers the smallest lambda_1 of the plan it was
    /// launched as ([`Self::launched_lambda1_min`]), whatever phases commands give it.
    pub fn commandable(mut self) -> Self {
        self.launched_lambda1 = Some(self.launched_lambda1_min());
        self
    }

    /// The smallest lambda_1(U_D) over the deformation segments of the plan the team was
    /// launched with (0 when its primary leaders become collinear): this plan's own unless it
    /// was commanded. The safety numbers of a team are this one's (eqs. 37-38), commanded or
    /// not.
    pub fn launched_lambda1_min(&self) -> Lambda1Min {
        self.launched_lambda1.unwrap_or_else(|| {
            self.lambda1_min_segments().map_or(
                Lambda1Min {
                    lambda1: 0.0,
                    s: 0.0,
                    t_s: 0.0,
                },
                |(l, _)| l,
            )
        })
    }

    /// Every phase in flight order.
    pub fn phases(&self) -> &[Phase] {
        &self.phases
    }

    /// True for a plan of more than the paper's one manoeuvre.
    pub fn is_mission(&self) -> bool {
        self.phases.len() > 1
    }

    /// The end of the last phase's motion: after it every leader hovers at its last goal.
    pub fn end_s(&self) -> Real {
        self.phases.last().map_or(0.0, Phase::t_end_s)
    }

    /// The end of the flight: the last phase's end, and `LANDING_SETTLE_S` more after a landing.
    /// Followers lag their plan (ERRATA 8) and are still moving when the landing's leaders
    /// touch down; the run goes on until they are at rest on the ground too.
    pub fn flight_end_s(&self) -> Real {
        match self.phases.last() {
            Some(p) if p.kind == PhaseKind::Landing => p.t_end_s() + LANDING_SETTLE_S,
            _ => self.end_s().max(self.end_not_before_s),
        }
    }

    /// The piece an instant lies on: a phase's motion when t is inside it (its end included, as
    /// the one-phase plan always did), otherwise the hover after the last phase ended before t.
    pub fn piece_at(&self, t: Real) -> Piece {
        let mut hold = 0;
        for (k, p) in self.phases.iter().enumerate() {
            if t < p.t_start_s {
                break;
            }
            if t <= p.t_end_s() {
                return Piece {
                    phase: k,
                    segment: Segment::Motion,
                };
            }
            hold = k;
        }
        Piece {
            phase: hold,
            segment: Segment::Hold,
        }
    }

    /// The first instant strictly inside (t_start, t_end) where s''' jumps (a phase's start or
    /// end): an integration step must be split there (ERRATA 12).
    pub fn break_inside(&self, t_start: Real, t_end: Real) -> Option<Real> {
        self.phases
            .iter()
            .flat_map(|p| [p.t_start_s, p.t_end_s()])
            .find(|&b| t_start < b && b < t_end)
    }

    /// The piece of an integration interval with no break inside it.
    pub fn piece_of(&self, t_start: Real, t_end: Real) -> Piece {
        self.piece_at(0.5 * (t_start + t_end))
    }

    /// Primary leaders' positions at segment 1's path parameter s.
    pub fn primaries_at_s(&self, s: Real) -> [Vec3; 3] {
        std::array::from_fn(|i| self.start[i] + (self.goal[i] - self.start[i]) * s)
    }

    /// Derivatives 0..4 of each primary leader's desired position (eq. 15) on `piece`.
    pub fn primary_derivs(&self, t: Real, piece: Piece) -> [Derivs; 3] {
        self.phases[piece.phase].primary_derivs(t, piece.segment)
    }

    /// Derivatives 0..4 of r_HT for a member with alpha parameters `alpha` (eq. 13): an affine
    /// combination of the primary leaders' (ERRATA, "useful identities"), so no numerical
    /// differentiation is needed.
    pub fn agent_derivs(&self, alpha: &[Real; 3], t: Real, piece: Piece) -> Derivs {
        combine(alpha, &self.primary_derivs(t, piece))
    }

    /// Q and d at segment 1's path parameter s (eq. 11).
    pub fn q_d_at_s(&self, s: Real) -> Result<(Mat3, Vec3), CollinearLeaders> {
        self.homogeneous.q_d(&self.primaries_at_s(s))
    }

    /// Q and d at time t (eq. 11), against the reference formation at t0 (segment 1's start).
    pub fn q_d_at(&self, t: Real) -> Result<(Mat3, Vec3), CollinearLeaders> {
        let p = self.primary_derivs(t, self.piece_at(t));
        self.homogeneous.q_d(&[p[0][0], p[1][0], p[2][0]])
    }

    /// Eigenvalues of U_D at segment 1's path parameter s.
    pub fn lambdas_at_s(&self, s: Real) -> Result<[Real; 3], CollinearLeaders> {
        Ok(deformation_eigenvalues(&self.q_d_at_s(s)?.0))
    }

    /// The smallest lambda_1(U_D) over segment 1 and when it happens.
    pub fn lambda1_min(&self) -> Result<Lambda1Min, CollinearLeaders> {
        let first = self
            .phases
            .iter()
            .position(|p| p.kind == PhaseKind::Segment(1))
            .unwrap_or(0);
        self.lambda1_min_of(&self.phases[first])
    }

    /// The smallest lambda_1(U_D) over every deformation segment (not take-off or landing) and
    /// the index of the phase where it happens.
    pub fn lambda1_min_segments(&self) -> Result<(Lambda1Min, usize), CollinearLeaders> {
        let mut best: Option<(Lambda1Min, usize)> = None;
        for (k, p) in self.phases.iter().enumerate() {
            if p.kind.is_ground() {
                continue;
            }
            let m = self.lambda1_min_of(p)?;
            if best.is_none_or(|(b, _)| m.lambda1 < b.lambda1) {
                best = Some((m, k));
            }
        }
        best.ok_or(CollinearLeaders { sine: 0.0 })
    }

    /// The smallest lambda_1(U_D) over one phase and when it happens. U_D depends on t only
    /// through s, so the scan is over s in [0, 1]: a dense grid, then golden-section refinement.
    /// Fails when the primary leaders become collinear anywhere on the way.
    pub fn lambda1_min_of(&self, phase: &Phase) -> Result<Lambda1Min, CollinearLeaders> {
        const GRID: usize = 2000;
        let l1 = |s: Real| -> Result<Real, CollinearLeaders> {
            let q = self.homogeneous.q_d(&phase.primaries_at_s(s))?.0;
            Ok(deformation_eigenvalues(&q)[0])
        };
        let mut best = (Real::INFINITY, 0.0);
        for k in 0..=GRID {
            let s = k as Real / GRID as Real;
            let l = l1(s)?;
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
            if l1(c)? < l1(d)? {
                b = d;
            } else {
                a = c;
            }
        }
        let s = 0.5 * (a + b);
        let l = l1(s)?;
        let (lambda1, s) = if l < best.0 { (l, s) } else { best };
        Ok(Lambda1Min {
            lambda1,
            s,
            t_s: phase.t_start_s + phase.time_of(s),
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

    const MOTION: Piece = Piece {
        phase: 0,
        segment: Segment::Motion,
    };

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
        let p0 = combine(&alpha, &plan.primary_derivs(0.0, MOTION))[0];
        for &t in &[0.0, 40.0, 100.0] {
            let s = plan.quintic.derivatives(t, Segment::Motion)[0];
            let (q, d) = plan.q_d_at_s(s).unwrap();
            let via_alpha = plan.agent_derivs(&alpha, t, MOTION)[0];
            assert!((q * p0 + d - via_alpha).norm() < 1e-9);
        }
    }

    /// Two phases with a hover between: the pieces, the breaks an RK4 step must not straddle,
    /// and a plan that is continuous in position, velocity and acceleration across them.
    #[test]
    fn a_chain_of_phases_is_smooth_and_split_at_every_start_and_end() {
        let one = paper_plan(100.0);
        let (a, b) = (one.start, one.goal);
        let back = Phase::rest_to_rest(PhaseKind::Segment(2), 105.0, 50.0, b, a);
        let plan = one.clone().with_phases(vec![one.phases()[0], back]);
        assert!(plan.is_mission() && !one.is_mission());
        assert_eq!(plan.end_s(), 155.0);
        let piece = |phase, segment| Piece { phase, segment };
        assert_eq!(plan.piece_at(100.0), piece(0, Segment::Motion));
        assert_eq!(plan.piece_at(102.0), piece(0, Segment::Hold));
        assert_eq!(plan.piece_at(105.0), piece(1, Segment::Motion));
        assert_eq!(plan.piece_at(200.0), piece(1, Segment::Hold));
        assert_eq!(plan.break_inside(99.99, 100.01), Some(100.0));
        assert_eq!(plan.break_inside(104.99, 105.01), Some(105.0));
        assert_eq!(plan.break_inside(100.0, 105.0), None);
        for t in [100.0, 105.0, 155.0] {
            let before = plan.primary_derivs(t - 1e-9, plan.piece_at(t - 1e-9));
            let after = plan.primary_derivs(t + 1e-9, plan.piece_at(t + 1e-9));
            for k in 0..3 {
                for d in 0..3 {
                    assert!(
                        (before[k][d] - after[k][d]).norm() < 1e-6,
                        "t {t} leader {k} d{d}"
                    );
                }
            }
        }
        // Segment 2 ends where segment 1 started; half way it is half way (s(T/2) = 1/2).
        let end = plan.primary_derivs(155.0, plan.piece_at(155.0));
        let mid = plan.primary_derivs(130.0, plan.piece_at(130.0));
        for k in 0..3 {
            assert!((end[k][0] - a[k]).norm() < 1e-9);
            assert!((mid[k][0] - (a[k] + b[k]) * 0.5).norm() < 1e-9);
        }
        // A one-phase plan: the old rule (motion up to T_total included, hover after).
        assert_eq!(one.piece_at(100.0), piece(0, Segment::Motion));
        assert_eq!(one.piece_of(99.99, 100.0), piece(0, Segment::Motion));
        assert_eq!(one.piece_of(100.0, 100.01), piece(0, Segment::Hold));
        assert_eq!(one.break_inside(99.995, 100.005), Some(100.0));
    }
}
