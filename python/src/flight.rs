//! `simulate`: the team flown by the in-process engine into a run directory, as `orchestrator
//! simulate` flies it (the figures and the replay page aside), and the run's telemetry read back
//! column by column.

use std::path::PathBuf;

use cdm_engine::loss::{LossSchedule, OnLoss};
use cdm_exit::Failure;
use cdm_records::rundir::RunDir;
use cdm_records::telemetry::{TelemetryFormat, HEADER};
use cdm_simulate::SimulateOptions;
use cdm_team::telemetry::every_or_default;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use crate::errors::{bad_input, to_py};
use crate::scenario::PyScenario;

/// Fly `scenario` into the run directory `out` (refused when it exists and is not empty,
/// unless `force`): telemetry.csv every `every` ticks (the CLI's default when `None`),
/// audit.json and scenario.toml. `max_ticks` flies ticks 0..=K only; `stop_on_violation` ends
/// the run at its first violation. Returns the verdict (`SAFE`, `UNSAFE` or `FAULT`).
#[pyfunction]
#[pyo3(signature = (scenario, out, force=false, every=None, max_ticks=None, stop_on_violation=false))]
pub fn simulate(
    py: Python<'_>,
    scenario: &PyScenario,
    out: PathBuf,
    force: bool,
    every: Option<u64>,
    max_ticks: Option<u64>,
    stop_on_violation: bool,
) -> PyResult<String> {
    if every == Some(0) {
        return Err(bad_input(
            "every: 0 is not in 1..18446744073709551615 (write every K-th tick, K >= 1)",
        ));
    }
    let s = &scenario.loaded;
    py.detach(|| {
        let losses = LossSchedule::new(s, &[], max_ticks).map_err(Failure::bad_input)?;
        let dir = RunDir::create(&out, force).map_err(Failure::from)?;
        let every = every_or_default(every, s.file.agents.len());
        let opts = SimulateOptions {
            every,
            stop_on_violation,
            max_ticks,
            telemetry: TelemetryFormat::Csv,
            losses,
            on_loss: OnLoss::Repair,
            commands: Vec::new(),
        };
        let mut tel = cdm_team::telemetry::open(&dir, TelemetryFormat::Csv, every, s)
            .map_err(Failure::bad_input)?;
        let report = cdm_simulate::simulate(s, &dir, opts, tel.as_mut(), |_, _| {})
            .map_err(Failure::fault)?;
        Ok(report.verdict.to_string())
    })
    .map_err(to_py)
}

/// The telemetry of a run directory (telemetry.csv or telemetry.parquet) as columns named by
/// telemetry.csv's header: `tick` as little-endian u64 bytes, `id` as u32 bytes, `role` as a
/// list of names, every other column as f64 bytes (the very values in the file).
#[pyfunction]
pub fn read_telemetry<'py>(py: Python<'py>, run_dir: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let columns = py
        .detach(|| {
            let mut c = Columns::default();
            cdm_report::data::read_telemetry(&run_dir, |row| {
                c.push(row);
                Ok::<_, std::convert::Infallible>(())
            })
            .map(|_| c)
        })
        .map_err(|e| to_py(Failure::bad_input(e)))?;
    columns.into_dict(py)
}

/// telemetry.csv's columns, in its order.
#[derive(Default)]
struct Columns {
    tick: Vec<u8>,
    id: Vec<u8>,
    role: Vec<&'static str>,
    /// t, x, y, z, vx, vy, vz, x_ht, y_ht, z_ht.
    reals: [Vec<u8>; 10],
}

impl Columns {
    fn push(&mut self, row: &cdm_records::telemetry::Row) {
        self.tick.extend_from_slice(&row.tick.to_le_bytes());
        self.id.extend_from_slice(&row.id.to_le_bytes());
        self.role.push(row.role.as_str());
        let values = [
            row.t_s, row.r.x, row.r.y, row.r.z, row.v.x, row.v.y, row.v.z, row.ht.x, row.ht.y,
            row.ht.z,
        ];
        for (column, v) in self.reals.iter_mut().zip(values) {
            column.extend_from_slice(&v.to_le_bytes());
        }
    }

    fn into_dict(self, py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
        let d = PyDict::new(py);
        let names: Vec<&str> = HEADER.split(',').collect();
        let mut reals = self.reals.iter();
        for name in names {
            match name {
                "tick" => d.set_item(name, PyBytes::new(py, &self.tick))?,
                "id" => d.set_item(name, PyBytes::new(py, &self.id))?,
                "role" => d.set_item(name, &self.role)?,
                _ => match reals.next() {
                    Some(c) => d.set_item(name, PyBytes::new(py, c))?,
                    None => return Err(bad_input(format!("telemetry column {name}: unknown"))),
                },
            }
        }
        Ok(d)
    }
}
