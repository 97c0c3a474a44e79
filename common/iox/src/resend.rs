//! What a repair's new reader gets of the states published before it subscribed.
//!
//! iceoryx2's own answer is a service history: the publisher keeps its last H samples and hands
//! them to every new subscriber. But a publisher then cycles through at least H + 1 chunks, and
//! every reader touches each of them: with several states per sample (a [`StateBatch`] of 520
//! bytes) that was 0.4-0.6 MiB more resident memory per member at N = 250 (BENCHMARKS.md, issue
//! 17), over the 8 MiB a member may take. So the state services keep no history; each member
//! keeps its last H states in a ring of plain memory (H x 128 bytes) and sends them again at a
//! hand-over. Every reader then gets them, the old ones too: a state is fully named by its
//! member and tick, so a repeated one changes nothing (the member's inbox replaces it with the
//! same bits or drops it as past; the orchestrator books a tick's state once and ignores past
//! ticks), and the subscribers' buffers have [`resend_room`] samples more so that the repeats
//! never push out a state not yet read. A new reader may get the publisher's next states before
//! the repeats (a publisher connects new subscribers at its next send): it holds those back
//! until the repeats ([`StateBatch::RESENT`]) arrive, so it sees its new in-neighbour's states in
//! order, as from a history ([`Held`]).

use std::collections::VecDeque;

use crate::messages::StateMsg;
use crate::wire::{StateBatch, STATES_PER_SAMPLE};

/// The state-service attribute that carries H, the states a member sends again at a hand-over
/// (absent or 0: none, the team has no repairs).
pub const RESEND_STATES_KEY: &str = "cdm.resend_states";

/// Extra subscriber buffer (in samples) for one hand-over's repeated states: `states` states
/// travel in full batches, plus the batch pending before them.
pub fn resend_room(states: usize) -> usize {
    match states {
        0 => 0,
        s => s.div_ceil(STATES_PER_SAMPLE) + 1,
    }
}

/// A member's last `capacity` published states, oldest first.
#[derive(Debug, Default)]
pub(crate) struct Recent {
    states: VecDeque<StateMsg>,
    capacity: usize,
}

impl Recent {
    /// A ring of `capacity` states (0: keeps nothing).
    pub(crate) fn new(capacity: usize) -> Self {
        Recent {
            states: VecDeque::with_capacity(capacity),
            capacity,
        }
    }

    /// Keeps `msg`, forgetting the oldest state when full.
    pub(crate) fn push(&mut self, msg: StateMsg) {
        if self.capacity == 0 {
            return;
        }
        if self.states.len() == self.capacity {
            self.states.pop_front();
        }
        self.states.push_back(msg);
    }

    /// True when the kept states go back, without a gap, from the newest to a state of `tick`
    /// or earlier. A relay forwards another host's states in order; its history reaches a
    /// repair's tick only once the writer's own repeats have crossed.
    pub(crate) fn reaches(&self, tick: u64) -> bool {
        let mut oldest: Option<u64> = None;
        for m in self.states.iter().rev() {
            if oldest.is_some_and(|o| m.tick + 1 < o) {
                return false;
            }
            if m.tick <= tick {
                return true;
            }
            oldest = Some(oldest.map_or(m.tick, |o| o.min(m.tick)));
        }
        false
    }

    /// The kept states cut into batches, oldest first.
    pub(crate) fn batches(&self) -> impl Iterator<Item = StateBatch> + '_ {
        let (a, b) = self.states.as_slices();
        let mut batch = StateBatch {
            flags: StateBatch::RESENT,
            ..StateBatch::EMPTY
        };
        let mut it = a.iter().chain(b).peekable();
        std::iter::from_fn(move || {
            batch.clear();
            while let Some(m) = it.next() {
                if batch.push(*m) {
                    return Some(batch);
                }
                if it.peek().is_none() {
                    return Some(batch);
                }
            }
            None
        })
    }
}

/// A new reader's states of one in-neighbour, held back until that neighbour's repeats arrive.
#[derive(Debug, Default)]
pub(crate) struct Held(Option<Vec<StateMsg>>);

