//! One team member as a process: the member core (cdm-runtime, no I/O) flown over the iceoryx2
//! ports by the generic loop. This file only loads the scenario, checks the binary flies this
//! member's role, opens the ports and maps the outcome to an error with an exit code.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use cdm_mavlink::udp::UdpError;
use cdm_mavlink::{PlantError, TeamArmError};
use cdm_runtime::member_core::{in_neighbors, subscriptions};
use cdm_runtime::member_lockstep::LockstepCore;
use cdm_runtime::member_loop::{fly, LoopError};
use cdm_runtime::member_loss::{LossFault, MemberLosses};
use cdm_runtime::realtime::{RealtimeCore, RealtimeSetup};
use cdm_runtime::seams::{Clock, LockstepClock, ModelVehicle, MonotonicClock};

use crate::member_vehicle::BeforeStart;
use crate::options::LinkArgs;
use crate::vehicles::Vehicles;
use cdm_core::dynamics::QuadState;
use cdm_core::formation::{Member, Role};
use cdm_core::loss_log::LossLog;
use cdm_core::scenario::{Checks, Scenario, ScenarioError};
use cdm_core::step::StepFault;
use cdm_iox::{MemberPorts, TeamName, TransportError};

pub use cdm_runtime::member_core::{Deadlines, Finished, MemberFault};

/// Which binary is running: `leader` flies primary and secondary leaders, `agent` flies followers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Leader,
    Agent,
}

impl Kind {
    fn accepts(self, role: Role) -> bool {
        match self {
            Kind::Leader => role.is_leader(),
            Kind::Agent => role == Role::Follower,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Kind::Leader => "leader",
            Kind::Agent => "agent",
        }
    }
}

/// How the member flies: on the orchestrator's grants (the default) or on its own clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    Lockstep,
    /// `--realtime`: a neighbour whose newest state is older than `stale_after` is a fault.
    Realtime {
        stale_after: Duration,
    },
}

