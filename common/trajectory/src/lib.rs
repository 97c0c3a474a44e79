//! Exports of a plan to the stacks that fly real fleets (Crazyswarm2, Skybrush): every member's
//! exact degree-5 trajectory (eqs. 13-16; for a mission the chain of its phases and the hovers
//! between them), cut into pieces, in the power basis of each piece or as Bézier control points,
//! the single-precision error bound that picks a Crazyflie's cut, and the target frame the plan
//! is scaled into. Pure: no I/O (the files are written by `orchestrator export`).

pub mod float32;
pub mod poly;
pub mod scale;

pub use float32::{crazyflie_split, CrazyflieSplit, SplitError, DEFAULT_TOLERANCE_M};
pub use poly::{pieces, AgentTrajectory, Cut, Motion, PolyPiece, DEGREE};
pub use scale::{FrameError, TargetFrame};

use cdm_math::Real;
use cdm_scenario::Scenario;

/// The longest segment a Skybrush show may have: its server refuses segments over 65.5 s
/// (skybrush-server `TrajectorySpecification.segments`); 60 s keeps a margin.
pub const SKYBRUSH_MAX_SEGMENT_S: Real = 60.0;

/// Every member's desired trajectory r_HT(t), in id order (the order of telemetry.csv).
pub fn team_trajectories(s: &Scenario) -> Vec<AgentTrajectory> {
    s.id_order()
        .into_iter()
        .map(|k| {
            let m = &s.formation.members[k];
            AgentTrajectory::new(&s.plan, m.id, &m.alpha)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_scenario::{paper40, Checks};

    /// The exported polynomials are the engine's own r_HT, member by member.
    #[test]
    fn team_trajectories_match_the_engine() {
        let s = Scenario::from_file(paper40(), "paper40", Checks::Member).unwrap();
        let trajs = team_trajectories(&s);
        let order = s.id_order();
        let mut ht = Vec::new();
        for t in [0.0, 13.7, 100.0, 199.99, 200.0] {
            s.desired_positions(t, &mut ht);
            for (tr, &k) in trajs.iter().zip(&order) {
                assert!(
                    (tr.position(t) - ht[k]).norm() < 1e-9,
                    "agent {} t={t}",
                    tr.id
                );
            }
        }
        // Skybrush: 200 s in 4 equal segments of at most 60 s.
        let sky = pieces(&trajs[0], Cut::MaxDuration(SKYBRUSH_MAX_SEGMENT_S));
        assert_eq!(sky.len(), 4);
        assert_eq!(sky[0].duration_s, 50.0);
    }
}
