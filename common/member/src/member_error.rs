//! Why a member process stopped without finishing, with its exit code: the one error the
//! member's files return, in a file of its own so that they import it without importing each
//! other.

use std::time::Duration;

use cdm_iox::{TeamName, TransportError};
use cdm_mavlink::udp::UdpError;
use cdm_mavlink::{PlantError, TeamArmError};
use cdm_model::step::StepFault;
use cdm_runtime::member_core::MemberFault;
use cdm_runtime::member_loop::LoopError;
use cdm_runtime::member_loss::LossFault;
use cdm_scenario::ScenarioError;

use crate::vehicle_origins::OriginsError;

/// Why the MAVLink options do not fit the scenario.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    #[error(transparent)]
    Origins(#[from] OriginsError),
    /// `--disarm-at-end` on a scenario that does not end on the ground.
    #[error("--disarm-at-end: the scenario has no [landing] (the vehicles would be disarmed in the air)")]
    DisarmWithoutLanding,
    /// `--vehicle-origin(s)` on a scenario with an `[origin]`, whose vehicles fly in global
    /// coordinates and have no use for a local origin.
    #[error("--vehicle-origin and --vehicle-origins are for local NED; the scenario has an [origin], so its vehicles fly latitude and longitude (leave them out)")]
    LocalOriginOutdoors,
    /// `--upload-fence` without an `[origin]`: fence items are latitudes and longitudes.
    #[error("--upload-fence: the scenario has no [origin] (a vehicle's fence is in latitude and longitude)")]
    FenceWithoutOrigin,
    /// `--upload-fence` with nothing to upload.
    #[error(
        "--upload-fence: the scenario has no [geofence] and no [[obstacle]] (nothing to upload)"
    )]
    NoFence,
}

/// Why a member stopped without finishing.
#[derive(Debug, thiserror::Error)]
pub enum MemberError {
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// Links too slow for real time (names the delay and the stale bound).
    #[error(transparent)]
    StaleLinks(crate::options::StaleLinks),
    /// `--record DIR`: the recording cannot be created (names the file).
    #[error("--record: {0}")]
    Recording(cdm_recording::WriterError),
    /// A bad `--link-*` or `--seed` value, or a `[link]` table the scenario refuses.
    #[error(transparent)]
    LinkOverrides(#[from] crate::options::LinkOverrideError),
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
    /// `--disarm-at-end`: the vehicle was not seen landed and disarmed after a complete flight
    /// (the message names the member).
    #[error(transparent)]
    Landing(#[from] cdm_mavlink::plant::DisarmError),
    /// A bad `--vehicle-origins` file (names the file, the line and the member).
    #[error(transparent)]
    VehicleOrigins(#[from] OriginsError),
    /// MAVLink options that do not fit the scenario (`--disarm-at-end` without a landing).
    #[error(transparent)]
    VehicleCheck(#[from] CheckError),
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
    #[error("agent {id}: cannot follow the commands to the team: {fault}")]
    Steer {
        id: u32,
        fault: cdm_runtime::member_steer::SteerFault,
    },
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
            | MemberError::StaleLinks(_)
            | MemberError::Recording(_)
            | MemberError::LinkOverrides(_)
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
            MemberError::VehicleOrigins(_) | MemberError::VehicleCheck(_) => 2,
            _ => 3,
        }
    }
}

impl MemberError {
    /// The loop's outcome as this process reports it (messages unchanged since the loop was one
    /// function).
    pub(crate) fn from_loop(e: LoopError<TransportError>, id: u32, team: &TeamName) -> Self {
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
            MemberFault::Steer(fault) => MemberError::Steer { id, fault },
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
