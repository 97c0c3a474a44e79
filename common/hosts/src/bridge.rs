//! The orchestrator's bridge: a thread that admits daemons, stands in for their members on this
//! host's shared memory (relay ports), and carries the clock and the crossing states to them.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use cdm_core::audit::FaultRecord;
use cdm_core::scenario::Scenario;
use cdm_iox::{MemberPorts, OrchestratorPorts, TeamName, TeamProcess};
use cdm_runtime::messages::{AgentStatus, ClockCommand, ClockMsg, FaultCode, LossNotice, StateMsg};
use cdm_team::out;
use cdm_zenoh::{
    down_key, up_key, Assignment, Channel, Down, IdleBackoff, JoinDesk, JoinReply, JoinRequest,
    Net, NetError, PendingJoin, Regions, Up, PROTOCOL_VERSION,
};
use serde::Serialize;

use super::handover::{self, warn_hand_over, PendingHandOver, HAND_OVER_WAIT};
use super::links::{Links, LostHost};
use super::placed::placed;
use super::repairs::{CrossRepairs, RepairStep};
use super::{HostOptions, TeamFlight};
use cdm_team::Failure;

/// How often a quiet link says it is alive.
pub const HEARTBEAT: Duration = Duration::from_millis(200);
/// How long the bridge waits, after the team's stop, for every daemon to stop its members.
const STOP_DEADLINE: Duration = Duration::from_secs(8);
/// How long a remote member's silence waits for the bridge's verdict on its host: a closed
/// session is reported after zenoh's grace (150 ms); the rest is slack for a loaded machine.
const VERDICT_WAIT: Duration = Duration::from_millis(600);

/// What the bridge thread needs, owned.
struct Ctx {
    team: TeamName,
    hash: u64,
    flight: TeamFlight,
    scenario_json: String,
    regions: Regions,
    ins: BTreeMap<u32, Vec<u32>>,
    outs: BTreeMap<u32, Vec<u32>>,
    link_timeout: Duration,
    quiet: bool,
    links: SharedLinks,
    /// No loss yet: each host's link follows the repairs from here.
    repairs: CrossRepairs,
}

/// What the bridge thread knows of each host's link, read by the launch.
type SharedLinks = Arc<Mutex<Links>>;

/// The bridge thread and its stop flag.
pub struct Bridge {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Vec<HostReport>>>,
    crossing: Vec<(u32, u32)>,
    links: SharedLinks,
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
#[derive(Debug, Clone, PartialEq)]
enum Phase {
    Joined,
    Ready,
    Lost(String),
    Stopped,
}

/// One joined daemon.
struct Remote {
    host: u32,
    who: String,
    members: Vec<u32>,
    chan: Channel,
    phase: Phase,
    relays: BTreeMap<u32, MemberPorts>,
    /// For each source read on that host, the one relay that forwards it (several may read it).
    forwarder: BTreeMap<u32, u32>,
    last_tick: BTreeMap<u32, u64>,
    last_heard: Instant,
    last_sent: Instant,
    stop_sent: bool,
    subscriptions: BTreeMap<u32, Vec<String>>,
    /// The repairs as the clock messages sent to this host announced them.
    repairs: CrossRepairs,
    /// The loss notice of the last clock message sent.
    last_notice: Option<LossNotice>,
    /// Members this bridge asked the daemon to kill (their exit is expected).
    killed: BTreeSet<u32>,
    /// Relays still to hand their history over (`handover.rs`).
    handing: Option<PendingHandOver>,
}

impl Bridge {
    /// Starts the bridge thread on an open session.
    pub fn start(
        net: Net,
        s: &Scenario,
        team: &TeamName,
        regions: &Regions,
        h: &HostOptions,
        flight: TeamFlight,
        quiet: bool,
    ) -> Result<Self, Failure> {
        let desk = net
            .join_desk(team.as_str())
            .map_err(|e| Failure::fault(format!("--listen: {e}")))?;
        let placed = placed(s);
        let crossing = regions.crossing(&placed);
        let mut ins = BTreeMap::new();
        let mut outs: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
        for p in &placed {
            ins.insert(p.id, p.in_neighbors.clone());
            for &j in &p.in_neighbors {
                outs.entry(j).or_default().push(p.id);
            }
        }
        let ctx = Ctx {
            team: team.clone(),
            hash: s.content_hash(),
            flight,
            scenario_json: s.to_json(),
            regions: regions.clone(),
            ins,
            outs,
            link_timeout: h.link_timeout,
            quiet,
            links: Arc::new(Mutex::new(Links {
                host_of: regions.pairs().into_iter().collect(),
                ..Links::default()
            })),
            repairs: CrossRepairs::new(s),
        };
        let links = ctx.links.clone();
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::Builder::new()
            .name("bridge".into())
            .spawn(move || run(net, desk, ctx, &flag))
            .map_err(|e| Failure::fault(format!("cannot start the bridge thread: {e}")))?;
        Ok(Self {
            stop,
            thread: Some(thread),
            crossing,
            links,
        })
    }

