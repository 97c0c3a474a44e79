//! `cdm-bench barrier` (BENCHMARKS.md's baseline): a bare iceoryx2 central barrier with N
//! processes and no math. Per tick the coordinator wakes every process, each reads its 3
//! neighbours' samples, publishes one 128-byte sample and acknowledges; the coordinator waits for
//! all N samples. This is what a naive one-process-per-member runtime pays per tick. It lives in
//! this crate, not in the `cdm-bench` binary, so that only the transport backend names iceoryx2.
//! Returns what it measured ([`BarrierRun`]; the binary prints it). Every wait has a deadline.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use cdm_runtime::messages::StateMsg;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use crate::wire::{StateWire, Wire};

/// No wait of the barrier lasts longer than this without progress.
const DEADLINE: Duration = Duration::from_secs(10);

/// Why the barrier benchmark did not run to its end.
#[derive(Debug, thiserror::Error)]
pub enum BarrierError {
    /// Fewer than four members (each reads three others).
    #[error("barrier needs --n 4 or more, not {0}")]
    TooFew(usize),
    /// An iceoryx2 call failed: what it was for, and iceoryx2's error.
    #[error("{what}: {detail}")]
    Ipc { what: String, detail: String },
    /// A member process could not start, or the process could not prepare.
    #[error("{what}: {source}")]
    Os {
        what: String,
        #[source]
        source: std::io::Error,
    },
    /// A wait ran past its deadline.
    #[error("{0}")]
    Deadline(String),
    /// The open-file limit could not be raised.
    #[error(transparent)]
    Transport(#[from] crate::TransportError),
}

/// What one barrier run measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BarrierRun {
    /// Member processes.
    pub n: usize,
    /// Ticks run.
    pub ticks: u64,
    /// Seconds for the ticks.
    pub secs: f64,
    /// Seconds from the first spawn until every member joined.
    pub startup_s: f64,
}

/// An iceoryx2 error, kept as its debug text, for `what`.
fn ipc<E: std::fmt::Debug>(what: impl Into<String>) -> impl FnOnce(E) -> BarrierError {
    let what = what.into();
    move |e| BarrierError::Ipc {
        what,
        detail: format!("{e:?}"),
    }
}

fn service(run: &str, what: &str) -> Result<ServiceName, BarrierError> {
    ServiceName::new(&format!("cdm-bench/{run}/{what}")).map_err(ipc(format!("service {what}")))
}

fn node() -> Result<Node<ipc::Service>, BarrierError> {
    NodeBuilder::new()
        .config(&crate::iceoryx2_config())
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(ipc("node"))
}

/// The three members that member `id` reads (no math, so any three others will do).
fn neighbours(n: usize, id: usize) -> [usize; 3] {
    [(id + 1) % n, (id + 2) % n, (id + 3) % n]
}

/// The barrier's coordinator side: one node with every member's state and wake services, a
/// subscriber and a notifier per member, and the acknowledgement event. Fields drop in order.
struct Coordinator {
    states: Vec<(StateService, Subscriber<ipc::Service, StateWire, ()>)>,
    wakes: Vec<(EventService, Notifier<ipc::Service>)>,
    listener: Listener<ipc::Service>,
    _ack: EventService,
    _node: Node<ipc::Service>,
}

type StateService =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, StateWire, ()>;
type EventService = iceoryx2::service::port_factory::event::PortFactory<ipc::Service>;

