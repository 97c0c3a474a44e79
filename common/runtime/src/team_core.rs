//! The orchestrator's protocol decisions as pure functions and plain types: how far to grant,
//! and which fault report names the root cause. The orchestrator's loop (`launch`) does the I/O
//! around them.

/// The first grant: a window of ticks (0..window), at most the last tick.
pub fn first_grant(window: u64, last: u64) -> u64 {
    (window.max(1) - 1).min(last)
}

/// The grant to send once ticks before `complete` are complete, or `None` to keep `grant`.
/// Members may run up to a window ahead; grants go out in steps of half a window (at least 1):
/// every grant wakes every member, so fewer, larger grants mean fewer wake-ups per tick. The
/// last tick is always granted.
pub fn next_grant(complete: u64, grant: u64, window: u64, last: u64) -> Option<u64> {
    let window = window.max(1);
    let want = (complete + window - 1).min(last);
    let step = (window / 2).max(1);
    (want > grant && (want >= grant + step || want == last)).then_some(want)
}

/// Where a fault report stands among the reports of a run: the root cause wins over an echo (a
/// member stopping because its neighbour reported a fault), then the earliest tick, then the
/// first member in formation order, as the engine stops at the first member that fails at the
/// first failing tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct FaultRank {
    /// True for an echo (`FaultCode::NeighborFault`).
    pub echo: bool,
    /// The tick of the report.
    pub tick: u64,
    /// The reporter's index in the formation (`usize::MAX` for a fault the orchestrator found).
    pub member: usize,
}

impl FaultRank {
    /// True when this report names the root cause better than `current` (or there is none).
    pub fn outranks(&self, current: Option<&FaultRank>) -> bool {
        current.is_none_or(|c| self < c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grant_window_grants_half_windows_and_always_the_last_tick() {
        assert_eq!(first_grant(4, 100), 3);
        assert_eq!(first_grant(1, 100), 0);
        assert_eq!(first_grant(8, 2), 2);
        // Window 4: from grant 3, tick 0 complete wants 4, a step of 2 is not reached yet.
        assert_eq!(next_grant(1, 3, 4, 100), None);
        assert_eq!(next_grant(2, 3, 4, 100), Some(5));
        // Window 1 is lockstep: every completed tick grants the next.
        assert_eq!(next_grant(1, 0, 1, 100), Some(1));
        assert_eq!(next_grant(1, 1, 1, 100), None);
        // The last tick is granted even when it is less than a step away.
        assert_eq!(next_grant(98, 99, 4, 100), Some(100));
        assert_eq!(next_grant(100, 100, 4, 100), None);
    }

    #[test]
    fn fault_ranking_puts_the_root_cause_over_its_echo() {
        let root = FaultRank {
            echo: false,
            tick: 7,
            member: 30,
        };
        let echo = FaultRank {
            echo: true,
            tick: 6,
            member: 2,
        };
        assert!(
            root.outranks(Some(&echo)),
            "an earlier echo hid the root cause"
        );
        assert!(!echo.outranks(Some(&root)));
        let earlier = FaultRank {
            echo: false,
            tick: 6,
            member: 31,
        };
        assert!(earlier.outranks(Some(&root)), "the earliest tick wins");
        let first = FaultRank {
            echo: false,
            tick: 7,
            member: 3,
        };
        assert!(first.outranks(Some(&root)), "then formation order");
        assert!(!root.outranks(Some(&root)), "a repeat is not better");
        assert!(echo.outranks(None));
    }
}
