//! One member's tick: the pure function both the in-process engine and the member processes call,
//! so that they produce bit-identical states.
//!
//! At tick k every member takes its in-neighbours' tick-k states and integrates its own plant and
//! controller from t_k = k dt to t_{k+1} with RK4 substeps. Inside the tick a follower does not
//! hold its neighbours still: it extrapolates each neighbour's position with the neighbour's own
//! velocity, acceleration and jerk at t_k (all exact functions of its 12-state),
//! r_j(t_k + tau) ~ r + v tau + a tau^2 / 2 + j tau^3 / 6. The error this adds against the
//! continuously coupled model of eqs. 24-25 is measured by `the exchange-error test (common/engine/tests/engine.rs)`.

use serde::{Deserialize, Serialize};

use crate::control::ControlFault;
use crate::dynamics::{Flat, Plant};
use crate::plan::{Piece, TeamPlan};
use cdm_math::{Real, Vec3};

/// What a follower assumes about a neighbour between two exchanges.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NeighborModel {
    /// Cubic Taylor extrapolation from the neighbour's tick-k state (the default).
    #[default]
    Taylor,
    /// Zero-order hold: the neighbour stays where it was at t_k, velocity as it was.
    Hold,
}

/// How a member steers (eqs. 44, ERRATA 4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Law {
    /// Leaders track r_HT = sum_j alpha_j r_j,HT with full feed-forward:
    /// U = r_HT'''' + k1 e''' + k2 e'' + k3 e' + k4 e, e = r_HT - r.
    Leader { alpha: [Real; 3] },
    /// Followers track r_d = sum_j w_j r_j of their in-neighbours:
    /// U = k4 (r_d - r) + k3 (r_d' - r') - k2 r'' - k1 r'''.
    Follower { weights: [Real; 3] },
}

/// Everything a tick needs that is the same for the whole team.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepConfig {
    pub gains: [Real; 4],
    pub dt_s: Real,
    pub substeps: u32,
    pub neighbor_model: NeighborModel,
}

/// Why a member could not complete a tick.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum StepFault {
    /// The controller or plant failed (singular decoupling matrix, non-finite state).
    #[error(transparent)]
    Control(#[from] ControlFault),
    /// An in-neighbour's state holds a non-finite number.
    #[error("in-neighbour {peer} sent a non-finite state")]
    NeighborNonFinite { peer: u32 },
}

/// Simulation time of a tick: tick x dt, never the wall clock.
pub fn tick_time(tick: u64, dt_s: Real) -> Real {
    tick as Real * dt_s
}

/// Position and velocity of a neighbour `tau` seconds after its sampled state.
#[inline]
pub fn extrapolate(f: &Flat, tau: Real, model: NeighborModel) -> (Vec3, Vec3) {
    match model {
        NeighborModel::Hold => (f.r, f.v),
        NeighborModel::Taylor => {
            let t2 = tau * tau;
            (
                f.r + f.v * tau + f.a * (0.5 * t2) + f.j * (t2 * tau / 6.0),
                f.v + f.a * tau + f.j * (0.5 * t2),
            )
        }
    }
}

/// The whole flat output of a neighbour `tau` seconds after its sampled state, on the cubic
/// Taylor polynomial of [`extrapolate`] (a cubic moved along itself is the same cubic, so a
/// follower that extrapolates this again inside its tick stays on the neighbour's polynomial).
/// Real time uses it to bring a neighbour's newest state to the follower's own time.
#[inline]
pub fn extrapolate_flat(f: &Flat, tau: Real, model: NeighborModel) -> Flat {
    let (r, v) = extrapolate(f, tau, model);
    match model {
        NeighborModel::Hold => *f,
        NeighborModel::Taylor => Flat {
            r,
            v,
            a: f.a + f.j * tau,
            j: f.j,
        },
    }
}

/// Where a tick sits on the time axis: it starts at `tick * dt + offset_s`. Lockstep and the
/// engine use offset 0 (`x + 0.0` is `x` exactly, so their results are unchanged bit for bit);
/// a real-time member uses its phase offset (ARCHITECTURE.md, "How time flows").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickAt {
    pub tick: u64,
    pub offset_s: Real,
}

/// Advance one member from tick `tick` to `tick + 1`. `neighbors` are the in-neighbours' tick-k
/// flat outputs in the order of the follower's weights (ignored for leaders); `neighbor_ids`
/// name them in faults.
pub fn step<P: Plant>(
    cfg: &StepConfig,
    plan: &TeamPlan,
    law: &Law,
    tick: u64,
    own: &P,
    neighbors: &[Flat; 3],
    neighbor_ids: &[u32; 3],
) -> Result<P, StepFault> {
    let at = TickAt {
        tick,
        offset_s: 0.0,
    };
    step_at(cfg, plan, law, at, own, neighbors, neighbor_ids)
}

