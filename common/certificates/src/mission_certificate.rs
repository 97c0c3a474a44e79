//! The certificate of a mission: each phase certified on its own, the mission's
//! verdict the worst of them, and the whole mission flown once for what carries over.
//!
//! - A deformation segment is the paper's manoeuvre between two waypoints: lambda_1(U_D) over
//!   it (against the reference formation at t0, eq. 37), and E_max(T) on the linear team flying
//!   that segment from rest (`LinearTeam::of_motion`), hence its T_threshold (eq. 34).
//! - Take-off and landing flatten the team onto the ground, where lambda_1 says nothing about
//!   safety. Every member moves vertically, so two members are never closer than their ground
//!   spots: the spots at least 2 (eps + delta) apart, with E_max <= delta, keep the balls apart
//!   (ARCHITECTURE.md, "Take-off and landing").
//! - A phase starts with whatever tracking error the previous one left: the certificate flies
//!   the whole mission once with the nonlinear engine and checks its largest follower deviation
//!   against delta too.

use crate::certificate::{
    t_threshold_from, unstable_gains, verdict_of, Certificate, Findings, PhaseCertificate,
};
use crate::delay::{delay_search, max_link_delay_linear, DelayBound};
use crate::linear_certificate::LinearTeam;
use cdm_engine::engine::max_follower_deviation;
use cdm_math::{Real, Vec3};
use cdm_model::plan::{Phase, PhaseKind, Scaling};
use cdm_records::audit::SafetyNumbers;
use cdm_scenario::{closest_ground_pair, Scenario};

/// The certificate of a scenario whose plan is a mission.
pub fn certify_mission(s: &Scenario) -> Certificate {
    let n = SafetyNumbers::of(s);
    let mut reasons = Vec::new();
    let worst = s.plan.lambda1_min_segments().ok();
    if n.delta_m.is_nan() || n.delta_m <= 0.0 {
        let at = worst.map_or(String::new(), |(l, k)| {
            format!(
                "{}: lambda_1 min {:.4} at t = {:.2} s gives ",
                s.plan.phases()[k].kind.name(),
                l.lambda1,
                l.t_s
            )
        });
        reasons.push(format!(
            "{at}delta = {:.4} m <= 0: eps = {} m is too large for D_B = {:.4} m, D_S = {:.4} m and lambda_CD,min = {:.4} (eq. 38)",
            n.delta_m, n.eps_m, n.d_b_m, n.d_s_m, n.lambda_cd_min
        ));
    }
    let mut rows = Vec::new();
    let mut delay = DelayBound::AtLeast(u64::MAX);
    // Without a positive delta every phase fails for that one reason, said once above.
    let quiet = !reasons.is_empty();
    for p in s.plan.phases() {
        let (row, d) = certify_phase(s, &n, p);
        if !quiet {
            reasons.extend(row.reasons.iter().map(|r| format!("{}: {r}", row.name)));
        }
        delay = tighter(delay, d);
        rows.push(row);
    }
    // What carries over from phase to phase: the mission flown once.
    let flown = max_follower_deviation(s).unwrap_or(Real::INFINITY);
    if !quiet && (flown.is_nan() || flown > n.delta_m) {
        reasons.push(format!(
            "the whole mission flown: max follower deviation {flown:.4} m exceeds delta = {:.4} m (eq. 34; a phase starts with the error the one before left)",
            n.delta_m
        ));
    }
    let margin = s.gains_margin.unwrap_or(Real::NAN);
    reasons.extend(unstable_gains(margin));
    Certificate::assemble(
        s,
        Findings {
            reasons,
            numbers: n,
            t_threshold_s: rows
                .iter()
                .map(|r| r.t_threshold_s)
                .fold(Real::NAN, Real::max),
            t_total_s: s.plan.end_s(),
            max_follower_deviation_m: flown,
            gains_stability_margin: margin,
            max_link_delay: delay,
            segments: Some(rows),
        },
    )
}

