//! The orchestrator's bridge as a state machine over two seams: each joined daemon's link
//! ([`HostLink`]: zenoh, or a fake one in the unit tests) and the relays that stand in for its
//! members on this host's shared memory ([`Relay`]). It admits daemons, carries the clock and
//! the crossing states to them and their members' states here, keeps each link's deadlines, and
//! notes for the launch what it learns ([`Note`]); the team core's kills come in. No clock is
//! read here: every turn is handed the loop's instant (`bridge.rs` is the loop).

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use cdm_iox::{MemberPorts, TeamName};
use cdm_runtime::messages::{AgentStatus, ClockMsg, FaultCode, StateMsg};
use cdm_runtime::process_exit::ProcessExit;
use cdm_scenario::Scenario;
use cdm_zenoh::{Assignment, Down, JoinRequest, Up};
use serde::Serialize;

use crate::error::{LinkLost, Refusal};
use crate::handover::{self, warn_hand_over, PendingHandOver, HAND_OVER_WAIT};
use crate::host_link::{HostLink, ZenohLink, HEARTBEAT};
use crate::links::{LostHost, Note};
use crate::placed::placed;
use crate::regions::Regions;
use crate::relay::Relay;
use crate::repairs::CrossRepairs;
use crate::{HostOptions, TeamFlight};

mod forward;
mod join;

/// How long the bridge waits, after the team's stop, for every daemon to stop its members.
const STOP_DEADLINE: Duration = Duration::from_secs(8);

/// What the bridge needs of the team, owned.
pub(crate) struct Ctx {
    team: TeamName,
    hash: u64,
    pub(crate) flight: TeamFlight,
    scenario_json: String,
    regions: Regions,
    ins: BTreeMap<u32, Vec<u32>>,
    outs: BTreeMap<u32, Vec<u32>>,
    link_timeout: Duration,
    /// No loss yet: each host's link follows the repairs from here.
    repairs: CrossRepairs,
    /// Mutual TLS: every daemon must ask as the host its certificate names.
    pub(crate) tls: bool,
}

impl Ctx {
    pub(crate) fn new(
        s: &Scenario,
        team: &TeamName,
        regions: &Regions,
        h: &HostOptions,
        flight: TeamFlight,
    ) -> Self {
        let mut ins = BTreeMap::new();
        let mut outs: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
        for p in &placed(s) {
            ins.insert(p.id, p.in_neighbors.clone());
            for &j in &p.in_neighbors {
                outs.entry(j).or_default().push(p.id);
            }
        }
        Ctx {
            team: team.clone(),
            hash: s.content_hash(),
            flight,
            scenario_json: s.to_json(),
            regions: regions.clone(),
            ins,
            outs,
            link_timeout: h.link_timeout,
            repairs: CrossRepairs::new(s),
            tls: matches!(h.transport, crate::Transport::Tls(_)),
        }
    }
}

/// One host as `hosts.json` records it.
#[derive(Debug, Clone, Serialize)]
pub struct HostReport {
    pub host: u32,
    /// The daemon (host name and pid), empty when none joined.
    pub daemon: String,
    pub agents: Vec<u32>,
    /// Readers (node names) of each of its members' states, as the daemon's host saw them.
    pub subscriptions: BTreeMap<u32, Vec<String>>,
    pub bytes_sent: u64,
    pub bytes_received: u64,
    /// `stopped`, `lost: ...`, or `never joined`.
    pub outcome: String,
}

/// Where one daemon's link is.
#[derive(Debug)]
enum Phase {
    Joined,
    Ready,
    Lost(LinkLost),
    Stopped,
}

/// The link to one daemon: its frames up, the orchestrator's down.
type DaemonLink = ZenohLink<Up, Down>;

/// One joined daemon, over link `L` (zenoh; a fake one in the unit tests), standing in for its
/// members through relays `R` (iceoryx2 ports; fakes in the unit tests).
struct Remote<L = DaemonLink, R = MemberPorts> {
    host: u32,
    who: String,
    members: Vec<u32>,
    chan: L,
    phase: Phase,
    relays: BTreeMap<u32, R>,
    /// For each source read on that host, the one relay that forwards it (several may read it).
    forwarder: BTreeMap<u32, u32>,
    last_tick: BTreeMap<u32, u64>,
    last_heard: Instant,
    last_sent: Instant,
    stop_sent: bool,
    subscriptions: BTreeMap<u32, Vec<String>>,
    /// The repairs as the clock messages sent to this host announced them.
    repairs: CrossRepairs,
    /// The loss and command notices of the last clock message sent.
    last_notice: forward::SentNotices,
    /// Members this bridge asked the daemon to kill (their exit is expected).
    killed: BTreeSet<u32>,
    /// Relays still to hand their history over (`handover.rs`).
    handing: Option<PendingHandOver>,
    /// What the launch is to learn, oldest first.
    notes: Vec<Note>,
    /// Parts of its members' recordings received and not yet written, in order.
    recordings: Vec<RecordingChunk>,
    /// Each member's recording: the bytes received so far (the next part's offset).
    recorded: BTreeMap<u32, u64>,
    /// Fault reports to publish on its members' behalf once the launch learnt the notes.
    faults: Vec<StateMsg>,
}

