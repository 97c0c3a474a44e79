//! One member's side of the team protocol as a plain type, with no I/O: events in (a clock
//! message, a neighbour's state, whether the orchestrator lives, "now"), actions out (publish,
//! wake readers, ask about the orchestrator, wait, fail). The loop around it ([`crate::member_loop`])
//! only moves messages between the core and a [`MemberTransport`](crate::seams::MemberTransport).
//!
//! Protocol (ARCHITECTURE.md): the orchestrator grants ticks on the clock channel; a member
//! publishes its tick-k state once tick k is granted, and computes tick k + 1 once k + 1 is
//! granted and its three in-neighbours' tick-k states are in. Every state carries its tick, so a
//! neighbour that runs ahead is buffered, never confused. Every wait has a deadline.
//!
//! Over imperfect links (`cdm_core::link`, set by [`MemberCore::with_links`]) tick k + 1 waits
//! only for the in-neighbours' states that may be usable at k (those of tick k - min delay),
//! and the follower flies on the newest state of each that the link model delivered, brought to
//! t_k: the same [`LinkModel::hear`] the engine calls, so both fly the same bits.

use std::fmt;
use std::time::Duration;

use cdm_core::dynamics::{Flat, QuadState};
use cdm_core::formation::Member;
use cdm_core::link::{Heard, LinkModel};
use cdm_core::math::Real;
use cdm_core::step::{law_for, Law, NeighborModel, StepConfig, StepFault};

use crate::inbox::Inbox;
use crate::member_loss::{LossFault, LossWork, MemberLosses};
use crate::member_watch::{report_fault, Watch};
use crate::messages::{AgentStatus, ClockCommand, ClockMsg, FaultCode, StateMsg, NO_PEER};
use crate::seams::{TickClock, Vehicle, VehicleFault};

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
    /// This member's real vehicle failed (lost, never heard, refused to arm).
    Vehicle { tick: u64, what: String },
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
    /// A loss notice this member cannot follow (missed, too late, or about itself).
    Loss(LossFault),
    /// The vehicle or the transport cannot switch to a repaired link.
    RepairUnsupported { tick: u64 },
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
    /// Open ports for a repaired graph, or hand new readers their missed states
    /// ([`LossWork`]), then poll again.
    Repair(LossWork),
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
    progress: bool,
    unnotified: bool,
    watch: Watch,
    /// Loss notices and repairs (`None`: a loss notice is a fault).
    losses: Option<Box<MemberLosses>>,
    links: Links,
}

