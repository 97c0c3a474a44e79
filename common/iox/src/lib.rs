//! The iceoryx2 backend, the only library crate that names iceoryx2: shared-memory ports of one
//! quadcopter team.
//!
//! One team = one orchestrator process + one process per member, each with one iceoryx2 node.
//! The orchestrator creates every service of the team, sized to the team's layout; members only
//! open them (iceoryx2 refuses an `open` that asks for larger limits than the creator set, and
//! exact limits let the transport itself refuse ports that the layout does not allow).
//!
//! | service | pattern | ports |
//! |---|---|---|
//! | `cdm/<team>/state/<id>` | publish-subscribe [`StateBatch`] (up to [`STATES_PER_SAMPLE`] [`StateMsg`](crate::messages::StateMsg)s) | publisher: member `id` (max 1); subscribers: its out-neighbours + orchestrator |
//! | `cdm/<team>/clock` | publish-subscribe [`ClockMsg`](crate::messages::ClockMsg) | publisher: orchestrator; subscribers: every member |
//! | `cdm/<team>/wake/<id>` | event | listener: member `id`; notifiers: its in-neighbours + orchestrator |
//! | `cdm/<team>/wake/orch` | event | listener: orchestrator; notifiers: every member |
//!
//! Wake-up rule: publish first, notify after `send` returned, so a woken reader always finds the
//! sample. Events merge repeated notifications, so a reader must drain everything it can after
//! each wake-up. Waiting is a blocking `Listener::timed_wait` (not a WaitSet: iceoryx2 0.10's
//! WaitSet can lose a wake-up under load).
//!
//! Overflow: state and clock subscribers use iceoryx2's *safe overflow*: when a subscriber's
//! buffer (`window + 2` samples, each at least one state; 2 grants) is full, the publisher replaces the oldest sample. A
//! publisher therefore never blocks on a slow or dead reader, and a reader that fell behind sees a
//! gap in `StateMsg::tick` (every state carries its tick) instead of a stall of the whole team.
//!
//! Ports use `ipc::Service` (single-threaded, no locks), so [`OrchestratorPorts`] and
//! [`MemberPorts`] are not `Send`: open them on the thread that uses them.
//!
//! iceoryx2 keeps its node and service files (and event sockets) under [`iox2_root`], on the
//! `/dev/shm` tmpfs instead of its default `/tmp/iceoryx2`: where `/tmp` is a disk file system
//! (ext4 here) the directory look-ups of 1000 processes opening their services took most of the
//! start-up (N = 1000: 26 s with `/tmp`, 12 s with the tmpfs root).
//!
//! Crashed processes leave their files in `/dev/shm` and [`iox2_root`]; the next
//! [`OrchestratorPorts::create`] of the same team (or [`remove_dead_nodes`]) removes them.

/// Where and under which names iceoryx2 keeps this user's files: the one place both are decided
/// (the Python tools mirror it). One per user, so nothing in `/dev/shm` is shared between users:
/// - `root`, `/dev/shm/cdm-iceoryx2-<uid>`: node and service files and event sockets (a tmpfs).
///   iceoryx2 creates its root owner-only (0750) and cannot mix users on one service anyway; a
///   shared root would let the first user on a machine lock every other user out.
/// - `prefix`, `cdm<uid>_`: the first part of every file iceoryx2 creates directly in `/dev/shm`
///   (shared-memory segments and its global management segment). With iceoryx2's default
///   `iox2_`, every user shared one world-writable (0666) management file: garbage written into
///   it stopped every launch of every user, and creating it first locked the others out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Iox2Location {
    /// iceoryx2's root directory.
    pub root: String,
    /// iceoryx2's global prefix.
    pub prefix: String,
}

