//! A bound on the chains over the rest of a hover, from their state at one tick of it.
//!
//! In the hover after the last motion the leaders are at rest: every signal's desired state is
//! one constant position with zero derivatives, so each step of the chains (`run_chains`,
//! without link delay) is the same linear map of their state, with no forcing (the one a
//! follower at rest on its plan gets is zero; its rounding is kept as `c` below):
//!
//!   Lam' = phi Lam,  chi' = phi chi + psi Lam,  phi_x' = phi phi_x + c,
//!   g_1' = phi g_1 + psi (g_0 - Lam),  g_l' = phi g_l + psi g_(l-1),  g_0 = phi_x + chi.
//!
//! For x' = phi x + psi u, every later state obeys ||x_k|| <= kappa ||x_0|| + sigma sup ||u||,
//! with kappa = sup_k ||phi^k|| and sigma = sum_k ||phi^k psi|| (Frobenius norms, which bound
//! the induced ones), finite because phi is stable (eq. 26). Down the cascade that bounds every
//! 4-vector of every level at every later tick, and so the position norm of each level and
//! primary (the three axes' signals). A follower's deviation there is at most
//! sum_l sum_j |c_lj| times those (the triangle inequality): when that is below the maximum
//! found on the ticks flown, no later tick can change the maximum, its follower or its tick.

use super::{Signals, SIGNALS};
use crate::linear_certificate::TickMaps;
use cdm_math::{Mat4, Real, Vec4};

/// The chains' state at one tick (`run_chains`' loop variables there).
pub(super) struct ChainState {
    /// The desired state of every signal, relative to the start.
    pub desired: Signals,
    pub lam: Signals,
    pub chi: Signals,
    pub phi_x: Signals,
    /// g_0 .. g_D.
    pub levels: Vec<Signals>,
}

/// kappa, sigma and sum_k ||phi^k|| of one team's tick maps (module text).
pub(super) struct RestBound {
    maps: TickMaps,
    kappa: Real,
    sigma: Real,
    phi_sum: Real,
}

/// Powers of phi summed until ||phi^K|| <= 1/2; with q = ||phi^K||, phi^(K + r) = phi^K phi^r
/// gives sup_k ||phi^k|| = max_(k < K) and sum_k <= sum_(k < K) / (1 - q).
const CONTRACTED: Real = 0.5;

/// More powers than a stable phi at any tick needs (its slowest pole, e^(-0.585 t) with the
/// paper's gains, halves in under a second): past them, nothing is bounded.
const MAX_POWERS: usize = 1 << 20;

impl RestBound {
    /// The constants of `maps`; infinite when phi does not contract within `MAX_POWERS` ticks.
    pub(super) fn new(maps: &TickMaps) -> Self {
        let (phi, psi) = (maps.phi, maps.psi);
        let mut power = Mat4::identity();
        let (mut kappa, mut sigma, mut phi_sum): (Real, Real, Real) = (0.0, 0.0, 0.0);
        let mut q = Real::INFINITY;
        for _ in 0..MAX_POWERS {
            let norm = power.norm();
            if norm <= CONTRACTED {
                q = norm;
                break;
            }
            kappa = kappa.max(norm);
            phi_sum += norm;
            sigma += (power * psi).norm();
            power = phi * power;
        }
        let scale = 1.0 / (1.0 - q.min(1.0));
        RestBound {
            maps: *maps,
            kappa: if q.is_finite() { kappa } else { Real::INFINITY },
            sigma: sigma * scale,
            phi_sum: phi_sum * scale,
        }
    }

    /// Per level l and primary j (at `l * 3 + j`): a bound on the norm of that primary's three
    /// axes' positions of g_l at every tick after `state`'s, with the leaders at rest.
    pub(super) fn after(&self, state: &ChainState) -> Vec<Real> {
        let (k, s) = (self.kappa, self.sigma);
        let levels = state.levels.len();
        let mut per_signal = vec![[0.0; SIGNALS]; levels];
        for i in 0..SIGNALS {
            let d = state.desired[i];
            // What a follower at rest on its plan gets each tick: zero, but for rounding.
            let c = (self.maps.phi * d + self.maps.psi * d - d).norm();
            let lam = k * state.lam[i].norm();
            let chi = k * state.chi[i].norm() + s * lam;
            let phi_x = k * state.phi_x[i].norm() + self.phi_sum * c;
            let mut below = phi_x + chi;
            per_signal[0][i] = below;
            for (l, g) in state.levels.iter().enumerate().skip(1) {
                let input = if l == 1 { below + lam } else { below };
                below = k * g[i].norm() + s * input;
                per_signal[l][i] = below;
            }
        }
        let mut out = Vec::with_capacity(levels * 3);
        for b in &per_signal {
            for j in 0..3 {
                let sq: Real = (0..3).map(|a| b[3 * j + a] * b[3 * j + a]).sum();
                // NaN (a diverging team) bounds nothing.
                out.push(if sq.is_nan() {
                    Real::INFINITY
                } else {
                    sq.sqrt()
                });
            }
        }
        out
    }
}

/// sum over levels and primaries of |c_lj| times `per`'s (l, j) entries: the bound on a
/// follower with coefficients `c` that `per` bounds the chains by.
pub(super) fn weigh(per: &[Real], c: &[[Real; 3]]) -> Real {
    (per.chunks_exact(3).zip(c))
        .map(|(b, cl)| (0..3).map(|j| b[j] * cl[j].abs()).sum::<Real>())
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A state of zeros but one level is bounded by kappa times it, and its followers' levels
    /// by sigma times the level above: the cascade, checked by hand.
    #[test]
    fn the_cascade_bounds_each_level_by_the_one_above() {
        let maps = TickMaps {
            a: Mat4::zeros(),
            phi: Mat4::identity() * 0.25,
            psi: Mat4::identity() * 0.5,
        };
        let b = RestBound::new(&maps);
        // ||I|| = 2 > 1/2, ||phi|| = 0.5: K = 1, q = 0.5.
        assert_eq!((b.kappa, b.sigma, b.phi_sum), (2.0, 2.0, 4.0));
        let zero = [Vec4::zeros(); SIGNALS];
        let mut lam = zero;
        lam[0] = Vec4::new(3.0, 0.0, 0.0, 4.0);
        let state = ChainState {
            desired: zero,
            lam,
            chi: zero,
            phi_x: zero,
            levels: vec![zero; 3],
        };
        let after = b.after(&state);
        // Lam: 2 * 5 = 10; chi: 2 * 10 = 20 = g_0; g_1: 2 (20 + 10) = 60; g_2: 2 * 60.
        assert_eq!(after.len(), 9);
        assert_eq!([after[0], after[3], after[6]], [20.0, 60.0, 120.0]);
        assert_eq!(weigh(&after, &[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), 20.0);
    }
}