    /// The team's fault, said in the terms of hosts ([`Links::explain`]). A remote member's
    /// silence may come before the bridge's verdict on its host (real time: a member is stale
    /// after 0.5 s, a closed zenoh session is reported after a short grace): for such a fault
    /// the verdict is awaited a bounded while.
    pub fn explain(&self, f: FaultRecord) -> FaultRecord {
        // The link's quiet is measured when the fault is seen, not after the wait.
        let seen = Instant::now();
        let until = seen + VERDICT_WAIT;
        loop {
            let links = self.links();
            if !links.undecided(&f) || Instant::now() >= until {
                return links.explain(f, seen);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// True when member `id` runs on another host whose reports may still arrive (its daemon
    /// joined, and neither stopped nor was lost).
    pub fn reporting(&self, id: u32) -> bool {
        self.links.lock().is_ok_and(|l| l.reporting(id))
    }

    /// The host member `id` runs on (host 0 is this one).
    pub fn host_of(&self, id: u32) -> Option<u32> {
        self.links.lock().ok()?.host_of.get(&id).copied()
    }

    fn links(&self) -> Links {
        self.links.lock().map(|l| l.clone()).unwrap_or_default()
    }

    /// The team core's kill of member `id`: when it runs on another host, its daemon kills it
    /// (the bridge thread sends the order); a member of this host is the launch's to kill.
    pub fn kill(&self, id: u32) {
        if let Ok(mut l) = self.links.lock() {
            if l.remote_host(Some(id)).is_some() {
                l.to_kill.push(id);
            }
        }
    }

    /// A remote member that exited since the last call (`--on-loss repair`), with how.
    pub fn take_exited(&self) -> Option<(u32, String)> {
        let mut l = self.links.lock().ok()?;
        (!l.exited.is_empty()).then(|| l.exited.remove(0))
    }

    /// True when the link (reader, writer) a repair opened is connected: on this host's shared
    /// memory when the reader runs here (the writer may be a remote member's relay), else as
    /// the reader's daemon reported it.
    pub fn linked(&self, ports: &OrchestratorPorts, reader: u32, writer: u32) -> bool {
        let Ok(l) = self.links.lock() else {
            return false;
        };
        if l.remote_host(Some(reader)).is_some() {
            return l.linked.contains(&(reader, writer));
        }
        let team = ports.team();
        let writer_node = match l.remote_host(Some(writer)) {
            Some(h) => team.relay_node_name(h, writer),
            None => team.node_name(TeamProcess::Agent(writer)),
        };
        let reader_node = team.node_name(TeamProcess::Agent(reader));
        let reads = ports
            .subscriber_nodes(writer)
            .is_ok_and(|n| n.contains(&reader_node));
        reads
            && ports
                .notifier_nodes(reader)
                .is_ok_and(|n| n.contains(&writer_node))
    }

    /// After the team's stop: lets the daemons stop their members (bounded), then writes
    /// `hosts.json` and says how many bytes a tick cost on the wire.
    pub fn finish(mut self, dir: &cdm_core::rundir::RunDir, ticks: u64, quiet: bool) {
        let hosts = self.join();
        // The edges that crossed hosts by the end: a repair may have added some.
        let added = self.links().crossing_added;
        let mut crossing: BTreeSet<(u32, u32)> = self.crossing.iter().copied().collect();
        crossing.extend(&added);
        let (sent, received) = hosts
            .iter()
            .fold((0, 0), |(a, b), h| (a + h.bytes_sent, b + h.bytes_received));
        let per_tick = (sent + received) as f64 / ticks.max(1) as f64;
        let doc = serde_json::json!({
            "crossing_edges": crossing,
            "crossing_edges_added_by_repairs": added,
            "hosts": hosts,
            "bytes_per_tick": per_tick,
        });
        let text = serde_json::to_string_pretty(&doc).unwrap_or_default();
        let _ = cdm_core::rundir::write_atomic(&dir.path().join("hosts.json"), text.as_bytes());
        if !quiet {
            out!(
                "  hosts: {} crossing edges, {:.0} bytes per tick on the network ({} sent, {} received)",
                crossing.len(),
                per_tick,
                sent,
                received
            );
        }
    }

    fn join(&mut self) -> Vec<HostReport> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default()
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        if self.thread.is_some() {
            let _ = self.join();
        }
    }
}

/// The bridge thread: admit daemons, pump frames both ways, until stopped.
fn run(net: Net, desk: JoinDesk, ctx: Ctx, stop: &AtomicBool) -> Vec<HostReport> {
    let mut remotes: BTreeMap<u32, Remote> = BTreeMap::new();
    let mut stopping_since: Option<Instant> = None;
    let mut idle = IdleBackoff::for_team(ctx.flight.realtime_stale_after.is_some());
    loop {
        while let Some(p) = desk.poll() {
            admit(&net, &ctx, &mut remotes, p);
        }
        let mut busy = false;
        for r in remotes.values_mut() {
            busy |= pump(r, &ctx);
        }
        if stop.load(Ordering::Relaxed) {
            let since = *stopping_since.get_or_insert_with(Instant::now);
            for r in remotes.values_mut() {
                stop_fallback(r, &ctx);
            }
            let done = remotes
                .values()
                .all(|r| matches!(r.phase, Phase::Lost(_) | Phase::Stopped));
            if done || since.elapsed() > STOP_DEADLINE {
                break;
            }
        }
        if let Some(sleep) = idle.after(busy) {
            match remotes.values_mut().next() {
                Some(r) => r.chan.wait(sleep),
                None => std::thread::sleep(sleep),
            }
        }
    }
    report(&ctx, remotes)
}

/// Answers one join request: refused with the reason, or accepted with the host's share.
fn admit(net: &Net, ctx: &Ctx, remotes: &mut BTreeMap<u32, Remote>, p: PendingJoin) {
    let key = cdm_zenoh::join_key(Some(ctx.team.as_str()));
    let q = p.request.clone();
    let refuse = |p: PendingJoin, why: String| {
        tracing::warn!(daemon = %q.who, "refused a daemon: {why}");
        p.answer(&JoinReply::Refused(why), &key);
    };
    let host = match which_host(ctx, remotes, &q) {
        Ok(h) => h,
        Err(why) => return refuse(p, why),
    };
    let chan = match net.channel(
        &down_key(ctx.team.as_str(), host),
        &up_key(ctx.team.as_str(), host),
    ) {
        Ok(c) => c,
        Err(e) => {
            return refuse(
                p,
                format!("the orchestrator cannot open host {host}'s link: {e}"),
            )
        }
    };
    let members = ctx.regions.members(host);
    let assignment = Assignment {
        team: ctx.team.as_str().to_owned(),
        host,
        hosts_of: ctx.regions.pairs(),
        scenario_json: ctx.scenario_json.clone(),
        scenario_hash: ctx.hash,
        window: ctx.flight.window,
        link_timeout_ms: ctx.link_timeout.as_millis() as u64,
        realtime_stale_after_s: ctx.flight.realtime_stale_after.map(|d| d.as_secs_f64()),
        realtime_priority: ctx.flight.realtime_priority,
        repair: ctx.flight.repair,
    };
    p.answer(&JoinReply::Accepted(Box::new(assignment)), &key);
    if !ctx.quiet {
        out!("host {host} joined: {} (agents {members:?})", q.who);
    }
    let now = Instant::now();
    remotes.insert(
        host,
        Remote {
            host,
            who: q.who,
            members,
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
            last_notice: None,
            killed: BTreeSet::new(),
            handing: None,
        },
    );
    if let Some(r) = remotes.get(&host) {
        heard(r, ctx);
    }
}

/// The host a join request may take, or why it is refused (another protocol, team or
/// scenario; a host number out of range or taken; no host left).
fn which_host(ctx: &Ctx, remotes: &BTreeMap<u32, Remote>, q: &JoinRequest) -> Result<u32, String> {
    if q.version != PROTOCOL_VERSION {
        let why = format!(
            "the daemon speaks host protocol {} and this orchestrator {PROTOCOL_VERSION}",
            q.version
        );
        return Err(why);
    }
    if let Some(t) = q.team.as_deref().filter(|t| *t != ctx.team.as_str()) {
        let why = format!(
            "the daemon asks for team {t}; this orchestrator runs team {}",
            ctx.team
        );
        return Err(why);
    }
    if let Some(h) = q.scenario_hash.filter(|&h| h != ctx.hash) {
        let why = format!(
            "the daemon's scenario has hash {h:016x}; team {} flies {:016x}",
            ctx.team, ctx.hash
        );
        return Err(why);
    }
    let hosts = ctx.regions.hosts();
    Ok(match q.host {
        Some(h) if h == 0 || h >= hosts => {
            let why = format!("--host {h}: team {} has hosts 1..={}", ctx.team, hosts - 1);
            return Err(why);
        }
        Some(h) => match remotes.get(&h) {
            Some(r) => {
                let why = format!(
                    "host {h} of team {} is already taken by {}",
                    ctx.team, r.who
                );
                return Err(why);
            }
            None => h,
        },
        None => match (1..hosts).find(|h| !remotes.contains_key(h)) {
            Some(h) => h,
            None => {
                let why = format!(
                    "all {} other hosts of team {} are taken",
                    hosts - 1,
                    ctx.team
                );
                return Err(why);
            }
        },
    })
}

/// One round for one daemon: its frames in, the clock and the crossing states out, the
/// heartbeat, the silence deadline. True when anything moved.
fn pump(r: &mut Remote, ctx: &Ctx) -> bool {
    if matches!(r.phase, Phase::Lost(_)) && ctx.flight.repair {
        follow_repairs(r, ctx);
        return false;
    }
    if matches!(r.phase, Phase::Lost(_) | Phase::Stopped) {
        return false;
    }
    let mut busy = false;
    loop {
        let frame = match r.chan.try_recv::<Up>() {
            Ok(Some(f)) => f,
            Ok(None) => break,
            Err(e @ NetError::PeerGone { .. }) => {
                let why = format!("the daemon is gone, {e}: killed or exited");
                lose(r, ctx, why, true);
                return true;
            }
            Err(e) => {
                lose(r, ctx, format!("{e}"), false);
                return true;
            }
        };
        busy = true;
        r.last_heard = Instant::now();
        if let Err(why) = on_frame(r, ctx, frame) {
            lose(r, ctx, why, false);
            return true;
        }
    }
    // The states just published may complete a relay's history for a pending hand-over.
    handover::poll(
        &mut r.handing,
        &mut r.relays,
        HAND_OVER_WAIT,
        warn_hand_over,
    );
    if busy {
        heard(r, ctx);
    }
    if r.phase == Phase::Ready {
        send_kills(r, ctx);
        match forward(r, ctx) {
            Ok(sent) => busy |= sent,
            Err(why) => {
                lose(r, ctx, why, false);
                return true;
            }
        }
    }
    if r.last_sent.elapsed() >= HEARTBEAT {
        let _ = r.chan.send(&Down::Heartbeat);
        r.last_sent = Instant::now();
    }
    // Once the stop went, the daemon may stop its members quietly for a while (a bounded
    // wait); the bridge's own stop deadline bounds it, and a killed daemon is still seen.
    if !r.stop_sent && r.last_heard.elapsed() > ctx.link_timeout {
        let why = format!(
            "nothing heard from host {} ({}) for {:.1} s: network partition or daemon gone",
            r.host,
            r.who,
            ctx.link_timeout.as_secs_f64()
        );
        lose(r, ctx, why, false);
        busy = true;
    }
    busy
}

/// Notes for the launch that host `r` was just heard.
fn heard(r: &Remote, ctx: &Ctx) {
    if let Ok(mut links) = ctx.links.lock() {
        links.heard.insert(r.host, (r.who.clone(), r.last_heard));
    }
}

/// One frame from a daemon.
fn on_frame(r: &mut Remote, ctx: &Ctx, frame: Up) -> Result<(), String> {
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
                relay
                    .publish_quietly(st.into())
                    .map_err(|e| e.to_string())?;
                r.last_tick.insert(st.id, st.tick);
                touched.push(st.id);
            }
            touched.dedup();
            for id in touched {
                if let Some(relay) = r.relays.get_mut(&id) {
                    relay.notify_readers().map_err(|e| e.to_string())?;
                }
            }
        }
        Up::Exited { id, how } => {
            if r.killed.contains(&id) {
                return Ok(());
            }
            tracing::warn!(host = r.host, id, "agent {id} on host {} {how}", r.host);
            if ctx.flight.repair {
                // Lost and repaired around, as a member of this host that exits.
                if let Ok(mut links) = ctx.links.lock() {
                    links.exited.push((id, how));
                }
            } else {
                report_fault(r, ctx, id, FaultCode::RemoteExited);
            }
        }
        Up::Linked(pairs) => {
            if let Ok(mut links) = ctx.links.lock() {
                links.linked.extend(pairs);
            }
        }
        Up::Heartbeat => {}
        Up::Stopped => {
            r.phase = Phase::Stopped;
            if let Ok(mut links) = ctx.links.lock() {
                links.stopped.insert(r.host);
            }
        }
    }
    Ok(())
}

