//! Lockstep: the orchestrator grants ticks on the clock channel; a member publishes its tick-k
//! state once tick k is granted, and computes tick k + 1 once k + 1 is granted and its three
//! in-neighbours' tick-k states are in (ARCHITECTURE.md). Every state carries its tick, so a
//! neighbour that runs ahead is buffered, never confused. Every wait has a deadline.
//!
//! Over imperfect links (`cdm_model::link`, set by [`MemberCore::with_links`]) tick k + 1 waits
//! only for the in-neighbours' states that may be usable at k (those of tick k - min delay),
//! and the follower flies on the newest state of each that the link model delivered, brought to
//! t_k: the same [`LinkModel::hear`] the engine calls, so both fly the same bits. Loss notices
//! ([`MemberLosses`]) switch the member to a repaired link at their tick.

use std::time::Duration;

use cdm_math::Real;
use cdm_model::dynamics::{Flat, QuadState};
use cdm_model::formation::Member;
use cdm_model::link::{Heard, LinkModel};
use cdm_model::step::{law_for, Law, NeighborModel, StepConfig};

use crate::inbox::Inbox;
use crate::member_core::{Action, Deadlines, MemberCore, MemberFault, Shared, Timing, Wiring};
use crate::member_loss::MemberLosses;
use crate::member_protocol::WaitingFor;
use crate::messages::{AgentStatus, ClockCommand, ClockMsg, FaultCode, StateMsg};
use crate::seams::{LockstepClock, TickClock, Vehicle};

/// A member flown in lockstep on the grants of `C`.
pub type LockstepCore<V, C = LockstepClock> = MemberCore<V, Lockstep<C>>;

/// Lockstep's side of a member: the grants, the in-neighbours' states not yet used, the link
/// model and the loss notices.
#[derive(Debug)]
pub struct Lockstep<C> {
    clock: C,
    rest: Flat,
    inbox: [Inbox; 3],
    last_progress: Duration,
    progress: bool,
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

impl<V: Vehicle, C: TickClock> MemberCore<V, Lockstep<C>> {
    /// `member` of the scenario with content hash `hash` and last tick `last`, flying `vehicle`
    /// paced by `clock`; `now` starts the deadlines.
    pub fn new(
        member: &Member,
        hash: u64,
        last: u64,
        (vehicle, clock): (V, C),
        deadlines: Deadlines,
        now: Duration,
    ) -> Self {
        let rest = Flat::rest(member.start);
        let lockstep = Lockstep {
            clock,
            rest,
            inbox: Default::default(),
            last_progress: now,
            progress: false,
            losses: None,
            links: Links {
                model: LinkModel::perfect(1.0),
                held: [Heard {
                    tick: 0,
                    flat: rest,
                }; 3],
                dt_s: 1.0,
                neighbor_model: NeighborModel::default(),
            },
        };
        Self::with_timing(member, (hash, last), vehicle, deadlines, (lockstep, now))
    }

    /// Fly over the imperfect links of `model` with ticks of `cfg`: `starts` are the
    /// in-neighbours' tick-0 states (in the order of [`law_for`]), known before anything arrives.
    pub fn with_links(mut self, model: LinkModel, cfg: &StepConfig, starts: [Flat; 3]) -> Self {
        self.timing.links = Links {
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
        self.timing.losses = Some(Box::new(losses));
        self
    }
}

impl<V: Vehicle, C: TickClock> Timing<V> for Lockstep<C> {
    const WIRING: Wiring = Wiring {
        every_clock_message: true,
        flush_each_publish: false,
        fine_waits: false,
    };

