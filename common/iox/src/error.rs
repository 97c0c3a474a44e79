//! The transport's errors: each names the team, the process and the service involved.

use super::{TeamName, TeamProcess};

/// Everything that can go wrong in the transport. Messages name the team, the process (`who`)
/// and the service involved.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// The team name is empty, too long or has characters outside `[A-Za-z0-9_-]`.
    #[error("invalid team name {name:?}: {reason}")]
    InvalidTeamName {
        /// The rejected name.
        name: String,
        /// Which rule it breaks.
        reason: &'static str,
    },
    /// The layout is inconsistent (duplicate ids, unknown neighbour, self-loop, window 0).
    #[error("invalid team layout: {reason}")]
    InvalidLayout {
        /// What is wrong.
        reason: String,
    },
    /// A live orchestrator (or live members of a previous run) already use the team name.
    #[error("team {team} is already running (live nodes: {live})")]
    TeamAlreadyRunning {
        /// The team.
        team: TeamName,
        /// Names of the live nodes found, or the service that already exists.
        live: String,
    },
    /// This user's iceoryx2 root or a file under this user's iceoryx2 prefix in `/dev/shm` is not
    /// safely ours: another user could rename, delete or overwrite the team's files through it.
    #[error(
        "{path} is {problem} (owner uid {owner}, mode {mode:04o}); this runtime needs it owned by \
         you (uid {uid}) and writable by no one else, or another user could rename, delete or \
         overwrite your team's files; remove it (as its owner or root: `rm -rf {path}`) and \
         launch again"
    )]
    UnsafeIox2Path {
        /// The directory or file.
        path: String,
        /// What is wrong with it.
        problem: &'static str,
        /// Its owner's user id.
        owner: u32,
        /// Its permission bits.
        mode: u32,
        /// This process's user id.
        uid: u32,
    },
    /// This user's iceoryx2 root or management segment could not be created or examined.
    #[error("cannot check the {what} {path}: {source}")]
    Iox2PathCheck {
        /// The directory or file.
        path: String,
        /// What it is.
        what: &'static str,
        /// The system's error.
        #[source]
        source: std::io::Error,
    },
    /// The team flies a different scenario than the process that tried to join it.
    #[error("agent {id} cannot join team {team}: its scenario (hash {mine:016x}) differs from the team's (hash {team_hash}); start it with the team's scenario file")]
    ScenarioMismatch {
        /// The team.
        team: TeamName,
        /// The member that tried to join.
        id: u32,
        /// The joining process's scenario hash.
        mine: u64,
        /// The team's scenario hash as published on its clock service.
        team_hash: String,
    },
    /// No orchestrator has created the team's services.
    #[error("team {team} does not exist ({who} found no service {service}); start its orchestrator first")]
    TeamNotFound {
        /// The team.
        team: TeamName,
        /// The process that looked.
        who: TeamProcess,
        /// The service that is missing.
        service: String,
    },
    /// The team exists but has no state service for this member id.
    #[error("agent {id} is not part of team {team} (no service {service})")]
    NotInTeam {
        /// The team.
        team: TeamName,
        /// The unknown member id.
        id: u32,
        /// The service that is missing.
        service: String,
    },
    /// Another process already holds this member's exclusive port.
    #[error("agent {id} of team {team} is already running ({service} refuses a second {port})")]
    AgentAlreadyRunning {
        /// The team.
        team: TeamName,
        /// The member id.
        id: u32,
        /// The service whose exclusive port is taken.
        service: String,
        /// The kind of port that was refused.
        port: &'static str,
    },
    /// The team's layout has no edge that allows this port (the service has no free slot for it).
    #[error(
        "agent {id} of team {team} is not a neighbour of agent {peer} in the team's layout \
         ({service} has no free {port} slot)"
    )]
    NotANeighbor {
        /// The team.
        team: TeamName,
        /// The member opening the port.
        id: u32,
        /// The member owning the service.
        peer: u32,
        /// The service.
        service: String,
        /// The kind of port that was refused.
        port: &'static str,
    },
    /// A member tried to publish a state that carries another member's id.
    #[error("agent {id} of team {team} tried to publish a state of agent {msg_id} on {service}")]
    ForeignState {
        /// The team.
        team: TeamName,
        /// The publishing member.
        id: u32,
        /// The id found in the message.
        msg_id: u32,
        /// The member's state service.
        service: String,
    },
    /// An iceoryx2 node could not be created.
    #[error("team {team}, {who}: cannot create node {node}: {detail}")]
    Node {
        /// The team.
        team: TeamName,
        /// The process.
        who: TeamProcess,
        /// The node name.
        node: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// iceoryx2's node registry could not be read.
    #[error("team {team}: cannot list iceoryx2 nodes: {detail}")]
    NodeList {
        /// The team.
        team: TeamName,
        /// iceoryx2's error.
        detail: String,
    },
    /// iceoryx2's node registry of this user could not be read.
    #[error("cannot list the iceoryx2 nodes under {root}: {detail}")]
    NodeRegistry {
        /// This user's iceoryx2 root.
        root: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// Any other iceoryx2 failure on a service or port.
    #[error("team {team}, {who}: {op} on {service} failed: {detail}")]
    Service {
        /// The team.
        team: TeamName,
        /// The process.
        who: TeamProcess,
        /// The service.
        service: String,
        /// What was attempted ("open service", "create publisher", "send", ...).
        op: &'static str,
        /// iceoryx2's error.
        detail: String,
    },
    /// A blocking wait was interrupted by a signal; the caller decides whether to stop.
    #[error("team {team}, {who}: wait on {service} was interrupted by a signal")]
    Interrupted {
        /// The team.
        team: TeamName,
        /// The process.
        who: TeamProcess,
        /// The event service waited on.
        service: String,
    },
    /// `setrlimit(RLIMIT_NOFILE)` failed.
    #[error("cannot raise the open-file limit: {0}")]
    FdLimit(#[source] std::io::Error),
    /// The shared-memory file system has less room than the team needs (iceoryx2 would die of
    /// SIGBUS writing past it).
    #[error(
        "team {team}: {dir} has {free_kib} KiB free, a team of {agents} agents needs about \
         {need_kib} KiB with a window of {window} ticks; free space there, enlarge it (e.g. \
         `mount -o remount,size=1G {dir}`) or launch with a smaller --window"
    )]
    ShmFull {
        /// The team.
        team: TeamName,
        /// The file system checked.
        dir: &'static str,
        /// Its free space.
        free_kib: u64,
        /// The team's size.
        agents: usize,
        /// The clock window (ticks a member may run ahead).
        window: u32,
        /// What the team needs (with a margin).
        need_kib: u64,
    },
    /// The orchestrator's open-file limit is below what the team needs (checked before anything
    /// is created).
    #[error(
        "team {team}: a team of {agents} agents needs about {need} file descriptors in the \
         orchestrator, which would run out of file descriptors (limit RLIMIT_NOFILE soft {soft}, \
         hard {hard}); raise it, e.g. `ulimit -n {need}` (as root, or after raising the hard \
         limit in /etc/security/limits.conf), or fly a smaller team"
    )]
    FdLimitTooLow {
        /// The team.
        team: TeamName,
        /// The team's size.
        agents: usize,
        /// Descriptors the team needs.
        need: u64,
        /// The soft limit.
        soft: u64,
        /// The hard limit.
        hard: u64,
    },
    /// A node, service or port could not be created because this process ran out of file
    /// descriptors (the orchestrator holds a few per member).
    #[error(
        "team {team}, {who}: {op} on {service} failed: out of file descriptors ({open} open, \
         limit RLIMIT_NOFILE soft {soft}, hard {hard}); raise it, e.g. `ulimit -n 65536` (as \
         root, or after raising the hard limit in /etc/security/limits.conf), and run again"
    )]
    FdLimitReached {
        /// The team.
        team: TeamName,
        /// The process.
        who: TeamProcess,
        /// The service (or node) being created.
        service: String,
        /// What was attempted.
        op: &'static str,
        /// Descriptors open at the failure.
        open: u64,
        /// The soft limit.
        soft: u64,
        /// The hard limit.
        hard: u64,
    },
}
