//! A host's daemon as a state machine, with no I/O: events in (a frame from the orchestrator,
//! the members' readiness and states, a member's exit, a turn of the loop), each with the
//! instant the loop read; actions out (a frame to send, a member to kill, a clock message or
//! other hosts' states to publish here, the end). The loop in `daemon.rs` owns the link, the
//! shared memory and the member processes, and reads the clock; every deadline is decided here.
//!
//! Phases: starting (members open their ports, bounded), flying (frames both ways until the
//! orchestrator's stop), stopping (the members' last states go up for a bounded while).

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use cdm_runtime::messages::{ClockCommand, ClockMsg, StateMsg, StopReason};
use cdm_runtime::process_exit::ProcessExit;
use cdm_zenoh::{Down, NetExit, Up};

use crate::error::DaemonStop;
use crate::host_link::HEARTBEAT;

/// How often the member processes are looked at while the team flies.
const CHILD_CHECK: Duration = Duration::from_millis(100);
/// After the stop, how long the members' last states (real time: their pacing reports) are
/// carried up: the members' graceful stop takes at most this long.
const STOPPING_WAIT: Duration = Duration::from_secs(3);

/// What happened, as the loop saw it.
#[derive(Debug)]
pub enum DaemonEvent {
    /// A turn of the loop begins (before the frames queued meanwhile are read).
    Woke,
    /// A turn of the loop ends: heartbeat and silence deadlines.
    Deadlines,
    /// Not every member of this host has opened its ports: these have not.
    Waiting(Vec<u32>),
    /// Every member opened its ports; the readers (node names) of each one's state.
    Ready(BTreeMap<u32, Vec<String>>),
    /// A frame from the orchestrator.
    Frame(Down),
    /// States (and fault reports) published on this host's shared memory, in order.
    States(Vec<StateMsg>),
    /// A member process ended.
    Exited { id: u32, how: ProcessExit },
    /// Links a repair opened, whose reader runs here, now connected.
    Linked(Vec<(u32, u32)>),
    /// Part of a member's recording, read after the members stopped: it goes up before the
    /// daemon says it leaves.
    Recording {
        id: u32,
        offset: u64,
        bytes: Vec<u8>,
    },
    /// The members were stopped: the daemon leaves.
    MembersStopped,
}

/// What the loop is to do, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum DaemonAction {
    /// Send this frame to the orchestrator.
    Send(Up),
    /// Kill this member (SIGKILL) and reap it.
    Kill(u32),
    /// Publish this clock message to the host's members (the repairs it announces first).
    Clock(ClockMsg),
    /// Re-publish these states of other hosts' members through their relays here.
    Relay(Vec<StateMsg>),
    /// Look whether member processes ended (each answer is a [`DaemonEvent::Exited`], after the
    /// states published before it).
    CheckExits,
    /// The orchestrator stopped the team for this reason: the members are to stop.
    Finish(StopReason),
    /// The stopping members' states were carried long enough.
    Done,
}

/// Where the daemon is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Starting {
        since: Instant,
        deadline: Duration,
    },
    Flying {
        last_turn: Instant,
        last_child_check: Instant,
    },
    Stopping {
        until: Instant,
    },
}

/// One host's daemon: its members and its link's deadlines.
#[derive(Debug)]
pub struct DaemonCore {
    mine: BTreeSet<u32>,
    link_timeout: Duration,
    phase: Phase,
    last_heard: Instant,
    last_sent: Instant,
    /// Members whose exit was reported.
    reported: BTreeSet<u32>,
}

impl DaemonCore {
    /// A daemon whose members `mine` were spawned at `now`; silence on the link for
    /// `link_timeout` loses it.
    pub fn new(mine: BTreeSet<u32>, link_timeout: Duration, now: Instant) -> Self {
        // Members take a while to open their ports, longer the more of them share a machine.
        let deadline = Duration::from_secs(30) + Duration::from_millis(60 * mine.len() as u64);
        DaemonCore {
            mine,
            link_timeout,
            phase: Phase::Starting {
                since: now,
                deadline,
            },
            last_heard: now,
            last_sent: now,
            reported: BTreeSet::new(),
        }
    }

    /// This host's members.
    pub fn mine(&self) -> &BTreeSet<u32> {
        &self.mine
    }

    /// True when member `id`'s exit was reported (the loop need not look again).
    pub fn reported(&self, id: u32) -> bool {
        self.reported.contains(&id)
    }

