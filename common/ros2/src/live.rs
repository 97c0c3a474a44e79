//! The live publisher: the launch loop offers each audited tick; at most `--ros2-hz` of them a
//! second are copied into a bounded queue, and a thread of their own turns them into the bag's
//! messages (cdm-rosbag `Team::messages`, the same bytes) and publishes them. The loop never
//! waits: a full queue drops the tick and counts it.

use std::sync::mpsc::{channel, sync_channel, Receiver, Sender, SyncSender, TrySendError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use cdm_math::Vec3;
use cdm_records::audit::{CommandSummary, SafetyNumbers};
use cdm_rosbag::{Limits, Team, Tick};
use cdm_scenario::Scenario;

use crate::pace::Pacer;
use crate::{Backend, Env, Publish, Ros2Error, Ros2Options};

/// Ticks waiting for the publishing thread. A few: at 30 Hz the thread is far ahead of the
/// queue unless the ROS side stalls it, and then old ticks are worth nothing.
const QUEUE: usize = 4;

/// How long `finish` waits for the thread to publish what is queued and let go of its
/// middleware (a DDS participant says goodbye, zenoh undeclares the tokens).
const FINISH_WITHIN: Duration = Duration::from_secs(3);

/// One tick as the thread needs it (member order).
struct Snapshot {
    tick: u64,
    t_s: f64,
    pos: Vec<Vec3>,
    ht: Vec<Vec3>,
    alive: Vec<bool>,
}

/// What the thread did.
#[derive(Debug, Default)]
struct Published {
    ticks: u64,
    failed: u64,
    first_error: Option<String>,
}

/// What the live topics did over a run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Summary {
    pub backend: Backend,
    /// Ticks whose messages went out.
    pub ticks: u64,
    /// Ticks the rate let through but the queue had no room for.
    pub dropped: u64,
    /// Messages the middleware refused, and the first reason.
    pub failed: u64,
    pub first_error: Option<String>,
    /// The thread was still publishing when `finish` stopped waiting.
    pub unfinished: bool,
}

/// The live topics of a launch.
pub struct Live {
    backend: Backend,
    pacer: Pacer,
    last_tick: u64,
    tx: Option<SyncSender<Snapshot>>,
    /// Commands decided in flight, for the thread (never dropped: a few per flight).
    commands: Option<Sender<CommandSummary>>,
    worker: Option<JoinHandle<Published>>,
    dropped: u64,
}

impl Live {
    /// Opens the middleware (`ROS_DOMAIN_ID` and the other variables a ROS 2 node reads) and
    /// declares a publisher per topic of `scenario`'s bag, before the team starts: a bad
    /// environment stops nothing, and subscribers may discover us while the team gathers.
    pub fn start(o: &Ros2Options, scenario: &Scenario) -> Result<Self, Ros2Error> {
        Self::start_commanded(o, scenario, Vec::new())
    }

    /// [`Live::start`] for a team that takes commands: each command (the run's, and those
    /// given in flight through [`Live::command`]) goes out on `/cdm/commands` with the first
    /// published tick at or after its switch (as the bag carries it); the topic exists from
    /// the start.
    pub fn start_commanded(
        o: &Ros2Options,
        scenario: &Scenario,
        commands: Vec<CommandSummary>,
    ) -> Result<Self, Ros2Error> {
        let env = Env::of_process()?;
        let team =
            Team::new(scenario, Limits::from(&SafetyNumbers::of(scenario))).with_commands(commands);
        let team = team.commandable();
        let out = open(o.backend, &env, &team)?;
        tracing::info!(backend = %o.backend, domain = env.domain, hz = o.hz, "live ROS 2 topics");
        Live::over(out, o, scenario, team)
    }

    /// The publishing thread over `out` (the middleware's publishers, or a test's).
    fn over(
        out: Box<dyn Publish + Send>,
        o: &Ros2Options,
        scenario: &Scenario,
        team: Team,
    ) -> Result<Self, Ros2Error> {
        let (tx, rx) = sync_channel(QUEUE);
        let (commands, decided) = channel();
        let worker = std::thread::Builder::new()
            .name("ros2".into())
            .spawn(move || publish_all(team, out, rx, decided))
            .map_err(Ros2Error::Thread)?;
        Ok(Live {
            backend: o.backend,
            pacer: Pacer::new(o.hz),
            last_tick: scenario.last_tick(),
            tx: Some(tx),
            commands: Some(commands),
            worker: Some(worker),
            dropped: 0,
        })
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
    ) {
        let Some(tx) = &self.tx else {
            return;
        };
        if !self.pacer.due(Instant::now(), tick == self.last_tick) {
            return;
        }
        let snapshot = Snapshot {
            tick,
            t_s,
            pos: pos.to_vec(),
            ht: ht.to_vec(),
            alive: (0..pos.len()).map(flying).collect(),
        };
        match tx.try_send(snapshot) {
            Ok(()) => {}
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => self.dropped += 1,
        }
    }

