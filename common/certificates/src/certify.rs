//! `orchestrator plan`'s certificate of a scenario: the paper's manoeuvre or a mission phase by
//! phase, and the airspace's margins.

use crate::airspace_certificate::certify_airspace;
use crate::certificate::{
    deviation_at, t_threshold, unstable_gains, verdict_of, Certificate, Findings,
};
use crate::delay::max_link_delay;
use crate::linear_certificate::LinearTeam;
use crate::mission_certificate::certify_mission;
use crate::vehicle_certificate::certify_vehicle;
use cdm_math::Real;
use cdm_records::audit::SafetyNumbers;
use cdm_scenario::Scenario;

/// The certificate of a scenario validated with `Checks::Full`: the paper's (or the mission's)
/// and, with a geofence or obstacles, the airspace's, and with `[vehicle]`, the limits' and the
/// downwash's, whose breaches are reasons too.
pub fn certify(s: &Scenario) -> Certificate {
    let mut c = if s.plan.is_mission() {
        certify_mission(s)
    } else {
        certify_one(s)
    };
    c.airspace = certify_airspace(s, c.numbers.delta_m);
    if let Some(a) = &c.airspace {
        c.reasons.extend(a.reasons());
        c.verdict = verdict_of(&c.reasons);
    }
    c.vehicle = certify_vehicle(s, c.numbers.delta_m);
    if let Some(v) = &c.vehicle {
        c.reasons.extend(v.reasons());
        c.verdict = verdict_of(&c.reasons);
    }
    c
}

/// The certificate of the paper's one manoeuvre.
fn certify_one(s: &Scenario) -> Certificate {
    let n = SafetyNumbers::of(s);
    // E(T) on the exactly linear error dynamics when the graph allows (linear_certificate.rs),
    // otherwise by flying the nonlinear team at every trial T.
    let linear = LinearTeam::new(s)
        .inspect_err(|why| tracing::info!("the certificate flies the plan: {why}"))
        .ok();
    let deviation = |t| match &linear {
        Some(team) => team.max_follower_deviation(t),
        None => deviation_at(s, t),
    };
    let e = deviation(s.file.t_total_s);
    let t_thr = t_threshold(s, n.delta_m, e, deviation);
    let margin = s.gains_margin.unwrap_or(Real::NAN);
    let mut reasons = Vec::new();
    if n.delta_m.is_nan() || n.delta_m <= 0.0 {
        reasons.push(format!(
            "delta = {:.4} m <= 0: eps = {} m is too large for D_B = {:.4} m, D_S = {:.4} m and lambda_CD,min = {:.4} (eq. 38)",
            n.delta_m, n.eps_m, n.d_b_m, n.d_s_m, n.lambda_cd_min
        ));
    }
    if n.lambda1_min < n.lambda_cd_min - 1e-12 {
        reasons.push(format!(
            "lambda_1(U_D) falls to {:.4} at t = {:.2} s, below lambda_CD,min = {:.4} (eq. 37)",
            n.lambda1_min, n.t_lambda1_min_s, n.lambda_cd_min
        ));
    }
    if t_thr.is_nan() || s.file.t_total_s < t_thr {
        reasons.push(format!(
            "t_total_s = {} s is below T_threshold = {:.2} s: max follower deviation {:.4} m exceeds delta = {:.4} m (eq. 34)",
            s.file.t_total_s, t_thr, e, n.delta_m
        ));
    }
    reasons.extend(unstable_gains(margin));
    Certificate::assemble(
        s,
        Findings {
            reasons,
            numbers: n,
            t_threshold_s: t_thr,
            t_total_s: s.file.t_total_s,
            max_follower_deviation_m: e,
            gains_stability_margin: margin,
            max_link_delay: max_link_delay(s, n.delta_m, e, linear.as_ref()),
            segments: None,
        },
    )
}
