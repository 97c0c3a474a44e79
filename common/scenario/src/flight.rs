//! What the whole-team engine and a single member's process both take from a scenario: the step
//! configuration, the desired positions r_HT at a time, and the telemetry order. Here, below
//! both, so the runtime does not reach into the engine for them.

use cdm_math::{Real, Vec3};
use cdm_model::step::{NeighborModel, StepConfig};

use super::Scenario;

impl Scenario {
    /// The step configuration every member flies with.
    pub fn step_config(&self) -> StepConfig {
        StepConfig {
            gains: self.file.gains,
            dt_s: self.dt_s(),
            substeps: self.substeps(),
            neighbor_model: NeighborModel::default(),
        }
    }

    /// The desired position r_HT of every member at time t (eqs. 13, 23), in member order.
    pub fn desired_positions(&self, t: Real, out: &mut Vec<Vec3>) {
        let prim = self.plan.primary_derivs(t, self.plan.piece_at(t));
        out.clear();
        for m in &self.formation.members {
            let a = m.alpha;
            out.push(prim[0][0] * a[0] + prim[1][0] * a[1] + prim[2][0] * a[2]);
        }
    }

    /// Member indices sorted by id (telemetry order).
    pub fn id_order(&self) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.formation.members.len()).collect();
        order.sort_by_key(|&k| self.formation.members[k].id);
        order
    }
}
