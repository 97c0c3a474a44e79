//! One member's side of the team protocol as a plain type, with no I/O: events in (a clock
//! message, a neighbour's state, whether the orchestrator lives, "now"), actions out (publish,
//! wake readers, ask about the orchestrator, wait, fail). The loop around it ([`crate::member_loop`])
//! only moves messages between the core and a [`MemberTransport`](crate::seams::MemberTransport).
//!
//! Protocol (ARCHITECTURE.md): the orchestrator grants ticks on the clock channel; a member
//! publishes its tick-k state once tick k is granted, and computes tick k + 1 once k + 1 is
//! granted and its three in-neighbours' tick-k states are in. Every state carries its tick, so a
//! neighbour that runs ahead is buffered, never confused. Every wait has a deadline.

use std::fmt;
use std::time::Duration;

use cdm_core::dynamics::{Flat, QuadState};
use cdm_core::formation::Member;
use cdm_core::step::{law_for, Law, StepFault};

use crate::inbox::Inbox;
use crate::messages::{AgentStatus, ClockCommand, ClockMsg, FaultCode, StateMsg, NO_PEER};
use crate::seams::{TickClock, Vehicle};

/// Deadlines of a member.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deadlines {
    /// How long to wait for the team to start (first grant) while the orchestrator lives.
    pub join: Duration,
    /// How long without progress (no grant, no neighbour state) before giving up mid-run.
    pub silence: Duration,
}

impl Default for Deadlines {
    fn default() -> Self {
        Deadlines {
            join: Duration::from_secs(300),
            silence: Duration::from_secs(10),
        }
    }
}

/// The longest single wait of a member: it only bounds how late the deadlines and the
/// orchestrator check run (every wake-up that matters is a notification). Short slices cost:
/// 1000 members polling every 50 ms took a tenth of a core at start-up.
pub const WAIT_SLICE: Duration = Duration::from_millis(250);

/// How often a waiting member asks whether the orchestrator still lives.
pub const ALIVE_CHECK: Duration = Duration::from_millis(500);

/// How a member ended normally: the orchestrator stopped the team.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Finished {
    /// The last tick published.
    pub tick: u64,
    /// The orchestrator's stop reason code.
    pub reason: u32,
}

/// What a member was waiting for when it gave up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WaitingFor {
    /// The first grant.
    Start,
    /// A grant of this tick.
    Grant(u64),
    /// These in-neighbours' states of this tick.
    States { tick: u64, missing: Vec<u32> },
    /// The orchestrator's stop after the last tick (real time).
    Stop,
}

impl fmt::Display for WaitingFor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WaitingFor::Start => f.write_str("the team to start"),
            WaitingFor::Grant(t) => write!(f, "a grant of tick {t}"),
            WaitingFor::Stop => f.write_str("the stop after the last tick"),
            WaitingFor::States { tick, missing } => {
                write!(f, "tick-{tick} states of in-neighbours {missing:?}")
            }
        }
    }
}

/// Why a member stops flying (the protocol's faults; the loop adds transport errors).
#[derive(Debug, Clone, PartialEq)]
pub enum MemberFault {
    /// The clock carried another scenario's hash.
    ScenarioMismatch { mine: u64, team: u64 },
    /// The orchestrator is gone.
    OrchestratorLost { tick: u64 },
    /// The team flies in the other mode (lockstep or real time) than this member.
    ModeMismatch { member_realtime: bool },
    /// Nothing happened for `waited`.
    Silent {
        tick: u64,
        waited: Duration,
        waiting_for: WaitingFor,
    },
    /// This member's own tick failed.
    Step { tick: u64, fault: StepFault },
    /// An in-neighbour sent a state of another scenario.
    ForeignState {
        tick: u64,
        peer: u32,
        peer_tick: u64,
    },
    /// An in-neighbour's states skipped from `tick` to `later` (samples were lost).
    TickGap { tick: u64, peer: u32, later: u64 },
    /// Real time: an in-neighbour's newest state was `age` old at this member's tick (older
    /// than the bound); the member reported it and holds.
    NeighborStale { tick: u64, peer: u32, age: Duration },
}

/// What the loop must do next.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Publish this state without waking its readers yet (notify on block).
    Publish(StateMsg),
    /// Wake the readers, then read the inputs again before sleeping (they may answer at once).
    NotifyReaders,
    /// Ask whether the orchestrator lives and tell [`MemberCore::on_orchestrator_alive`].
    CheckOrchestrator,
    /// Read the inputs again without sleeping (the member progressed).
    Poll,
    /// Sleep until woken or this long passes, then read the inputs again.
    Wait(Duration),
    /// Stop: publish `report` (a fault notice) if any, linger for the stop, then exit.
    Fail {
        report: Option<StateMsg>,
        fault: MemberFault,
    },
}

