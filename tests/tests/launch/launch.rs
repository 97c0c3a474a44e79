//! `orchestrator launch` end to end: the real `orchestrator`, `leader` and `agent` binaries, one
//! process per quadcopter, over real iceoryx2 shared memory.
//!
//! - A team flown as processes writes exactly the telemetry of the in-process engine
//!   (`simulate`), byte for byte, and subscribes each follower to its three in-neighbours only.
//! - Two teams fly at once without seeing each other.
//! - A follower killed with SIGKILL, or the orchestrator interrupted with SIGINT, stops the whole
//!   team with a fault (exit 3): the telemetry keeps only complete ticks, no process of the team
//!   survives, and nothing of the team is left in /dev/shm or /dev/shm/cdm-iceoryx2-<uid>.
//! - A hand-started team (`--no-spawn`) refuses members with a wrong id, the wrong binary or a
//!   different scenario (exit 2), then flies with the right ones.
//!
//! Every test has its own team name and temporary directory, and every process runs under a
//! deadline (the harness kills its process group when the deadline passes or a guard drops).
//!
//! "Nothing left behind" is checked by attribution, not by a plain before/after listing of
//! /dev/shm: other teams (another test, a benchmark) may create and remove iceoryx2 files at the
//! same time. While the team runs, the test records its processes (from /proc and from the node
//! files iceoryx2 writes) and its services' hashes; afterwards no service or node named after the
//! team, and no file named by one of those hashes or by an id minted by one of those processes
//! since it was born (iceoryx2's ids carry their creation second: an old dead node of a process
//! that had the same pid before pids wrapped is not the team's), may remain. The check is first
//! shown to see the live team, so it cannot pass vacuously.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use cdm_model::formation::Role;
use cdm_scenario::ScenarioFile;
use integration_tests::{bin, run, spawn, unique_team, write_scenario, Running, TempDir};
use serde_json::Value;

/// paper40 as processes takes ~10-20 s on two cores; the rest is slack for a loaded machine.
const PAPER40_DEADLINE: Duration = integration_tests::deadline::FLIGHT;
/// A 10-agent team of a few thousand ticks runs in about a second.
const SMALL_DEADLINE: Duration = integration_tests::deadline::SHORT;
/// How long a team may take to start and write its first ticks.
/// From a member's death to the orchestrator's exit. The orchestrator notices a dead child within
/// ~100 ms and stops the team in under a second, by its own bounded waits; this deadline only ends
/// a stop that hangs, so a loaded machine cannot fail the test.
const KILLED_STOP_DEADLINE: Duration = integration_tests::deadline::REFUSE;
/// From SIGINT to the orchestrator's exit, with every member stopped and reaped. The stop is
/// bounded by the orchestrator's own waits (stop message, SIGTERM, SIGKILL, 300 ms each); this
/// deadline only ends a stop that hangs.
const INTERRUPTED_STOP_DEADLINE: Duration = integration_tests::deadline::REFUSE;
/// A refused member exits as soon as it has read the scenario and looked at the team.
const REFUSE_DEADLINE: Duration = integration_tests::deadline::REFUSE;
/// Rows of telemetry (over 20 ticks of a 10-agent team) to see before breaking a run.
const ROWS_BEFORE_FAULT: usize = 200;

// ---------------------------------------------------------------------------------------------
// Running the binaries
// ---------------------------------------------------------------------------------------------

use integration_tests::support;
use support::*;

