//! The vehicle certificate: every member's commanded speed and acceleration against the
//! `[vehicle]` limits, and separation in the downwash metric, over every phase, exactly.
//!
//! In a phase the primary leaders move r_j(t) = start_j + s(t) (goal_j - start_j) (eq. 15) and
//! every member's desired position is the fixed affine combination r_i,HT = sum_j alpha_ij r_j
//! (eq. 13), so r_i,HT(t) = a_i + s(t) D_i with D_i = b_i - a_i. Its velocity is D_i s'(t) and its
//! acceleration D_i s''(t): the largest value of each limit's measure over the phase is that
//! measure of D_i times max s' or max |s''|, closed forms of the quintic
//! (`cdm_model::limits`). Between phases every member hovers (zero velocity and acceleration).
//!
//! The pair r_i,HT - r_j,HT = (a_i - a_j) + s(t) (D_i - D_j) runs along a straight segment too,
//! so its smallest downwash distance over the phase (and the hovers at its ends) is the
//! distance from the origin to that segment in the scaled metric: exact. Every member is within
//! delta of its desired position in the Euclidean norm (eq. 34), and the downwash distance of an
//! error is at most its Euclidean norm (the ratio is >= 1), so two members' ellipsoids of
//! horizontal semi-axis eps stay apart whenever that smallest distance is at least
//! 2 (eps + delta): the paper's bound of Theorem 3 in the downwash metric (the book's
//! certificates page, "Downwash").

use serde::Serialize;

use cdm_math::{Real, Vec3};
use cdm_model::limits::{segment_min_downwash, Limit};
use cdm_model::plan::{PeakRates, Phase, PhaseKind, Scaling};
use cdm_scenario::Scenario;

/// One limit's largest commanded value over the plan: who, where, when.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LimitPeak {
    /// The `[vehicle]` key (`max_speed_xy_m_s`, ...).
    pub limit: &'static str,
    /// The limit's value in the file.
    pub max: Real,
    /// The largest commanded value (m/s or m/s^2) and the member commanding it.
    pub value: Real,
    pub agent: u32,
    /// The phase (`segment 1` without a mission) and the instant of the peak.
    pub phase: String,
    pub t_s: Real,
}

impl LimitPeak {
    /// True when the plan commands more than the vehicle can fly.
    pub fn exceeded(&self) -> bool {
        self.value > self.max || self.value.is_nan()
    }
}

/// The closest two members in the downwash metric over the plan.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DownwashClearance {
    pub downwash_ratio: Real,
    /// 2 (eps + delta): the smallest downwash distance of two desired positions that keeps the
    /// ellipsoids apart.
    pub required_m: Real,
    /// The smallest downwash distance of two members' desired positions, who and when.
    pub min_m: Real,
    pub agents: [u32; 2],
    pub phase: String,
    pub t_s: Real,
}

/// The shortest travel time of one phase that meets every limit (`plan --suggest`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PhaseTime {
    pub phase: String,
    /// The scenario key that sets it (`t_total_s`, `takeoff.t_s`, `segment N t_s`, ...).
    pub key: String,
    pub t_s: Real,
    /// Rounded up to the millisecond, so that the suggested time passes.
    pub shortest_t_s: Real,
    /// The limit and member that set it (absent when no member loads any limit).
    pub limit: Option<&'static str>,
    pub agent: Option<u32>,
}

/// The vehicle part of `plan`'s certificate (absent without a `[vehicle]` table).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VehicleCertificate {
    /// Every limit the file sets, in the file's order.
    pub limits: Vec<LimitPeak>,
    /// With `downwash_ratio`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub downwash: Option<DownwashClearance>,
    /// `plan --suggest`: per phase, the shortest travel time meeting the limits.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub suggestion: Option<Vec<PhaseTime>>,
}