/// The relay ports of a ready host's members: each reads (and forwards) its in-neighbours on
/// other hosts and wakes its out-neighbours on other hosts.
fn open_relays(r: &mut Remote, ctx: &Ctx) -> Result<(), String> {
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
        let ports = MemberPorts::open_relay(&ctx.team, r.host, g, ctx.hash, &ins, &outs)
            .map_err(|e| format!("cannot stand in for agent {g} of host {}: {e}", r.host))?;
        r.relays.insert(g, ports);
    }
    Ok(())
}

/// The clock and the crossing states towards a ready host; true when anything went.
fn forward(r: &mut Remote, ctx: &Ctx) -> Result<bool, String> {
    let mut clocks = vec![];
    let mut batch = vec![];
    for (k, (&g, relay)) in r.relays.iter_mut().enumerate() {
        // Every relay subscribes to the clock: each drains its own, the first one's are kept.
        relay
            .receive_clock(|c| {
                if k == 0 {
                    clocks.push(c);
                }
            })
            .map_err(|e| e.to_string())?;
        let forwarder = &r.forwarder;
        relay
            .receive_neighbors(|m| {
                if forwarder.get(&m.id) == Some(&g) {
                    batch.push(m.into());
                }
            })
            .map_err(|e| e.to_string())?;
    }
    let moved = !clocks.is_empty() || !batch.is_empty();
    // States first: a grant must never reach members before the states it lets them use.
    if !batch.is_empty() {
        r.chan
            .send(&Down::States(batch))
            .map_err(|e| e.to_string())?;
        r.last_sent = Instant::now();
    }
    for c in worth_sending(&clocks, &mut r.last_notice) {
        // A new loss: the relays carry the repaired links before the daemon's members hear it.
        let step = r.repairs.on_notice(c.loss()).map_err(|e| e.to_string())?;
        carry_repair(r, ctx, &step);
        r.stop_sent |= matches!(c.command(), ClockCommand::Stop(_));
        r.chan
            .send(&Down::Clock(c.into()))
            .map_err(|e| e.to_string())?;
        r.last_sent = Instant::now();
    }
    Ok(moved)
}

