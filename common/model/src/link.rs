//! Imperfect links as part of the deterministic model: a state sent from one member
//! to another arrives some whole ticks late, or not at all.
//!
//! The paper assumes continuous exchange (eqs. 24-25). Real links are late and lossy, so a
//! follower flies on the newest state it has heard of each in-neighbour, brought from that
//! state's own tick to the current one with the cubic Taylor model used inside a tick
//! (`step::extrapolate`); `step` then runs unchanged. A lost state is never waited for: the
//! follower extrapolates from the newest one it holds.
//!
//! Every draw is a pure function of (seed, sender, receiver, tick): the engine and every member
//! process compute the same deliveries without communicating, and both go through
//! [`LinkModel::hear`], so `simulate` and lockstep `launch` stay byte-identical with impairments
//! set.
//!
//! - A state sampled at tick m on link (j -> i) is delayed by `delay_ms + u * jitter_ms`,
//!   u uniform in [0, 1) from the link's draw, rounded to whole ticks: it can be used from tick
//!   m + that many ticks on. Jitter only ever adds delay (nothing arrives before `delay_ms`).
//! - With probability `loss` (a second, independent draw) it never arrives.
//! - Before anything has arrived a follower knows where its neighbour started (at rest, from
//!   the scenario), i.e. the tick-0 state, which therefore is never waited for.

use serde::{Deserialize, Serialize};

use crate::dynamics::Flat;
use crate::step::{extrapolate, NeighborModel};
use cdm_math::Real;

/// A neighbour's state as a follower has heard it: the flat output and the tick it was
/// sampled at (the current tick with perfect links, older over delayed or lossy ones).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Heard {
    pub tick: u64,
    pub flat: Flat,
}

impl Heard {
    /// This state brought to tick `k` (>= its own) the way a follower extrapolates a neighbour
    /// inside a tick (`step::extrapolate`; the cubic is carried exactly). A state of tick `k`
    /// itself is returned untouched, so perfect links fly the paper's model bit for bit.
    pub fn at_tick(&self, k: u64, dt_s: Real, model: NeighborModel) -> Flat {
        if self.tick >= k || model == NeighborModel::Hold {
            return self.flat;
        }
        let tau = (k - self.tick) as Real * dt_s;
        let f = &self.flat;
        let (r, v) = extrapolate(f, tau, model);
        Flat {
            r,
            v,
            a: f.a + f.j * tau,
            j: f.j,
        }
    }
}

/// The `[link]` table of a scenario: every key optional, all zero = perfect links (the
/// paper's model, and the default).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkSpec {
    /// Delay of every state, milliseconds (rounded to whole ticks).
    #[serde(default)]
    pub delay_ms: Real,
    /// Extra delay drawn uniformly in [0, jitter_ms) per (link, tick), milliseconds.
    #[serde(default)]
    pub jitter_ms: Real,
    /// Probability in [0, 1) that a state is lost, per (link, tick).
    #[serde(default)]
    pub loss: Real,
    /// Seed of the draws (at most 2^63 - 1: TOML integers are signed).
    #[serde(default)]
    pub seed: u64,
}

impl LinkSpec {
    /// True when every impairment is zero (the seed alone changes nothing).
    pub fn is_perfect(&self) -> bool {
        self.delay_ms == 0.0 && self.jitter_ms == 0.0 && self.loss == 0.0
    }

    /// Why the spec cannot be flown, as (field, reason), or `None`.
    pub fn problem(&self) -> Option<(&'static str, String)> {
        let ms = |field, v: Real| {
            (!(v.is_finite() && (0.0..=MAX_DELAY_MS).contains(&v))).then(|| {
                (
                    field,
                    format!("must be a number of milliseconds in [0, {MAX_DELAY_MS}], got {v}"),
                )
            })
        };
        ms("link.delay_ms", self.delay_ms)
            .or_else(|| ms("link.jitter_ms", self.jitter_ms))
            .or_else(|| {
                (!(self.loss.is_finite() && (0.0..1.0).contains(&self.loss))).then(|| {
                    (
                        "link.loss",
                        format!("must be a probability in [0, 1), got {}", self.loss),
                    )
                })
            })
            .or_else(|| {
                (self.seed > i64::MAX as u64).then(|| {
                    (
                        "link.seed",
                        format!("must be at most {}, got {}", i64::MAX, self.seed),
                    )
                })
            })
    }
}