    /// A grant may allow more ticks; a loss notice is followed (or is a fault).
    fn on_clock(
        &mut self,
        m: &mut Shared<V>,
        c: &ClockMsg,
        (now, _): (Duration, u64),
    ) -> Result<(), MemberFault> {
        // A grant shows the orchestrator lived a moment ago (the watch's question waits). Only
        // in lockstep, where grants keep coming while the team flies: in real time the one
        // start message would put every member's question at the same instants, a burst of
        // registry reads every half second that made about 1 % of the ticks late at N = 250.
        m.watch.heard_from_orchestrator(now);
        // Pass it on: the readers are woken before this member sleeps (or, at a stop, exits),
        // so a clock message the orchestrator sent only to the team's roots reaches everyone
        // (relayed wake-ups, cdm-iox `TeamLayout::with_relayed_wakes`).
        m.unnotified = true;
        if let Some(n) = c.loss() {
            let taken = match self.losses.as_mut() {
                Some(l) => l.on_notice(n, m.tick).map_err(MemberFault::Loss),
                None => Err(MemberFault::RepairUnsupported { tick: m.tick }),
            };
            if let Err(fault) = taken {
                m.watch.defer(Action::Fail {
                    report: None,
                    fault,
                });
            }
            self.progress = true;
        }
        match c.command() {
            ClockCommand::Run => {
                self.progress |= self.clock.on_grant(c.grant_tick);
                Ok(())
            }
            // A real-time team: this member was started without --realtime.
            ClockCommand::Realtime { .. } => Err(MemberFault::ModeMismatch {
                member_realtime: false,
            }),
            ClockCommand::Arm | ClockCommand::Stop(_) => Ok(()),
        }
    }

    /// Kept when it is of a tick still needed.
    fn on_neighbor(&mut self, m: &mut Shared<V>, slot: usize, msg: &StateMsg) {
        if msg.tick >= self.links.model.oldest_candidate(m.tick) {
            self.inbox[slot].insert(msg.tick, QuadState(msg.state).flat());
            self.progress = true;
        }
    }

    /// A repair's future in-neighbour: kept until its link applies.
    fn on_stranger(&mut self, m: &mut Shared<V>, msg: &StateMsg) {
        let tick = m.tick;
        if let Some(l) = self
            .losses
            .as_mut()
            .filter(|l| l.is_future_neighbor(msg.id, tick))
        {
            if msg.status() == AgentStatus::Ok && msg.scenario_hash == m.hash {
                l.keep(msg.id, msg.tick, QuadState(msg.state).flat());
                self.progress = true;
            }
        }
    }

    fn poll(&mut self, m: &mut Shared<V>, now: Duration) -> Action {
        if let Some(w) = self.losses.as_mut().and_then(|l| l.next_work()) {
            return Action::Repair(w);
        }
        if let Some(a) = self.advance(m) {
            return a;
        }
        if std::mem::take(&mut self.progress) {
            self.last_progress = now;
            return Action::Poll;
        }
        let limit = if self.clock.allowed().is_none() {
            m.deadlines.join
        } else {
            m.deadlines.silence
        };
        let deadline = self.last_progress + limit;
        match m.idle(now, Some(deadline), None) {
            Some(a) => a,
            None => m.silent(now.saturating_sub(self.last_progress), self.waiting_for(m)),
        }
    }
}

impl<C: TickClock> Lockstep<C> {
    /// One step of "advance as far as grants and neighbour data allow": a state to publish, a
    /// fault, or `None` when blocked (several ticks per wake-up, one action per call).
    fn advance<V: Vehicle>(&mut self, m: &mut Shared<V>) -> Option<Action> {
        while let Some(g) = self.clock.allowed() {
            let tick = m.tick;
            if m.published != Some(tick) && g >= tick {
                m.unnotified = true;
                self.progress = true;
                return Some(m.publish_tick());
            }
            if m.published != Some(tick) || tick >= m.last || g < tick + 1 {
                return None;
            }
            if self.losses.as_ref().is_some_and(|l| l.waits_at(tick)) {
                return None;
            }
            if let Some(a) = self.relink_if_due(m, tick) {
                return Some(a);
            }
            let flats = match self.neighbor_flats(m) {
                Ok(Some(f)) => f,
                Ok(None) => return None,
                Err((peer, later)) => {
                    let fault = MemberFault::TickGap { tick, peer, later };
                    return Some(m.fail(FaultCode::TickGap, peer, fault));
                }
            };
            if let Err(fault) = m.vehicle.fly_tick(tick, &flats) {
                return Some(m.vehicle_failed(tick, fault));
            }
            m.tick += 1;
            let oldest = self.links.model.oldest_candidate(m.tick);
            for b in self.inbox.iter_mut() {
                b.drop_before(oldest);
            }
            self.progress = true;
        }
        None
    }

