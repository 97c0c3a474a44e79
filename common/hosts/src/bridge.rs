//! The orchestrator's bridge thread: the loop around [`BridgeCore`]. It owns the zenoh session
//! and its join desk, reads the clock, hands the core each turn's instant and the team core's
//! kills, and passes what the core noted on to the launch ([`Links`], shared with it).

use std::collections::BTreeSet;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use cdm_iox::{OrchestratorPorts, TeamName, TeamProcess};
use cdm_records::audit::FaultRecord;
use cdm_runtime::process_exit::ProcessExit;
use cdm_scenario::Scenario;
use cdm_team::notices::NoticeSink;
use cdm_zenoh::{down_key, up_key, JoinDesk, JoinReply, Net, PendingJoin};

use crate::bridge_core::{BridgeCore, Ctx, HostReport, RecordingChunk};
use crate::error::{BridgeError, Refusal};
use crate::host_link::ZenohLink;
use crate::idle::IdleBackoff;
use crate::links::Links;
use crate::notice::HostNotice;
use crate::other_hosts::OtherHosts;
use crate::placed::placed;
use crate::regions::Regions;
use crate::{HostOptions, TeamFlight};

/// What the bridge thread knows of each host's link, read by the launch.
type SharedLinks = Arc<Mutex<Links>>;

/// The bridge thread and its stop flag.
pub struct Bridge {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Vec<HostReport>>>,
    crossing: Vec<(u32, u32)>,
    links: SharedLinks,
    notices: Arc<dyn NoticeSink>,
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
        notices: Arc<dyn NoticeSink>,
    ) -> Result<Self, BridgeError> {
        let ctx = Ctx::new(s, team, regions, h, flight);
        let desk = net
            .join_desk(team.as_str(), ctx.tls.then(|| regions.hosts() - 1))
            .map_err(BridgeError::Listen)?;
        let crossing = regions.crossing(&placed(s));
        let links = Arc::new(Mutex::new(Links {
            host_of: regions.pairs().into_iter().collect(),
            link_timeout: Some(h.link_timeout),
            ..Links::default()
        }));
        let shared = links.clone();
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let said = notices.clone();
        let thread = std::thread::Builder::new()
            .name("bridge".into())
            .spawn(move || run(net, desk, ctx, &shared, &flag, &*said))
            .map_err(BridgeError::Thread)?;
        Ok(Self {
            stop,
            thread: Some(thread),
            crossing,
            links,
            notices,
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
        let mut now = seen;
        loop {
            let links = self.links();
            match links.verdict_wait(&f, seen) {
                Some(until) if now < until => {}
                _ => return links.judged_at(now).explain(f, seen),
            }
            std::thread::sleep(Duration::from_millis(10));
            now = Instant::now();
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
    fn finish(mut self: Box<Self>, dir: &cdm_records::rundir::RunDir, ticks: u64) {
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
        self.notices.notice(&HostNotice::Traffic {
            crossing: crossing.len(),
            per_tick,
            sent,
            received,
        });
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        if self.thread.is_some() {
            let _ = self.join();
        }
    }
}

/// The bridge thread: admit daemons, let the core pump frames both ways, until stopped. The
/// only place that reads the clock: every turn of the core is handed its instant.
fn run(
    net: Net,
    desk: JoinDesk,
    ctx: Ctx,
    shared: &Mutex<Links>,
    stop: &AtomicBool,
    notices: &dyn NoticeSink,
) -> Vec<HostReport> {
    let mut idle = IdleBackoff::for_team(ctx.flight.realtime_stale_after.is_some());
    let recording = ctx.flight.recording.clone();
    let mut core = BridgeCore::new(ctx);
    loop {
        let now = Instant::now();
        while let Some(p) = desk.poll() {
            admit(&net, &mut core, p, now, notices);
        }
        let kills = shared
            .lock()
            .map(|mut l| std::mem::take(&mut l.to_kill))
            .unwrap_or_default();
        let busy = core.turn(kills, now);
        for part in core.take_recordings() {
            let Some(dir) = &recording else { break };
            if let Err(e) = write_recording(dir, &part) {
                tracing::warn!(id = part.id, "agent {}'s recording not saved: {e}", part.id);
            }
        }
        let done = stop.load(Ordering::Relaxed) && core.stopping(now);
        core.settle(|notes| {
            if let Ok(mut l) = shared.lock() {
                notes.into_iter().for_each(|n| l.note(n));
            }
        });
        if done {
            break;
        }
        if let Some(sleep) = idle.after(busy) {
            if !core.wait(sleep) {
                std::thread::sleep(sleep);
            }
        }
    }
    core.report()
}

/// Writes a part of another host's member's recording into the run directory's recording
/// folder (created owner-only if the launch spawned no member here), at its offset; the first
/// part starts the file afresh. Owner-only, and never through a symbolic link.
fn write_recording(dir: &Path, part: &RecordingChunk) -> std::io::Result<()> {
    use std::io::{Seek, SeekFrom, Write};
    use std::os::unix::fs::{DirBuilderExt, OpenOptionsExt};
    match std::fs::DirBuilder::new().mode(0o700).create(dir) {
        Err(e) if e.kind() != std::io::ErrorKind::AlreadyExists => return Err(e),
        _ => {}
    }
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(part.offset == 0)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW)
        .open(dir.join(cdm_recording::file_name(part.id)))?;
    f.seek(SeekFrom::Start(part.offset))?;
    f.write_all(&part.bytes)
}

/// Answers one join request: refused with the reason, or accepted with the host's share.
fn admit(net: &Net, core: &mut BridgeCore, p: PendingJoin, now: Instant, notices: &dyn NoticeSink) {
    let q = p.request.clone();
    let refuse = |p: PendingJoin, why: Refusal| {
        tracing::warn!(daemon = %q.who, "refused a daemon: {why}");
        p.answer(&JoinReply::Refused(why.to_string()));
    };
    let host = match core.which_host(p.slot, &q) {
        Ok(h) => h,
        Err(why) => return refuse(p, why),
    };
    let team = core.team().as_str().to_owned();
    let chan = match net.channel(&down_key(&team, host), &up_key(&team, host)) {
        Ok(c) => ZenohLink::new(c),
        Err(e) => {
            let detail = e.to_string();
            return refuse(p, Refusal::NoLink { host, detail });
        }
    };
    p.answer(&JoinReply::Accepted(Box::new(core.assignment(host))));
    let members = core.joined(host, q.who.clone(), chan, now);
    notices.notice(&HostNotice::Joined {
        host,
        who: q.who,
        members,
    });
}