impl VehicleCertificate {
    /// The UNSAFE reasons: each limit exceeded, the downwash clearance short.
    pub fn reasons(&self) -> Vec<String> {
        let mut out: Vec<String> = (self.limits.iter().filter(|p| p.exceeded()))
            .map(|p| {
                let unit = unit_of(p.limit);
                format!(
                    "vehicle limit {}: member {} in {} commands {:.4} {unit} at t = {:.2} s, above {} {unit}",
                    p.limit, p.agent, p.phase, p.value, p.t_s, p.max
                )
            })
            .collect();
        if let Some(d) = self
            .downwash
            .as_ref()
            .filter(|d| d.min_m < d.required_m || d.min_m.is_nan())
        {
            out.push(format!(
                "downwash: members {} and {} in {} come {:.4} m apart in the downwash metric (ratio {}) at t = {:.2} s, below 2 (eps + delta) = {:.4} m",
                d.agents[0], d.agents[1], d.phase, d.min_m, d.downwash_ratio, d.t_s, d.required_m
            ));
        }
        out
    }
}

fn unit_of(key: &str) -> &'static str {
    Limit::ALL
        .into_iter()
        .find(|l| l.key() == key)
        .map_or("", Limit::unit)
}

/// The largest value of `limit`'s measure over phase `p` for a member moving by `d`: the
/// quintic's closed form for a rest-to-rest phase, the phase's own peak rates for one a command
/// cut or stopped (a hold's stop: its cubic's extremes; a cut: its whole quintic's).
fn peak_in(p: &Phase, limit: Limit, d: &Vec3, rates: &PeakRates) -> Real {
    match p.scaling {
        Scaling::RestToRest => limit.peak(d, p.quintic.t_total_s),
        _ if limit.is_accel() => limit.measure(d) * rates.accel,
        _ => limit.measure(d) * rates.speed,
    }
}

/// About when into phase `p` the peak of `limit` is.
fn peak_at(p: &Phase, limit: Limit, t: Real, rates: &PeakRates) -> Real {
    match p.scaling {
        Scaling::RestToRest => limit.tau_of_peak() * t,
        _ if limit.is_accel() => rates.accel_at_s,
        _ => rates.speed_at_s,
    }
}

/// Each member's desired segment over a phase: (a_i, D_i), in formation order.
fn segments(s: &Scenario, p: &Phase) -> Vec<(Vec3, Vec3)> {
    let d: [Vec3; 3] = std::array::from_fn(|j| p.goal[j] - p.start[j]);
    (s.formation.members.iter())
        .map(|m| {
            let a = combine_points(&m.alpha, &p.start);
            (a, combine_points(&m.alpha, &d))
        })
        .collect()
}

/// sum_j alpha_j v_j (eq. 13; the order of `plan::combine`).
fn combine_points(alpha: &[Real; 3], v: &[Vec3; 3]) -> Vec3 {
    v[0] * alpha[0] + v[1] * alpha[1] + v[2] * alpha[2]
}

/// The vehicle certificate of `s` with the tracking bound `delta_m` (eq. 38); `None` without a
/// `[vehicle]` table.
pub fn certify_vehicle(s: &Scenario, delta_m: Real) -> Option<VehicleCertificate> {
    let spec = s.file.vehicle?;
    let phases = s.plan.phases();
    let per_phase: Vec<Vec<(Vec3, Vec3)>> = phases.iter().map(|p| segments(s, p)).collect();
    let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
    let limits = (spec.limits().into_iter())
        .map(|(limit, max)| {
            let mut best: Option<LimitPeak> = None;
            for (p, segs) in phases.iter().zip(&per_phase) {
                let t = p.quintic.t_total_s;
                let rates = p.peak_rates();
                for (k, (_, d)) in segs.iter().enumerate() {
                    let value = peak_in(p, limit, d, &rates);
                    if best.as_ref().is_none_or(|b| value > b.value) {
                        best = Some(LimitPeak {
                            limit: limit.key(),
                            max,
                            value,
                            agent: ids[k],
                            phase: p.kind.name(),
                            t_s: p.t_start_s + peak_at(p, limit, t, &rates),
                        });
                    }
                }
            }
            best.unwrap_or(LimitPeak {
                limit: limit.key(),
                max,
                value: 0.0,
                agent: ids.first().copied().unwrap_or(0),
                phase: String::new(),
                t_s: 0.0,
            })
        })
        .collect();
    let downwash = spec.downwash_ratio.map(|ratio| {
        let (min_m, agents, phase, t_s) = closest_pair(phases, &per_phase, &ids, ratio);
        DownwashClearance {
            downwash_ratio: ratio,
            required_m: 2.0 * (s.file.eps_m + delta_m),
            min_m,
            agents,
            phase,
            t_s,
        }
    });
    Some(VehicleCertificate {
        limits,
        downwash,
        suggestion: None,
    })
}

