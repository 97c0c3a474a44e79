//! Which members' state subscribers the orchestrator reads after a wake-up, in lockstep.
//!
//! Every member wakes `wake/orch` with its own event id (its id + 1) when it goes to sleep, and
//! it sends its states before that (`MemberPorts::notify_readers`). The orchestrator therefore
//! reads only the members that woke it, instead of polling every subscriber each time it wakes:
//! at N = 1000 that poll of 1,000 subscribers was 42 % of the orchestrator's CPU (perf, issue
//! 28). Event id 0 (a notifier without an id: a relay, another tool) and [`FULL_SWEEP`] bring
//! back a read of every subscriber, so a state sent without its notification is still read
//! within that time. What is read is the same either way; only when it is read changes, and the
//! team core books states by tick and member whatever their order.

use std::time::{Duration, Instant};

/// At least this often every subscriber is read, whatever woke the orchestrator.
pub(crate) const FULL_SWEEP: Duration = Duration::from_millis(250);

/// The event id with which member `id` wakes the orchestrator, given the service's largest
/// (`max`): 0 (read everyone) when `id + 1` does not fit.
pub(crate) fn event_id_of(id: u32, max: usize) -> usize {
    match usize::try_from(id).ok().and_then(|i| i.checked_add(1)) {
        Some(e) if e <= max => e,
        _ => 0,
    }
}

/// The largest event id `wake/orch` needs for members `ids` (0 when the largest id would make
/// the event's bit set larger than [`MAX_EVENT_ID`]: every member then wakes with id 0).
pub(crate) fn max_event_id(ids: &[u32]) -> usize {
    let max = ids.iter().max().map_or(0, |&m| m as usize + 1);
    if max > MAX_EVENT_ID {
        0
    } else {
        max
    }
}

/// Larger member ids wake the orchestrator without their id (the event's bit set is sized by
/// the largest id).
pub(crate) const MAX_EVENT_ID: usize = 1 << 16;

/// The members that woke the orchestrator since its last read.
#[derive(Debug)]
pub(crate) struct Notified {
    ids: Vec<u32>,
    everyone: bool,
    last_full: Instant,
}

/// What to read now.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum Sweep<'a> {
    /// Every subscriber.
    All,
    /// These members' subscribers (sorted, once each).
    Only(&'a [u32]),
}

impl Notified {
    /// The first read reads everyone.
    pub(crate) fn new(now: Instant) -> Self {
        Notified {
            ids: Vec::new(),
            everyone: true,
            last_full: now,
        }
    }

    /// An event id that woke the orchestrator.
    pub(crate) fn note(&mut self, event: usize) {
        match event.checked_sub(1).and_then(|i| u32::try_from(i).ok()) {
            Some(id) if !self.everyone => self.ids.push(id),
            Some(_) => {}
            None => self.everyone = true,
        }
    }

    /// What to read at `now`; call [`Self::read`] once it is read.
    pub(crate) fn sweep(&mut self, now: Instant) -> Sweep<'_> {
        if self.everyone || now.saturating_duration_since(self.last_full) >= FULL_SWEEP {
            return Sweep::All;
        }
        self.ids.sort_unstable();
        self.ids.dedup();
        Sweep::Only(&self.ids)
    }

    /// The read of [`Self::sweep`] at `now` is done.
    pub(crate) fn read(&mut self, all: bool, now: Instant) {
        self.ids.clear();
        if all {
            self.everyone = false;
            self.last_full = now;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_who_woke_it_and_everyone_at_first_on_id_zero_and_every_full_sweep() {
        let t0 = Instant::now();
        let mut n = Notified::new(t0);
        assert_eq!(n.sweep(t0), Sweep::All);
        n.read(true, t0);
        assert_eq!(n.sweep(t0), Sweep::Only(&[]));
        for e in [8, 3, 8, 1] {
            n.note(e);
        }
        assert_eq!(n.sweep(t0), Sweep::Only(&[0, 2, 7]));
        n.read(false, t0);
        assert_eq!(n.sweep(t0), Sweep::Only(&[]));
        n.note(5);
        n.note(0);
        assert_eq!(n.sweep(t0), Sweep::All);
        n.read(true, t0);
        n.note(5);
        assert_eq!(n.sweep(t0 + FULL_SWEEP), Sweep::All);
        n.read(true, t0 + FULL_SWEEP);
        assert_eq!(n.sweep(t0 + FULL_SWEEP), Sweep::Only(&[]));
    }

    #[test]
    fn event_ids_fit_the_service_or_fall_back_to_zero() {
        assert_eq!(max_event_id(&[1, 1000, 7]), 1001);
        assert_eq!(max_event_id(&[]), 0);
        assert_eq!(max_event_id(&[u32::MAX]), 0);
        assert_eq!(event_id_of(1000, 1001), 1001);
        assert_eq!(event_id_of(0, 1001), 1);
        assert_eq!(event_id_of(1001, 1001), 0);
        assert_eq!(event_id_of(u32::MAX, 0), 0);
    }
}
