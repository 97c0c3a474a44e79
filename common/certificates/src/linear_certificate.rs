//! E_max(T) for the certificate, computed on the team's exactly linear error dynamics instead of
//! flying the nonlinear team at every trial travel time.
//!
//! Why this is exact enough: under the corrected feedback linearisation (ERRATA 2) every
//! quadcopter's position obeys the 4th-order chain r'''' = U (eq. 43a), so the team is the linear
//! system of eq. 32 (the nonlinear engine matches the linear one to about 1e-13 m). What we
//! reproduce here is the engine's own discrete team: a follower integrates its chain over a tick
//! with its in-neighbours' tick-k states extrapolated by a cubic (`step::extrapolate`). Over one
//! tick that is a linear ODE with polynomial input, so its exact discretisation is one matrix
//! exponential ([`TickMaps`]); the engine's RK4 differs from it by O((k dt)^5) per tick. The
//! test `common/certificates/tests/certificate.rs` bounds the difference against the full flight.
//!
//! How it stays cheap at N = 1000. Every member's desired position is r_i,HT(t) = r_i0 + s(t) D_i
//! with D_i = sum_p alpha_ip (goal_p - start_p) (eqs. 13, 15), and the weights reproduce it
//! (sum_j w_ij D_j = D_i, eq. 18). In error coordinates x_i = state_i - state_i,HT:
//! - a leader (full feed-forward, ERRATA 4) has x_L(k) = Lam(k) D_L, one scalar response Lam;
//! - a follower has x_i = phi D_i + H[sum_j w_ij x_j], where phi is its response to the plan's
//!   forcing E_Q (ERRATA 8) and H the operator "one follower driven by a neighbour sequence".
//!
//! H acts on time and W on members, so they commute, and with an acyclic graph (ERRATA 7: the
//! follower block W_FF is nilpotent) the series ends:
//! x_F = (phi + H Lam) c_0 + sum_{l >= 1} H^l psi c_l, with psi = phi + H Lam - Lam and
//! c_l = W_FF^l D_F. So the whole team is D + 2 scalar chains (D = the follower graph's depth)
//! plus one coefficient vector per follower and depth, and E_max is the largest norm of a
//! follower's combination over the ticks, found exactly (every tick counts) by a coarse pass with
//! a curvature bound ([`max_norm`]). The coarse pass runs in parallel over followers.
//!
//! Link delay (`link.rs`) keeps all of this: a follower whose neighbours' states
//! arrive d ticks late flies tick k with their tick-h states, h = max(k - d, 0), brought to t_k
//! by the cubic Taylor shift S(k - h) (`Heard::at_tick`), so the neighbour term of the tick map
//! becomes psi S(k - h) applied to the tick-h input. H is still linear and acts on time only, so
//! it still commutes with W: only the scalar chains change (`chains` with a delay), and E_max at
//! a delay costs what it costs without one.

use cdm_math::{Mat4, Mat8, Real, Vec3, Vec4};
use cdm_model::formation::Role;
use cdm_model::plan::{Quintic, Segment};
use cdm_model::step::{tick_time, NeighborModel};
use cdm_scenario::Scenario;

/// Why a scenario's certificate cannot use the linear model (it then flies the plan instead).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NotLinear {
    /// The follower graph has a cycle (allowed in scenario files): W_FF is not nilpotent.
    #[error("follower {id} is on a cycle of the communication graph")]
    Cyclic { id: u32 },
    /// A follower's weights do not reproduce its desired position (sum_j w_ij alpha_j != alpha_i).
    #[error("follower {id}: weights reproduce its alpha only to {residual:e}")]
    Weights { id: u32, residual: Real },
    /// A member does not start at its desired position r_HT(0).
    #[error("agent {id} starts {distance_m:e} m from its desired position")]
    OffPlan { id: u32, distance_m: Real },
}

