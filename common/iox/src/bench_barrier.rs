//! `cdm-bench barrier` (BENCHMARKS.md's baseline): a bare iceoryx2 central barrier with N
//! processes and no math. Per tick the coordinator wakes every process, each reads its 3
//! neighbours' samples, publishes one 128-byte sample and acknowledges; the coordinator waits for
//! all N samples. This is what a naive one-process-per-member runtime pays per tick. It lives in
//! this crate, not in the `cdm-bench` binary, so that only the transport backend names iceoryx2.
//! Prints `barrier: N agents, K ticks in S s (R ticks/s)`. Every wait has a deadline.

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

fn service(run: &str, what: &str) -> Result<ServiceName, String> {
    ServiceName::new(&format!("cdm-bench/{run}/{what}")).map_err(|e| format!("{e:?}"))
}

fn node() -> Result<Node<ipc::Service>, String> {
    NodeBuilder::new()
        .config(&crate::iceoryx2_config())
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| format!("node: {e:?}"))
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
    fn create(run: &str, n: usize) -> Result<Self, String> {
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
                .map_err(|e| format!("state/{id}: {e:?}"))?;
            let sub = st
                .subscriber_builder()
                .buffer_size(2)
                .create()
                .map_err(|e| format!("subscriber {id}: {e:?}"))?;
            states.push((st, sub));
            let w = node
                .service_builder(&service(run, &format!("wake/{id}"))?)
                .event()
                .max_listeners(1)
                .max_notifiers(1)
                .max_nodes(3)
                .create()
                .map_err(|e| format!("wake/{id}: {e:?}"))?;
            let notifier = w
                .notifier_builder()
                .create()
                .map_err(|e| format!("notifier {id}: {e:?}"))?;
            wakes.push((w, notifier));
        }
        let ack = node
            .service_builder(&service(run, "ack")?)
            .event()
            .max_listeners(1)
            .max_notifiers(n)
            .max_nodes(n + 2)
            .create()
            .map_err(|e| format!("ack: {e:?}"))?;
        let listener = ack
            .listener_builder()
            .create()
            .map_err(|e| format!("ack listener: {e:?}"))?;
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
    fn run_ticks(&self, ticks: u64) -> Result<(), String> {
        let n = self.states.len();
        for tick in 1..=ticks {
            for (_, notifier) in &self.wakes {
                notifier.notify().map_err(|e| format!("notify: {e:?}"))?;
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
                    return Err(format!(
                        "tick {tick}: {got} of {n} samples within {DEADLINE:?}"
                    ));
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
fn spawn_members(run: &str, n: usize) -> Result<Vec<Child>, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let mut children: Vec<Child> = Vec::with_capacity(n);
    for id in 0..n {
        let child = Command::new(&exe)
            .args(["barrier-member", "--run", run, "--n", &n.to_string()])
            .args(["--id", &id.to_string()])
            .stdin(Stdio::null())
            .spawn();
        match child {
            Ok(c) => children.push(c),
            Err(e) => {
                stop_all(&mut children);
                return Err(format!("spawn member {id}: {e}"));
            }
        }
    }
    Ok(children)
}

pub fn barrier(n: usize, ticks: u64) -> Result<(), String> {
    if n < 4 {
        return Err("barrier needs --n 4 or more".into());
    }
    let run = format!("b{}", std::process::id());
    // The coordinator holds a subscriber and a notifier per member (~11 descriptors each).
    crate::raise_fd_limit().map_err(|e| e.to_string())?;
    let coordinator = Coordinator::create(&run, n)?;
    let mut children = spawn_members(&run, n)?;
    let started = Instant::now();
    while !coordinator.joined() {
        if started.elapsed() > DEADLINE + Duration::from_millis(50 * n as u64) {
            stop_all(&mut children);
            return Err(format!(
                "members did not join within {:?}",
                started.elapsed()
            ));
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
    println!(
        "barrier: {n} agents, {ticks} ticks in {secs:.3} s ({:.0} ticks/s), start-up {:.2} s",
        ticks as f64 / secs,
        startup.as_secs_f64()
    );
    Ok(())
}

pub fn barrier_member(run: &str, n: usize, id: usize) -> Result<(), String> {
    let node = node()?;
    let open_state = |k: usize| {
        node.service_builder(&service(run, &format!("state/{k}"))?)
            .publish_subscribe::<StateWire>()
            .open()
            .map_err(|e| format!("member {id}: state/{k}: {e:?}"))
    };
    let mine = open_state(id)?;
    let publisher = mine
        .publisher_builder()
        .create()
        .map_err(|e| format!("member {id}: publisher: {e:?}"))?;
    let mut subs = Vec::new();
    for k in neighbours(n, id) {
        let s = open_state(k)?;
        let sub = s
            .subscriber_builder()
            .buffer_size(2)
            .create()
            .map_err(|e| format!("member {id}: subscriber {k}: {e:?}"))?;
        subs.push((s, sub));
    }
    let wake = node
        .service_builder(&service(run, &format!("wake/{id}"))?)
        .event()
        .open()
        .map_err(|e| format!("member {id}: wake: {e:?}"))?;
    let listener = wake
        .listener_builder()
        .create()
        .map_err(|e| format!("member {id}: listener: {e:?}"))?;
    let ack = node
        .service_builder(&service(run, "ack")?)
        .event()
        .open()
        .map_err(|e| format!("member {id}: ack: {e:?}"))?;
    let acker = ack
        .notifier_builder()
        .create()
        .map_err(|e| format!("member {id}: ack notifier: {e:?}"))?;

    let me = u32::try_from(id).map_err(|e| e.to_string())?;
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
            .map_err(|e| format!("member {id}: send: {e:?}"))?;
        acker
            .notify()
            .map_err(|e| format!("member {id}: ack: {e:?}"))?;
    }
}
