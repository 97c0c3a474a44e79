//! Faults a flying team must survive, each with the real binaries over real iceoryx2
//! shared memory, each under a deadline. After each: the documented exit code, no process of the
//! team alive, nothing of the team in /dev/shm or /dev/shm/cdm-iceoryx2-<uid>, telemetry.csv holding only
//! whole ticks (every one before the fault), and audit.json saying what happened.
//!
//! - A primary or a secondary leader dies (SIGKILL) at a chosen tick (`--on-loss stop`; the
//!   default repair is tested in `loss_launch.rs`).
//! - An agent hangs without dying (SIGSTOP): named by `--agent-timeout`.
//! - The orchestrator gets SIGTERM; or SIGKILL, after which its members stop by themselves and
//!   a new launch of the same team removes what the dead orchestrator left and flies.
//! - Two launches of one team at once: the second is refused and writes nothing.
//! - A foreign process opens a live team's services: every port it could disturb the team with
//!   is refused by the transport, and the team's result does not change.
//! - A neighbour state carrying NaN or a tick from the wrong step: a reader reports it with both
//!   ids; a state nobody reads is reported by the orchestrator.
//!
//! Faults at a chosen tick are injected with the test-only `CDM_FAULT_INJECT`
//! (`cdm_process::fault_inject`): the orchestrator's children inherit it, only the named agent acts.

use integration_tests::support;

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use cdm_iox::{ClockWire, MemberPorts, StateBatchWire, TeamName, TransportError};
use cdm_model::formation::Role;
use cdm_scenario::{Checks, Scenario, ScenarioFile};
use integration_tests::{bin, describe, run, spawn, unique_team, Running, TempDir};
use serde_json::Value;
use support::*;

/// A 10-agent team: 3 primary leaders (1-3), 3 secondary (4-6), followers 7-10.
const TEAM: [&str; 2] = ["--n", "10"];
/// The tick at which injected faults happen.
const FAULT_TICK: u64 = 1000;
/// A 10-agent team starts and stops in about a second; the rest is slack for a loaded machine.
const STOP_DEADLINE: Duration = integration_tests::deadline::REFUSE;
/// A short plan of a 10-agent team (3,001 ticks) runs in about a second.
const SHORT_DEADLINE: Duration = integration_tests::deadline::SHORT;
/// Rows of telemetry to see before breaking a run from outside.
const ROWS_BEFORE_FAULT: usize = 200;

/// `launch` of the 10-agent team with a plan of `t_total` seconds and extra arguments.
fn launch_team(team: &str, out: &Path, t_total: &str, extra: &[&str]) -> Command {
    let mut args: Vec<&str> = TEAM.to_vec();
    args.extend(["--t-total", t_total]);
    args.extend(extra);
    launch(team, out, &args)
}

/// The ids of a flown scenario.
fn ids_of(s: &ScenarioFile) -> BTreeSet<u32> {
    s.agents.iter().map(|a| a.id).collect()
}

/// A team whose members all run: the orchestrator, the flown scenario and the footprint
/// (checked visible: orchestrator + 10 members).
fn running(team: &str, out: &Path, extra: &[&str]) -> (Running, ScenarioFile, TeamFootprint) {
    let mut orch = spawn(&mut launch_team(team, out, "600", extra));
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), ROWS_BEFORE_FAULT);
    let s = flown_scenario(out);
    let procs = team_processes(team);
    assert_eq!(procs.len(), s.agents.len() + 1, "{procs:#?}");
    let fp = TeamFootprint::record(team, procs.keys().copied());
    fp.assert_visible(s.agents.len() + 1);
    (orch, s, fp)
}

/// audit.json of a faulted run: verdict FAULT, incomplete, a fault of `kind`; telemetry.csv
/// holds whole ticks 0..k-1 where k is the fault's tick. Returns the fault.
fn assert_fault(out: &Path, s: &ScenarioFile, kind: &str) -> Value {
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "FAULT", "{audit:#}");
    assert_eq!(audit["complete"], false, "{audit:#}");
    let fault = audit["fault"].clone();
    assert_eq!(fault["kind"], kind, "{audit:#}");
    let ticks = complete_ticks(&out.join("telemetry.csv"), &ids_of(s));
    assert!(ticks > 0, "no tick in telemetry: {audit:#}");
    assert_eq!(
        fault["tick"], ticks,
        "the fault's tick is the first tick missing from telemetry.csv: {audit:#}"
    );
    fault
}

