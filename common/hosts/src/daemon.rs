//! `orchestrator host --connect ENDPOINT`: one host's daemon. Joins the team whose orchestrator
//! listens there, spawns its share of the members on this host's shared memory, and bridges:
//! the clock and the other hosts' states its members read come down, every member's state goes
//! up (the orchestrator audits them all).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use cdm_iox::{MemberPorts, OrchestratorPorts, TeamLayout, TeamName};
use cdm_runtime::messages::{ClockCommand, ClockMsg, StopReason};
use cdm_runtime::process_exit::ProcessExit;
use cdm_scenario::{Checks, Scenario};
use cdm_team::out;
use cdm_team::team::{first_exited, spawn_member, stop_team, Spawned};
use cdm_team::{Exit, Failure};
use cdm_zenoh::{
    down_key, up_key, Assignment, Down, JoinReply, JoinRequest, Net, NetExit, NetState, Up,
    PROTOCOL_VERSION,
};

use crate::bridge::HEARTBEAT;
use crate::daemon_repair::DaemonRepairs;
use crate::error::DaemonStop;
use crate::host_link::{HostLink, ZenohLink};
use crate::idle::IdleBackoff;
use crate::repairs::{partners, single_loss_links, CrossRepairs};

/// The link to the orchestrator: its frames down, this host's up.
type OrchestratorLink = ZenohLink<Down, Up>;

/// `orchestrator host`'s options, validated.
pub struct DaemonOptions {
    pub connect: String,
    /// Mutual TLS with `--keys` (the host number is its certificate's), or `--insecure`.
    pub transport: crate::Transport,
    /// Join only this team.
    pub team: Option<TeamName>,
    /// Be this host of the team (1..K); default: the first free one.
    pub host: Option<u32>,
    /// The scenario this host expects the team to fly (refused when the team's differs).
    pub scenario: Option<PathBuf>,
    /// How long to wait for the orchestrator and for the members to start.
    pub join_timeout: Duration,
    pub quiet: bool,
}

/// A daemon that joined: its share of the team and its ports.
struct Joined {
    a: Assignment,
    team: TeamName,
    s: Scenario,
    mine: BTreeSet<u32>,
    link_timeout: Duration,
}

/// Runs the daemon to the end of the team (exit 0), a lost link (3) or a refusal (2).
pub fn run(o: &DaemonOptions) -> Result<Exit, Failure> {
    let interrupted = cdm_process::signals::install();
    cdm_team::team::member_binaries_present()?;
    super::workdir::sweep_dead();
    let expected_hash = match &o.scenario {
        Some(p) => Some(
            Scenario::load(p, Checks::Member)
                .map_err(Failure::bad_input)?
                .content_hash(),
        ),
        None => None,
    };
    let (security, bound) = crate::security::daemon(&o.transport)?;
    let host = match (bound, o.host) {
        (Some(k), Some(h)) if h != k => {
            return Err(Failure::bad_input(format!(
                "--host {h}: the certificate in --keys is host {k}'s (a daemon is the host its certificate names)"
            )))
        }
        (Some(k), _) => Some(k),
        (None, h) => h,
    };
    if let Some(w) = o.transport.warning(&o.connect) {
        tracing::warn!("{w}");
    }
    let net = Net::connect(&o.connect, &security)
        .map_err(|e| Failure::bad_input(format!("--connect: {e}")))?;
    let request = JoinRequest {
        version: PROTOCOL_VERSION,
        team: o.team.as_ref().map(|t| t.as_str().to_owned()),
        host,
        scenario_hash: expected_hash,
        who: who(),
    };
    let a = match net.join(&request, o.join_timeout) {
        Ok(JoinReply::Accepted(a)) => *a,
        Ok(JoinReply::Refused(why)) => {
            return Err(Failure::bad_input(format!(
                "refused by the orchestrator at {}: {why}",
                o.connect
            )))
        }
        Err(e) => return Err(Failure::fault(e)),
    };
    let (j, chan) = joined(&net, a)?;
    if let Some(p) = j.a.realtime_priority {
        // `--rt-priority` of the team: this thread (the bridge loop) now, the members through
        // their flag. zenoh's threads started before the team's mode was known and keep theirs.
        cdm_process::sched::fifo(p)
            .map_err(|e| Failure::bad_input(format!("team {}: {e}", j.team)))?;
    }
    if !o.quiet {
        out!(
            "joined team {} as host {}: agents {:?}",
            j.team,
            j.a.host,
            j.mine.iter().collect::<Vec<_>>()
        );
    }
    let dir = super::workdir::create(j.team.as_str())?;
    let result = fly(&j, chan, &dir, interrupted);
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Checks the assignment and opens the host's link.
fn joined(net: &Net, a: Assignment) -> Result<(Joined, OrchestratorLink), Failure> {
    let team = TeamName::new(&a.team).map_err(Failure::fault)?;
    let s = Scenario::parse_json(
        &a.scenario_json,
        "the orchestrator's scenario",
        Checks::Member,
    )
    .map_err(Failure::fault)?;
    if s.content_hash() != a.scenario_hash {
        return Err(Failure::fault(format!(
            "the orchestrator's scenario has hash {:016x} here and {:016x} there",
            s.content_hash(),
            a.scenario_hash
        )));
    }
    let mine = a
        .hosts_of
        .iter()
        .filter(|(_, h)| *h == a.host)
        .map(|(i, _)| *i)
        .collect();
    let chan = net
        .channel(&up_key(&a.team, a.host), &down_key(&a.team, a.host))
        .map(ZenohLink::new)
        .map_err(Failure::fault)?;
    let link_timeout = Duration::from_millis(a.link_timeout_ms.max(1));
    let j = Joined {
        a,
        team,
        s,
        mine,
        link_timeout,
    };
    Ok((j, chan))
}

/// `host name (pid N)`, for the orchestrator's messages.
fn who() -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
    format!("{} (pid {})", host.trim(), std::process::id())
}

