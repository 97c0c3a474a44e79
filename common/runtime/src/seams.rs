//! The seams a member is flown through, so that a second transport (the network), a second clock
//! (the wall clock) and a second plant (a real vehicle) plug in under the same protocol core.
//! Every method is generic (no `dyn`) and the hot path allocates nothing.

use std::time::{Duration, Instant};

use cdm_core::dynamics::{Flat, QuadState};
use cdm_core::formation::Member;
use cdm_core::plan::TeamPlan;
use cdm_core::step::{law_for, step, step_at, Law, StepConfig, StepFault, TickAt};

use crate::messages::{ClockMsg, StateMsg};

/// What a member needs from a transport: publish its state, receive its in-neighbours' states,
/// read the clock channel, wake its readers, and sleep until woken. The iceoryx2 backend
/// (cdm-iox `MemberPorts`) implements it; tests use an in-memory fake.
pub trait MemberTransport {
    /// The backend's error (kept whole: callers keep its source chain).
    type Error;
    /// Publishes `msg` and wakes the readers at once.
    fn publish(&mut self, msg: StateMsg) -> Result<usize, Self::Error>;
    /// Publishes `msg` without waking anyone; [`Self::notify_readers`] must follow before sleep.
    fn publish_quietly(&mut self, msg: StateMsg) -> Result<usize, Self::Error>;
    /// Wakes every reader of this member's state.
    fn notify_readers(&mut self) -> Result<(), Self::Error>;
    /// Drains every in-neighbour's states (neighbours in id order, oldest first) into `f`.
    fn receive_neighbors(&mut self, f: impl FnMut(StateMsg)) -> Result<usize, Self::Error>;
    /// The newest message of the clock channel since the last call, if any.
    fn latest_clock(&mut self) -> Result<Option<ClockMsg>, Self::Error>;
    /// Sleeps until woken or `timeout` passes; true when woken.
    fn wait(&mut self, timeout: Duration) -> Result<bool, Self::Error>;
    /// False once the orchestrator is known to be gone.
    fn orchestrator_alive(&self) -> bool;
}

/// Where "now" comes from for deadlines. Simulation time is never read from it (it is
/// `tick * dt`); it only bounds how long a member waits.
pub trait Clock {
    /// Time since this clock started (monotonic).
    fn now(&self) -> Duration;
}

/// The process's monotonic clock.
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock(Instant);

impl MonotonicClock {
    /// A clock that reads zero now.
    pub fn start() -> Self {
        Self(Instant::now())
    }
}

impl Clock for MonotonicClock {
    fn now(&self) -> Duration {
        self.0.elapsed()
    }
}

/// Which ticks a member may compute. Lockstep: the orchestrator grants them on the clock channel
/// (the first implementation); a wall clock would grant tick k at `k * dt` of real time.
pub trait TickClock {
    /// Takes a grant of the clock channel; true when it allows more ticks than before.
    fn on_grant(&mut self, grant_tick: u64) -> bool;
    /// The last tick this member may compute, or `None` before the team started.
    fn allowed(&self) -> Option<u64>;
}

/// Ticks granted by the orchestrator: grants only grow, a stale or repeated one changes nothing.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LockstepClock {
    grant: Option<u64>,
}

impl TickClock for LockstepClock {
    fn on_grant(&mut self, grant_tick: u64) -> bool {
        if self.grant.is_none_or(|g| grant_tick > g) {
            self.grant = Some(grant_tick);
            return true;
        }
        false
    }

    fn allowed(&self) -> Option<u64> {
        self.grant
    }
}

/// What a member flies: today the 12-state quadcopter model; later a real vehicle that takes
/// the same tick's inputs and reports its state.
pub trait Vehicle {
    /// The full state published on the wire (the dynamics module's layout).
    fn state(&self) -> [f64; 12];
    /// Flies from `tick` to `tick + 1`, given the in-neighbours' tick-`tick` outputs.
    fn fly_tick(&mut self, tick: u64, neighbors: &[Flat; 3]) -> Result<(), StepFault>;
    /// Flies the tick that starts at `at.tick * dt + at.offset_s` (a real-time member's phase),
    /// given the in-neighbours' outputs at that time. A vehicle that keeps its own time (a real
    /// one) has nothing to shift: by default this is [`Self::fly_tick`].
    fn fly_tick_at(&mut self, at: TickAt, neighbors: &[Flat; 3]) -> Result<(), StepFault> {
        self.fly_tick(at.tick, neighbors)
    }
}

/// The 12-state model flown by `step::step` (the engine flies the very same function).
#[derive(Debug, Clone)]
pub struct ModelVehicle<'a> {
    cfg: StepConfig,
    plan: &'a TeamPlan,
    law: Law,
    neighbor_ids: [u32; 3],
    x: QuadState,
}

impl<'a> ModelVehicle<'a> {
    /// `member` hovering at its initial position.
    pub fn new(cfg: StepConfig, plan: &'a TeamPlan, member: &Member) -> Self {
        let (law, neighbor_ids) = law_for(member);
        Self {
            cfg,
            plan,
            law,
            neighbor_ids,
            x: QuadState::hover(member.position),
        }
    }
}

impl Vehicle for ModelVehicle<'_> {
    fn state(&self) -> [f64; 12] {
        self.x.0
    }

    fn fly_tick(&mut self, tick: u64, neighbors: &[Flat; 3]) -> Result<(), StepFault> {
        let next = step(
            &self.cfg,
            self.plan,
            &self.law,
            tick,
            &self.x,
            neighbors,
            &self.neighbor_ids,
        )?;
        self.x = next;
        Ok(())
    }

    fn fly_tick_at(&mut self, at: TickAt, neighbors: &[Flat; 3]) -> Result<(), StepFault> {
        let next = step_at(
            &self.cfg,
            self.plan,
            &self.law,
            at,
            &self.x,
            neighbors,
            &self.neighbor_ids,
        )?;
        self.x = next;
        Ok(())
    }
}