fn message(fault: &Value) -> String {
    fault["message"].as_str().unwrap_or_default().to_string()
}

/// Launches the team with `CDM_FAULT_INJECT=<id>:<kind>@FAULT_TICK` and waits for its end.
fn launch_injected(
    team: &str,
    out: &Path,
    (id, kind): (u32, &str),
    extra: &[&str],
) -> std::process::Output {
    let mut cmd = launch_team(team, out, "600", extra);
    cmd.env(
        cdm_process::fault_inject::ENV,
        format!("{id}:{kind}@{FAULT_TICK}"),
    );
    let mut orch = spawn(&mut cmd);
    // Record the team's processes and services while it lives (until the fault stops it).
    let until = Instant::now() + PROGRESS_DEADLINE;
    let mut fp = TeamFootprint::record(team, []);
    let mut seen_whole_team = false;
    while !orch.has_exited() && Instant::now() < until {
        let procs = team_processes(team);
        seen_whole_team |= procs.len() == 11;
        fp.absorb(TeamFootprint::record(team, procs.keys().copied()));
        std::thread::sleep(Duration::from_millis(2));
    }
    let o = orch.finish(STOP_DEADLINE);
    assert!(seen_whole_team, "never saw the 11 processes of team {team}");
    assert_no_process_of(team);
    fp.assert_nothing_left();
    o
}

// ---------------------------------------------------------------------------------------------
// 1. Leaders die
// ---------------------------------------------------------------------------------------------

fn a_killed_leader(id: u32, role: Role) {
    let dir = TempDir::new();
    let team = unique_team(&format!("kill_{}", role.as_str()));
    let out = dir.path().join("run");
    // A dead member is a fault with `--on-loss stop` (the default repairs: `loss_launch.rs`).
    let o = launch_injected(&team, &out, (id, "kill"), &["--on-loss", "stop"]);
    assert_exit(&o, 3, &format!("launch after {} {id} died", role.as_str()));
    let s = flown_scenario(&out);
    assert_eq!(
        s.agents.iter().find(|a| a.id == id).map(|a| a.role),
        Some(role)
    );
    let fault = assert_fault(&out, &s, "agent-exited");
    assert_eq!(fault["agent"], id, "{fault:#}");
    assert_eq!(fault["tick"], FAULT_TICK, "{fault:#}");
    assert!(
        message(&fault).contains(&format!(
            "agent {id} was killed by signal 9 at tick {FAULT_TICK}"
        )),
        "{fault:#}"
    );
}

/// SIGKILL of primary leader 1 at tick 1000: exit 3, `agent-exited` naming agent 1 and tick
/// 1000, telemetry ticks 0..999, nothing left.
#[test]
fn a_primary_leader_killed_at_a_chosen_tick_stops_the_team() {
    a_killed_leader(1, Role::Primary);
}

/// The same for secondary leader 5.
#[test]
fn a_secondary_leader_killed_at_a_chosen_tick_stops_the_team() {
    a_killed_leader(5, Role::Secondary);
}

// ---------------------------------------------------------------------------------------------
// 2. An agent hangs
// ---------------------------------------------------------------------------------------------

/// SIGSTOP of follower 9 (alive, silent): after `--agent-timeout 1.5` the orchestrator names
/// it, stops the team (the stopped process is killed) and exits 3.
#[test]
fn a_hung_agent_is_named_within_the_agent_timeout_and_the_team_stopped() {
    let dir = TempDir::new();
    let team = unique_team("sigstop");
    let out = dir.path().join("run");
    let stop = ["--agent-timeout", "1.5", "--on-loss", "stop"];
    let (orch, s, fp) = running(&team, &out, &stop);
    let victim = 9;
    let pid = member_pid(&team, victim).expect("agent 9 runs");
    let _guard = Stopped(pid);
    signal(pid, libc::SIGSTOP);
    let o = orch.finish(STOP_DEADLINE);
    assert_exit(&o, 3, "launch after an agent hung");
    let fault = assert_fault(&out, &s, "agent-silent");
    assert_eq!(fault["agent"], victim, "{fault:#}");
    assert!(
        message(&fault).contains("agents [9] sent no state") && message(&fault).contains("1.5s"),
        "{fault:#}"
    );
    assert_no_process_of(&team);
    fp.assert_nothing_left();
}

