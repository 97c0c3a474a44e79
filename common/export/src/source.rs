//! Which scenario a command flies: a file, a built-in, or a generated team, and an optional
//! travel time in place of the file's. Plain values: the orchestrator's flags and the Python
//! package's arguments both become one.

use std::path::PathBuf;

use cdm_math::Real;
use cdm_scenario::{Checks, Scenario, ScenarioError};

/// A scenario file, else a generated team of `n`, else a built-in (paper40 when none is named).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ScenarioSource {
    pub scenario: Option<PathBuf>,
    pub n: Option<usize>,
    pub builtin: Option<String>,
    /// In place of the scenario's `t_total_s`.
    pub t_total_s: Option<Real>,
}

/// Load and fully validate the scenario `source` names. Its notes (defaults it filled in) are
/// logged at INFO.
pub fn load(source: &ScenarioSource) -> Result<Scenario, ScenarioError> {
    let mut s = match (&source.scenario, source.n, &source.builtin) {
        (Some(p), _, _) => Scenario::load(p, Checks::Full),
        (None, Some(n), _) => Scenario::generated(n),
        (None, None, Some(b)) => Scenario::builtin(b),
        (None, None, None) => Scenario::builtin("paper40"),
    }?;
    if let Some(t) = source.t_total_s {
        let mut f = s.file.clone();
        f.t_total_s = t;
        let origin = format!("{} with --t-total {t}", s.origin);
        s = Scenario::from_file(f, &origin, Checks::Full)?;
    }
    for note in &s.notes {
        tracing::info!("{note}");
    }
    Ok(s)
}