/// A lost host's relays still stand in for its members' last states: repairs that make a
/// member of this host read one of them are carried (linked, history handed over), as the
/// killed member's own publisher would on one host.
fn follow_repairs(r: &mut Remote, ctx: &Ctx) {
    let mut clocks = vec![];
    for (k, relay) in r.relays.values_mut().enumerate() {
        let _ = relay.receive_clock(|c| {
            if k == 0 {
                clocks.push(c);
            }
        });
        let _ = relay.receive_neighbors(|_| {});
    }
    for c in worth_sending(&clocks, &mut r.last_notice) {
        match r.repairs.on_notice(c.loss()) {
            Ok(step) => carry_repair(r, ctx, &step),
            Err(e) => tracing::warn!("host {}: the repairs its relays carry: {e}", r.host),
        }
    }
    // Nothing more will cross from a lost host: its relays hand over what they hold.
    handover::poll(
        &mut r.handing,
        &mut r.relays,
        Duration::ZERO,
        warn_hand_over,
    );
}

/// Of the clock messages drained, in order: each whose loss notice differs from the one sent
/// before (members must see every loss, and every rise of the connected count), and the newest.
fn worth_sending(clocks: &[ClockMsg], last: &mut Option<LossNotice>) -> Vec<ClockMsg> {
    let mut out = vec![];
    for (k, c) in clocks.iter().enumerate() {
        if c.loss() != *last || k + 1 == clocks.len() {
            *last = c.loss();
            out.push(*c);
        }
    }
    out
}

