//! Wire types exchanged over shared memory, named by direction of travel:
//! [`StateMsg`] goes from a member to its out-neighbours and the orchestrator, [`ClockMsg`] from
//! the orchestrator to every member.
//!
//! Both are `#[repr(C)]` with plain fields only (`u32`, `u64`, `f64`, arrays), so iceoryx2 can
//! place them in shared memory as they are. The backend (cdm-iox) gives them `ZeroCopySend` and
//! their stable type names; this crate does not name iceoryx2. The same types cross hosts: they
//! derive serde, and cdm-zenoh's one `encode` (postcard) writes them field by field in
//! declaration order. Codes travel as `u32` with the
//! documented constants below; [`AgentStatus`] and [`ClockCommand`] are the Rust-side view of
//! them. Decoding never fails: a code this build does not know is kept as `Unknown(code)` so a
//! newer peer cannot crash an older one.

/// `StateMsg::status`: the member is healthy.
pub const STATUS_OK: u32 = 0;
/// `StateMsg::status`: the member has detected a fault and is no longer following the plan.
pub const STATUS_FAULT: u32 = 1;
/// `StateMsg::status`: not a state but a real-time member's pacing report, sent once when the
/// team stops (`tick`: ticks flown; `state`: the figures, see `cdm_runtime::realtime::MemberPacing`).
/// [`StateMsg::status`] decodes it as a fault, so a reader that does not know it never audits it.
pub const STATUS_PACING: u32 = 2;

/// `StateMsg::status`: not a state but a member's answer to [`COMMAND_ARM`]: its vehicle is in
/// OFFBOARD/GUIDED and armed (`state[0]` = 1), or the member only streams (started without
/// `--arm`: `state[0]` = 0). [`StateMsg::status`] decodes it as a fault, like
/// [`STATUS_PACING`], so a reader that does not know it never audits it.
pub const STATUS_ARMED: u32 = 3;
/// `StateMsg::status`: not a state but a MAVLink member's vehicle report (attitude and late
/// setpoints, `cdm_mavlink::report`), published just before each of its pacing reports.
pub const STATUS_VEHICLE: u32 = 4;
/// `StateMsg::status`: not a state but a real-time leader's acknowledgement of a proposed
/// command ([`STEER_PROPOSED`]): it can switch at the notice's tick (`state[0]` = the notice's
/// sequence number, `tick` = the tick it flies next). [`StateMsg::status`] decodes it as a
/// fault, like [`STATUS_PACING`], so a reader that does not know it never audits it.
pub const STATUS_STEER_ACK: u32 = 5;

/// `StateMsg::fault_code`: no fault (always the value while `status == STATUS_OK`).
pub const FAULT_NONE: u32 = 0;
/// `StateMsg::fault_code`: the member's own state or command became non-finite.
pub const FAULT_NON_FINITE: u32 = 1;
/// `StateMsg::fault_code`: a neighbour (`fault_peer`) sent nothing before the deadline.
pub const FAULT_NEIGHBOR_SILENT: u32 = 2;
/// `StateMsg::fault_code`: a neighbour (`fault_peer`) reported a fault itself.
pub const FAULT_NEIGHBOR_FAULT: u32 = 3;
/// `StateMsg::fault_code`: samples of a neighbour (`fault_peer`) were lost (a tick gap).
pub const FAULT_TICK_GAP: u32 = 4;
/// `StateMsg::fault_code`: a message carried another scenario's hash (`fault_peer` is the sender,
/// or [`NO_PEER`] when it was the clock).
pub const FAULT_SCENARIO_MISMATCH: u32 = 5;
/// `StateMsg::fault_code`: a safety check (separation, bounds) failed.
pub const FAULT_SAFETY: u32 = 6;
/// `StateMsg::fault_code`: the orchestrator's node is gone.
pub const FAULT_ORCHESTRATOR_LOST: u32 = 7;
/// `StateMsg::fault_code`: the controller refused to fly on (decoupling matrix M near singular:
/// thrust near 0 or roll near 90 degrees, eq. 46).
pub const FAULT_CONTROL: u32 = 8;
/// `StateMsg::fault_code`: the member lost its real vehicle (`--vehicles mavlink`: no HEARTBEAT
/// for 1 s or no position for 0.5 s, or the vehicle refused to arm).
pub const FAULT_VEHICLE_LOST: u32 = 9;
/// `StateMsg::fault_code`: the member runs on another host whose daemon can no longer be heard
/// (a network partition or a dead daemon); published on the member's behalf by the orchestrator's
/// bridge.
pub const FAULT_HOST_LOST: u32 = 10;
/// `StateMsg::fault_code`: the member's process on another host exited before the stop; its
/// host's daemon saw it and the orchestrator's bridge publishes this on its behalf.
pub const FAULT_REMOTE_EXITED: u32 = 11;

