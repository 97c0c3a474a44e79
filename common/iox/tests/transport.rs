//! Transport over real iceoryx2 shared memory. Every test uses its own team name (`t<pid>_<n>`),
//! a watchdog deadline, and cleans up after itself.
//!
//! Tests that check "nothing of the team is left" hold an exclusive lock so no other test of
//! this binary creates iceoryx2 files at the same time; the rest share it.
//!
//! How to run (the throughput line is printed, never asserted):
//! `cargo test --release -p cdm-iox --test transport -- --nocapture`

use cdm_iox::ids::{id_pid, id_seconds, ids_in, monotonic_s};
use cdm_test_support::Watchdog;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};
use std::thread;
use std::time::{Duration, Instant};

use cdm_iox::{
    remove_dead_nodes, MemberPorts, OrchestratorPorts, TeamLayout, TeamName, TeamProcess,
    TransportError, STATES_PER_SAMPLE,
};
use cdm_runtime::messages::{ClockCommand, ClockMsg, StateMsg, StopReason};
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;

const HASH: u64 = 0x5eed;
const POLL: Duration = Duration::from_millis(50);
/// Set in a child process spawned by `stale_resources_of_a_killed_team_are_removed`.
const CHILD_ENV: &str = "CDM_TRANSPORT_TEST_CHILD";

static FILES: RwLock<()> = RwLock::new(());

fn shared_files() -> RwLockReadGuard<'static, ()> {
    FILES.read().unwrap_or_else(|e| e.into_inner())
}

fn exclusive_files() -> RwLockWriteGuard<'static, ()> {
    FILES.write().unwrap_or_else(|e| e.into_inner())
}

fn team(n: u32) -> TeamName {
    TeamName::new(&format!("t{}_{n}", std::process::id())).unwrap()
}

fn layout(ids: &[u32], edges: &[(u32, u32)], window: u32) -> TeamLayout {
    // edge (from, to): `to` reads `from`.
    let mut ins: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for &(from, to) in edges {
        ins.entry(to).or_default().push(from);
    }
    TeamLayout::new(ids.to_vec(), ins, window).unwrap()
}

fn wait_ready(orch: &OrchestratorPorts, deadline: Duration) {
    let start = Instant::now();
    loop {
        let r = orch.readiness();
        if r.is_complete() {
            return;
        }
        assert!(
            start.elapsed() < deadline,
            "team not ready, waiting for {:?}: {r:?}",
            r.waiting_for()
        );
        thread::sleep(Duration::from_millis(2));
    }
}

/// An agent thread of test 1: waits for the grant, publishes its state at that tick, collects
/// its neighbours' states (id, tick) until it has one per in-neighbour and the stop arrived.
fn chain_member(
    team: TeamName,
    id: u32,
    ins: Vec<u32>,
    outs: Vec<u32>,
) -> Result<Vec<(u32, u64)>, TransportError> {
    let mut m = MemberPorts::open(&team, id, 0, &ins, &outs)?;
    let mut got = vec![];
    let mut published = false;
    let mut stopped = false;
    while !(stopped && got.len() >= ins.len()) {
        if let Some(c) = m.latest_clock()? {
            match c.command() {
                ClockCommand::Run if !published => {
                    m.publish(StateMsg::ok(c.grant_tick, HASH, id, [f64::from(id); 12]))?;
                    published = true;
                }
                ClockCommand::Run | ClockCommand::Realtime { .. } | ClockCommand::Arm => {}
                ClockCommand::Stop(_) => stopped = true,
            }
        }
        m.receive_neighbors(|s| got.push((s.id, s.tick)))?;
        m.wait(POLL)?;
    }
    m.receive_neighbors(|s| got.push((s.id, s.tick)))?;
    got.sort_unstable();
    Ok(got)
}