/// This host's layout: its members with all their neighbours. The other hosts' members they
/// read or wake appear too, each standing in through a relay (its in-neighbours here are the
/// members of this host that it reads); edges between two other hosts are not here at all.
/// Returns the layout and, per relayed member, its in- and out-neighbours on this host.
fn host_layout(j: &Joined) -> Result<(TeamLayout, BTreeMap<u32, Neighbours>), Failure> {
    let mut ins = BTreeMap::new();
    let mut ghosts: BTreeMap<u32, Neighbours> = BTreeMap::new();
    for m in
        j.s.formation
            .members
            .iter()
            .filter(|m| j.mine.contains(&m.id))
    {
        let list = m.link.map_or_else(Vec::new, |l| l.in_neighbors.to_vec());
        for &n in list.iter().filter(|n| !j.mine.contains(n)) {
            ghosts.entry(n).or_default().outs.push(m.id);
        }
        ins.insert(m.id, list);
    }
    for m in
        j.s.formation
            .members
            .iter()
            .filter(|m| !j.mine.contains(&m.id))
    {
        let list = m.link.map_or_else(Vec::new, |l| l.in_neighbors.to_vec());
        let here: Vec<u32> = list.into_iter().filter(|n| j.mine.contains(n)).collect();
        if !here.is_empty() {
            ins.insert(m.id, here.clone());
            ghosts.entry(m.id).or_default().ins = here;
        }
    }
    if j.a.repair {
        // A repair may join a member here to one of another host: that one's services must
        // exist here before the members hear of the loss.
        for g in partners(&single_loss_links(&j.s), &j.mine) {
            ghosts.entry(g).or_default();
        }
    }
    let ids: Vec<u32> = j.mine.iter().chain(ghosts.keys()).copied().collect();
    let mut layout = TeamLayout::new(ids, ins, j.a.window)
        .map_err(Failure::fault)?
        .with_scenario_hash(j.a.scenario_hash);
    if j.a.repair {
        // The same room as on the orchestrator's host (`launch`'s layout).
        let room = cdm_team::loss::repair_room(&j.s, j.a.window);
        let mut groups: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
        for &(id, host) in j.a.hosts_of.iter().filter(|(_, h)| *h != 0) {
            groups.entry(host).or_default().push(id);
        }
        let groups: Vec<Vec<u32>> = groups.into_values().collect();
        layout = layout.with_repair_room(cdm_team::loss::with_group_losses(room, &j.s, &groups));
    }
    Ok((layout, ghosts))
}