/// `StateMsg::fault_code`: the member's real vehicle left OFFBOARD/GUIDED after it was engaged
/// (a pilot, a mode switch or an autopilot failsafe took it over): [`FAULT_VEHICLE_LOST`] of
/// that kind.
pub const FAULT_VEHICLE_MODE: u32 = 12;
/// `StateMsg::fault_code`: the member's real vehicle was disarmed in flight.
pub const FAULT_VEHICLE_DISARMED: u32 = 13;

/// `StateMsg::fault_peer` when the fault involves no other member.
pub const NO_PEER: u32 = u32::MAX;

/// `ClockMsg::command`: members may compute ticks up to and including `grant_tick`.
pub const COMMAND_RUN: u32 = 0;
/// `ClockMsg::command`: members stop; `reason` says why.
pub const COMMAND_STOP: u32 = 1;
/// `ClockMsg::command`: fly in real time (`--realtime`). `grant_tick` carries the start instant,
/// tick 0's wall time as CLOCK_REALTIME nanoseconds since the Unix epoch, and `reason` the phase
/// seed ([`PHASES_ALIGNED`]: no phase offsets). The message keeps its 24 bytes: other languages
/// mirror the layout (`python/cdm_bus.py`).
pub const COMMAND_REALTIME: u32 = 2;
/// `ClockMsg::command`: every member's vehicle is ready (a MAVLink member joins only once its
/// vehicle is heard): switch it to OFFBOARD/GUIDED and arm it, then answer [`STATUS_ARMED`].
/// Sent once, before the start, and only by `orchestrator launch --arm`. A member that does not
/// know the command decodes it as a stop: it cannot arm on the team's order, so it must not fly.
pub const COMMAND_ARM: u32 = 3;
/// `ClockMsg::reason` with [`COMMAND_REALTIME`]: every member ticks at the start instant plus
/// whole periods (no phase offsets).
pub const PHASES_ALIGNED: u32 = 0;

/// `ClockMsg::reason`: no reason (always the value with `COMMAND_RUN`).
pub const REASON_NONE: u32 = 0;
/// `ClockMsg::reason`: the scenario reached its last tick.
pub const REASON_FINISHED: u32 = 1;
/// `ClockMsg::reason`: a member reported a fault.
pub const REASON_AGENT_FAULT: u32 = 2;
/// `ClockMsg::reason`: a member stopped answering before the deadline.
pub const REASON_AGENT_SILENT: u32 = 3;
/// `ClockMsg::reason`: the operator interrupted the run (signal).
pub const REASON_INTERRUPTED: u32 = 4;

use cdm_math::Vec3;
use cdm_model::steer::TeamCommand;

/// One member's full state at one tick, published once per tick.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[repr(C)]
pub struct StateMsg {
    /// The tick this state belongs to (simulation time is `tick * dt`). Consumers detect lost
    /// samples through gaps in this number.
    pub tick: u64,
    /// Hash of the scenario the sender runs; a mismatch means two different runs got mixed.
    pub scenario_hash: u64,
    /// The sender's member id (equal to the `<id>` of the `state/<id>` service it arrives on).
    pub id: u32,
    /// [`STATUS_OK`] or [`STATUS_FAULT`].
    pub status: u32,
    /// One of the `FAULT_*` codes; [`FAULT_NONE`] while the status is ok.
    pub fault_code: u32,
    /// The member the fault is about, or [`NO_PEER`].
    pub fault_peer: u32,
    /// The full quadcopter state; its layout belongs to the dynamics module, the transport never
    /// looks inside.
    pub state: [f64; 12],
}

