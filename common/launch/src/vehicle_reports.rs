//! The members' vehicle reports (`launch --vehicles mavlink`): taken out of the state stream
//! before the real-time monitor sees them (they are not states), the newest of each member kept,
//! and written to audit.json's `vehicles` (what the team measured on its vehicles: late
//! setpoints, attitude; the tracking error against r_HT is the audit's own).

use std::collections::BTreeMap;

use cdm_member::vehicles::{vehicle_figures, VehicleReport};
use cdm_records::audit::Auditor;
use cdm_runtime::messages::StateMsg;

/// The newest vehicle report of each member.
#[derive(Debug)]
pub struct VehicleBook {
    /// The scenario's content hash (reports of another are dropped).
    hash: u64,
    newest: BTreeMap<u32, VehicleReport>,
}

impl VehicleBook {
    /// The book of a team flying the scenario with content hash `hash`.
    pub fn new(hash: u64) -> Self {
        VehicleBook {
            hash,
            newest: BTreeMap::new(),
        }
    }

    /// Keeps `m` if it is a vehicle report of this scenario (true: it was a report, whatever
    /// its scenario, and is not for the monitor).
    pub fn take(&mut self, m: &StateMsg) -> bool {
        let Some((id, r)) = VehicleReport::from_msg(m) else {
            return false;
        };
        if m.scenario_hash == self.hash {
            self.newest.insert(id, r);
        }
        true
    }

    /// Writes every member's newest report into the audit.
    pub fn record(&self, audit: &mut Auditor) {
        for (&id, r) in &self.newest {
            audit.set_vehicle(id, vehicle_figures(r));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_are_taken_and_states_are_not() {
        let mut book = VehicleBook::new(9);
        let r = VehicleReport {
            setpoints_sent: 10,
            late_setpoints: 1,
            max_late_ms: 30.0,
            attitudes: 9,
            max_abs_roll_rad: 0.1,
            max_abs_pitch_rad: 0.2,
            last_attitude_rad: None,
            foreign_packets: 0,
            bad_signatures: 0,
            battery: Default::default(),
            mode: None,
        };
        assert!(book.take(&r.to_msg(4, 9)));
        assert!(
            book.take(&r.to_msg(5, 8)),
            "another scenario's: not a state either"
        );
        assert!(!book.take(&StateMsg::ok(0, 9, 4, [0.0; 12])));
        assert_eq!(book.newest.keys().copied().collect::<Vec<_>>(), vec![4]);
    }
}