#[test]
fn chain_members_receive_exactly_their_in_neighbors() {
    let _files = shared_files();
    let _dog = Watchdog::new("chain", Duration::from_secs(60));
    let team = team(1);
    // 0 -> 1 -> 2: agent 1 reads 0, agent 2 reads 1.
    let lay = layout(&[0, 1, 2], &[(0, 1), (1, 2)], 2);
    let mut orch = OrchestratorPorts::create(&team, &lay).unwrap();
    assert_eq!(orch.stale_nodes_removed(), 0);
    assert_eq!(orch.readiness().waiting_for(), vec![0, 1, 2]);

    let members: Vec<_> = lay
        .ids()
        .iter()
        .map(|&id| {
            let (t, ins, outs) = (
                team.clone(),
                lay.in_neighbors(id).to_vec(),
                lay.out_neighbors(id).to_vec(),
            );
            thread::spawn(move || chain_member(t, id, ins, outs))
        })
        .collect();
    wait_ready(&orch, Duration::from_secs(20));

    let node = |who| team.node_name(who);
    let orch_node = node(TeamProcess::Orchestrator);
    assert_eq!(
        orch.subscriber_nodes(0).unwrap(),
        vec![node(TeamProcess::Agent(1)), orch_node.clone()]
    );
    assert_eq!(
        orch.subscriber_nodes(1).unwrap(),
        vec![node(TeamProcess::Agent(2)), orch_node.clone()]
    );
    assert_eq!(orch.subscriber_nodes(2).unwrap(), vec![orch_node]);
    assert!(orch.subscriber_nodes(7).unwrap().is_empty());

    assert_eq!(orch.publish_clock(ClockMsg::run(0, HASH)).unwrap(), 3);
    let mut states = vec![];
    let start = Instant::now();
    while states.len() < 3 {
        orch.receive_states(|s| states.push(s)).unwrap();
        orch.wait(POLL).unwrap();
        assert!(start.elapsed() < Duration::from_secs(20), "got {states:?}");
    }
    orch.publish_clock(ClockMsg::stop(0, HASH, StopReason::Finished))
        .unwrap();
    // Arrival order across publishers is not defined: compare by id.
    states.sort_by_key(|s| s.id);
    let ids: Vec<u32> = states.iter().map(|s| s.id).collect();
    assert_eq!(ids, vec![0, 1, 2]);
    assert!(states
        .iter()
        .all(|s| s.tick == 0 && s.scenario_hash == HASH));
    assert_eq!(states[2].state, [2.0; 12]);

    let got: Vec<_> = members
        .into_iter()
        .map(|h| h.join().unwrap().unwrap())
        .collect();
    assert_eq!(got, vec![vec![], vec![(0, 0)], vec![(1, 0)]]);
    orch.shutdown().unwrap();
}

/// Relayed wake-ups (`TeamLayout::with_relayed_wakes`): the orchestrator wakes only the chain's
/// root (0) after a clock message, holds no port on the other wake events once the team flies
/// (only 0 notifies 1's, only 1 notifies 2's), and after a loss notice wakes the lost member's
/// reader itself.
#[test]
fn relayed_wakes_reach_the_roots_and_the_readers_of_a_loss() {
    use cdm_runtime::messages::LossNotice;
    let _files = shared_files();
    let _dog = Watchdog::new("relayed", Duration::from_secs(60));
    let team = team(8);
    let lay = layout(&[0, 1, 2], &[(0, 1), (1, 2)], 2).with_relayed_wakes();
    assert_eq!(lay.wake_roots(), vec![0]);
    let mut orch = OrchestratorPorts::create(&team, &lay).unwrap();
    let members: Vec<MemberPorts> = lay
        .ids()
        .iter()
        .map(|&id| {
            let (ins, outs) = (lay.in_neighbors(id), lay.out_neighbors(id));
            MemberPorts::open(&team, id, 0, ins, outs).unwrap()
        })
        .collect();
    wait_ready(&orch, Duration::from_secs(20));
    assert_eq!(orch.publish_clock(ClockMsg::run(0, HASH)).unwrap(), 1);
    let node = |id| team.node_name(TeamProcess::Agent(id));
    let orch_node = team.node_name(TeamProcess::Orchestrator);
    assert_eq!(orch.notifier_nodes(0).unwrap(), vec![orch_node.clone()]);
    assert_eq!(orch.notifier_nodes(1).unwrap(), vec![node(0)]);
    assert_eq!(orch.notifier_nodes(2).unwrap(), vec![node(1)]);
    let notice = LossNotice {
        seq: 1,
        id: 1,
        tick: 1,
        linked: 0,
    };
    let lost = ClockMsg::run(1, HASH).with_loss(Some(notice));
    assert_eq!(orch.publish_clock(lost).unwrap(), 2);
    assert_eq!(orch.notifier_nodes(2).unwrap(), vec![node(1), orch_node]);
    assert!(members.iter().all(|m| m.orchestrator_alive()));
    drop(members);
}

