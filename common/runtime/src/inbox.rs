//! One in-neighbour's states not yet used, by tick (ascending).

use std::collections::VecDeque;

use cdm_model::dynamics::Flat;

/// A neighbour publishes its ticks in order, so states are appended and taken from the front: no
/// allocation per tick (a `BTreeMap` here took a sixth of a member's time at N = 40).
#[derive(Debug, Default)]
pub struct Inbox(VecDeque<(u64, Flat)>);

impl Inbox {
    /// Stores `tick`'s state; a repeated tick replaces the earlier one.
    pub fn insert(&mut self, tick: u64, f: Flat) {
        match self.0.back() {
            Some(&(last, _)) if last >= tick => match self.0.binary_search_by_key(&tick, |e| e.0) {
                Ok(k) => self.0[k].1 = f,
                Err(k) => self.0.insert(k, (tick, f)),
            },
            _ => self.0.push_back((tick, f)),
        }
    }

    /// The state of `tick`, if it arrived.
    pub fn get(&self, tick: u64) -> Option<&Flat> {
        // Used ticks are dropped, so the wanted one is (nearly always) at the front.
        self.0
            .iter()
            .find(|e| e.0 >= tick)
            .filter(|e| e.0 == tick)
            .map(|e| &e.1)
    }

    /// The states of ticks up to `tick`, oldest first.
    pub fn upto(&self, tick: u64) -> impl Iterator<Item = (u64, Flat)> + '_ {
        self.0.iter().take_while(move |e| e.0 <= tick).copied()
    }

    /// The newest tick held.
    pub fn last_tick(&self) -> Option<u64> {
        self.0.back().map(|e| e.0)
    }

    /// The oldest tick held.
    pub fn first_tick(&self) -> Option<u64> {
        self.0.front().map(|e| e.0)
    }

    /// Adds `other`'s states (a repeated tick replaces the one held).
    pub fn merge(&mut self, other: Inbox) {
        for (t, f) in other.0 {
            self.insert(t, f);
        }
    }

    /// Forgets every tick before `tick`.
    pub fn drop_before(&mut self, tick: u64) {
        while self.0.front().is_some_and(|e| e.0 < tick) {
            self.0.pop_front();
        }
    }
}