// ---------------------------------------------------------------------------------------------
// 3, 4. The orchestrator is terminated or killed
// ---------------------------------------------------------------------------------------------

/// SIGTERM to the orchestrator: the stop sequence, exit 3, `interrupted`, nothing left.
#[test]
fn a_terminated_orchestrator_stops_its_team_and_leaves_nothing_behind() {
    let dir = TempDir::new();
    let team = unique_team("sigterm");
    let out = dir.path().join("run");
    let (mut orch, s, fp) = running(&team, &out, &[]);
    signal(orch.id(), libc::SIGTERM);
    let o = orch.finish(STOP_DEADLINE);
    assert_exit(&o, 3, "launch after SIGTERM");
    let fault = assert_fault(&out, &s, "interrupted");
    assert_eq!(fault["agent"], Value::Null, "{fault:#}");
    assert_no_process_of(&team);
    fp.assert_nothing_left();
}

/// SIGHUP (the terminal closed) and SIGQUIT to the orchestrator: handled like SIGTERM, the
/// stop sequence, exit 3, audit.json with `interrupted` naming the signal, nothing left. Their
/// default actions killed the orchestrator at once (exit 129 / 131, no audit.json, the team's
/// files left in /dev/shm).
#[test]
fn a_hangup_or_quit_signal_stops_the_team_like_sigterm() {
    for (sig, name) in [(libc::SIGHUP, "SIGHUP"), (libc::SIGQUIT, "SIGQUIT")] {
        let dir = TempDir::new();
        let team = unique_team(&name.to_lowercase());
        let out = dir.path().join("run");
        let (mut orch, s, fp) = running(&team, &out, &[]);
        signal(orch.id(), sig);
        let o = orch.finish(STOP_DEADLINE);
        assert_exit(&o, 3, &format!("launch after {name}"));
        let fault = assert_fault(&out, &s, "interrupted");
        assert!(message(&fault).contains(name), "{fault:#}");
        assert_no_process_of(&team);
        fp.assert_nothing_left();
    }
}