/// A repair's new links at this host's relays: a reader on that host gets its new
/// in-neighbour's states forwarded (one relay subscribes to it here), a reader on this host is
/// woken by the relay of its new in-neighbour there; history goes to new readers once every
/// link is connected. A link that cannot be opened (no room left) is left for the team core's
/// deadline, which names it.
fn carry_repair(r: &mut Remote, ctx: &Ctx, step: &RepairStep) {
    for &(reader, writer) in &step.new_links {
        let (hr, hw) = (ctx.regions.host_of(reader), ctx.regions.host_of(writer));
        let opened = if hr == r.host && hw != r.host && !r.forwarder.contains_key(&writer) {
            r.forwarder.insert(writer, reader);
            r.relays.get_mut(&reader).map(|p| p.connect(&[writer], &[]))
        } else if hw == r.host && hr == 0 {
            r.relays.get_mut(&writer).map(|p| p.connect(&[], &[reader]))
        } else {
            None
        };
        if let Some(Err(e)) = opened {
            tracing::warn!(
                host = r.host,
                "cannot carry the repaired link {writer} -> {reader}: {e}"
            );
        }
        if hr != hw && (hr == r.host || hw == r.host) {
            if let Ok(mut links) = ctx.links.lock() {
                links.crossing_added.insert((writer, reader));
            }
        }
    }
    if step.hand_over {
        handover::start(
            &mut r.handing,
            step.needs_from,
            &mut r.relays,
            warn_hand_over,
        );
    }
}