/// The largest delay or jitter accepted, milliseconds (a minute: far beyond any useful link,
/// and it bounds the states a member keeps).
pub const MAX_DELAY_MS: Real = 60_000.0;

/// A scenario's links at its tick length: the deliveries of every (link, tick).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkModel {
    spec: LinkSpec,
    dt_ms: Real,
    min_ticks: u64,
    max_ticks: u64,
}

impl LinkModel {
    /// The links of `spec` with ticks of `dt_s` seconds.
    pub fn new(spec: LinkSpec, dt_s: Real) -> Self {
        let dt_ms = dt_s * 1000.0;
        let ticks = |ms: Real| (ms / dt_ms).round() as u64;
        LinkModel {
            spec,
            dt_ms,
            min_ticks: ticks(spec.delay_ms),
            max_ticks: ticks(spec.delay_ms + spec.jitter_ms),
        }
    }

    /// Perfect links: every state is used at the tick it was sampled (the paper's model).
    pub fn perfect(dt_s: Real) -> Self {
        Self::new(LinkSpec::default(), dt_s)
    }

    /// True when every state arrives at once: the engine and members then take their
    /// original, faster path.
    pub fn is_perfect(&self) -> bool {
        self.max_ticks == 0 && self.spec.loss == 0.0
    }

    /// The smallest delay of any state, ticks.
    pub fn min_ticks(&self) -> u64 {
        self.min_ticks
    }

    /// The largest delay of any state, ticks.
    pub fn max_ticks(&self) -> u64 {
        self.max_ticks
    }

    /// The links as specified (real time applies them in milliseconds, unrounded).
    pub fn spec(&self) -> LinkSpec {
        self.spec
    }

    /// The delay of the state sampled at tick `m` on link `from -> to` before any rounding,
    /// milliseconds: `delay_ms + u * jitter_ms`, u the link's draw; `None` when it is lost.
    /// Lockstep rounds it to whole ticks ([`Self::arrival`]); real time holds a received state
    /// back by this much wall time (cdm-runtime's `realtime_links`).
    pub fn delay_ms(&self, from: u32, to: u32, m: u64) -> Option<Real> {
        let key = draw_key(self.spec.seed, from, to, m);
        if self.spec.loss > 0.0 && unit(splitmix64(key ^ LOSS_STREAM)) < self.spec.loss {
            return None;
        }
        if self.spec.jitter_ms == 0.0 {
            return Some(self.spec.delay_ms);
        }
        Some(self.spec.delay_ms + self.spec.jitter_ms * unit(splitmix64(key ^ JITTER_STREAM)))
    }

    /// The tick from which the state sampled at tick `m` on link `from -> to` can be used, or
    /// `None` when it is lost.
    pub fn arrival(&self, from: u32, to: u32, m: u64) -> Option<u64> {
        let ms = self.delay_ms(from, to, m)?;
        if self.max_ticks == self.min_ticks {
            return Some(m + self.min_ticks);
        }
        let ticks = ((ms / self.dt_ms).round() as u64).clamp(self.min_ticks, self.max_ticks);
        Some(m + ticks)
    }

    /// The neighbour tick a follower must have received before it computes tick `k`: every
    /// state that may be usable at k is then in (a neighbour publishes its ticks in order).
    /// `None` before the smallest delay has passed (only the known start is usable).
    pub fn needed(&self, k: u64) -> Option<u64> {
        k.checked_sub(self.min_ticks)
    }

    /// States sampled before this tick are no longer candidates at tick `k`: they arrived (or
    /// were lost) by tick k - 1 at the latest, and `newest` has already seen them.
    pub fn oldest_candidate(&self, k: u64) -> u64 {
        k.saturating_sub(self.max_ticks)
    }

    /// The newest state follower `to` has of in-neighbour `from` at its tick `k`: `held` (the
    /// newest at tick k - 1) or a candidate that has arrived by k, whichever was sampled later
    /// (a received state of the same tick replaces the held one: the tick-0 state as sent, not
    /// as assumed, so that a bad one is noticed).
    pub fn newest(
        &self,
        from: u32,
        to: u32,
        k: u64,
        held: Heard,
        candidates: impl IntoIterator<Item = Heard>,
    ) -> Heard {
        let mut best = held;
        for c in candidates {
            if c.tick >= best.tick
                && c.tick <= k
                && self.arrival(from, to, c.tick).is_some_and(|a| a <= k)
            {
                best = c;
            }
        }
        best
    }

