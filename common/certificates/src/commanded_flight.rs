//! The largest follower deviation of a commanded flight from its switch on (eq. 34), computed
//! on the team's exactly linear error dynamics instead of flying the nonlinear team from t = 0.
//!
//! Why it is exact: it is `linear_certificate.rs`'s model (the engine's own discrete team, each
//! tick one matrix exponential; the nonlinear engine matches it to about 1e-12 relative) with
//! one change: the team's forcing is no longer one rest-to-rest quintic. Every member's desired
//! position is r_i,HT(t) = sum_j alpha_ij P_j(t) (eq. 13) whatever the primary leaders' paths
//! P_j do (cut phases, a hold's stop, new segments, hovers), and the weights reproduce alpha
//! (sum_k w_ik alpha_k = alpha_i, eq. 18). So each of the nine scalar signals "primary j along
//! axis a" drives the team exactly as `linear_certificate.rs`'s s(t) does, with alpha_.j in place
//! of D: the same D + 2 scalar chains per signal, run once over the whole flight (a few
//! thousand 4x4 products per tick, no member in them), and one coefficient vector per follower
//! and depth (W_FF^l alpha_F), the same for every command. The tracking error every phase
//! leaves to the next is carried by the chains themselves, so no phase is assumed to start at
//! rest, and the tick of the switch is just where the maximum starts being taken.
//!
//! The leaders' errors (full feed-forward, ERRATA 4) evolve by e^{A h} between the instants
//! where their plan's derivatives jump (every phase's start and end, ERRATA 12; a cut's
//! velocity and acceleration jumps are cancelled by the stop that continues it) and take
//! minus the jump there, the state itself being continuous: as the engine integrates them,
//! split at every break (`step::step_at`).

use crate::linear_certificate::{taylor_shift, LinearTeam, NotLinear, TickMaps, COARSE_TICKS};
use cdm_math::{Mat4, Real, Vec3, Vec4};
use cdm_model::plan::{Piece, TeamPlan};
use cdm_model::step::tick_time;
use cdm_scenario::Scenario;

/// Primary leader j along axis a is signal 3 j + a.
const SIGNALS: usize = 9;

/// One 4-vector (position, velocity, acceleration, jerk) per signal.
type Signals = [Vec4; SIGNALS];

/// The largest follower deviation over a span of ticks, and where.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deviation {
    /// max ||r_i - r_i,HT||_2 over the followers and ticks (m); infinite when not finite.
    pub max_m: Real,
    /// The follower it is reached by (0 without followers).
    pub agent: u32,
    /// The tick it is reached at.
    pub tick: u64,
}

/// The largest follower deviation of `s` flying its plan (as commanded) over ticks
/// `from_tick..=` its last, with every state between members `delay_ticks` late (the engine's
/// `[link] delay_ms` without jitter or loss), or why the linear model does not apply.
pub fn max_follower_deviation_from(
    s: &Scenario,
    from_tick: u64,
    delay_ticks: u64,
) -> Result<Deviation, NotLinear> {
    let plan = &s.plan;
    let origin = plan.primary_derivs(0.0, plan.piece_at(0.0)).map(|d| d[0]);
    for m in &s.formation.members {
        let at: Vec3 = (0..3).map(|p| origin[p] * m.alpha[p]).sum();
        let distance_m = (m.start - at).norm();
        if distance_m > 1e-6 {
            return Err(NotLinear::OffPlan {
                id: m.id,
                distance_m,
            });
        }
    }
    // The coefficients of "primary j moves by one along x, y, z": c_l = W_FF^l alpha_F.
    let unit = [Vec3::x(), Vec3::y(), Vec3::z()];
    let goal = std::array::from_fn(|j| plan.start[j] + unit[j]);
    let team = LinearTeam::of_motion(s, &plan.start, &goal)?;
    let last = s.last_tick() as usize;
    let from = (from_tick as usize).min(last);
    let chains = run_chains(plan, &team, &origin, from, last, delay_ticks as usize);
    let followers = team.start.len() - 1;
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, followers.max(1));
    let per = followers.div_ceil(threads);
    let best = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let (chains, team) = (&chains, &team);
                scope.spawn(move || {
                    let mut best = (0.0, 0, from);
                    for i in t * per..((t + 1) * per).min(followers) {
                        let c = &team.coef[team.start[i]..team.start[i + 1]];
                        let (e, k) = max_norm(chains, c, team.dt_s, best.0);
                        if e > best.0 || !e.is_finite() {
                            best = (e, i, k);
                        }
                        if !best.0.is_finite() {
                            break;
                        }
                    }
                    best
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or((Real::INFINITY, 0, from)))
            .fold((0.0, 0, from), |a, b| {
                if b.0 > a.0 || !b.0.is_finite() {
                    b
                } else {
                    a
                }
            })
    });
    let (max_m, i, tick) = best;
    Ok(Deviation {
        max_m: if max_m.is_finite() {
            max_m
        } else {
            Real::INFINITY
        },
        agent: (team.members.get(i)).map_or(0, |&k| s.formation.members[k].id),
        tick: tick as u64,
    })
}

