//! `orchestrator host --connect ENDPOINT`: one host's daemon. Joins the team whose orchestrator
//! listens there, spawns its share of the members on this host's shared memory, and bridges:
//! the clock and the other hosts' states its members read come down, every member's state goes
//! up (the orchestrator audits them all).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use cdm_core::scenario::{Checks, Scenario};
use cdm_iox::{MemberPorts, OrchestratorPorts, TeamLayout, TeamName};
use cdm_runtime::messages::{ClockCommand, ClockMsg, StopReason};
use cdm_team::out;
use cdm_zenoh::{
    down_key, up_key, Assignment, Channel, Down, JoinReply, JoinRequest, Net, NetState, Up,
    PROTOCOL_VERSION,
};

use super::bridge::HEARTBEAT;
use super::daemon_repair::DaemonRepairs;
use super::repairs::{partners, single_loss_links, CrossRepairs};
use cdm_team::team::{first_exited, spawn_member, stop_team, Spawned};
use cdm_team::{Exit, Failure};

/// `orchestrator host`'s options, validated.
pub struct DaemonOptions {
    pub connect: String,
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
    let net =
        Net::connect(&o.connect).map_err(|e| Failure::bad_input(format!("--connect: {e}")))?;
    let request = JoinRequest {
        version: PROTOCOL_VERSION,
        team: o.team.as_ref().map(|t| t.as_str().to_owned()),
        host: o.host,
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
fn joined(net: &Net, a: Assignment) -> Result<(Joined, Channel), Failure> {
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
    chan: Channel,
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
    cdm_core::rundir::write_atomic(&file, j.a.scenario_json.as_bytes())
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
    let repairs = DaemonRepairs::new(
        j.team.clone(),
        host_of,
        j.mine.clone(),
        CrossRepairs::new(&j.s),
    );
    let mut link = Link {
        j,
        chan,
        last_heard: Instant::now(),
        last_sent: Instant::now(),
        reported: BTreeSet::new(),
        repairs,
    };
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
        let _ = link.up(&mut ports);
        let _ = link.chan.send(&Up::Stopped);
    }
    drop(relays);
    if let Err(e) = ports.shutdown() {
        tracing::warn!("{e}");
    }
    outcome.map(|_| Exit::Safe).map_err(|why| {
        Failure::fault(format!(
            "host {} of team {}: {why}; its members were stopped",
            j.a.host, j.team
        ))
    })
}

/// The daemon's side of the link, with its deadlines.
struct Link<'a> {
    j: &'a Joined,
    chan: Channel,
    last_heard: Instant,
    last_sent: Instant,
    /// Members whose exit was reported.
    reported: BTreeSet<u32>,
    repairs: DaemonRepairs,
}