/// The members' flags for the team's mode: real time paces on the start instant the clock
/// announces (a wall-clock time, the same on every host).
fn member_flags(a: &Assignment) -> Vec<String> {
    let Some(stale_s) = a.realtime_stale_after_s else {
        return Vec::new();
    };
    let mut flags = vec![
        "--realtime".into(),
        "--stale-after".into(),
        stale_s.to_string(),
    ];
    if let Some(p) = a.realtime_priority {
        flags.extend(["--rt-priority".into(), p.to_string()]);
    }
    flags
}

/// A relayed member's neighbours on this host.
#[derive(Default)]
struct Neighbours {
    ins: Vec<u32>,
    outs: Vec<u32>,
}

/// Creates the host's services, spawns the members, waits for them, then bridges to the end.
fn fly(
    j: &Joined,
    chan: OrchestratorLink,
    dir: &Path,
    interrupted: &std::sync::atomic::AtomicBool,
) -> Result<Exit, Failure> {
    let (layout, ghosts) = host_layout(j)?;
    let mut ports = OrchestratorPorts::create(&j.team, &layout).map_err(Failure::bad_input)?;
    let host_of: BTreeMap<u32, u32> = j.a.hosts_of.iter().copied().collect();
    let mut relays = BTreeMap::new();
    for (&g, nb) in &ghosts {
        let h = host_of.get(&g).copied().unwrap_or(0);
        let hash = j.a.scenario_hash;
        let relay = MemberPorts::open_relay(&j.team, h, g, hash, &nb.ins, &nb.outs)
            .map_err(Failure::fault)?;
        relays.insert(g, relay);
    }
    let file = dir.join("scenario.json");
    cdm_records::rundir::write_atomic(&file, j.a.scenario_json.as_bytes())
        .map_err(|e| Failure::fault(format!("cannot write {}: {e}", file.display())))?;
    let mut children = Vec::new();
    let flags = member_flags(&j.a);
    for m in
        j.s.formation
            .members
            .iter()
            .filter(|m| j.mine.contains(&m.id))
    {
        match spawn_member(&file, &j.team, m.id, m.role, &flags) {
            Ok(child) => children.push(Spawned { id: m.id, child }),
            Err(e) => {
                stop_team(&mut ports, &mut children, &j.s, StopReason::AgentFault);
                return Err(Failure::fault(format!("cannot start agent {}: {e}", m.id)));
            }
        }
    }
    let now = Instant::now();
    let repairs = DaemonRepairs::new(
        j.team.clone(),
        host_of,
        j.mine.clone(),
        CrossRepairs::new(&j.s),
        now,
    );
    let mut link = Link::new(j, chan, repairs, now);
    let outcome = link
        .wait_ready(&mut ports, &mut children, interrupted)
        .and_then(|()| link.bridge(&mut ports, &mut relays, &mut children, interrupted));
    let reason = match &outcome {
        Ok(r) => *r,
        Err(_) => StopReason::AgentSilent,
    };
    if outcome.is_ok() {
        link.up_while_stopping(&mut ports, &mut children);
    }
    stop_team(&mut ports, &mut children, &j.s, reason);
    if outcome.is_ok() {
        // What the members published as they stopped (real time: their pacing reports).
        let now = Instant::now();
        let _ = link.up(&mut ports, now);
        let _ = link.send(&Up::Stopped, now);
    }
    drop(relays);
    if let Err(e) = ports.shutdown() {
        tracing::warn!("{e}");
    }
    let outcome = outcome.and_then(|reason| match reason {
        StopReason::Finished => Ok(()),
        r => Err(DaemonStop::TeamStopped(r)),
    });
    outcome.map(|()| Exit::Safe).map_err(|why| {
        Failure::fault(format!(
            "host {} of team {}: {why}; its members were stopped",
            j.a.host, j.team
        ))
    })
}

/// The daemon's side of the link, with its deadlines, over link `L` (zenoh; a fake one in the
/// unit tests). Every step is handed the instant of its turn: the loops read the clock.
struct Link<'a, L = OrchestratorLink> {
    j: &'a Joined,
    chan: L,
    last_heard: Instant,
    last_sent: Instant,
    /// Members whose exit was reported.
    reported: BTreeSet<u32>,
    repairs: DaemonRepairs,
}