#[test]
fn paper40_as_processes_matches_simulate_over_the_designed_graph() {
    let dir = TempDir::new();
    let team = unique_team("paper40");
    let launched = dir.path().join("launch");
    let simulated = dir.path().join("simulate");
    let source = ["--builtin", "paper40"];

    let sim = spawn(&mut simulate(&simulated, &source));
    let out = run(&mut launch(&team, &launched, &source), PAPER40_DEADLINE);
    assert_exit(&out, 0, "launch paper40");
    let sim_out = sim.finish(PAPER40_DEADLINE);
    assert_exit(&sim_out, 0, "simulate paper40");

    let audit = read_json(&launched.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    assert_eq!(audit["agents"], 40, "{audit:#}");
    assert_eq!(audit["ticks"], 20_001, "{audit:#}");
    assert_eq!(audit["fault"], Value::Null, "{audit:#}");
    assert_eq!(audit["violations"], Value::Array(vec![]), "{audit:#}");
    assert_same_file(
        &launched.join("telemetry.csv"),
        &simulated.join("telemetry.csv"),
    );
    assert_same_file(
        &launched.join("scenario.toml"),
        &simulated.join("scenario.toml"),
    );

    // The subscription graph: the orchestrator reads every agent; a follower reads exactly its
    // three in-neighbours; a leader reads no one.
    let subs: BTreeMap<String, Vec<String>> =
        serde_json::from_value(read_json(&launched.join("subscriptions.json")))
            .unwrap_or_else(|e| panic!("subscriptions.json is not a map of lists of names: {e}"));
    let s = flown_scenario(&launched);
    let node = |id: u32| format!("cdm/{team}/agent/{id}");
    let mut expected: BTreeMap<String, Vec<String>> = s
        .agents
        .iter()
        .map(|a| (a.id.to_string(), vec![format!("cdm/{team}/orchestrator")]))
        .collect();
    for f in s.agents.iter().filter(|a| a.role == Role::Follower) {
        let ins = f.in_neighbors.as_deref().unwrap_or_default();
        let distinct: BTreeSet<&u32> = ins.iter().collect();
        assert_eq!(distinct.len(), 3, "follower {} in-neighbours {ins:?}", f.id);
        for n in ins {
            expected
                .get_mut(&n.to_string())
                .unwrap_or_else(|| panic!("follower {} reads unknown agent {n}", f.id))
                .push(node(f.id));
        }
    }
    for list in expected.values_mut() {
        list.sort();
    }
    let leaders: BTreeSet<String> = s
        .agents
        .iter()
        .filter(|a| a.role.is_leader())
        .map(|a| node(a.id))
        .collect();
    let leader_reads: Vec<&String> = subs
        .values()
        .flatten()
        .filter(|n| leaders.contains(*n))
        .collect();
    assert!(
        leader_reads.is_empty(),
        "leaders subscribe to states: {leader_reads:?}"
    );
    let orchestrator = format!("cdm/{team}/orchestrator");
    assert!(
        subs.values().all(|list| list.contains(&orchestrator)),
        "the orchestrator does not read every agent: {subs:#?}"
    );
    let wrong: Vec<String> = expected
        .iter()
        .filter(|(id, want)| subs.get(*id) != Some(*want))
        .map(|(id, want)| {
            format!(
                "agent {id}: subscribers {:?}, expected {want:?}",
                subs.get(id)
            )
        })
        .collect();
    assert!(
        wrong.is_empty() && subs.len() == expected.len(),
        "subscription graph differs from the scenario's ({} keys, expected {}):\n{}",
        subs.len(),
        expected.len(),
        wrong.join("\n")
    );
}

/// Two teams fly at the same time, each exactly as simulated: team names keep them apart.
#[test]
fn two_teams_fly_at_once_without_seeing_each_other() {
    let dir = TempDir::new();
    let source = ["--n", "10", "--t-total", "30"];
    let (a, b) = (unique_team("twin_a"), unique_team("twin_b"));
    let (out_a, out_b, sim) = (
        dir.path().join("a"),
        dir.path().join("b"),
        dir.path().join("sim"),
    );
    let first = spawn(&mut launch(&a, &out_a, &source));
    let second = spawn(&mut launch(&b, &out_b, &source));
    let s = run(&mut simulate(&sim, &source), SMALL_DEADLINE);
    assert_exit(&s, 0, "simulate --n 10");
    let ra = first.finish(SMALL_DEADLINE);
    let rb = second.finish(SMALL_DEADLINE);
    assert_exit(&ra, 0, &format!("launch team {a}"));
    assert_exit(&rb, 0, &format!("launch team {b}"));
    for (team, out) in [(&a, &out_a), (&b, &out_b)] {
        let audit = read_json(&out.join("audit.json"));
        assert_eq!(audit["verdict"], "SAFE", "team {team}: {audit:#}");
        assert_eq!(audit["complete"], true, "team {team}: {audit:#}");
        assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
        let subs = read_json(&out.join("subscriptions.json"));
        let foreign = subs
            .as_object()
            .into_iter()
            .flat_map(|m| m.values())
            .filter_map(Value::as_array)
            .flatten()
            .filter_map(Value::as_str)
            .filter(|n| !n.starts_with(&format!("cdm/{team}/")))
            .collect::<Vec<_>>();
        assert!(foreign.is_empty(), "team {team} sees {foreign:?}");
    }
}

/// Starts a 10-agent team and lets it write some ticks; returns the orchestrator, the flown
/// scenario and the team's footprint (checked to be visible: 11 processes).
fn running_team(team: &str, out: &Path) -> (Running, ScenarioFile, TeamFootprint) {
    // `--on-loss stop`: a dead member is a fault (the default repairs: `loss_launch.rs`).
    let args = ["--n", "10", "--t-total", "600", "--on-loss", "stop"];
    let mut orch = spawn(&mut launch(team, out, &args));
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), ROWS_BEFORE_FAULT);
    let s = flown_scenario(out);
    let procs = team_processes(team);
    assert_eq!(
        procs.len(),
        s.agents.len() + 1,
        "expected the orchestrator and {} members of team {team}: {procs:#?}",
        s.agents.len()
    );
    // Forked from the member template, each member is the orchestrator's own child (adopted):
    // waited for, and its exit status read, by the orchestrator.
    let orch_pid = orch.id();
    for (&pid, args) in procs.iter().filter(|(&pid, _)| pid != orch_pid) {
        assert_eq!(parent_of(pid), Some(orch_pid), "member {pid} {args:?}");
    }
    let footprint = TeamFootprint::record(team, procs.keys().copied());
    footprint.assert_visible(s.agents.len() + 1);
    (orch, s, footprint)
}

