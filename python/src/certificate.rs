//! `plan`: the pre-flight certificate of `orchestrator plan` (with `--losses`, `--suggest`) as a
//! typed object, and its JSON exactly as `plan --json` writes it.

use cdm_certificates::airspace_certificate::{AirspaceCertificate, ClearanceKind};
use cdm_certificates::airspace_suggest::suggest;
use cdm_certificates::certificate::{self, PhaseCertificate};
use cdm_certificates::certify::certify;
use cdm_certificates::losscert::certify_losses;
use cdm_exit::Failure;
use pyo3::prelude::*;

use crate::errors::to_py;
use crate::scenario::PyScenario;

/// One phase of a mission, certified (`take-off`, `segment N`, `landing`).
#[pyclass(module = "cdm", name = "Phase", frozen, get_all)]
#[derive(Clone)]
pub struct PyPhase {
    pub name: String,
    pub t_start_s: f64,
    pub t_end_s: f64,
    /// Smallest lambda_1(U_D) over the phase and when.
    pub lambda_1: f64,
    pub t_lambda_1_s: f64,
    pub d_b_m: f64,
    pub d_s_m: f64,
    pub delta_m: f64,
    /// Smallest travel time of this phase whose deviation stays under delta (eq. 34).
    pub t_threshold_s: f64,
    pub max_follower_deviation_m: f64,
    /// Take-off and landing: the closest two members' ground spots.
    pub min_ground_separation_m: Option<f64>,
    pub verdict: String,
    pub reasons: Vec<String>,
}

/// The smallest margin to one boundary of the airspace.
#[pyclass(module = "cdm", name = "Clearance", frozen, get_all)]
#[derive(Clone)]
pub struct PyClearance {
    /// `fence` or `obstacle`.
    pub kind: String,
    /// The fence's side (`floor`, `ceiling`, `edge K`) or the obstacle's name.
    pub name: String,
    /// Distance of the member's ball to the boundary: negative inside an obstacle or beyond
    /// the fence.
    pub margin_m: f64,
    pub agent: u32,
    pub t_s: f64,
    pub phase: String,
}

/// The airspace's margins: every fence side, then every obstacle.
#[pyclass(module = "cdm", name = "Airspace", frozen, get_all)]
#[derive(Clone)]
pub struct PyAirspace {
    /// The ball around each member's desired path: eps + delta (eq. 38).
    pub radius_m: f64,
    pub clearances: Vec<PyClearance>,
}

/// The pre-flight certificate (`orchestrator plan`).
#[pyclass(module = "cdm", name = "Certificate", frozen, get_all)]
pub struct PyCertificate {
    /// `"SAFE"` or `"UNSAFE"`.
    pub verdict: String,
    /// Why it is UNSAFE (empty when SAFE).
    pub reasons: Vec<String>,
    pub scenario: String,
    pub agents: usize,
    /// min lambda_1(U_D) over the plan (eq. 37) and when.
    pub lambda_1: f64,
    pub t_lambda_1_s: f64,
    /// lambda_CD,min (eqs. 37-38).
    pub lambda_cd_min: f64,
    /// D_B and D_S (Sec. VI).
    pub d_b_m: f64,
    pub d_s_m: f64,
    /// delta_max (eq. 35) and delta (eq. 38).
    pub delta_max_m: f64,
    pub delta_m: f64,
    pub eps_m: f64,
    /// Smallest travel time whose max follower deviation stays under delta (eq. 34).
    pub t_threshold_s: f64,
    pub t_total_s: f64,
    pub max_follower_deviation_m: f64,
    /// eq. 26.
    pub gains_stability_margin: f64,
    pub max_link_delay_ms: Option<f64>,
    pub max_link_delay_at_least: bool,
    pub notes: Vec<String>,
    /// A mission's phases in flight order (empty otherwise).
    pub phases: Vec<PyPhase>,
    /// The airspace's margins; `None` without a fence or obstacles.
    pub airspace: Option<PyAirspace>,
    /// `plan --json`'s text, byte for byte (losses and suggestions included when asked for).
    pub json: String,
}