/// The ticks of the states that arrived since the last call: at the reader, at the orchestrator.
fn ticks_received(reader: &mut MemberPorts, orch: &mut OrchestratorPorts) -> (Vec<u64>, Vec<u64>) {
    let (mut r, mut o) = (vec![], vec![]);
    reader.receive_neighbors(|s| r.push(s.tick)).unwrap();
    orch.receive_states(|s| o.push(s.tick)).unwrap();
    (r, o)
}

#[test]
fn quiet_states_travel_in_batches_in_order_and_all_arrive_by_the_wake_up() {
    let _files = shared_files();
    let _dog = Watchdog::new("batches", Duration::from_secs(30));
    let t = team(9);
    // 0 -> 1; a window wide enough for every state below to stay in the buffers.
    let k = STATES_PER_SAMPLE as u64;
    let lay = layout(&[0, 1], &[(0, 1)], 4 * k as u32);
    let mut orch = OrchestratorPorts::create(&t, &lay).unwrap();
    let mut m0 = MemberPorts::open(&t, 0, 0, &[], &[1]).unwrap();
    let mut m1 = MemberPorts::open(&t, 1, 0, &[0], &[]).unwrap();
    wait_ready(&orch, Duration::from_secs(10));
    let state = |tick: u64| StateMsg::ok(tick, HASH, 0, [tick as f64; 12]);

    // A full batch leaves at once, the rest waits for the wake-up.
    let quiet = 2 * k + 3;
    for tick in 0..quiet {
        m0.publish_quietly(state(tick)).unwrap();
    }
    let full: Vec<u64> = (0..2 * k).collect();
    assert_eq!(ticks_received(&mut m1, &mut orch), (full.clone(), full));
    m0.notify_readers().unwrap();
    let rest: Vec<u64> = (2 * k..quiet).collect();
    assert_eq!(ticks_received(&mut m1, &mut orch), (rest.clone(), rest));
    assert!(m1.wait(Duration::ZERO).unwrap(), "the reader was not woken");

    // `publish` sends the quiet states before it with it; each state keeps its content.
    m0.publish_quietly(state(quiet)).unwrap();
    m0.publish(state(quiet + 1)).unwrap();
    let mut got = vec![];
    m1.receive_neighbors(|s| got.push(s)).unwrap();
    assert_eq!(got, vec![state(quiet), state(quiet + 1)]);

    // A state another member's id is refused, and nothing is sent for it.
    let foreign = StateMsg::ok(quiet + 2, HASH, 1, [0.0; 12]);
    assert!(matches!(
        m0.publish_quietly(foreign),
        Err(TransportError::ForeignState { .. })
    ));
    m0.notify_readers().unwrap();
    let (r, o) = ticks_received(&mut m1, &mut orch);
    assert_eq!((r.len(), o), (0, (quiet..quiet + 2).collect()));
    drop((m0, m1));
    orch.shutdown().unwrap();
}

#[test]
fn a_second_orchestrator_of_a_running_team_is_refused() {
    let _files = shared_files();
    let _dog = Watchdog::new("second orchestrator", Duration::from_secs(30));
    let (a, b) = (team(2), team(3));
    let lay = layout(&[1, 2], &[(1, 2)], 1);
    let first = OrchestratorPorts::create(&a, &lay).unwrap();
    let err = OrchestratorPorts::create(&a, &lay).err().unwrap();
    assert!(
        matches!(err, TransportError::TeamAlreadyRunning { .. }),
        "{err}"
    );
    let msg = err.to_string();
    assert!(
        msg.starts_with(&format!("team {a} is already running")),
        "{msg}"
    );
    assert!(
        msg.contains(&a.node_name(TeamProcess::Orchestrator)),
        "{msg}"
    );

    let other = OrchestratorPorts::create(&b, &lay).unwrap();
    // Both teams work side by side, each agent 1 belongs to its own team.
    let m_a = MemberPorts::open(&a, 1, 0, &[], &[2]).unwrap();
    let m_b = MemberPorts::open(&b, 1, 0, &[], &[2]).unwrap();
    assert!(m_a.orchestrator_alive() && m_b.orchestrator_alive());
    drop((m_a, m_b, first, other));
}