/// SIGSTOP of the orchestrator until its members, seeing no grant for their silence timeout
/// (10 s), have stopped by themselves; then SIGCONT: the orchestrator records that its own clock
/// stalled (`orchestrator-stalled`, no agent blamed), not `agent 1 exited`. Exit 3, nothing left.
#[test]
fn a_stopped_orchestrator_records_that_its_clock_stalled() {
    let dir = TempDir::new();
    let team = unique_team("orchstop");
    let out = dir.path().join("run");
    let (mut orch, s, fp) = running(&team, &out, &[]);
    let pid = orch.id();
    signal(pid, libc::SIGSTOP);
    // The members' exit is the event (they are zombies of the stopped orchestrator meanwhile,
    // which `team_processes` does not count).
    let until = std::time::Instant::now() + integration_tests::deadline::scaled(SHORT_DEADLINE);
    while team_processes(&team).len() > 1 {
        assert!(
            std::time::Instant::now() < until,
            "members still running {SHORT_DEADLINE:?} after SIGSTOP of the orchestrator: {:#?}",
            team_processes(&team)
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    signal(pid, libc::SIGCONT);
    let o = orch.finish(STOP_DEADLINE);
    assert_exit(
        &o,
        3,
        "launch after SIGSTOP until its members stopped, and SIGCONT",
    );
    let audit = read_json(&out.join("audit.json"));
    let fault = &audit["fault"];
    assert_eq!(fault["kind"], "orchestrator-stalled", "{audit:#}");
    assert_eq!(fault["agent"], Value::Null, "{audit:#}");
    assert!(
        message(fault).contains("the orchestrator itself did not run for"),
        "{audit:#}"
    );
    // The stall began at a tick the team had not completed; telemetry holds whole ticks.
    let ticks = complete_ticks(&out.join("telemetry.csv"), &ids_of(&s));
    assert_eq!(fault["tick"], ticks, "{audit:#}");
    assert_no_process_of(&team);
    fp.assert_nothing_left();
}

/// SIGKILL of the orchestrator: every member notices the clock's node is dead and exits by
/// itself (exit 3, "the orchestrator of team T is gone"); telemetry keeps whole ticks; the
/// leftover checker lists its node and command channel; then a new launch of the same team
/// removes the dead orchestrator's files and flies to the end.
#[test]
fn after_the_orchestrator_is_killed_members_exit_and_the_team_can_fly_again() {
    let dir = TempDir::new();
    let team = unique_team("orchkill");
    let out = dir.path().join("run");
    let (mut orch, s, fp) = running(&team, &out, &[]);
    signal(orch.id(), libc::SIGKILL);
    // The members hold the orchestrator's stderr: `finish` returns once they have all exited.
    let o = orch.finish(STOP_DEADLINE);
    assert_eq!(
        std::os::unix::process::ExitStatusExt::signal(&o.status),
        Some(9),
        "{}",
        describe(&o)
    );
    let err = String::from_utf8_lossy(&o.stderr);
    let gone = format!("the orchestrator of team {team} is gone");
    assert_eq!(
        err.matches(&gone).count(),
        s.agents.len(),
        "every member says why it stopped:\n{err}"
    );
    assert_no_process_of(&team);
    // No audit can be written by a killed process; telemetry holds whole ticks (a SIGKILL in
    // the middle of a flush could cut the last one: whole ticks are checked up to it).
    assert!(!out.join("audit.json").exists());
    let text = std::fs::read_to_string(out.join("telemetry.csv")).expect("telemetry.csv");
    let whole = match text.rfind('\n') {
        Some(k) => &text[..=k],
        None => "",
    };
    let cut = dir.path().join("whole.csv");
    let ids = ids_of(&s);
    let mut lines: Vec<&str> = whole.lines().collect();
    while lines.len() > 1 && {
        let last_tick = lines[lines.len() - 1].split(',').next();
        lines
            .iter()
            .skip(1)
            .filter(|l| l.split(',').next() == last_tick)
            .count()
            < ids.len()
    } {
        lines.pop();
    }
    std::fs::write(&cut, lines.join("\n") + "\n").expect("write");
    let ticks = complete_ticks(&cut, &ids);
    assert!(
        ticks as usize * ids.len() > ROWS_BEFORE_FAULT,
        "{ticks} ticks"
    );
    // The dead orchestrator's node is all that is left ...
    let left = fp.leftovers();
    assert!(
        left.iter()
            .any(|l| l.contains(&format!("cdm/{team}/orchestrator"))),
        "expected the dead orchestrator's node: {left:#?}"
    );
    // ... with its command channel (the socket `<team>.command`) ...
    assert!(
        left.iter()
            .any(|l| l.ends_with(&format!("/{team}.command"))),
        "expected the dead orchestrator's command channel: {left:#?}"
    );
    // ... and the next launch of the team removes them and flies.
    let again = dir.path().join("again");
    let mut relaunch = launch_team(&team, &again, "30", &[]);
    relaunch.env("RUST_LOG", "info");
    let o = run(&mut relaunch, SHORT_DEADLINE);
    assert_exit(&o, 0, "a new launch of the team");
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("removed stale resources"),
        "{}",
        describe(&o)
    );
    let audit = read_json(&again.join("audit.json"));
    assert_eq!(audit["complete"], true, "{audit:#}");
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_no_process_of(&team);
    fp.assert_nothing_left();
}

// ---------------------------------------------------------------------------------------------
// 5. Two launches of one team
// ---------------------------------------------------------------------------------------------

/// A second launch of a running team is refused (exit 2, "team T is already running"), writes
/// no run directory, and does not touch the first one's (even with the same --out and
/// --force); the first flies to the end.
#[test]
fn a_second_launch_of_a_running_team_is_refused_and_writes_nothing() {
    let dir = TempDir::new();
    let team = unique_team("twice");
    let out = dir.path().join("first");
    // 60,001 ticks: a few seconds, long enough to be running when the second launches come.
    let mut first = spawn(&mut launch_team(&team, &out, "600", &[]));
    wait_for_rows(&mut first, &out.join("telemetry.csv"), ROWS_BEFORE_FAULT);

    let other = dir.path().join("second");
    for (second_out, extra) in [(&other, &[][..]), (&out, &["--force"][..])] {
        let o = run(
            &mut launch_team(&team, second_out, "60", extra),
            SHORT_DEADLINE,
        );
        assert_exit(&o, 2, "a second launch of a running team");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(&format!("team {team} is already running")),
            "{}",
            describe(&o)
        );
    }
    assert!(
        !other.exists(),
        "the refused launch wrote {}",
        other.display()
    );
    let o = first.finish(SHORT_DEADLINE);
    assert_exit(&o, 0, "the first launch");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["complete"], true, "{audit:#}");
    let s = flown_scenario(&out);
    assert_eq!(
        complete_ticks(&out.join("telemetry.csv"), &ids_of(&s)),
        60_001
    );
    assert_no_process_of(&team);
}