/// Interrupted by a signal: the daemon says which.
fn interrupted_by() -> DaemonStop {
    DaemonStop::Interrupted(cdm_process::signals::received())
}

impl<'a, L: HostLink<In = Down, Out = Up>> Link<'a, L> {
    fn new(j: &'a Joined, chan: L, repairs: DaemonRepairs, now: Instant) -> Self {
        Link {
            j,
            chan,
            last_heard: now,
            last_sent: now,
            reported: BTreeSet::new(),
            repairs,
        }
    }

    /// Heartbeat out when due at `now`; an error when the orchestrator has been silent too long.
    fn keep_alive(&mut self, now: Instant) -> Result<(), DaemonStop> {
        if now.saturating_duration_since(self.last_sent) >= HEARTBEAT {
            self.send(&Up::Heartbeat, now)?;
        }
        if now.saturating_duration_since(self.last_heard) > self.j.link_timeout {
            return Err(DaemonStop::Silent {
                after: self.j.link_timeout,
            });
        }
        Ok(())
    }

    /// Between two turns at `last` and `now`, this process did not run for longer than the link
    /// timeout (SIGSTOP, a debugger): checked before the frames queued meanwhile are read, which
    /// would make the link look alive.
    fn check_ran(&self, last: Instant, now: Instant) -> Result<(), DaemonStop> {
        let gap = now.saturating_duration_since(last);
        let timeout = self.j.link_timeout;
        if gap > timeout {
            return Err(DaemonStop::Stalled { gap, timeout });
        }
        Ok(())
    }

    fn send(&mut self, frame: &Up, now: Instant) -> Result<(), DaemonStop> {
        self.last_sent = now;
        Ok(self.chan.send(frame)?)
    }

    /// Frames from the orchestrator before the team starts: a stop ends the wait.
    fn before_start(&mut self, now: Instant) -> Result<(), DaemonStop> {
        while let Some(f) = self.chan.try_recv()? {
            self.last_heard = now;
            if let Down::Clock(c) = f {
                if matches!(ClockMsg::from(c).command(), ClockCommand::Stop(_)) {
                    return Err(DaemonStop::StoppedBeforeStart);
                }
            }
        }
        self.keep_alive(now)
    }

    /// Waits (bounded) until every member of this host has opened its ports, then says so.
    fn wait_ready(
        &mut self,
        ports: &mut OrchestratorPorts,
        children: &mut [Spawned],
        interrupted: &std::sync::atomic::AtomicBool,
    ) -> Result<(), DaemonStop> {
        let n = self.j.mine.len() as u64;
        let deadline = Duration::from_secs(30) + Duration::from_millis(60 * n);
        let started = Instant::now();
        while !ports.readiness().is_complete() {
            let now = Instant::now();
            if interrupted.load(Ordering::Relaxed) {
                return Err(interrupted_by());
            }
            if let Some((id, how)) = first_exited(children) {
                return Err(DaemonStop::ExitedEarly { id, how });
            }
            if now.saturating_duration_since(started) > deadline {
                let late = ports.readiness().waiting_for();
                return Err(DaemonStop::NotStarted { late, deadline });
            }
            self.before_start(now)?;
            let _ = ports.wait(Duration::from_millis(20));
        }
        let subscriptions = ports
            .subscriber_graph(self.j.mine.iter().copied())
            .unwrap_or_default();
        self.send(&Up::Ready { subscriptions }, Instant::now())
    }

