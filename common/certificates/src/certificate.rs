//! The pre-flight certificate of `orchestrator plan` and how it is assembled, once for the
//! paper's manoeuvre and for a mission: the safety numbers (Sec. VI), T_threshold by simulation
//! (eq. 34), the gains' stability (eq. 26), the link delay it tolerates, and the airspace's
//! margins. `certify` computes one.

use serde::Serialize;

use crate::delay::{bound_ms, DelayBound};
use crate::losscert::LossCertificate;
use cdm_engine::engine::max_follower_deviation;
use cdm_math::Real;
use cdm_model::outcome::Verdict;
use cdm_records::audit::SafetyNumbers;
use cdm_scenario::{Checks, Scenario};

/// The pre-flight certificate printed by `orchestrator plan`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Certificate {
    /// SAFE or UNSAFE.
    pub verdict: Verdict,
    pub reasons: Vec<String>,
    pub scenario: String,
    pub agents: usize,
    #[serde(flatten)]
    pub numbers: SafetyNumbers,
    /// Smallest t_total_s whose simulated max follower deviation (2-norm) stays under delta.
    pub t_threshold_s: Real,
    pub t_total_s: Real,
    /// Simulated max follower deviation at the scenario's own t_total_s.
    pub max_follower_deviation_m: Real,
    pub gains_stability_margin: Real,
    /// The largest link delay (ms, whole ticks at comm_hz) at which the plan still meets
    /// E_max <= delta, every state that late (`delay.rs`); `None` when it fails even without.
    pub max_link_delay_ms: Option<Real>,
    /// True when `max_link_delay_ms` is only the largest delay searched (the plan held there).
    pub max_link_delay_at_least: bool,
    pub notes: Vec<String>,
    /// `plan --losses`: the loss of every single member, certified (`losscert`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub losses: Option<LossCertificate>,
    /// A mission: every phase's certificate in flight order; the verdict above is
    /// the worst of them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub segments: Option<Vec<PhaseCertificate>>,
    /// `[geofence]` and `[[obstacle]]`: each boundary's smallest margin; absent
    /// without them, so other certificates keep the JSON they had.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub airspace: Option<crate::airspace_certificate::AirspaceCertificate>,
    /// `[vehicle]`: the commanded peaks against the limits and the downwash clearance; absent
    /// without the table.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vehicle: Option<crate::vehicle_certificate::VehicleCertificate>,
}

/// One phase of a mission, certified.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PhaseCertificate {
    /// `takeoff`, `segment N` or `landing`.
    pub name: String,
    pub t_start_s: Real,
    pub t_end_s: Real,
    /// Smallest lambda_1(U_D) over the phase and when (informative for take-off and landing).
    pub lambda1_min: Real,
    pub t_lambda1_min_s: Real,
    pub d_b_m: Real,
    pub d_s_m: Real,
    pub delta_m: Real,
    /// Smallest travel time of this phase whose E_max stays under delta.
    pub t_threshold_s: Real,
    /// E_max of this phase flown from rest at its own travel time (linear model).
    pub max_follower_deviation_m: Real,
    /// Take-off and landing: the closest two members' ground spots (metres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_ground_separation_m: Option<Real>,
    pub verdict: Verdict,
    pub reasons: Vec<String>,
}

/// The reason a certificate fails when the gains' stability margin (eq. 26) is not positive.
pub fn unstable_gains(margin: Real) -> Option<String> {
    (margin.is_nan() || margin <= 0.0)
        .then(|| format!("gains are not stable for this graph (margin {margin:.4}, eq. 26)"))
}

/// SAFE when nothing is wrong, UNSAFE otherwise.
pub fn verdict_of(reasons: &[String]) -> Verdict {
    if reasons.is_empty() {
        Verdict::Safe
    } else {
        Verdict::Unsafe
    }
}

/// Max follower deviation at a given travel time (infinite when the flight faults).
pub fn deviation_at(s: &Scenario, t_total_s: Real) -> Real {
    let mut f = s.file.clone();
    f.t_total_s = t_total_s;
    match Scenario::from_file(f, &s.origin, Checks::Member) {
        Ok(v) => max_follower_deviation(&v).unwrap_or(Real::INFINITY),
        Err(_) => Real::INFINITY,
    }
}