/// The scalar chains of the nine signals over ticks `from..=last`, levels g_0..g_D.
struct FlightChains {
    /// Per tick from `from`: the position of level l, signal i at `l * SIGNALS + i`.
    pos: Vec<Real>,
    /// Per coarse interval (from `from` on) and level and primary j: a bound on the norm of
    /// the 3-vector of that primary's three axes' g_l''.
    acc_bound: Vec<Real>,
    /// The same layout: the largest norm of that 3-vector's positions over the interval and
    /// every later one (the tail bound of [`max_norm`]).
    tail: Vec<Real>,
    levels: usize,
    from: usize,
    last: usize,
}

/// The desired state of every signal at `t` on `piece`, relative to the start.
fn desired(plan: &TeamPlan, origin: &[Vec3; 3], t: Real, piece: Piece) -> Signals {
    let p = plan.primary_derivs(t, piece);
    std::array::from_fn(|i| {
        let (j, a) = (i / 3, i % 3);
        Vec4::new(
            p[j][0][a] - origin[j][a],
            p[j][1][a],
            p[j][2][a],
            p[j][3][a],
        )
    })
}

/// Runs the chains of `linear_certificate.rs` (g_0 = phi + H Lam, g_l = H^l psi) for every
/// signal over the whole flight, recording ticks `from..=last`.
fn run_chains(
    plan: &TeamPlan,
    team: &LinearTeam,
    origin: &[Vec3; 3],
    from: usize,
    last: usize,
    delay: usize,
) -> FlightChains {
    let TickMaps { phi, psi, .. } = team.maps;
    let dt = team.dt_s;
    let at = |k: usize| {
        let t = tick_time(k as u64, dt);
        desired(plan, origin, t, plan.piece_at(t))
    };
    let levels = team.depth + 1;
    let intervals = (last - from).div_ceil(COARSE_TICKS).max(1);
    let mut ch = FlightChains {
        pos: Vec::with_capacity((last - from + 1) * levels * SIGNALS),
        acc_bound: vec![0.0; intervals * levels * 3],
        tail: vec![0.0; intervals * levels * 3],
        levels,
        from,
        last,
    };
    let zero = [Vec4::zeros(); SIGNALS];
    // At rest at the start, with whatever derivatives the plan starts with.
    let mut d_k = at(0);
    let x0 = d_k.map(|d| -d);
    let (mut phi_x, mut lam, mut chi) = (x0, x0, zero);
    let mut y = vec![zero; levels];
    // The last delay + 1 ticks of what H reads (desired, Lam, g_0 .. g_D), slot k mod (delay + 1).
    let width = levels + 2;
    let mut past = vec![zero; (delay + 1) * width];
    let psi_delay = psi * taylor_shift(delay as Real * dt);
    for k in 0..=last {
        for i in 0..SIGNALS {
            y[0][i] = phi_x[i] + chi[i];
        }
        let slot = (k % (delay + 1)) * width;
        past[slot] = d_k;
        past[slot + 1] = lam;
        past[slot + 2..slot + width].copy_from_slice(&y);
        if k >= from {
            ch.record(k - from, &y, dt, intervals);
        }
        if k == last {
            break;
        }
        let h = k.saturating_sub(delay);
        let psi_h = if k - h == delay {
            psi_delay
        } else {
            psi * taylor_shift((k - h) as Real * dt)
        };
        let at_h = &past[(h % (delay + 1)) * width..][..width];
        let d_next = at(k + 1);
        follower_step(
            (phi, psi_h),
            at_h,
            (&d_k, &d_next),
            &mut y,
            &mut chi,
            &mut phi_x,
        );
        lam = leader_step(plan, team, origin, k, &lam, &d_k, &d_next);
        d_k = d_next;
    }
    // Each interval's largest position norm, then the largest over it and every later one.
    let row = levels * 3;
    for m in (0..intervals.saturating_sub(1)).rev() {
        for q in 0..row {
            ch.tail[m * row + q] = ch.tail[m * row + q].max(ch.tail[(m + 1) * row + q]);
        }
    }
    ch
}