    /// One event at `now`: the actions it calls for, or why the daemon stops bridging.
    pub fn handle(
        &mut self,
        event: DaemonEvent,
        now: Instant,
    ) -> Result<Vec<DaemonAction>, DaemonStop> {
        let mut out = Vec::new();
        match event {
            DaemonEvent::Woke => self.woke(now, &mut out)?,
            DaemonEvent::Deadlines => self.deadlines(now, &mut out)?,
            DaemonEvent::Waiting(late) => {
                if let Phase::Starting { since, deadline } = self.phase {
                    if now.saturating_duration_since(since) > deadline {
                        return Err(DaemonStop::NotStarted { late, deadline });
                    }
                }
            }
            DaemonEvent::Ready(subscriptions) => {
                self.phase = Phase::Flying {
                    last_turn: now,
                    last_child_check: now,
                };
                self.send(Up::Ready { subscriptions }, now, &mut out);
            }
            DaemonEvent::Frame(f) => {
                self.last_heard = now;
                self.on_frame(f, now, &mut out)?;
            }
            DaemonEvent::States(mut states) => {
                states.retain(|m| self.mine.contains(&m.id));
                if !states.is_empty() {
                    self.send(Up::States(states), now, &mut out);
                }
            }
            DaemonEvent::Exited { id, how } => match self.phase {
                Phase::Starting { .. } => return Err(DaemonStop::ExitedEarly { id, how }),
                Phase::Flying { .. } if self.reported.insert(id) => {
                    let how = NetExit::of(&how);
                    self.send(Up::Exited { id, how }, now, &mut out);
                }
                _ => {}
            },
            DaemonEvent::Linked(pairs) => {
                if !pairs.is_empty() {
                    self.send(Up::Linked(pairs), now, &mut out);
                }
            }
            DaemonEvent::Recording { id, offset, bytes } if self.mine.contains(&id) => {
                self.send(Up::Recording { id, offset, bytes }, now, &mut out)
            }
            DaemonEvent::Recording { .. } => {}
            DaemonEvent::MembersStopped => self.send(Up::Stopped, now, &mut out),
        }
        Ok(out)
    }

    fn send(&mut self, frame: Up, now: Instant, out: &mut Vec<DaemonAction>) {
        self.last_sent = now;
        out.push(DaemonAction::Send(frame));
    }

    /// The start of a turn. Flying: between two turns this process did not run for longer than
    /// the link timeout (SIGSTOP, a debugger) is checked before the frames queued meanwhile
    /// are read, which would make the link look alive; the member processes are due a look.
    /// Stopping: done once the wait is over.
    fn woke(&mut self, now: Instant, out: &mut Vec<DaemonAction>) -> Result<(), DaemonStop> {
        match &mut self.phase {
            Phase::Flying {
                last_turn,
                last_child_check,
            } => {
                let gap = now.saturating_duration_since(*last_turn);
                let timeout = self.link_timeout;
                if gap > timeout {
                    return Err(DaemonStop::Stalled { gap, timeout });
                }
                *last_turn = now;
                if now.saturating_duration_since(*last_child_check) > CHILD_CHECK {
                    *last_child_check = now;
                    out.push(DaemonAction::CheckExits);
                }
            }
            Phase::Stopping { until } if now >= *until => out.push(DaemonAction::Done),
            _ => {}
        }
        Ok(())
    }

    /// Heartbeat out when due at `now`; an error when the orchestrator has been silent too long.
    fn deadlines(&mut self, now: Instant, out: &mut Vec<DaemonAction>) -> Result<(), DaemonStop> {
        if matches!(self.phase, Phase::Stopping { .. }) {
            return Ok(());
        }
        if now.saturating_duration_since(self.last_sent) >= HEARTBEAT {
            self.send(Up::Heartbeat, now, out);
        }
        if now.saturating_duration_since(self.last_heard) > self.link_timeout {
            let after = self.link_timeout;
            return Err(DaemonStop::Silent { after });
        }
        Ok(())
    }