/// The parent pid of process `pid` (`/proc/<pid>/stat`, field 4).
fn parent_of(pid: u32) -> Option<u32> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let rest = stat.rsplit_once(')')?.1;
    rest.split_whitespace().nth(1)?.parse().ok()
}

/// The faulted run's audit and telemetry: a fault of `kind` at the first tick the telemetry
/// does not hold; the telemetry holds only whole ticks.
fn assert_stopped_with(out: &Path, s: &ScenarioFile, kind: &str) -> Value {
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "FAULT", "{audit:#}");
    assert_eq!(audit["complete"], false, "{audit:#}");
    let fault = &audit["fault"];
    assert_eq!(fault["kind"], kind, "{audit:#}");
    let ids: BTreeSet<u32> = s.agents.iter().map(|a| a.id).collect();
    let ticks = complete_ticks(&out.join("telemetry.csv"), &ids);
    assert!(
        ticks as usize * ids.len() > ROWS_BEFORE_FAULT,
        "only {ticks} ticks"
    );
    assert_eq!(
        fault["tick"], ticks,
        "the fault's tick is the first tick missing from telemetry.csv: {audit:#}"
    );
    fault.clone()
}

/// SIGKILL of one follower mid-run (`--on-loss stop`): the orchestrator stops the team with a fault naming the
/// agent and the tick, keeps only whole ticks, and leaves no process and no shared memory.
#[test]
fn a_killed_follower_stops_the_team_and_leaves_nothing_behind() {
    let dir = TempDir::new();
    let team = unique_team("kill");
    let out = dir.path().join("run");
    let (orch, s, footprint) = running_team(&team, &out);
    let victim = s
        .agents
        .iter()
        .find(|a| a.role == Role::Follower)
        .map(|a| a.id)
        .expect("the team has a follower");
    let pid = member_pid(&team, victim)
        .unwrap_or_else(|| panic!("no process flies agent {victim} of team {team}"));
    signal(pid, libc::SIGKILL);

    let o = orch.finish(KILLED_STOP_DEADLINE);
    assert_exit(&o, 3, "launch after a follower was killed");
    let fault = assert_stopped_with(&out, &s, "agent-exited");
    assert_eq!(fault["agent"], victim, "{fault:#}");
    let message = fault["message"].as_str().unwrap_or_default();
    assert!(
        message.contains(&format!("agent {victim}")) && message.contains("signal 9"),
        "{fault:#}"
    );
    assert_no_process_of(&team);
    footprint.assert_nothing_left();
}

