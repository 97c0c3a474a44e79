//! Noticing that the orchestrator itself stalled (SIGSTOP, a debugger, a starved machine), so
//! that what follows is blamed on the clock and not on its members. The clock's loop wakes at
//! least every 20 ms; a much longer gap between two turns means the process did not run. Its
//! members then see no grant for their silence timeout (10 s by default) and stop by
//! themselves: their exits, or their silence, are consequences of the stall, not its cause.
//! Pure logic: the caller passes "now" (time since its clock started); part of the team core.

use std::time::Duration;

use cdm_model::outcome::FaultKind;
use cdm_records::audit::FaultRecord;

/// A gap between two turns of the loop that counts as a stall of the orchestrator itself.
pub const STALL_MIN: Duration = Duration::from_secs(2);

/// How long after a stall a member's exit or silence is blamed on the stall: the members'
/// default silence timeout (10 s) plus room for them to exit and be noticed.
pub const BLAME_WINDOW: Duration = Duration::from_secs(15);

/// The longest stall seen so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Stall {
    gap: Duration,
    tick: u64,
    ended: Duration,
}

/// Watches the gaps between the turns of the clock's loop.
#[derive(Debug)]
pub struct StallWatch {
    last_turn: Duration,
    stall: Option<Stall>,
}

impl StallWatch {
    /// Starts watching at `now`.
    pub fn new(now: Duration) -> Self {
        Self {
            last_turn: now,
            stall: None,
        }
    }

    /// One turn of the loop at `now`, waiting for `tick`; true when the loop had stalled just
    /// before (the caller restarts the timeouts it keeps for its members).
    pub fn turn(&mut self, now: Duration, tick: u64) -> bool {
        let gap = now.saturating_sub(self.last_turn);
        self.last_turn = now;
        if gap < STALL_MIN {
            return false;
        }
        if self
            .stall
            .is_none_or(|s| gap >= s.gap || now > s.ended + BLAME_WINDOW)
        {
            self.stall = Some(Stall {
                gap,
                tick,
                ended: now,
            });
        }
        true
    }

    /// True when a stall ended less than [`BLAME_WINDOW`] before `now`: a member's exit or
    /// silence then is the stall's consequence (a fault), not a loss to repair.
    pub fn blames(&self, now: Duration) -> bool {
        self.stall
            .is_some_and(|s| now.saturating_sub(s.ended) <= BLAME_WINDOW)
    }

    /// The fault to record for a member `fault` found at `now`: an `orchestrator-stalled` record
    /// naming the stall (and keeping the member's own message and tick) when a stall ended less than
    /// [`BLAME_WINDOW`] before; `fault` itself otherwise.
    pub fn explain(&self, fault: FaultRecord, now: Duration) -> FaultRecord {
        match self.stall {
            Some(s) if now.saturating_sub(s.ended) <= BLAME_WINDOW => FaultRecord {
                kind: FaultKind::OrchestratorStalled,
                agent: None,
                peer: None,
                // As every fault record: the first tick the team did not complete.
                tick: fault.tick,
                message: format!(
                    "the orchestrator itself did not run for {:.1} s at tick {} (stopped or \
                     starved), so its clock stalled and the members stopped by themselves \
                     (then: {})",
                    s.gap.as_secs_f64(),
                    s.tick,
                    fault.message
                ),
            },
            _ => fault,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exited(tick: u64) -> FaultRecord {
        FaultRecord {
            kind: FaultKind::AgentExited,
            agent: Some(1),
            peer: None,
            tick,
            message: format!("agent 1 exited with code 3 at tick {tick}"),
        }
    }

    #[test]
    fn short_gaps_are_not_stalls_and_blame_stays_with_the_member() {
        let t0 = Duration::from_secs(100);
        let mut w = StallWatch::new(t0);
        assert!(!w.turn(t0 + Duration::from_millis(900), 5));
        assert!(!w.turn(t0 + Duration::from_millis(2800), 6));
        let f = w.explain(exited(6), t0 + Duration::from_secs(3));
        assert_eq!(f, exited(6));
    }

    #[test]
    fn a_member_exit_after_a_stall_is_blamed_on_the_stall() {
        let t0 = Duration::from_secs(100);
        let mut w = StallWatch::new(t0);
        assert!(w.turn(t0 + Duration::from_secs(20), 42));
        let f = w.explain(exited(43), t0 + Duration::from_secs(21));
        assert_eq!(f.kind, FaultKind::OrchestratorStalled);
        assert_eq!((f.agent, f.tick), (None, 43));
        assert!(
            f.message.contains("did not run for 20.0 s at tick 42"),
            "{}",
            f.message
        );
        assert!(
            f.message.contains("agent 1 exited with code 3"),
            "{}",
            f.message
        );
    }

    #[test]
    fn a_member_fault_long_after_a_stall_is_the_members_own() {
        let t0 = Duration::from_secs(100);
        let mut w = StallWatch::new(t0);
        assert!(w.turn(t0 + Duration::from_secs(3), 1));
        let later = t0 + Duration::from_secs(3) + BLAME_WINDOW + Duration::from_secs(1);
        assert_eq!(w.explain(exited(900), later), exited(900));
    }
}
