//! A scenario as the CLI loads it (`--scenario FILE`, `--builtin NAME`, `--n N`, `--t-total`),
//! with where it came from, so an export reloads it the CLI's way.

use std::path::PathBuf;

use cdm_exit::Failure;
use cdm_export::ScenarioSource;
use cdm_scenario::{Checks, Scenario as Loaded};
use pyo3::prelude::*;

use crate::errors::to_py;

/// A validated scenario (`cdm.load`, `cdm.parse`).
#[pyclass(module = "cdm", name = "Scenario", frozen)]
pub struct PyScenario {
    pub loaded: Loaded,
    /// How the CLI would name it; `None` for a scenario parsed from text.
    pub source: Option<ScenarioSource>,
}

#[pymethods]
impl PyScenario {
    /// The scenario's `name`.
    #[getter]
    fn name(&self) -> &str {
        &self.loaded.file.name
    }
    /// Where it was read from (a path, `builtin paper40`, ...).
    #[getter]
    fn origin(&self) -> &str {
        &self.loaded.origin
    }
    /// The members' ids in file order.
    #[getter]
    fn ids(&self) -> Vec<u32> {
        self.loaded.file.agents.iter().map(|a| a.id).collect()
    }
    /// Number of members.
    #[getter]
    fn agents(&self) -> usize {
        self.loaded.file.agents.len()
    }
    /// The travel time (seconds).
    #[getter]
    fn t_total_s(&self) -> f64 {
        self.loaded.file.t_total_s
    }
    /// The tick (seconds): 1 / comm_hz.
    #[getter]
    fn dt_s(&self) -> f64 {
        self.loaded.dt_s()
    }
    /// The last tick of the plan.
    #[getter]
    fn last_tick(&self) -> u64 {
        self.loaded.last_tick()
    }
    /// Whether the plan is a mission (take-off, segments, landing).
    #[getter]
    fn is_mission(&self) -> bool {
        self.loaded.plan.is_mission()
    }
    /// The notes validation made (defaults it filled in).
    #[getter]
    fn notes(&self) -> Vec<String> {
        self.loaded.notes.clone()
    }
    /// Whether it was loaded from a file, a built-in or `n` (not parsed from text): the CLI
    /// can name it, and `export` reloads it that way.
    #[getter]
    fn has_source(&self) -> bool {
        self.source.is_some()
    }
    /// The scenario as TOML (`orchestrator scenario export`).
    fn to_toml(&self) -> String {
        self.loaded.to_toml()
    }
    /// The scenario as JSON.
    fn to_json(&self) -> String {
        self.loaded.to_json()
    }
    fn __repr__(&self) -> String {
        format!(
            "Scenario({:?}: {} members, t_total_s = {}, from {})",
            self.loaded.file.name,
            self.loaded.file.agents.len(),
            self.loaded.file.t_total_s,
            self.loaded.origin
        )
    }
}

/// Load a scenario the CLI's way: a file, else a generated team of `n`, else a built-in name
/// (paper40 when none is given); `t_total_s` overrides the travel time (`--t-total`).
#[pyfunction]
#[pyo3(signature = (path=None, builtin=None, n=None, t_total_s=None))]
pub fn load(
    py: Python<'_>,
    path: Option<PathBuf>,
    builtin: Option<String>,
    n: Option<usize>,
    t_total_s: Option<f64>,
) -> PyResult<PyScenario> {
    let source = ScenarioSource {
        scenario: path,
        n,
        builtin,
        t_total_s,
    };
    let loaded = py
        .detach(|| cdm_export::load(&source))
        .map_err(|e| to_py(Failure::bad_input(e)))?;
    Ok(PyScenario {
        loaded,
        source: Some(source),
    })
}

/// A scenario from TOML text (what a scenario file holds), validated fully; `origin` names it
/// in messages.
#[pyfunction]
#[pyo3(signature = (text, origin="<text>"))]
pub fn parse(py: Python<'_>, text: &str, origin: &str) -> PyResult<PyScenario> {
    let loaded = py
        .detach(|| Loaded::parse(text, origin, Checks::Full))
        .map_err(|e| to_py(Failure::bad_input(e)))?;
    Ok(PyScenario {
        loaded,
        source: None,
    })
}
