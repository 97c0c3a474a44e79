//! Why a host's link ends, as typed values: the bridge's verdict on a daemon ([`LinkLost`]), a
//! join request it refuses ([`Refusal`]), what ends a daemon's bridging ([`DaemonStop`]), and
//! why a daemon fails as a whole ([`DaemonError`]); before any of them, why a team cannot be
//! split ([`PlanError`]), an endpoint is refused ([`EndpointError`]) or the bridge cannot start
//! ([`BridgeError`]).
//! Their texts are written here and nowhere else; the multi-host tests and the operators read
//! them in the log, audit.json's fault and hosts.json.

use std::time::Duration;

#[cfg(feature = "hosts")]
use crate::{security::SecurityError, workdir::WorkDirError};
use cdm_iox::TransportError;
use cdm_runtime::messages::StopReason;
use cdm_runtime::notices::NoticeGap;
#[cfg(feature = "hosts")]
use {
    cdm_process::sched::SchedError, cdm_records::rundir::RunDirError, cdm_scenario::ScenarioError,
    cdm_zenoh::NetError, std::path::PathBuf,
};

use crate::host_link::LinkError;

/// Why a team cannot be split over the hosts asked for (the operator's input: exit 2).
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    #[error("--hosts {hosts}: the team has only {members} members")]
    TooManyHosts { hosts: u32, members: usize },
    #[error("--hosts: this orchestrator was built without the `hosts` feature (zenoh)")]
    NotBuilt,
    #[error("--hosts needs --listen ENDPOINT (e.g. tls/10.77.0.1:7447 with --keys DIR)")]
    NoListen,
}

/// An endpoint refused before anything opens (the operator's input: exit 2).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{option} {endpoint}: {problem}")]
pub struct EndpointError {
    /// The option that gave it (`--listen`, `--connect`).
    pub option: String,
    pub endpoint: String,
    pub problem: EndpointProblem,
}

/// What is wrong with an endpoint and the options beside it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EndpointProblem {
    #[error("a tls/ endpoint needs --keys DIR (the directory `orchestrator keys new` made for this machine)")]
    TlsWithoutKeys,
    #[error("--insecure is for tcp/ endpoints only")]
    TlsInsecure,
    #[error("--keys is for tls/ endpoints; plain TCP would not use them")]
    TcpWithKeys,
    #[error("plain TCP lets anyone who reaches the port join the team, read every member's state and send it frames; use tls/ADDR with --keys DIR, or say --insecure on a network you trust")]
    TcpNotInsecure,
    #[error("expected tls/ADDR:PORT (or tcp/ADDR:PORT with --insecure)")]
    Form,
}

