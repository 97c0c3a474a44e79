//! The live safety audit catches what it claims to catch (Sec. VI, Theorem 3), with the real
//! `orchestrator` binary:
//!
//! - deformation: paper40 with lambda_CD,min = 0.6 is flagged at the first tick where
//!   lambda_1(U_D) falls under 0.6 (eq. 37), naming the three primary leaders;
//! - tracking: paper40 flown in 25 s (T_threshold is about 34 s) is flagged for exactly the
//!   agents and ticks where ||r_i - r_i,HT||_2 first exceeds delta (eq. 34), recomputed here
//!   from telemetry.csv;
//! - containment: the same rushed flight is flagged for exactly the followers and ticks where a
//!   follower first leaves the containment prism of Theorem 3, recomputed from telemetry.csv;
//! - collision: a follower placed 2 m from another (2 eps = 3 m) is flagged at tick 0 naming
//!   exactly that pair, in `simulate` and, as processes, in `launch`.
//!
//! Every case also runs with `--stop-on-violation`: exit 1, verdict UNSAFE, telemetry kept up to
//! and including the tick of the first violation, and nothing after it.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use cdm_model::formation::Role;
use cdm_model::plan::Segment;
use cdm_model::step::tick_time;
use cdm_scenario::{Checks, Scenario, ScenarioFile};
use integration_tests::{bin, describe, paper40, run, unique_team, write_scenario, TempDir};
use serde_json::Value;

/// A paper40 flight in-process takes about a second in release; the rest is slack.
const DEADLINE: Duration = integration_tests::deadline::FLIGHT;

fn orchestrator(args: &[&str]) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    c
}

/// `simulate --scenario FILE --out OUT --no-figures` plus `extra`; returns the output.
fn simulate(scenario: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut c = orchestrator(&["simulate", "--no-figures"]);
    c.arg("--scenario").arg(scenario).arg("--out").arg(out);
    c.args(extra);
    run(&mut c, DEADLINE)
}

fn audit(dir: &Path) -> Value {
    let p = dir.join("audit.json");
    let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("read {}: {e}", p.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("parse {}: {e}", p.display()))
}

/// (tick, agents) of every violation of one kind, in the report's order.
fn violations(a: &Value, kind: &str) -> Vec<(u64, Vec<u32>)> {
    a["violations"]
        .as_array()
        .expect("violations is an array")
        .iter()
        .filter(|v| v["kind"] == kind)
        .map(|v| {
            let agents = v["agents"]
                .as_array()
                .expect("agents")
                .iter()
                .map(|x| x.as_u64().expect("agent id") as u32)
                .collect();
            (v["tick"].as_u64().expect("tick"), agents)
        })
        .collect()
}

/// Every violation record carries the fields its log line has.
fn assert_records_complete(a: &Value) {
    for v in a["violations"].as_array().expect("violations") {
        for field in ["kind", "tick", "t_s", "agents", "value", "limit"] {
            assert!(v.get(field).is_some(), "violation {v} lacks `{field}`");
        }
    }
}

/// One telemetry row: tick, id, position, desired position.
struct Row {
    tick: u64,
    id: u32,
    r: [f64; 3],
    ht: [f64; 3],
}

fn telemetry(dir: &Path) -> Vec<Row> {
    let p = dir.join("telemetry.csv");
    let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("read {}: {e}", p.display()));
    text.lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let x = |i: usize| f[i].parse::<f64>().expect("number");
            Row {
                tick: f[0].parse().expect("tick"),
                id: f[2].parse().expect("id"),
                r: [x(4), x(5), x(6)],
                ht: [x(10), x(11), x(12)],
            }
        })
        .collect()
}

fn assert_exit(out: &Output, code: i32) {
    assert_eq!(out.status.code(), Some(code), "{}", describe(out));
}

/// The stopped run: UNSAFE, not complete, every violation at `tick`, telemetry through `tick`.
fn assert_stopped_at(dir: &Path, tick: u64, agents: usize) {
    let a = audit(dir);
    assert_eq!(a["verdict"], "UNSAFE");
    assert_eq!(a["stopped_on_violation"], true);
    assert_eq!(a["complete"], false);
    assert_eq!(a["ticks"].as_u64(), Some(tick + 1));
    for v in a["violations"].as_array().expect("violations") {
        assert_eq!(v["tick"].as_u64(), Some(tick), "{v}");
    }
    let rows = telemetry(dir);
    assert_eq!(rows.len() as u64, (tick + 1) * agents as u64);
    assert_eq!(rows.last().map(|r| r.tick), Some(tick));
}

