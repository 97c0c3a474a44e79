//! The faults the team side stops a run on, lockstep or real time, as one typed value: its kind
//! (`fault.kind` in audit.json), the member and tick it names, the reason sent to the members,
//! and its text, written here and nowhere else. [`FaultRank`] orders fault reports the same way
//! in both modes.

use std::fmt;
use std::time::Duration;

use cdm_model::outcome::FaultKind;
use cdm_records::audit::FaultRecord;

use crate::messages::{FaultCode, StopReason};
use crate::process_exit::ProcessExit;

/// Whose clock a member's tick is on: lockstep ticks are the team's (every member flies tick k
/// at once); real-time ticks are each member's own (phase offsets, no barrier), so the text says
/// "its tick".
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WhoseTick {
    Team,
    Own,
}

impl WhoseTick {
    fn at(self) -> &'static str {
        match self {
            WhoseTick::Team => "at tick",
            WhoseTick::Own => "at its tick",
        }
    }
}

/// Where an interrupt found the run: at a tick (lockstep), or at audit instant `index`, time
/// `t_s` of the common time line (real time).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InterruptedAt {
    /// Before the start: while the team was created or joined.
    BeforeStart,
    /// While the members armed their vehicles (`--arm`).
    Arming,
    Tick(u64),
    Instant {
        index: u64,
        t_s: f64,
    },
}

/// A fault the team stops on.
#[derive(Debug, Clone, PartialEq)]
pub enum TeamFault {
    /// Member `id` reported `code` at its `tick` (`peer`: the member it is about).
    Reported {
        id: u32,
        tick: u64,
        code: FaultCode,
        peer: Option<u32>,
        clock: WhoseTick,
    },
    /// Member `id` published a non-finite state at `tick` and no reader reported it.
    NonFinite {
        id: u32,
        tick: u64,
        clock: WhoseTick,
    },
    /// Real time: member `peer`'s newest state was older than `bound_s` when `reporter` read it
    /// at its tick `tick` (the reporter holds position; the peer is the fault).
    NeighborStale {
        peer: u32,
        reporter: u32,
        tick: u64,
        bound_s: f64,
    },
    /// Lockstep: `missing` sent no state for `tick` within `timeout`.
    Silent {
        missing: Vec<u32>,
        tick: u64,
        timeout: Duration,
    },
    /// Real time: member `id`'s newest state (its tick `newest`) was `age_s` old at audit
    /// instant `index`.
    Stale {
        id: u32,
        newest: u64,
        age_s: f64,
        index: u64,
    },
    /// Member `id`'s process ended (`how`) before `tick`.
    Exited {
        id: u32,
        how: ProcessExit,
        tick: u64,
    },
    /// SIGINT, SIGTERM, SIGHUP or SIGQUIT (`signal` names it).
    Interrupted { signal: String, at: InterruptedAt },
    /// The repair after losing member `id` did not connect within `timeout`: the links
    /// (reader, writer) `missing` never joined; found with tick `tick` next.
    RepairUnlinked {
        id: u32,
        missing: Vec<(u32, u32)>,
        timeout: Duration,
        tick: u64,
    },
    /// Member `id` was lost after tick `from - 1` under `--on-loss stop`.
    LostStop { id: u32, from: u64 },
    /// Members `waiting` (ascending) did not report their vehicle armed within `within`.
    NotArmed { waiting: Vec<u32>, within: Duration },
}

impl TeamFault {
    /// The kind audit.json records.
    pub fn kind(&self) -> FaultKind {
        match self {
            TeamFault::Reported { code, .. } => code.kind(),
            TeamFault::NonFinite { .. } => FaultKind::NonFiniteState,
            TeamFault::NeighborStale { .. }
            | TeamFault::Silent { .. }
            | TeamFault::Stale { .. }
            | TeamFault::RepairUnlinked { .. } => FaultKind::AgentSilent,
            TeamFault::Exited { .. } => FaultKind::AgentExited,
            TeamFault::LostStop { .. } => FaultKind::Lost,
            TeamFault::NotArmed { .. } => FaultKind::VehicleLost,
            TeamFault::Interrupted { .. } => FaultKind::Interrupted,
        }
    }

    /// The reason the members are told.
    pub fn reason(&self) -> StopReason {
        match self {
            TeamFault::NeighborStale { .. }
            | TeamFault::Silent { .. }
            | TeamFault::Stale { .. }
            | TeamFault::RepairUnlinked { .. }
            | TeamFault::NotArmed { .. } => StopReason::AgentSilent,
            TeamFault::Interrupted { .. } => StopReason::Interrupted,
            _ => StopReason::AgentFault,
        }
    }