/// Why the bridge cannot start: the endpoint or keys given (exit 2), or this host (exit 3).
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// `--listen`'s endpoint cannot be listened on.
    #[cfg(feature = "hosts")]
    #[error("--listen: {0}")]
    Endpoint(NetError),
    /// `--keys` cannot secure the link.
    #[cfg(feature = "hosts")]
    #[error(transparent)]
    Security(#[from] SecurityError),
    /// The join desk cannot be declared on the session.
    #[cfg(feature = "hosts")]
    #[error("--listen: {0}")]
    Listen(#[source] NetError),
    #[error("cannot start the bridge thread: {0}")]
    Thread(#[source] std::io::Error),
}

/// Why the bridge calls a host lost.
#[derive(Debug, thiserror::Error)]
pub enum LinkLost {
    /// The daemon's session closed: the daemon is gone, its members with it.
    #[error("the daemon is gone, {0}: killed or exited")]
    DaemonGone(#[source] LinkError),
    /// The daemon sent a frame that does not decode.
    #[error("the daemon sent a frame that does not decode (its protocol error): {0}")]
    Protocol(#[source] LinkError),
    /// The link failed otherwise.
    #[error(transparent)]
    Link(LinkError),
    /// Nothing came from the daemon for the link timeout.
    #[error(
        "nothing heard from host {host} ({who}) for {:.1} s: network partition or daemon gone",
        after.as_secs_f64()
    )]
    Silent {
        host: u32,
        who: String,
        after: Duration,
    },
    /// This host's shared memory refused a relay port of one of that host's members.
    #[error("cannot stand in for agent {id} of host {host}: {source}")]
    Relay {
        host: u32,
        id: u32,
        #[source]
        source: TransportError,
    },
    /// A relay could not publish or read on this host.
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// The clock's loss notices jumped on their way to that host.
    #[error(transparent)]
    Notice(#[from] NoticeGap),
}

impl LinkLost {
    /// True when the daemon itself is gone (its members with it), not only its link.
    pub fn daemon_gone(&self) -> bool {
        matches!(self, LinkLost::DaemonGone(_))
    }
}

impl From<LinkError> for LinkLost {
    fn from(e: LinkError) -> Self {
        match e {
            e @ LinkError::PeerGone(_) => LinkLost::DaemonGone(e),
            e @ LinkError::Protocol(_) => LinkLost::Protocol(e),
            e => LinkLost::Link(e),
        }
    }
}

/// Why the bridge refuses a daemon's join request.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    #[error("the daemon speaks host protocol {theirs} and this orchestrator {ours}")]
    Protocol { theirs: u32, ours: u32 },
    #[error("the daemon asks for team {asked}; this orchestrator runs team {team}")]
    Team { asked: String, team: String },
    #[error("the daemon's scenario has hash {theirs:016x}; team {team} flies {ours:016x}")]
    Scenario {
        theirs: u64,
        team: String,
        ours: u64,
    },
    #[error("--host {host}: team {team} has hosts 1..={last}")]
    NoSuchHost { host: u32, team: String, last: u32 },
    #[error("host {host} of team {team} is already taken by {by}")]
    Taken { host: u32, team: String, by: String },
    #[error("all {others} other hosts of team {team} are taken")]
    Full { others: u32, team: String },
    #[error("the orchestrator cannot open host {host}'s link: {detail}")]
    NoLink { host: u32, detail: String },
    #[error("with TLS a daemon joins as the host its certificate names, not as any free host")]
    Unbound,
    #[error("the request for host {host:?} came on the key of host {slot:?}")]
    Slot {
        slot: Option<u32>,
        host: Option<u32>,
    },
}

/// What ends a daemon's bridging before the orchestrator's stop.
#[derive(Debug, thiserror::Error)]
pub enum DaemonStop {
    #[error("interrupted by {0}")]
    Interrupted(&'static str),
    #[error("agent {id} {how} before the team started")]
    ExitedEarly {
        id: u32,
        how: cdm_runtime::process_exit::ProcessExit,
    },
    #[error("agents {late:?} did not start within {deadline:?}")]
    NotStarted { late: Vec<u32>, deadline: Duration },
    #[error("the orchestrator stopped the team before it started")]
    StoppedBeforeStart,
    /// The orchestrator's session closed.
    #[error("the orchestrator is gone, {0}: killed or exited")]
    OrchestratorGone(#[source] LinkError),
    /// The orchestrator sent a frame that does not decode.
    #[error("the orchestrator sent a frame that does not decode (its protocol error): {0}")]
    Protocol(#[source] LinkError),
    #[error(transparent)]
    Link(LinkError),
    #[error(
        "nothing heard from the orchestrator for {:.1} s (network partition or orchestrator gone)",
        after.as_secs_f64()
    )]
    Silent { after: Duration },
    /// The daemon itself did not run for longer than the link timeout: the orchestrator has
    /// called this host lost meanwhile, whatever frames are still queued.
    #[error(
        "this daemon did not run for {:.1} s (stopped by a signal, a debugger or a starved \
         machine), longer than the link timeout ({:.1} s): the orchestrator has lost this host",
        gap.as_secs_f64(),
        timeout.as_secs_f64()
    )]
    Stalled { gap: Duration, timeout: Duration },
    /// The orchestrator stopped the team on a fault (or an interrupt): the flight did not end
    /// as planned, so neither does the daemon.
    #[error("the orchestrator stopped the team ({})", stop_text(*.0))]
    TeamStopped(StopReason),
    #[error(transparent)]
    Transport(#[from] TransportError),
    #[error(transparent)]
    Notice(#[from] NoticeGap),
}

/// Why the orchestrator stopped a team, for a daemon's message.
fn stop_text(r: StopReason) -> String {
    match r {
        StopReason::Finished => "the plan was flown".into(),
        StopReason::AgentFault => "a member's fault, see its audit.json".into(),
        StopReason::AgentSilent => "a silent member, see its audit.json".into(),
        StopReason::Interrupted => "it was interrupted".into(),
        StopReason::Unknown(c) => format!("stop reason {c}"),
    }
}

impl From<LinkError> for DaemonStop {
    fn from(e: LinkError) -> Self {
        match e {
            e @ LinkError::PeerGone(_) => DaemonStop::OrchestratorGone(e),
            e @ LinkError::Protocol(_) => DaemonStop::Protocol(e),
            e => DaemonStop::Link(e),
        }
    }
}

/// Why `orchestrator host` fails: bad input of its own (exit 2) or the team's fault (exit 3).
#[cfg(feature = "hosts")]
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    /// `--host` names another host than the certificate in `--keys`.
    #[error(
        "--host {asked}: the certificate in --keys is host {certified}'s (a daemon is the host \
         its certificate names)"
    )]
    NotCertified { asked: u32, certified: u32 },
    /// The member binaries are not beside this one.
    #[error(transparent)]
    Binaries(#[from] cdm_team::team::MemberBinaryError),
    /// `--scenario` (the scenario this host expects) does not load.
    #[error(transparent)]
    Scenario(ScenarioError),
    /// `--keys` cannot secure the link.
    #[error(transparent)]
    Security(#[from] SecurityError),
    /// The daemon's work directory cannot be made.
    #[error(transparent)]
    WorkDir(#[from] WorkDirError),
    /// The orchestrator's endpoint cannot be reached.
    #[error("--connect: {0}")]
    Connect(#[source] NetError),
    /// The orchestrator answered no.
    #[error("refused by the orchestrator at {at}: {why}")]
    Refused { at: String, why: String },
    /// Joining failed on the network (no answer within the join timeout).
    #[error(transparent)]
    Join(NetError),
    /// The host's link cannot be opened.
    #[error(transparent)]
    Channel(NetError),
    /// The team's `--rt-priority` cannot be had on this machine.
    #[error("team {team}: {source}")]
    Priority {
        team: String,
        #[source]
        source: SchedError,
    },
    /// The assignment names a team or scenario this host cannot take.
    #[error(transparent)]
    Assignment(#[from] ScenarioError),
    /// The scenario the orchestrator sent does not hash as it says.
    #[error("the orchestrator's scenario has hash {here:016x} here and {there:016x} there")]
    ScenarioHash { here: u64, there: u64 },
    /// This host's shared memory refused the team's services.
    #[error(transparent)]
    Services(TransportError),
    /// A port, a relay or the layout of the host's share could not be made.
    #[error(transparent)]
    Transport(#[from] TransportError),
    #[error("cannot write {}: {source}", file.display())]
    WriteScenario {
        file: PathBuf,
        #[source]
        source: RunDirError,
    },
    #[error("cannot create the members' recording folder {}: {source}", dir.display())]
    RecordingDir {
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot start agent {id}: {source}")]
    Spawn {
        id: u32,
        #[source]
        source: std::io::Error,
    },
    /// The bridging ended before the plan was flown.
    #[error("host {host} of team {team}: {why}; its members were stopped")]
    Stopped {
        host: u32,
        team: String,
        #[source]
        why: Box<DaemonStop>,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texts_name_the_host_and_the_cause() {
        let silent = LinkLost::Silent {
            host: 2,
            who: "b (pid 7)".into(),
            after: Duration::from_millis(3000),
        };
        assert_eq!(
            silent.to_string(),
            "nothing heard from host 2 (b (pid 7)) for 3.0 s: network partition or daemon gone"
        );
        let gone: LinkLost = LinkError::PeerGone("its zenoh session closed".into()).into();
        assert!(gone.daemon_gone());
        assert_eq!(
            gone.to_string(),
            "the daemon is gone, its zenoh session closed: killed or exited"
        );
        let bad: LinkLost =
            LinkError::Protocol("frame on cdm/t/host/1/up: truncated".into()).into();
        assert_eq!(
            bad.to_string(),
            "the daemon sent a frame that does not decode (its protocol error): frame on cdm/t/host/1/up: truncated"
        );
        assert!(!bad.daemon_gone());
        let r = Refusal::Taken {
            host: 1,
            team: "t".into(),
            by: "c (pid 9)".into(),
        };
        assert_eq!(
            r.to_string(),
            "host 1 of team t is already taken by c (pid 9)"
        );
        let d = DaemonStop::Silent {
            after: Duration::from_millis(1500),
        };
        assert_eq!(
            d.to_string(),
            "nothing heard from the orchestrator for 1.5 s (network partition or orchestrator gone)"
        );
    }
}