/// The team core's kills of this host's members, sent to its daemon.
fn send_kills(r: &mut Remote, ctx: &Ctx) {
    let ids: Vec<u32> = match ctx.links.lock() {
        Ok(mut l) => {
            let (mine, rest) = l.to_kill.drain(..).partition(|id| r.members.contains(id));
            l.to_kill = rest;
            mine
        }
        Err(_) => return,
    };
    for id in ids {
        r.killed.insert(id);
        if let Err(e) = r.chan.send(&Down::Kill(id)) {
            tracing::warn!(host = r.host, id, "cannot send a kill: {e}");
        }
        r.last_sent = Instant::now();
    }
}

/// Publishes a fault report for `id` through its relay: the orchestrator stops the team with it
/// as it does for a member's own report (telemetry keeps every complete tick).
fn report_fault(r: &mut Remote, ctx: &Ctx, id: u32, code: FaultCode) {
    let tick = r.last_tick.get(&id).copied().unwrap_or(0);
    let msg = StateMsg::ok(tick, ctx.hash, id, [0.0; 12])
        .with_status(AgentStatus::Fault { code, peer: None });
    if let Some(relay) = r.relays.get_mut(&id) {
        if let Err(e) = relay.publish(msg) {
            tracing::warn!(id, error = %e, "cannot report a remote agent's fault");
        }
    }
}

