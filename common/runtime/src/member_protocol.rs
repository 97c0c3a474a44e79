//! What a member's protocol core hears of and says, in lockstep and in real time alike: its
//! deadlines, the actions it asks of the loop, and the faults it stops on. Plain types, so the
//! core ([`crate::member_core`]), its watch ([`crate::member_watch`]) and both timings use them
//! without depending on one another.

use std::fmt;
use std::time::Duration;

use cdm_model::step::StepFault;

use crate::member_loss::{LossFault, LossWork};
use crate::messages::StateMsg;

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
    /// A command notice this member cannot follow (missed, too late, unknown, or a vehicle
    /// that cannot change its plan).
    Steer(crate::member_steer::SteerFault),
}

/// What the loop must do next.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Publish this state without waking its readers yet (notify on block).
    Publish(StateMsg),
    /// Wake the readers, then read the inputs again before sleeping (they may answer at once).
    NotifyReaders,
    /// Ask whether the orchestrator lives and tell the core (`MemberCore::on_orchestrator_alive`).
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
