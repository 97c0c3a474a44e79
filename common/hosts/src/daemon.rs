//! `orchestrator host --connect ENDPOINT`: one host's daemon. Joins the team whose orchestrator
//! listens there, spawns its share of the members on this host's shared memory, and bridges:
//! the clock and the other hosts' states its members read come down, every member's state goes
//! up (the orchestrator audits them all).

use std::collections::{BTreeMap, BTreeSet};
use std::os::unix::fs::DirBuilderExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use cdm_iox::{MemberPorts, OrchestratorPorts, TeamLayout, TeamName};
use cdm_runtime::messages::{StateMsg, StopReason};
use cdm_runtime::process_exit::ProcessExit;
use cdm_scenario::{Checks, Scenario};
use cdm_team::notices::NoticeSink;
use cdm_team::team::{first_exited, spawn_member, stop_team, Spawned};
use cdm_zenoh::{
    down_key, up_key, Assignment, Down, JoinReply, JoinRequest, Net, Up, PROTOCOL_VERSION,
};

use crate::daemon_core::{DaemonAction, DaemonCore, DaemonEvent};
use crate::daemon_repair::DaemonRepairs;
use crate::error::{DaemonError, DaemonStop};
use crate::host_link::{HostLink, ZenohLink};
use crate::idle::IdleBackoff;
use crate::notice::HostNotice;
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
}

/// A daemon that joined: its share of the team and its ports.
struct Joined {
    a: Assignment,
    team: TeamName,
    s: Scenario,
    mine: BTreeSet<u32>,
    link_timeout: Duration,
}