/// Part of another host's member's recording, for the run directory's copy of its file.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RecordingChunk {
    pub id: u32,
    pub offset: u64,
    pub bytes: Vec<u8>,
}

/// The bridge: every joined daemon, the team core's kills not yet sent, the stop's start.
pub(crate) struct BridgeCore<L = DaemonLink, R = MemberPorts> {
    ctx: Ctx,
    remotes: BTreeMap<u32, Remote<L, R>>,
    /// Kills of remote members whose daemon is not ready yet.
    kills: Vec<u32>,
    stopping_since: Option<Instant>,
}

impl<L: HostLink<In = Up, Out = Down>, R: Relay> BridgeCore<L, R> {
    pub(crate) fn new(ctx: Ctx) -> Self {
        BridgeCore {
            ctx,
            remotes: BTreeMap::new(),
            kills: Vec::new(),
            stopping_since: None,
        }
    }

    pub(crate) fn team(&self) -> &TeamName {
        &self.ctx.team
    }

    /// The host a join request asking on the key of host `slot` may take, or why not.
    pub(crate) fn which_host(&self, slot: Option<u32>, q: &JoinRequest) -> Result<u32, Refusal> {
        join::bound(&self.ctx, slot, q.host)?;
        join::which_host(&self.ctx, &self.remotes, q)
    }

    /// Host `host`'s share of the team, as its daemon needs it.
    pub(crate) fn assignment(&self, host: u32) -> Assignment {
        join::assignment(&self.ctx, host)
    }

    /// The daemon `who` joined as host `host` at `now`, over `chan`; its members.
    pub(crate) fn joined(&mut self, host: u32, who: String, chan: L, now: Instant) -> Vec<u32> {
        let mut r = Remote::joined(&self.ctx, host, who, chan, now);
        heard(&mut r);
        let members = r.members.clone();
        self.remotes.insert(host, r);
        members
    }

    /// One turn at `now`, with the team core's kills since the last one: every daemon's frames
    /// in, the clock and the crossing states out, heartbeats and deadlines. True when anything
    /// moved.
    pub(crate) fn turn(&mut self, kills: Vec<u32>, now: Instant) -> bool {
        self.kills.extend(kills);
        let mut busy = false;
        for r in self.remotes.values_mut() {
            busy |= pump(r, &self.ctx, &mut self.kills, now);
        }
        busy
    }

    /// The team stopped: a daemon that never received the stop gets one. True once every
    /// daemon stopped or was lost, or the stop deadline passed.
    pub(crate) fn stopping(&mut self, now: Instant) -> bool {
        let since = *self.stopping_since.get_or_insert(now);
        for r in self.remotes.values_mut() {
            stop_fallback(r, &self.ctx);
        }
        let done = self
            .remotes
            .values()
            .all(|r| matches!(r.phase, Phase::Lost(_) | Phase::Stopped));
        done || now.saturating_duration_since(since) > STOP_DEADLINE
    }

    /// Ends a turn: what the launch is to learn since the last one goes to `launch`, in order,
    /// and only then the fault reports go out on the remote members' behalf, so a host's loss is
    /// known before the team core sees its members' reports.
    pub(crate) fn settle(&mut self, launch: impl FnOnce(Vec<Note>)) {
        let notes: Vec<Note> = self
            .remotes
            .values_mut()
            .flat_map(|r| std::mem::take(&mut r.notes))
            .collect();
        if !notes.is_empty() {
            launch(notes);
        }
        for r in self.remotes.values_mut() {
            for msg in std::mem::take(&mut r.faults) {
                let Some(relay) = r.relays.get_mut(&msg.id) else {
                    continue;
                };
                if let Err(e) = relay.publish(msg) {
                    let id = msg.id;
                    tracing::warn!(id, error = %e, "cannot report a remote agent's fault");
                }
            }
        }
    }

    /// The parts of the other hosts' recordings received since the last call, in order.
    pub(crate) fn take_recordings(&mut self) -> Vec<RecordingChunk> {
        (self.remotes.values_mut())
            .flat_map(|r| std::mem::take(&mut r.recordings))
            .collect()
    }

    /// Sleeps until a frame comes from the first daemon or `timeout` passes; false when no
    /// daemon joined (nothing to wait on).
    pub(crate) fn wait(&mut self, timeout: Duration) -> bool {
        match self.remotes.values_mut().next() {
            Some(r) => {
                r.chan.wait(timeout);
                true
            }
            None => false,
        }
    }