#[test]
fn deformation_is_flagged_where_lambda1_first_falls_under_lambda_cd_min() {
    let dir = TempDir::new();
    let mut f = paper40();
    f.lambda_cd_min = Some(0.6);
    let scenario = write_scenario(dir.path(), "unsafe-plan.toml", &f);
    // Where lambda_1(U_D) first falls under 0.6, scanned tick by tick (eq. 37).
    let s = Scenario::from_file(f.clone(), "unsafe-plan.toml", Checks::Full).expect("valid");
    let lambda1 = |tick: u64| {
        let t = tick_time(tick, s.dt_s());
        let sp = s.plan.quintic.derivatives(t, Segment::Motion)[0];
        s.plan.lambdas_at_s(sp).expect("leaders not collinear")[0]
    };
    let first = (0..=s.last_tick())
        .find(|&k| lambda1(k) < 0.6)
        .expect("paper40's lambda_1 falls to 0.5431");
    assert!(first > 0 && lambda1(first - 1) >= 0.6);

    let full = dir.path().join("full");
    let out = simulate(&scenario, &full, &["--every", "100"]);
    assert_exit(&out, 1);
    let a = audit(&full);
    assert_eq!(a["verdict"], "UNSAFE");
    assert_records_complete(&a);
    assert_eq!(violations(&a, "deformation"), vec![(first, vec![1, 2, 3])]);
    let v = a["violations"]
        .as_array()
        .expect("violations")
        .iter()
        .find(|v| v["kind"] == "deformation")
        .expect("deformation record");
    assert_eq!(v["limit"].as_f64(), Some(0.6));
    assert!(v["value"].as_f64().expect("value") < 0.6);
    assert!((v["t_s"].as_f64().expect("t_s") - first as f64 * 0.01).abs() < 1e-9);
    // Only the plan is unsafe: nobody collides, leaves the prism or strays beyond delta.
    assert_eq!(a["violations"].as_array().map(Vec::len), Some(1), "{a}");
    // The log line carries the same fields.
    let stderr = String::from_utf8_lossy(&out.stderr);
    let line = stderr
        .lines()
        .find(|l| l.contains("safety violation") && l.contains("deformation"))
        .unwrap_or_else(|| panic!("no violation log line:\n{stderr}"));
    assert!(line.contains(&format!("tick={first}")), "{line}");
    assert!(line.contains("agents=[1, 2, 3]"), "{line}");
    assert!(line.contains("limit=0.6"), "{line}");

    let stopped = dir.path().join("stopped");
    let out = simulate(&scenario, &stopped, &["--stop-on-violation"]);
    assert_exit(&out, 1);
    assert_stopped_at(&stopped, first, 40);
    assert_eq!(
        violations(&audit(&stopped), "deformation"),
        vec![(first, vec![1, 2, 3])]
    );
}

#[test]
fn tracking_is_flagged_for_the_agents_and_ticks_that_exceed_delta() {
    let dir = TempDir::new();
    let mut f = paper40();
    f.t_total_s = 25.0; // T_threshold of paper40 is about 34 s (README).
    let scenario = write_scenario(dir.path(), "rushed.toml", &f);
    let full = dir.path().join("full");
    let out = simulate(&scenario, &full, &[]);
    assert_exit(&out, 1);
    let a = audit(&full);
    assert_records_complete(&a);
    let delta = a["delta_m"].as_f64().expect("delta_m");
    // Every onset of ||r - r_HT||_2 > delta, per agent, from telemetry (eq. 34).
    let mut over: BTreeMap<u32, bool> = BTreeMap::new();
    let mut expected = Vec::new();
    for r in telemetry(&full) {
        let e = [r.r[0] - r.ht[0], r.r[1] - r.ht[1], r.r[2] - r.ht[2]];
        let bad = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt() > delta;
        let was = over.insert(r.id, bad).unwrap_or(false);
        if bad && !was {
            expected.push((r.tick, vec![r.id]));
        }
    }
    assert!(
        !expected.is_empty(),
        "T = 25 s should break delta = {delta}"
    );
    let s = Scenario::from_file(f.clone(), "rushed.toml", Checks::Member).expect("valid");
    for (_, ids) in &expected {
        assert_eq!(s.role_of(ids[0]), Some(Role::Follower), "agent {ids:?}");
    }
    let mut got = violations(&a, "tracking");
    got.sort();
    expected.sort();
    assert_eq!(got, expected);

    let first = expected[0].0;
    let at_first: Vec<_> = expected
        .iter()
        .filter(|(t, _)| *t == first)
        .cloned()
        .collect();
    let stopped = dir.path().join("stopped");
    let out = simulate(&scenario, &stopped, &["--stop-on-violation"]);
    assert_exit(&out, 1);
    assert_stopped_at(&stopped, first, 40);
    let mut got = violations(&audit(&stopped), "tracking");
    got.sort();
    assert_eq!(got, at_first);
}

/// paper40 with follower 40 moved 2 m from follower 21 (2 eps = 3 m), graph re-synthesised.
fn crowded(dir: &Path) -> std::path::PathBuf {
    let mut f: ScenarioFile = paper40();
    let pos = |id: u32| {
        f.agents
            .iter()
            .find(|a| a.id == id)
            .map(|a| a.position)
            .expect("agent")
    };
    let (a, b) = (pos(21), pos(22));
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let p = [
        a[0] + 2.0 * d[0] / n,
        a[1] + 2.0 * d[1] / n,
        a[2] + 2.0 * d[2] / n,
    ];
    for ag in &mut f.agents {
        ag.in_neighbors = None;
        if ag.id == 40 {
            ag.position = p;
        }
    }
    write_scenario(dir, "crowded.toml", &f)
}

