//! The seams a member is flown through, so that a second transport (the network), a second clock
//! (the wall clock) and a second plant (a real vehicle) plug in under the same protocol core.
//! Every method is generic (no `dyn`) and the hot path allocates nothing.

use std::borrow::Cow;
use std::fmt;
use std::time::{Duration, Instant};

use cdm_model::dynamics::{Flat, QuadState};
use cdm_model::formation::Member;
use cdm_model::plan::TeamPlan;
use cdm_model::step::{law_for, step_at, Law, StepConfig, StepFault, TickAt};

use crate::messages::{ClockMsg, StateMsg, VehicleLoss};

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
    /// Wakes every reader of this member's state (sending first what [`Self::publish_quietly`]
    /// held back).
    fn notify_readers(&mut self) -> Result<(), Self::Error>;
    /// Sends what [`Self::publish_quietly`] held back, without waking anyone: for a member whose
    /// readers look by the clock instead of waiting for a wake-up (real time), and before an
    /// injected fault. The default does nothing (a transport that sends every state at once).
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
    /// Drains every in-neighbour's states (neighbours in id order, oldest first) into `f`.
    fn receive_neighbors(&mut self, f: impl FnMut(StateMsg)) -> Result<usize, Self::Error>;
    /// The newest message of the clock channel since the last call, if any.
    fn latest_clock(&mut self) -> Result<Option<ClockMsg>, Self::Error>;
    /// Sleeps until woken or `timeout` passes; true when woken.
    fn wait(&mut self, timeout: Duration) -> Result<bool, Self::Error>;
    /// False once the orchestrator is known to be gone.
    fn orchestrator_alive(&self) -> bool;
    /// Every message of the clock channel since the last call, oldest first (loss notices must
    /// not be skipped). The default hands over only the newest ([`Self::latest_clock`]).
    fn receive_clock(&mut self, mut f: impl FnMut(ClockMsg)) -> Result<usize, Self::Error> {
        Ok(self.latest_clock()?.map(&mut f).map_or(0, |()| 1))
    }
    /// After a loss: subscribe to these members' states and notify these members' wake-ups
    /// (the repaired graph's new links). Ok(false) when this transport cannot (the default):
    /// the member then stops with a fault rather than fly without its new neighbours.
    fn connect(&mut self, subscribe: &[u32], notify: &[u32]) -> Result<bool, Self::Error> {
        let _ = (subscribe, notify);
        Ok(false)
    }
    /// Every new link of a repair is connected: deliver to new readers the states they missed
    /// (published before they subscribed), then wake every reader. Ok(false) when this
    /// transport cannot (the default).
    fn hand_over(&mut self) -> Result<bool, Self::Error> {
        Ok(false)
    }
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

/// Why a vehicle could not fly a tick.
#[derive(Debug, Clone, PartialEq)]
pub enum VehicleFault {
    /// The model's tick failed (controller, or a neighbour's non-finite state).
    Step(StepFault),
    /// The link to a real vehicle failed: lost (no HEARTBEAT for `--heartbeat-timeout`, no
    /// position for `--position-timeout`), never heard, refused to arm, or taken over. `what`
    /// is the link's own message, which names the member (the link's typed error lives in its
    /// crate, which this one does not know); `loss` what kind of loss it is for the team.
    Link { what: String, loss: VehicleLoss },
}

impl fmt::Display for VehicleFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            VehicleFault::Step(s) => s.fmt(f),
            VehicleFault::Link { what, .. } => f.write_str(what),
        }
    }
}

impl std::error::Error for VehicleFault {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            VehicleFault::Step(s) => Some(s),
            VehicleFault::Link { .. } => None,
        }
    }
}

impl From<StepFault> for VehicleFault {
    fn from(f: StepFault) -> Self {
        VehicleFault::Step(f)
    }
}

/// What a member flies: the 12-state quadcopter model ([`ModelVehicle`]), or a real vehicle
/// (cdm-mavlink's `MavlinkPlant`) that takes the same tick's inputs and reports its measured
/// state.
pub trait Vehicle {
    /// The full state published on the wire (the dynamics module's layout).
    fn state(&self) -> [f64; 12];
    /// Flies from `tick` to `tick + 1`, given the in-neighbours' tick-`tick` outputs.
    fn fly_tick(&mut self, tick: u64, neighbors: &[Flat; 3]) -> Result<(), VehicleFault>;
    /// Flies the tick that starts at `at.tick * dt + at.offset_s` (a real-time member's phase),
    /// given the in-neighbours' outputs at that time. A vehicle that keeps its own time (a real
    /// one) has nothing to shift: by default this is [`Self::fly_tick`].
    fn fly_tick_at(&mut self, at: TickAt, neighbors: &[Flat; 3]) -> Result<(), VehicleFault> {
        self.fly_tick(at.tick, neighbors)
    }
    /// Flies `member`'s link from now on (a repair after a loss: new in-neighbours and eq. 18
    /// weights, or none for a follower degraded to its plan). The default refuses: a vehicle
    /// that computes its own law must say how it switches.
    fn relink(&mut self, member: &Member) -> Result<(), RelinkUnsupported> {
        let _ = member;
        Err(RelinkUnsupported)
    }
    /// Flies `plan` from now on (a command to the team in flight: the same plan before its
    /// switch). The default refuses: a vehicle that keeps its own plan must say how it
    /// switches.
    fn replan(&mut self, plan: &TeamPlan) -> Result<(), RelinkUnsupported> {
        let _ = plan;
        Err(RelinkUnsupported)
    }
}

/// A vehicle that cannot switch links in flight.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RelinkUnsupported;

/// The 12-state model flown by `step::step` (the engine flies the very same function).
#[derive(Debug, Clone)]
pub struct ModelVehicle<'a> {
    cfg: StepConfig,
    /// The launched plan, or the commanded one once a command arrived.
    plan: Cow<'a, TeamPlan>,
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
            plan: Cow::Borrowed(plan),
            law,
            neighbor_ids,
            x: QuadState::hover(member.start),
        }
    }
}

impl Vehicle for ModelVehicle<'_> {
    fn state(&self) -> [f64; 12] {
        self.x.0
    }

    fn fly_tick(&mut self, tick: u64, neighbors: &[Flat; 3]) -> Result<(), VehicleFault> {
        // A lockstep tick is a tick with no phase offset (as `step` is `step_at`).
        let at = TickAt {
            tick,
            offset_s: 0.0,
        };
        self.fly_tick_at(at, neighbors)
    }

    fn fly_tick_at(&mut self, at: TickAt, neighbors: &[Flat; 3]) -> Result<(), VehicleFault> {
        let next = step_at(
            &self.cfg,
            &self.plan,
            &self.law,
            at,
            &self.x,
            neighbors,
            &self.neighbor_ids,
        )?;
        self.x = next;
        Ok(())
    }

    fn relink(&mut self, member: &Member) -> Result<(), RelinkUnsupported> {
        (self.law, self.neighbor_ids) = law_for(member);
        Ok(())
    }

    fn replan(&mut self, plan: &TeamPlan) -> Result<(), RelinkUnsupported> {
        self.plan = Cow::Owned(plan.clone());
        Ok(())
    }
}