/// This user's [`Iox2Location`], computed once.
pub fn iox2_location() -> &'static Iox2Location {
    static LOCATION: OnceLock<Iox2Location> = OnceLock::new();
    LOCATION.get_or_init(|| {
        // SAFETY: getuid(2) cannot fail and touches no memory of ours.
        let uid = unsafe { libc::getuid() };
        Iox2Location {
            root: format!("/dev/shm/cdm-iceoryx2-{uid}"),
            prefix: format!("cdm{uid}_"),
        }
    })
}

/// This user's iceoryx2 root directory ([`Iox2Location::root`]).
pub fn iox2_root() -> &'static str {
    &iox2_location().root
}

mod creator;
mod dead_teams;
mod error;
mod limits;
mod member;
mod notified;
mod orchestrator;
mod orphan_nodes;
mod ownership;
mod resend;
mod team;
mod wake_roots;
mod wire;

pub use dead_teams::{remove_dead_teams, Cleaned, RemovedTeam};
pub use error::TransportError;
pub use limits::{describe_spawn_error, lockstep_window, shm_free_bytes, MIN_AUTO_WINDOW};
pub use member::MemberPorts;
pub use orchestrator::{AgentReadiness, OrchestratorPorts, Readiness};
pub use team::{scenario_hash_value, RepairRoom, TeamLayout, TeamName, SCENARIO_HASH_KEY};
pub mod bench_barrier;
pub mod ids;
pub use wire::{
    ClockWire, StateBatch, StateBatchWire, StateWire, Wire, CLOCK_TYPE_NAME, STATES_PER_SAMPLE,
    STATE_BATCH_TYPE_NAME, STATE_TYPE_NAME,
};

/// The runtime's wire messages, at the path the backend's modules name them.
use cdm_runtime::messages;

use std::fmt;
use std::sync::{Once, OnceLock};
use std::time::Duration;

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;

/// Longest accepted team name; keeps every service and node name well inside iceoryx2's limits.
pub const TEAM_NAME_MAX_LEN: usize = 48;

/// Node slots each service keeps beyond the team's own processes: room for a diagnostic tool and
/// for a duplicate member process to get far enough to be told precisely why it is refused.
const SPARE_NODES: usize = 2;

/// Subscriber slots each state service keeps beyond the team's own readers: room for one
/// observer (`python/examples/watch.py`, a viewer) to read every member's state. The team's
/// publishers never wait for it (safe overflow: a slow observer loses its oldest samples).
const OBSERVER_SLOTS: usize = 1;

/// Clock messages a subscriber keeps: members read every one (a loss notice must not be
/// overwritten by the grants after it), and lag at most a few grants behind (window). The
/// losses of one tick are announced back to back (a lost host's members: 20 at N = 40 over two
/// hosts), each a message, and a member starved of CPU may not drain meanwhile: 16 lost
/// notices at N = 100. A message is 48 bytes.
const CLOCK_BUFFER: usize = 64;

/// How long a stale-resource cleanup waits for another process that is cleaning the same node.
const CLEANUP_TIMEOUT: Duration = Duration::from_secs(2);

/// Which process of a team is talking (for error messages and node names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TeamProcess {
    /// The orchestrator.
    Orchestrator,
    /// The member with this id.
    Agent(u32),
}

impl fmt::Display for TeamProcess {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TeamProcess::Orchestrator => f.write_str("orchestrator"),
            TeamProcess::Agent(id) => write!(f, "agent {id}"),
        }
    }
}

/// Raises this process's soft `RLIMIT_NOFILE` to the hard limit and returns the new soft limit.
pub fn raise_fd_limit() -> Result<u64, TransportError> {
    limits::raise_fd_limit().map_err(TransportError::FdLimit)
}

/// Removes the files of every dead (crashed or killed) process of `team` and returns how many
/// nodes were cleaned. Safe to call while the team runs: live nodes are never touched.
pub fn remove_dead_nodes(team: &TeamName) -> Result<usize, TransportError> {
    init_logging();
    let mut registry = dead_teams::scan_teams(process_config())?;
    Ok(registry
        .teams
        .remove(team)
        .map_or(0, |scan| remove_stale(team, scan.dead)))
}

