//! The orchestrator's bridge: a thread that admits daemons, stands in for their members on this
//! host's shared memory (relay ports), and carries the clock and the crossing states to them.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use cdm_iox::{MemberPorts, OrchestratorPorts, TeamName, TeamProcess};
use cdm_records::audit::FaultRecord;
use cdm_runtime::messages::{AgentStatus, ClockCommand, ClockMsg, FaultCode, LossNotice, StateMsg};
use cdm_runtime::process_exit::ProcessExit;
use cdm_scenario::Scenario;
use cdm_team::out;
use cdm_team::Failure;
use cdm_zenoh::{
    down_key, up_key, Assignment, Down, JoinDesk, JoinReply, JoinRequest, Net, PendingJoin, Up,
    PROTOCOL_VERSION,
};
use serde::Serialize;

use crate::error::{LinkLost, Refusal};
use crate::handover::{self, warn_hand_over, PendingHandOver, HAND_OVER_WAIT};
use crate::host_link::{HostLink, ZenohLink};
use crate::idle::IdleBackoff;
use crate::links::{Links, LostHost};
use crate::other_hosts::OtherHosts;
use crate::placed::placed;
use crate::regions::Regions;
use crate::repairs::{CrossRepairs, RepairStep};
use crate::{HostOptions, TeamFlight};

/// How often a quiet link says it is alive.
pub const HEARTBEAT: Duration = Duration::from_millis(200);
/// How long the bridge waits, after the team's stop, for every daemon to stop its members.
const STOP_DEADLINE: Duration = Duration::from_secs(8);

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
    /// Mutual TLS: every daemon must ask as the host its certificate names.
    tls: bool,
}

impl Ctx {
    fn new(
        s: &Scenario,
        team: &TeamName,
        regions: &Regions,
        h: &HostOptions,
        flight: TeamFlight,
        quiet: bool,
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
            quiet,
            links: Arc::new(Mutex::new(Links {
                host_of: regions.pairs().into_iter().collect(),
                link_timeout: Some(h.link_timeout),
                ..Links::default()
            })),
            repairs: CrossRepairs::new(s),
            tls: matches!(h.transport, crate::Transport::Tls(_)),
        }
    }
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
#[derive(Debug)]
enum Phase {
    Joined,
    Ready,
    Lost(LinkLost),
    Stopped,
}

/// The link to one daemon: its frames up, the orchestrator's down.
type DaemonLink = ZenohLink<Up, Down>;

/// One joined daemon, over link `L` (zenoh; a fake one in the unit tests).
struct Remote<L = DaemonLink> {
    host: u32,
    who: String,
    members: Vec<u32>,
    chan: L,
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
        let ctx = Ctx::new(s, team, regions, h, flight, quiet);
        let desk = net
            .join_desk(team.as_str(), ctx.tls.then(|| regions.hosts() - 1))
            .map_err(|e| Failure::fault(format!("--listen: {e}")))?;
        let crossing = regions.crossing(&placed(s));
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

    fn links(&self) -> Links {
        self.links.lock().map(|l| l.clone()).unwrap_or_default()
    }

    fn join(&mut self) -> Vec<HostReport> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default()
    }
}