    /// The member it names (`agent`) and the other one (`peer`), and the tick of the record.
    fn subject(&self) -> (Option<u32>, Option<u32>, u64) {
        match *self {
            TeamFault::Reported { id, tick, peer, .. } => (Some(id), peer, tick),
            TeamFault::NonFinite { id, tick, .. } => (Some(id), None, tick),
            TeamFault::NeighborStale {
                peer,
                reporter,
                tick,
                ..
            } => (Some(peer), Some(reporter), tick),
            TeamFault::Silent {
                ref missing, tick, ..
            } => (missing.first().copied(), None, tick),
            TeamFault::Stale { id, index, .. } => (Some(id), None, index),
            TeamFault::Exited { id, tick, .. } => (Some(id), None, tick),
            TeamFault::RepairUnlinked { id, tick, .. } => (Some(id), None, tick),
            TeamFault::LostStop { id, from } => (Some(id), None, from),
            TeamFault::NotArmed { ref waiting, .. } => (waiting.first().copied(), None, 0),
            TeamFault::Interrupted { at, .. } => match at {
                InterruptedAt::BeforeStart | InterruptedAt::Arming => (None, None, 0),
                InterruptedAt::Tick(tick) => (None, None, tick),
                InterruptedAt::Instant { index, .. } => (None, None, index),
            },
        }
    }

    /// Its audit record.
    pub fn record(&self) -> FaultRecord {
        let (agent, peer, tick) = self.subject();
        FaultRecord::new(self.kind(), agent, peer, tick, self.to_string())
    }

    /// Its audit record and the reason sent to the members.
    pub fn stop(&self) -> (FaultRecord, StopReason) {
        (self.record(), self.reason())
    }
}