    /// Carries frames both ways until the orchestrator's stop (its reason) or a lost link.
    fn bridge(
        &mut self,
        ports: &mut OrchestratorPorts,
        relays: &mut BTreeMap<u32, MemberPorts>,
        children: &mut [Spawned],
        interrupted: &std::sync::atomic::AtomicBool,
    ) -> Result<StopReason, DaemonStop> {
        let mut last_child_check = Instant::now();
        let mut last_turn = last_child_check;
        let realtime = self.j.a.realtime_stale_after_s.is_some();
        let mut idle = IdleBackoff::for_team(realtime);
        loop {
            let now = Instant::now();
            if interrupted.load(Ordering::Relaxed) {
                return Err(interrupted_by());
            }
            self.check_ran(last_turn, now)?;
            last_turn = now;
            let mut busy = false;
            while let Some(f) = self.chan.try_recv()? {
                self.last_heard = now;
                busy = true;
                match &f {
                    Down::Kill(id) => cdm_team::loss::kill_and_reap(children, *id),
                    Down::Clock(c) => self.repairs.on_clock(&ClockMsg::from(*c), relays, now)?,
                    _ => {}
                }
                if let Some(reason) = down(f, ports, relays)? {
                    return Ok(reason);
                }
            }
            busy |= self.up(ports, now)?;
            self.repairs.hand_over_ready(relays, now);
            let linked = self.repairs.connected(ports, now);
            if !linked.is_empty() {
                self.send(&Up::Linked(linked), now)?;
            }
            if now.saturating_duration_since(last_child_check) > Duration::from_millis(100) {
                last_child_check = now;
                self.report_exits(ports, children, now)?;
            }
            self.keep_alive(now)?;
            if let Some(sleep) = idle.after(busy) {
                self.chan.wait(sleep);
            }
        }
    }

    /// This host's members' states (and fault reports) up, in order; true when any.
    fn up(&mut self, ports: &mut OrchestratorPorts, now: Instant) -> Result<bool, DaemonStop> {
        let mine = &self.j.mine;
        let mut batch: Vec<NetState> = vec![];
        ports.receive_states(|m| {
            if mine.contains(&m.id) {
                batch.push(m.into());
            }
        })?;
        if batch.is_empty() {
            return Ok(false);
        }
        self.send(&Up::States(batch), now)?;
        Ok(true)
    }

    /// After the orchestrator's stop (the bridge published it here): the members' last states
    /// (real time: their final pacing reports) go up as they come, until every member exited
    /// or the graceful stop's 3 s passed; the orchestrator waits for them a bounded while.
    fn up_while_stopping(&mut self, ports: &mut OrchestratorPorts, children: &mut [Spawned]) {
        let until = Instant::now() + Duration::from_secs(3);
        loop {
            let now = Instant::now();
            let _ = self.up(ports, now);
            let running = children
                .iter_mut()
                .any(|c| matches!(c.child.try_wait(), Ok(None)));
            if !running || now >= until {
                return;
            }
            let _ = ports.wait(Duration::from_millis(5));
        }
    }

    /// A member that exited: its last states first, then the exit.
    fn report_exits(
        &mut self,
        ports: &mut OrchestratorPorts,
        children: &mut [Spawned],
        now: Instant,
    ) -> Result<(), DaemonStop> {
        for c in children.iter_mut() {
            if self.reported.contains(&c.id) {
                continue;
            }
            if let Ok(Some(status)) = c.child.try_wait() {
                self.up(ports, now)?;
                let how = NetExit::of(&ProcessExit::of(status));
                self.reported.insert(c.id);
                self.send(&Up::Exited { id: c.id, how }, now)?;
            }
        }
        Ok(())
    }
}

