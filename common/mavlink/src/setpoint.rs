//! What a member asks of its vehicle each tick, and what it publishes of it: pure functions over
//! the same inputs the model's tick takes (`cdm_model::step::step`), so a real vehicle is flown by
//! the very law the engine integrates.
//!
//! The published state of a measured vehicle: position and velocity as
//! LOCAL_POSITION_NED measured them; acceleration and jerk as the member commanded them, the
//! feed-forward of the setpoint in force (by default, [`FeedForward::Commanded`]). Why the
//! commanded ones and not HIGHRES_IMU's: the IMU's accelerometer gives the specific force in
//! the body frame (raw, with the motors' vibration on it), which needs the attitude and gravity
//! removed to become an acceleration, and it has no jerk, which would have to come from
//! differencing it, handing every out-neighbour that noise; the commanded acceleration and
//! jerk are exact derivatives of r_d (a leader's plan, eq. 13; a follower's eq. 18 of its
//! neighbours), what the simulated model's published a and j follow when it tracks (the
//! model's flat outputs track r_d), and what a vehicle flying its setpoints' feed-forward
//! tries to do. Their cost: a vehicle that does not follow its setpoints (lagging, saturated)
//! publishes an acceleration it does not have; `--vehicle-feed-forward zero` publishes zero
//! instead (thrust g, level), as before.

use cdm_math::{Real, Vec3, GRAVITY_MPS2};
use cdm_model::dynamics::{Flat, QuadState};
use cdm_model::plan::TeamPlan;
use cdm_model::step::{extrapolate, Law, StepConfig};

use crate::messages::Setpoint;

/// The setpoint of the tick that starts at `t_k_s` (k dt in lockstep; plus the member's phase in
/// real time): where the member must be at t_k + dt, the end of the tick it flies now, with
/// velocity and acceleration feed-forward. `neighbors` are the in-neighbours' states at t_k.
/// - Leader: r_HT and its derivatives of its own plan (eq. 13, ERRATA "useful identities").
/// - Follower: r_d = sum_j w_j r_j (eq. 18) of its in-neighbours' tick-k states, carried to
///   t_{k+1} as the model's tick carries them (`step::extrapolate`); the acceleration and jerk
///   are the weighted sums of theirs carried the same way (a measured neighbour publishes the
///   ones it commanded, or zero with `--vehicle-feed-forward zero`).
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
                jerk: d[3],
            }
        }
        Law::Follower { weights } => {
            let mut sp = hold_at(Vec3::zeros());
            for (nb, w) in neighbors.iter().zip(weights) {
                let (r, v) = extrapolate(nb, cfg.dt_s, cfg.neighbor_model);
                sp.position += r * *w;
                sp.velocity += v * *w;
                sp.acceleration += (nb.a + nb.j * cfg.dt_s) * *w;
                sp.jerk += nb.j * *w;
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
        jerk: Vec3::zeros(),
    }
}

/// `--vehicle-feed-forward`: the acceleration and jerk a member publishes with its vehicle's
/// measured position and velocity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FeedForward {
    /// Those of the setpoint in force (the member's r_d at the published state's time).
    #[default]
    Commanded,
    /// Zero (thrust g, level attitude): no feed-forward for the out-neighbours.
    Zero,
}

/// The wire state of a measured vehicle: position and velocity as measured, and the thrust,
/// attitude and their rates (the model's state, eq. 42) whose acceleration and jerk
/// (`QuadState::flat`) are `acceleration` and `jerk`. The inverse of eq. 42's a = F u - g e_z:
/// F = |a + g e_z|, u = (a + g e_z) / F = [cos(phi) sin(theta); -sin(phi); cos(phi) cos(theta)];
/// and of jerk = M qdot: qdot = M^{-1} jerk, whose columns u, F e_phi, F d_theta are
/// orthogonal with squared norms 1, F^2, F^2 cos^2(phi) (`dynamics::Kinematics`). An
/// acceleration at or below free fall (F under `MIN_THRUST_MPS2`, no attitude gives it) or a
/// non-finite one publishes zero instead (hover), as with [`FeedForward::Zero`].
pub fn measured_state(position: Vec3, velocity: Vec3, acceleration: Vec3, jerk: Vec3) -> QuadState {
    let mut x = QuadState::hover(position);
    x.0[3] = velocity.x;
    x.0[4] = velocity.y;
    x.0[5] = velocity.z;
    debug_assert!(x.0[6] == GRAVITY_MPS2);
    let w = acceleration + Vec3::new(0.0, 0.0, GRAVITY_MPS2);
    let f = w.norm();
    // Written so that a NaN (norm of a non-finite acceleration) publishes hover.
    let thrust_ok = f >= MIN_THRUST_MPS2;
    if !thrust_ok || !jerk.iter().all(|c| c.is_finite()) {
        return x;
    }
    let u = w / f;
    // |u_y| <= 1 up to rounding; cos(phi) = sqrt(u_x^2 + u_z^2) >= 0 on this branch.
    let phi = (-u.y).clamp(-1.0, 1.0).asin();
    let theta = u.x.atan2(u.z);
    let (sp, cp) = phi.sin_cos();
    let (st, ct) = theta.sin_cos();
    let e_phi = Vec3::new(-sp * st, -cp, -sp * ct);
    let d_theta = Vec3::new(cp * ct, 0.0, -cp * st);
    x.0[6] = f;
    x.0[7] = phi;
    x.0[8] = theta;
    x.0[9] = u.dot(&jerk);
    x.0[10] = e_phi.dot(&jerk) / f;
    // cos(phi) is 0 only for a horizontal thrust of at least g, above any tilt a member flies.
    let pitch_rate = d_theta.dot(&jerk) / (f * cp * cp);
    x.0[11] = if pitch_rate.is_finite() {
        pitch_rate
    } else {
        0.0
    };
    x
}

