//! What the bridge thread knows of each host's link, shared with the launch (plain data, no
//! I/O): which hosts were lost and why, which stopped, when each was last heard. From it, the
//! team's fault is said in the terms of hosts ([`Links::explain`]) and a real-time monitor knows
//! whose final pacing reports may still come ([`Links::reporting`]).

use std::collections::{BTreeMap, BTreeSet};
use std::time::Instant;

use cdm_core::audit::FaultRecord;
use cdm_core::outcome::FaultKind;

/// A host whose link was lost, and the members that went with it.
#[derive(Debug, Clone, PartialEq)]
pub struct LostHost {
    /// The daemon (host name and pid).
    pub who: String,
    pub members: Vec<u32>,
    pub why: String,
}

/// Every remote host's link as the bridge last saw it.
#[derive(Debug, Clone, Default)]
pub struct Links {
    /// Member id -> host number (host 0 is the orchestrator's).
    pub host_of: BTreeMap<u32, u32>,
    pub lost: BTreeMap<u32, LostHost>,
    /// Hosts whose daemon stopped its members and said so.
    pub stopped: BTreeSet<u32>,
    /// Joined hosts: the daemon and when a frame last came from it.
    pub heard: BTreeMap<u32, (String, Instant)>,
    /// Remote members that exited (`--on-loss repair`: lost, not a fault), oldest first, with
    /// `first_exited`'s wording of how.
    pub exited: Vec<(u32, String)>,
    /// Remote members the team core asked to kill, not yet sent to their daemon.
    pub to_kill: Vec<u32>,
    /// Links (reader, writer) of repairs, whose reader runs on another host, that its daemon
    /// reported connected.
    pub linked: BTreeSet<(u32, u32)>,
    /// Edges (source, reader) that repairs made cross hosts.
    pub crossing_added: BTreeSet<(u32, u32)>,
}

impl Links {
    /// The host of member `id` when it is not this one.
    pub fn remote_host(&self, id: Option<u32>) -> Option<u32> {
        id.and_then(|id| self.host_of.get(&id).copied())
            .filter(|&h| h != 0)
    }

    /// True when member `id` runs on another host whose daemon joined and has neither stopped
    /// nor been lost: its reports may still arrive.
    pub fn reporting(&self, id: u32) -> bool {
        self.remote_host(Some(id)).is_some_and(|h| {
            self.heard.contains_key(&h) && !self.stopped.contains(&h) && !self.lost.contains_key(&h)
        })
    }

    /// True when `f` is a remote member's silence whose host has not been judged yet: the
    /// bridge may be about to call the host lost (real time: a member's 0.5 s staleness can
    /// come before the link's verdict).
    pub fn undecided(&self, f: &FaultRecord) -> bool {
        f.kind == FaultKind::AgentSilent
            && self
                .remote_host(f.agent)
                .is_some_and(|h| !self.lost.contains_key(&h))
    }

    /// The team's fault said in the terms of hosts, at `now`:
    /// - a member reported lost with its host (`host-lost`), or a remote member gone silent
    ///   (`agent-silent`) on a host the bridge lost, is that host's loss, naming the host, why,
    ///   and every member it ran;
    /// - any other silence of a remote member names its host and how long its link was quiet
    ///   (a silent link points at the network, a live one at the member).
    pub fn explain(&self, f: FaultRecord, now: Instant) -> FaultRecord {
        let Some(host) = self.remote_host(f.agent) else {
            return f;
        };
        if !matches!(f.kind, FaultKind::HostLost | FaultKind::AgentSilent) {
            return f;
        }
        if let Some(h) = self.lost.get(&host) {
            let message = format!(
                "host {host} ({}) lost at tick {}: {}; its agents {:?} were lost with it",
                h.who, f.tick, h.why, h.members
            );
            return FaultRecord {
                kind: FaultKind::HostLost,
                message,
                ..f
            };
        }
        let Some((who, at)) = self.heard.get(&host) else {
            return f;
        };
        let quiet_ms = now.saturating_duration_since(*at).as_secs_f64() * 1e3;
        let message = format!(
            "{}; agent {} runs on host {host} ({who}), last heard {quiet_ms:.0} ms before",
            f.message,
            f.agent.unwrap_or_default()
        );
        FaultRecord { message, ..f }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    /// The links as of `now` (a test's own instant: its "ms before" must not depend on how
    /// long a loaded machine takes between two `Instant::now()`).
    fn links_at(now: Instant) -> Links {
        Links {
            host_of: [(1, 0), (2, 1), (3, 1), (4, 2)].into_iter().collect(),
            heard: [
                (1, ("b (pid 7)".into(), now)),
                (2, ("c (pid 8)".into(), now)),
            ]
            .into_iter()
            .collect(),
            ..Links::default()
        }
    }

    fn links() -> Links {
        links_at(Instant::now())
    }

    fn silent(agent: u32) -> FaultRecord {
        let what = format!("agent {agent} sent no state for 600 ms");
        FaultRecord::new(FaultKind::AgentSilent, Some(agent), None, 42, what)
    }

    #[test]
    fn a_remote_silence_on_a_lost_host_is_the_hosts_loss() {
        let mut l = links();
        assert!(l.undecided(&silent(3)));
        l.lost.insert(
            1,
            LostHost {
                who: "b (pid 7)".into(),
                members: vec![2, 3],
                why: "its zenoh session closed".into(),
            },
        );
        assert!(!l.undecided(&silent(3)));
        let f = l.explain(silent(3), Instant::now());
        assert_eq!(f.kind, FaultKind::HostLost);
        assert_eq!((f.agent, f.tick), (Some(3), 42));
        for needle in ["host 1 (b (pid 7)) lost at tick 42", "zenoh", "[2, 3]"] {
            assert!(f.message.contains(needle), "{needle:?} in {}", f.message);
        }
    }

    #[test]
    fn a_remote_silence_on_a_live_link_names_the_host_and_its_quiet() {
        let heard = Instant::now();
        let l = links_at(heard);
        let later = heard + Duration::from_millis(250);
        let f = l.explain(silent(4), later);
        assert_eq!(f.kind, FaultKind::AgentSilent);
        assert!(
            f.message
                .starts_with("agent 4 sent no state for 600 ms; agent 4 runs on host 2"),
            "{}",
            f.message
        );
        assert!(
            f.message.contains("last heard 250 ms before"),
            "{}",
            f.message
        );
    }

    #[test]
    fn local_members_and_other_faults_are_left_alone() {
        let mut l = links();
        l.lost.insert(
            1,
            LostHost {
                who: "b".into(),
                members: vec![2, 3],
                why: "gone".into(),
            },
        );
        assert_eq!(l.explain(silent(1), Instant::now()), silent(1));
        assert!(!l.undecided(&silent(1)));
        let other = FaultRecord::new(FaultKind::AgentExited, Some(2), None, 5, "x".into());
        assert_eq!(l.explain(other.clone(), Instant::now()), other);
    }

    #[test]
    fn reports_are_awaited_from_live_remote_hosts_only() {
        let mut l = links();
        assert!(
            !l.reporting(1),
            "host 0's member: its own process is watched"
        );
        assert!(l.reporting(2) && l.reporting(4));
        l.stopped.insert(1);
        assert!(!l.reporting(2));
        l.lost.insert(
            2,
            LostHost {
                who: "c".into(),
                members: vec![4],
                why: "gone".into(),
            },
        );
        assert!(!l.reporting(4));
        assert!(!l.reporting(99), "an unknown id is nobody's");
    }
}