/// The orchestrator's grant: how far members may run, or that they must stop.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[repr(C)]
pub struct ClockMsg {
    /// The last tick members may compute (inclusive).
    pub grant_tick: u64,
    /// Hash of the scenario the orchestrator runs.
    pub scenario_hash: u64,
    /// [`COMMAND_RUN`] or [`COMMAND_STOP`].
    pub command: u32,
    /// One of the `REASON_*` codes; [`REASON_NONE`] with [`COMMAND_RUN`].
    pub reason: u32,
    /// The latest loss announced: the tick from which its repair applies (the tick after the
    /// lost member's last published state). Meaningless while `loss_seq` is 0.
    pub loss_tick: u64,
    /// How many losses were announced so far (0: none). Every later clock message repeats the
    /// latest loss, so a member that drains the clock sees each loss at least once, and a jump
    /// of more than one tells it that it missed one.
    pub loss_seq: u32,
    /// The member lost in loss number `loss_seq`.
    pub loss_id: u32,
    /// How many of the announced losses have every new link of their repair connected: the
    /// new in-neighbours then hand their readers the states these missed (iceoryx2 history).
    pub loss_linked: u32,
    /// One of the `STEER_*` phases of the latest command notice: [`STEER_FINAL`] (lockstep,
    /// and a real-time command every leader acknowledged), [`STEER_PROPOSED`] or
    /// [`STEER_WITHDRAWN`]. It also keeps the layout free of implicit padding.
    pub steer_phase: u32,
    /// The latest command to the team in flight announced: the tick its new motion starts
    /// from. Meaningless while `steer_seq` is 0.
    pub steer_tick: u64,
    /// How many commands were announced so far (0: none); repeated by every later clock
    /// message, as the loss notice is.
    pub steer_seq: u32,
    /// One of the `STEER_*` codes.
    pub steer_command: u32,
    /// A goto's three primary leaders' goals in the plan's order, x y z each.
    pub steer_goals: [f64; 9],
    /// A goto's travel time in seconds; 0 for the default (`cdm_model::steer`).
    pub steer_travel_s: f64,
}

/// `ClockMsg::steer_command`: hold.
pub const STEER_HOLD: u32 = 1;
/// `ClockMsg::steer_command`: resume.
pub const STEER_RESUME: u32 = 2;
/// `ClockMsg::steer_command`: land.
pub const STEER_LAND: u32 = 3;
/// `ClockMsg::steer_command`: goto (`steer_goals`, `steer_travel_s`).
pub const STEER_GOTO: u32 = 4;

/// `ClockMsg::steer_phase`: the command is decided; every member flies it from its switch tick.
pub const STEER_FINAL: u32 = 0;
/// `ClockMsg::steer_phase`: real time, the command is proposed: every leader that can still
/// switch at its tick acknowledges it ([`STATUS_STEER_ACK`]) and waits for the decision
/// before flying that tick.
pub const STEER_PROPOSED: u32 = 1;
/// `ClockMsg::steer_phase`: real time, the proposed command is withdrawn (a leader did not
/// acknowledge it in time): nothing changes, and its sequence number is spent.
pub const STEER_WITHDRAWN: u32 = 2;

/// Where a command notice stands (the Rust view of `ClockMsg::steer_phase`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SteerPhase {
    /// [`STEER_FINAL`]
    Final,
    /// [`STEER_PROPOSED`]
    Proposed,
    /// [`STEER_WITHDRAWN`]
    Withdrawn,
    /// A phase this build does not know (a member then stops: it cannot tell whether to fly it).
    Unknown(u32),
}

impl SteerPhase {
    /// The wire value.
    pub fn code(self) -> u32 {
        match self {
            SteerPhase::Final => STEER_FINAL,
            SteerPhase::Proposed => STEER_PROPOSED,
            SteerPhase::Withdrawn => STEER_WITHDRAWN,
            SteerPhase::Unknown(c) => c,
        }
    }

    /// The Rust view of a wire value.
    pub fn from_code(code: u32) -> Self {
        match code {
            STEER_FINAL => SteerPhase::Final,
            STEER_PROPOSED => SteerPhase::Proposed,
            STEER_WITHDRAWN => SteerPhase::Withdrawn,
            other => SteerPhase::Unknown(other),
        }
    }
}