/// Below this thrust per mass (m/s^2) no attitude is meaningful: the published feed-forward is
/// zero instead (a setpoint commanding near free fall, which no formation plan does).
pub const MIN_THRUST_MPS2: Real = 0.1 * GRAVITY_MPS2;

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_model::step::NeighborModel;

    fn cfg() -> StepConfig {
        StepConfig {
            gains: [1.0; 4],
            dt_s: 0.1,
            substeps: 1,
            neighbor_model: NeighborModel::Taylor,
        }
    }

    #[test]
    fn measured_states_publish_zero_acceleration_and_jerk_when_asked() {
        let z = Vec3::zeros();
        let x = measured_state(Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.5, -0.5, 0.25), z, z);
        let f = x.flat();
        assert_eq!(f.r, Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(f.v, Vec3::new(0.5, -0.5, 0.25));
        assert!(f.a.norm() < 1e-12, "{:?}", f.a);
        assert!(f.j.norm() < 1e-12, "{:?}", f.j);
    }

    #[test]
    fn measured_states_publish_the_commanded_acceleration_and_jerk() {
        let (r, v) = (Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.5, -0.5, 0.25));
        let cases = [
            (Vec3::new(0.3, -0.2, 0.1), Vec3::new(0.05, 0.1, -0.2)),
            (Vec3::new(-2.0, 1.5, -3.0), Vec3::new(-1.0, 2.0, 0.5)),
            (Vec3::new(0.0, 0.0, 4.0), Vec3::new(0.0, 0.0, 0.0)),
            (Vec3::new(5.0, -5.0, 0.0), Vec3::new(3.0, 3.0, -3.0)),
        ];
        for (a, j) in cases {
            let f = measured_state(r, v, a, j).flat();
            assert_eq!((f.r, f.v), (r, v));
            assert!((f.a - a).norm() < 1e-12, "{a:?}: {:?}", f.a);
            assert!((f.j - j).norm() < 1e-12, "{j:?}: {:?}", f.j);
        }
        // Free fall has no attitude: hover instead, and non-finite input changes nothing.
        let down = Vec3::new(0.0, 0.0, -GRAVITY_MPS2);
        let hover = measured_state(r, v, Vec3::zeros(), Vec3::zeros());
        assert_eq!(measured_state(r, v, down, Vec3::zeros()), hover);
        let nan = Vec3::new(f64::NAN, 0.0, 0.0);
        assert_eq!(measured_state(r, v, nan, Vec3::zeros()), hover);
        assert_eq!(measured_state(r, v, Vec3::zeros(), nan), hover);
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
        assert_eq!(sp.jerk, Vec3::zeros());
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
            (sp.position, sp.velocity, sp.acceleration, sp.jerk),
            (d[0], d[1], d[2], d[3])
        );
        // Past T_total the leader holds its goal.
        let end = plan.quintic.t_total_s + 1.0;
        let sp = setpoint_for(&c, &plan, &law, end, &[Flat::rest(Vec3::zeros()); 3]);
        let goal = plan.agent_derivs(&alpha, end, plan.piece_at(end));
        assert_eq!(sp.position, goal[0]);
        assert_eq!(sp.velocity, Vec3::zeros());
    }

    fn paper_plan() -> TeamPlan {
        cdm_scenario::Scenario::builtin("paper40")
            .expect("the paper's scenario is valid")
            .plan
    }
}