    /// Every host's record for `hosts.json`.
    pub(crate) fn report(self) -> Vec<HostReport> {
        report(&self.ctx, self.remotes)
    }
}

impl<L, R> Remote<L, R> {
    /// A daemon that joined as host `host` at `now`, over `chan`.
    fn joined(ctx: &Ctx, host: u32, who: String, chan: L, now: Instant) -> Self {
        Remote {
            host,
            who,
            members: ctx.regions.members(host),
            chan,
            phase: Phase::Joined,
            relays: BTreeMap::new(),
            forwarder: BTreeMap::new(),
            last_tick: BTreeMap::new(),
            last_heard: now,
            last_sent: now,
            stop_sent: false,
            subscriptions: BTreeMap::new(),
            repairs: ctx.repairs.clone(),
            last_notice: forward::SentNotices::default(),
            killed: BTreeSet::new(),
            handing: None,
            notes: Vec::new(),
            recordings: Vec::new(),
            recorded: BTreeMap::new(),
            faults: Vec::new(),
        }
    }
}

/// One round for one daemon at `now`: its frames in, the clock and the crossing states out,
/// the heartbeat, the silence deadline. True when anything moved.
fn pump<L: HostLink<In = Up, Out = Down>, R: Relay>(
    r: &mut Remote<L, R>,
    ctx: &Ctx,
    kills: &mut Vec<u32>,
    now: Instant,
) -> bool {
    if matches!(r.phase, Phase::Lost(_)) && ctx.flight.repair {
        forward::follow_repairs(r, ctx, now);
        return false;
    }
    if matches!(r.phase, Phase::Lost(_) | Phase::Stopped) {
        return false;
    }
    let mut busy = false;
    loop {
        let frame = match r.chan.try_recv() {
            Ok(Some(f)) => f,
            Ok(None) => break,
            Err(e) => {
                lose(r, ctx, e.into());
                return true;
            }
        };
        busy = true;
        r.last_heard = now;
        if let Err(why) = on_frame(r, ctx, frame) {
            lose(r, ctx, why);
            return true;
        }
    }
    // The states just published may complete a relay's history for a pending hand-over.
    let wait = HAND_OVER_WAIT;
    handover::poll(&mut r.handing, &mut r.relays, wait, now, warn_hand_over);
    if busy {
        heard(r);
    }
    if matches!(r.phase, Phase::Ready) {
        send_kills(r, kills, now);
        match forward::forward(r, ctx, now) {
            Ok(sent) => busy |= sent,
            Err(why) => {
                lose(r, ctx, why);
                return true;
            }
        }
    }
    if now.saturating_duration_since(r.last_sent) >= HEARTBEAT {
        let _ = r.chan.send(&Down::Heartbeat);
        r.last_sent = now;
    }
    // Once the stop went, the daemon may stop its members quietly for a while (a bounded
    // wait); the bridge's own stop deadline bounds it, and a killed daemon is still seen.
    if !r.stop_sent && now.saturating_duration_since(r.last_heard) > ctx.link_timeout {
        let why = LinkLost::Silent {
            host: r.host,
            who: r.who.clone(),
            after: ctx.link_timeout,
        };
        lose(r, ctx, why);
        busy = true;
    }
    busy
}

/// Notes for the launch that host `r` was just heard.
fn heard<L, R>(r: &mut Remote<L, R>) {
    let (host, who, at) = (r.host, r.who.clone(), r.last_heard);
    r.notes.push(Note::Heard { host, who, at });
}

/// One frame from a daemon.
fn on_frame<L, R: Relay>(r: &mut Remote<L, R>, ctx: &Ctx, frame: Up) -> Result<(), LinkLost> {
    match frame {
        Up::Ready { subscriptions } => {
            r.subscriptions = subscriptions;
            open_relays(r, ctx)?;
            r.phase = Phase::Ready;
        }
        Up::States(states) => {
            let mut touched = vec![];
            for st in states {
                let Some(relay) = r.relays.get_mut(&st.id) else {
                    continue;
                };
                relay.publish_quietly(st)?;
                r.last_tick.insert(st.id, st.tick);
                touched.push(st.id);
            }
            touched.dedup();
            for id in touched {
                if let Some(relay) = r.relays.get_mut(&id) {
                    relay.notify_readers()?;
                }
            }
        }
        Up::Exited { id, how } => {
            if r.killed.contains(&id) {
                return Ok(());
            }
            let how = ProcessExit::from(how);
            tracing::warn!(host = r.host, id, "agent {id} on host {} {how}", r.host);
            if ctx.flight.repair {
                // Lost and repaired around, as a member of this host that exits.
                r.notes.push(Note::Exited(id, how));
            } else {
                report_fault(r, ctx, id, FaultCode::RemoteExited);
            }
        }
        Up::Linked(pairs) => r.notes.push(Note::Linked(pairs)),
        Up::Heartbeat => {}
        Up::Stopped => {
            r.phase = Phase::Stopped;
            r.notes.push(Note::Stopped(r.host));
        }
        Up::Recording { id, offset, bytes } => on_recording(r, ctx, id, offset, bytes),
    }
    Ok(())
}

