//! Imperfect links on real deliveries (`--realtime` with `--link-delay-ms`, `--link-jitter-ms`,
//! `--link-loss`, `--seed`), as a plain type with no I/O or clock of its own.
//!
//! The draws are lockstep's (`cdm_model::link`): the state sampled at its sender's tick m on link
//! j -> i is lost with probability P, else delayed by `delay_ms + u * jitter_ms`, both drawn from
//! the seeded generator keyed by (seed, j, i, m). Lockstep rounds that delay to whole ticks; in
//! real time it is milliseconds of wall time, unrounded: a state received over the transport is
//! held back until the receiver's own time reaches the state's stamp plus the delay (or is
//! dropped). Measured from the stamp, the delay includes the transport's own latency, which a
//! slower delivery can only exceed: a state is never used earlier than the link allows, and its
//! age at use is at least the delay. Between deliveries the follower extrapolates from the
//! newest state it has (`realtime.rs`), the same policy as for a state that simply came late.

use std::collections::VecDeque;

use cdm_model::dynamics::Flat;
use cdm_model::link::LinkModel;

/// A received state not yet usable.
#[derive(Debug, Clone, Copy)]
struct Held {
    tick: u64,
    flat: Flat,
    delay_s: f64,
}

/// One follower's incoming links: what arrived, held back until its delay has passed.
#[derive(Debug, Clone)]
pub struct DelayLine {
    model: LinkModel,
    /// False for perfect links: every state is usable as it arrives.
    impaired: bool,
    to: u32,
    from: [u32; 3],
    held: [VecDeque<Held>; 3],
    received: u64,
    lost: u64,
}

impl DelayLine {
    /// The links `from[slot] -> to` of `model`. Any impairment counts, even a delay under half a
    /// tick (lockstep rounds that away; real time does not).
    pub fn new(model: LinkModel, to: u32, from: [u32; 3]) -> Self {
        Self {
            impaired: !model.spec().is_perfect(),
            model,
            to,
            from,
            held: Default::default(),
            received: 0,
            lost: 0,
        }
    }

    /// The state of in-neighbour `slot` sampled at its tick `tick`, just received: returned when
    /// it is usable at once (perfect links), else held back or, when the link loses it, dropped.
    pub fn receive(&mut self, slot: usize, tick: u64, flat: Flat) -> Option<(u64, Flat)> {
        self.received += 1;
        if !self.impaired {
            return Some((tick, flat));
        }
        match self.model.delay_ms(self.from[slot], self.to, tick) {
            None => self.lost += 1,
            Some(ms) => self.held[slot].push_back(Held {
                tick,
                flat,
                delay_s: ms * 1e-3,
            }),
        }
        None
    }

    /// Hands `deliver(slot, tick, flat)` every held state whose delay has passed at the
    /// receiver's own time `t_s` (`stamp(slot, tick)`: the sender's time of that tick); the
    /// others stay held. Jitter may release them out of order: the caller keeps the newest.
    pub fn release(
        &mut self,
        t_s: f64,
        stamp: impl Fn(usize, u64) -> f64,
        mut deliver: impl FnMut(usize, u64, Flat),
    ) {
        for (slot, q) in self.held.iter_mut().enumerate() {
            q.retain(|h| {
                let due = stamp(slot, h.tick) + h.delay_s <= t_s;
                if due {
                    deliver(slot, h.tick, h.flat);
                }
                !due
            });
        }
    }

    /// The links now come from `from` (a repair after a loss): the states held back for the
    /// in-neighbours kept move to their new slots, those of the dropped ones are forgotten.
    pub fn relink(&mut self, from: [u32; 3]) {
        let mut held: [VecDeque<Held>; 3] = Default::default();
        for (slot, j) in from.iter().enumerate() {
            if let Some(k) = self.from.iter().position(|o| o == j) {
                held[slot] = std::mem::take(&mut self.held[k]);
            }
        }
        self.held = held;
        self.from = from;
    }

