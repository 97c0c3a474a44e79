//! Missions: take off, fly several deformations, land, certified as one flight.
//!
//! - A 10-member mission (take-off, 3 segments, landing) flies the same telemetry, byte for
//!   byte, as 10 processes (lockstep windows 1 and 256) as in `simulate`.
//! - Its leaders are at each segment's goals at its end and half way between at its middle
//!   (computed here from the waypoints alone: s(T/2) = 1/2 for eq. 16's quintic), and every
//!   member is on the ground at t = 0 and at the end.
//! - A mission whose segment 2 squeezes the leaders nearly collinear is UNSAFE, naming segment 2.
//! - Bad mission tables are refused with exit 2, naming the phase and the field.
//! - The same mission with its members started by hand (`launch --no-spawn`, one process each)
//!   flies `simulate`'s telemetry byte for byte; a tiny mission in real time is SAFE and its
//!   telemetry covers the whole mission.
//!
//! How to run: `cargo test --release -p integration-tests --test simulate -- mission::`.

use integration_tests::support;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

use cdm_scenario::ScenarioFile;
use integration_tests::{bin, run, spawn, unique_team, write_scenario, Running, TempDir};
use support::{
    assert_exit, assert_no_process_of, assert_same_file, assert_stderr_has,
    assert_windows_match_simulate, binary_for, launch, launch_loud, member, mission, read_json,
    simulate, GROUND_Z, SEGMENT_2, SEGMENT_3,
};

const DEADLINE: std::time::Duration = integration_tests::deadline::FLIGHT;
/// `orchestrator plan --scenario SCENARIO --json JSON`.
fn plan_json(scenario: &Path, json: &Path) -> std::process::Output {
    let (scenario, json) = (scenario.to_str().unwrap(), json.to_str().unwrap());
    orchestrator(&["plan", "--scenario", scenario, "--json", json])
}

fn orchestrator(args: &[&str]) -> std::process::Output {
    run(Command::new(bin("orchestrator")).args(args), DEADLINE)
}

/// telemetry.csv as rows of name -> text, in file order.
fn telemetry(dir: &Path) -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(dir.join("telemetry.csv")).expect("telemetry.csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    lines
        .map(|l| {
            (header.iter().map(|h| h.to_string()))
                .zip(l.split(',').map(str::to_string))
                .collect()
        })
        .collect()
}

fn num(row: &BTreeMap<String, String>, key: &str) -> f64 {
    row[key]
        .parse()
        .unwrap_or_else(|e| panic!("{key} = {}: {e}", row[key]))
}