/// Routes iceoryx2's log through `tracing` (the crate is built with its `tracing` logger) and
/// sets iceoryx2's own threshold to `IOX2_LOG_LEVEL` or, by default, warn: iceoryx2 reports
/// expected refusals (a second publisher, a missing service) at debug level, which the errors of
/// this module already describe.
fn init_logging() {
    static INIT: Once = Once::new();
    INIT.call_once(|| set_log_level_from_env_or(LogLevel::Warn));
}

/// The iceoryx2 config of this runtime's processes, built once. No process runs iceoryx2's
/// implicit dead-node scans (on node creation and destruction, on service open): with hundreds
/// of processes starting together they cost seconds, and they clean up every team on the machine,
/// so one launch could remove the evidence of another team's crash while it is being examined.
/// The orchestrator cleans up its own team's dead nodes explicitly ([`OrchestratorPorts::create`],
/// [`remove_dead_nodes`]).
fn process_config() -> &'static Config {
    static CONFIG: OnceLock<Config> = OnceLock::new();
    CONFIG.get_or_init(|| {
        let mut cfg = Config::default();
        let here = iox2_location();
        let root = format!("{}/", here.root);
        // Both fit iceoryx2's types (short ASCII); the warnings are a fallback, never expected.
        match iceoryx2::prelude::Path::new(root.as_bytes()) {
            Ok(root) => cfg.global.set_root_path(&root),
            Err(e) => tracing::warn!("iceoryx2 root {root}: {e:?}; using the default"),
        }
        match FileName::new(here.prefix.as_bytes()) {
            Ok(prefix) => cfg.global.prefix = prefix,
            Err(e) => tracing::warn!("iceoryx2 prefix {}: {e:?}; using the default", here.prefix),
        }
        // Each subscriber pre-allocates (and touches) room for this many connections of departed
        // publishers, about 3.6 KiB each: iceoryx2's default of 128 cost 460 KiB per subscriber,
        // a quarter of a member's memory and most of the orchestrator's (N subscribers). Every
        // state service has one publisher for the team's lifetime; 2 covers the one borrowed
        // sample a subscriber may hold (iceoryx2 asks for at least that many).
        cfg.defaults
            .publish_subscribe
            .subscriber_expired_connection_buffer = 2;
        cfg.global.node.cleanup_dead_nodes_on_creation = false;
        cfg.global.node.cleanup_dead_nodes_on_destruction = false;
        cfg.global.service.cleanup_dead_nodes_on_open = false;
        cfg
    })
}

/// The iceoryx2 configuration of this runtime's processes (root [`iox2_root`]), for tools and
/// tests that list its services and nodes.
pub fn iceoryx2_config() -> Config {
    process_config().clone()
}

/// Creates the one node of a process.
fn create_node(team: &TeamName, who: TeamProcess) -> Result<Node<ipc::Service>, TransportError> {
    create_named_node(team, who, team.node_name(who))
}

/// Creates the node `name` for `who` (a bridge's relay nodes are named apart from the members').
fn create_named_node(
    team: &TeamName,
    who: TeamProcess,
    name: String,
) -> Result<Node<ipc::Service>, TransportError> {
    let err = |detail: String| TransportError::Node {
        team: team.clone(),
        who,
        node: name.clone(),
        detail,
    };
    let node_name = NodeName::new(&name).map_err(|e| err(format!("{e:?}")))?;
    // Before iceoryx2 writes anything: our root and management segment must be ours alone. The
    // orchestrator (first of a team) also checks the segment; members skip the `/dev/shm` listing.
    let here = iox2_location();
    ownership::check_root(here)?;
    if who == TeamProcess::Orchestrator {
        ownership::check_global_mgmt(here, false)?;
    }
    let node = NodeBuilder::new()
        .name(&node_name)
        .config(process_config())
        // Signals belong to the process's main; iceoryx2 must not swallow SIGINT/SIGTERM.
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| match limits::fd_exhausted() {
            Some(u) => fd_limit_reached(team, who, &name, "create node", u),
            None => err(format!("{e:?}")),
        })?;
    if who == TeamProcess::Orchestrator {
        // iceoryx2 creates the management segment world-writable (0666); make it ours alone.
        ownership::check_global_mgmt(here, true)?;
    }
    Ok(node)
}