impl fmt::Display for TeamFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TeamFault::Reported {
                id,
                tick,
                code,
                peer,
                clock,
            } => {
                write!(f, "agent {id} reported {code:?} {} {tick}", clock.at())?;
                if let Some(p) = peer {
                    write!(f, " (peer {p})")?;
                }
                Ok(())
            }
            TeamFault::NonFinite { id, tick, clock } => {
                write!(f, "agent {id} published a non-finite state {} {tick}", clock.at())
            }
            TeamFault::NeighborStale {
                peer,
                reporter,
                tick,
                bound_s,
            } => write!(
                f,
                "agent {peer} sent no state for more than {:.0} ms (reported by agent {reporter} at its tick {tick}, which holds position)",
                bound_s * 1e3
            ),
            TeamFault::Silent {
                missing,
                tick,
                timeout,
            } => write!(
                f,
                "agents {missing:?} sent no state for tick {tick} within {timeout:?}"
            ),
            TeamFault::Stale {
                id, newest, age_s, ..
            } => write!(
                f,
                "agent {id} sent no state for {:.0} ms (its newest is its tick {newest}): stopped or hung",
                age_s * 1e3
            ),
            TeamFault::Exited { id, how, tick } => write!(f, "agent {id} {how} at tick {tick}"),
            TeamFault::Interrupted { signal, at } => match at {
                InterruptedAt::BeforeStart => write!(f, "interrupted by {signal} before the start"),
                InterruptedAt::Arming => write!(f, "interrupted by {signal} while arming"),
                InterruptedAt::Tick(tick) => write!(f, "interrupted by {signal} at tick {tick}"),
                InterruptedAt::Instant { t_s, .. } => {
                    write!(f, "interrupted by {signal} at t = {t_s:.3} s")
                }
            },
            TeamFault::RepairUnlinked {
                id,
                missing,
                timeout,
                ..
            } => write!(
                f,
                "the repair after losing agent {id} did not connect within {timeout:?}: links (reader, writer) {missing:?} missing"
            ),
            TeamFault::NotArmed { waiting, within } => {
                let ids: Vec<String> = waiting.iter().map(u32::to_string).collect();
                write!(
                    f,
                    "agents {} did not report their vehicle armed within {} s (--join-timeout)",
                    ids.join(", "),
                    within.as_secs_f64()
                )
            }
            TeamFault::LostStop { id, from } => write!(
                f,
                "agent(s) [{id}] lost after tick {} (--on-loss stop)",
                from.saturating_sub(1)
            ),
        }
    }
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
    /// The rank of member `member`'s (formation index) report of `code` at `tick`.
    pub fn of_report(code: FaultCode, tick: u64, member: usize) -> Self {
        FaultRank {
            echo: code == FaultCode::NeighborFault,
            tick,
            member,
        }
    }

    /// The rank of a fault the orchestrator found itself at `tick` (a non-finite state nobody
    /// reported): after every member's report of that tick.
    pub fn found(tick: u64) -> Self {
        FaultRank {
            echo: false,
            tick,
            member: usize::MAX,
        }
    }

    /// True when this report names the root cause better than `current` (or there is none).
    pub fn outranks(&self, current: Option<&FaultRank>) -> bool {
        current.is_none_or(|c| self < c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_ranking_puts_the_root_cause_over_its_echo() {
        let root = FaultRank::of_report(FaultCode::Control, 7, 30);
        let echo = FaultRank::of_report(FaultCode::NeighborFault, 6, 2);
        assert!(
            root.outranks(Some(&echo)),
            "an earlier echo hid the root cause"
        );
        assert!(!echo.outranks(Some(&root)));
        let earlier = FaultRank::of_report(FaultCode::Safety, 6, 31);
        assert!(earlier.outranks(Some(&root)), "the earliest tick wins");
        let first = FaultRank::of_report(FaultCode::Control, 7, 3);
        assert!(first.outranks(Some(&root)), "then formation order");
        assert!(!root.outranks(Some(&root)), "a repeat is not better");
        assert!(echo.outranks(None));
        assert!(root.outranks(Some(&FaultRank::found(7))));
    }

    #[test]
    fn texts_are_the_ones_audit_json_had() {
        let reported = |clock| TeamFault::Reported {
            id: 5,
            tick: 12,
            code: FaultCode::NeighborFault,
            peer: Some(4),
            clock,
        };
        assert_eq!(
            reported(WhoseTick::Team).to_string(),
            "agent 5 reported NeighborFault at tick 12 (peer 4)"
        );
        assert_eq!(
            reported(WhoseTick::Own).to_string(),
            "agent 5 reported NeighborFault at its tick 12 (peer 4)"
        );
        let r = reported(WhoseTick::Team).record();
        assert_eq!(
            (r.kind, r.agent, r.peer, r.tick),
            (FaultKind::AgentFault, Some(5), Some(4), 12)
        );
        let nf = TeamFault::NonFinite {
            id: 3,
            tick: 9,
            clock: WhoseTick::Own,
        };
        assert_eq!(
            nf.to_string(),
            "agent 3 published a non-finite state at its tick 9"
        );
        let silent = TeamFault::Silent {
            missing: vec![7, 8],
            tick: 4,
            timeout: Duration::from_millis(1500),
        };
        assert_eq!(
            silent.to_string(),
            "agents [7, 8] sent no state for tick 4 within 1.5s"
        );
        assert_eq!(silent.stop().1, StopReason::AgentSilent);
        let stale = TeamFault::Stale {
            id: 2,
            newest: 40,
            age_s: 0.5123,
            index: 41,
        };
        assert_eq!(
            stale.to_string(),
            "agent 2 sent no state for 512 ms (its newest is its tick 40): stopped or hung"
        );
        assert_eq!(stale.record().tick, 41);
        let ns = TeamFault::NeighborStale {
            peer: 2,
            reporter: 9,
            tick: 30,
            bound_s: 0.25,
        };
        assert_eq!(
            ns.to_string(),
            "agent 2 sent no state for more than 250 ms (reported by agent 9 at its tick 30, which holds position)"
        );
        assert_eq!(ns.record().peer, Some(9));
        let int = |at| TeamFault::Interrupted {
            signal: "SIGINT".into(),
            at,
        };
        assert_eq!(
            int(InterruptedAt::Tick(3)).to_string(),
            "interrupted by SIGINT at tick 3"
        );
        let rt = int(InterruptedAt::Instant {
            index: 20,
            t_s: 2.0,
        });
        assert_eq!(rt.to_string(), "interrupted by SIGINT at t = 2.000 s");
        assert_eq!(rt.stop().0.tick, 20);
        let ex = TeamFault::Exited {
            id: 1,
            how: ProcessExit::Code(3),
            tick: 6,
        };
        assert_eq!(ex.to_string(), "agent 1 exited with code 3 at tick 6");
        assert_eq!(
            int(InterruptedAt::BeforeStart).to_string(),
            "interrupted by SIGINT before the start"
        );
        assert_eq!(
            int(InterruptedAt::Arming).to_string(),
            "interrupted by SIGINT while arming"
        );
        let unarmed = TeamFault::NotArmed {
            waiting: vec![3, 7],
            within: Duration::from_secs(30),
        };
        assert_eq!(
            unarmed.to_string(),
            "agents 3, 7 did not report their vehicle armed within 30 s (--join-timeout)"
        );
        assert_eq!(
            (unarmed.kind(), unarmed.reason(), unarmed.record().agent),
            (FaultKind::VehicleLost, StopReason::AgentSilent, Some(3))
        );
        let unlinked = TeamFault::RepairUnlinked {
            id: 20,
            missing: vec![(21, 4)],
            timeout: Duration::from_secs(5),
            tick: 9,
        };
        assert_eq!(
            unlinked.to_string(),
            "the repair after losing agent 20 did not connect within 5s: links (reader, writer) [(21, 4)] missing"
        );
        assert_eq!(unlinked.stop().1, StopReason::AgentSilent);
        let lost = TeamFault::LostStop { id: 20, from: 6 };
        assert_eq!(
            lost.to_string(),
            "agent(s) [20] lost after tick 5 (--on-loss stop)"
        );
        assert_eq!((lost.kind(), lost.record().tick), (FaultKind::Lost, 6));
    }
}