/// Ticks between the points of the coarse pass of [`max_norm`] (0.25 s at 100 Hz).
pub(crate) const COARSE_TICKS: usize = 25;

/// The per-tick maps of one axis of one member (exact discretisation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickMaps {
    /// Continuous chain matrix of a follower (and of a leader's error): x' = A x + e4 u.
    pub a: Mat4,
    /// e^{A dt}.
    pub phi: Mat4,
    /// Contribution of the weighted in-neighbour state at t_k through the extrapolated input
    /// u = k4 r_d + k3 r_d' over the tick.
    pub psi: Mat4,
}

impl TickMaps {
    /// The maps for gains k1..k4, a tick of `dt_s` and a neighbour model: one 8x8 matrix
    /// exponential of the chain augmented with the generator of its input polynomial.
    pub fn new(gains: [Real; 4], dt_s: Real, model: NeighborModel) -> Self {
        let [k1, k2, k3, k4] = gains;
        let mut m = Mat8::zeros();
        for i in 0..3 {
            m[(i, i + 1)] = 1.0;
        }
        m[(3, 0)] = -k4;
        m[(3, 1)] = -k3;
        m[(3, 2)] = -k2;
        m[(3, 3)] = -k1;
        // u = k4 w0 + k3 w1, w = the neighbour's (r, v, a, j) carried along the tick.
        m[(3, 4)] = k4;
        m[(3, 5)] = k3;
        if model == NeighborModel::Taylor {
            // w' = shift(w): the cubic Taylor extrapolation of `step::extrapolate`.
            for i in 4..7 {
                m[(i, i + 1)] = 1.0;
            }
        }
        let e = (m * dt_s).exp();
        TickMaps {
            a: m.fixed_view::<4, 4>(0, 0).into_owned(),
            phi: e.fixed_view::<4, 4>(0, 0).into_owned(),
            psi: e.fixed_view::<4, 4>(0, 4).into_owned(),
        }
    }
}

/// A team reduced to its scalar chains and per-follower coefficients (independent of T).
#[derive(Debug, Clone)]
pub struct LinearTeam {
    pub(crate) maps: TickMaps,
    pub(crate) dt_s: Real,
    comm_hz: Real,
    /// Coefficients c_l of every follower, l = 0..=depth_i, as [x, y, z] rows; `start[i]..start[i+1]`.
    pub(crate) coef: Vec<[Real; 3]>,
    pub(crate) start: Vec<usize>,
    /// The member index of every follower, in the order of `start`.
    pub(crate) members: Vec<usize>,
    /// Depth of the follower graph (longest chain of followers), so D + 1 coefficient levels.
    pub(crate) depth: usize,
}

/// The scalar chains of one travel time: positions of g_0..g_D at every tick (tick-major) and,
/// per coarse interval and level, a bound on |g_l''| inside it.
struct Chains {
    pos: Vec<Real>,
    acc_bound: Vec<Real>,
    levels: usize,
    last_tick: usize,
}

impl LinearTeam {
    /// Reduce a scenario (validated) to its chains, or say why the linear model does not apply.
    pub fn new(s: &Scenario) -> Result<Self, NotLinear> {
        Self::of_motion(s, &s.plan.start, &s.plan.goal)
    }

