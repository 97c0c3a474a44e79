//! The server and its publisher: the launch loop (or a replay) offers each audited tick; at most
//! `--foxglove-hz` of them a second are copied into a bounded queue, and a thread of their own
//! turns them into the topics' messages and logs them to the SDK's server, which keeps a bounded
//! backlog per client and drops the oldest for a slow one. The loop never waits: a full queue
//! drops the tick and counts it.

use std::net::SocketAddr;
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use foxglove::schemas::{log, FrameTransforms, Log, PoseInFrame, SceneUpdate};
use foxglove::websocket::Capability;
use foxglove::WebSocketServerHandle;
use foxglove::{Channel, ChannelBuilder, Context, RawChannel, Schema, WebSocketServer};

use cdm_math::Vec3;
use cdm_model::outcome::Verdict;
use cdm_records::audit::SafetyNumbers;
use cdm_ros2::pace::Pacer;
use cdm_rosbag::{Limits, Team, Tick};
use cdm_scenario::Scenario;

use crate::scene::{frame, stamp};
use crate::{FoxgloveError, FoxgloveOptions, FoxgloveSummary};

/// Ticks waiting for the publishing thread: a few, old ticks are worth nothing.
const QUEUE: usize = 4;

/// Messages the server keeps per client before it drops the oldest (a slow client's backlog):
/// about two seconds of a 40-member team at 30 Hz.
const BACKLOG: usize = 4096;

/// How long `finish` waits for the thread to publish what is queued, and the server to close.
const FINISH_WITHIN: Duration = Duration::from_secs(3);

/// The server's name in the protocol's `serverInfo`.
const SERVER_NAME: &str = "cdm";

/// One tick as the thread needs it (member order).
struct Snapshot {
    tick: u64,
    t_s: f64,
    pos: Vec<Vec3>,
    ht: Vec<Vec3>,
    alive: Vec<bool>,
    verdict: Verdict,
    /// The run is over: the verdict is final.
    last: bool,
}

/// The topics of a team, in the order they are advertised.
struct Topics {
    /// The SDK's context: its channels close when it is dropped, so the topics keep it.
    _ctx: Arc<Context>,
    poses: Vec<Channel<PoseInFrame>>,
    tf: Channel<FrameTransforms>,
    formation: Channel<SceneUpdate>,
    audit: Arc<RawChannel>,
    verdict: Arc<RawChannel>,
    events: Channel<Log>,
}

impl Topics {
    fn advertise(ctx: &Arc<Context>, team: &Team) -> Result<Self, FoxgloveError> {
        let names = team.topics();
        let name = |k: usize| names[k].1.clone();
        let n = team.ids().len();
        let json = |topic: &str, schema: &str, what: &'static str| {
            ChannelBuilder::new(topic)
                .context(ctx)
                .message_encoding("json")
                .schema(Schema::new(schema, "jsonschema", what.as_bytes()))
                .build_raw()
                .map_err(|e| FoxgloveError::Channel {
                    topic: topic.to_owned(),
                    reason: e.to_string(),
                })
        };
        Ok(Topics {
            _ctx: ctx.clone(),
            poses: (0..n)
                .map(|k| ChannelBuilder::new(name(k)).context(ctx).build())
                .collect(),
            tf: ChannelBuilder::new(name(n)).context(ctx).build(),
            formation: ChannelBuilder::new(name(n + 1)).context(ctx).build(),
            audit: json(&name(n + 2), "cdm.Margins", MARGINS_SCHEMA)?,
            verdict: json("/cdm/verdict", "cdm.Verdict", VERDICT_SCHEMA)?,
            events: ChannelBuilder::new("/cdm/events").context(ctx).build(),
        })
    }
}

/// The bag's `/cdm/audit` object (cdm-rosbag `Team::margins`), for Foxglove's Plot panel.
const MARGINS_SCHEMA: &str = r#"{"type":"object","properties":{"tick":{"type":"integer"},"t_s":{"type":"number"},"separation_m":{"type":"number"},"separation_margin_m":{"type":"number"},"deviation_m":{"type":["number","null"]},"deviation_margin_m":{"type":["number","null"]},"boundary_margin_m":{"type":["number","null"]},"lambda1":{"type":"number"},"lambda1_margin":{"type":"number"}}}"#;