    /// One frame from the orchestrator. Before the start only a stop matters (it ends the wait);
    /// then: a kill, the clock to every member (a stop ends the flight), other hosts' states
    /// for their readers here.
    fn on_frame(
        &mut self,
        f: Down,
        now: Instant,
        out: &mut Vec<DaemonAction>,
    ) -> Result<(), DaemonStop> {
        let stop = match &f {
            Down::Clock(c) => match c.command() {
                ClockCommand::Stop(reason) => Some(reason),
                _ => None,
            },
            _ => None,
        };
        if matches!(self.phase, Phase::Starting { .. }) {
            return match stop {
                Some(_) => Err(DaemonStop::StoppedBeforeStart),
                None => Ok(()),
            };
        }
        match f {
            Down::Kill(id) => out.push(DaemonAction::Kill(id)),
            Down::Clock(c) => out.push(DaemonAction::Clock(c)),
            Down::States(states) => out.push(DaemonAction::Relay(states)),
            Down::Heartbeat => {}
        }
        if let Some(reason) = stop {
            self.phase = Phase::Stopping {
                until: now + STOPPING_WAIT,
            };
            out.push(DaemonAction::Finish(reason));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_runtime::messages::AgentStatus;

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// A daemon of members 2 and 4, its link timing out after 3 s, flying from `t0`.
    fn flying(t0: Instant) -> DaemonCore {
        let mut d = DaemonCore::new([2, 4].into(), ms(3000), t0);
        let ready = d.handle(DaemonEvent::Ready(BTreeMap::new()), t0).unwrap();
        assert_eq!(
            ready,
            [DaemonAction::Send(Up::Ready {
                subscriptions: BTreeMap::new()
            })]
        );
        d
    }

    fn state(id: u32, tick: u64) -> StateMsg {
        StateMsg::ok(tick, 1, id, [0.0; 12])
    }

    #[test]
    fn the_daemon_keeps_its_link_alive_and_gives_up_on_a_silent_orchestrator() {
        let t0 = Instant::now();
        let mut d = flying(t0);
        assert_eq!(d.handle(DaemonEvent::Deadlines, t0 + ms(199)).unwrap(), []);
        let beat = d.handle(DaemonEvent::Deadlines, t0 + ms(200)).unwrap();
        assert_eq!(beat, [DaemonAction::Send(Up::Heartbeat)]);
        d.handle(DaemonEvent::Frame(Down::Heartbeat), t0 + ms(2000))
            .unwrap();
        d.handle(DaemonEvent::Woke, t0 + ms(2000)).unwrap();
        d.handle(DaemonEvent::Deadlines, t0 + ms(5000)).unwrap();
        d.handle(DaemonEvent::Woke, t0 + ms(5000)).unwrap();
        let e = d.handle(DaemonEvent::Deadlines, t0 + ms(5001)).unwrap_err();
        assert!(matches!(e, DaemonStop::Silent { .. }), "{e}");
        assert_eq!(
            e.to_string(),
            "nothing heard from the orchestrator for 3.0 s (network partition or orchestrator gone)"
        );
    }

    #[test]
    fn a_late_frame_after_a_stall_does_not_keep_the_link() {
        let t0 = Instant::now();
        let mut d = flying(t0);
        d.handle(DaemonEvent::Woke, t0 + ms(3000)).unwrap();
        // The process did not run for 5.2 s; a frame queued meanwhile is read after the check.
        let e = d.handle(DaemonEvent::Woke, t0 + ms(8200)).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("this daemon did not run for 5.2 s"),
            "{e}"
        );
        let stopped = DaemonStop::TeamStopped(StopReason::AgentSilent);
        assert_eq!(
            stopped.to_string(),
            "the orchestrator stopped the team (a silent member, see its audit.json)"
        );
    }

    #[test]
    fn a_stop_before_the_start_ends_the_wait_and_members_must_start_in_time() {
        let t0 = Instant::now();
        let mut d = DaemonCore::new([2, 4].into(), ms(3000), t0);
        let run = ClockMsg::run(3, 0);
        let actions = d.handle(DaemonEvent::Frame(Down::Clock(run)), t0).unwrap();
        assert_eq!(
            actions,
            [],
            "no grant is published before the members are up"
        );
        let stop = ClockMsg::stop(0, 0, StopReason::AgentFault);
        let e = d
            .handle(DaemonEvent::Frame(Down::Clock(stop)), t0 + ms(10))
            .unwrap_err();
        assert!(matches!(e, DaemonStop::StoppedBeforeStart), "{e}");

        let mut d = DaemonCore::new([2, 4].into(), ms(3000), t0);
        let deadline = ms(30_120);
        d.handle(DaemonEvent::Waiting(vec![4]), t0 + deadline)
            .unwrap();
        let e = d
            .handle(DaemonEvent::Waiting(vec![4]), t0 + deadline + ms(1))
            .unwrap_err();
        assert_eq!(e.to_string(), "agents [4] did not start within 30.12s");
        let how = ProcessExit::Code(3);
        let e = d
            .handle(DaemonEvent::Exited { id: 2, how }, t0)
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "agent 2 exited with code 3 before the team started"
        );
    }