#[test]
fn members_are_refused_with_precise_errors() {
    let _files = shared_files();
    let _dog = Watchdog::new("member errors", Duration::from_secs(30));
    let t = team(4);
    let missing = team(5);

    let err = MemberPorts::open(&missing, 1, 0, &[], &[]).err().unwrap();
    assert!(matches!(err, TransportError::TeamNotFound { .. }), "{err}");
    assert!(err
        .to_string()
        .starts_with(&format!("team {missing} does not exist")));

    let lay = layout(&[1, 2], &[(1, 2)], 1);
    let orch = OrchestratorPorts::create(&t, &lay).unwrap();

    // A member flying another scenario is refused before it takes any slot.
    let err = MemberPorts::open(&t, 1, 0xdead_beef, &[], &[2])
        .err()
        .unwrap();
    assert!(
        matches!(err, TransportError::ScenarioMismatch { id: 1, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("00000000deadbeef"), "{err}");

    let err = MemberPorts::open(&t, 99, 0, &[], &[]).err().unwrap();
    assert!(
        matches!(err, TransportError::NotInTeam { id: 99, .. }),
        "{err}"
    );
    assert!(err
        .to_string()
        .starts_with(&format!("agent 99 is not part of team {t}")));

    let mut one = MemberPorts::open(&t, 1, 0, &[], &[2]).unwrap();
    let err = MemberPorts::open(&t, 1, 0, &[], &[2]).err().unwrap();
    assert!(
        matches!(
            err,
            TransportError::AgentAlreadyRunning {
                id: 1,
                port: "publisher",
                ..
            }
        ),
        "{err}"
    );
    assert!(err
        .to_string()
        .starts_with(&format!("agent 1 of team {t} is already running")));

    // Agent 2 claims it wakes agent 1: the layout has no edge 2 -> 1.
    let err = MemberPorts::open(&t, 2, 0, &[1], &[1]).err().unwrap();
    assert!(
        matches!(err, TransportError::NotANeighbor { id: 2, peer: 1, .. }),
        "{err}"
    );
    let two = MemberPorts::open(&t, 2, 0, &[1], &[]).unwrap();

    let err = one
        .publish(StateMsg::ok(0, HASH, 2, [0.0; 12]))
        .err()
        .unwrap();
    assert!(matches!(err, TransportError::ForeignState { .. }), "{err}");

    assert!(one.orchestrator_alive() && two.orchestrator_alive());
    let start = Instant::now();
    for _ in 0..200 {
        assert!(two.orchestrator_alive());
    }
    println!(
        "orchestrator_alive: {:.1} us per call",
        start.elapsed().as_secs_f64() * 1e6 / 200.0
    );
    drop(orch);
    assert!(!one.orchestrator_alive() && !two.orchestrator_alive());
}

#[test]
fn names_and_layouts_are_validated() {
    for bad in ["", "a/b", "sp ace", "dots.no", &"x".repeat(49)] {
        assert!(TeamName::new(bad).is_err(), "{bad:?} accepted");
    }
    let ok = TeamName::new(&"A-z_9".repeat(10)[..48]).unwrap();
    assert_eq!(ok.state_service(3), format!("cdm/{ok}/state/3"));
    assert!(ok.owns_node(&ok.node_name(TeamProcess::Agent(4))));
    assert!(!ok.owns_node(&format!("cdm/{ok}x/orchestrator")));

    let ins = |pairs: &[(u32, &[u32])]| -> BTreeMap<u32, Vec<u32>> {
        pairs.iter().map(|&(k, v)| (k, v.to_vec())).collect()
    };
    assert!(TeamLayout::new(vec![], ins(&[]), 1).is_err());
    assert!(TeamLayout::new(vec![1, 1], ins(&[]), 1).is_err());
    assert!(TeamLayout::new(vec![1, 2], ins(&[]), 0).is_err());
    assert!(TeamLayout::new(vec![1, 2], ins(&[(1, &[1])]), 1).is_err());
    assert!(TeamLayout::new(vec![1, 2], ins(&[(1, &[3])]), 1).is_err());
    assert!(TeamLayout::new(vec![1, 2], ins(&[(5, &[1])]), 1).is_err());
    let l = TeamLayout::new(vec![3, 1, 2], ins(&[(1, &[3, 2, 3]), (2, &[3])]), 4).unwrap();
    assert_eq!(l.ids(), &[1, 2, 3]);
    assert_eq!(l.in_neighbors(1), &[2, 3]);
    assert_eq!(l.out_neighbors(3), &[1, 2]);
    assert_eq!(l.out_neighbors(9), &[] as &[u32]);
}

/// This process's pid as iceoryx2 encodes it (the host pid, which may differ in a container).
fn iceoryx2_pid() -> u32 {
    let probe = NodeBuilder::new()
        .config(&cdm_iox::iceoryx2_config())
        .create::<ipc::Service>()
        .unwrap();
    id_pid(probe.id().value())
}

/// Everything of `team` still visible: its services, its nodes, and any iceoryx2 file under
/// /dev/shm (iceoryx2's root included) whose name carries an id minted by one of `pids` at or
/// after the monotonic second `since_s` (taken when the test began: the files of an older
/// process that had the same pid are not the test's).
fn leftovers(team: &TeamName, pids: &[u32], since_s: u32) -> Vec<String> {
    let mut out = team_entries(team);
    out.extend(files_of(pids, since_s));
    out
}

/// The services and nodes named after `team` in iceoryx2's registries.
fn team_entries(team: &TeamName) -> Vec<String> {
    let cfg = cdm_iox::iceoryx2_config();
    let prefix = format!("cdm/{team}/");
    let mut out = vec![];
    ipc::Service::list(&cfg, |s| {
        let name = s.static_details.name().as_str();
        if name.starts_with(&prefix) {
            out.push(format!("service {name}"));
        }
        CallbackProgression::Continue
    })
    .unwrap();
    Node::<ipc::Service>::list(&cfg, |state| {
        let name = match &state {
            NodeState::Alive(v) => v.details().as_ref().map(|d| d.name().to_string()),
            NodeState::Dead(v) => v.details().as_ref().map(|d| d.name().to_string()),
            _ => None,
        };
        if let Some(n) = name.filter(|n| team.owns_node(n)) {
            out.push(format!("node {n}"));
        }
        CallbackProgression::Continue
    })
    .unwrap();
    out.sort();
    out
}

/// Files under /dev/shm (iceoryx2's root, `iox2_root()`, is inside it) whose names carry an
/// iceoryx2 id minted by `pids` at or after the monotonic second `since_s`.
fn files_of(pids: &[u32], since_s: u32) -> Vec<String> {
    let mut out = vec![];
    let mut dirs = vec![std::path::PathBuf::from("/dev/shm")];
    if !cdm_iox::iox2_root().starts_with("/dev/shm/") {
        dirs.push(cdm_iox::iox2_root().into());
    }
    while let Some(dir) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if e.file_type().is_ok_and(|t| t.is_dir()) {
                dirs.push(e.path());
            }
            let ours =
                ids_in(&name).any(|id| pids.contains(&id_pid(id)) && id_seconds(id) >= since_s);
            if ours {
                out.push(e.path().display().to_string());
            }
        }
    }
    out.sort();
    out
}