/// `/cdm/verdict`: the audit's verdict so far (SAFE, UNSAFE or FAULT) and whether it is final.
const VERDICT_SCHEMA: &str = r#"{"type":"object","properties":{"tick":{"type":"integer"},"t_s":{"type":"number"},"verdict":{"type":"string","enum":["SAFE","UNSAFE","FAULT"]},"final":{"type":"boolean"}}}"#;

/// The Foxglove server of a launch or a replay.
pub struct FoxgloveLive {
    addr: SocketAddr,
    pacer: Pacer,
    last_tick: u64,
    tx: Option<SyncSender<Snapshot>>,
    worker: Option<JoinHandle<u64>>,
    server: Option<Arc<WebSocketServerHandle>>,
    dropped: u64,
    /// The last tick offered and its time (the final verdict's).
    offered: (u64, f64),
}

impl FoxgloveLive {
    /// Binds the server and advertises the topics of `scenario`, before the team starts: an
    /// address in use stops nothing (exit 2), and a client may connect while the team gathers.
    pub fn start(o: &FoxgloveOptions, scenario: &Scenario) -> Result<Self, FoxgloveError> {
        let team = Team::new(scenario, Limits::from(&SafetyNumbers::of(scenario)));
        let ctx = Context::new();
        let topics = Topics::advertise(&ctx, &team)?;
        let server = WebSocketServer::new()
            .name(SERVER_NAME)
            .bind(o.addr.ip().to_string(), o.addr.port())
            .capabilities([Capability::Time])
            .message_backlog_size(BACKLOG)
            .context(&ctx)
            .start_blocking()
            .map_err(|e| FoxgloveError::Bind {
                addr: o.addr,
                source: Box::new(e),
            })?;
        let addr = SocketAddr::new(o.addr.ip(), server.port());
        tracing::info!(%addr, hz = o.hz, "Foxglove server");
        let server = Arc::new(server);
        let (tx, rx) = sync_channel(QUEUE);
        let clock = server.clone();
        let worker = std::thread::Builder::new()
            .name("foxglove".into())
            .spawn(move || publish_all(&team, &topics, &clock, rx))
            .map_err(FoxgloveError::Thread)?;
        Ok(FoxgloveLive {
            addr,
            pacer: Pacer::new(o.hz),
            last_tick: scenario.last_tick(),
            tx: Some(tx),
            worker: Some(worker),
            server: Some(server),
            dropped: 0,
            offered: (0, 0.0),
        })
    }

    /// Where the server listens (its port when `--foxglove` asked for port 0).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// How many clients are connected.
    pub fn clients(&self) -> usize {
        self.server.as_ref().map_or(0, |s| s.client_count())
    }

    /// One audited tick (positions and desired positions in member order; `flying(k)` false
    /// for a member lost by then): published if the rate lets it through and the queue has
    /// room. Never waits.
    pub fn tick(
        &mut self,
        tick: u64,
        t_s: f64,
        (pos, ht): (&[Vec3], &[Vec3]),
        flying: impl Fn(usize) -> bool,
        verdict: Verdict,
    ) {
        self.offered = (tick, t_s);
        if !self.pacer.due(Instant::now(), tick == self.last_tick) {
            return;
        }
        self.offer(Snapshot {
            tick,
            t_s,
            pos: pos.to_vec(),
            ht: ht.to_vec(),
            alive: (0..pos.len()).map(flying).collect(),
            verdict,
            last: false,
        });
    }

    fn offer(&mut self, s: Snapshot) {
        let Some(tx) = &self.tx else {
            return;
        };
        match tx.try_send(s) {
            Ok(()) => {}
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => self.dropped += 1,
        }
    }

    /// Publishes the final verdict, lets the thread publish what is queued and closes the
    /// server (waiting at most a few seconds), and says what was published.
    pub fn finish(mut self, verdict: Verdict) -> FoxgloveSummary {
        if let Some(tx) = self.tx.take() {
            let last = Snapshot {
                tick: self.offered.0,
                t_s: self.offered.1,
                pos: Vec::new(),
                ht: Vec::new(),
                alive: Vec::new(),
                verdict,
                last: true,
            };
            // The final verdict waits for room (bounded): it is the one message a viewer must see.
            let until = Instant::now() + FINISH_WITHIN;
            let mut pending = Some(last);
            while let Some(s) = pending.take() {
                match tx.try_send(s) {
                    Err(TrySendError::Full(s)) if Instant::now() < until => {
                        pending = Some(s);
                        std::thread::sleep(Duration::from_millis(2));
                    }
                    _ => {}
                }
            }
        }
        let until = Instant::now() + FINISH_WITHIN;
        let worker = self.worker.take();
        while worker.as_ref().is_some_and(|w| !w.is_finished()) && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(5));
        }
        let (ticks, unfinished) = match worker {
            Some(w) if w.is_finished() => (w.join().unwrap_or_default(), false),
            _ => (0, true),
        };
        if let Some(server) = self.server.take() {
            stop(server);
        }
        FoxgloveSummary {
            addr: self.addr,
            ticks,
            dropped: self.dropped,
            unfinished,
        }
    }
}

