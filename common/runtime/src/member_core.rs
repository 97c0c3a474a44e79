//! One member's side of the team protocol as a plain type, with no I/O: events in (a clock
//! message, a neighbour's state, whether the orchestrator lives, "now"), actions out (publish,
//! wake readers, ask about the orchestrator, wait, fail). The loop around it
//! ([`crate::member_loop`]) only moves messages between the core and a
//! [`MemberTransport`](crate::seams::MemberTransport).
//!
//! One core, two timings ([`Timing`]): in lockstep ([`crate::member_lockstep`]) the orchestrator
//! grants ticks and a follower waits for its in-neighbours' states of each tick (over the link
//! model of `cdm_model::link`); in real time ([`crate::realtime`]) the wall clock with this
//! member's phase offset says when a tick is due, and a follower flies on the newest state it
//! has of each in-neighbour. What both do alike lives here: the scenario check and the stop of
//! a clock message, which states are an in-neighbour's, the orchestrator watch and the pending
//! fault, publishing a tick's state, reporting a failed tick, and what an idle member does.

use std::time::Duration;

use cdm_model::formation::Member;
use cdm_model::step::{law_for, Law, StepFault};

use crate::member_steer::{MemberSteering, SteerFault};
use crate::member_watch::{report_fault, Watch};
use crate::messages::{
    AgentStatus, ClockCommand, ClockMsg, FaultCode, StateMsg, SteerNotice, NO_PEER,
};
use crate::seams::{Vehicle, VehicleFault};

pub use crate::member_protocol::{
    Action, Deadlines, Finished, MemberFault, WaitingFor, ALIVE_CHECK, WAIT_SLICE,
};

/// How the loop moves a timing's messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wiring {
    /// Read every clock message, oldest first (loss notices must not be skipped), rather than
    /// only the newest.
    pub every_clock_message: bool,
    /// Send each state as it is published: its readers look by their own clock, not because
    /// a neighbour woke them.
    pub flush_each_publish: bool,
    /// Meet the end of a wait to a fraction of a period (a tick's instant), not to the
    /// transport's coarser timeout.
    pub fine_waits: bool,
}

/// What paces a member and what its links deliver: the part of the protocol in which lockstep
/// and real time differ. The core hands each event on once it has done what both do alike.
pub trait Timing<V: Vehicle> {
    /// How the loop moves this timing's messages.
    const WIRING: Wiring;

    /// A clock message of this member's scenario, before the core looks for a stop: a grant, a
    /// start, a loss notice. `now` is this member's clock, `unix_now_ns` the system clock.
    fn on_clock(
        &mut self,
        m: &mut Shared<V>,
        c: &ClockMsg,
        clocks: (Duration, u64),
    ) -> Result<(), MemberFault>;

    /// An in-neighbour's state of this scenario (`slot` in the order of its law).
    fn on_neighbor(&mut self, m: &mut Shared<V>, slot: usize, msg: &StateMsg);

    /// A state of a member that is not an in-neighbour (yet).
    fn on_stranger(&mut self, m: &mut Shared<V>, msg: &StateMsg) {
        let _ = (m, msg);
    }

    /// The next action at `now`, once no fault is pending.
    fn poll(&mut self, m: &mut Shared<V>, now: Duration) -> Action;

    /// A new command notice was taken: the commanded plan flies from tick `m.tick` on.
    fn steered(&mut self, m: &Shared<V>, n: &SteerNotice) {
        let _ = (m, n);
    }

    /// What the member publishes when the stop arrives (its pacing figures), if anything; the
    /// loop then keeps it readable until the orchestrator's second stop.
    fn final_report(&self, m: &Shared<V>) -> Option<StateMsg> {
        let _ = m;
        None
    }
}

/// The member's state both timings share.
#[derive(Debug)]
pub struct Shared<V> {
    pub(crate) id: u32,
    pub(crate) hash: u64,
    /// The last tick of the plan.
    pub(crate) last: u64,
    pub(crate) vehicle: V,
    pub(crate) deadlines: Deadlines,
    /// The in-neighbours in the order of the law's weights (itself, for a leader).
    pub(crate) neighbor_ids: [u32; 3],
    pub(crate) is_follower: bool,
    /// The tick this member computes (lockstep) or flies (real time) next.
    pub(crate) tick: u64,
    pub(crate) published: Option<u64>,
    /// Readers not yet woken since something was published or passed on.
    pub(crate) unnotified: bool,
    pub(crate) watch: Watch,
    /// Commands to the team in flight (`None`: a command notice is a fault).
    pub(crate) steering: Option<Box<MemberSteering>>,
}