impl Held {
    /// Holds back everything until a [`StateBatch::RESENT`] batch arrives.
    pub(crate) fn until_resent() -> Self {
        Held(Some(Vec::new()))
    }

    /// Takes one received batch: hands `f` what may be delivered now, in order.
    pub(crate) fn take(&mut self, batch: &StateBatch, mut f: impl FnMut(StateMsg)) -> usize {
        let states = batch.states();
        match &mut self.0 {
            None => {
                states.iter().for_each(|m| f(*m));
                states.len()
            }
            Some(held) if batch.flags == StateBatch::RESENT => {
                let n = states.len() + held.len();
                states.iter().chain(held.iter()).for_each(|m| f(*m));
                self.0 = None;
                n
            }
            Some(held) => {
                held.extend_from_slice(states);
                0
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ring_keeps_the_newest_states_and_cuts_them_in_order() {
        let state = |tick| StateMsg::ok(tick, 1, 7, [tick as f64; 12]);
        let mut r = Recent::new(10);
        for tick in 0..13 {
            r.push(state(tick));
        }
        let got: Vec<Vec<u64>> = r
            .batches()
            .map(|b| b.states().iter().map(|m| m.tick).collect())
            .collect();
        let want: Vec<u64> = (3..13).collect();
        assert_eq!(got.concat(), want);
        assert!(got
            .iter()
            .all(|b| !b.is_empty() && b.len() <= STATES_PER_SAMPLE));
        assert_eq!(got.len(), 10usize.div_ceil(STATES_PER_SAMPLE));
        assert!(got.len() < resend_room(10));
        assert_eq!(Recent::new(0).batches().count(), 0);
        let mut none = Recent::new(0);
        none.push(state(1));
        assert_eq!(none.batches().count(), 0);
        assert_eq!(resend_room(0), 0);
        let mut r = Recent::new(3);
        r.push(state(5));
        assert!(r.batches().all(|b| b.flags == StateBatch::RESENT));
    }

    #[test]
    fn the_history_reaches_a_tick_only_without_a_gap() {
        let state = |tick| StateMsg::ok(tick, 1, 7, [tick as f64; 12]);
        let mut r = Recent::new(64);
        assert!(!r.reaches(5));
        for tick in [20, 21, 22] {
            r.push(state(tick));
        }
        assert!(r.reaches(20) && r.reaches(30) && !r.reaches(19));
        // The writer's repeats cross after its newest states: the history then reaches back.
        for tick in 10..=22 {
            r.push(state(tick));
        }
        assert!(r.reaches(10) && !r.reaches(9));
        let mut gap = Recent::new(64);
        for tick in [10, 11, 15, 16] {
            gap.push(state(tick));
        }
        assert!(gap.reaches(15) && !gap.reaches(11));
    }

    #[test]
    fn a_new_reader_holds_back_what_comes_before_the_repeats() {
        let state = |tick| StateMsg::ok(tick, 1, 7, [tick as f64; 12]);
        let batch = |ticks: &[u64], flags| {
            let mut b = StateBatch {
                flags,
                ..StateBatch::EMPTY
            };
            ticks.iter().for_each(|&t| {
                b.push(state(t));
            });
            b
        };
        let mut got = vec![];
        let mut h = Held::until_resent();
        assert_eq!(h.take(&batch(&[12, 13], 0), |m| got.push(m.tick)), 0);
        assert!(got.is_empty());
        let n = h.take(&batch(&[10, 11, 12], StateBatch::RESENT), |m| {
            got.push(m.tick)
        });
        assert_eq!((n, got.clone()), (5, vec![10, 11, 12, 12, 13]));
        // Once the repeats came, everything passes at once (a later repeat too).
        h.take(&batch(&[14], 0), |m| got.push(m.tick));
        h.take(&batch(&[13, 14], StateBatch::RESENT), |m| got.push(m.tick));
        assert_eq!(got[5..], [14, 13, 14]);
        let mut plain = Held::default();
        assert_eq!(plain.take(&batch(&[1], 0), |_| {}), 1);
    }
}