/// The latest accepted command a clock message announces (the Rust view of the `steer_*`
/// fields): every member applies it to its plan from tick `tick` on, as the orchestrator did
/// (`cdm_model::steer::Steering`, the same code, so the same plan).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteerNotice {
    /// Commands announced so far; this is number `seq` (1-based).
    pub seq: u32,
    /// The switch tick.
    pub tick: u64,
    /// The command; `None` for a code this build does not know (a member then stops: it
    /// cannot fly the team's plan).
    pub command: Option<TeamCommand>,
    /// Decided, proposed (real time, waiting for the leaders' acknowledgements) or withdrawn.
    pub phase: SteerPhase,
}

impl SteerNotice {
    /// A decided command: number `seq`, switching at `tick`.
    pub fn decided(seq: u32, tick: u64, command: TeamCommand) -> Self {
        SteerNotice {
            seq,
            tick,
            command: Some(command),
            phase: SteerPhase::Final,
        }
    }

    /// The same notice in `phase`.
    pub fn in_phase(self, phase: SteerPhase) -> Self {
        SteerNotice { phase, ..self }
    }
}

/// The latest loss a clock message announces (the Rust view of the `loss_*` fields).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LossNotice {
    /// Losses announced so far; this is number `seq` (1-based).
    pub seq: u32,
    /// The lost member.
    pub id: u32,
    /// The repair applies from this tick.
    pub tick: u64,
    /// Losses whose new links are all connected.
    pub linked: u32,
}

/// What kind of loss a real vehicle's failure is for the team (`FaultCode` on the wire, the
/// loss cause in audit.json): the team repairs around each alike, and says which it was.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VehicleLoss {
    /// The link itself: silence, a low battery, the autopilot's own failsafe state, arming.
    Lost,
    /// The vehicle left the mode that flies the member's setpoints (a pilot took it over).
    LeftMode,
    /// The vehicle was disarmed in flight.
    Disarmed,
}

/// Why a member is faulty (the Rust view of `StateMsg::fault_code`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FaultCode {
    /// [`FAULT_NON_FINITE`]
    NonFinite,
    /// [`FAULT_NEIGHBOR_SILENT`]
    NeighborSilent,
    /// [`FAULT_NEIGHBOR_FAULT`]
    NeighborFault,
    /// [`FAULT_TICK_GAP`]
    TickGap,
    /// [`FAULT_SCENARIO_MISMATCH`]
    ScenarioMismatch,
    /// [`FAULT_SAFETY`]
    Safety,
    /// [`FAULT_ORCHESTRATOR_LOST`]
    OrchestratorLost,
    /// [`FAULT_CONTROL`]
    Control,
    /// [`FAULT_VEHICLE_LOST`]
    VehicleLost,
    /// [`FAULT_VEHICLE_MODE`]
    VehicleMode,
    /// [`FAULT_VEHICLE_DISARMED`]
    VehicleDisarmed,
    /// [`FAULT_HOST_LOST`]
    HostLost,
    /// [`FAULT_REMOTE_EXITED`]
    RemoteExited,
    /// A code this build does not know (sent by a newer peer).
    Unknown(u32),
}

impl FaultCode {
    /// The wire value.
    pub fn code(self) -> u32 {
        match self {
            FaultCode::NonFinite => FAULT_NON_FINITE,
            FaultCode::NeighborSilent => FAULT_NEIGHBOR_SILENT,
            FaultCode::NeighborFault => FAULT_NEIGHBOR_FAULT,
            FaultCode::TickGap => FAULT_TICK_GAP,
            FaultCode::ScenarioMismatch => FAULT_SCENARIO_MISMATCH,
            FaultCode::Safety => FAULT_SAFETY,
            FaultCode::OrchestratorLost => FAULT_ORCHESTRATOR_LOST,
            FaultCode::Control => FAULT_CONTROL,
            FaultCode::VehicleLost => FAULT_VEHICLE_LOST,
            FaultCode::VehicleMode => FAULT_VEHICLE_MODE,
            FaultCode::VehicleDisarmed => FAULT_VEHICLE_DISARMED,
            FaultCode::HostLost => FAULT_HOST_LOST,
            FaultCode::RemoteExited => FAULT_REMOTE_EXITED,
            FaultCode::Unknown(c) => c,
        }
    }