#[test]
fn a_mission_flies_in_processes_as_in_simulate_and_is_certified_per_phase() {
    let dir = TempDir::new();
    let scenario = write_scenario(dir.path(), "mission.toml", &mission());
    let json = dir.path().join("cert.json");
    let plan = plan_json(&scenario, &json);
    assert_exit(&plan, 0, "plan of the mission");
    let cert = read_json(&json);
    let names: Vec<&str> = (cert["segments"].as_array().expect("segments"))
        .iter()
        .map(|r| r["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        ["takeoff", "segment 1", "segment 2", "segment 3", "landing"],
        "{cert:#}"
    );
    assert_eq!(cert["t_total_s"], 194.0, "{cert:#}");
    let source = ["--scenario", scenario.to_str().unwrap(), "--no-figures"];
    let sim = dir.path().join("sim");
    assert_exit(&run(&mut simulate(&sim, &source), DEADLINE), 0, "simulate");
    assert_windows_match_simulate(
        dir.path(),
        &source,
        &sim,
        &["1", "256"],
        "mission",
        DEADLINE,
    );
    let audit = read_json(&dir.path().join("mission1").join("audit.json"));
    assert_eq!(audit["ticks"], 20_401, "{audit:#}");
    // README "By hand: one terminal per process": the same mission with every member started
    // by hand as its own process flies the same telemetry, byte for byte.
    let by_hand = dir.path().join("by-hand");
    fly_by_hand(&scenario, &by_hand);
    assert_same_file(&by_hand.join("telemetry.csv"), &sim.join("telemetry.csv"));
}

/// `launch --no-spawn` on `scenario` into `out`, with each member started by hand (`leader` or
/// `agent`, one process each, on the run directory's scenario.toml as the README says); every
/// process exits 0 and nothing of the team is left.
fn fly_by_hand(scenario: &Path, out: &Path) {
    let team = unique_team("mission_hand");
    let source = ["--scenario", scenario.to_str().unwrap(), "--no-figures"];
    let mut launch = launch_loud(&team, out, &source);
    let mut orch = spawn(launch.args(["--no-spawn", "--join-timeout", "60"]));
    orch.wait_for_output("waits for", DEADLINE);
    let file = support::flown_scenario(out);
    let flown = out.join("scenario.toml");
    let members: Vec<(u32, Running)> = (file.agents.iter())
        .map(|a| {
            let cmd = &mut member(binary_for(a.role), &flown, &team, a.id);
            (a.id, spawn(cmd))
        })
        .collect();
    assert_exit(
        &orch.finish(DEADLINE),
        0,
        "launch --no-spawn of the mission",
    );
    for (id, m) in members {
        assert_exit(&m.finish(DEADLINE), 0, &format!("hand-started member {id}"));
    }
    assert_no_process_of(&team);
}

/// Real time: a tiny mission (the lab mission's take-off and its one segment,
/// 6.5 s) launched with `--realtime` is SAFE and complete, exit 0, and its telemetry covers the
/// whole mission: every member at every audit instant from t = 0, on the ground, to the
/// mission's end. Nothing about how fast it ran.
#[test]
fn a_tiny_mission_flies_safe_in_real_time_over_the_whole_mission() {
    let dir = TempDir::new();
    let mut f = support::lab_mission();
    f.landing = None;
    let scenario = write_scenario(dir.path(), "lab.toml", &f);
    let out = dir.path().join("rt");
    let team = unique_team("mission_rt");
    let source = [
        "--scenario",
        scenario.to_str().unwrap(),
        "--no-figures",
        "--realtime",
    ];
    let o = run(&mut launch(&team, &out, &source), DEADLINE);
    assert_exit(&o, 0, "launch --realtime of a tiny mission");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    // Take-off 4 s and segment 1's 2.5 s at comm_hz 50: ticks 0..=325.
    let rows = telemetry(&out);
    let times: BTreeSet<String> = rows.iter().map(|r| r["t"].clone()).collect();
    assert_eq!(times.len(), 326, "{audit:#}");
    assert_eq!(rows.len(), 326 * f.agents.len(), "{audit:#}");
    let t_end = rows.iter().map(|r| num(r, "t")).fold(f64::MIN, f64::max);
    assert!((t_end - 6.5).abs() < 1e-9, "telemetry ends at t = {t_end}");
    for r in rows.iter().filter(|r| num(r, "t") == 0.0) {
        assert_eq!(num(r, "z"), 0.0, "{r:?} is not on the ground at t = 0");
    }
    assert_no_process_of(&team);
}

#[test]
fn the_leaders_reach_every_waypoint_and_every_member_starts_and_ends_on_the_ground() {
    let dir = TempDir::new();
    let f = mission();
    let scenario = write_scenario(dir.path(), "mission.toml", &f);
    let sim = dir.path().join("sim");
    let source = ["--scenario", scenario.to_str().unwrap(), "--no-figures"];
    assert_exit(&run(&mut simulate(&sim, &source), DEADLINE), 0, "simulate");
    let rows = telemetry(&sim);
    // Primary leaders by ascending id, and their waypoints: start, then each segment's goals.
    let mut primaries: Vec<&cdm_scenario::AgentSpec> =
        (f.agents.iter()).filter(|a| a.goal.is_some()).collect();
    primaries.sort_by_key(|a| a.id);
    let start: Vec<[f64; 3]> = primaries.iter().map(|a| a.position).collect();
    let goal1: Vec<[f64; 3]> = primaries.iter().map(|a| a.goal.unwrap()).collect();
    // (segment, its start time, end time, waypoints before and after).
    let segments = [
        (1, 41.0, 101.0, start.clone(), goal1.clone()),
        (2, 102.0, 132.0, goal1, SEGMENT_2.to_vec()),
        (3, 133.0, 163.0, SEGMENT_2.to_vec(), SEGMENT_3.to_vec()),
    ];
    let at = |t: f64, id: u32| {
        let tick = (t * 100.0).round() as u64;
        rows.iter()
            .find(|r| r["tick"] == tick.to_string() && r["id"] == id.to_string())
            .unwrap_or_else(|| panic!("no row of agent {id} at t = {t}"))
    };
    for (n, t0, t1, from, to) in &segments {
        for (k, a) in primaries.iter().enumerate() {
            let mid: [f64; 3] = std::array::from_fn(|c| 0.5 * (from[k][c] + to[k][c]));
            for (t, want) in [(0.5 * (t0 + t1), mid), (*t1, to[k])] {
                let r = at(t, a.id);
                for (c, axis) in ["x", "y", "z"].iter().enumerate() {
                    let ht = num(r, &format!("{axis}_ht"));
                    let flown = num(r, axis);
                    assert!(
                        (ht - want[c]).abs() < 1e-6 && (flown - want[c]).abs() < 1e-3,
                        "segment {n}, leader {} at t = {t}: {axis}_ht {ht}, {axis} {flown}, want {}",
                        a.id,
                        want[c]
                    );
                }
            }
        }
    }
    let last = rows.last().expect("rows")["tick"].clone();
    for r in &rows {
        if r["tick"] == "0" {
            assert_eq!(num(r, "z"), GROUND_Z, "agent {} at t = 0: {r:?}", r["id"]);
        }
        if r["tick"] == last {
            let z = num(r, "z");
            assert!(
                (z - GROUND_Z).abs() < 0.005,
                "agent {} at the end: z = {z}",
                r["id"]
            );
            let z_ht = num(r, "z_ht");
            assert!(
                (z_ht - GROUND_Z).abs() < 1e-9,
                "agent {} at the end: {r:?}",
                r["id"]
            );
        }
    }
}

#[test]
fn a_mission_squeezing_its_leaders_in_segment_2_is_unsafe_and_names_segment_2() {
    let dir = TempDir::new();
    let mut f = mission();
    // Segment 2 ends with the leaders 20 m off a line 200 m long: a sliver.
    f.segments[0].goals = vec![
        [100.0, 200.0, 540.0],
        [300.0, 200.0, 540.0],
        [200.0, 220.0, 540.0],
    ];
    let scenario = write_scenario(dir.path(), "squeezed.toml", &f);
    let json = dir.path().join("cert.json");
    let plan = plan_json(&scenario, &json);
    assert_exit(&plan, 1, "plan of the squeezed mission");
    let stdout = String::from_utf8_lossy(&plan.stdout);
    assert!(
        stdout.contains("UNSAFE") && stdout.contains("segment 2: lambda_1 min"),
        "{stdout}"
    );
    let cert = read_json(&json);
    let seg2 = &cert["segments"][2];
    assert_eq!(seg2["name"], "segment 2", "{cert:#}");
    let squeezed = seg2["lambda1_min"].as_f64().unwrap();
    let first = cert["segments"][1]["lambda1_min"].as_f64().unwrap();
    assert!(squeezed < 0.1 * first, "{cert:#}");
    assert_eq!(seg2["verdict"], "UNSAFE", "{cert:#}");
    assert_eq!(cert["verdict"], "UNSAFE", "{cert:#}");
}

#[test]
fn bad_mission_tables_are_refused_naming_the_phase_and_field() {
    let dir = TempDir::new();
    type Edit = fn(&mut ScenarioFile);
    let cases: [(&str, Edit, &[&str]); 8] = [
        (
            "t_s <= 0",
            |f| f.segments[1].t_s = 0.0,
            &["segment 3.t_s", "> 0"],
        ),
        (
            "negative hold",
            |f| f.segments[0].hold_s = Some(-1.0),
            &["segment 2.hold_s", ">= 0"],
        ),
        (
            "two goals",
            |f| {
                f.segments[0].goals.pop();
            },
            &["segment 2.goals", "3 primary leaders"],
        ),
        (
            "collinear waypoint",
            |f| {
                f.segments[1].goals =
                    vec![[0.0, 0.0, 600.0], [100.0, 0.0, 600.0], [200.0, 0.0, 600.0]];
            },
            &["collinear", "segment 3's goals"],
        ),
        (
            "ground above",
            |f| f.takeoff.as_mut().unwrap().ground_z_m = 950.0,
            &["takeoff.ground_z_m", "not below agent"],
        ),
        (
            "landing ground above",
            |f| f.landing.as_mut().unwrap().ground_z_m = 700.0,
            &["landing.ground_z_m", "not below agent"],
        ),
        (
            "ground spots too close",
            |f| f.eps_m = 30.0,
            &["takeoff.ground_z_m", "ground spots", "closer than 2 eps"],
        ),
        (
            "non-finite",
            |f| f.landing.as_mut().unwrap().t_s = f64::NAN,
            &["landing.t_s"],
        ),
    ];
    for (what, edit, needles) in cases {
        let mut f = mission();
        edit(&mut f);
        let path = write_scenario(dir.path(), "bad.toml", &f);
        let r = orchestrator(&["plan", "--scenario", path.to_str().unwrap()]);
        assert_exit(&r, 2, what);
        assert_stderr_has(&r, what, needles);
    }
}

/// The built-in mission of the README is SAFE and flies from the ground to the ground.
#[test]
fn the_builtin_mission_is_certified_safe() {
    let r = orchestrator(&["plan", "--builtin", "paper40-mission", "--quiet"]);
    assert_exit(&r, 0, "plan --builtin paper40-mission");
    assert_eq!(String::from_utf8_lossy(&r.stdout).trim(), "SAFE");
}