    /// True when the state of in-neighbour `from` sampled at its tick `tick` (stamped
    /// `stamp_s`) is usable at the receiver's own time `t_s`: the link does not lose it and its
    /// delay has passed (always, over perfect links).
    pub fn delivered_by(&self, from: u32, tick: u64, stamp_s: f64, t_s: f64) -> bool {
        if !self.impaired {
            return true;
        }
        self.model
            .delay_ms(from, self.to, tick)
            .is_some_and(|ms| stamp_s + ms * 1e-3 <= t_s)
    }

    /// States received, and how many of them the links lost.
    pub fn counts(&self) -> (u64, u64) {
        (self.received, self.lost)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_math::Vec3;
    use cdm_model::link::LinkSpec;

    const DT: f64 = 0.01;

    fn line(delay_ms: f64, jitter_ms: f64, loss: f64) -> DelayLine {
        let spec = LinkSpec {
            delay_ms,
            jitter_ms,
            loss,
            seed: 3,
        };
        DelayLine::new(LinkModel::new(spec, DT), 10, [1, 2, 3])
    }

    fn at(tick: u64) -> Flat {
        Flat::rest(Vec3::new(tick as f64, 0.0, 0.0))
    }

    /// Releases at `t_s` with every neighbour at phase 0; the (slot, tick) pairs released.
    fn released(l: &mut DelayLine, t_s: f64) -> Vec<(usize, u64)> {
        let mut out = Vec::new();
        l.release(t_s, |_, tick| tick as f64 * DT, |s, t, _| out.push((s, t)));
        out
    }

    #[test]
    fn perfect_links_deliver_at_once() {
        let mut l = line(0.0, 0.0, 0.0);
        assert_eq!(l.receive(1, 7, at(7)), Some((7, at(7))));
        assert!(released(&mut l, 1e9).is_empty());
        assert_eq!(l.counts(), (1, 0));
    }

    #[test]
    fn a_state_is_held_until_its_stamp_plus_the_delay_in_unrounded_milliseconds() {
        // 4 ms: lockstep rounds it to no delay at 100 Hz; real time holds it 4 ms.
        let mut l = line(4.0, 0.0, 0.0);
        assert_eq!(l.receive(0, 10, at(10)), None);
        assert!(released(&mut l, 0.1 + 0.0039).is_empty());
        assert_eq!(released(&mut l, 0.1 + 0.0041), vec![(0, 10)]);
        assert!(released(&mut l, 1.0).is_empty(), "released once");
    }

    #[test]
    fn jitter_and_loss_follow_the_lockstep_draws_of_each_link_and_tick() {
        let spec = LinkSpec {
            delay_ms: 20.0,
            jitter_ms: 30.0,
            loss: 0.2,
            seed: 3,
        };
        let model = LinkModel::new(spec, DT);
        let mut l = line(20.0, 30.0, 0.2);
        for tick in 0..500 {
            for slot in 0..3 {
                assert_eq!(l.receive(slot, tick, at(tick)), None);
            }
        }
        let (received, lost) = l.counts();
        assert_eq!(received, 1500);
        let expected_lost = (0..500)
            .flat_map(|t| [1, 2, 3].map(|j| model.delay_ms(j, 10, t)))
            .filter(Option::is_none)
            .count() as u64;
        assert_eq!(lost, expected_lost);
        assert!((200..400).contains(&lost), "about 20 % of 1500: {lost}");
        // Every kept state comes out in the period its own draw says, not before.
        let mut out = 0;
        for step in 0..600 {
            let t = step as f64 * DT;
            for (slot, k) in released(&mut l, t) {
                let ms = model.delay_ms(slot as u32 + 1, 10, k).expect("not lost");
                let due = k as f64 * DT + ms * 1e-3;
                assert!(
                    due <= t && due > t - DT - 1e-12,
                    "tick {k}: due {due} at {t}"
                );
                out += 1;
            }
        }
        assert_eq!(out, received - lost, "every kept state is released once");
    }
}