impl Drop for FoxgloveLive {
    fn drop(&mut self) {
        drop(self.tx.take());
        if let Some(server) = self.server.take() {
            stop(server);
        }
    }
}

/// Stops the server (once the thread has let go of it; otherwise it ends with the process): its
/// clients get what was queued for them within a bounded wait.
fn stop(server: Arc<WebSocketServerHandle>) {
    let Ok(server) = Arc::try_unwrap(server) else {
        return;
    };
    let shutdown = server.stop();
    let waiter = std::thread::Builder::new()
        .name("foxglove-stop".into())
        .spawn(move || shutdown.wait_blocking());
    if let Ok(w) = waiter {
        let until = Instant::now() + FINISH_WITHIN;
        while !w.is_finished() && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

/// The thread: every queued tick to its messages, until the launch lets go; returns how many
/// ticks went out.
fn publish_all(
    team: &Team,
    topics: &Topics,
    server: &WebSocketServerHandle,
    rx: Receiver<Snapshot>,
) -> u64 {
    let mut ticks = 0;
    let mut was_alive: Option<Vec<bool>> = None;
    for s in rx {
        let time_ns = cdm_rosbag::tick::time_ns(s.t_s);
        if !s.last {
            let tick = Tick {
                tick: s.tick,
                t_s: s.t_s,
                pos: &s.pos,
                ht: &s.ht,
                alive: &s.alive,
            };
            // The protocol's `time` capability: the clients' clock is simulation time.
            server.broadcast_time(time_ns);
            let f = frame(team, &tick);
            for (k, p) in &f.poses {
                topics.poses[*k].log_with_time(p, time_ns);
            }
            topics.tf.log_with_time(&f.tf, time_ns);
            topics.formation.log_with_time(&f.formation, time_ns);
            let margins = team.margins(&tick).to_string();
            topics.audit.log_with_meta(
                margins.as_bytes(),
                foxglove::PartialMetadata::with_log_time(time_ns),
            );
            for (k, lost) in losses(was_alive.as_deref(), &s.alive) {
                if lost {
                    topics.events.log_with_time(
                        &Log {
                            timestamp: Some(stamp(time_ns)),
                            level: log::Level::Warning as i32,
                            message: format!(
                                "member {} lost by tick {} (t = {:.2} s)",
                                team.ids()[k],
                                s.tick,
                                s.t_s
                            ),
                            name: SERVER_NAME.to_owned(),
                            ..Log::default()
                        },
                        time_ns,
                    );
                }
            }
            was_alive = Some(s.alive.clone());
            ticks += 1;
        }
        let verdict = serde_json::json!({
            "tick": s.tick,
            "t_s": s.t_s,
            "verdict": s.verdict,
            "final": s.last,
        })
        .to_string();
        topics.verdict.log_with_meta(
            verdict.as_bytes(),
            foxglove::PartialMetadata::with_log_time(time_ns),
        );
    }
    ticks
}

/// The members whose flying state changed since the previous published tick: (index, lost).
fn losses(before: Option<&[bool]>, now: &[bool]) -> Vec<(usize, bool)> {
    (0..now.len())
        .filter(|&k| before.map_or(!now[k], |b| b.get(k) != Some(&now[k])))
        .map(|k| (k, !now[k]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_loss_is_reported_once_when_it_is_first_seen() {
        assert_eq!(losses(None, &[true, true]), vec![]);
        assert_eq!(losses(None, &[true, false]), vec![(1, true)]);
        assert_eq!(losses(Some(&[true, true]), &[true, false]), vec![(1, true)]);
        assert_eq!(losses(Some(&[true, false]), &[true, false]), vec![]);
    }
}