/// The followers' chains from tick k to k + 1 (`linear_certificate::LinearTeam::chains`):
/// g_l <- phi g_l + psi_h (input of level l), H Lam and g_0's own forcing, with `heard` what
/// H reads at tick k (the tick-h desired state, Lam, g_0 .. g_D) and `(d_k, d_next)` the
/// desired states at k and k + 1.
fn follower_step(
    (phi, psi_h): (Mat4, Mat4),
    heard: &[Signals],
    (d_k, d_next): (&Signals, &Signals),
    y: &mut [Signals],
    chi: &mut Signals,
    phi_x: &mut Signals,
) {
    for l in (1..y.len()).rev() {
        for i in 0..SIGNALS {
            let input = if l == 1 {
                heard[2][i] - heard[1][i]
            } else {
                heard[l + 1][i]
            };
            y[l][i] = phi * y[l][i] + psi_h * input;
        }
    }
    for i in 0..SIGNALS {
        chi[i] = phi * chi[i] + psi_h * heard[1][i];
        phi_x[i] = phi * phi_x[i] + phi * d_k[i] + psi_h * heard[0][i] - d_next[i];
    }
}

/// A leader's error (per unit of alpha) from tick k to k + 1: e^{A dt} between breaks, minus
/// the plan's jump at each (see the module text). `lam` and the result are relative to the
/// desired state at the ticks, `d_k` and `d_next`.
fn leader_step(
    plan: &TeamPlan,
    team: &LinearTeam,
    origin: &[Vec3; 3],
    k: usize,
    lam: &Signals,
    d_k: &Signals,
    d_next: &Signals,
) -> Signals {
    let dt = team.dt_s;
    let (t0, t1) = (tick_time(k as u64, dt), tick_time(k as u64 + 1, dt));
    let whole = plan.piece_of(t0, t1);
    if plan.break_inside(t0, t1).is_none()
        && whole == plan.piece_at(t0)
        && whole == plan.piece_at(t1)
    {
        return lam.map(|e| team.maps.phi * e);
    }
    let (mut e, mut prev, mut from) = (*lam, *d_k, t0);
    loop {
        let to = plan.break_inside(from, t1).unwrap_or(t1);
        let piece = plan.piece_of(from, to);
        let d_from = desired(plan, origin, from, piece);
        let m = (team.maps.a * (to - from)).exp();
        for i in 0..SIGNALS {
            e[i] = m * (e[i] + prev[i] - d_from[i]);
        }
        prev = desired(plan, origin, to, piece);
        if to == t1 {
            break;
        }
        from = to;
    }
    std::array::from_fn(|i| e[i] + prev[i] - d_next[i])
}