    /// The team flying one motion of its primary leaders from `start` to `goal` (a mission's
    /// phase: every member's displacement is the same affine combination, eq. 13), from rest
    /// on its plan.
    pub fn of_motion(s: &Scenario, start: &[Vec3; 3], goal: &[Vec3; 3]) -> Result<Self, NotLinear> {
        let f = &s.formation;
        let plan = &s.plan;
        let delta: Vec<Vec3> = f
            .members
            .iter()
            .map(|m| (0..3).map(|p| (goal[p] - start[p]) * m.alpha[p]).sum())
            .collect();
        for m in &f.members {
            let at: Vec3 = (0..3).map(|p| plan.start[p] * m.alpha[p]).sum();
            let distance_m = (m.position - at).norm();
            if distance_m > 1e-6 {
                return Err(NotLinear::OffPlan {
                    id: m.id,
                    distance_m,
                });
            }
        }
        let order = follower_order(s)?;
        let depth = order.iter().map(|&(_, d)| d).max().unwrap_or(0);
        // c_0 = D_F; c_{l+1} = W_FF c_l (follower in-neighbours only).
        let n = f.members.len();
        let mut level: Vec<Vec3> = (0..n)
            .map(|k| match f.members[k].role {
                Role::Follower => delta[k],
                _ => Vec3::zeros(),
            })
            .collect();
        let mut per: Vec<Vec<[Real; 3]>> = vec![Vec::new(); n];
        for l in 0..=depth {
            for &(k, d) in &order {
                if l <= d {
                    let c = level[k];
                    per[k].push([c.x, c.y, c.z]);
                }
            }
            let next: Vec<Vec3> = (0..n)
                .map(|k| match &f.members[k].link {
                    Some(link) if f.members[k].role == Role::Follower => link
                        .in_neighbors
                        .iter()
                        .zip(link.weights)
                        .filter_map(|(id, w)| f.index_of(*id).map(|j| (j, w)))
                        .filter(|(j, _)| f.members[*j].role == Role::Follower)
                        .map(|(j, w)| level[j] * w)
                        .sum(),
                    _ => Vec3::zeros(),
                })
                .collect();
            level = next;
        }
        let mut coef = Vec::new();
        let mut start = vec![0];
        for &(k, _) in &order {
            coef.extend_from_slice(&per[k]);
            start.push(coef.len());
        }
        Ok(LinearTeam {
            maps: TickMaps::new(s.file.gains, s.dt_s(), NeighborModel::default()),
            dt_s: s.dt_s(),
            comm_hz: s.file.comm_hz,
            coef,
            start,
            members: order.iter().map(|&(k, _)| k).collect(),
            depth,
        })
    }

    /// Depth of the follower graph.
    pub fn depth(&self) -> usize {
        self.depth
    }

    /// Largest follower deviation ||r_i - r_i,HT||_2 over ticks 0..=last tick of a plan of
    /// `t_total_s` (eq. 34): what `engine::max_follower_deviation` measures by flying.
    pub fn max_follower_deviation(&self, t_total_s: Real) -> Real {
        self.max_follower_deviation_delayed(t_total_s, 0)
    }

    /// [`Self::max_follower_deviation`] with every state between members `delay_ticks` late
    /// (what the engine flies with `[link] delay_ms` = delay_ticks / comm_hz and no jitter or
    /// loss). Not finite when the delayed team diverges.
    pub fn max_follower_deviation_delayed(&self, t_total_s: Real, delay_ticks: u64) -> Real {
        self.deviation_over(t_total_s, delay_ticks, 0.0, Real::INFINITY)
    }

    /// Whether E_max <= `limit_m` with every state `delay_ticks` late: the question the delay
    /// search asks, answered with the coarse pass alone (no interval is refined unless its
    /// bound reaches the limit) and stopped at the first point beyond it.
    pub fn meets(&self, t_total_s: Real, delay_ticks: u64, limit_m: Real) -> bool {
        self.deviation_over(t_total_s, delay_ticks, limit_m, limit_m) <= limit_m
    }