impl<V: Vehicle> Shared<V> {
    /// A command notice: the vehicle flies the commanded plan from now on (the same as the old
    /// one before the switch), and the flight ends at its last tick. True when it was a new one.
    fn steer(&mut self, n: SteerNotice) -> Result<bool, MemberFault> {
        let seq = n.seq;
        let Some(st) = self.steering.as_mut() else {
            return Err(MemberFault::Steer(SteerFault::Unsupported { seq }));
        };
        let Some(replan) = st.on_notice(n, self.tick).map_err(MemberFault::Steer)? else {
            return Ok(false);
        };
        if self.vehicle.replan(&replan.plan).is_err() {
            return Err(MemberFault::Steer(SteerFault::Unsupported { seq }));
        }
        tracing::info!(
            id = self.id,
            seq,
            switch_tick = n.tick,
            last_tick = replan.last_tick,
            "flying the commanded plan"
        );
        self.last = replan.last_tick;
        Ok(true)
    }

    /// Publishes this tick's state (once).
    pub(crate) fn publish_tick(&mut self) -> Action {
        let tick = self.tick;
        self.published = Some(tick);
        let state = self.vehicle.state();
        Action::Publish(StateMsg::ok(tick, self.hash, self.id, state))
    }

    /// A fault that is reported to the team (this member's state flagged with `code`).
    pub(crate) fn fail(&self, code: FaultCode, peer: u32, fault: MemberFault) -> Action {
        let state = self.vehicle.state();
        report_fault((self.id, self.hash, self.tick), state, (code, peer), fault)
    }

    /// The report of a failed tick `tick`.
    pub(crate) fn vehicle_failed(&self, tick: u64, fault: VehicleFault) -> Action {
        let (code, peer, fault) = report_of(tick, fault);
        self.fail(code, peer, fault)
    }

    /// Nothing to do now: ask about the orchestrator every [`ALIVE_CHECK`], wake the readers
    /// held back, else sleep at most a slice, and not past `deadline` or `until` (the next
    /// tick's instant). `None` once `deadline` has passed: the member gives up
    /// ([`Self::silent`]).
    pub(crate) fn idle(
        &mut self,
        now: Duration,
        deadline: Option<Duration>,
        until: Option<Duration>,
    ) -> Option<Action> {
        if self.watch.check_due(now) {
            return Some(Action::CheckOrchestrator);
        }
        if deadline.is_some_and(|d| now >= d) {
            return None;
        }
        if std::mem::take(&mut self.unnotified) {
            return Some(Action::NotifyReaders);
        }
        let mut slice = WAIT_SLICE;
        for t in [deadline, until].into_iter().flatten() {
            slice = slice.min(t.saturating_sub(now));
        }
        Some(Action::Wait(slice))
    }

    /// Gives up after `waited` without what it was `waiting_for` (unreported: the team knows).
    pub(crate) fn silent(&self, waited: Duration, waiting_for: WaitingFor) -> Action {
        let fault = MemberFault::Silent {
            tick: self.tick,
            waited,
            waiting_for,
        };
        Action::Fail {
            report: None,
            fault,
        }
    }
}

/// One member's protocol state, paced by `T` (lockstep or real time).
#[derive(Debug)]
pub struct MemberCore<V, T> {
    pub(crate) m: Shared<V>,
    pub(crate) timing: T,
}

impl<V, T> MemberCore<V, T> {
    /// `member` of the scenario with content hash `hash` and last tick `last`, flying
    /// `vehicle` with `timing`.
    pub(crate) fn with_timing(
        member: &Member,
        (hash, last): (u64, u64),
        vehicle: V,
        deadlines: Deadlines,
        (timing, now): (T, Duration),
    ) -> Self {
        let (law, neighbor_ids) = law_for(member);
        let m = Shared {
            id: member.id,
            hash,
            last,
            vehicle,
            deadlines,
            neighbor_ids,
            is_follower: matches!(law, Law::Follower { .. }),
            tick: 0,
            published: None,
            unnotified: false,
            watch: Watch::new(now),
            steering: None,
        };
        Self { m, timing }
    }