/// A part of member `id`'s recording: kept for the run directory when the team records, the
/// member is this host's and the part continues what came before (a part out of order would
/// leave a hole in the file; it and the member's later parts are dropped, and the replay then
/// finds that recording cut short).
fn on_recording<L, R>(r: &mut Remote<L, R>, ctx: &Ctx, id: u32, offset: u64, bytes: Vec<u8>) {
    let next = r.recorded.get(&id).copied().unwrap_or(0);
    if ctx.flight.recording.is_none() || !r.members.contains(&id) || offset != next {
        tracing::warn!(
            host = r.host,
            id,
            offset,
            expected = next,
            "dropped a part of agent {id}'s recording from host {} that does not belong",
            r.host
        );
        r.recorded.insert(id, u64::MAX);
        return;
    }
    r.recorded.insert(id, next + bytes.len() as u64);
    r.recordings.push(RecordingChunk { id, offset, bytes });
}

/// The relay ports of a ready host's members: each reads (and forwards) its in-neighbours on
/// other hosts and wakes its out-neighbours on other hosts.
fn open_relays<L, R: Relay>(r: &mut Remote<L, R>, ctx: &Ctx) -> Result<(), LinkLost> {
    let elsewhere = |ids: Option<&Vec<u32>>| -> Vec<u32> {
        let ids = ids.map_or(&[][..], Vec::as_slice);
        ids.iter()
            .copied()
            .filter(|&j| ctx.regions.host_of(j) != r.host)
            .collect()
    };
    for &g in &r.members {
        let ins = elsewhere(ctx.ins.get(&g));
        let outs = elsewhere(ctx.outs.get(&g));
        for &j in &ins {
            r.forwarder.entry(j).or_insert(g);
        }
        let ports = R::open(&ctx.team, r.host, g, ctx.hash, &ins, &outs).map_err(|source| {
            LinkLost::Relay {
                host: r.host,
                id: g,
                source,
            }
        })?;
        r.relays.insert(g, ports);
    }
    Ok(())
}

/// The team core's kills of this host's members, sent to its daemon.
fn send_kills<L: HostLink<In = Up, Out = Down>, R: Relay>(
    r: &mut Remote<L, R>,
    kills: &mut Vec<u32>,
    now: Instant,
) {
    let (ids, rest): (Vec<u32>, Vec<u32>) = kills.drain(..).partition(|id| r.members.contains(id));
    *kills = rest;
    for id in ids {
        r.killed.insert(id);
        if let Err(e) = r.chan.send(&Down::Kill(id)) {
            tracing::warn!(host = r.host, id, "cannot send a kill: {e}");
        }
        r.last_sent = now;
    }
}

/// A fault report for `id`, to publish through its relay once the launch has this turn's notes
/// ([`BridgeCore::settle`]): the orchestrator stops the team with it as it does for a member's
/// own report (telemetry keeps every complete tick), and says it in the terms of hosts.
fn report_fault<L, R>(r: &mut Remote<L, R>, ctx: &Ctx, id: u32, code: FaultCode) {
    let tick = r.last_tick.get(&id).copied().unwrap_or(0);
    let msg = StateMsg::ok(tick, ctx.hash, id, [0.0; 12])
        .with_status(AgentStatus::Fault { code, peer: None });
    r.faults.push(msg);
}

/// The link to a daemon is gone (the daemon itself, when its session closed: its members with
/// it): every member of that host is reported lost.
fn lose<L, R: Relay>(r: &mut Remote<L, R>, ctx: &Ctx, why: LinkLost) {
    tracing::error!(host = r.host, "host {} lost: {why}", r.host);
    let host = LostHost {
        who: r.who.clone(),
        members: r.members.clone(),
        why: why.to_string(),
    };
    // Lockstep `--on-loss repair`: each member still flying is lost as if SIGKILLed on one host
    // (the team core repairs, or stops naming the losses); otherwise the team stops `host-lost`.
    let repaired = why.daemon_gone() && ctx.flight.repair;
    let alive: Vec<u32> = r
        .members
        .iter()
        .copied()
        .filter(|id| !r.killed.contains(id))
        .collect();
    if repaired {
        let how = ProcessExit::WithHost {
            host: r.host,
            who: r.who.clone(),
            why: why.to_string(),
        };
        let exits = alive.iter().map(|&id| Note::Exited(id, how.clone()));
        r.notes.extend(exits);
    }
    let lost = host;
    r.notes.push(Note::Lost { host: r.host, lost });
    if !repaired {
        for id in alive {
            report_fault(r, ctx, id, FaultCode::HostLost);
        }
    }
    r.phase = Phase::Lost(why);
}