fn assert_collision_at_tick0(dir: &Path) {
    let a = audit(dir);
    assert_records_complete(&a);
    assert_eq!(violations(&a, "collision"), vec![(0, vec![21, 40])]);
    let v = a["violations"]
        .as_array()
        .expect("violations")
        .iter()
        .find(|v| v["kind"] == "collision")
        .expect("collision record");
    assert!(
        (v["value"].as_f64().expect("value") - 2.0).abs() < 1e-6,
        "{v}"
    );
    assert_eq!(v["limit"].as_f64(), Some(3.0));
}

#[test]
fn collision_at_tick_zero_names_exactly_the_pair() {
    let dir = TempDir::new();
    let scenario = crowded(dir.path());
    let full = dir.path().join("full");
    let out = simulate(&scenario, &full, &["--every", "100"]);
    assert_exit(&out, 1);
    assert_collision_at_tick0(&full);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.lines().any(|l| l.contains("safety violation")
            && l.contains("kind=\"collision\"")
            && l.contains("tick=0")
            && l.contains("agents=[21, 40]")),
        "no collision log line:\n{stderr}"
    );

    let stopped = dir.path().join("stopped");
    let out = simulate(&scenario, &stopped, &["--stop-on-violation"]);
    assert_exit(&out, 1);
    assert_stopped_at(&stopped, 0, 40);
    assert_collision_at_tick0(&stopped);
}

#[test]
fn launch_audits_live_and_stops_at_the_first_violation() {
    let dir = TempDir::new();
    let scenario = crowded(dir.path());
    let sim = dir.path().join("sim");
    assert_exit(&simulate(&scenario, &sim, &["--stop-on-violation"]), 1);
    let launched = dir.path().join("launched");
    let team = unique_team("audit-stop");
    let source = ["--scenario", scenario.to_str().unwrap_or_default()];
    let mut c = integration_tests::launch(&team, &launched, &source);
    c.args(["--no-figures", "--stop-on-violation"]);
    let out = run(&mut c, DEADLINE);
    assert_exit(&out, 1);
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), "UNSAFE");
    assert_stopped_at(&launched, 0, 40);
    assert_collision_at_tick0(&launched);
    assert_eq!(
        violations(&audit(&launched), "tracking"),
        violations(&audit(&sim), "tracking")
    );
    let bytes = |d: &Path| std::fs::read(d.join("telemetry.csv")).expect("telemetry");
    assert!(
        bytes(&launched) == bytes(&sim),
        "launch and simulate telemetry differ"
    );
}

#[test]
fn containment_is_flagged_for_the_followers_and_ticks_outside_the_prism() {
    let dir = TempDir::new();
    let mut f = paper40();
    f.t_total_s = 25.0;
    let scenario = write_scenario(dir.path(), "rushed.toml", &f);
    let full = dir.path().join("full");
    assert_exit(&simulate(&scenario, &full, &[]), 1);
    let a = audit(&full);
    let half_height = a["delta_m"].as_f64().expect("delta_m") + a["eps_m"].as_f64().expect("eps");
    let s = Scenario::from_file(f.clone(), "rushed.toml", Checks::Member).expect("valid");
    let members = &s.formation.members;
    let index: BTreeMap<u32, usize> = members.iter().enumerate().map(|(k, m)| (m.id, k)).collect();
    // Theorem 3's prism over the leading polygon's desired positions, tick by tick, and every
    // onset of a follower outside it (beyond a side face or a base).
    let rows = telemetry(&full);
    let mut outside: BTreeMap<u32, bool> = BTreeMap::new();
    let mut expected = Vec::new();
    for tick_rows in rows.chunks(members.len()) {
        let mut ht = vec![cdm_math::Vec3::zeros(); members.len()];
        for r in tick_rows {
            ht[index[&r.id]] = cdm_math::vec3(r.ht);
        }
        let verts: Vec<_> = s.formation.polygon.iter().map(|&k| ht[k]).collect();
        let normal = (verts[1] - verts[0])
            .cross(&(verts[2] - verts[0]))
            .normalize();
        let prism = cdm_model::safety::Prism::new(verts, normal, half_height);
        for r in tick_rows {
            if members[index[&r.id]].role != Role::Follower {
                continue;
            }
            let p = cdm_math::vec3(r.r);
            let bad = prism.side_distance(&p) < 0.0 || prism.height(&p).abs() > half_height;
            let was = outside.insert(r.id, bad).unwrap_or(false);
            if bad && !was {
                expected.push((r.tick, vec![r.id]));
            }
        }
    }
    assert!(!expected.is_empty(), "T = 25 s should leave the prism");
    let mut got = violations(&a, "containment");
    got.sort();
    expected.sort();
    assert_eq!(got, expected);
}