    /// The kind audit.json records for a member that reported this code (the same kind as
    /// `simulate` records for a controller fault).
    pub fn kind(self) -> cdm_model::outcome::FaultKind {
        use cdm_model::outcome::FaultKind;
        match self {
            FaultCode::Control => FaultKind::Control,
            FaultCode::VehicleLost | FaultCode::VehicleMode | FaultCode::VehicleDisarmed => {
                FaultKind::VehicleLost
            }
            FaultCode::HostLost => FaultKind::HostLost,
            // A member on another host exited: as a member here would (its daemon saw it).
            FaultCode::RemoteExited => FaultKind::AgentExited,
            _ => FaultKind::AgentFault,
        }
    }

    /// The code a member reports for its vehicle's `loss`.
    pub fn of_vehicle(loss: VehicleLoss) -> Self {
        match loss {
            VehicleLoss::Lost => FaultCode::VehicleLost,
            VehicleLoss::LeftMode => FaultCode::VehicleMode,
            VehicleLoss::Disarmed => FaultCode::VehicleDisarmed,
        }
    }

    /// The Rust view of a wire value ([`FAULT_NONE`] has none: it is not a fault).
    pub fn from_code(code: u32) -> Option<Self> {
        Some(match code {
            FAULT_NONE => return None,
            FAULT_NON_FINITE => FaultCode::NonFinite,
            FAULT_NEIGHBOR_SILENT => FaultCode::NeighborSilent,
            FAULT_NEIGHBOR_FAULT => FaultCode::NeighborFault,
            FAULT_TICK_GAP => FaultCode::TickGap,
            FAULT_SCENARIO_MISMATCH => FaultCode::ScenarioMismatch,
            FAULT_SAFETY => FaultCode::Safety,
            FAULT_ORCHESTRATOR_LOST => FaultCode::OrchestratorLost,
            FAULT_CONTROL => FaultCode::Control,
            FAULT_VEHICLE_LOST => FaultCode::VehicleLost,
            FAULT_VEHICLE_MODE => FaultCode::VehicleMode,
            FAULT_VEHICLE_DISARMED => FaultCode::VehicleDisarmed,
            FAULT_HOST_LOST => FaultCode::HostLost,
            FAULT_REMOTE_EXITED => FaultCode::RemoteExited,
            other => FaultCode::Unknown(other),
        })
    }
}

/// The Rust view of `status`, `fault_code` and `fault_peer` together.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AgentStatus {
    /// Healthy.
    Ok,
    /// Faulty, with the reason and the member it is about (if any).
    Fault {
        /// What went wrong.
        code: FaultCode,
        /// The other member involved, if any.
        peer: Option<u32>,
    },
}

impl StateMsg {
    /// A healthy member's state at `tick`.
    pub fn ok(tick: u64, scenario_hash: u64, id: u32, state: [f64; 12]) -> Self {
        Self {
            tick,
            scenario_hash,
            id,
            status: STATUS_OK,
            fault_code: FAULT_NONE,
            fault_peer: NO_PEER,
            state,
        }
    }

    /// The same message with `status` set (encodes [`AgentStatus`] into the three wire fields).
    pub fn with_status(mut self, status: AgentStatus) -> Self {
        match status {
            AgentStatus::Ok => {
                self.status = STATUS_OK;
                self.fault_code = FAULT_NONE;
                self.fault_peer = NO_PEER;
            }
            AgentStatus::Fault { code, peer } => {
                self.status = STATUS_FAULT;
                self.fault_code = code.code();
                self.fault_peer = peer.unwrap_or(NO_PEER);
            }
        }
        self
    }

    /// A member's answer to [`COMMAND_ARM`] ([`STATUS_ARMED`]): `armed` says it armed its
    /// vehicle (false: it only streams, started without `--arm`).
    pub fn arm_report(tick: u64, scenario_hash: u64, id: u32, armed: bool) -> Self {
        let mut state = [0.0; 12];
        state[0] = if armed { 1.0 } else { 0.0 };
        Self {
            status: STATUS_ARMED,
            ..Self::ok(tick, scenario_hash, id, state)
        }
    }

    /// A real-time leader's acknowledgement ([`STATUS_STEER_ACK`]) of the proposed command
    /// number `seq`, sent while it flies `tick` next.
    pub fn steer_ack(tick: u64, scenario_hash: u64, id: u32, seq: u32) -> Self {
        let mut state = [0.0; 12];
        state[0] = f64::from(seq);
        Self {
            status: STATUS_STEER_ACK,
            ..Self::ok(tick, scenario_hash, id, state)
        }
    }