// ---------------------------------------------------------------------------------------------
// 7. A foreign process
// ---------------------------------------------------------------------------------------------

/// A process outside the team opens its services while it flies: another payload type on a
/// state service, a second publisher of a state or of the clock, a subscriber beyond the one
/// observer slot, and a
/// second process claiming a running agent's id are all refused; the team flies exactly as
/// `simulate` does.
#[test]
fn a_foreign_process_cannot_publish_into_a_team() {
    use iceoryx2::prelude::*;
    let dir = TempDir::new();
    let team = unique_team("foreign");
    let out = dir.path().join("run");
    // `--on-loss repair` (the default) sizes every state service with spare subscriber slots for
    // the readers a repair may add: those are open to a reader of this user. Without repairs
    // the only spare slot is the observer's.
    let mut orch = spawn(&mut launch_team(&team, &out, "60", &["--on-loss", "stop"]));
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), ROWS_BEFORE_FAULT);

    let t = TeamName::new(&team).expect("team name");
    let node = NodeBuilder::new()
        .name(&NodeName::new("foreign").expect("node name"))
        .config(&cdm_iox::iceoryx2_config())
        .create::<ipc::Service>()
        .expect("a foreign node");
    let name = |s: String| ServiceName::new(&s).expect("service name");
    // Another payload type on agent 1's state service.
    let wrong = node
        .service_builder(&name(t.state_service(1)))
        .publish_subscribe::<u64>()
        .open();
    assert!(wrong.is_err(), "a foreign payload type was accepted");
    // The right type: the service opens (it is readable metadata), but no port is granted.
    let state = node
        .service_builder(&name(t.state_service(1)))
        .publish_subscribe::<StateBatchWire>()
        .open()
        .expect("open agent 1's state service");
    let publisher = state.publisher_builder().create();
    assert!(
        publisher.is_err(),
        "a second publisher of agent 1's state was accepted"
    );
    // One observer may read the states (watch.py); a second one is refused.
    let observer = state.subscriber_builder().create();
    assert!(observer.is_ok(), "the observer's subscriber was refused");
    let subscriber = state.subscriber_builder().create();
    assert!(
        subscriber.is_err(),
        "a second extra subscriber was accepted"
    );
    let clock = node
        .service_builder(&name(t.clock_service()))
        .publish_subscribe::<ClockWire>()
        .open()
        .expect("open the clock service");
    assert!(
        clock.publisher_builder().create().is_err(),
        "a second clock publisher was accepted"
    );
    // A second process claiming agent 1 (with the team's own scenario).
    let hash = Scenario::load(&out.join("scenario.toml"), Checks::Member)
        .expect("the flown scenario loads")
        .content_hash();
    let err = MemberPorts::open(&t, 1, hash, &[], &[9])
        .err()
        .expect("a second agent 1 was accepted");
    assert!(
        matches!(err, TransportError::AgentAlreadyRunning { id: 1, .. }),
        "{err}"
    );
    drop((state, clock, node));

    let o = orch.finish(SHORT_DEADLINE);
    assert_exit(&o, 0, "the team a foreign process tried to disturb");
    let sim = dir.path().join("sim");
    let so = run(
        &mut simulate(&sim, &["--n", "10", "--t-total", "60"]),
        SHORT_DEADLINE,
    );
    assert_exit(&so, 0, "simulate");
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
    assert_no_process_of(&team);
}