impl Coordinator {
    /// Creates the services of `n` members of `run`.
    fn create(run: &str, n: usize) -> Result<Self, BarrierError> {
        let node = node()?;
        let mut states = Vec::with_capacity(n);
        let mut wakes = Vec::with_capacity(n);
        for id in 0..n {
            let st = node
                .service_builder(&service(run, &format!("state/{id}"))?)
                .publish_subscribe::<StateWire>()
                .max_publishers(1)
                .max_subscribers(4)
                .max_nodes(6)
                .subscriber_max_buffer_size(2)
                .history_size(0)
                .enable_safe_overflow(true)
                .create()
                .map_err(ipc(format!("state/{id}")))?;
            let sub = st
                .subscriber_builder()
                .buffer_size(2)
                .create()
                .map_err(ipc(format!("subscriber {id}")))?;
            states.push((st, sub));
            let w = node
                .service_builder(&service(run, &format!("wake/{id}"))?)
                .event()
                .max_listeners(1)
                .max_notifiers(1)
                .max_nodes(3)
                .create()
                .map_err(ipc(format!("wake/{id}")))?;
            let notifier = w
                .notifier_builder()
                .create()
                .map_err(ipc(format!("notifier {id}")))?;
            wakes.push((w, notifier));
        }
        let ack = node
            .service_builder(&service(run, "ack")?)
            .event()
            .max_listeners(1)
            .max_notifiers(n)
            .max_nodes(n + 2)
            .create()
            .map_err(ipc("ack"))?;
        let listener = ack
            .listener_builder()
            .create()
            .map_err(ipc("ack listener"))?;
        Ok(Self {
            states,
            wakes,
            listener,
            _ack: ack,
            _node: node,
        })
    }

    /// True when every member has its listener and its three subscribers.
    fn joined(&self) -> bool {
        let n = self.wakes.len();
        let listeners: usize = self
            .wakes
            .iter()
            .map(|(w, _)| w.dynamic_config().number_of_listeners())
            .sum();
        let subs: usize = self
            .states
            .iter()
            .map(|(s, _)| s.dynamic_config().number_of_subscribers())
            .sum();
        listeners == n && subs == 4 * n
    }

    /// Ticks 1..=ticks: wake every member, wait for all their samples of the tick.
    fn run_ticks(&self, ticks: u64) -> Result<(), BarrierError> {
        let n = self.states.len();
        for tick in 1..=ticks {
            for (_, notifier) in &self.wakes {
                notifier.notify().map_err(ipc("notify"))?;
            }
            let mut got = 0;
            let mut last = Instant::now();
            while got < n {
                for (_, sub) in &self.states {
                    while let Ok(Some(s)) = sub.receive() {
                        if s.0.tick == tick {
                            got += 1;
                            last = Instant::now();
                        }
                    }
                }
                if got == n {
                    break;
                }
                if last.elapsed() > DEADLINE {
                    return Err(BarrierError::Deadline(format!(
                        "tick {tick}: {got} of {n} samples within {DEADLINE:?}"
                    )));
                }
                let _ = self.listener.timed_wait(|_| {}, Duration::from_millis(20));
            }
        }
        Ok(())
    }

    /// Event 1 tells members to leave.
    fn dismiss(&self) {
        for (_, notifier) in &self.wakes {
            let _ = notifier.notify_with_custom_event_id(EventId::new(1));
        }
    }
}

/// Kills and reaps every child.
fn stop_all(children: &mut [Child]) {
    for c in children.iter_mut() {
        let _ = c.kill();
        let _ = c.wait();
    }
}

/// Starts the `n` member processes of `run` (all stopped again if one cannot start).
fn spawn_members(run: &str, n: usize) -> Result<Vec<Child>, BarrierError> {
    let exe = std::env::current_exe().map_err(|source| BarrierError::Os {
        what: "the benchmark's own executable".into(),
        source,
    })?;
    let mut children: Vec<Child> = Vec::with_capacity(n);
    for id in 0..n {
        let child = Command::new(&exe)
            .args(["barrier-member", "--run", run, "--n", &n.to_string()])
            .args(["--id", &id.to_string()])
            .stdin(Stdio::null())
            .spawn();
        match child {
            Ok(c) => children.push(c),
            Err(source) => {
                stop_all(&mut children);
                return Err(BarrierError::Os {
                    what: format!("spawn member {id}"),
                    source,
                });
            }
        }
    }
    Ok(children)
}