    /// `Some(seq)` for an acknowledgement of proposed command `seq`, `None` for anything else.
    pub fn steer_acked(&self) -> Option<u32> {
        (self.status == STATUS_STEER_ACK).then_some(self.state[0] as u32)
    }

    /// `Some(armed)` for an answer to [`COMMAND_ARM`], `None` for anything else.
    pub fn armed(&self) -> Option<bool> {
        (self.status == STATUS_ARMED).then_some(self.state[0] == 1.0)
    }

    /// True for a real-time member's pacing report ([`STATUS_PACING`]), which is not a state.
    pub fn is_pacing(&self) -> bool {
        self.status == STATUS_PACING
    }

    /// Decodes the status fields. Any status other than [`STATUS_OK`] counts as a fault, so a
    /// corrupted or unknown status is never mistaken for health; a fault without a code decodes
    /// as `Unknown(0)`.
    pub fn status(&self) -> AgentStatus {
        if self.status == STATUS_OK {
            return AgentStatus::Ok;
        }
        AgentStatus::Fault {
            code: FaultCode::from_code(self.fault_code).unwrap_or(FaultCode::Unknown(FAULT_NONE)),
            peer: (self.fault_peer != NO_PEER).then_some(self.fault_peer),
        }
    }
}

/// Why the orchestrator stops a run (the Rust view of `ClockMsg::reason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StopReason {
    /// [`REASON_FINISHED`]
    Finished,
    /// [`REASON_AGENT_FAULT`]
    AgentFault,
    /// [`REASON_AGENT_SILENT`]
    AgentSilent,
    /// [`REASON_INTERRUPTED`]
    Interrupted,
    /// A reason this build does not know (sent by a newer orchestrator).
    Unknown(u32),
}

impl StopReason {
    /// The wire value.
    pub fn code(self) -> u32 {
        match self {
            StopReason::Finished => REASON_FINISHED,
            StopReason::AgentFault => REASON_AGENT_FAULT,
            StopReason::AgentSilent => REASON_AGENT_SILENT,
            StopReason::Interrupted => REASON_INTERRUPTED,
            StopReason::Unknown(c) => c,
        }
    }

    /// The Rust view of a wire value.
    pub fn from_code(code: u32) -> Self {
        match code {
            REASON_FINISHED => StopReason::Finished,
            REASON_AGENT_FAULT => StopReason::AgentFault,
            REASON_AGENT_SILENT => StopReason::AgentSilent,
            REASON_INTERRUPTED => StopReason::Interrupted,
            other => StopReason::Unknown(other),
        }
    }
}

/// The Rust view of `ClockMsg::command` and `reason` together.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClockCommand {
    /// Run up to and including the grant tick.
    Run,
    /// Fly in real time from this start instant (CLOCK_REALTIME ns) with these phase offsets.
    Realtime { start_unix_ns: u64, phase_seed: u32 },
    /// Arm the vehicles ([`COMMAND_ARM`]): sent once every member's vehicle is ready.
    Arm,
    /// Stop now.
    Stop(StopReason),
}

impl ClockMsg {
    /// A grant to run up to and including `grant_tick`.
    pub fn run(grant_tick: u64, scenario_hash: u64) -> Self {
        Self {
            grant_tick,
            scenario_hash,
            command: COMMAND_RUN,
            reason: REASON_NONE,
            loss_tick: 0,
            loss_seq: 0,
            loss_id: 0,
            loss_linked: 0,
            steer_phase: STEER_FINAL,
            steer_tick: 0,
            steer_seq: 0,
            steer_command: 0,
            steer_goals: [0.0; 9],
            steer_travel_s: 0.0,
        }
    }

    /// The same message carrying `notice` (the latest command announced, repeated by every
    /// later clock message).
    pub fn with_steer(mut self, notice: Option<SteerNotice>) -> Self {
        let Some(n) = notice else { return self };
        self.steer_seq = n.seq;
        self.steer_tick = n.tick;
        self.steer_phase = n.phase.code();
        self.steer_command = match n.command {
            Some(TeamCommand::Hold) | None => STEER_HOLD,
            Some(TeamCommand::Resume) => STEER_RESUME,
            Some(TeamCommand::Land) => STEER_LAND,
            Some(TeamCommand::Goto { goals, travel_s }) => {
                for (k, g) in goals.iter().enumerate() {
                    self.steer_goals[3 * k..3 * k + 3].copy_from_slice(&[g.x, g.y, g.z]);
                }
                self.steer_travel_s = travel_s.unwrap_or(0.0);
                STEER_GOTO
            }
        };
        self
    }