/// SIGINT to the orchestrator mid-run: it stops every member, exits 3 with an `interrupted`
/// fault within a bounded time, and leaves no process and no shared memory.
#[test]
fn an_interrupted_orchestrator_stops_its_team_and_leaves_nothing_behind() {
    let dir = TempDir::new();
    let team = unique_team("sigint");
    let out = dir.path().join("run");
    let (mut orch, s, footprint) = running_team(&team, &out);
    signal(orch.id(), libc::SIGINT);

    let o = orch.finish(INTERRUPTED_STOP_DEADLINE);
    assert_exit(&o, 3, "launch after SIGINT");
    assert_no_process_of(&team);
    let fault = assert_stopped_with(&out, &s, "interrupted");
    assert_eq!(fault["agent"], Value::Null, "{fault:#}");
    footprint.assert_nothing_left();
}

/// `--no-spawn`: members started by hand. A wrong id, the wrong binary for the role, a
/// different scenario and a team that does not exist are refused (exit 2) without disturbing the
/// team; the right members then fly it exactly as simulated.
#[test]
fn a_hand_started_team_refuses_wrong_members_and_flies_with_the_right_ones() {
    let dir = TempDir::new();
    let team = unique_team("hand");
    let exported = dir.path().join("exported.toml");
    let out = run(
        Command::new(bin("orchestrator"))
            .args(["scenario", "export", "--n", "10", "--out"])
            .arg(&exported),
        SMALL_DEADLINE,
    );
    assert_exit(&out, 0, "scenario export --n 10");
    let text = std::fs::read_to_string(&exported).expect("read the exported scenario");
    let mut file: ScenarioFile = toml::from_str(&text).expect("the exported scenario parses");
    file.t_total_s = 30.0;
    let scenario = write_scenario(dir.path(), "team.toml", &file);
    file.t_total_s = 31.0;
    let other = write_scenario(dir.path(), "other.toml", &file);

    let run_dir = dir.path().join("run");
    let source = ["--scenario", scenario.to_str().unwrap_or_default()];
    let mut orch =
        spawn(launch_loud(&team, &run_dir, &source).args(["--no-spawn", "--join-timeout", "60"]));
    orch.wait_for_output("waits for 10 processes", SMALL_DEADLINE);

    let follower = file
        .agents
        .iter()
        .find(|a| a.role == Role::Follower)
        .map(|a| a.id)
        .expect("a follower");
    let refused = |cmd: &mut Command, what: &str, needles: &[&str]| {
        let o = run(cmd, REFUSE_DEADLINE);
        assert_exit(&o, 2, what);
        assert_stderr_has(&o, what, needles);
    };
    refused(
        &mut member("agent", &scenario, &team, 999),
        "agent --id 999",
        &["agent 999 is not in scenario"],
    );
    refused(
        &mut member("leader", &scenario, &team, follower),
        "leader with a follower's id",
        &[
            format!("agent {follower} is a follower").as_str(),
            "`leader` binary flies primary and secondary leaders",
        ],
    );
    refused(
        &mut member("agent", &other, &team, follower),
        "agent with another scenario",
        &[
            format!("cannot join team {team}").as_str(),
            "differs from the team's",
        ],
    );
    let absent = unique_team("absent");
    refused(
        &mut member("agent", &scenario, &absent, follower),
        "agent of a team that does not exist",
        &[format!("team {absent} does not exist").as_str()],
    );
    assert!(
        !orch.has_exited(),
        "the orchestrator gave up after refused members: {:?}",
        orch.output_so_far()
    );

    let members: Vec<(u32, Running)> = file
        .agents
        .iter()
        .map(|a| {
            let cmd = &mut member(binary_for(a.role), &scenario, &team, a.id);
            (a.id, spawn(cmd))
        })
        .collect();
    let o = orch.finish(SMALL_DEADLINE);
    assert_exit(&o, 0, "launch --no-spawn");
    for (id, m) in members {
        assert_exit(
            &m.finish(SMALL_DEADLINE),
            0,
            &format!("hand-started agent {id}"),
        );
    }
    assert_no_process_of(&team);

    let sim = dir.path().join("sim");
    let so = run(
        &mut simulate(
            &sim,
            &["--scenario", scenario.to_str().expect("a UTF-8 path")],
        ),
        SMALL_DEADLINE,
    );
    assert_exit(&so, 0, "simulate the hand-started team's scenario");
    let audit = read_json(&run_dir.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    assert_same_file(&run_dir.join("telemetry.csv"), &sim.join("telemetry.csv"));
}

/// A plan far too fast for the quadcopters makes a member's controller refuse (eq. 46 near a
/// singular M). As processes the run must end exactly as in-process: every tick up to the fault
/// in telemetry, byte for byte, the same agent and tick named, exit 3.
#[test]
fn a_control_fault_ends_a_launch_exactly_like_simulate() {
    let dir = TempDir::new();
    let source = ["--n", "40", "--t-total", "10", "--no-figures"];
    let (out, sim) = (dir.path().join("launch"), dir.path().join("sim"));
    let s = run(&mut simulate(&sim, &source), SMALL_DEADLINE);
    assert_exit(&s, 3, "simulate of a 10 s paper40");
    // Follower 20 (no ancestor of agent 39, whose in-neighbours are the primaries) publishes
    // its tick 0 late, as a process slow to start on a loaded machine does: agent 39 runs
    // ahead to its fault meanwhile, and the team must still record every tick before it.
    let mut l = launch(&unique_team("ctlfault"), &out, &source);
    l.env(cdm_process::fault_inject::ENV, "20:pause@0");
    let l = run(&mut l, SMALL_DEADLINE);
    assert_exit(&l, 3, "launch of a 10 s paper40");
    let (fs, fl) = (
        read_json(&sim.join("audit.json")),
        read_json(&out.join("audit.json")),
    );
    for key in ["kind", "agent", "tick"] {
        assert_eq!(
            fs["fault"][key], fl["fault"][key],
            "fault.{key}: {fs:#} vs {fl:#}"
        );
    }
    assert_eq!(fl["fault"]["kind"], "control", "{fl:#}");
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
}

/// Determinism does not depend on the clock window: strict lockstep (1), small windows and the
/// benchmarks' sizes (64; the default 256 is every other launch test) give the same telemetry
/// as `simulate`, byte for byte.
#[test]
fn every_window_gives_the_telemetry_of_simulate() {
    let dir = TempDir::new();
    let source = ["--n", "40", "--max-ticks", "600", "--no-figures"];
    let sim = dir.path().join("sim");
    assert_exit(
        &run(&mut simulate(&sim, &source), SMALL_DEADLINE),
        0,
        "simulate --n 40",
    );
    assert_windows_match_simulate(
        dir.path(),
        &source,
        &sim,
        &["1", "4", "64"],
        "w",
        SMALL_DEADLINE,
    );
}

/// Scale regression: 250 processes start, fly a few ticks of their plan, and match the engine.
#[test]
fn a_250_process_team_flies_a_few_ticks_like_simulate() {
    let dir = TempDir::new();
    let source = ["--n", "250", "--max-ticks", "20", "--no-figures"];
    let (out, sim) = (dir.path().join("launch"), dir.path().join("sim"));
    let s = run(&mut simulate(&sim, &source), SMALL_DEADLINE);
    assert_exit(&s, 0, "simulate --n 250");
    let l = run(
        &mut launch(&unique_team("n250"), &out, &source),
        integration_tests::deadline::FLIGHT,
    );
    assert_exit(&l, 0, "launch --n 250");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["agents"], 250, "{audit:#}");
    assert_eq!(audit["ticks"], 21, "{audit:#}");
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
}
