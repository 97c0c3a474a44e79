//! How long a bridge sleeps when nothing moved (pure; no I/O).
//!
//! A bridge waits on its zenoh queue, so a frame from the network wakes it at once; what it
//! cannot wait on in the same call is its own host's shared memory (a member's state, the
//! clock), which it polls. Right after traffic the next local event is microseconds away (a
//! lockstep team), so the first sleeps are short; while nothing moves they double up to a cap,
//! so an idle team costs a few hundred wake-ups a second instead of thousands. In real time a
//! state waiting in shared memory ages by the sleep (readers extrapolate it by its stamp, but the
//! newest is the best), so a real-time team's bridges cap the sleep at [`REALTIME_MAX_IDLE`].

use std::time::Duration;

/// The sleep after the first idle round.
pub const FIRST_IDLE: Duration = Duration::from_micros(500);
/// The longest sleep: the most a local event can wait after a long quiet spell.
pub const MAX_IDLE: Duration = Duration::from_millis(8);
/// The longest sleep of a real-time team's bridge: a tenth of a 100 Hz period.
pub const REALTIME_MAX_IDLE: Duration = Duration::from_millis(1);

/// The idle sleep of a polling loop: doubles while idle, back to [`FIRST_IDLE`] on traffic.
#[derive(Debug, Clone)]
pub struct IdleBackoff {
    next: Duration,
    max: Duration,
}

impl Default for IdleBackoff {
    fn default() -> Self {
        Self::up_to(MAX_IDLE)
    }
}

impl IdleBackoff {
    /// A backoff whose sleeps stop doubling at `max` (at least [`FIRST_IDLE`]).
    pub fn up_to(max: Duration) -> Self {
        Self {
            next: FIRST_IDLE,
            max: max.max(FIRST_IDLE),
        }
    }

    /// The backoff of a team's bridge: capped at [`REALTIME_MAX_IDLE`] in real time.
    pub fn for_team(realtime: bool) -> Self {
        Self::up_to(if realtime {
            REALTIME_MAX_IDLE
        } else {
            MAX_IDLE
        })
    }

    /// After a round: `None` when it moved something (go on at once), else how long to sleep.
    pub fn after(&mut self, busy: bool) -> Option<Duration> {
        if busy {
            self.next = FIRST_IDLE;
            return None;
        }
        let sleep = self.next;
        self.next = (self.next * 2).min(self.max);
        Some(sleep)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn idle_sleeps_double_to_the_cap_and_traffic_resets_them() {
        let mut b = IdleBackoff::default();
        let sleeps: Vec<Duration> = (0..8).filter_map(|_| b.after(false)).collect();
        assert_eq!(sleeps[0], FIRST_IDLE);
        assert_eq!(sleeps[1], FIRST_IDLE * 2);
        assert!(sleeps.windows(2).all(|w| w[1] >= w[0]));
        assert_eq!(*sleeps.last().unwrap(), MAX_IDLE);
        assert_eq!(b.after(true), None);
        assert_eq!(b.after(false), Some(FIRST_IDLE));
    }

    #[test]
    fn a_real_time_bridge_sleeps_at_most_its_cap() {
        let mut b = IdleBackoff::for_team(true);
        let longest = (0..20).filter_map(|_| b.after(false)).max();
        assert_eq!(longest, Some(REALTIME_MAX_IDLE));
        let mut b = IdleBackoff::up_to(Duration::ZERO);
        assert_eq!(b.after(false), Some(FIRST_IDLE));
        assert_eq!(b.after(false), Some(FIRST_IDLE));
    }
}