    /// The latest command announced, if any.
    pub fn steer(&self) -> Option<SteerNotice> {
        if self.steer_seq == 0 {
            return None;
        }
        let g = &self.steer_goals;
        let command = match self.steer_command {
            STEER_HOLD => Some(TeamCommand::Hold),
            STEER_RESUME => Some(TeamCommand::Resume),
            STEER_LAND => Some(TeamCommand::Land),
            STEER_GOTO => Some(TeamCommand::Goto {
                goals: std::array::from_fn(|k| Vec3::new(g[3 * k], g[3 * k + 1], g[3 * k + 2])),
                travel_s: (self.steer_travel_s > 0.0).then_some(self.steer_travel_s),
            }),
            _ => None,
        };
        Some(SteerNotice {
            seq: self.steer_seq,
            tick: self.steer_tick,
            command,
            phase: SteerPhase::from_code(self.steer_phase),
        })
    }

    /// The same message carrying `notice` (the latest loss announced, repeated by every later
    /// clock message).
    pub fn with_loss(mut self, notice: Option<LossNotice>) -> Self {
        if let Some(n) = notice {
            self.loss_seq = n.seq;
            self.loss_id = n.id;
            self.loss_tick = n.tick;
            self.loss_linked = n.linked;
        }
        self
    }

    /// The latest loss announced, if any.
    pub fn loss(&self) -> Option<LossNotice> {
        (self.loss_seq > 0).then_some(LossNotice {
            seq: self.loss_seq,
            id: self.loss_id,
            tick: self.loss_tick,
            linked: self.loss_linked.min(self.loss_seq),
        })
    }

    /// An order to stop, sent with the last granted tick.
    pub fn stop(grant_tick: u64, scenario_hash: u64, reason: StopReason) -> Self {
        Self {
            grant_tick,
            scenario_hash,
            command: COMMAND_STOP,
            reason: reason.code(),
            ..Self::run(grant_tick, scenario_hash)
        }
    }

    /// The start of a real-time flight: tick 0 at `start_unix_ns` (CLOCK_REALTIME), phase
    /// offsets drawn from `phase_seed` ([`PHASES_ALIGNED`]: none).
    pub fn realtime(start_unix_ns: u64, scenario_hash: u64, phase_seed: u32) -> Self {
        Self {
            grant_tick: start_unix_ns,
            scenario_hash,
            command: COMMAND_REALTIME,
            reason: phase_seed,
            ..Self::run(0, scenario_hash)
        }
    }

    /// The order to arm every vehicle ([`COMMAND_ARM`]).
    pub fn arm(scenario_hash: u64) -> Self {
        Self {
            command: COMMAND_ARM,
            ..Self::run(0, scenario_hash)
        }
    }