// ---------------------------------------------------------------------------------------------
// 8. Bad neighbour states
// ---------------------------------------------------------------------------------------------

/// A reader of agent 1 reports agent 1's bad state at tick 1000 with both ids; exit 3;
/// telemetry ticks 0..999 (the bad state is never written).
fn a_bad_state_of_agent_1(kind: &str, code: &str) {
    let dir = TempDir::new();
    let team = unique_team(&format!("bad_{kind}"));
    let out = dir.path().join("run");
    let o = launch_injected(&team, &out, (1, kind), &[]);
    assert_exit(&o, 3, &format!("launch with a {kind} state of agent 1"));
    let s = flown_scenario(&out);
    let fault = assert_fault(&out, &s, "agent-fault");
    assert_eq!(fault["tick"], FAULT_TICK, "{fault:#}");
    assert_eq!(fault["peer"], 1, "{fault:#}");
    let reader = fault["agent"].as_u64().expect("a reporting agent") as u32;
    let reads_1 = s
        .agents
        .iter()
        .find(|a| a.id == reader)
        .and_then(|a| a.in_neighbors.as_ref())
        .is_some_and(|ins| ins.contains(&1));
    assert!(reads_1, "agent {reader} does not read agent 1: {fault:#}");
    assert_eq!(
        message(&fault),
        format!("agent {reader} reported {code} at tick {FAULT_TICK} (peer 1)")
    );
}

/// A NaN in agent 1's tick-1000 state.
#[test]
fn a_non_finite_neighbour_state_is_reported_with_both_ids() {
    a_bad_state_of_agent_1("nan", "NonFinite");
}

/// Agent 1's tick-1000 state labelled tick 1001.
#[test]
fn a_neighbour_state_from_the_wrong_step_is_reported_with_both_ids() {
    a_bad_state_of_agent_1("tick", "TickGap");
}

/// A NaN from a follower no member reads (found in the team's exported scenario): the
/// orchestrator reports it itself.
#[test]
fn a_non_finite_state_nobody_reads_is_reported_by_the_orchestrator() {
    let dir = TempDir::new();
    let team = unique_team("bad_leaf");
    let out = dir.path().join("run");
    let exported = dir.path().join("team.toml");
    let mut export = Command::new(bin("orchestrator"));
    export
        .args(["scenario", "export"])
        .args(TEAM)
        .arg("--out")
        .arg(&exported);
    assert_exit(&run(&mut export, SHORT_DEADLINE), 0, "scenario export");
    let s = flown_scenario_file(&exported);
    let read: BTreeSet<u32> = s
        .agents
        .iter()
        .flat_map(|a| a.in_neighbors.iter().flatten().copied())
        .collect();
    let leaf = s
        .agents
        .iter()
        .map(|a| a.id)
        .filter(|id| !read.contains(id))
        .max()
        .expect("an agent without readers");
    let o = launch_injected(&team, &out, (leaf, "nan"), &[]);
    assert_exit(&o, 3, &format!("launch with a NaN state of agent {leaf}"));
    assert_eq!(
        flown_scenario(&out).agents,
        s.agents,
        "the flown team is the exported one"
    );
    let fault = assert_fault(&out, &s, "non-finite-state");
    assert_eq!(fault["agent"], leaf, "{fault:#}");
    assert_eq!(fault["tick"], FAULT_TICK, "{fault:#}");
}