/// Runs the daemon to the end of the team, or to a lost link or a refusal ([`DaemonError`]);
/// says which members it runs to `notices`.
pub fn run(o: &DaemonOptions, notices: &dyn NoticeSink) -> Result<(), DaemonError> {
    let interrupted = cdm_process::signals::install();
    cdm_team::team::member_binaries_present()?;
    super::workdir::sweep_dead();
    let expected_hash = match &o.scenario {
        Some(p) => Some(
            Scenario::load(p, Checks::Member)
                .map_err(DaemonError::Scenario)?
                .content_hash(),
        ),
        None => None,
    };
    let (security, bound) = crate::security::daemon(&o.transport)?;
    let host = match (bound, o.host) {
        (Some(certified), Some(asked)) if asked != certified => {
            return Err(DaemonError::NotCertified { asked, certified })
        }
        (Some(k), _) => Some(k),
        (None, h) => h,
    };
    if let Some(w) = o.transport.warning(&o.connect) {
        tracing::warn!("{w}");
    }
    let net = Net::connect(&o.connect, &security).map_err(DaemonError::Connect)?;
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
            let at = o.connect.clone();
            return Err(DaemonError::Refused { at, why });
        }
        Err(e) => return Err(DaemonError::Join(e)),
    };
    let (j, chan) = joined(&net, a)?;
    if let Some(p) = j.a.realtime_priority {
        // `--rt-priority` of the team: this thread (the bridge loop) now, the members through
        // their flag. zenoh's threads started before the team's mode was known and keep theirs.
        cdm_process::sched::fifo(p).map_err(|source| DaemonError::Priority {
            team: j.team.to_string(),
            source,
        })?;
    }
    notices.notice(&HostNotice::DaemonJoined {
        team: j.team.to_string(),
        host: j.a.host,
        members: j.mine.iter().copied().collect(),
    });
    let dir = super::workdir::create(j.team.as_str())?;
    let result = fly(&j, chan, &dir, interrupted);
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Checks the assignment and opens the host's link.
fn joined(net: &Net, a: Assignment) -> Result<(Joined, OrchestratorLink), DaemonError> {
    let team = TeamName::new(&a.team)?;
    let s = Scenario::parse_json(
        &a.scenario_json,
        "the orchestrator's scenario",
        Checks::Member,
    )?;
    if s.content_hash() != a.scenario_hash {
        return Err(DaemonError::ScenarioHash {
            here: s.content_hash(),
            there: a.scenario_hash,
        });
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
        .map_err(DaemonError::Channel)?;
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
fn host_layout(j: &Joined) -> Result<(TeamLayout, BTreeMap<u32, Neighbours>), DaemonError> {
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
    let mut layout = TeamLayout::new(ids, ins, j.a.window)?.with_scenario_hash(j.a.scenario_hash);
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

/// Where this host's members write their recordings: a folder of the work directory, in real
/// time with recording on.
fn recording_dir(j: &Joined, dir: &Path) -> Option<PathBuf> {
    let records = j.a.record && j.a.realtime_stale_after_s.is_some();
    records.then(|| dir.join(cdm_recording::DIR))
}

/// The largest part of a recording in one frame.
const RECORDING_PART: usize = 256 * 1024;

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
    interrupted: &AtomicBool,
) -> Result<(), DaemonError> {
    let (layout, ghosts) = host_layout(j)?;
    let mut ports = OrchestratorPorts::create(&j.team, &layout).map_err(DaemonError::Services)?;
    let host_of: BTreeMap<u32, u32> = j.a.hosts_of.iter().copied().collect();
    let mut relays = BTreeMap::new();
    for (&g, nb) in &ghosts {
        let h = host_of.get(&g).copied().unwrap_or(0);
        let hash = j.a.scenario_hash;
        let relay = MemberPorts::open_relay(&j.team, h, g, hash, &nb.ins, &nb.outs)?;
        relays.insert(g, relay);
    }
    let children = spawn_members(j, dir, &mut ports)?;
    let now = Instant::now();
    let repairs = DaemonRepairs::new(
        j.team.clone(),
        host_of,
        j.mine.clone(),
        CrossRepairs::new(&j.s),
        now,
    );
    let mut host = Host {
        core: DaemonCore::new(j.mine.clone(), j.link_timeout, now),
        chan,
        ports,
        relays,
        children,
        repairs,
        interrupted,
        realtime: j.a.realtime_stale_after_s.is_some(),
        recording: recording_dir(j, dir),
    };
    let outcome = host.wait_ready().and_then(|()| host.bridge());
    host.land(&j.s, &outcome);
    let outcome = outcome.and_then(|reason| match reason {
        StopReason::Finished => Ok(()),
        r => Err(DaemonStop::TeamStopped(r)),
    });
    outcome.map_err(|why| DaemonError::Stopped {
        host: j.a.host,
        team: j.team.to_string(),
        why: Box::new(why),
    })
}

/// Writes the team's scenario where the members read it and spawns this host's members; on a
/// failure the ones started are stopped.
fn spawn_members(
    j: &Joined,
    dir: &Path,
    ports: &mut OrchestratorPorts,
) -> Result<Vec<Spawned>, DaemonError> {
    let file = dir.join("scenario.json");
    cdm_records::rundir::write_atomic(&file, j.a.scenario_json.as_bytes()).map_err(|source| {
        DaemonError::WriteScenario {
            file: file.clone(),
            source,
        }
    })?;
    let mut children = Vec::new();
    let mut flags = member_flags(&j.a);
    if let Some(at) = recording_dir(j, dir) {
        std::fs::DirBuilder::new()
            .mode(0o700)
            .create(&at)
            .map_err(|source| DaemonError::RecordingDir {
                dir: at.clone(),
                source,
            })?;
        flags.extend(["--record".into(), at.display().to_string()]);
    }
    for m in
        j.s.formation
            .members
            .iter()
            .filter(|m| j.mine.contains(&m.id))
    {
        match spawn_member(&file, &j.team, m.id, m.role, &flags) {
            Ok(child) => children.push(Spawned {
                id: m.id,
                child: child.into(),
            }),
            Err(source) => {
                stop_team(ports, &mut children, &j.s, StopReason::AgentFault);
                return Err(DaemonError::Spawn { id: m.id, source });
            }
        }
    }
    Ok(children)
}

/// The states published on this host's shared memory since the last call, in order.
fn drain(ports: &mut OrchestratorPorts) -> Vec<StateMsg> {
    let mut states = vec![];
    if let Err(e) = ports.receive_states(|m| states.push(m)) {
        tracing::warn!("{e}");
    }
    states
}

/// The daemon's loops: the state machine, and the link, ports, relays and member processes it
/// acts through. The only place that reads the clock: each turn hands the core its instant.
struct Host<'a, L = OrchestratorLink> {
    core: DaemonCore,
    chan: L,
    ports: OrchestratorPorts,
    relays: BTreeMap<u32, MemberPorts>,
    children: Vec<Spawned>,
    repairs: DaemonRepairs,
    interrupted: &'a AtomicBool,
    realtime: bool,
    /// Where this host's members record (real time with recording on).
    recording: Option<PathBuf>,
}

/// Interrupted by a signal: the daemon says which.
fn interrupted_by() -> DaemonStop {
    DaemonStop::Interrupted(cdm_process::signals::received())
}

impl<L: HostLink<In = Down, Out = Up>> Host<'_, L> {
    /// Waits (bounded) until every member of this host has opened its ports, then says so.
    fn wait_ready(&mut self) -> Result<(), DaemonStop> {
        loop {
            let now = Instant::now();
            let readiness = self.ports.readiness();
            if readiness.is_complete() {
                let mine = self.core.mine().iter().copied();
                let subscriptions = self.ports.subscriber_graph(mine).unwrap_or_default();
                self.apply(DaemonEvent::Ready(subscriptions), now)?;
                return Ok(());
            }
            if self.interrupted.load(Ordering::Relaxed) {
                return Err(interrupted_by());
            }
            if let Some((id, how)) = first_exited(&mut self.children) {
                self.apply(DaemonEvent::Exited { id, how }, now)?;
            }
            self.apply(DaemonEvent::Waiting(readiness.waiting_for()), now)?;
            while let Some(f) = self.chan.try_recv()? {
                self.apply(DaemonEvent::Frame(f), now)?;
            }
            self.apply(DaemonEvent::Deadlines, now)?;
            let _ = self.ports.wait(Duration::from_millis(20));
        }
    }

    /// Carries frames both ways until the orchestrator's stop (its reason) or a lost link.
    fn bridge(&mut self) -> Result<StopReason, DaemonStop> {
        let mut idle = IdleBackoff::for_team(self.realtime);
        loop {
            let now = Instant::now();
            if self.interrupted.load(Ordering::Relaxed) {
                return Err(interrupted_by());
            }
            let mut busy = false;
            self.apply(DaemonEvent::Woke, now)?;
            while let Some(f) = self.chan.try_recv()? {
                busy = true;
                if let Some(reason) = self.apply(DaemonEvent::Frame(f), now)? {
                    return Ok(reason);
                }
            }
            let states = drain(&mut self.ports);
            busy |= states.iter().any(|m| self.core.mine().contains(&m.id));
            self.apply(DaemonEvent::States(states), now)?;
            self.repairs.hand_over_ready(&mut self.relays, now);
            let linked = self.repairs.connected(&self.ports, now);
            self.apply(DaemonEvent::Linked(linked), now)?;
            self.apply(DaemonEvent::Deadlines, now)?;
            if let Some(sleep) = idle.after(busy) {
                self.chan.wait(sleep);
            }
        }
    }

    /// After the orchestrator's stop (the bridge published it here): the members' last states
    /// (real time: their final pacing reports) go up as they come, until every member exited
    /// or the core's wait is over; the orchestrator waits for them a bounded while.
    fn up_while_stopping(&mut self) {
        loop {
            let now = Instant::now();
            let states = drain(&mut self.ports);
            let _ = self.apply(DaemonEvent::States(states), now);
            let running = self
                .children
                .iter_mut()
                .any(|c| matches!(c.child.try_wait(), Ok(None)));
            if !running || matches!(self.apply(DaemonEvent::Woke, now), Ok(Some(_)) | Err(_)) {
                return;
            }
            let _ = self.ports.wait(Duration::from_millis(5));
        }
    }

    /// After the bridging: the members' last states go up while they stop (a flight that ended
    /// on the orchestrator's stop), the members are stopped, the daemon says it leaves, and the
    /// host's services go.
    fn land(mut self, s: &Scenario, outcome: &Result<StopReason, DaemonStop>) {
        let reason = match outcome {
            Ok(r) => *r,
            Err(_) => StopReason::AgentSilent,
        };
        if outcome.is_ok() {
            self.up_while_stopping();
        }
        stop_team(&mut self.ports, &mut self.children, s, reason);
        if outcome.is_ok() {
            // What the members published as they stopped (real time: their pacing reports).
            let now = Instant::now();
            let states = drain(&mut self.ports);
            let _ = self.apply(DaemonEvent::States(states), now);
            self.send_recordings(now);
            let _ = self.apply(DaemonEvent::MembersStopped, now);
        }
        drop(self.relays);
        if let Err(e) = self.ports.shutdown() {
            tracing::warn!("{e}");
        }
    }

    /// Hands `event` to the core and carries out its actions, in order; the stop's reason when
    /// the orchestrator stopped the team (or, stopping, when the wait is over).
    fn apply(
        &mut self,
        event: DaemonEvent,
        now: Instant,
    ) -> Result<Option<StopReason>, DaemonStop> {
        let mut stop = None;
        for action in self.core.handle(event, now)? {
            match action {
                DaemonAction::Send(frame) => self.chan.send(&frame)?,
                DaemonAction::Kill(id) => cdm_team::loss::kill_and_reap(&mut self.children, id),
                DaemonAction::Clock(c) => {
                    // A new loss: the relays wake their new readers before the members hear it.
                    self.repairs.on_clock(&c, &mut self.relays, now)?;
                    self.ports.publish_clock(c)?;
                }
                DaemonAction::Relay(states) => relay(&mut self.relays, states)?,
                DaemonAction::CheckExits => self.report_exits(now)?,
                DaemonAction::Finish(reason) => stop = Some(reason),
                DaemonAction::Done => stop = Some(StopReason::Finished),
            }
        }
        Ok(stop)
    }

    /// The members' recordings, complete now that they stopped, go up in bounded parts (a
    /// member that never started one has none to send).
    fn send_recordings(&mut self, now: Instant) {
        let Some(dir) = self.recording.clone() else {
            return;
        };
        let ids: Vec<u32> = self.children.iter().map(|c| c.id).collect();
        for id in ids {
            let Ok(bytes) = std::fs::read(dir.join(cdm_recording::file_name(id))) else {
                continue;
            };
            for (k, part) in bytes.chunks(RECORDING_PART).enumerate() {
                let (offset, bytes) = ((k * RECORDING_PART) as u64, part.to_vec());
                if self
                    .apply(DaemonEvent::Recording { id, offset, bytes }, now)
                    .is_err()
                {
                    return;
                }
            }
        }
    }

    /// Members that exited: each one's last states first, then the exit.
    fn report_exits(&mut self, now: Instant) -> Result<(), DaemonStop> {
        for k in 0..self.children.len() {
            let c = &mut self.children[k];
            if self.core.reported(c.id) {
                continue;
            }
            if let Ok(Some(status)) = c.child.try_wait() {
                let (id, how) = (c.id, ProcessExit::of(status));
                let states = drain(&mut self.ports);
                self.apply(DaemonEvent::States(states), now)?;
                self.apply(DaemonEvent::Exited { id, how }, now)?;
            }
        }
        Ok(())
    }
}

/// Other hosts' states re-published here for their readers, in order; each relay wakes its
/// readers once.
fn relay(relays: &mut BTreeMap<u32, MemberPorts>, states: Vec<StateMsg>) -> Result<(), DaemonStop> {
    let mut touched = vec![];
    for st in states {
        if let Some(relay) = relays.get_mut(&st.id) {
            relay.publish_quietly(st)?;
            touched.push(st.id);
        }
    }
    touched.dedup();
    for id in touched {
        if let Some(relay) = relays.get_mut(&id) {
            relay.notify_readers()?;
        }
    }
    Ok(())
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
            record: false,
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