    /// What follower `to` flies tick `k` with: `held` (the newest state of each in-neighbour
    /// `from[slot]` at tick k - 1) is updated with the states of `candidates(slot)` that have
    /// arrived by k, and each is brought to tick k ([`Heard::at_tick`]). The engine and the
    /// member processes both call this, so they cannot drift apart.
    #[allow(clippy::too_many_arguments)]
    pub fn hear<I: IntoIterator<Item = Heard>>(
        &self,
        to: u32,
        from: &[u32; 3],
        k: u64,
        held: &mut [Heard; 3],
        mut candidates: impl FnMut(usize) -> I,
        dt_s: Real,
        model: NeighborModel,
    ) -> [Flat; 3] {
        for (slot, h) in held.iter_mut().enumerate() {
            *h = self.newest(from[slot], to, k, *h, candidates(slot));
        }
        held.map(|h| h.at_tick(k, dt_s, model))
    }
}

/// Stream separators: the loss and jitter draws of one (link, tick) are independent.
const LOSS_STREAM: u64 = 0x6c6f_7373_6c6f_7373;
const JITTER_STREAM: u64 = 0x6a69_7474_6a69_7474;

/// One 64-bit key per (seed, link, tick), by chaining SplitMix64 over the inputs.
fn draw_key(seed: u64, from: u32, to: u32, tick: u64) -> u64 {
    let link = (u64::from(from) << 32) | u64::from(to);
    splitmix64(seed ^ splitmix64(link ^ splitmix64(tick)))
}