    /// Decodes `command` and `reason`. Any command other than [`COMMAND_RUN`] and
    /// [`COMMAND_REALTIME`] stops: a member that cannot understand the orchestrator must not
    /// keep flying the plan.
    pub fn command(&self) -> ClockCommand {
        match self.command {
            COMMAND_RUN => ClockCommand::Run,
            COMMAND_REALTIME => ClockCommand::Realtime {
                start_unix_ns: self.grant_tick,
                phase_seed: self.reason,
            },
            COMMAND_ARM => ClockCommand::Arm,
            _ => ClockCommand::Stop(StopReason::from_code(self.reason)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wire_sizes_are_stable() {
        // Every process of a team must agree on the layout; pin it.
        assert_eq!(core::mem::size_of::<StateMsg>(), 8 + 8 + 4 * 4 + 12 * 8);
        assert_eq!(
            core::mem::size_of::<ClockMsg>(),
            8 + 8 + 4 + 4 + 8 + 4 * 4 + 8 + 4 + 4 + 9 * 8 + 8
        );
    }

    #[test]
    fn status_round_trips() {
        let m = StateMsg::ok(3, 9, 7, [0.0; 12]);
        assert_eq!(m.status(), AgentStatus::Ok);
        let fault = AgentStatus::Fault {
            code: FaultCode::NeighborSilent,
            peer: Some(4),
        };
        let f = m.with_status(fault);
        assert_eq!((f.status, f.fault_code, f.fault_peer), (1, 2, 4));
        assert_eq!(f.status(), fault);
        assert_eq!(f.with_status(AgentStatus::Ok), m);
        let unknown = StateMsg {
            status: 9,
            fault_code: 77,
            ..m
        };
        assert_eq!(
            unknown.status(),
            AgentStatus::Fault {
                code: FaultCode::Unknown(77),
                peer: None
            }
        );
    }

    #[test]
    fn a_vehicles_loss_is_reported_by_its_kind_and_audited_as_vehicle_lost() {
        for (loss, wire) in [
            (VehicleLoss::Lost, FAULT_VEHICLE_LOST),
            (VehicleLoss::LeftMode, FAULT_VEHICLE_MODE),
            (VehicleLoss::Disarmed, FAULT_VEHICLE_DISARMED),
        ] {
            let code = FaultCode::of_vehicle(loss);
            assert_eq!(code.code(), wire);
            assert_eq!(FaultCode::from_code(wire), Some(code));
            assert_eq!(code.kind(), cdm_model::outcome::FaultKind::VehicleLost);
        }
    }

    #[test]
    fn clock_commands_round_trip() {
        assert_eq!(ClockMsg::run(5, 1).command(), ClockCommand::Run);
        let s = ClockMsg::stop(5, 1, StopReason::AgentFault);
        assert_eq!((s.command, s.reason), (COMMAND_STOP, REASON_AGENT_FAULT));
        assert_eq!(s.command(), ClockCommand::Stop(StopReason::AgentFault));
        let odd = ClockMsg { command: 42, ..s };
        assert_eq!(s.loss(), None);
        let n = LossNotice {
            seq: 2,
            id: 7,
            tick: 40,
            linked: 1,
        };
        assert_eq!(ClockMsg::run(5, 1).with_loss(Some(n)).loss(), Some(n));
        assert_eq!(odd.command(), ClockCommand::Stop(StopReason::AgentFault));
        assert_eq!(ClockMsg::arm(1).command(), ClockCommand::Arm);
        assert_eq!(ClockMsg::run(5, 1).steer(), None);
        for command in [
            TeamCommand::Hold,
            TeamCommand::Resume,
            TeamCommand::Land,
            TeamCommand::Goto {
                goals: [
                    Vec3::new(1.0, 2.0, 3.0),
                    Vec3::new(4.0, 5.0, 6.0),
                    Vec3::new(7.0, 8.0, 9.5),
                ],
                travel_s: Some(12.5),
            },
            TeamCommand::Goto {
                goals: [Vec3::new(1.0, 2.0, 3.0); 3],
                travel_s: None,
            },
        ] {
            for phase in [
                SteerPhase::Final,
                SteerPhase::Proposed,
                SteerPhase::Withdrawn,
                SteerPhase::Unknown(9),
            ] {
                let n = SteerNotice::decided(3, 77, command).in_phase(phase);
                assert_eq!(ClockMsg::run(5, 1).with_steer(Some(n)).steer(), Some(n));
            }
        }
        let unknown = ClockMsg {
            steer_seq: 1,
            steer_command: 99,
            ..ClockMsg::run(5, 1)
        };
        assert_eq!(unknown.steer().map(|n| n.command), Some(None));
        let r = StateMsg::arm_report(0, 1, 4, true);
        assert_eq!(r.armed(), Some(true));
        assert!(matches!(r.status(), AgentStatus::Fault { .. }));
        assert_eq!(StateMsg::ok(0, 1, 4, [1.0; 12]).armed(), None);
        let ack = StateMsg::steer_ack(40, 1, 2, 3);
        assert_eq!(ack.steer_acked(), Some(3));
        assert!(matches!(ack.status(), AgentStatus::Fault { .. }));
        assert_eq!(ack.armed(), None);
        assert_eq!(StateMsg::ok(0, 1, 4, [3.0; 12]).steer_acked(), None);
        assert_eq!(
            ClockMsg::realtime(1_700_000_000_000_000_000, 1, 7).command(),
            ClockCommand::Realtime {
                start_unix_ns: 1_700_000_000_000_000_000,
                phase_seed: 7
            }
        );
    }
}