    /// The same core, following the orchestrator's command notices with `steering`; without
    /// it a notice is a fault.
    pub fn with_steering(mut self, steering: MemberSteering) -> Self {
        self.m.steering = Some(Box::new(steering));
        self
    }

    /// This member's id.
    pub fn id(&self) -> u32 {
        self.m.id
    }

    /// The scenario's content hash.
    pub fn hash(&self) -> u64 {
        self.m.hash
    }

    /// The tick this member computes or flies next (its last published one once it has
    /// published, in lockstep).
    pub fn tick(&self) -> u64 {
        self.m.tick
    }

    /// The vehicle flown.
    pub fn vehicle(&self) -> &V {
        &self.m.vehicle
    }
}

impl<V: Vehicle, T: Timing<V>> MemberCore<V, T> {
    /// A clock message (read while this member's clock reads `now` and the system clock
    /// `unix_now_ns`): a grant or a start (may allow more ticks) or a stop (the member is
    /// finished).
    pub fn on_clock(
        &mut self,
        c: &ClockMsg,
        now: Duration,
        unix_now_ns: u64,
    ) -> Result<Option<Finished>, MemberFault> {
        if c.scenario_hash != self.m.hash {
            return Err(MemberFault::ScenarioMismatch {
                mine: self.m.hash,
                team: c.scenario_hash,
            });
        }
        self.timing.on_clock(&mut self.m, c, (now, unix_now_ns))?;
        if let Some(n) = c.steer() {
            if self.m.steer(n)? {
                self.timing.steered(&self.m, &n);
            }
        }
        match c.command() {
            ClockCommand::Stop(_) => Ok(Some(Finished {
                tick: self.m.tick,
                reason: c.reason,
            })),
            // A MAVLink member answers the arm order before its core runs (cdm-mavlink
            // `team_arm`); the model has nothing to arm. Grants and starts are the timing's.
            ClockCommand::Arm | ClockCommand::Run | ClockCommand::Realtime { .. } => Ok(None),
        }
    }

    /// A state from the transport. A neighbour's fault notice is not a state: the orchestrator
    /// stops the team once every tick before the fault is complete (as the engine would have
    /// flown them). A state of another scenario is a fault reported to the team.
    pub fn on_neighbor(&mut self, msg: &StateMsg) {
        let Some(slot) = self.m.neighbor_ids.iter().position(|n| *n == msg.id) else {
            self.timing.on_stranger(&mut self.m, msg);
            return;
        };
        if msg.status() != AgentStatus::Ok {
            return;
        }
        if msg.scenario_hash != self.m.hash && !self.m.watch.is_pending() {
            let fault = MemberFault::ForeignState {
                tick: self.m.tick,
                peer: msg.id,
                peer_tick: msg.tick,
            };
            let fail = self.m.fail(FaultCode::NeighborFault, msg.id, fault);
            self.m.watch.defer(fail);
            return;
        }
        self.timing.on_neighbor(&mut self.m, slot, msg);
    }

    /// The answer to [`Action::CheckOrchestrator`].
    pub fn on_orchestrator_alive(&mut self, alive: bool) {
        self.m.watch.orchestrator_alive(alive, self.m.tick);
    }

    /// The next action at time `now` (this member's monotonic clock). Call it until it returns
    /// [`Action::Poll`], [`Action::NotifyReaders`] or [`Action::Wait`] (then read the inputs)
    /// or [`Action::Fail`].
    pub fn poll(&mut self, now: Duration) -> Action {
        if let Some(a) = self.m.watch.take() {
            return a;
        }
        self.timing.poll(&mut self.m, now)
    }

    /// What to publish when the stop arrives, if anything ([`Timing::final_report`]).
    pub fn final_report(&self) -> Option<StateMsg> {
        self.timing.final_report(&self.m)
    }
}

/// The in-neighbours of `member` in the order of its weights (itself, for a leader): the order
/// of a lockstep core's `with_links` starts and of a real-time core's neighbour positions.
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
        VehicleFault::Link { what, loss } => (
            FaultCode::of_vehicle(loss),
            NO_PEER,
            MemberFault::Vehicle { tick, what },
        ),
    }
}
