//! What a member core ([`crate::member_core::MemberCore`]) does between its ticks, whatever
//! paces it: ask whether the orchestrator lives every [`ALIVE_CHECK`], hold the one action an
//! incoming message decided until the next poll (the first fault wins), and flag a fault in a
//! state for the team.

use std::time::Duration;

use crate::member_protocol::{Action, MemberFault, ALIVE_CHECK};
use crate::messages::{AgentStatus, FaultCode, StateMsg, NO_PEER};

/// The orchestrator watch and the pending action of a member core.
#[derive(Debug)]
pub(crate) struct Watch {
    last_alive_check: Duration,
    pending: Option<Action>,
}

impl Watch {
    /// A watch whose first check comes [`ALIVE_CHECK`] after `now`.
    pub(crate) fn new(now: Duration) -> Self {
        Self {
            last_alive_check: now,
            pending: None,
        }
    }

    /// The answer to [`Action::CheckOrchestrator`] at the member's tick `tick`: a lost
    /// orchestrator ends the flight (unreported: nobody is left to read it).
    pub(crate) fn orchestrator_alive(&mut self, alive: bool, tick: u64) {
        if !alive {
            self.defer(Action::Fail {
                report: None,
                fault: MemberFault::OrchestratorLost { tick },
            });
        }
    }

    /// Returns `a` at the next poll, unless an action is pending already (the first wins).
    pub(crate) fn defer(&mut self, a: Action) {
        if self.pending.is_none() {
            self.pending = Some(a);
        }
    }

    /// True when an action waits for the next poll.
    pub(crate) fn is_pending(&self) -> bool {
        self.pending.is_some()
    }

    /// The pending action: the first thing a poll returns.
    pub(crate) fn take(&mut self) -> Option<Action> {
        self.pending.take()
    }

    /// A grant (lockstep) arrived at `now`: its publisher lived a moment ago, so the next
    /// question waits [`ALIVE_CHECK`] from here. A dead orchestrator is still found within
    /// [`ALIVE_CHECK`] of its last message. Asking costs a read of every node attached to the
    /// member's state service (iceoryx2 parses each node's details file): at N = 1000, asking
    /// every half second while grants kept arriving was 13 % of the members' CPU.
    pub(crate) fn heard_from_orchestrator(&mut self, now: Duration) {
        self.last_alive_check = self.last_alive_check.max(now);
    }

    /// True (once per period) when it is time to ask whether the orchestrator lives.
    pub(crate) fn check_due(&mut self, now: Duration) -> bool {
        let due = now.saturating_sub(self.last_alive_check) >= ALIVE_CHECK;
        if due {
            self.last_alive_check = now;
        }
        due
    }
}

/// A fault reported to the team: member `id`'s `state` at `tick` (scenario `hash`) flagged with
/// `code` and the `peer` it is about ([`NO_PEER`] when none).
pub(crate) fn report_fault(
    (id, hash, tick): (u32, u64, u64),
    state: [f64; 12],
    (code, peer): (FaultCode, u32),
    fault: MemberFault,
) -> Action {
    let msg = StateMsg::ok(tick, hash, id, state);
    let peer = (peer != NO_PEER).then_some(peer);
    Action::Fail {
        report: Some(msg.with_status(AgentStatus::Fault { code, peer })),
        fault,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_clock_message_postpones_the_check_and_silence_brings_it_back() {
        let mut w = Watch::new(Duration::ZERO);
        let ms = Duration::from_millis;
        w.heard_from_orchestrator(ms(400));
        assert!(!w.check_due(ALIVE_CHECK));
        assert!(!w.check_due(ms(899)));
        // An older message (read late) never brings the check forward.
        w.heard_from_orchestrator(ms(100));
        assert!(w.check_due(ms(900)));
        assert!(!w.check_due(ms(1000)));
        assert!(w.check_due(ms(1400)));
    }

    #[test]
    fn the_first_deferred_action_wins_and_checks_come_once_a_period() {
        let mut w = Watch::new(Duration::ZERO);
        assert!(!w.check_due(ALIVE_CHECK / 2));
        assert!(w.check_due(ALIVE_CHECK));
        assert!(!w.check_due(ALIVE_CHECK + ALIVE_CHECK / 2));
        w.orchestrator_alive(true, 3);
        assert!(!w.is_pending());
        w.orchestrator_alive(false, 4);
        w.orchestrator_alive(false, 5);
        assert_eq!(
            w.take(),
            Some(Action::Fail {
                report: None,
                fault: MemberFault::OrchestratorLost { tick: 4 }
            })
        );
        assert_eq!(w.take(), None);
    }
}