/// One member's protocol state.
#[derive(Debug)]
pub struct MemberCore<V, C> {
    id: u32,
    hash: u64,
    last: u64,
    vehicle: V,
    clock: C,
    deadlines: Deadlines,
    neighbor_ids: [u32; 3],
    is_follower: bool,
    rest: Flat,
    tick: u64,
    published: Option<u64>,
    inbox: [Inbox; 3],
    last_progress: Duration,
    last_alive_check: Duration,
    progress: bool,
    unnotified: bool,
    pending: Option<Action>,
}

impl<V: Vehicle, C: TickClock> MemberCore<V, C> {
    /// `member` of the scenario with content hash `hash` and last tick `last`, flying `vehicle`
    /// paced by `clock`; `now` starts the deadlines.
    pub fn new(
        member: &Member,
        hash: u64,
        last: u64,
        parts: (V, C),
        deadlines: Deadlines,
        now: Duration,
    ) -> Self {
        let (law, neighbor_ids) = law_for(member);
        let is_follower = matches!(law, Law::Follower { .. });
        Self {
            id: member.id,
            hash,
            last,
            vehicle: parts.0,
            clock: parts.1,
            deadlines,
            neighbor_ids,
            is_follower,
            rest: Flat::rest(member.position),
            tick: 0,
            published: None,
            inbox: Default::default(),
            last_progress: now,
            last_alive_check: now,
            progress: false,
            unnotified: false,
            pending: None,
        }
    }

    /// The tick this member computes next (its last published one once it has published).
    pub fn tick(&self) -> u64 {
        self.tick
    }

    /// The vehicle flown.
    pub fn vehicle(&self) -> &V {
        &self.vehicle
    }

    /// The in-neighbours `member` subscribes to (sorted), empty for a leader.
    pub fn subscriptions(member: &Member) -> Vec<u32> {
        let mut ins = match law_for(member) {
            (Law::Follower { .. }, ids) => ids.to_vec(),
            _ => Vec::new(),
        };
        ins.sort_unstable();
        ins
    }

    /// A clock message: a grant (may allow more ticks) or a stop (the member is finished).
    pub fn on_clock(&mut self, c: &ClockMsg) -> Result<Option<Finished>, MemberFault> {
        if c.scenario_hash != self.hash {
            return Err(MemberFault::ScenarioMismatch {
                mine: self.hash,
                team: c.scenario_hash,
            });
        }
        match c.command() {
            ClockCommand::Run => {
                self.progress |= self.clock.on_grant(c.grant_tick);
                Ok(None)
            }
            // A real-time team: this member was started without --realtime.
            ClockCommand::Realtime { .. } => Err(MemberFault::ModeMismatch {
                member_realtime: false,
            }),
            ClockCommand::Stop(_) => Ok(Some(Finished {
                tick: self.tick,
                reason: c.reason,
            })),
        }
    }

    /// A state from the transport: kept when it is an in-neighbour's state of a tick still
    /// needed. A neighbour's fault notice is not a state: the orchestrator stops the team once
    /// every tick before the fault is complete (as the engine would have flown them).
    pub fn on_neighbor(&mut self, msg: &StateMsg) {
        let Some(slot) = self.neighbor_ids.iter().position(|n| *n == msg.id) else {
            return;
        };
        if msg.status() != AgentStatus::Ok {
            return;
        }
        if msg.scenario_hash != self.hash && self.pending.is_none() {
            let fault = MemberFault::ForeignState {
                tick: self.tick,
                peer: msg.id,
                peer_tick: msg.tick,
            };
            self.pending = Some(self.fail(FaultCode::NeighborFault, msg.id, fault));
        }
        if msg.tick >= self.tick {
            self.inbox[slot].insert(msg.tick, QuadState(msg.state).flat());
            self.progress = true;
        }
    }

    /// The answer to [`Action::CheckOrchestrator`].
    pub fn on_orchestrator_alive(&mut self, alive: bool) {
        if !alive && self.pending.is_none() {
            let fault = MemberFault::OrchestratorLost { tick: self.tick };
            self.pending = Some(Action::Fail {
                report: None,
                fault,
            });
        }
    }