#[test]
fn nothing_of_a_team_is_left_after_drop() {
    let _files = exclusive_files();
    let _dog = Watchdog::new("cleanup", Duration::from_secs(30));
    let since = monotonic_s();
    let me = iceoryx2_pid();
    let t = team(6);
    // Nothing of this process's earlier tests either (minted since it was born).
    let born = cdm_iox::ids::born_s(std::process::id()).expect("this process is alive");
    assert_eq!(
        leftovers(&t, &[me], born),
        Vec::<String>::new(),
        "dirty start"
    );

    let lay = layout(&[0, 1], &[(0, 1), (1, 0)], 1);
    let mut orch = OrchestratorPorts::create(&t, &lay).unwrap();
    let mut m0 = MemberPorts::open(&t, 0, 0, &[1], &[1]).unwrap();
    let mut m1 = MemberPorts::open(&t, 1, 0, &[0], &[0]).unwrap();
    wait_ready(&orch, Duration::from_secs(10));
    orch.publish_clock(ClockMsg::run(0, HASH)).unwrap();
    for m in [&mut m0, &mut m1] {
        assert!(m.wait(Duration::from_secs(5)).unwrap());
        let grant = m.latest_clock().unwrap().unwrap();
        let id = m.id();
        assert_eq!(
            m.publish(StateMsg::ok(grant.grant_tick, HASH, id, [0.0; 12]))
                .unwrap(),
            2
        );
    }
    let mut n = 0;
    orch.receive_states(|_| n += 1).unwrap();
    assert_eq!(n, 2);
    let mut seen = vec![];
    m0.receive_neighbors(|s| seen.push(s.id)).unwrap();
    m1.receive_neighbors(|s| seen.push(s.id)).unwrap();
    assert_eq!(seen, vec![1, 0]);

    // The checker does see a live team (services, nodes, files named by our ids).
    let live = leftovers(&t, &[me], since);
    for what in ["service ", "node ", "/dev/shm/"] {
        assert!(
            live.iter().any(|l| l.starts_with(what)),
            "no {what} in {live:#?}"
        );
    }
    // Members may leave before or after the orchestrator; here the orchestrator goes first.
    drop(orch);
    drop((m0, m1));
    assert_eq!(leftovers(&t, &[me], since), Vec::<String>::new());
}