impl OtherHosts for Bridge {
    /// The team's fault, said in the terms of hosts ([`Links::explain`]). A remote member's
    /// silence may come before the bridge's verdict on its host (real time: a member is stale
    /// after 0.5 s; a closed zenoh session is reported after a short grace, a quiet link after
    /// the link timeout): for such a fault the verdict is awaited as long as
    /// [`Links::verdict_wait`] says.
    fn explain(&self, f: FaultRecord) -> FaultRecord {
        // The link's quiet is measured when the fault is seen, not after the wait.
        let seen = Instant::now();
        loop {
            let links = self.links();
            let now = Instant::now();
            match links.verdict_wait(&f, seen) {
                Some(until) if now < until => {}
                _ => return links.judged_at(now).explain(f, seen),
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// True when member `id` runs on another host whose reports may still arrive (its daemon
    /// joined, and neither stopped nor was lost).
    fn reporting(&self, id: u32) -> bool {
        self.links.lock().is_ok_and(|l| l.reporting(id))
    }

    /// The host member `id` runs on (host 0 is this one).
    fn host_of(&self, id: u32) -> Option<u32> {
        self.links.lock().ok()?.host_of.get(&id).copied()
    }

    /// The team core's kill of member `id`: when it runs on another host, its daemon kills it
    /// (the bridge thread sends the order); a member of this host is the launch's to kill.
    fn kill(&self, id: u32) {
        if let Ok(mut l) = self.links.lock() {
            if l.remote_host(Some(id)).is_some() {
                l.to_kill.push(id);
            }
        }
    }

    /// A remote member that exited since the last call (`--on-loss repair`), with how.
    fn take_exited(&self) -> Option<(u32, ProcessExit)> {
        let mut l = self.links.lock().ok()?;
        (!l.exited.is_empty()).then(|| l.exited.remove(0))
    }

    /// True when the link (reader, writer) a repair opened is connected: on this host's shared
    /// memory when the reader runs here (the writer may be a remote member's relay), else as
    /// the reader's daemon reported it.
    fn linked(&self, ports: &OrchestratorPorts, reader: u32, writer: u32) -> bool {
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
    fn finish(mut self: Box<Self>, dir: &cdm_records::rundir::RunDir, ticks: u64, quiet: bool) {
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
        let _ = cdm_records::rundir::write_atomic(&dir.path().join("hosts.json"), text.as_bytes());
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
}

impl Drop for Bridge {
    fn drop(&mut self) {
        if self.thread.is_some() {
            let _ = self.join();
        }
    }
}

/// The bridge thread: admit daemons, pump frames both ways, until stopped. The only place that
/// reads the clock: every step below is handed the instant of its turn.
fn run(net: Net, desk: JoinDesk, ctx: Ctx, stop: &AtomicBool) -> Vec<HostReport> {
    let mut remotes: BTreeMap<u32, Remote> = BTreeMap::new();
    let mut stopping_since: Option<Instant> = None;
    let mut idle = IdleBackoff::for_team(ctx.flight.realtime_stale_after.is_some());
    loop {
        let now = Instant::now();
        while let Some(p) = desk.poll() {
            admit(&net, &ctx, &mut remotes, p, now);
        }
        let mut busy = false;
        for r in remotes.values_mut() {
            busy |= pump(r, &ctx, now);
        }
        if stop.load(Ordering::Relaxed) {
            let since = *stopping_since.get_or_insert(now);
            for r in remotes.values_mut() {
                stop_fallback(r, &ctx);
            }
            let done = remotes
                .values()
                .all(|r| matches!(r.phase, Phase::Lost(_) | Phase::Stopped));
            if done || now.saturating_duration_since(since) > STOP_DEADLINE {
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
fn admit(net: &Net, ctx: &Ctx, remotes: &mut BTreeMap<u32, Remote>, p: PendingJoin, now: Instant) {
    let q = p.request.clone();
    let refuse = |p: PendingJoin, why: Refusal| {
        tracing::warn!(daemon = %q.who, "refused a daemon: {why}");
        p.answer(&JoinReply::Refused(why.to_string()));
    };
    if let Err(why) = bound(ctx, p.slot, q.host) {
        return refuse(p, why);
    }
    let host = match which_host(ctx, remotes, &q) {
        Ok(h) => h,
        Err(why) => return refuse(p, why),
    };
    let chan = match net.channel(
        &down_key(ctx.team.as_str(), host),
        &up_key(ctx.team.as_str(), host),
    ) {
        Ok(c) => ZenohLink::new(c),
        Err(e) => {
            let detail = e.to_string();
            return refuse(p, Refusal::NoLink { host, detail });
        }
    };
    p.answer(&JoinReply::Accepted(Box::new(assignment(ctx, host))));
    let r = Remote::joined(ctx, host, q.who, chan, now);
    if !ctx.quiet {
        out!("host {host} joined: {} (agents {:?})", r.who, r.members);
    }
    heard(&r, ctx);
    remotes.insert(host, r);
}

/// A request asks on its own host's key (`join/k` for `host: Some(k)`): with TLS, access control
/// lets only host k's certificate ask there, so the host number is the certificate's.
fn bound(ctx: &Ctx, slot: Option<u32>, host: Option<u32>) -> Result<(), Refusal> {
    match (slot, host) {
        (None, _) if ctx.tls => Err(Refusal::Unbound),
        (s, h) if s != h => Err(Refusal::Slot { slot, host }),
        _ => Ok(()),
    }
}

/// Host `host`'s share of the team, as its daemon needs it.
fn assignment(ctx: &Ctx, host: u32) -> Assignment {
    Assignment {
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
    }
}

impl<L> Remote<L> {
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
            last_notice: None,
            killed: BTreeSet::new(),
            handing: None,
        }
    }
}

/// The host a join request may take, or why it is refused (another protocol, team or
/// scenario; a host number out of range or taken; no host left).
fn which_host<L>(
    ctx: &Ctx,
    remotes: &BTreeMap<u32, Remote<L>>,
    q: &JoinRequest,
) -> Result<u32, Refusal> {
    let team = || ctx.team.as_str().to_owned();
    if q.version != PROTOCOL_VERSION {
        return Err(Refusal::Protocol {
            theirs: q.version,
            ours: PROTOCOL_VERSION,
        });
    }
    if let Some(t) = q.team.as_deref().filter(|t| *t != ctx.team.as_str()) {
        let asked = t.to_owned();
        return Err(Refusal::Team {
            asked,
            team: team(),
        });
    }
    if let Some(h) = q.scenario_hash.filter(|&h| h != ctx.hash) {
        let (theirs, ours) = (h, ctx.hash);
        return Err(Refusal::Scenario {
            theirs,
            team: team(),
            ours,
        });
    }
    let hosts = ctx.regions.hosts();
    match q.host {
        Some(host) if host == 0 || host >= hosts => Err(Refusal::NoSuchHost {
            host,
            team: team(),
            last: hosts - 1,
        }),
        Some(host) => match remotes.get(&host) {
            Some(r) => Err(Refusal::Taken {
                host,
                team: team(),
                by: r.who.clone(),
            }),
            None => Ok(host),
        },
        None => (1..hosts)
            .find(|h| !remotes.contains_key(h))
            .ok_or_else(|| Refusal::Full {
                others: hosts - 1,
                team: team(),
            }),
    }
}

/// One round for one daemon at `now`: its frames in, the clock and the crossing states out,
/// the heartbeat, the silence deadline. True when anything moved.
fn pump<L: HostLink<In = Up, Out = Down>>(r: &mut Remote<L>, ctx: &Ctx, now: Instant) -> bool {
    if matches!(r.phase, Phase::Lost(_)) && ctx.flight.repair {
        follow_repairs(r, ctx, now);
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
        heard(r, ctx);
    }
    if matches!(r.phase, Phase::Ready) {
        send_kills(r, ctx, now);
        match forward(r, ctx, now) {
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
fn heard<L>(r: &Remote<L>, ctx: &Ctx) {
    if let Ok(mut links) = ctx.links.lock() {
        links.heard.insert(r.host, (r.who.clone(), r.last_heard));
    }
}

/// One frame from a daemon.
fn on_frame<L>(r: &mut Remote<L>, ctx: &Ctx, frame: Up) -> Result<(), LinkLost> {
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
                relay.publish_quietly(st.into())?;
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
fn open_relays<L>(r: &mut Remote<L>, ctx: &Ctx) -> Result<(), LinkLost> {
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
        let ports = MemberPorts::open_relay(&ctx.team, r.host, g, ctx.hash, &ins, &outs).map_err(
            |source| LinkLost::Relay {
                host: r.host,
                id: g,
                source,
            },
        )?;
        r.relays.insert(g, ports);
    }
    Ok(())
}

/// The clock and the crossing states towards a ready host; true when anything went.
fn forward<L: HostLink<In = Up, Out = Down>>(
    r: &mut Remote<L>,
    ctx: &Ctx,
    now: Instant,
) -> Result<bool, LinkLost> {
    let mut clocks = vec![];
    let mut batch = vec![];
    for (k, (&g, relay)) in r.relays.iter_mut().enumerate() {
        // Every relay subscribes to the clock: each drains its own, the first one's are kept.
        relay.receive_clock(|c| {
            if k == 0 {
                clocks.push(c);
            }
        })?;
        let forwarder = &r.forwarder;
        relay.receive_neighbors(|m| {
            if forwarder.get(&m.id) == Some(&g) {
                batch.push(m.into());
            }
        })?;
    }
    let moved = !clocks.is_empty() || !batch.is_empty();
    // States first: a grant must never reach members before the states it lets them use.
    if !batch.is_empty() {
        r.chan.send(&Down::States(batch))?;
        r.last_sent = now;
    }
    for c in worth_sending(&clocks, &mut r.last_notice) {
        // A new loss: the relays carry the repaired links before the daemon's members hear it.
        let step = r.repairs.on_notice(c.loss())?;
        carry_repair(r, ctx, &step, now);
        r.stop_sent |= matches!(c.command(), ClockCommand::Stop(_));
        r.chan.send(&Down::Clock(c.into()))?;
        r.last_sent = now;
    }
    Ok(moved)
}

/// A lost host's relays still stand in for its members' last states: repairs that make a
/// member of this host read one of them are carried (linked, history handed over), as the
/// killed member's own publisher would on one host.
fn follow_repairs<L>(r: &mut Remote<L>, ctx: &Ctx, now: Instant) {
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
            Ok(step) => carry_repair(r, ctx, &step, now),
            Err(e) => tracing::warn!("host {}: the repairs its relays carry: {e}", r.host),
        }
    }
    // Nothing more will cross from a lost host: its relays hand over what they hold.
    let wait = Duration::ZERO;
    handover::poll(&mut r.handing, &mut r.relays, wait, now, warn_hand_over);
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
fn carry_repair<L>(r: &mut Remote<L>, ctx: &Ctx, step: &RepairStep, now: Instant) {
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
        let from = step.needs_from;
        handover::start(&mut r.handing, from, &mut r.relays, now, warn_hand_over);
    }
}

/// The team core's kills of this host's members, sent to its daemon.
fn send_kills<L: HostLink<In = Up, Out = Down>>(r: &mut Remote<L>, ctx: &Ctx, now: Instant) {
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
        r.last_sent = now;
    }
}

/// Publishes a fault report for `id` through its relay: the orchestrator stops the team with it
/// as it does for a member's own report (telemetry keeps every complete tick).
fn report_fault<L>(r: &mut Remote<L>, ctx: &Ctx, id: u32, code: FaultCode) {
    let tick = r.last_tick.get(&id).copied().unwrap_or(0);
    let msg = StateMsg::ok(tick, ctx.hash, id, [0.0; 12])
        .with_status(AgentStatus::Fault { code, peer: None });
    if let Some(relay) = r.relays.get_mut(&id) {
        if let Err(e) = relay.publish(msg) {
            tracing::warn!(id, error = %e, "cannot report a remote agent's fault");
        }
    }
}

/// The link to a daemon is gone (the daemon itself, when its session closed: its members with
/// it): every member of that host is reported lost.
fn lose<L>(r: &mut Remote<L>, ctx: &Ctx, why: LinkLost) {
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
    if let Ok(mut links) = ctx.links.lock() {
        if repaired {
            let how = ProcessExit::WithHost {
                host: r.host,
                who: r.who.clone(),
                why: why.to_string(),
            };
            links
                .exited
                .extend(alive.iter().map(|&id| (id, how.clone())));
        }
        links.lost.insert(r.host, host);
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
fn stop_fallback<L: HostLink<In = Up, Out = Down>>(r: &mut Remote<L>, ctx: &Ctx) {
    if r.stop_sent || matches!(r.phase, Phase::Lost(_) | Phase::Stopped) {
        return;
    }
    let reason = cdm_runtime::messages::StopReason::AgentFault;
    let stop = ClockMsg::stop(0, ctx.hash, reason);
    let _ = r.chan.send(&Down::Clock(stop.into()));
    r.stop_sent = true;
}

/// Every host's record for `hosts.json`.
fn report<L: HostLink>(ctx: &Ctx, mut remotes: BTreeMap<u32, Remote<L>>) -> Vec<HostReport> {
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

    type Fake = FakeLink<Up, Down>;

    /// paper40 over two hosts, flown by the test's clock from `t0`.
    fn ctx(repair: bool) -> Ctx {
        let s = Scenario::builtin("paper40").unwrap();
        let regions = Regions::split(&placed(&s), 2);
        let flight = TeamFlight {
            window: 16,
            realtime_stale_after: None,
            realtime_priority: None,
            repair,
        };
        let team = TeamName::new("unit").unwrap();
        Ctx::new(&s, &team, &regions, &HostOptions::default(), flight, true)
    }

    fn joined(ctx: &Ctx, t0: Instant) -> Remote<Fake> {
        Remote::joined(ctx, 1, "b (pid 7)".into(), Fake::default(), t0)
    }

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    #[test]
    fn a_quiet_link_gets_heartbeats_and_a_silent_one_is_lost() {
        let (ctx, t0) = (ctx(false), Instant::now());
        let mut r = joined(&ctx, t0);
        assert!(!pump(&mut r, &ctx, t0 + ms(199)));
        assert!(r.chan.sent.is_empty(), "no heartbeat before {HEARTBEAT:?}");
        pump(&mut r, &ctx, t0 + ms(200));
        assert_eq!(r.chan.sent, [Down::Heartbeat]);
        r.chan.incoming.push_back(Ok(Up::Heartbeat));
        assert!(pump(&mut r, &ctx, t0 + ms(1000)), "a frame moved");
        assert_eq!(r.last_heard, t0 + ms(1000));
        pump(&mut r, &ctx, t0 + ms(4000));
        assert!(
            matches!(r.phase, Phase::Joined),
            "3 s of quiet is the limit, not over it"
        );
        assert!(pump(&mut r, &ctx, t0 + ms(4001)));
        assert!(matches!(
            r.phase,
            Phase::Lost(LinkLost::Silent { host: 1, .. })
        ));
        let links = ctx.links.lock().unwrap();
        let why = &links.lost[&1].why;
        assert_eq!(
            why,
            "nothing heard from host 1 (b (pid 7)) for 3.0 s: network partition or daemon gone"
        );
        assert_eq!(links.lost[&1].members, ctx.regions.members(1));
        assert!(links.exited.is_empty(), "a partition is not an exit");
    }

    #[test]
    fn a_closed_session_under_repair_is_every_member_of_the_host_exiting() {
        let (ctx, t0) = (ctx(true), Instant::now());
        let mut r = joined(&ctx, t0);
        let gone = LinkError::PeerGone("its zenoh session closed".into());
        r.chan.incoming.push_back(Err(gone));
        assert!(pump(&mut r, &ctx, t0 + ms(50)));
        assert!(matches!(r.phase, Phase::Lost(LinkLost::DaemonGone(_))));
        let links = ctx.links.lock().unwrap().clone();
        let members = ctx.regions.members(1);
        let exited: Vec<u32> = links.exited.iter().map(|(id, _)| *id).collect();
        assert_eq!(exited, members);
        assert_eq!(
            links.exited[0].1.to_string(),
            "was killed with host 1 (b (pid 7)): the daemon is gone, its zenoh session closed: \
             killed or exited"
        );
        assert!(
            !pump(&mut r, &ctx, t0 + ms(9000)),
            "a lost host only follows repairs"
        );
    }

    #[test]
    fn a_stopped_daemon_or_one_told_to_stop_is_not_lost_by_its_silence() {
        let (ctx, t0) = (ctx(false), Instant::now());
        let mut r = joined(&ctx, t0);
        r.chan.incoming.push_back(Ok(Up::Stopped));
        pump(&mut r, &ctx, t0 + ms(10));
        assert!(matches!(r.phase, Phase::Stopped));
        assert!(ctx.links.lock().unwrap().stopped.contains(&1));
        assert!(!pump(&mut r, &ctx, t0 + ms(60_000)));
        assert!(matches!(r.phase, Phase::Stopped));

        let mut told = joined(&ctx, t0);
        told.stop_sent = true;
        pump(&mut told, &ctx, t0 + ms(60_000));
        assert!(
            matches!(told.phase, Phase::Joined),
            "the bridge's stop deadline bounds it"
        );
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
        let mut remotes: BTreeMap<u32, Remote<Fake>> = BTreeMap::new();
        assert_eq!(which_host(&ctx, &remotes, &q(None)), Ok(1));
        assert_eq!(which_host(&ctx, &remotes, &q(Some(1))), Ok(1));
        let refused = |q: JoinRequest, remotes: &BTreeMap<u32, Remote<Fake>>| {
            which_host(&ctx, remotes, &q).unwrap_err().to_string()
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
        remotes.insert(1, joined(&ctx, t0));
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