impl Link<'_> {
    /// Heartbeat out when due; an error when the orchestrator has been silent too long.
    fn keep_alive(&mut self) -> Result<(), String> {
        if self.last_sent.elapsed() >= HEARTBEAT {
            self.send(&Up::Heartbeat)?;
        }
        if self.last_heard.elapsed() > self.j.link_timeout {
            return Err(format!(
                "nothing heard from the orchestrator for {:.1} s (network partition or \
                 orchestrator gone)",
                self.j.link_timeout.as_secs_f64()
            ));
        }
        Ok(())
    }

    fn send(&mut self, frame: &Up) -> Result<(), String> {
        self.last_sent = Instant::now();
        self.chan.send(frame).map_err(|e| e.to_string())
    }

    /// Waits (bounded) until every member of this host has opened its ports, then says so.
    fn wait_ready(
        &mut self,
        ports: &mut OrchestratorPorts,
        children: &mut [Spawned],
        interrupted: &std::sync::atomic::AtomicBool,
    ) -> Result<(), String> {
        let n = self.j.mine.len() as u64;
        let deadline = Duration::from_secs(30) + Duration::from_millis(60 * n);
        let started = Instant::now();
        while !ports.readiness().is_complete() {
            if interrupted.load(Ordering::Relaxed) {
                return Err(format!(
                    "interrupted by {}",
                    cdm_process::signals::received()
                ));
            }
            if let Some((id, how)) = first_exited(children) {
                return Err(format!("agent {id} {how} before the team started"));
            }
            if started.elapsed() > deadline {
                let late = ports.readiness().waiting_for();
                return Err(format!("agents {late:?} did not start within {deadline:?}"));
            }
            while let Some(f) = self.chan.try_recv::<Down>().map_err(link_error)? {
                self.last_heard = Instant::now();
                if let Down::Clock(c) = f {
                    if matches!(ClockMsg::from(c).command(), ClockCommand::Stop(_)) {
                        return Err("the orchestrator stopped the team before it started".into());
                    }
                }
            }
            self.keep_alive()?;
            let _ = ports.wait(Duration::from_millis(20));
        }
        let mut subscriptions = BTreeMap::new();
        for &id in &self.j.mine {
            subscriptions.insert(id, ports.subscriber_nodes(id).unwrap_or_default());
        }
        self.send(&Up::Ready { subscriptions })
    }

    /// Carries frames both ways until the orchestrator's stop (its reason) or a lost link.
    fn bridge(
        &mut self,
        ports: &mut OrchestratorPorts,
        relays: &mut BTreeMap<u32, MemberPorts>,
        children: &mut [Spawned],
        interrupted: &std::sync::atomic::AtomicBool,
    ) -> Result<StopReason, String> {
        let mut last_child_check = Instant::now();
        let realtime = self.j.a.realtime_stale_after_s.is_some();
        let mut idle = cdm_zenoh::IdleBackoff::for_team(realtime);
        loop {
            if interrupted.load(Ordering::Relaxed) {
                return Err(format!(
                    "interrupted by {}",
                    cdm_process::signals::received()
                ));
            }
            let mut busy = false;
            while let Some(f) = self.chan.try_recv::<Down>().map_err(link_error)? {
                self.last_heard = Instant::now();
                busy = true;
                match &f {
                    Down::Kill(id) => cdm_team::loss::kill_and_reap(children, *id),
                    Down::Clock(c) => self
                        .repairs
                        .on_clock(&ClockMsg::from(*c), relays)
                        .map_err(|e| e.to_string())?,
                    _ => {}
                }
                if let Some(reason) = down(f, ports, relays)? {
                    return Ok(reason);
                }
            }
            busy |= self.up(ports)?;
            self.repairs.hand_over_ready(relays);
            let linked = self.repairs.connected(ports);
            if !linked.is_empty() {
                self.send(&Up::Linked(linked))?;
            }
            if last_child_check.elapsed() > Duration::from_millis(100) {
                last_child_check = Instant::now();
                self.report_exits(ports, children)?;
            }
            self.keep_alive()?;
            if let Some(sleep) = idle.after(busy) {
                self.chan.wait(sleep);
            }
        }
    }

    /// This host's members' states (and fault reports) up, in order; true when any.
    fn up(&mut self, ports: &mut OrchestratorPorts) -> Result<bool, String> {
        let mine = &self.j.mine;
        let mut batch: Vec<NetState> = vec![];
        ports
            .receive_states(|m| {
                if mine.contains(&m.id) {
                    batch.push(m.into());
                }
            })
            .map_err(|e| e.to_string())?;
        if batch.is_empty() {
            return Ok(false);
        }
        self.send(&Up::States(batch))?;
        Ok(true)
    }

    /// After the orchestrator's stop (the bridge published it here): the members' last states
    /// (real time: their final pacing reports) go up as they come, until every member exited
    /// or the graceful stop's 3 s passed; the orchestrator waits for them a bounded while.
    fn up_while_stopping(&mut self, ports: &mut OrchestratorPorts, children: &mut [Spawned]) {
        let until = Instant::now() + Duration::from_secs(3);
        loop {
            let _ = self.up(ports);
            let running = children
                .iter_mut()
                .any(|c| matches!(c.child.try_wait(), Ok(None)));
            if !running || Instant::now() >= until {
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
    ) -> Result<(), String> {
        for c in children.iter_mut() {
            if self.reported.contains(&c.id) {
                continue;
            }
            if let Ok(Some(status)) = c.child.try_wait() {
                self.up(ports)?;
                let how = cdm_team::team::describe_exit(status);
                self.reported.insert(c.id);
                self.send(&Up::Exited { id: c.id, how })?;
            }
        }
        Ok(())
    }
}

/// A failed receive, said from the daemon's side.
fn link_error(e: cdm_zenoh::NetError) -> String {
    match e {
        cdm_zenoh::NetError::PeerGone { .. } => {
            format!("the orchestrator is gone, {e}: killed or exited")
        }
        e => e.to_string(),
    }
}

/// One frame from the orchestrator: the clock to every member (a stop ends the bridge), or
/// other hosts' states re-published here for their readers.
fn down(
    f: Down,
    ports: &mut OrchestratorPorts,
    relays: &mut BTreeMap<u32, MemberPorts>,
) -> Result<Option<StopReason>, String> {
    match f {
        Down::Clock(c) => {
            let c = ClockMsg::from(c);
            ports.publish_clock(c).map_err(|e| e.to_string())?;
            if let ClockCommand::Stop(reason) = c.command() {
                return Ok(Some(reason));
            }
        }
        Down::States(states) => {
            let mut touched = vec![];
            for st in states {
                if let Some(relay) = relays.get_mut(&st.id) {
                    relay
                        .publish_quietly(st.into())
                        .map_err(|e| e.to_string())?;
                    touched.push(st.id);
                }
            }
            touched.dedup();
            for id in touched {
                if let Some(relay) = relays.get_mut(&id) {
                    relay.notify_readers().map_err(|e| e.to_string())?;
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