/// Runs the barrier with `n` member processes for `ticks` ticks.
pub fn barrier(n: usize, ticks: u64) -> Result<BarrierRun, BarrierError> {
    if n < 4 {
        return Err(BarrierError::TooFew(n));
    }
    let run = format!("b{}", std::process::id());
    // The coordinator holds a subscriber and a notifier per member (~11 descriptors each).
    crate::raise_fd_limit()?;
    let coordinator = Coordinator::create(&run, n)?;
    let mut children = spawn_members(&run, n)?;
    let started = Instant::now();
    while !coordinator.joined() {
        if started.elapsed() > DEADLINE + Duration::from_millis(50 * n as u64) {
            stop_all(&mut children);
            return Err(BarrierError::Deadline(format!(
                "members did not join within {:?}",
                started.elapsed()
            )));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let startup = started.elapsed();

    let start = Instant::now();
    let result = coordinator.run_ticks(ticks);
    let secs = start.elapsed().as_secs_f64();
    coordinator.dismiss();
    let deadline = Instant::now() + Duration::from_secs(5);
    for c in children.iter_mut() {
        while matches!(c.try_wait(), Ok(None)) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    stop_all(&mut children);
    result?;
    Ok(BarrierRun {
        n,
        ticks,
        secs,
        startup_s: startup.as_secs_f64(),
    })
}

/// One member process of [`barrier`]: `id` of `n` in run `run`.
pub fn barrier_member(run: &str, n: usize, id: usize) -> Result<(), BarrierError> {
    let node = node()?;
    let open_state = |k: usize| {
        node.service_builder(&service(run, &format!("state/{k}"))?)
            .publish_subscribe::<StateWire>()
            .open()
            .map_err(ipc(format!("member {id}: state/{k}")))
    };
    let mine = open_state(id)?;
    let publisher = mine
        .publisher_builder()
        .create()
        .map_err(ipc(format!("member {id}: publisher")))?;
    let mut subs = Vec::new();
    for k in neighbours(n, id) {
        let s = open_state(k)?;
        let sub = s
            .subscriber_builder()
            .buffer_size(2)
            .create()
            .map_err(ipc(format!("member {id}: subscriber {k}")))?;
        subs.push((s, sub));
    }
    let wake = node
        .service_builder(&service(run, &format!("wake/{id}"))?)
        .event()
        .open()
        .map_err(ipc(format!("member {id}: wake")))?;
    let listener = wake
        .listener_builder()
        .create()
        .map_err(ipc(format!("member {id}: listener")))?;
    let ack = node
        .service_builder(&service(run, "ack")?)
        .event()
        .open()
        .map_err(ipc(format!("member {id}: ack")))?;
    let acker = ack
        .notifier_builder()
        .create()
        .map_err(ipc(format!("member {id}: ack notifier")))?;

    let me = u32::try_from(id).map_err(ipc(format!("member id {id}")))?;
    let mut tick: u64 = 0;
    let mut sum = 0.0;
    let mut idle = Instant::now();
    loop {
        let mut leave = false;
        let mut woken = 0;
        let r = listener.timed_wait(
            |e| {
                woken += 1;
                leave |= e.id == EventId::new(1);
            },
            Duration::from_millis(100),
        );
        if r.is_err() || leave || idle.elapsed() > DEADLINE {
            return Ok(());
        }
        if woken == 0 {
            continue;
        }
        idle = Instant::now();
        // Read the neighbours' latest samples (the previous tick), publish this tick's.
        for (_, sub) in &subs {
            while let Ok(Some(s)) = sub.receive() {
                sum += s.0.state[0];
            }
        }
        tick += 1;
        let mut msg = StateMsg::ok(tick, 0, me, [0.0; 12]);
        msg.state[0] = sum * 0.0 + tick as f64;
        publisher
            .send_copy(Wire(msg))
            .map_err(ipc(format!("member {id}: send")))?;
        acker.notify().map_err(ipc(format!("member {id}: ack")))?;
    }
}