#[pymethods]
impl PyCertificate {
    fn __repr__(&self) -> String {
        format!(
            "Certificate({}: {} members, lambda_1 = {}, delta_m = {}, t_threshold_s = {}, {} reason(s))",
            self.verdict,
            self.agents,
            self.lambda_1,
            self.delta_m,
            self.t_threshold_s,
            self.reasons.len()
        )
    }
}

impl PyPhase {
    fn of(p: &PhaseCertificate) -> Self {
        PyPhase {
            name: p.name.clone(),
            t_start_s: p.t_start_s,
            t_end_s: p.t_end_s,
            lambda_1: p.lambda1_min,
            t_lambda_1_s: p.t_lambda1_min_s,
            d_b_m: p.d_b_m,
            d_s_m: p.d_s_m,
            delta_m: p.delta_m,
            t_threshold_s: p.t_threshold_s,
            max_follower_deviation_m: p.max_follower_deviation_m,
            min_ground_separation_m: p.min_ground_separation_m,
            verdict: p.verdict.to_string(),
            reasons: p.reasons.clone(),
        }
    }
}

impl PyAirspace {
    fn of(a: &AirspaceCertificate) -> Self {
        let clearances = (a.clearances.iter())
            .map(|c| PyClearance {
                kind: match c.kind {
                    ClearanceKind::Fence => "fence",
                    ClearanceKind::Obstacle => "obstacle",
                }
                .to_string(),
                name: c.name.clone(),
                margin_m: c.margin_m,
                agent: c.agent,
                t_s: c.t_s,
                phase: c.phase.clone(),
            })
            .collect();
        PyAirspace {
            radius_m: a.radius_m,
            clearances,
        }
    }
}

impl PyCertificate {
    fn of(c: &certificate::Certificate) -> Result<Self, Failure> {
        let n = &c.numbers;
        Ok(PyCertificate {
            verdict: c.verdict.to_string(),
            reasons: c.reasons.clone(),
            scenario: c.scenario.clone(),
            agents: c.agents,
            lambda_1: n.lambda1_min,
            t_lambda_1_s: n.t_lambda1_min_s,
            lambda_cd_min: n.lambda_cd_min,
            d_b_m: n.d_b_m,
            d_s_m: n.d_s_m,
            delta_max_m: n.delta_max_m,
            delta_m: n.delta_m,
            eps_m: n.eps_m,
            t_threshold_s: c.t_threshold_s,
            t_total_s: c.t_total_s,
            max_follower_deviation_m: c.max_follower_deviation_m,
            gains_stability_margin: c.gains_stability_margin,
            max_link_delay_ms: c.max_link_delay_ms,
            max_link_delay_at_least: c.max_link_delay_at_least,
            notes: c.notes.clone(),
            phases: c.segments.iter().flatten().map(PyPhase::of).collect(),
            airspace: c.airspace.as_ref().map(PyAirspace::of),
            json: serde_json::to_string_pretty(c).map_err(Failure::fault)?,
        })
    }
}

/// Certify a scenario as `orchestrator plan` does: `losses` adds the loss of every single
/// member (`--losses`, on `threads` threads: all cores by default), `suggest` the offsets that
/// clear the airspace's breaches (`--suggest`).
#[pyfunction]
#[pyo3(signature = (scenario, losses=false, suggest_offsets=false, threads=None))]
pub fn plan(
    py: Python<'_>,
    scenario: &PyScenario,
    losses: bool,
    suggest_offsets: bool,
    threads: Option<usize>,
) -> PyResult<PyCertificate> {
    let s = &scenario.loaded;
    let c = py.detach(|| {
        let mut c = certify(s);
        if suggest_offsets {
            if let Some(a) = &mut c.airspace {
                a.suggestion = Some(suggest(s, a.radius_m));
            }
        }
        if losses {
            let all = std::thread::available_parallelism().map_or(1, |n| n.get());
            c.losses = Some(certify_losses(s, threads.unwrap_or(all).max(1)));
        }
        c
    });
    PyCertificate::of(&c).map_err(to_py)
}

/// The max follower deviation (2-norm, metres) of the plan flown with travel time
/// `t_total_s` (what `plan --sweep` draws; infinite when the flight faults).
#[pyfunction]
pub fn deviation_at(py: Python<'_>, scenario: &PyScenario, t_total_s: f64) -> f64 {
    py.detach(|| certificate::deviation_at(&scenario.loaded, t_total_s))
}