    /// The next action at time `now`. Call it until it returns [`Action::Poll`],
    /// [`Action::NotifyReaders`] or [`Action::Wait`] (then read the inputs) or [`Action::Fail`].
    pub fn poll(&mut self, now: Duration) -> Action {
        if let Some(a) = self.pending.take() {
            return a;
        }
        if let Some(a) = self.advance() {
            return a;
        }
        if std::mem::take(&mut self.progress) {
            self.last_progress = now;
            return Action::Poll;
        }
        let idle = now.saturating_sub(self.last_progress);
        if now.saturating_sub(self.last_alive_check) >= ALIVE_CHECK {
            self.last_alive_check = now;
            return Action::CheckOrchestrator;
        }
        let limit = if self.clock.allowed().is_none() {
            self.deadlines.join
        } else {
            self.deadlines.silence
        };
        if idle >= limit {
            let fault = MemberFault::Silent {
                tick: self.tick,
                waited: idle,
                waiting_for: self.waiting_for(),
            };
            return Action::Fail {
                report: None,
                fault,
            };
        }
        if std::mem::take(&mut self.unnotified) {
            return Action::NotifyReaders;
        }
        Action::Wait(WAIT_SLICE.min(limit - idle))
    }

    /// One step of "advance as far as grants and neighbour data allow": a state to publish, a
    /// fault, or `None` when blocked (several ticks per wake-up, one action per call).
    fn advance(&mut self) -> Option<Action> {
        while let Some(g) = self.clock.allowed() {
            let tick = self.tick;
            if self.published != Some(tick) && g >= tick {
                self.published = Some(tick);
                self.unnotified = true;
                self.progress = true;
                return Some(Action::Publish(StateMsg::ok(
                    tick,
                    self.hash,
                    self.id,
                    self.vehicle.state(),
                )));
            }
            if self.published != Some(tick) || tick >= self.last || g < tick + 1 {
                return None;
            }
            let flats = match self.neighbor_flats() {
                Ok(Some(f)) => f,
                Ok(None) => return None,
                Err((peer, later)) => {
                    let fault = MemberFault::TickGap { tick, peer, later };
                    return Some(self.fail(FaultCode::TickGap, peer, fault));
                }
            };
            if let Err(fault) = self.vehicle.fly_tick(tick, &flats) {
                let (code, peer) = match fault {
                    StepFault::NeighborNonFinite { peer } => (FaultCode::NonFinite, peer),
                    StepFault::Control(_) => (FaultCode::Control, NO_PEER),
                };
                return Some(self.fail(code, peer, MemberFault::Step { tick, fault }));
            }
            self.tick += 1;
            for b in self.inbox.iter_mut() {
                b.drop_before(self.tick);
            }
            self.progress = true;
        }
        None
    }

    /// The in-neighbours' states of this tick; `None` while one is missing; `Err((peer, later))`
    /// when a later tick of `peer` arrived without this one (a sample was lost).
    fn neighbor_flats(&self) -> Result<Option<[Flat; 3]>, (u32, u64)> {
        let mut flats = [self.rest; 3];
        if !self.is_follower {
            return Ok(Some(flats));
        }
        let tick = self.tick;
        let mut ready = true;
        for (slot, f) in flats.iter_mut().enumerate() {
            match self.inbox[slot].get(tick) {
                Some(v) => *f = *v,
                None => {
                    if let Some(later) = self.inbox[slot].first_tick().filter(|&l| l > tick) {
                        return Err((self.neighbor_ids[slot], later));
                    }
                    ready = false;
                }
            }
        }
        Ok(ready.then_some(flats))
    }

    /// A fault that is reported to the team (this member's state flagged with `code`).
    fn fail(&self, code: FaultCode, peer: u32, fault: MemberFault) -> Action {
        let msg = StateMsg::ok(self.tick, self.hash, self.id, self.vehicle.state());
        let peer = (peer != NO_PEER).then_some(peer);
        Action::Fail {
            report: Some(msg.with_status(AgentStatus::Fault { code, peer })),
            fault,
        }
    }

    fn waiting_for(&self) -> WaitingFor {
        let tick = self.tick;
        match self.clock.allowed() {
            None => WaitingFor::Start,
            Some(g) if g < tick + 1 || self.published != Some(tick) => WaitingFor::Grant(tick + 1),
            Some(_) => WaitingFor::States {
                tick,
                missing: (0..3)
                    .filter(|&k| self.inbox[k].get(tick).is_none())
                    .map(|k| self.neighbor_ids[k])
                    .collect(),
            },
        }
    }
}

#[cfg(test)]
#[path = "member_core_tests.rs"]
mod tests;