/// Smallest T with E(T) < delta, by bracketing from the 1 / T^2 law (Sec. VII-D) and
/// bisection to 0.1 % (E falls monotonically with T in practice; the bracket is checked).
/// `e_of` gives E(T).
pub fn t_threshold(s: &Scenario, delta_m: Real, e_at_t: Real, e_of: impl Fn(Real) -> Real) -> Real {
    t_threshold_from(s.file.t_total_s, s.file.comm_hz, delta_m, e_at_t, e_of)
}

/// [`t_threshold`] of a motion whose travel time is `t0` now (a mission's phase), at ticks of
/// `comm_hz`. A threshold longer than a scenario may fly (`MAX_TICKS` ticks) is infinite: every
/// E(T) costs its ticks, so the search never tries a T longer than that, whatever the numbers.
pub fn t_threshold_from(
    t0: Real,
    comm_hz: Real,
    delta_m: Real,
    e_at_t: Real,
    e_of: impl Fn(Real) -> Real,
) -> Real {
    if delta_m.is_nan() || delta_m <= 0.0 {
        return Real::INFINITY;
    }
    let t_max_s = cdm_scenario::MAX_TICKS / comm_hz;
    let guess = if e_at_t.is_finite() && e_at_t > 0.0 {
        t0 * (e_at_t / delta_m).sqrt()
    } else {
        t0 * 2.0
    };
    let (mut lo, mut hi) = (guess * 0.9, guess * 1.1);
    let mut grow = 0;
    loop {
        if hi.is_nan() || hi > t_max_s {
            return Real::INFINITY;
        }
        if e_of(hi) < delta_m {
            break;
        }
        lo = hi;
        hi *= 2.0;
        grow += 1;
        if grow > 12 {
            return Real::INFINITY;
        }
    }
    let mut shrink = 0;
    while lo > 1e-3 && e_of(lo) < delta_m {
        hi = lo;
        lo *= 0.5;
        shrink += 1;
        if shrink > 30 {
            return hi;
        }
    }
    while (hi - lo) > 1e-3 * hi {
        let mid = 0.5 * (lo + hi);
        if e_of(mid) < delta_m {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}

/// What a certificate found, before the verdict: the parts the paper's manoeuvre and a mission
/// compute differently.
pub struct Findings {
    /// Every UNSAFE reason (none: SAFE).
    pub reasons: Vec<String>,
    pub numbers: SafetyNumbers,
    pub t_threshold_s: Real,
    /// The plan's travel time (a mission's: its end).
    pub t_total_s: Real,
    pub max_follower_deviation_m: Real,
    pub gains_stability_margin: Real,
    /// The largest link delay in ticks (`delay.rs`).
    pub max_link_delay: DelayBound,
    /// A mission's phases, in flight order.
    pub segments: Option<Vec<PhaseCertificate>>,
}

impl Certificate {
    /// The certificate of `s` from what was found: the verdict from the reasons, the delay in
    /// milliseconds at `s`'s tick, the scenario's name, size and notes.
    pub fn assemble(s: &Scenario, f: Findings) -> Certificate {
        let (max_link_delay_ms, max_link_delay_at_least) = bound_ms(f.max_link_delay, s.dt_s());
        Certificate {
            verdict: verdict_of(&f.reasons),
            reasons: f.reasons,
            scenario: s.file.name.clone(),
            agents: s.formation.members.len(),
            numbers: f.numbers,
            t_threshold_s: f.t_threshold_s,
            t_total_s: f.t_total_s,
            max_follower_deviation_m: f.max_follower_deviation_m,
            gains_stability_margin: f.gains_stability_margin,
            max_link_delay_ms,
            max_link_delay_at_least,
            notes: s.notes.clone(),
            losses: None,
            segments: f.segments,
            airspace: None,
            vehicle: None,
        }
    }
}