/// The iceoryx2 name of a service.
fn service_name(
    team: &TeamName,
    who: TeamProcess,
    service: &str,
) -> Result<ServiceName, TransportError> {
    ServiceName::new(service).map_err(|e| TransportError::Service {
        team: team.clone(),
        who,
        service: service.to_owned(),
        op: "name service",
        detail: format!("{e:?}"),
    })
}

/// Builds a [`TransportError::Service`] (the common case of every port operation).
fn service_error(
    team: &TeamName,
    who: TeamProcess,
    service: &str,
    op: &'static str,
    detail: impl fmt::Debug,
) -> TransportError {
    if let Some(u) = limits::fd_exhausted() {
        return fd_limit_reached(team, who, service, op, u);
    }
    TransportError::Service {
        team: team.clone(),
        who,
        service: service.to_owned(),
        op,
        detail: format!("{detail:?}"),
    }
}

fn fd_limit_reached(
    team: &TeamName,
    who: TeamProcess,
    service: &str,
    op: &'static str,
    u: limits::FdUsage,
) -> TransportError {
    TransportError::FdLimitReached {
        team: team.clone(),
        who,
        service: service.to_owned(),
        op,
        open: u.open,
        soft: u.soft,
        hard: u.hard,
    }
}

/// Blocks on `listener` until a notification arrives or `timeout` passes; true when woken.
fn wait_on(
    listener: &iceoryx2::port::listener::Listener<ipc::Service>,
    (timeout, on_event): (Duration, impl FnMut(iceoryx2::port::EventActivation)),
    team: &TeamName,
    who: TeamProcess,
    service: impl FnOnce() -> String,
) -> Result<bool, TransportError> {
    use iceoryx2::port::listener::ListenerWaitError;
    match listener.timed_wait(on_event, timeout) {
        Ok(n) => Ok(n > 0),
        // A signal (SIGCONT after SIGSTOP, a debugger attaching, SIGINT) interrupts the wait:
        // that is a spurious wake-up, not an error. Callers check their stop flag every loop.
        Err(ListenerWaitError::InterruptSignal) => Ok(true),
        // The service's name only for an error: formatting it for every wait was 7 % of a
        // member's CPU at N = 1000 (perf).
        Err(e) => Err(service_error(team, who, &service(), "wait", e)),
    }
}

/// Removes the resources of dead nodes; returns how many this call cleaned. Failures are logged
/// and skipped: a leftover shows up later as a precise service error.
fn remove_stale(team: &TeamName, dead: Vec<iceoryx2::node::DeadNodeView<ipc::Service>>) -> usize {
    use iceoryx2::node::NodeCleanupFailure;
    let mut removed = 0;
    for node in dead {
        let name = node
            .details()
            .as_ref()
            .map_or_else(String::new, |d| d.name().to_string());
        let result = match node.clone().try_remove_stale_resources() {
            // Someone else is cleaning it: wait for them, it is not ours to count.
            Err(NodeCleanupFailure::AnotherInstanceIsCleaningUpTheNode) => node
                .blocking_remove_stale_resources(CLEANUP_TIMEOUT)
                .map(|()| false),
            Err(NodeCleanupFailure::ResourcesAlreadyCleanedUp) => Ok(false),
            other => other.map(|()| true),
        };
        match result {
            Ok(true) => removed += 1,
            Ok(false) => {}
            Err(e) => tracing::warn!(team = %team, node = %name, error = ?e,
                "cannot remove the resources of a dead node"),
        }
    }
    removed
}