    /// max(floor, E_max), or the first value found above `stop` (infinite when not finite).
    fn deviation_over(&self, t_total_s: Real, delay_ticks: u64, floor: Real, stop: Real) -> Real {
        let last = cdm_scenario::last_tick_of(t_total_s, self.comm_hz) as usize;
        let chains = self.chains(t_total_s, last, delay_ticks as usize);
        let followers = self.start.len() - 1;
        let threads = std::thread::available_parallelism()
            .map_or(1, |n| n.get())
            .clamp(1, followers.max(1));
        let per = followers.div_ceil(threads);
        let stopped = std::sync::atomic::AtomicBool::new(false);
        std::thread::scope(|scope| {
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    let (chains, stopped) = (&chains, &stopped);
                    scope.spawn(move || {
                        let mut best: Real = floor;
                        for i in t * per..((t + 1) * per).min(followers) {
                            if stopped.load(std::sync::atomic::Ordering::Relaxed) {
                                break;
                            }
                            let c = &self.coef[self.start[i]..self.start[i + 1]];
                            best = max_norm(chains, c, self.dt_s, best, stop);
                            if best.is_nan() || best > stop {
                                stopped.store(true, std::sync::atomic::Ordering::Relaxed);
                                return best;
                            }
                        }
                        best
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap_or(Real::INFINITY))
                .fold(floor, Real::max)
        })
    }

    /// Run the scalar chains over ticks 0..=last (see the module text): g_0 = phi + H Lam,
    /// g_l = H^l psi, with H's input `delay` ticks late.
    fn chains(&self, t_total_s: Real, last: usize, delay: usize) -> Chains {
        let TickMaps { a, phi, psi } = self.maps;
        let q = Quintic { t_total_s };
        let dt = self.dt_s;
        let s_at = |k: usize| {
            let t = tick_time(k as u64, dt);
            let seg = if t <= t_total_s {
                Segment::Motion
            } else {
                Segment::Hold
            };
            let d = q.derivatives(t, seg);
            Vec4::new(d[0], d[1], d[2], d[3])
        };
        let levels = self.depth + 1;
        let intervals = last.div_ceil(COARSE_TICKS).max(1);
        let mut pos = Vec::with_capacity((last + 1) * levels);
        let mut acc_bound: Vec<Real> = vec![0.0; intervals * levels];
        // At t = 0 the team is at rest while s''' = 60 / T^3: every error starts with that jerk.
        let x0 = -Vec4::new(0.0, 0.0, 0.0, s_at(0)[3]);
        let (mut phi_x, mut lam, mut chi) = (x0, x0, Vec4::zeros());
        let mut y = vec![Vec4::zeros(); levels];
        let mut s_k = s_at(0);
        // The last delay + 1 ticks of what H reads (s, Lam, g_0 .. g_D), slot k mod (delay + 1).
        let width = levels + 2;
        let mut past = vec![Vec4::zeros(); (delay + 1) * width];
        let psi_delay = psi * taylor_shift(delay as Real * dt);
        for k in 0..=last {
            y[0] = phi_x + chi;
            let slot = (k % (delay + 1)) * width;
            past[slot] = s_k;
            past[slot + 1] = lam;
            past[slot + 2..slot + width].copy_from_slice(&y);
            record_tick(k, &y, dt, intervals, &mut pos, &mut acc_bound);
            if k == last {
                break;
            }
            // The neighbours' states heard at tick k are those of tick h (link.rs: before the
            // first arrives, the start), brought to t_k.
            let h = k.saturating_sub(delay);
            let psi_h = if delay == 0 {
                psi
            } else if k - h == delay {
                psi_delay
            } else {
                psi * taylor_shift((k - h) as Real * dt)
            };
            let at_h = &past[(h % (delay + 1)) * width..][..width];
            let (s_h, lam_h, y_h) = (at_h[0], at_h[1], &at_h[2..]);
            for l in (1..levels).rev() {
                let input = if l == 1 { y_h[0] - lam_h } else { y_h[l - 1] };
                y[l] = phi * y[l] + psi_h * input;
            }
            let s_next = s_at(k + 1);
            chi = phi * chi + psi_h * lam_h;
            phi_x = if delay == 0 {
                // The same operations as before delays existed: the same bits.
                phi * phi_x + (phi + psi) * s_k - s_next
            } else {
                phi * phi_x + phi * s_k + psi_h * s_h - s_next
            };
            lam = phi * lam;
            let t_next = tick_time(k as u64 + 1, dt);
            if t_next > t_total_s && tick_time(k as u64, dt) < t_total_s {
                // ERRATA 12: r_HT''' drops to 0 at T, a leader's r''' does not.
                let jump = Vec4::new(0.0, 0.0, 0.0, q.derivatives(t_total_s, Segment::Motion)[3]);
                lam += (a * (t_next - t_total_s)).exp() * jump;
            }
            s_k = s_next;
        }
        Chains {
            pos,
            acc_bound,
            levels,
            last_tick: last,
        }
    }
}

/// Records tick `k` of every level `y` (its position) and raises the acceleration bound of the
/// coarse intervals holding tick `k`.
fn record_tick(
    k: usize,
    y: &[Vec4],
    dt: Real,
    intervals: usize,
    pos: &mut Vec<Real>,
    acc_bound: &mut [Real],
) {
    let levels = y.len();
    for (l, g) in y.iter().enumerate() {
        pos.push(g[0]);
        // |g''| between ticks is at most |g''(t_k)| + dt |g'''| (+ O(dt^2)).
        let b = g[2].abs() + dt * g[3].abs();
        let j = k / COARSE_TICKS;
        // Interval j holds ticks j M ..= (j + 1) M: a boundary tick is in two.
        for j in [
            Some(j),
            (k > 0 && k.is_multiple_of(COARSE_TICKS)).then(|| j - 1),
        ]
        .into_iter()
        .flatten()
        .filter(|&j| j < intervals)
        {
            let slot = &mut acc_bound[j * levels + l];
            *slot = slot.max(b);
        }
    }
}

/// The cubic Taylor shift by `tau` seconds of a (position, velocity, acceleration, jerk) state:
/// `Heard::at_tick` as a matrix.
pub(crate) fn taylor_shift(tau: Real) -> Mat4 {
    let (t2, t3) = (tau * tau / 2.0, tau * tau * tau / 6.0);
    Mat4::new(
        1.0, tau, t2, t3, //
        0.0, 1.0, tau, t2, //
        0.0, 0.0, 1.0, tau, //
        0.0, 0.0, 0.0, 1.0,
    )
}

/// Followers in topological order with their depth (longest chain of follower in-neighbours).
fn follower_order(s: &Scenario) -> Result<Vec<(usize, usize)>, NotLinear> {
    let f = &s.formation;
    let n = f.members.len();
    let follower_in = |k: usize| -> Vec<usize> {
        f.members[k]
            .link
            .map(|l| {
                l.in_neighbors
                    .iter()
                    .filter_map(|id| f.index_of(*id))
                    .filter(|&j| f.members[j].role == Role::Follower)
                    .collect()
            })
            .unwrap_or_default()
    };
    let mut depth: Vec<Option<usize>> = vec![None; n];
    let mut order = Vec::new();
    let followers: Vec<usize> = (0..n)
        .filter(|&k| f.members[k].role == Role::Follower)
        .collect();
    // Relax until every follower is placed; a pass that places nobody means a cycle.
    let mut left = followers.clone();
    while !left.is_empty() {
        let before = left.len();
        left.retain(|&k| {
            let ins = follower_in(k);
            if ins.iter().all(|&j| depth[j].is_some()) {
                let d = ins.iter().filter_map(|&j| depth[j]).map(|d| d + 1).max();
                depth[k] = Some(d.unwrap_or(0));
                order.push((k, d.unwrap_or(0)));
                false
            } else {
                true
            }
        });
        if left.len() == before {
            return Err(NotLinear::Cyclic {
                id: f.members[left[0]].id,
            });
        }
    }
    for &(k, _) in &order {
        let Some(link) = f.members[k].link else {
            continue;
        };
        let mut alpha = [0.0; 3];
        for (id, w) in link.in_neighbors.iter().zip(link.weights) {
            let j = f.index_of(*id).unwrap_or(k);
            for (a, b) in alpha.iter_mut().zip(f.members[j].alpha) {
                *a += w * b;
            }
        }
        let residual = (0..3)
            .map(|p| (alpha[p] - f.members[k].alpha[p]).abs())
            .fold(0.0, Real::max);
        if residual > 1e-9 {
            return Err(NotLinear::Weights {
                id: f.members[k].id,
                residual,
            });
        }
    }
    Ok(order)
}

/// max(floor, max over ticks of ||sum_l g_l(k) c_l||) for one follower with coefficients `c`.
/// Coarse points every [`COARSE_TICKS`] ticks; an interval is refined tick by tick only when its
/// bound max(ends) + h^2 / 8 max||e''|| can exceed the best so far (e is within h^2/8 max||e''||
/// of the chord between its ends), so the result is the maximum over every tick.
/// Returns early, with a value above `stop` (infinite for a non-finite one), once one is found.
fn max_norm(ch: &Chains, c: &[[Real; 3]], dt_s: Real, floor: Real, stop: Real) -> Real {
    let at = |k: usize| -> Real {
        let g = &ch.pos[k * ch.levels..k * ch.levels + c.len()];
        let mut e = [0.0; 3];
        for (gl, cl) in g.iter().zip(c) {
            for (ea, ca) in e.iter_mut().zip(cl) {
                *ea += gl * ca;
            }
        }
        (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
    };
    let norms: Vec<Real> = c
        .iter()
        .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
        .collect();
    let last = ch.last_tick;
    let intervals = last.div_ceil(COARSE_TICKS).max(1);
    let mut ends = Vec::with_capacity(intervals + 1);
    for j in 0..=intervals {
        let e = at((j * COARSE_TICKS).min(last));
        if e.is_nan() || e > stop {
            // A diverging team overflows to inf and NaN, which `max` would skip.
            return if e.is_finite() { e } else { Real::INFINITY };
        }
        ends.push(e);
    }
    let mut best = ends.iter().copied().fold(floor, Real::max);
    for j in 0..intervals {
        let (a, b) = (j * COARSE_TICKS, ((j + 1) * COARSE_TICKS).min(last));
        let h = (b - a) as Real * dt_s;
        let curv: Real = ch.acc_bound[j * ch.levels..j * ch.levels + c.len()]
            .iter()
            .zip(&norms)
            .map(|(g, n)| g * n)
            .sum();
        if ends[j].max(ends[j + 1]) + h * h / 8.0 * curv * 1.01 > best {
            for k in a + 1..b {
                let e = at(k);
                if e.is_nan() || e > stop {
                    return if e.is_finite() { e } else { Real::INFINITY };
                }
                best = best.max(e);
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_follower_with_neighbours_at_rest_stays_at_rest() {
        let m = TickMaps::new([8.0, 24.0, 51.5625, 23.4375], 0.01, NeighborModel::Taylor);
        let x = Vec4::new(1.0, 0.0, 0.0, 0.0);
        let next = (m.phi + m.psi) * x;
        assert!((next - x).norm() < 1e-14, "{next}");
    }

    #[test]
    fn the_tick_map_is_the_matrix_exponential_of_the_chain() {
        // Without input, many small RK4 steps of x' = A x converge to phi.
        let m = TickMaps::new([8.0, 24.0, 51.5625, 23.4375], 0.01, NeighborModel::Taylor);
        let mut x = Vec4::new(0.3, -0.2, 0.5, 1.0);
        let x0 = x;
        let h = 0.01 / 100.0;
        for _ in 0..100 {
            let k1 = m.a * x;
            let k2 = m.a * (x + k1 * (h / 2.0));
            let k3 = m.a * (x + k2 * (h / 2.0));
            let k4 = m.a * (x + k3 * h);
            x += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
        }
        assert!((m.phi * x0 - x).norm() < 1e-13);
    }
}
