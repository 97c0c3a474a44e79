//! Why a host's link ends, as typed values: the bridge's verdict on a daemon ([`LinkLost`]), a
//! join request it refuses ([`Refusal`]), and what ends a daemon's bridging ([`DaemonStop`]).
//! Their texts are written here and nowhere else; the multi-host tests and the operators read
//! them in the log, audit.json's fault and hosts.json.

use std::time::Duration;

use cdm_iox::TransportError;
use cdm_runtime::messages::StopReason;
use cdm_runtime::notices::NoticeGap;

use crate::host_link::LinkError;

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
