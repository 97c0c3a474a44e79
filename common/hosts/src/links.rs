//! What the bridge thread knows of each host's link, shared with the launch (plain data, no
//! I/O): which hosts were lost and why, which stopped, when each was last heard. From it, the
//! team's fault is said in the terms of hosts ([`Links::explain`]) and a real-time monitor knows
//! whose final pacing reports may still come ([`Links::reporting`]).

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use cdm_model::outcome::FaultKind;
use cdm_records::audit::FaultRecord;
use cdm_runtime::process_exit::ProcessExit;

/// How long a remote member's silence waits at least for the bridge's verdict on its host: a
/// closed session is reported after zenoh's grace (150 ms); the rest is slack for a loaded
/// machine. It is also the slack after a quiet link's own deadline.
pub const VERDICT_WAIT: Duration = Duration::from_millis(600);

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
    /// how.
    pub exited: Vec<(u32, ProcessExit)>,
    /// Remote members the team core asked to kill, not yet sent to their daemon.
    pub to_kill: Vec<u32>,
    /// Links (reader, writer) of repairs, whose reader runs on another host, that its daemon
    /// reported connected.
    pub linked: BTreeSet<(u32, u32)>,
    /// Edges (source, reader) that repairs made cross hosts.
    pub crossing_added: BTreeSet<(u32, u32)>,
    /// Silence on a link for this long loses the host (`--link-timeout`); `None`: judged by
    /// the bridge thread only.
    pub link_timeout: Option<Duration>,
}

/// What the bridge learnt of a host's link, for the launch: the bridge thread applies its
/// core's notes to the [`Links`] it shares ([`Links::note`]).
#[derive(Debug, Clone, PartialEq)]
pub enum Note {
    /// A frame came from host `host` (its daemon `who`) at `at`.
    Heard { host: u32, who: String, at: Instant },
    /// The host's link is lost, and its members with it.
    Lost { host: u32, lost: LostHost },
    /// The host's daemon stopped its members and said so.
    Stopped(u32),
    /// A remote member exited (`--on-loss repair`: lost, not a fault).
    Exited(u32, ProcessExit),
    /// Links (reader, writer) of repairs that a daemon reported connected.
    Linked(Vec<(u32, u32)>),
    /// An edge (source, reader) that a repair made cross hosts.
    CrossingAdded(u32, u32),
}

impl Links {
    /// Applies one of the bridge's notes.
    pub fn note(&mut self, n: Note) {
        match n {
            Note::Heard { host, who, at } => {
                self.heard.insert(host, (who, at));
            }
            Note::Lost { host, lost } => {
                self.lost.insert(host, lost);
            }
            Note::Stopped(host) => {
                self.stopped.insert(host);
            }
            Note::Exited(id, how) => self.exited.push((id, how)),
            Note::Linked(pairs) => self.linked.extend(pairs),
            Note::CrossingAdded(source, reader) => {
                self.crossing_added.insert((source, reader));
            }
        }
    }

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

    /// Until when the team's fault `f`, seen at `seen`, waits for the bridge's verdict on the
    /// host of the member it names; `None`: it can be said now (not a remote member's silence,
    /// or its host already judged). Always [`VERDICT_WAIT`] (a closed session's report is on its
    /// way); when nothing came from that host since `seen`, until its link's own deadline
    /// ([`Links::link_timeout`] after its last frame) and [`VERDICT_WAIT`] more: a partition, or
    /// a daemon that does not run (SIGSTOP), is the host's loss, not its member's silence. A link
    /// heard after the fault lives: the member is silent on its own.
    pub fn verdict_wait(&self, f: &FaultRecord, seen: Instant) -> Option<Instant> {
        if !self.undecided(f) {
            return None;
        }
        let floor = seen + VERDICT_WAIT;
        let last = self
            .remote_host(f.agent)
            .and_then(|h| self.heard.get(&h))
            .map(|(_, at)| *at);
        Some(match (last, self.link_timeout) {
            (Some(at), Some(timeout)) if at <= seen => floor.max(at + timeout + VERDICT_WAIT),
            _ => floor,
        })
    }

    /// These links as judged at `now`: a joined host, neither stopped nor lost, whose link has
    /// been quiet for longer than the link timeout is lost, as the bridge thread would call it
    /// on its next turn. The launch judges so itself once a fault's wait is over: the bridge
    /// thread may be held in a send that zenoh blocks while the link is down (real time
    /// forwards states at the clock's rate), and a partition must still be named as one.
    pub fn judged_at(mut self, now: Instant) -> Self {
        let Some(timeout) = self.link_timeout else {
            return self;
        };
        for (&host, (who, at)) in &self.heard {
            let quiet = now.saturating_duration_since(*at);
            if quiet <= timeout || self.stopped.contains(&host) || self.lost.contains_key(&host) {
                continue;
            }
            let members = self
                .host_of
                .iter()
                .filter(|&(_, &h)| h == host)
                .map(|(&id, _)| id)
                .collect();
            let why = crate::error::LinkLost::Silent {
                host,
                who: who.clone(),
                after: timeout,
            };
            let lost = LostHost {
                who: who.clone(),
                members,
                why: why.to_string(),
            };
            self.lost.insert(host, lost);
        }
        self
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
    fn a_silence_waits_for_a_quiet_links_deadline_and_not_for_a_live_one() {
        let heard = Instant::now();
        let mut l = links_at(heard);
        let timeout = Duration::from_secs(3);
        l.link_timeout = Some(timeout);
        // Host 2 quiet since `heard`; its member 4 seen silent 500 ms later.
        let seen = heard + Duration::from_millis(500);
        assert_eq!(
            l.verdict_wait(&silent(4), seen),
            Some(heard + timeout + VERDICT_WAIT)
        );
        // A frame from host 2 after the fault: only the floor.
        l.heard
            .insert(2, ("c (pid 8)".into(), seen + Duration::from_millis(200)));
        assert_eq!(l.verdict_wait(&silent(4), seen), Some(seen + VERDICT_WAIT));
        // Judged, a local member, another fault: at once.
        l.lost.insert(
            2,
            LostHost {
                who: "c (pid 8)".into(),
                members: vec![4],
                why: "gone".into(),
            },
        );
        assert_eq!(l.verdict_wait(&silent(4), seen), None);
        assert_eq!(l.verdict_wait(&silent(1), seen), None);
        let other = FaultRecord::new(FaultKind::AgentExited, Some(3), None, 5, "x".into());
        assert_eq!(l.verdict_wait(&other, seen), None);
    }

    #[test]
    fn a_link_quiet_past_its_timeout_is_judged_lost_naming_its_members() {
        let heard = Instant::now();
        let mut l = links_at(heard);
        let later = heard + Duration::from_millis(2500);
        assert!(
            l.clone().judged_at(later).lost.is_empty(),
            "no timeout: the thread judges"
        );
        l.link_timeout = Some(Duration::from_secs(2));
        l.heard
            .insert(1, ("b (pid 7)".into(), heard + Duration::from_millis(1000)));
        l.stopped.insert(1);
        let j = l.clone().judged_at(later);
        assert_eq!(
            j.lost.keys().collect::<Vec<_>>(),
            [&2],
            "host 1 heard late and stopped"
        );
        assert_eq!(j.lost[&2].members, [4]);
        assert_eq!(
            j.lost[&2].why,
            "nothing heard from host 2 (c (pid 8)) for 2.0 s: network partition or daemon gone"
        );
        let f = j.explain(silent(4), later);
        assert_eq!(f.kind, FaultKind::HostLost);
        assert!(l
            .judged_at(heard + Duration::from_millis(1999))
            .lost
            .is_empty());
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