    /// A repaired link that applies from `tick` (a loss notice's tick): the vehicle flies it
    /// and the in-neighbours' states come from the new neighbours, from this tick's step on.
    fn relink_if_due<V: Vehicle>(&mut self, m: &mut Shared<V>, tick: u64) -> Option<Action> {
        let member = self.losses.as_mut()?.due(tick)?;
        if m.vehicle.relink(&member).is_err() {
            let fault = MemberFault::RepairUnsupported { tick };
            return Some(Action::Fail {
                report: None,
                fault,
            });
        }
        let (law, ids) = law_for(&member);
        m.is_follower = matches!(law, Law::Follower { .. });
        let mut old = std::mem::take(&mut self.inbox);
        // A neighbour dropped here may come back at this very tick (a later notice of the same
        // tick, `MemberLosses::due`): its states are kept, not thrown away.
        if let Some(l) = self.losses.as_mut() {
            for (k, id) in m.neighbor_ids.iter().enumerate() {
                if !ids.contains(id) && l.is_future_neighbor(*id, tick) {
                    l.keep_all(*id, std::mem::take(&mut old[k]));
                }
            }
        }
        for (slot, id) in ids.iter().enumerate() {
            let kept = match m.neighbor_ids.iter().position(|j| j == id) {
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
            if *id != m.neighbor_ids[slot] {
                // As the engine: a new neighbour in a slot is known where it started until
                // its states arrive (`Engine::apply_repair`).
                let start = self.losses.as_ref().and_then(|l| l.start_of(*id));
                self.links.held[slot] = Heard {
                    tick: 0,
                    flat: Flat::rest(start.unwrap_or(self.rest.r)),
                };
            }
        }
        m.neighbor_ids = ids;
        tracing::info!(id = m.id, tick, in_neighbors = ?ids, "flying the repaired link");
        None
    }

    /// The in-neighbours' states of this tick; `None` while one is missing; `Err((peer, later))`
    /// when a later tick of `peer` arrived without this one (a sample was lost).
    fn neighbor_flats<V>(&mut self, m: &Shared<V>) -> Result<Option<[Flat; 3]>, (u32, u64)> {
        let mut flats = [self.rest; 3];
        if !m.is_follower {
            return Ok(Some(flats));
        }
        if !self.links.model.is_perfect() {
            return self.heard_flats(m);
        }
        let tick = m.tick;
        let mut ready = true;
        for (slot, f) in flats.iter_mut().enumerate() {
            match self.inbox[slot].get(tick) {
                Some(v) => *f = *v,
                None => {
                    if let Some(later) = self.inbox[slot].first_tick().filter(|&l| l > tick) {
                        return Err((m.neighbor_ids[slot], later));
                    }
                    ready = false;
                }
            }
        }
        Ok(ready.then_some(flats))
    }

    /// [`Self::neighbor_flats`] over imperfect links: once every state that may be usable at
    /// this tick is in (the one of tick `needed`, and in order those before it), the newest
    /// delivered state of each in-neighbour, brought to this tick.
    fn heard_flats<V>(&mut self, m: &Shared<V>) -> Result<Option<[Flat; 3]>, (u32, u64)> {
        let tick = m.tick;
        let l = &mut self.links;
        let need = l.model.needed(tick);
        if let Some(n) = need {
            let mut ready = true;
            for (slot, b) in self.inbox.iter().enumerate() {
                if b.get(n).is_none() {
                    if let Some(later) = b.last_tick().filter(|&l| l > n) {
                        return Err((m.neighbor_ids[slot], later));
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
        let (to, from) = (m.id, &m.neighbor_ids);
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

    fn waiting_for<V>(&self, m: &Shared<V>) -> WaitingFor {
        let tick = m.tick;
        match self.clock.allowed() {
            None => WaitingFor::Start,
            Some(g) if g < tick + 1 || m.published != Some(tick) => WaitingFor::Grant(tick + 1),
            Some(_) => {
                // Over delayed links tick k waits for the states of tick k - min delay.
                let need = self.links.model.needed(tick).unwrap_or(0);
                WaitingFor::States {
                    tick: need,
                    missing: (0..3)
                        .filter(|&k| self.inbox[k].get(need).is_none())
                        .map(|k| m.neighbor_ids[k])
                        .collect(),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