/// Spawns this test binary as a child running only `child_process` in `role`; returns once the
/// child has opened its ports, with the child and its iceoryx2 pid.
fn spawn_child(role: &str) -> (Child, u32) {
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args([
            "child_process",
            "--exact",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_ENV, role)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    for line in BufReader::new(stdout).lines() {
        let line = line.unwrap();
        // libtest may have printed "test child_process ... " on the same line.
        if let Some((_, pid)) = line.split_once("READY ") {
            return (child, pid.trim().parse().unwrap());
        }
    }
    panic!("child {role} ended before it was ready: {:?}", child.wait());
}

/// Not a test on its own: the body of the child processes of the stale-cleanup test. In a normal
/// run (no `CDM_TRANSPORT_TEST_CHILD`) it returns at once.
#[test]
fn child_process() {
    let Ok(role) = std::env::var(CHILD_ENV) else {
        return;
    };
    let _dog = Watchdog::new("child", Duration::from_secs(60));
    let parts: Vec<&str> = role.split(':').collect();
    let t = TeamName::new(parts[1]).unwrap();
    let _ports: Box<dyn std::any::Any> = match parts[0] {
        "orchestrator" => {
            Box::new(OrchestratorPorts::create(&t, &layout(&[0, 1], &[(0, 1)], 1)).unwrap())
        }
        _ => Box::new(MemberPorts::open(&t, 0, 0, &[], &[1]).unwrap()),
    };
    println!("READY {}", iceoryx2_pid());
    thread::sleep(Duration::from_secs(50)); // until the parent kills us
}

#[test]
fn stale_resources_of_a_killed_team_are_removed() {
    let _files = exclusive_files();
    let _dog = Watchdog::new("stale cleanup", Duration::from_secs(60));
    let since = monotonic_s();
    let t = team(7);
    let lay = layout(&[0, 1], &[(0, 1)], 1);

    // A crashed team: orchestrator and agent 0 SIGKILLed, nothing cleaned.
    let (mut orch_child, orch_pid) = spawn_child(&format!("orchestrator:{t}"));
    let (mut member_child, member_pid) = spawn_child(&format!("member:{t}"));
    for c in [&mut orch_child, &mut member_child] {
        c.kill().unwrap();
        c.wait().unwrap();
    }
    let stale = leftovers(&t, &[orch_pid, member_pid], since);
    assert!(
        stale.iter().any(|l| l.starts_with("/dev/shm/")),
        "{stale:#?}"
    );

    // A new run of the same team cleans the crashed one and works.
    let orch = OrchestratorPorts::create(&t, &lay).unwrap();
    assert_eq!(orch.stale_nodes_removed(), 2);
    assert_eq!(
        files_of(&[orch_pid, member_pid], since),
        Vec::<String>::new()
    );
    let m0 = MemberPorts::open(&t, 0, 0, &[], &[1]).unwrap();
    let m1 = MemberPorts::open(&t, 1, 0, &[0], &[]).unwrap();
    wait_ready(&orch, Duration::from_secs(10));
    drop(m0);

    // A member killed during the run: its slot comes back after `remove_dead_nodes`.
    let (mut child, child_pid) = spawn_child(&format!("member:{t}"));
    assert_eq!(orch.readiness().agents[0].state_publishers, 1);
    child.kill().unwrap();
    child.wait().unwrap();
    assert_eq!(
        orch.readiness().agents[0].state_publishers,
        1,
        "dead but not cleaned"
    );
    assert_eq!(remove_dead_nodes(&t).unwrap(), 1);
    assert_eq!(orch.readiness().agents[0].state_publishers, 0);
    assert_eq!(files_of(&[child_pid], since), Vec::<String>::new());

    drop((m1, orch));
    let me = iceoryx2_pid();
    assert_eq!(
        leftovers(&t, &[me, orch_pid, member_pid, child_pid], since),
        Vec::<String>::new()
    );
}

/// One agent of the throughput run: publishes every granted tick, drains its neighbours.
fn lockstep_member(team: TeamName, id: u32, ins: Vec<u32>, outs: Vec<u32>) -> u64 {
    let mut m = MemberPorts::open(&team, id, 0, &ins, &outs).unwrap();
    let (mut next, mut grant, mut received) = (0u64, None::<u64>, 0u64);
    loop {
        if let Some(c) = m.latest_clock().unwrap() {
            if let ClockCommand::Stop(_) = c.command() {
                // Every state was sent before the stop (the orchestrator saw them all).
                m.receive_neighbors(|_| received += 1).unwrap();
                return received;
            }
            grant = Some(c.grant_tick);
        }
        while grant.is_some_and(|g| next <= g) {
            m.receive_neighbors(|_| received += 1).unwrap();
            m.publish(StateMsg::ok(next, HASH, id, [0.0; 12])).unwrap();
            next += 1;
        }
        m.receive_neighbors(|_| received += 1).unwrap();
        m.wait(Duration::from_millis(100)).unwrap();
    }
}

#[test]
fn lockstep_round_trip_throughput() {
    let _files = shared_files();
    let _dog = Watchdog::new("throughput", Duration::from_secs(120));
    const N: u32 = 10;
    const TICKS: u64 = 2_000;
    let t = team(8);
    let ids: Vec<u32> = (0..N).collect();
    let ring: Vec<(u32, u32)> = ids
        .iter()
        .flat_map(|&i| [(i, (i + 1) % N), ((i + 1) % N, i)])
        .collect();
    let lay = layout(&ids, &ring, 1);
    let mut orch = OrchestratorPorts::create(&t, &lay).unwrap();
    let members: Vec<_> = ids
        .iter()
        .map(|&id| {
            let (tm, ins, outs) = (
                t.clone(),
                lay.in_neighbors(id).to_vec(),
                lay.out_neighbors(id).to_vec(),
            );
            thread::spawn(move || lockstep_member(tm, id, ins, outs))
        })
        .collect();
    wait_ready(&orch, Duration::from_secs(20));

    let start = Instant::now();
    let mut gaps = 0;
    for tick in 0..TICKS {
        orch.publish_clock(ClockMsg::run(tick, HASH)).unwrap();
        let mut done = 0;
        while done < N {
            orch.receive_states(|s| {
                if s.tick == tick {
                    done += 1;
                } else {
                    gaps += 1;
                }
            })
            .unwrap();
            if done < N {
                orch.wait(Duration::from_millis(100)).unwrap();
            }
        }
    }
    let elapsed = start.elapsed();
    orch.publish_clock(ClockMsg::stop(TICKS - 1, HASH, StopReason::Finished))
        .unwrap();
    let received: Vec<u64> = members.into_iter().map(|h| h.join().unwrap()).collect();
    println!(
        "lockstep round trip, {N} member threads + orchestrator, {TICKS} ticks: {:.0} ticks/s \
         ({:.1} us/tick); neighbour samples per member: {received:?}",
        TICKS as f64 / elapsed.as_secs_f64(),
        elapsed.as_secs_f64() * 1e6 / TICKS as f64
    );
    assert_eq!(gaps, 0);
    // Each member reads 2 neighbours: all their samples arrive (buffer = window + 2, lockstep).
    assert!(received.iter().all(|&r| r == 2 * TICKS), "{received:?}");
}
