//! `export`: the plan for Crazyswarm2 or Skybrush, scaled into the target volume and certified
//! again there, by `orchestrator export`'s own code (cdm-export).

use std::path::PathBuf;

use cdm_exit::Failure;
use cdm_export::{export_plan, ExportFrame, PlanTarget};
use pyo3::prelude::*;

use crate::errors::{bad_input, to_py};
use crate::scenario::PyScenario;

/// Export `scenario` to `target` (`crazyswarm2`: a directory; `skybrush`: a .skyc file) at
/// `out`, mapped p -> scale p + origin ("X,Y,Z"), for vehicles of radius `eps`. Returns the
/// certificate's verdict at the target scale and whether the trajectory files were written
/// (an UNSAFE certificate writes them only with `force`).
#[pyfunction]
#[pyo3(signature = (scenario, target, out, scale=1.0, origin=None, eps=0.1, force=false))]
#[allow(clippy::too_many_arguments)]
pub fn export(
    py: Python<'_>,
    scenario: &PyScenario,
    target: &str,
    out: PathBuf,
    scale: f64,
    origin: Option<String>,
    eps: f64,
    force: bool,
) -> PyResult<(String, bool)> {
    let Some(source) = scenario.source.clone() else {
        return Err(bad_input(
            "export: the scenario was parsed from text: save it (to_toml) and load the file",
        ));
    };
    let frame = ExportFrame {
        scale,
        origin,
        eps_m: eps,
        force,
    };
    let target = match target {
        "crazyswarm2" => PlanTarget::Crazyswarm2,
        "skybrush" => PlanTarget::Skybrush,
        other => {
            return Err(bad_input(format!(
                "export: unknown target {other:?} (crazyswarm2 or skybrush)"
            )))
        }
    };
    let done = py
        .detach(|| export_plan(target, &source, &out, &frame))
        .map_err(|e| {
            to_py(if e.is_bad_input() {
                Failure::bad_input(e)
            } else {
                Failure::fault(e)
            })
        })?;
    let verdict = if done.certificate.verdict == cdm_model::outcome::Verdict::Safe {
        "SAFE"
    } else {
        "UNSAFE"
    };
    Ok((verdict.to_string(), done.written))
}