/// A member's side of the link model: perfect links unless [`MemberCore::with_links`] said
/// otherwise.
#[derive(Debug)]
struct Links {
    model: LinkModel,
    /// The newest state heard of each in-neighbour (link.rs).
    held: [Heard; 3],
    dt_s: Real,
    neighbor_model: NeighborModel,
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
            progress: false,
            unnotified: false,
            watch: Watch::new(now),
            losses: None,
            links: Links {
                model: LinkModel::perfect(1.0),
                held: [Heard {
                    tick: 0,
                    flat: Flat::rest(member.position),
                }; 3],
                dt_s: 1.0,
                neighbor_model: NeighborModel::default(),
            },
        }
    }

    /// Fly over the imperfect links of `model` with ticks of `cfg`: `starts` are the
    /// in-neighbours' tick-0 states (in the order of [`law_for`]), known before anything arrives.
    pub fn with_links(mut self, model: LinkModel, cfg: &StepConfig, starts: [Flat; 3]) -> Self {
        self.links = Links {
            model,
            held: starts.map(|flat| Heard { tick: 0, flat }),
            dt_s: cfg.dt_s,
            neighbor_model: cfg.neighbor_model,
        };
        self
    }

    /// The same core, following the orchestrator's loss notices with `losses` (repair in
    /// flight); without it a notice is a fault.
    pub fn with_losses(mut self, losses: MemberLosses) -> Self {
        self.losses = Some(Box::new(losses));
        self
    }

    /// The tick this member computes next (its last published one once it has published).
    pub fn tick(&self) -> u64 {
        self.tick
    }

    /// The vehicle flown.
    pub fn vehicle(&self) -> &V {
        &self.vehicle
    }

    /// The in-neighbours of `member` in the order of its weights (itself, for a leader): the
    /// order of [`Self::with_links`]'s `starts`.
    pub fn in_neighbors(member: &Member) -> [u32; 3] {
        law_for(member).1
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
        // Pass it on: the readers are woken before this member sleeps (or, at a stop, exits),
        // so a clock message the orchestrator sent only to the team's roots reaches everyone
        // (relayed wake-ups, cdm-iox `TeamLayout::with_relayed_wakes`).
        self.unnotified = true;
        if let Some(n) = c.loss() {
            let taken = match self.losses.as_mut() {
                Some(l) => l.on_notice(n, self.tick).map_err(MemberFault::Loss),
                None => Err(MemberFault::RepairUnsupported { tick: self.tick }),
            };
            if let Err(fault) = taken {
                self.watch.defer(Action::Fail {
                    report: None,
                    fault,
                });
            }
            self.progress = true;
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
            // Only a real-time team of MAVLink vehicles is armed; the model has nothing to arm.
            ClockCommand::Arm => Ok(None),
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
            // A repair's future in-neighbour: kept until its link applies.
            let tick = self.tick;
            if let Some(l) = self
                .losses
                .as_mut()
                .filter(|l| l.is_future_neighbor(msg.id, tick))
            {
                if msg.status() == AgentStatus::Ok && msg.scenario_hash == self.hash {
                    l.keep(msg.id, msg.tick, QuadState(msg.state).flat());
                    self.progress = true;
                }
            }
            return;
        };
        if msg.status() != AgentStatus::Ok {
            return;
        }
        if msg.scenario_hash != self.hash && !self.watch.is_pending() {
            let fault = MemberFault::ForeignState {
                tick: self.tick,
                peer: msg.id,
                peer_tick: msg.tick,
            };
            self.watch
                .defer(self.fail(FaultCode::NeighborFault, msg.id, fault));
        }
        if msg.tick >= self.links.model.oldest_candidate(self.tick) {
            self.inbox[slot].insert(msg.tick, QuadState(msg.state).flat());
            self.progress = true;
        }
    }

    /// The answer to [`Action::CheckOrchestrator`].
    pub fn on_orchestrator_alive(&mut self, alive: bool) {
        self.watch.orchestrator_alive(alive, self.tick);
    }

    /// The next action at time `now`. Call it until it returns [`Action::Poll`],
    /// [`Action::NotifyReaders`] or [`Action::Wait`] (then read the inputs) or [`Action::Fail`].
    pub fn poll(&mut self, now: Duration) -> Action {
        if let Some(a) = self.watch.take() {
            return a;
        }
        if let Some(w) = self.losses.as_mut().and_then(|l| l.next_work()) {
            return Action::Repair(w);
        }
        if let Some(a) = self.advance() {
            return a;
        }
        if std::mem::take(&mut self.progress) {
            self.last_progress = now;
            return Action::Poll;
        }
        let idle = now.saturating_sub(self.last_progress);
        if self.watch.check_due(now) {
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
            if self.losses.as_ref().is_some_and(|l| l.waits_at(tick)) {
                return None;
            }
            if let Some(a) = self.relink_if_due(tick) {
                return Some(a);
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
                return Some(self.vehicle_failed(tick, fault));
            }
            self.tick += 1;
            let oldest = self.links.model.oldest_candidate(self.tick);
            for b in self.inbox.iter_mut() {
                b.drop_before(oldest);
            }
            self.progress = true;
        }
        None
    }

    /// A repaired link that applies from `tick` (a loss notice's tick): the vehicle flies it
    /// and the in-neighbours' states come from the new neighbours, from this tick's step on.
    fn relink_if_due(&mut self, tick: u64) -> Option<Action> {
        let m = self.losses.as_mut()?.due(tick)?;
        if self.vehicle.relink(&m).is_err() {
            let fault = MemberFault::RepairUnsupported { tick };
            return Some(Action::Fail {
                report: None,
                fault,
            });
        }
        let (law, ids) = law_for(&m);
        self.is_follower = matches!(law, Law::Follower { .. });
        let mut old = std::mem::take(&mut self.inbox);
        // A neighbour dropped here may come back at this very tick (a later notice of the same
        // tick, `MemberLosses::due`): its states are kept, not thrown away.
        if let Some(l) = self.losses.as_mut() {
            for (k, id) in self.neighbor_ids.iter().enumerate() {
                if !ids.contains(id) && l.is_future_neighbor(*id, tick) {
                    l.keep_all(*id, std::mem::take(&mut old[k]));
                }
            }
        }
        for (slot, id) in ids.iter().enumerate() {
            let kept = match self.neighbor_ids.iter().position(|j| j == id) {
                Some(k) => std::mem::take(&mut old[k]),
                None => self
                    .losses
                    .as_mut()
                    .map(|l| l.take_kept(*id))
                    .unwrap_or_default(),
            };
            self.inbox[slot] = kept;
            // Over delayed links the states of a few ticks back are still candidates.
            self.inbox[slot].drop_before(self.links.model.oldest_candidate(tick));
            if *id != self.neighbor_ids[slot] {
                // As the engine: a new neighbour in a slot is known where it started until
                // its states arrive (`Engine::apply_repair`).
                let start = self.losses.as_ref().and_then(|l| l.start_of(*id));
                self.links.held[slot] = Heard {
                    tick: 0,
                    flat: Flat::rest(start.unwrap_or(self.rest.r)),
                };
            }
        }
        self.neighbor_ids = ids;
        tracing::info!(id = self.id, tick, in_neighbors = ?ids, "flying the repaired link");
        None
    }

    /// The in-neighbours' states of this tick; `None` while one is missing; `Err((peer, later))`
    /// when a later tick of `peer` arrived without this one (a sample was lost).
    fn neighbor_flats(&mut self) -> Result<Option<[Flat; 3]>, (u32, u64)> {
        let mut flats = [self.rest; 3];
        if !self.is_follower {
            return Ok(Some(flats));
        }
        if !self.links.model.is_perfect() {
            return self.heard_flats();
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

    /// The report of a failed [`Vehicle::fly_tick`].
    fn vehicle_failed(&self, tick: u64, fault: VehicleFault) -> Action {
        let (code, peer, fault) = report_of(tick, fault);
        self.fail(code, peer, fault)
    }

    /// [`Self::neighbor_flats`] over imperfect links: once every state that may be usable at
    /// this tick is in (the one of tick `needed`, and in order those before it), the newest
    /// delivered state of each in-neighbour, brought to this tick.
    fn heard_flats(&mut self) -> Result<Option<[Flat; 3]>, (u32, u64)> {
        let tick = self.tick;
        let l = &mut self.links;
        let need = l.model.needed(tick);
        if let Some(n) = need {
            let mut ready = true;
            for (slot, b) in self.inbox.iter().enumerate() {
                if b.get(n).is_none() {
                    if let Some(later) = b.last_tick().filter(|&l| l > n) {
                        return Err((self.neighbor_ids[slot], later));
                    }
                    ready = false;
                }
            }
            if !ready {
                return Ok(None);
            }
        }
        let inbox = &self.inbox;
        let candidates = |slot: usize| {
            let arrived = need.map(|n| inbox[slot].upto(n));
            arrived
                .into_iter()
                .flatten()
                .map(|(tick, flat)| Heard { tick, flat })
        };
        let (to, from) = (self.id, &self.neighbor_ids);
        let (dt, nm) = (l.dt_s, l.neighbor_model);
        Ok(Some(l.model.hear(
            to,
            from,
            tick,
            &mut l.held,
            candidates,
            dt,
            nm,
        )))
    }

    /// A fault that is reported to the team (this member's state flagged with `code`).
    fn fail(&self, code: FaultCode, peer: u32, fault: MemberFault) -> Action {
        let state = self.vehicle.state();
        report_fault((self.id, self.hash, self.tick), state, (code, peer), fault)
    }

    fn waiting_for(&self) -> WaitingFor {
        let tick = self.tick;
        match self.clock.allowed() {
            None => WaitingFor::Start,
            Some(g) if g < tick + 1 || self.published != Some(tick) => WaitingFor::Grant(tick + 1),
            Some(_) => {
                // Over delayed links tick k waits for the states of tick k - min delay.
                let need = self.links.model.needed(tick).unwrap_or(0);
                WaitingFor::States {
                    tick: need,
                    missing: (0..3)
                        .filter(|&k| self.inbox[k].get(need).is_none())
                        .map(|k| self.neighbor_ids[k])
                        .collect(),
                }
            }
        }
    }
}

/// How a failed tick is reported (lockstep and real time alike): the wire code, the peer it is
/// about ([`NO_PEER`] when none), and the member's own fault.
pub(crate) fn report_of(tick: u64, fault: VehicleFault) -> (FaultCode, u32, MemberFault) {
    match fault {
        VehicleFault::Step(fault) => {
            let (code, peer) = match fault {
                StepFault::NeighborNonFinite { peer } => (FaultCode::NonFinite, peer),
                StepFault::Control(_) => (FaultCode::Control, NO_PEER),
            };
            (code, peer, MemberFault::Step { tick, fault })
        }
        VehicleFault::Link { what } => (
            FaultCode::VehicleLost,
            NO_PEER,
            MemberFault::Vehicle { tick, what },
        ),
    }
}

#[cfg(test)]
#[path = "member_core_tests.rs"]
mod tests;