/// The smallest downwash distance between two members' desired positions over every phase:
/// (distance, ids, phase, instant).
fn closest_pair(
    phases: &[Phase],
    per_phase: &[Vec<(Vec3, Vec3)>],
    ids: &[u32],
    ratio: Real,
) -> (Real, [u32; 2], String, Real) {
    let mut best = (Real::INFINITY, [0, 0], String::new(), 0.0);
    for (p, segs) in phases.iter().zip(per_phase) {
        for (i, (ai, di)) in segs.iter().enumerate() {
            for (j, (aj, dj)) in segs.iter().enumerate().skip(i + 1) {
                let a = ai - aj;
                let (d, s) = segment_min_downwash(&a, &(a + (di - dj)), ratio);
                if d < best.0 {
                    let (x, y) = (ids[i].min(ids[j]), ids[i].max(ids[j]));
                    best = (d, [x, y], p.kind.name(), p.t_start_s + p.quintic.time_of(s));
                }
            }
        }
    }
    best
}

/// The scenario key that sets a phase's travel time.
fn time_key(kind: PhaseKind) -> String {
    match kind {
        PhaseKind::Takeoff => "takeoff.t_s".into(),
        PhaseKind::Segment(1) => "t_total_s".into(),
        PhaseKind::Segment(n) => format!("t_s of [[segment]] {}", n - 1),
        PhaseKind::Landing => "landing.t_s".into(),
    }
}