/// Why a member stopped without finishing.
#[derive(Debug, thiserror::Error)]
pub enum MemberError {
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// A bad `--link-*` or `--seed` value (the message names the flag).
    #[error("{0}")]
    Link(String),
    /// A bad `--link-*` or `--seed` value, or a `[link]` table the scenario refuses.
    #[error(transparent)]
    LinkArgs(#[from] crate::options::LinkArgsError),
    #[error("agent {id} is not in scenario {origin}")]
    NotInScenario { id: u32, origin: String },
    #[error("agent {id} is a {role} in {origin}; the `{binary}` binary flies {flies}")]
    WrongRole {
        id: u32,
        role: &'static str,
        binary: &'static str,
        flies: &'static str,
        origin: String,
    },
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// The MAVLink vehicle could not be reached or armed before the team started.
    #[error(transparent)]
    VehicleLink(#[from] PlantError),
    /// A bad `--vehicle-origins` file (names the file, the line and the member).
    #[error(transparent)]
    VehicleOrigins(#[from] crate::vehicle_origins::OriginsError),
    /// Waiting for the team's arm order failed (the vehicle, the orchestrator, a mismatch).
    #[error(transparent)]
    TeamArm(#[from] TeamArmError<TransportError>),
    #[error("agent {id}: the orchestrator of team {team} is gone (at tick {tick}); stopping")]
    OrchestratorLost { id: u32, team: String, tick: u64 },
    #[error("agent {id}: nothing happened for {waited:?} at tick {tick} (waiting for {waiting_for}); stopping")]
    Silent {
        id: u32,
        tick: u64,
        waited: Duration,
        waiting_for: String,
    },
    #[error("agent {id} at tick {tick}: {fault}")]
    Step {
        id: u32,
        tick: u64,
        fault: StepFault,
    },
    /// `what` names the member already (the vehicle link's message).
    #[error("{what} (at tick {tick})")]
    Vehicle { id: u32, tick: u64, what: String },
    #[error("agent {id} at tick {tick}: in-neighbour {peer} {what}")]
    Neighbor {
        id: u32,
        tick: u64,
        peer: u32,
        what: String,
    },
    #[error("agent {id} at tick {tick}: cannot follow the loss notices: {what}")]
    Loss { id: u32, tick: u64, what: String },
    #[error("agent {id}: interrupted at tick {tick}")]
    Interrupted { id: u32, tick: u64 },
    #[error("agent {id}: team {team} flies {team_mode} and this member {mode}: start it {fix}")]
    ModeMismatch {
        id: u32,
        team: String,
        team_mode: &'static str,
        mode: &'static str,
        fix: &'static str,
    },
}

impl MemberError {
    /// Exit code: 2 for bad input (scenario, id, role, mismatch), 3 for runtime faults.
    pub fn exit_code(&self) -> i32 {
        match self {
            MemberError::Scenario(_)
            | MemberError::Link(_)
            | MemberError::LinkArgs(_)
            | MemberError::NotInScenario { .. }
            | MemberError::WrongRole { .. }
            | MemberError::ModeMismatch { .. } => 2,
            MemberError::Transport(
                TransportError::ScenarioMismatch { .. }
                | TransportError::NotInTeam { .. }
                | TransportError::TeamNotFound { .. }
                | TransportError::AgentAlreadyRunning { .. }
                | TransportError::InvalidTeamName { .. },
            ) => 2,
            // A port that cannot be bound or does not exist is the operator's input.
            MemberError::VehicleLink(PlantError::Udp(
                UdpError::Bind { .. } | UdpError::PortOutOfRange { .. },
            )) => 2,
            // --arm on a member of a team launched without it.
            MemberError::TeamArm(TeamArmError::NotOrdered { .. }) => 2,
            MemberError::VehicleOrigins(_) => 2,
            _ => 3,
        }
    }
}

/// How a member flies: its deadlines, lockstep or real time, and what it flies.
#[derive(Debug, Clone, PartialEq)]
pub struct Flight {
    pub deadlines: Deadlines,
    pub mode: Mode,
    pub vehicles: Vehicles,
}

/// Run one member until the orchestrator stops the team.
pub fn run_member(
    kind: Kind,
    scenario_path: &Path,
    team: &TeamName,
    (id, link): (u32, &LinkArgs),
    flight: &Flight,
    interrupted: &AtomicBool,
) -> Result<Finished, MemberError> {
    let Flight {
        deadlines,
        mode,
        ref vehicles,
    } = *flight;
    let s = Scenario::load(scenario_path, Checks::Member)?;
    let s = link.apply(&s)?;
    if let Some(why) = match mode {
        Mode::Realtime { stale_after } => crate::options::realtime_links_refusal(&s, stale_after),
        Mode::Lockstep => None,
    } {
        return Err(MemberError::Link(why));
    }
    let Some(me) = s.formation.member(id).cloned() else {
        return Err(MemberError::NotInScenario {
            id,
            origin: s.origin.clone(),
        });
    };
    if !kind.accepts(me.role) {
        return Err(MemberError::WrongRole {
            id,
            role: me.role.as_str(),
            binary: kind.name(),
            flies: if kind == Kind::Leader {
                "primary and secondary leaders"
            } else {
                "followers"
            },
            origin: s.origin.clone(),
        });
    }
    let member = Joined {
        s: &s,
        me: &me,
        team,
        deadlines,
        mode,
    };
    match vehicles {
        Vehicles::Model => member.fly(
            ModelVehicle::new(s.step_config(), &s.plan, &me),
            interrupted,
        ),
        // The vehicle first: the team starts only once every member's vehicle is heard (and
        // armed with --arm), since a member joins only then.
        Vehicles::Mavlink(o) => {
            let plant = crate::vehicles::connect(&s, &me, o, deadlines.join, interrupted)?;
            member.fly(plant, interrupted)
        }
    }
}

/// A member about to join its team.
struct Joined<'a> {
    s: &'a Scenario,
    me: &'a Member,
    team: &'a TeamName,
    deadlines: Deadlines,
    mode: Mode,
}

impl Joined<'_> {
    /// Opens the ports and flies `vehicle` until the team stops.
    fn fly<V: BeforeStart>(
        &self,
        vehicle: V,
        interrupted: &AtomicBool,
    ) -> Result<Finished, MemberError> {
        let (s, me, team, id) = (self.s, self.me, self.team, self.me.id);
        let hash = s.content_hash();
        let ins = subscriptions(me);
        let outs = s.formation.readers_of(id);
        let mut ports = MemberPorts::open(team, id, hash, &ins, &outs)?;
        tracing::info!(
            id,
            role = me.role.as_str(),
            team = %team,
            subscribes = ?ins,
            notifies = ?outs,
            "joined: subscribed to state services of {:?}",
            ins
        );
        // The deadlines start once the ports are open (opening takes seconds at N = 1000).
        let clock = MonotonicClock::start();
        let deadlines = self.deadlines;
        if let Mode::Realtime { stale_after } = self.mode {
            let setup = RealtimeSetup {
                hash,
                last: s.last_tick(),
                dt_s: s.dt_s(),
                stale_after,
                deadlines,
                links: s.link_model(),
            };
            let waits = (&clock, deadlines.join);
            let first = vehicle.before_start(&mut ports, hash, waits, interrupted)?;
            let link = vehicle.link();
            let at_rest = neighbor_positions(s, me);
            let mut core = RealtimeCore::realtime(me, at_rest, setup, vehicle, clock.now());
            return crate::member_vehicle::fly(
                &mut core,
                &mut ports,
                (first, link),
                &clock,
                interrupted,
            )
            .map_err(|e| MemberError::from_loop(e, id, team));
        }
        let parts = (vehicle, LockstepClock::default());
        let starts = in_neighbors(me).map(|n| {
            QuadState::hover(s.formation.member(n).map_or(me.position, |m| m.position)).flat()
        });
        let mut core = LockstepCore::new(me, hash, s.last_tick(), parts, deadlines, clock.now())
            .with_links(s.link_model(), &s.step_config(), starts)
            .with_losses(MemberLosses::new(me, LossLog::new(s), &ins, &outs));
        let inject = cdm_runtime::fault_inject::from_env(id);
        fly(&mut core, &mut ports, &clock, interrupted, inject.as_ref())
            .map_err(|e| MemberError::from_loop(e, id, team))
    }
}

/// A follower's in-neighbours' initial positions, in the order of its law (a real-time follower
/// assumes them at rest there until their first state arrives); zeros for a leader.
fn neighbor_positions(s: &Scenario, me: &cdm_core::formation::Member) -> [cdm_core::math::Vec3; 3] {
    let mut at = [cdm_core::math::Vec3::zeros(); 3];
    if let Some(link) = me.link.filter(|_| me.role == Role::Follower) {
        for (p, j) in at.iter_mut().zip(link.in_neighbors) {
            if let Some(m) = s.formation.member(j) {
                *p = m.position;
            }
        }
    }
    at
}

impl MemberError {
    /// The loop's outcome as this process reports it (messages unchanged since the loop was one
    /// function).
    fn from_loop(e: LoopError<TransportError>, id: u32, team: &TeamName) -> Self {
        match e {
            LoopError::Transport(e) => MemberError::Transport(e),
            LoopError::Interrupted { tick } => MemberError::Interrupted { id, tick },
            LoopError::Fault(f) => Self::from_fault(f, id, team),
        }
    }

    /// A fault the member's core reported, as this process reports it.
    fn from_fault(f: MemberFault, id: u32, team: &TeamName) -> Self {
        match f {
            MemberFault::ScenarioMismatch { mine, team: theirs } => {
                MemberError::Transport(TransportError::ScenarioMismatch {
                    team: team.clone(),
                    id,
                    mine,
                    team_hash: cdm_iox::scenario_hash_value(theirs),
                })
            }
            MemberFault::OrchestratorLost { tick } => MemberError::OrchestratorLost {
                id,
                team: team.to_string(),
                tick,
            },
            MemberFault::Silent {
                tick,
                waited,
                waiting_for,
            } => MemberError::Silent {
                id,
                tick,
                waited,
                waiting_for: waiting_for.to_string(),
            },
            MemberFault::Step { tick, fault } => MemberError::Step { id, tick, fault },
            MemberFault::Vehicle { tick, what } => MemberError::Vehicle { id, tick, what },
            MemberFault::ForeignState {
                tick,
                peer,
                peer_tick,
            } => MemberError::Neighbor {
                id,
                tick,
                peer,
                what: format!("sent a state of another scenario (tick {peer_tick})"),
            },
            MemberFault::Loss(f) => Self::from_loss(f, id),
            MemberFault::RepairUnsupported { tick } => MemberError::Loss {
                id,
                tick,
                what: "this vehicle or transport cannot switch links in flight".into(),
            },
            MemberFault::TickGap { tick, peer, later } => MemberError::Neighbor {
                id,
                tick,
                peer,
                what: format!("skipped from tick {tick} to {later}"),
            },
            MemberFault::NeighborStale { tick, peer, age } => MemberError::Neighbor {
                id,
                tick,
                peer,
                what: format!(
                    "sent nothing for {:.0} ms (newest state older than the bound): \
                         holding position",
                    age.as_secs_f64() * 1e3
                ),
            },
            MemberFault::ModeMismatch { member_realtime } => {
                Self::mode_mismatch(member_realtime, id, team)
            }
        }
    }

    /// A loss notice this member cannot act on.
    fn from_loss(f: LossFault, id: u32) -> Self {
        let (tick, what) = match f {
            LossFault::Missed { seen, got } => (
                0,
                format!("notice {got} arrived after notice {seen}: one was missed"),
            ),
            LossFault::SelfLost { tick } => {
                (tick, "the orchestrator declared this agent lost".into())
            }
            LossFault::Late { tick, at } => (
                tick,
                format!("the repair changes this agent's link from tick {at}, already flown"),
            ),
        };
        MemberError::Loss { id, tick, what }
    }

    /// The member flies in real time and the team in lockstep, or the other way round.
    fn mode_mismatch(member_realtime: bool, id: u32, team: &TeamName) -> Self {
        MemberError::ModeMismatch {
            id,
            team: team.to_string(),
            team_mode: if member_realtime {
                "lockstep"
            } else {
                "in real time"
            },
            mode: if member_realtime {
                "in real time"
            } else {
                "lockstep"
            },
            fix: if member_realtime {
                "without --realtime"
            } else {
                "with --realtime"
            },
        }
    }
}
