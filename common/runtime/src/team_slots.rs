//! The team core's per-tick data structures (and the real-time monitor's id lookup), built for
//! the orchestrator's hot path: every member's state of every tick passes through them (N = 40:
//! 800,000 states in a full plan).
//! A profile of `launch --n 40` put the `BTreeMap`s they replace at about 5 % of the
//! orchestrator; these are a `Vec` indexed by member id and a ring of tick slots.

use std::collections::VecDeque;

/// Member id -> formation index. Ids are dense (0..N or 1..=N in every built-in and generated
/// scenario), so a table indexed by id; a scenario with far-apart ids falls back to a sorted
/// list searched by halves (the table would be mostly empty).
#[derive(Debug, Clone)]
pub enum IdIndex {
    /// `table[id]` is the index, or `usize::MAX` for no member.
    Dense(Vec<usize>),
    /// (id, index) sorted by id.
    Sorted(Vec<(u32, usize)>),
}

impl IdIndex {
    /// The index of `ids` (formation order; ids unique).
    pub fn new(ids: &[u32]) -> Self {
        let max = ids.iter().copied().max().map_or(0, |m| m as usize);
        if max <= 4 * ids.len() + 64 {
            let mut table = vec![usize::MAX; max + 1];
            for (k, &id) in ids.iter().enumerate() {
                table[id as usize] = k;
            }
            IdIndex::Dense(table)
        } else {
            let mut sorted: Vec<(u32, usize)> =
                ids.iter().enumerate().map(|(k, &id)| (id, k)).collect();
            sorted.sort_unstable();
            IdIndex::Sorted(sorted)
        }
    }

    /// The formation index of member `id`, if it is one.
    pub fn get(&self, id: u32) -> Option<usize> {
        match self {
            IdIndex::Dense(t) => t.get(id as usize).copied().filter(|&k| k != usize::MAX),
            IdIndex::Sorted(s) => s
                .binary_search_by_key(&id, |&(i, _)| i)
                .ok()
                .map(|p| s[p].1),
        }
    }
}

/// Slots of consecutive ticks from `base` on (the next tick to hand out): slot `tick - base`.
/// Ticks before `base` are gone; a tick far ahead grows the ring (the granted window bounds it).
#[derive(Debug)]
pub struct TickSlots<T> {
    base: u64,
    slots: VecDeque<Option<T>>,
}

impl<T> TickSlots<T> {
    /// Empty, starting at tick 0.
    pub fn new() -> Self {
        TickSlots {
            base: 0,
            slots: VecDeque::new(),
        }
    }

    /// The slot of `tick`, if it holds one.
    pub fn get(&self, tick: u64) -> Option<&T> {
        let i = usize::try_from(tick.checked_sub(self.base)?).ok()?;
        self.slots.get(i)?.as_ref()
    }

    /// The slot of `tick` (at or after `base`), made by `make` when empty.
    pub fn get_or_insert_with(&mut self, tick: u64, make: impl FnOnce() -> T) -> Option<&mut T> {
        let i = usize::try_from(tick.checked_sub(self.base)?).ok()?;
        if i >= self.slots.len() {
            self.slots.resize_with(i + 1, || None);
        }
        Some(self.slots[i].get_or_insert_with(make))
    }

    /// Takes the slot of `base`'s tick and moves on to the next tick; `None` (and no move) when
    /// `tick` is not `base` or its slot is empty.
    pub fn take_first(&mut self, tick: u64) -> Option<T> {
        if tick != self.base || self.slots.front().is_none_or(Option::is_none) {
            return None;
        }
        self.base += 1;
        self.slots.pop_front().flatten()
    }
}

impl<T> Default for TickSlots<T> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_find_their_index_dense_or_sparse() {
        for ids in [vec![3, 0, 2, 1], vec![7, 1_000_000, 42, u32::MAX]] {
            let index = IdIndex::new(&ids);
            for (k, &id) in ids.iter().enumerate() {
                assert_eq!(index.get(id), Some(k), "{ids:?}");
            }
            assert_eq!(index.get(5), None);
            assert_eq!(index.get(u32::MAX - 1), None);
        }
        assert!(matches!(IdIndex::new(&[3, 0, 2, 1]), IdIndex::Dense(_)));
        assert!(matches!(IdIndex::new(&[7, 1_000_000]), IdIndex::Sorted(_)));
        assert_eq!(IdIndex::new(&[]).get(0), None);
    }

    #[test]
    fn tick_slots_fill_out_of_order_and_hand_out_in_order() {
        let mut s = TickSlots::new();
        *s.get_or_insert_with(2, || 0).unwrap() += 20;
        *s.get_or_insert_with(0, || 0).unwrap() += 1;
        assert_eq!(s.get(1), None);
        assert_eq!(s.take_first(1), None, "not the first tick");
        assert_eq!(s.take_first(0), Some(1));
        assert_eq!(s.take_first(1), None, "tick 1 has no slot: no move");
        *s.get_or_insert_with(1, || 5).unwrap() += 5;
        assert_eq!(s.get(1), Some(&10));
        assert_eq!(
            s.get_or_insert_with(0, || 9),
            None,
            "a tick already handed out"
        );
        assert_eq!(s.take_first(1), Some(10));
        assert_eq!(s.take_first(2), Some(20));
        assert_eq!(s.get(2), None);
    }
}