/// SplitMix64's output function (Steele, Lea and Flood, "Fast splittable pseudorandom number
/// generators", OOPSLA 2014; the constants of Vigna's reference `splitmix64.c`): a bijective
/// 64-bit mix, a counter-based generator when fed a counter.
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The top 53 bits as a uniform number in [0, 1).
fn unit(x: u64) -> Real {
    (x >> 11) as Real * (1.0 / (1u64 << 53) as Real)
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_math::Vec3;

    fn spec(delay_ms: Real, jitter_ms: Real, loss: Real) -> LinkSpec {
        LinkSpec {
            delay_ms,
            jitter_ms,
            loss,
            seed: 7,
        }
    }

    #[test]
    fn splitmix64_matches_the_reference_sequence() {
        // Vigna's splitmix64.c with state 0: the state advances by the golden gamma before
        // each output, which `splitmix64(k * gamma)` reproduces.
        let gamma = 0x9e37_79b9_7f4a_7c15u64;
        assert_eq!(splitmix64(0), 0xe220_a839_7b1d_cdaf);
        assert_eq!(splitmix64(gamma), 0x6e78_9e6a_a1b9_65f4);
    }

    #[test]
    fn delay_rounds_to_whole_ticks() {
        let m = LinkModel::new(spec(24.0, 0.0, 0.0), 0.01);
        assert_eq!((m.min_ticks(), m.max_ticks()), (2, 2));
        assert_eq!(m.arrival(1, 2, 10), Some(12));
        assert!(!m.is_perfect());
        let p = LinkModel::new(spec(4.0, 0.0, 0.0), 0.01);
        assert!(p.is_perfect(), "under half a tick rounds to no delay");
    }

    #[test]
    fn jitter_stays_within_its_bounds_and_uses_them() {
        let m = LinkModel::new(spec(20.0, 50.0, 0.0), 0.01);
        assert_eq!((m.min_ticks(), m.max_ticks()), (2, 7));
        let mut seen = std::collections::BTreeSet::new();
        for t in 0..2000 {
            let a = m.arrival(3, 9, t).map(|a| a - t);
            let d = a.unwrap_or(u64::MAX);
            assert!((2..=7).contains(&d), "tick {t}: delay {d}");
            seen.insert(d);
        }
        assert_eq!(seen.len(), 6, "every whole-tick delay occurs: {seen:?}");
    }

    #[test]
    fn loss_rate_is_near_p_and_depends_on_link_and_seed() {
        let m = LinkModel::new(spec(0.0, 0.0, 0.2), 0.01);
        let lost = (0..20_000)
            .filter(|&t| m.arrival(1, 2, t).is_none())
            .count();
        assert!(
            (3600..4400).contains(&lost),
            "lost {lost} of 20000 at p = 0.2"
        );
        let other_link = (0..200).filter(|&t| m.arrival(2, 1, t) != m.arrival(1, 2, t));
        assert!(other_link.count() > 20, "links draw independently");
        let reseeded = LinkModel::new(
            LinkSpec {
                seed: 8,
                ..spec(0.0, 0.0, 0.2)
            },
            0.01,
        );
        let differ = (0..200).filter(|&t| reseeded.arrival(1, 2, t) != m.arrival(1, 2, t));
        assert!(differ.count() > 20, "the seed changes the draws");
    }

    #[test]
    fn delay_ms_is_the_unrounded_draw_of_arrival() {
        let m = LinkModel::new(spec(20.0, 50.0, 0.3), 0.01);
        let mut lost = 0;
        for t in 0..2000 {
            match (m.delay_ms(4, 9, t), m.arrival(4, 9, t)) {
                (None, None) => lost += 1,
                (Some(ms), Some(a)) => {
                    assert!((20.0..70.0).contains(&ms), "tick {t}: {ms} ms");
                    assert_eq!(a - t, (ms / 10.0).round() as u64, "tick {t}: {ms} ms");
                }
                other => panic!("tick {t}: lost in one and not the other: {other:?}"),
            }
        }
        assert!((450..750).contains(&lost), "lost {lost} of 2000 at p = 0.3");
        let fixed = LinkModel::new(spec(4.0, 0.0, 0.0), 0.01);
        assert_eq!(
            fixed.delay_ms(1, 2, 3),
            Some(4.0),
            "under half a tick still counts"
        );
    }

    #[test]
    fn newest_takes_the_latest_arrived_state_and_keeps_it_through_losses() {
        let m = LinkModel::new(spec(30.0, 0.0, 0.0), 0.01);
        let at = |tick: u64| Heard {
            tick,
            flat: Flat::rest(Vec3::new(tick as Real, 0.0, 0.0)),
        };
        let start = at(0);
        // At tick 5 with 3 ticks of delay, states 0..=2 have arrived: 2 is the newest.
        let h = m.newest(1, 2, 5, start, (0..=5).map(at));
        assert_eq!(h.tick, 2);
        // Nothing newer: the held state stays.
        assert_eq!(m.newest(1, 2, 5, at(4), (0..=5).map(at)).tick, 4);
        // Before the delay has passed only the known start is usable.
        assert_eq!(m.newest(1, 2, 2, start, (0..=2).map(at)).tick, 0);
    }

    #[test]
    fn a_state_brought_forward_is_the_cubic_at_the_later_tick() {
        let h = Heard {
            tick: 3,
            flat: Flat {
                r: Vec3::new(1.0, 2.0, 3.0),
                v: Vec3::new(0.5, 0.0, -1.0),
                a: Vec3::new(0.0, 2.0, 0.0),
                j: Vec3::new(6.0, 0.0, 0.0),
            },
        };
        assert_eq!(h.at_tick(3, 0.5, NeighborModel::Taylor), h.flat);
        assert_eq!(h.at_tick(5, 0.5, NeighborModel::Hold), h.flat);
        // tau = 1 s: r + v + a / 2 + j / 6, v + a + j / 2, a + j.
        let f = h.at_tick(5, 0.5, NeighborModel::Taylor);
        assert!((f.r - Vec3::new(2.5, 3.0, 2.0)).norm() < 1e-15, "{}", f.r);
        assert!((f.v - Vec3::new(3.5, 2.0, -1.0)).norm() < 1e-15, "{}", f.v);
        assert!((f.a - Vec3::new(6.0, 2.0, 0.0)).norm() < 1e-15, "{}", f.a);
        assert_eq!(f.j, h.flat.j);
    }

    #[test]
    fn problems_name_the_field() {
        assert_eq!(
            spec(-1.0, 0.0, 0.0).problem().map(|p| p.0),
            Some("link.delay_ms")
        );
        assert_eq!(
            spec(0.0, Real::NAN, 0.0).problem().map(|p| p.0),
            Some("link.jitter_ms")
        );
        assert_eq!(
            spec(0.0, 0.0, 1.0).problem().map(|p| p.0),
            Some("link.loss")
        );
        assert_eq!(spec(10.0, 5.0, 0.5).problem(), None);
    }
}