/// At the end, a daemon that never received the stop (the team failed before its first grant)
/// gets one.
fn stop_fallback<L: HostLink<In = Up, Out = Down>, R: Relay>(r: &mut Remote<L, R>, ctx: &Ctx) {
    if r.stop_sent || matches!(r.phase, Phase::Lost(_) | Phase::Stopped) {
        return;
    }
    let reason = cdm_runtime::messages::StopReason::AgentFault;
    let stop = ClockMsg::stop(0, ctx.hash, reason);
    let _ = r.chan.send(&Down::Clock(stop));
    r.stop_sent = true;
}

/// Every host's record for `hosts.json`.
fn report<L: HostLink, R>(ctx: &Ctx, mut remotes: BTreeMap<u32, Remote<L, R>>) -> Vec<HostReport> {
    (1..ctx.regions.hosts())
        .map(|host| match remotes.remove(&host) {
            Some(r) => {
                let (bytes_sent, bytes_received) = r.chan.bytes();
                HostReport {
                    host,
                    daemon: r.who,
                    agents: r.members,
                    subscriptions: r.subscriptions,
                    bytes_sent,
                    bytes_received,
                    outcome: match r.phase {
                        Phase::Lost(why) => format!("lost: {why}"),
                        Phase::Stopped => "stopped".into(),
                        _ => "did not stop in time".into(),
                    },
                }
            }
            None => HostReport {
                host,
                daemon: String::new(),
                agents: ctx.regions.members(host),
                subscriptions: BTreeMap::new(),
                bytes_sent: 0,
                bytes_received: 0,
                outcome: "never joined".into(),
            },
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::host_link::{FakeLink, LinkError};
    use crate::links::Links;
    use crate::relay::FakeRelay;
    use cdm_runtime::messages::StopReason;
    use cdm_zenoh::{NetExit, PROTOCOL_VERSION};

    type Fake = FakeLink<Up, Down>;
    type Core = BridgeCore<Fake, FakeRelay>;

    /// paper40 over two hosts, flown by the test's clock from `t0`.
    fn ctx(repair: bool) -> Ctx {
        let s = Scenario::builtin("paper40").unwrap();
        let regions = Regions::split(&placed(&s), 2);
        let flight = TeamFlight {
            window: 16,
            realtime_stale_after: None,
            realtime_priority: None,
            repair,
            recording: None,
        };
        let team = TeamName::new("unit").unwrap();
        Ctx::new(&s, &team, &regions, &HostOptions::default(), flight)
    }

    /// A bridge whose host 1 joined at `t0`.
    fn core(repair: bool, t0: Instant) -> Core {
        let mut c = Core::new(ctx(repair));
        let members = c.joined(1, "b (pid 7)".into(), Fake::default(), t0);
        assert_eq!(members, c.ctx.regions.members(1));
        c
    }

    /// Host 1's daemon, as the bridge sees it.
    fn host1(c: &mut Core) -> &mut Remote<Fake, FakeRelay> {
        c.remotes.get_mut(&1).unwrap()
    }

    /// What the launch knows once the bridge's notes so far are applied (the turn settled).
    fn links(c: &mut Core) -> Links {
        let mut l = Links::default();
        c.settle(|notes| notes.into_iter().for_each(|n| l.note(n)));
        l
    }

    /// Host 1's daemon says its members are up at `t`.
    fn ready(c: &mut Core, t: Instant) {
        let subscriptions = BTreeMap::new();
        host1(c)
            .chan
            .incoming
            .push_back(Ok(Up::Ready { subscriptions }));
        assert!(c.turn(vec![], t));
        assert!(matches!(host1(c).phase, Phase::Ready));
    }

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    #[test]
    fn recordings_are_kept_in_order_for_the_hosts_members_only() {
        let t0 = Instant::now();
        let mut c = core(false, t0);
        c.ctx.flight.recording = Some("unused".into());
        let mine = c.ctx.regions.members(1)[0];
        let theirs = c.ctx.regions.members(0)[0];
        let part = |id, offset, n| Up::Recording {
            id,
            offset,
            bytes: vec![7; n],
        };
        let frames = [
            part(mine, 0, 3),
            part(mine, 3, 2),
            part(theirs, 0, 4), // another host's member: not this daemon's to send
            part(mine, 9, 1),   // a gap: this and what follows are dropped
            part(mine, 5, 1),
        ];
        host1(&mut c)
            .chan
            .incoming
            .extend(frames.into_iter().map(Ok));
        c.turn(vec![], t0 + ms(1));
        let kept: Vec<(u32, u64, usize)> = (c.take_recordings().into_iter())
            .map(|p| (p.id, p.offset, p.bytes.len()))
            .collect();
        assert_eq!(kept, [(mine, 0, 3), (mine, 3, 2)]);
        assert!(
            c.take_recordings().is_empty(),
            "each part is handed over once"
        );

        let mut c = core(false, t0);
        host1(&mut c).chan.incoming.push_back(Ok(part(mine, 0, 3)));
        c.turn(vec![], t0 + ms(1));
        assert!(
            c.take_recordings().is_empty(),
            "a team that does not record keeps nothing"
        );
    }

    fn state(id: u32, tick: u64) -> StateMsg {
        StateMsg::ok(tick, 1, id, [0.0; 12])
    }

    #[test]
    fn a_quiet_link_gets_heartbeats_and_a_silent_one_is_lost() {
        let t0 = Instant::now();
        let mut c = core(false, t0);
        assert!(!c.turn(vec![], t0 + ms(199)));
        assert!(
            host1(&mut c).chan.sent.is_empty(),
            "no heartbeat before {HEARTBEAT:?}"
        );
        c.turn(vec![], t0 + ms(200));
        assert_eq!(host1(&mut c).chan.sent, [Down::Heartbeat]);
        host1(&mut c).chan.incoming.push_back(Ok(Up::Heartbeat));
        assert!(c.turn(vec![], t0 + ms(1000)), "a frame moved");
        let heard = links(&mut c).heard[&1].clone();
        assert_eq!(heard, ("b (pid 7)".to_owned(), t0 + ms(1000)));
        c.turn(vec![], t0 + ms(4000));
        assert!(
            matches!(host1(&mut c).phase, Phase::Joined),
            "3 s of quiet is the limit, not over it"
        );
        assert!(c.turn(vec![], t0 + ms(4001)));
        assert!(matches!(
            host1(&mut c).phase,
            Phase::Lost(LinkLost::Silent { host: 1, .. })
        ));
        let links = links(&mut c);
        let why = &links.lost[&1].why;
        assert_eq!(
            why,
            "nothing heard from host 1 (b (pid 7)) for 3.0 s: network partition or daemon gone"
        );
        assert_eq!(links.lost[&1].members, c.ctx.regions.members(1));
        assert!(links.exited.is_empty(), "a partition is not an exit");
    }

    #[test]
    fn a_closed_session_under_repair_is_every_member_of_the_host_exiting() {
        let t0 = Instant::now();
        let mut c = core(true, t0);
        let gone = LinkError::PeerGone("its zenoh session closed".into());
        host1(&mut c).chan.incoming.push_back(Err(gone));
        assert!(c.turn(vec![], t0 + ms(50)));
        assert!(matches!(
            host1(&mut c).phase,
            Phase::Lost(LinkLost::DaemonGone(_))
        ));
        let links = links(&mut c);
        let members = c.ctx.regions.members(1);
        let exited: Vec<u32> = links.exited.iter().map(|(id, _)| *id).collect();
        assert_eq!(exited, members);
        assert_eq!(
            links.exited[0].1.to_string(),
            "was killed with host 1 (b (pid 7)): the daemon is gone, its zenoh session closed: \
             killed or exited"
        );
        assert!(
            !c.turn(vec![], t0 + ms(9000)),
            "a lost host only follows repairs"
        );
    }

    #[test]
    fn a_bad_frame_loses_the_host_and_its_members_report_the_loss() {
        let t0 = Instant::now();
        let mut c = core(false, t0);
        ready(&mut c, t0);
        let bad = LinkError::Protocol("frame on cdm/unit/host/1/up: truncated".into());
        host1(&mut c).chan.incoming.push_back(Err(bad));
        c.turn(vec![], t0 + ms(10));
        assert!(matches!(
            host1(&mut c).phase,
            Phase::Lost(LinkLost::Protocol(_))
        ));
        let members = c.ctx.regions.members(1);
        let first = &host1(&mut c).relays[&members[0]];
        assert!(
            first.published.is_empty(),
            "the launch learns the loss first"
        );
        let why = links(&mut c).lost[&1].why.clone();
        assert!(
            why.starts_with("the daemon sent a frame that does not decode"),
            "{why}"
        );
        for id in &members {
            let relay = &host1(&mut c).relays[id];
            let [report] = relay.published[..] else {
                panic!("agent {id}: {:?}", relay.published)
            };
            let lost = AgentStatus::Fault {
                code: FaultCode::HostLost,
                peer: None,
            };
            assert_eq!((report.id, report.status()), (*id, lost));
        }
    }

    #[test]
    fn a_ready_daemon_gets_relays_and_its_members_states_reach_them_in_order() {
        let t0 = Instant::now();
        let mut c = core(false, t0);
        ready(&mut c, t0);
        let members = c.ctx.regions.members(1);
        let r = host1(&mut c);
        assert_eq!(r.relays.keys().copied().collect::<Vec<_>>(), members);
        let elsewhere = |ids: &[u32]| ids.iter().all(|j| !members.contains(j));
        assert!(r
            .relays
            .values()
            .all(|p| elsewhere(&p.ins) && elsewhere(&p.outs)));
        assert!(
            r.relays.values().any(|p| !p.ins.is_empty()),
            "edges cross hosts"
        );
        let (a, b) = (members[0], members[1]);
        let states = vec![state(a, 5), state(a, 6), state(b, 5), state(999, 6)];
        r.chan.incoming.push_back(Ok(Up::States(states)));
        assert!(c.turn(vec![], t0 + ms(20)));
        let r = host1(&mut c);
        assert_eq!(r.relays[&a].published, [state(a, 5), state(a, 6)]);
        assert_eq!(r.relays[&b].published, [state(b, 5)]);
        assert_eq!((r.relays[&a].woken, r.relays[&b].woken), (1, 1));
        assert_eq!(r.last_tick[&a], 6);
    }

    #[test]
    fn the_crossing_states_go_down_before_the_clock_that_lets_members_use_them() {
        let t0 = Instant::now();
        let mut c = core(false, t0);
        ready(&mut c, t0);
        let r = host1(&mut c);
        let (&source, &reader) = r.forwarder.iter().next().unwrap();
        let first = *r.relays.keys().next().unwrap();
        let (grant, stop) = (
            ClockMsg::run(4, 1),
            ClockMsg::stop(4, 1, StopReason::Finished),
        );
        r.relays
            .get_mut(&first)
            .unwrap()
            .clock
            .extend([grant, stop]);
        r.relays
            .get_mut(&reader)
            .unwrap()
            .neighbors
            .push_back(state(source, 4));
        for (_, relay) in r.relays.iter_mut().filter(|(&g, _)| g != reader) {
            // Another reader of the same source: forwarded once, by its forwarder only.
            if relay.ins.contains(&source) {
                relay.neighbors.push_back(state(source, 4));
            }
        }
        r.chan.sent.clear();
        assert!(c.turn(vec![], t0 + ms(30)));
        let r = host1(&mut c);
        assert_eq!(
            r.chan.sent,
            [Down::States(vec![state(source, 4)]), Down::Clock(stop)],
            "of clock messages with the same loss notice only the newest goes"
        );
        assert!(r.stop_sent, "the daemon was told to stop");
        assert!(!c.stopping(t0 + ms(40)), "not stopped yet");
        assert_eq!(host1(&mut c).chan.sent.len(), 2, "no second stop");
    }

    #[test]
    fn kills_go_to_the_members_daemon_once_it_is_ready_and_expected_exits_are_no_fault() {
        let t0 = Instant::now();
        let mut c = core(false, t0);
        let members = c.ctx.regions.members(1);
        let (killed, other) = (members[0], members[1]);
        let here = c.ctx.regions.members(0)[0];
        c.turn(vec![killed, here], t0);
        assert!(
            host1(&mut c).chan.sent.is_empty(),
            "not ready: the kill waits"
        );
        ready(&mut c, t0 + ms(10));
        assert_eq!(host1(&mut c).chan.sent, [Down::Kill(killed)]);
        assert_eq!(c.kills, [here], "another host's kill stays");
        let exits = [killed, other].map(|id| {
            let how = NetExit::Signal(9);
            Ok(Up::Exited { id, how })
        });
        host1(&mut c).chan.incoming.extend(exits);
        c.turn(vec![], t0 + ms(20));
        assert!(
            links(&mut c).exited.is_empty(),
            "without repair an exit is a fault"
        );
        let r = host1(&mut c);
        assert!(
            r.relays[&killed].published.is_empty(),
            "its exit was ordered"
        );
        let [report] = r.relays[&other].published[..] else {
            panic!("{:?}", r.relays[&other].published)
        };
        let exited = AgentStatus::Fault {
            code: FaultCode::RemoteExited,
            peer: None,
        };
        assert_eq!(report.status(), exited);

        let mut c = core(true, t0);
        ready(&mut c, t0);
        let how = NetExit::Code(1);
        host1(&mut c)
            .chan
            .incoming
            .push_back(Ok(Up::Exited { id: other, how }));
        c.turn(vec![], t0 + ms(20));
        assert_eq!(links(&mut c).exited, [(other, ProcessExit::Code(1))]);
    }

    #[test]
    fn the_stop_waits_for_every_daemon_within_its_deadline() {
        let t0 = Instant::now();
        let mut c = core(false, t0);
        assert!(!c.stopping(t0));
        let stop = ClockMsg::stop(0, c.ctx.hash, StopReason::AgentFault);
        assert_eq!(
            host1(&mut c).chan.sent,
            [Down::Clock(stop)],
            "it never got one"
        );
        assert!(!c.stopping(t0 + ms(8000)));
        assert!(c.stopping(t0 + ms(8001)), "the deadline bounds the wait");

        let mut c = core(false, t0);
        c.stopping(t0);
        host1(&mut c).chan.incoming.push_back(Ok(Up::Stopped));
        c.turn(vec![], t0 + ms(10));
        assert!(c.stopping(t0 + ms(10)));
        assert!(links(&mut c).stopped.contains(&1));
        assert!(
            !c.turn(vec![], t0 + ms(60_000)),
            "a stopped daemon is not lost"
        );
        assert!(matches!(host1(&mut c).phase, Phase::Stopped));
        let report = c.report();
        assert_eq!(report[0].outcome, "stopped");
    }

    #[test]
    fn join_requests_get_a_free_host_or_the_reason_they_cannot() {
        let (ctx, t0) = (ctx(false), Instant::now());
        let q = |host: Option<u32>| JoinRequest {
            version: PROTOCOL_VERSION,
            team: Some("unit".into()),
            host,
            scenario_hash: Some(ctx.hash),
            who: "c (pid 9)".into(),
        };
        let mut remotes: BTreeMap<u32, Remote<Fake, FakeRelay>> = BTreeMap::new();
        assert_eq!(join::which_host(&ctx, &remotes, &q(None)), Ok(1));
        assert_eq!(join::which_host(&ctx, &remotes, &q(Some(1))), Ok(1));
        let refused = |q: JoinRequest, remotes: &BTreeMap<u32, Remote<Fake, FakeRelay>>| {
            join::which_host(&ctx, remotes, &q).unwrap_err().to_string()
        };
        let old = JoinRequest {
            version: PROTOCOL_VERSION - 1,
            ..q(None)
        };
        assert!(refused(old, &remotes).contains("speaks host protocol"));
        let other = JoinRequest {
            team: Some("other".into()),
            ..q(None)
        };
        assert_eq!(
            refused(other, &remotes),
            "the daemon asks for team other; this orchestrator runs team unit"
        );
        let hash = JoinRequest {
            scenario_hash: Some(ctx.hash ^ 1),
            ..q(None)
        };
        assert!(refused(hash, &remotes).starts_with("the daemon's scenario has hash"));
        for host in [0, 2] {
            assert_eq!(
                refused(q(Some(host)), &remotes),
                format!("--host {host}: team unit has hosts 1..=1")
            );
        }
        let who = "b (pid 7)".to_owned();
        remotes.insert(1, Remote::joined(&ctx, 1, who, Fake::default(), t0));
        assert_eq!(
            refused(q(Some(1)), &remotes),
            "host 1 of team unit is already taken by b (pid 7)"
        );
        assert_eq!(
            refused(q(None), &remotes),
            "all 1 other hosts of team unit are taken"
        );
    }

    #[test]
    fn every_changed_notice_is_sent_and_the_newest_grant() {
        use cdm_runtime::messages::LossNotice;
        let n = |seq, linked| LossNotice {
            seq,
            id: 7,
            tick: 30,
            linked,
        };
        let c = |g, notice| ClockMsg::run(g, 1).with_loss(notice);
        let clocks = [
            c(10, None),
            c(11, Some(n(1, 0))),
            c(12, Some(n(1, 0))),
            c(13, Some(n(1, 1))),
            c(14, Some(n(1, 1))),
            c(15, Some(n(1, 1))),
        ];
        let mut last = forward::SentNotices::default();
        let sent: Vec<u64> = forward::worth_sending(&clocks, &mut last)
            .iter()
            .map(|c| c.grant_tick)
            .collect();
        assert_eq!(sent, [11, 13, 15]);
        let newest = forward::SentNotices {
            loss: Some(n(1, 1)),
            steer: None,
        };
        assert_eq!(last, newest);
        assert_eq!(forward::worth_sending(&[], &mut last), vec![]);
        let again = forward::worth_sending(&clocks[4..], &mut last);
        assert_eq!(again.len(), 1, "only the newest of unchanged notices");
    }

    #[test]
    fn every_command_notice_is_sent_proposed_decided_and_the_next_proposed() {
        use cdm_model::steer::TeamCommand;
        use cdm_runtime::messages::{SteerNotice, SteerPhase};
        let hold = SteerNotice::decided(1, 300, TeamCommand::Hold);
        let land = SteerNotice::decided(2, 500, TeamCommand::Land);
        let c = |notice: SteerNotice| ClockMsg::run(0, 1).with_steer(Some(notice));
        // A real-time team's clock: the hold proposed, final, the land proposed, all drained
        // at once: a member that missed the hold's decision would see notice 2 after none.
        let clocks = [
            c(hold.in_phase(SteerPhase::Proposed)),
            c(hold.in_phase(SteerPhase::Final)),
            c(land.in_phase(SteerPhase::Proposed)),
        ];
        let mut last = forward::SentNotices::default();
        let sent = forward::worth_sending(&clocks, &mut last);
        assert_eq!(sent, clocks);
    }
}