/// `plan --suggest`: per phase, the shortest travel time whose commanded peaks meet every limit
/// (a speed's peak scales as 1/T, an acceleration's as 1/T^2), rounded up to the millisecond.
pub fn suggest_times(s: &Scenario) -> Vec<PhaseTime> {
    let Some(spec) = s.file.vehicle else {
        return Vec::new();
    };
    let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
    (s.plan.phases().iter())
        .map(|p| {
            let mut need: (Real, Option<&'static str>, Option<u32>) = (0.0, None, None);
            for (k, (_, d)) in segments(s, p).iter().enumerate() {
                for (limit, max) in spec.limits() {
                    let t = limit.shortest_time(d, max);
                    if t > need.0 {
                        need = (t, Some(limit.key()), Some(ids[k]));
                    }
                }
            }
            PhaseTime {
                phase: p.kind.name(),
                key: time_key(p.kind),
                t_s: p.quintic.t_total_s,
                shortest_t_s: (need.0 * 1000.0).ceil() / 1000.0,
                limit: need.1,
                agent: need.2,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_model::plan::Segment;
    use cdm_scenario::{paper40, Checks, VehicleSpec};

    fn paper40_with(v: VehicleSpec) -> Scenario {
        let mut f = paper40();
        f.vehicle = Some(v);
        Scenario::from_file(f, "test", Checks::Member).unwrap()
    }

    /// The exact peak of every member against a dense scan of its commanded velocity and
    /// acceleration (the plan's own derivatives, eq. 13): the scan never exceeds it and comes
    /// within the grid's resolution of it.
    #[test]
    fn the_exact_peaks_bound_a_dense_scan_of_the_plan() {
        let v = VehicleSpec {
            max_speed_xy_m_s: Some(1.0),
            max_speed_up_m_s: Some(1.0),
            max_speed_down_m_s: Some(1.0),
            max_accel_xy_m_s2: Some(1.0),
            max_accel_z_m_s2: Some(1.0),
            downwash_ratio: None,
        };
        let s = paper40_with(v);
        let c = certify_vehicle(&s, 1.0).unwrap();
        let t_total = s.file.t_total_s;
        let mut scan = [0.0; 5];
        for k in 0..=4000 {
            let t = t_total * k as Real / 4000.0;
            let piece = s.plan.piece_at(t);
            for m in &s.formation.members {
                let d = s.plan.agent_derivs(&m.alpha, t, piece);
                for (x, l) in scan.iter_mut().zip(Limit::ALL) {
                    *x = Real::max(*x, l.measure(if l.is_accel() { &d[2] } else { &d[1] }));
                }
            }
        }
        for (peak, x) in c.limits.iter().zip(scan) {
            assert!(x <= peak.value * (1.0 + 1e-12), "{peak:?} scan {x}");
            assert!(x >= peak.value * (1.0 - 1e-5), "{peak:?} scan {x}");
        }
        assert_eq!(s.plan.piece_at(0.0).segment, Segment::Motion);
    }

    /// The suggested time meets every limit and a time 1 % shorter does not.
    #[test]
    fn the_suggested_time_is_the_shortest_that_passes() {
        let v = VehicleSpec {
            max_speed_xy_m_s: Some(2.0),
            max_accel_z_m_s2: Some(0.05),
            ..VehicleSpec::default()
        };
        let s = paper40_with(v);
        let c = certify_vehicle(&s, 1.0).unwrap();
        assert!(!c.reasons().is_empty(), "{c:?}");
        let t = suggest_times(&s)[0].shortest_t_s;
        let at = |t_s: Real| {
            let mut f = s.file.clone();
            f.t_total_s = t_s;
            let s = Scenario::from_file(f, "test", Checks::Member).unwrap();
            certify_vehicle(&s, 1.0).unwrap().reasons()
        };
        assert!(at(t).is_empty(), "{:?}", at(t));
        assert!(!at(t * 0.99).is_empty());
    }

    /// The followers' overshoot of their commanded peaks, flown by the nonlinear engine on
    /// paper40 at its T_threshold (36 s) and at 60 and 120 s, stays under the live audit's
    /// tolerances: the numbers the book quotes (`--nocapture` prints them).
    #[test]
    fn the_followers_overshoot_stays_under_the_audits_tolerance() {
        use cdm_model::formation::Role;
        use cdm_records::limit_audit::tolerance;
        for t_total_s in [36.0, 60.0, 120.0] {
            let mut f = paper40();
            f.t_total_s = t_total_s;
            let s = Scenario::from_file(f, "test", Checks::Member).unwrap();
            let segs = segments(&s, &s.plan.phases()[0]);
            let mut e = cdm_engine::engine::quad_engine(&s);
            let n = s.formation.members.len();
            let mut flown = vec![[0.0; 5]; n];
            while e.tick() < s.last_tick() {
                e.advance().unwrap();
                for (k, x) in e.states().iter().enumerate() {
                    let fl = x.flat();
                    for (j, l) in Limit::ALL.into_iter().enumerate() {
                        let v = l.measure(if l.is_accel() { &fl.a } else { &fl.v });
                        flown[k][j] = Real::max(flown[k][j], v);
                    }
                }
            }
            let mut worst = [0.0; 5];
            for (k, m) in s.formation.members.iter().enumerate() {
                for (j, l) in Limit::ALL.into_iter().enumerate() {
                    let commanded = l.peak(&segs[k].1, t_total_s);
                    if m.role == Role::Follower && commanded > 1e-3 {
                        worst[j] = Real::max(worst[j], flown[k][j] / commanded - 1.0);
                    }
                }
            }
            println!("paper40 at {t_total_s} s: followers' overshoot {worst:.4?} (xy, up, down speed; xy, z acceleration)");
            for (w, l) in worst.iter().zip(Limit::ALL) {
                assert!(*w < tolerance(l), "{l:?} {w}");
            }
        }
    }
}