/// One frame from the orchestrator: the clock to every member (a stop ends the bridge), or
/// other hosts' states re-published here for their readers.
fn down(
    f: Down,
    ports: &mut OrchestratorPorts,
    relays: &mut BTreeMap<u32, MemberPorts>,
) -> Result<Option<StopReason>, DaemonStop> {
    match f {
        Down::Clock(c) => {
            let c = ClockMsg::from(c);
            ports.publish_clock(c)?;
            if let ClockCommand::Stop(reason) = c.command() {
                return Ok(Some(reason));
            }
        }
        Down::States(states) => {
            let mut touched = vec![];
            for st in states {
                if let Some(relay) = relays.get_mut(&st.id) {
                    relay.publish_quietly(st.into())?;
                    touched.push(st.id);
                }
            }
            touched.dedup();
            for id in touched {
                if let Some(relay) = relays.get_mut(&id) {
                    relay.notify_readers()?;
                }
            }
        }
        // Handled by the caller (it owns the children).
        Down::Heartbeat | Down::Kill(_) => {}
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assignment(stale: Option<f64>, priority: Option<u8>) -> Assignment {
        Assignment {
            team: "t".into(),
            host: 1,
            hosts_of: vec![(1, 0), (2, 1)],
            scenario_json: String::new(),
            scenario_hash: 0,
            window: 16,
            link_timeout_ms: 3000,
            realtime_stale_after_s: stale,
            realtime_priority: priority,
            repair: false,
        }
    }

    /// Host 1 of paper40 over two hosts, as a daemon joins it.
    fn joined() -> Joined {
        let s = Scenario::builtin("paper40").unwrap();
        let mut a = assignment(None, None);
        a.hosts_of = s
            .formation
            .members
            .iter()
            .map(|m| (m.id, m.id % 2))
            .collect();
        let mine = a
            .hosts_of
            .iter()
            .filter(|p| p.1 == 1)
            .map(|p| p.0)
            .collect();
        Joined {
            team: TeamName::new("unit").unwrap(),
            s,
            mine,
            link_timeout: Duration::from_millis(a.link_timeout_ms),
            a,
        }
    }

    type Fake = crate::host_link::FakeLink<Down, Up>;

    fn link(j: &Joined, t0: Instant) -> Link<'_, Fake> {
        let host_of = j.a.hosts_of.iter().copied().collect();
        let repairs = CrossRepairs::new(&j.s);
        let repairs = DaemonRepairs::new(j.team.clone(), host_of, j.mine.clone(), repairs, t0);
        Link::new(j, Fake::default(), repairs, t0)
    }

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    #[test]
    fn the_daemon_keeps_its_link_alive_and_gives_up_on_a_silent_orchestrator() {
        let (j, t0) = (joined(), Instant::now());
        let mut l = link(&j, t0);
        l.keep_alive(t0 + ms(199)).unwrap();
        assert!(l.chan.sent.is_empty());
        l.keep_alive(t0 + ms(200)).unwrap();
        assert_eq!(l.chan.sent, [Up::Heartbeat]);
        l.chan.incoming.push_back(Ok(Down::Heartbeat));
        l.before_start(t0 + ms(2000)).unwrap();
        l.keep_alive(t0 + ms(5000)).unwrap();
        let e = l.keep_alive(t0 + ms(5001)).unwrap_err();
        assert!(matches!(e, DaemonStop::Silent { .. }), "{e}");
        assert_eq!(
            e.to_string(),
            "nothing heard from the orchestrator for 3.0 s (network partition or orchestrator gone)"
        );
    }

    #[test]
    fn a_daemon_that_did_not_run_for_the_link_timeout_says_so() {
        let (j, t0) = (joined(), Instant::now());
        let l = link(&j, t0);
        l.check_ran(t0, t0 + ms(3000)).unwrap();
        let e = l.check_ran(t0, t0 + ms(5200)).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("this daemon did not run for 5.2 s"),
            "{e}"
        );
        let stopped = DaemonStop::TeamStopped(StopReason::AgentSilent);
        assert_eq!(
            stopped.to_string(),
            "the orchestrator stopped the team (a silent member, see its audit.json)"
        );
    }

    #[test]
    fn a_stop_before_the_start_or_a_closed_session_ends_the_wait() {
        let (j, t0) = (joined(), Instant::now());
        let mut l = link(&j, t0);
        let stop = ClockMsg::stop(0, 0, StopReason::AgentFault);
        l.chan.incoming.push_back(Ok(Down::Clock(stop.into())));
        let e = l.before_start(t0 + ms(10)).unwrap_err();
        assert!(matches!(e, DaemonStop::StoppedBeforeStart), "{e}");

        let gone = crate::host_link::LinkError::PeerGone("its zenoh session closed".into());
        l.chan.incoming.push_back(Err(gone));
        let e = l.before_start(t0 + ms(20)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "the orchestrator is gone, its zenoh session closed: killed or exited"
        );
    }

    #[test]
    fn members_fly_in_the_teams_mode() {
        assert!(member_flags(&assignment(None, None)).is_empty());
        assert_eq!(
            member_flags(&assignment(Some(0.5), None)),
            ["--realtime", "--stale-after", "0.5"]
        );
        assert_eq!(
            member_flags(&assignment(Some(0.25), Some(20))),
            ["--realtime", "--stale-after", "0.25", "--rt-priority", "20"]
        );
    }
}