    #[test]
    fn orders_from_the_orchestrator_become_actions_in_order() {
        let t0 = Instant::now();
        let mut d = flying(t0);
        let grant = ClockMsg::run(5, 1);
        let crossing = vec![state(7, 4)];
        let t = t0 + ms(10);
        assert_eq!(
            d.handle(DaemonEvent::Frame(Down::Kill(4)), t).unwrap(),
            [DaemonAction::Kill(4)]
        );
        assert_eq!(
            d.handle(DaemonEvent::Frame(Down::States(crossing.clone())), t)
                .unwrap(),
            [DaemonAction::Relay(crossing)]
        );
        assert_eq!(
            d.handle(DaemonEvent::Frame(Down::Clock(grant)), t).unwrap(),
            [DaemonAction::Clock(grant)]
        );
        let stop = ClockMsg::stop(9, 1, StopReason::Finished);
        assert_eq!(
            d.handle(DaemonEvent::Frame(Down::Clock(stop)), t).unwrap(),
            [
                DaemonAction::Clock(stop),
                DaemonAction::Finish(StopReason::Finished)
            ]
        );
        // Stopping: the last states still go up, for 3 s at most; the link is not judged.
        let last = vec![state(2, 9)];
        let up = d
            .handle(DaemonEvent::States(last.clone()), t + ms(5))
            .unwrap();
        assert_eq!(up, [DaemonAction::Send(Up::States(last))]);
        assert_eq!(d.handle(DaemonEvent::Deadlines, t + ms(2999)).unwrap(), []);
        assert_eq!(d.handle(DaemonEvent::Woke, t + ms(2999)).unwrap(), []);
        assert_eq!(
            d.handle(DaemonEvent::Woke, t + ms(3000)).unwrap(),
            [DaemonAction::Done]
        );
        // The recordings go up before the leave; another host's member's is none of this one's.
        let part = |id| DaemonEvent::Recording {
            id,
            offset: 0,
            bytes: vec![1, 2],
        };
        let sent = Up::Recording {
            id: 2,
            offset: 0,
            bytes: vec![1, 2],
        };
        let t3 = t + ms(3000);
        assert_eq!(d.handle(part(2), t3).unwrap(), [DaemonAction::Send(sent)]);
        assert_eq!(d.handle(part(7), t3).unwrap(), []);
        let bye = d.handle(DaemonEvent::MembersStopped, t + ms(3000)).unwrap();
        assert_eq!(bye, [DaemonAction::Send(Up::Stopped)]);
    }

    #[test]
    fn this_hosts_states_and_exits_go_up_once_each() {
        let t0 = Instant::now();
        let mut d = flying(t0);
        let fault = state(4, 8).with_status(AgentStatus::Fault {
            code: cdm_runtime::messages::FaultCode::NonFinite,
            peer: None,
        });
        let published = vec![state(2, 8), state(7, 8), fault];
        let up = d.handle(DaemonEvent::States(published), t0).unwrap();
        assert_eq!(
            up,
            [DaemonAction::Send(Up::States(vec![state(2, 8), fault]))],
            "a relay's state is not this host's to send"
        );
        assert_eq!(
            d.handle(DaemonEvent::States(vec![state(7, 9)]), t0)
                .unwrap(),
            []
        );
        assert_eq!(d.handle(DaemonEvent::Woke, t0 + ms(100)).unwrap(), []);
        let due = d.handle(DaemonEvent::Woke, t0 + ms(101)).unwrap();
        assert_eq!(due, [DaemonAction::CheckExits]);
        let how = ProcessExit::Signal(9);
        let exit = d.handle(
            DaemonEvent::Exited {
                id: 4,
                how: how.clone(),
            },
            t0 + ms(101),
        );
        assert_eq!(
            exit.unwrap(),
            [DaemonAction::Send(Up::Exited {
                id: 4,
                how: NetExit::Signal(9)
            })]
        );
        assert!(d.reported(4));
        let again = d.handle(DaemonEvent::Exited { id: 4, how }, t0 + ms(300));
        assert_eq!(again.unwrap(), []);
        let linked = d.handle(DaemonEvent::Linked(vec![(2, 7)]), t0).unwrap();
        assert_eq!(linked, [DaemonAction::Send(Up::Linked(vec![(2, 7)]))]);
        assert_eq!(d.handle(DaemonEvent::Linked(vec![]), t0).unwrap(), []);
    }
}