/// The tighter of two delay bounds (the mission tolerates the smallest of its phases').
pub(crate) fn tighter(a: DelayBound, b: DelayBound) -> DelayBound {
    use DelayBound::*;
    match (a, b) {
        (None, _) | (_, None) => None,
        (Ticks(x), Ticks(y)) => Ticks(x.min(y)),
        (Ticks(x), AtLeast(y)) | (AtLeast(y), Ticks(x)) => {
            if x <= y {
                Ticks(x)
            } else {
                AtLeast(y)
            }
        }
        (AtLeast(x), AtLeast(y)) => AtLeast(x.min(y)),
    }
}

/// One phase's row and the largest link delay it tolerates.
pub(crate) fn certify_phase(
    s: &Scenario,
    n: &SafetyNumbers,
    p: &Phase,
) -> (PhaseCertificate, DelayBound) {
    // A hold's stop (`command_certificate.rs`) starts moving, not from rest: the linear team
    // from rest does not model it, and its E_max is measured by flying the commanded flight.
    let stop = matches!(p.scaling, Scaling::Stop(_));
    let name = format!("{}{}", p.kind.name(), if stop { " (hold)" } else { "" });
    let mut reasons = Vec::new();
    let l = s.plan.lambda1_min_of(p).ok();
    let (lambda1, t_l) = l.map_or((0.0, p.t_start_s), |l| (l.lambda1, l.t_s));
    let t_s = p.quintic.t_total_s;
    let linear = LinearTeam::of_motion(s, &p.start, &p.goal);
    let (e, t_thr, delay) = match &linear {
        _ if stop => (Real::NAN, Real::NAN, DelayBound::AtLeast(u64::MAX)),
        Ok(team) => {
            let e = team.max_follower_deviation(t_s);
            let t_thr = t_threshold_from(t_s, s.file.comm_hz, n.delta_m, e, |t| {
                team.max_follower_deviation(t)
            });
            let d = max_link_delay_linear(team, t_s, n.delta_m, e, delay_search(t_s, s.dt_s()));
            (e, t_thr, d)
        }
        Err(why) => {
            reasons.push(format!(
                "a mission is certified on the linear team only: {why}"
            ));
            (Real::INFINITY, Real::INFINITY, DelayBound::None)
        }
    };
    if n.delta_m.is_nan() || n.delta_m <= 0.0 {
        reasons.push("delta <= 0 (eq. 38)".into());
    } else if !stop && (t_thr.is_nan() || t_s < t_thr) {
        reasons.push(format!(
            "t_s = {t_s} s is below its T_threshold = {t_thr:.2} s: max follower deviation {e:.4} m exceeds delta = {:.4} m (eq. 34)",
            n.delta_m
        ));
    }
    let mut ground = None;
    if p.kind.is_ground() {
        let top = if p.kind == PhaseKind::Takeoff {
            &p.goal
        } else {
            &p.start
        };
        let (d, a, b) = ground_separation(s, top);
        ground = Some(d);
        let need = 2.0 * (n.eps_m + n.delta_m);
        if d.is_nan() || d < need {
            reasons.push(format!(
                "agents {a} and {b} climb or descend {d:.3} m apart, closer than 2 (eps + delta) = {need:.4} m"
            ));
        }
    } else if lambda1 < n.lambda_cd_min - 1e-12 {
        reasons.push(format!(
            "lambda_1 min {lambda1:.4} at t = {t_l:.2} s below lambda_CD,min = {:.4} (eq. 37)",
            n.lambda_cd_min
        ));
    }
    let row = PhaseCertificate {
        name,
        t_start_s: p.t_start_s,
        t_end_s: p.t_end_s(),
        lambda1_min: lambda1,
        t_lambda1_min_s: t_l,
        d_b_m: n.d_b_m,
        d_s_m: n.d_s_m,
        delta_m: n.delta_m,
        t_threshold_s: t_thr,
        max_follower_deviation_m: e,
        min_ground_separation_m: ground,
        verdict: verdict_of(&reasons),
        reasons,
    };
    (row, delay)
}

/// The closest two members' horizontal distance when the primary leaders are at `top`.
fn ground_separation(s: &Scenario, top: &[Vec3; 3]) -> (Real, u32, u32) {
    let at: Vec<(u32, Vec3)> = (s.formation.members.iter())
        .map(|m| {
            let a = m.alpha;
            (m.id, top[0] * a[0] + top[1] * a[1] + top[2] * a[2])
        })
        .collect();
    closest_ground_pair(&at)
}