/// The link to a daemon is gone (`dead`: the daemon itself, so its members with it): every
/// member of that host is reported lost.
fn lose(r: &mut Remote, ctx: &Ctx, why: String, dead: bool) {
    tracing::error!(host = r.host, "host {} lost: {why}", r.host);
    let host = LostHost {
        who: r.who.clone(),
        members: r.members.clone(),
        why: why.clone(),
    };
    // Lockstep `--on-loss repair`: each member still flying is lost as if SIGKILLed on one host
    // (the team core repairs, or stops naming the losses); otherwise the team stops `host-lost`.
    let repaired = dead && ctx.flight.repair;
    let alive: Vec<u32> = r
        .members
        .iter()
        .copied()
        .filter(|id| !r.killed.contains(id))
        .collect();
    if let Ok(mut links) = ctx.links.lock() {
        links.lost.insert(r.host, host);
        if repaired {
            let how = format!("was killed with host {} ({}): {why}", r.host, r.who);
            links
                .exited
                .extend(alive.iter().map(|&id| (id, how.clone())));
        }
    }
    if !repaired {
        for id in alive {
            report_fault(r, ctx, id, FaultCode::HostLost);
        }
    }
    r.phase = Phase::Lost(why);
}

/// At the end, a daemon that never received the stop (the team failed before its first grant)
/// gets one.
fn stop_fallback(r: &mut Remote, ctx: &Ctx) {
    if r.stop_sent || matches!(r.phase, Phase::Lost(_) | Phase::Stopped) {
        return;
    }
    let reason = cdm_runtime::messages::StopReason::AgentFault;
    let stop = ClockMsg::stop(0, ctx.hash, reason);
    let _ = r.chan.send(&Down::Clock(stop.into()));
    r.stop_sent = true;
}

/// Every host's record for `hosts.json`.
fn report(ctx: &Ctx, mut remotes: BTreeMap<u32, Remote>) -> Vec<HostReport> {
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

    #[test]
    fn every_changed_notice_is_sent_and_the_newest_grant() {
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
        let mut last = None;
        let sent: Vec<u64> = worth_sending(&clocks, &mut last)
            .iter()
            .map(|c| c.grant_tick)
            .collect();
        assert_eq!(sent, [11, 13, 15]);
        assert_eq!(last, Some(n(1, 1)));
        assert_eq!(worth_sending(&[], &mut last), vec![]);
        let again = worth_sending(&clocks[4..], &mut last);
        assert_eq!(again.len(), 1, "only the newest of unchanged notices");
    }
}