    /// A command decided in flight (`orchestrator command`): it goes out on `/cdm/commands`
    /// with the first published tick at or after its switch. Never waits.
    pub fn command(&mut self, c: &CommandSummary) {
        if let Some(tx) = &self.commands {
            let _ = tx.send(c.clone());
        }
    }

    /// Lets the thread publish what is queued and close the middleware (waiting at most a few
    /// seconds), and says what was published.
    pub fn finish(mut self) -> Summary {
        drop(self.tx.take());
        drop(self.commands.take());
        let until = Instant::now() + FINISH_WITHIN;
        let worker = self.worker.take();
        while worker.as_ref().is_some_and(|w| !w.is_finished()) && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(5));
        }
        let (done, unfinished) = match worker {
            Some(w) if w.is_finished() => (w.join().unwrap_or_default(), false),
            _ => (Published::default(), true),
        };
        Summary {
            backend: self.backend,
            ticks: done.ticks,
            dropped: self.dropped,
            failed: done.failed,
            first_error: done.first_error,
            unfinished,
        }
    }
}

/// The publishers of `backend`, one per topic of `team`.
fn open(backend: Backend, env: &Env, team: &Team) -> Result<Box<dyn Publish + Send>, Ros2Error> {
    let topics = team.topics();
    match backend {
        #[cfg(feature = "dds")]
        Backend::Dds => Ok(Box::new(crate::dds::DdsOut::open(env, &topics)?)),
        #[cfg(feature = "zenoh")]
        Backend::Zenoh => Ok(Box::new(crate::zenoh::ZenohOut::open(env, &topics)?)),
        #[allow(unreachable_patterns)]
        b => {
            let _ = (env, topics);
            Err(Ros2Error::NotBuilt(b))
        }
    }
}

/// The thread: every queued tick to its messages, each to its topic, until the launch lets go.
fn publish_all(
    mut team: Team,
    mut out: Box<dyn Publish + Send>,
    rx: Receiver<Snapshot>,
    decided: Receiver<CommandSummary>,
) -> Published {
    let members = team.ids().len();
    let mut done = Published::default();
    let mut messages = Vec::new();
    let mut shown = None;
    for s in rx {
        messages.clear();
        let tick = Tick {
            tick: s.tick,
            t_s: s.t_s,
            pos: &s.pos,
            ht: &s.ht,
            alive: &s.alive,
        };
        team.messages(&tick, &mut messages);
        // A command is decided before any tick at or after its switch is audited.
        for c in decided.try_iter() {
            team.add_command(c);
        }
        team.command_messages(shown, &tick, &mut messages);
        shown = Some(s.tick);
        for m in &messages {
            if let Err(e) = out.publish(m.topic.index(members), &m.data) {
                done.failed += 1;
                if done.first_error.is_none() {
                    tracing::warn!(tick = s.tick, "ROS 2: {e}");
                    done.first_error = Some(e.to_string());
                }
            }
        }
        done.ticks += 1;
    }
    done
}

#[cfg(test)]
mod tests {
    use std::sync::mpsc::{channel, Receiver, Sender};
    use std::sync::{Arc, Mutex};

    use cdm_rosbag::Message;

    use super::*;

    /// What a test's publisher saw: (topic index, CDR bytes) in order.
    type Seen = Arc<Mutex<Vec<(usize, Vec<u8>)>>>;

    /// Records what is published; waits for a go-ahead first when given one.
    struct Recorder {
        seen: Seen,
        gate: Option<Receiver<()>>,
    }

    impl Publish for Recorder {
        fn publish(&mut self, index: usize, cdr: &[u8]) -> Result<(), crate::PublishError> {
            if let Some(gate) = &self.gate {
                // Bounded: a test that never opens the gate fails instead of hanging.
                let _ = gate.recv_timeout(Duration::from_secs(10));
            }
            self.seen.lock().unwrap().push((index, cdr.to_vec()));
            Ok(())
        }
    }

    fn live(gate: Option<Receiver<()>>) -> (Scenario, Live, Seen) {
        let s = Scenario::generated(6).unwrap();
        let team = Team::new(&s, Limits::from(&SafetyNumbers::of(&s)));
        let (live, seen) = recorded(&s, team, gate, 30.0);
        (s, live, seen)
    }

    /// The live topics of `team` at `hz`, into a recorder (held at `gate` when given).
    fn recorded(s: &Scenario, team: Team, gate: Option<Receiver<()>>, hz: f64) -> (Live, Seen) {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let out = Box::new(Recorder {
            seen: seen.clone(),
            gate,
        });
        let o = Ros2Options {
            backend: Backend::Dds,
            hz,
        };
        (Live::over(out, &o, s, team).unwrap(), seen)
    }