/// [`step`] for a tick that starts at `at.tick * dt + at.offset_s` (a real-time member's phase):
/// leaders evaluate their plan at those times, followers extrapolate from that tick start.
pub fn step_at<P: Plant>(
    cfg: &StepConfig,
    plan: &TeamPlan,
    law: &Law,
    at: TickAt,
    own: &P,
    neighbors: &[Flat; 3],
    neighbor_ids: &[u32; 3],
) -> Result<P, StepFault> {
    if let Law::Follower { .. } = law {
        for (f, id) in neighbors.iter().zip(neighbor_ids) {
            if !f.is_finite() {
                return Err(StepFault::NeighborNonFinite { peer: *id });
            }
        }
    }
    let TickAt { tick, offset_s } = at;
    let t_k = tick_time(tick, cfg.dt_s) + offset_s;
    let sub = cfg.substeps.max(1);
    let mut x = *own;
    for i in 0..sub {
        let ts = (tick as Real + i as Real / sub as Real) * cfg.dt_s + offset_s;
        let te = (tick as Real + (i + 1) as Real / sub as Real) * cfg.dt_s + offset_s;
        // ERRATA 12: split at every phase's start and end (T_total for the paper's one plan) so
        // that no RK4 step straddles a jump of s'''.
        let mut from = ts;
        loop {
            let to = plan.break_inside(from, te).unwrap_or(te);
            let piece = plan.piece_of(from, to);
            x = substep(cfg, plan, law, t_k, &x, from, to, piece, neighbors)?;
            if to == te {
                break;
            }
            from = to;
        }
    }
    Ok(x)
}

#[allow(clippy::too_many_arguments)]
#[inline]
fn substep<P: Plant>(
    cfg: &StepConfig,
    plan: &TeamPlan,
    law: &Law,
    t_k: Real,
    x: &P,
    ts: Real,
    te: Real,
    seg: Piece,
    neighbors: &[Flat; 3],
) -> Result<P, StepFault> {
    let [k1, k2, k3, k4] = cfg.gains;
    let h = te - ts;
    let next = match law {
        Law::Leader { alpha } => x.rk4_step(ts, h, |t, f| {
            let d = plan.agent_derivs(alpha, t, seg);
            d[4] + (d[3] - f.j) * k1 + (d[2] - f.a) * k2 + (d[1] - f.v) * k3 + (d[0] - f.r) * k4
        })?,
        Law::Follower { weights } => x.rk4_step(ts, h, |t, f| {
            let tau = t - t_k;
            let mut rd = Vec3::zeros();
            let mut vd = Vec3::zeros();
            for (nb, w) in neighbors.iter().zip(weights) {
                let (r, v) = extrapolate(nb, tau, cfg.neighbor_model);
                rd += r * *w;
                vd += v * *w;
            }
            (rd - f.r) * k4 + (vd - f.v) * k3 - f.a * k2 - f.j * k1
        })?,
    };
    Ok(next)
}

/// The law and in-neighbour ids of a formation member (leaders: alpha of eq. 14; followers: the
/// weights of eq. 18 computed from the in-neighbours' initial positions).
pub fn law_for(member: &crate::formation::Member) -> (Law, [u32; 3]) {
    match member.link {
        Some(link) if member.role == crate::formation::Role::Follower => (
            Law::Follower {
                weights: link.weights,
            },
            link.in_neighbors,
        ),
        _ => (
            Law::Leader {
                alpha: member.alpha,
            },
            [member.id; 3],
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_math::vec3;

    /// Real time brings a neighbour to the follower's time with `extrapolate_flat`, then the
    /// tick extrapolates again from there: both moves together must stay on the neighbour's one
    /// cubic, as if extrapolated once.
    #[test]
    fn moving_a_flat_along_its_cubic_composes() {
        let f = Flat {
            r: vec3([1.0, -2.0, 3.0]),
            v: vec3([0.5, 0.25, -1.0]),
            a: vec3([-0.3, 0.2, 0.1]),
            j: vec3([0.05, -0.04, 0.02]),
        };
        let (a, b) = (0.007, 0.0031);
        let moved = extrapolate_flat(&f, a, NeighborModel::Taylor);
        let (r2, v2) = extrapolate(&moved, b, NeighborModel::Taylor);
        let (r1, v1) = extrapolate(&f, a + b, NeighborModel::Taylor);
        assert!((r2 - r1).norm() < 1e-14 && (v2 - v1).norm() < 1e-14);
        assert_eq!(extrapolate_flat(&f, 0.0, NeighborModel::Taylor), f);
        assert_eq!(extrapolate_flat(&f, a, NeighborModel::Hold), f);
    }
}
