//! What a member asks of its vehicle each tick, and what it publishes of it: pure functions over
//! the same inputs the model's tick takes (`cdm_core::step::step`), so a real vehicle is flown by
//! the very law the engine integrates.

use cdm_core::dynamics::{Flat, QuadState};
use cdm_core::plan::TeamPlan;
use cdm_core::step::{extrapolate, Law, StepConfig};
use cdm_math::{Real, Vec3, GRAVITY_MPS2};

use crate::messages::Setpoint;

/// The setpoint of the tick that starts at `t_k_s` (k dt in lockstep; plus the member's phase in
/// real time): where the member must be at t_k + dt, the end of the tick it flies now, with
/// velocity and acceleration feed-forward. `neighbors` are the in-neighbours' states at t_k.
/// - Leader: r_HT and its derivatives of its own plan (eq. 13, ERRATA "useful identities").
/// - Follower: r_d = sum_j w_j r_j (eq. 18) of its in-neighbours' tick-k states, carried to
///   t_{k+1} as the model's tick carries them (`step::extrapolate`); the acceleration is the
///   weighted sum of theirs carried the same way (zero when they publish measured states, which
///   have none).
pub fn setpoint_for(
    cfg: &StepConfig,
    plan: &TeamPlan,
    law: &Law,
    t_k_s: Real,
    neighbors: &[Flat; 3],
) -> Setpoint {
    match law {
        Law::Leader { alpha } => {
            let t = t_k_s + cfg.dt_s;
            let d = plan.agent_derivs(alpha, t, plan.piece_at(t));
            Setpoint {
                position: d[0],
                velocity: d[1],
                acceleration: d[2],
            }
        }
        Law::Follower { weights } => {
            let mut sp = Setpoint {
                position: Vec3::zeros(),
                velocity: Vec3::zeros(),
                acceleration: Vec3::zeros(),
            };
            for (nb, w) in neighbors.iter().zip(weights) {
                let (r, v) = extrapolate(nb, cfg.dt_s, cfg.neighbor_model);
                sp.position += r * *w;
                sp.velocity += v * *w;
                sp.acceleration += (nb.a + nb.j * cfg.dt_s) * *w;
            }
            sp
        }
    }
}

/// Holding still at `p` (before the team starts).
pub fn hold_at(p: Vec3) -> Setpoint {
    Setpoint {
        position: p,
        velocity: Vec3::zeros(),
        acceleration: Vec3::zeros(),
    }
}

/// The wire state of a measured vehicle: position and velocity as measured; thrust g, level
/// attitude and zero rates, so that its acceleration and jerk (`QuadState::flat`) are zero.
/// LOCAL_POSITION_NED carries no acceleration, and differencing 50 Hz velocities would publish
/// noise to every out-neighbour; zero is the documented choice (README "Fly real vehicles").
pub fn measured_state(position: Vec3, velocity: Vec3) -> QuadState {
    let mut x = QuadState::hover(position);
    x.0[3] = velocity.x;
    x.0[4] = velocity.y;
    x.0[5] = velocity.z;
    debug_assert!(x.0[6] == GRAVITY_MPS2);
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_core::step::NeighborModel;

    fn cfg() -> StepConfig {
        StepConfig {
            gains: [1.0; 4],
            dt_s: 0.1,
            substeps: 1,
            neighbor_model: NeighborModel::Taylor,
        }
    }

    #[test]
    fn measured_states_publish_zero_acceleration_and_jerk() {
        let x = measured_state(Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.5, -0.5, 0.25));
        let f = x.flat();
        assert_eq!(f.r, Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(f.v, Vec3::new(0.5, -0.5, 0.25));
        assert!(f.a.norm() < 1e-12, "{:?}", f.a);
        assert!(f.j.norm() < 1e-12, "{:?}", f.j);
    }

    #[test]
    fn a_follower_asks_for_the_weighted_neighbours_one_tick_ahead() {
        let law = Law::Follower {
            weights: [0.5, 0.25, 0.25],
        };
        let nb = |x: f64, vx: f64| Flat {
            v: Vec3::new(vx, 0.0, 0.0),
            ..Flat::rest(Vec3::new(x, 1.0, 2.0))
        };
        let neighbors = [nb(0.0, 1.0), nb(4.0, 0.0), nb(8.0, 2.0)];
        let plan = paper_plan();
        let sp = setpoint_for(&cfg(), &plan, &law, 0.7, &neighbors);
        // r = 0.5 (0 + 0.1) + 0.25 (4) + 0.25 (8 + 0.2); v = 0.5 + 0.5.
        assert!(
            (sp.position - Vec3::new(3.1, 1.0, 2.0)).norm() < 1e-12,
            "{sp:?}"
        );
        assert!(
            (sp.velocity - Vec3::new(1.0, 0.0, 0.0)).norm() < 1e-12,
            "{sp:?}"
        );
        assert_eq!(sp.acceleration, Vec3::zeros());
    }

    #[test]
    fn a_leader_asks_for_its_plan_at_the_end_of_the_tick() {
        let plan = paper_plan();
        let alpha = [1.0, 0.0, 0.0];
        let law = Law::Leader { alpha };
        let c = cfg();
        let sp = setpoint_for(&c, &plan, &law, 0.9, &[Flat::rest(Vec3::zeros()); 3]);
        let d = plan.agent_derivs(&alpha, 1.0, plan.piece_at(1.0));
        assert_eq!(
            (sp.position, sp.velocity, sp.acceleration),
            (d[0], d[1], d[2])
        );
        // Past T_total the leader holds its goal.
        let end = plan.quintic.t_total_s + 1.0;
        let sp = setpoint_for(&c, &plan, &law, end, &[Flat::rest(Vec3::zeros()); 3]);
        let goal = plan.agent_derivs(&alpha, end, plan.piece_at(end));
        assert_eq!(sp.position, goal[0]);
        assert_eq!(sp.velocity, Vec3::zeros());
    }

    fn paper_plan() -> TeamPlan {
        cdm_core::scenario::Scenario::builtin("paper40")
            .expect("the paper's scenario is valid")
            .plan
    }
}