    #[test]
    fn a_tick_goes_out_as_the_bags_messages_on_their_topics() {
        let (s, mut live, seen) = live(None);
        let n = s.formation.members.len();
        let pos: Vec<Vec3> = (0..n).map(|k| Vec3::new(k as f64, 1.0, 2.0)).collect();
        live.tick(7, 0.07, (&pos, &pos), |k| k != 2);
        let summary = live.finish();
        assert_eq!((summary.ticks, summary.dropped, summary.failed), (1, 0, 0));
        let team = Team::new(&s, Limits::from(&SafetyNumbers::of(&s)));
        let alive: Vec<bool> = (0..n).map(|k| k != 2).collect();
        let tick = Tick {
            tick: 7,
            t_s: 0.07,
            pos: &pos,
            ht: &pos,
            alive: &alive,
        };
        let mut want: Vec<Message> = Vec::new();
        team.messages(&tick, &mut want);
        let want: Vec<(usize, Vec<u8>)> = want
            .into_iter()
            .map(|m| (m.topic.index(n), m.data))
            .collect();
        assert_eq!(*seen.lock().unwrap(), want);
    }

    /// A command goes out once on `/cdm/commands`, with the first published tick at or after
    /// its switch, even when the rate let its own tick pass unpublished.
    #[test]
    fn a_command_goes_out_once_with_the_first_tick_after_its_switch() {
        let s = Scenario::generated(6).unwrap();
        let goto = CommandSummary {
            command: "goto".into(),
            arrived_s: 0.05,
            switch_tick: 5,
            verdict: None,
            accepted: false,
            why: Some("too quick".into()),
        };
        let team = Team::new(&s, Limits::from(&SafetyNumbers::of(&s))).with_commands(vec![goto]);
        let commands = team.topics().len() - 1;
        assert_eq!(team.topics()[commands].1, "/cdm/commands");
        let (mut live, seen) = recorded(&s, team, None, 30.0);
        let n = s.formation.members.len();
        let pos = vec![Vec3::zeros(); n];
        // At 30 Hz of wall time the first tick goes out, the next two (the switch's among them)
        // are dropped by the rate, and the plan's last is always let through.
        for k in [0, 3, 5, s.last_tick()] {
            live.tick(k, k as f64 * 0.01, (&pos, &pos), |_| true);
        }
        assert!(live.finish().ticks >= 2);
        let seen = seen.lock().unwrap();
        let on_commands: Vec<&Vec<u8>> = (seen.iter())
            .filter(|(i, _)| *i == commands)
            .map(|(_, b)| b)
            .collect();
        assert_eq!(on_commands.len(), 1);
        let text = String::from_utf8_lossy(on_commands[0]);
        assert!(
            text.contains(r#""tick":5"#) && text.contains("too quick"),
            "{text}"
        );
    }

    /// A command decided in flight goes out like one known from the start: once, with the
    /// first published tick at or after its switch; the topic exists before it comes.
    #[test]
    fn a_command_given_in_flight_goes_out_once_after_its_switch() {
        let s = Scenario::generated(6).unwrap();
        let team = Team::new(&s, Limits::from(&SafetyNumbers::of(&s))).commandable();
        let commands = team.topics().len() - 1;
        assert_eq!(team.topics()[commands].1, "/cdm/commands");
        let (mut live, seen) = recorded(&s, team, None, 1000.0);
        let n = s.formation.members.len();
        let pos = vec![Vec3::zeros(); n];
        live.tick(0, 0.0, (&pos, &pos), |_| true);
        live.command(&CommandSummary {
            command: "hold".into(),
            arrived_s: 0.01,
            switch_tick: 4,
            verdict: None,
            accepted: true,
            why: None,
        });
        for k in [2, 4, 6] {
            std::thread::sleep(Duration::from_millis(2)); // past the rate's period
            live.tick(k, k as f64 * 0.01, (&pos, &pos), |_| true);
        }
        assert_eq!(live.finish().ticks, 4);
        let seen = seen.lock().unwrap();
        let on_commands: Vec<String> = (seen.iter())
            .filter(|(i, _)| *i == commands)
            .map(|(_, b)| String::from_utf8_lossy(b).into_owned())
            .collect();
        assert_eq!(on_commands.len(), 1, "{on_commands:?}");
        assert!(
            on_commands[0].contains(r#""tick":4"#) && on_commands[0].contains("hold"),
            "{on_commands:?}"
        );
    }

    #[test]
    fn a_stalled_ros_side_drops_ticks_and_never_holds_the_loop() {
        let (gate_tx, gate_rx): (Sender<()>, Receiver<()>) = channel();
        let (s, mut live, seen) = live(Some(gate_rx));
        let n = s.formation.members.len();
        let pos = vec![Vec3::zeros(); n];
        // The plan's last tick is always let through by the rate: ten of them in a row.
        for _ in 0..10 {
            live.tick(s.last_tick(), 1.0, (&pos, &pos), |_| true);
        }
        // The thread holds one tick and the queue four; the others were dropped, not waited for.
        let dropped = live.dropped;
        assert!((5..=6).contains(&dropped), "{dropped} dropped");
        for _ in 0..1000 {
            let _ = gate_tx.send(());
        }
        let summary = live.finish();
        assert_eq!(summary.ticks + summary.dropped, 10);
        assert_eq!(
            seen.lock().unwrap().len() as u64,
            summary.ticks * (n as u64 + 3)
        );
    }
}
