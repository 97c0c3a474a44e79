//! When a relay hands its history to a repair's new readers.
//!
//! A member hands over at once: its ring holds what it published. A relay standing in for a
//! member of another host publishes what crosses, in order, and the writer's own repeats cross
//! only after the notice that made it send them, so at the notice the relay's ring may lack the
//! states a new reader needs (a writer whose states did not cross before: the ring is empty).
//! Handing over then sends too little, and the reader, holding back its new in-neighbour's
//! states until repeats arrive (cdm-iox `resend.rs`), waits for ever. So each relay hands over
//! once its history reaches the repair's tick, or after [`HAND_OVER_WAIT`] whatever it holds.
//! The caller's clock says when: every call is handed its `now`.

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use crate::relay::Relay;

/// The longest a relay's hand-over waits for its history to reach the repair's tick.
pub const HAND_OVER_WAIT: Duration = Duration::from_secs(1);

/// The relays still to hand over after a repair connected.
#[derive(Debug)]
pub struct PendingHandOver {
    needs_from: u64,
    since: Instant,
    left: BTreeSet<u32>,
}

impl PendingHandOver {
    /// Every relay in `relays` is to hand over the states from `needs_from` on.
    pub fn new<R>(needs_from: u64, relays: &BTreeMap<u32, R>, now: Instant) -> Self {
        PendingHandOver {
            needs_from,
            since: now,
            left: relays.keys().copied().collect(),
        }
    }

    /// Hands over every relay whose history reaches the tick (all of them once `wait` passed
    /// at `now`); true when none is left. `failed` hears of a relay that could not.
    pub fn poll<R: Relay>(
        &mut self,
        relays: &mut BTreeMap<u32, R>,
        wait: Duration,
        now: Instant,
        mut failed: impl FnMut(u32, String),
    ) -> bool {
        let late = now.saturating_duration_since(self.since) >= wait;
        self.left.retain(|id| {
            let Some(relay) = relays.get_mut(id) else {
                return false;
            };
            if !late && !relay.history_reaches(self.needs_from) {
                return true;
            }
            if let Err(e) = relay.hand_over() {
                failed(*id, e.to_string());
            }
            false
        });
        self.left.is_empty()
    }
}

/// Starts a hand-over (the one before, if any is still pending, goes at once) and moves it on.
pub fn start<R: Relay>(
    pending: &mut Option<PendingHandOver>,
    needs_from: u64,
    relays: &mut BTreeMap<u32, R>,
    now: Instant,
    failed: impl FnMut(u32, String) + Copy,
) {
    if let Some(mut before) = pending.take() {
        before.poll(relays, Duration::ZERO, now, failed);
    }
    let mut next = PendingHandOver::new(needs_from, relays, now);
    if !next.poll(relays, HAND_OVER_WAIT, now, failed) {
        *pending = Some(next);
    }
}

/// Moves a pending hand-over on (`wait`: how long a relay may wait for its history).
pub fn poll<R: Relay>(
    pending: &mut Option<PendingHandOver>,
    relays: &mut BTreeMap<u32, R>,
    wait: Duration,
    now: Instant,
    failed: impl FnMut(u32, String),
) {
    if let Some(p) = pending {
        if p.poll(relays, wait, now, failed) {
            *pending = None;
        }
    }
}

/// What a relay that cannot hand over leaves: a warning (the new reader's silence deadline
/// names the link if it then lacks states).
pub fn warn_hand_over(id: u32, e: String) {
    tracing::warn!(
        id,
        "the relay of agent {id} cannot hand over its history: {e}"
    );
}
