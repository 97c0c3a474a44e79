//! The formation as the split into host regions sees it: read by the plan (which splits) and
//! by the bridge (which finds the links that cross hosts).

use crate::regions::Placed;
use cdm_scenario::Scenario;

/// The formation as the split sees it (plain data).
pub fn placed(s: &Scenario) -> Vec<Placed> {
    s.formation
        .members
        .iter()
        .map(|m| Placed {
            id: m.id,
            planar: [m.planar[0], m.planar[1]],
            in_neighbors: m.link.map_or_else(Vec::new, |l| l.in_neighbors.to_vec()),
        })
        .collect()
}