impl FlightChains {
    /// Records tick `from + r` of every level (its positions) and raises the curvature bounds
    /// and the position norms of the coarse intervals holding it.
    fn record(&mut self, r: usize, y: &[Signals], dt: Real, intervals: usize) {
        let (pos, acc_bound, sup) = (&mut self.pos, &mut self.acc_bound, &mut self.tail);
        let levels = y.len();
        for (l, g) in y.iter().enumerate() {
            pos.extend(g.iter().map(|v| v[0]));
            for j in 0..3 {
                // |g''| between ticks is at most |g''(t_k)| + dt |g'''| (+ O(dt^2)), per axis.
                let b = (0..3)
                    .map(|a| {
                        let v = g[3 * j + a];
                        let b = v[2].abs() + dt * v[3].abs();
                        b * b
                    })
                    .sum::<Real>()
                    .sqrt();
                let norm = (0..3)
                    .map(|a| g[3 * j + a][0] * g[3 * j + a][0])
                    .sum::<Real>()
                    .sqrt();
                let m = r / COARSE_TICKS;
                for m in [
                    Some(m),
                    (r > 0 && r.is_multiple_of(COARSE_TICKS)).then(|| m - 1),
                ]
                .into_iter()
                .flatten()
                .filter(|&m| m < intervals)
                {
                    let q = (m * levels + l) * 3 + j;
                    acc_bound[q] = acc_bound[q].max(b);
                    sup[q] = sup[q].max(norm);
                }
            }
        }
    }
}

/// (max(floor, max over ticks of ||sum_l sum_j c_lj G_lj||), the tick) for one follower with
/// coefficients `c` (one [j = 0, 1, 2] row per level): `linear_certificate::max_norm`'s
/// coarse pass and refinement, with nine signals in place of one, ended at the first interval
/// from which no later tick can exceed the best so far: there sum_lj |c_lj| max ||G_lj|| over
/// the rest of the flight (the triangle inequality; the hovers after the last motion, where
/// the errors only decay, are most of a commanded flight) is at most the best.
fn max_norm(ch: &FlightChains, c: &[[Real; 3]], dt_s: Real, floor: Real) -> (Real, usize) {
    let at = |r: usize| -> Real {
        let g = &ch.pos[r * ch.levels * SIGNALS..][..c.len() * SIGNALS];
        let mut e = [0.0; 3];
        for (gl, cl) in g.chunks_exact(SIGNALS).zip(c) {
            for (j, cj) in cl.iter().enumerate() {
                for (a, ea) in e.iter_mut().enumerate() {
                    *ea += gl[3 * j + a] * cj;
                }
            }
        }
        (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
    };
    // sum over levels and primaries of |c_lj| times `per`'s (l, j) entries of interval m.
    let weigh = |per: &[Real], m: usize| -> Real {
        let row = &per[m * ch.levels * 3..][..c.len() * 3];
        (row.chunks_exact(3).zip(c))
            .map(|(b, cl)| (0..3).map(|j| b[j] * cl[j].abs()).sum::<Real>())
            .sum()
    };
    let span = ch.last - ch.from;
    let intervals = span.div_ceil(COARSE_TICKS).max(1);
    let mut best = (floor, ch.from);
    let mut ends = Vec::with_capacity(intervals + 1);
    let mut cut = intervals;
    for m in 0..=intervals {
        let r = (m * COARSE_TICKS).min(span);
        let e = at(r);
        if !e.is_finite() {
            // A diverging team overflows to inf and NaN, which `max` would skip.
            return (Real::INFINITY, ch.from + r);
        }
        if e > best.0 {
            best = (e, ch.from + r);
        }
        ends.push(e);
        if m < intervals && weigh(&ch.tail, m) <= best.0 {
            cut = m;
            break;
        }
    }
    for m in 0..cut {
        let (a, b) = (m * COARSE_TICKS, ((m + 1) * COARSE_TICKS).min(span));
        let h = (b - a) as Real * dt_s;
        let curv = weigh(&ch.acc_bound, m);
        if ends[m].max(ends[m + 1]) + h * h / 8.0 * curv * 1.01 > best.0 {
            for r in a + 1..b {
                let e = at(r);
                if !e.is_finite() {
                    return (Real::INFINITY, ch.from + r);
                }
                if e > best.0 {
                    best = (e, ch.from + r);
                }
            }
        }
    }
    best
}

#[cfg(test)]
mod tests;
