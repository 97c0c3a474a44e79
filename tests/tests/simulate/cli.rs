//! The orchestrator's offline commands on the paper's 40-agent scenario: `plan` (the pre-flight
//! certificate and its exit code), `simulate` (the run directory) and `scenario export`.
//!
//! paper40 (`--builtin paper40`, the default) has T_threshold ~ 34.1 s and t_total 200 s; one
//! `plan` takes a second or two in release, a `simulate` of 6,001 ticks about half a second.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use cdm_model::formation::Role;
use cdm_scenario::ScenarioFile;
use integration_tests::{bin, describe, run, spawn, write_text, TempDir};
use serde_json::Value;

/// A plan or a short simulate takes seconds; the deadline only keeps a hang from stalling CI.
const DEADLINE: Duration = integration_tests::deadline::FLIGHT;

/// Keys every certificate (`plan --json`) carries.
const CERTIFICATE_KEYS: [&str; 13] = [
    "verdict",
    "reasons",
    "lambda1_min",
    "t_lambda1_min_s",
    "lambda_cd_min",
    "d_b_m",
    "d_s_m",
    "delta_max_m",
    "delta_m",
    "t_threshold_s",
    "t_total_s",
    "gains_stability_margin",
    "max_follower_deviation_m",
];

/// Keys every audit.json carries.
const AUDIT_KEYS: [&str; 17] = [
    "verdict",
    "agents",
    "ticks",
    "complete",
    "t_total_s",
    "lambda1_min",
    "lambda_cd_min",
    "d_b_m",
    "d_s_m",
    "delta_max_m",
    "delta_m",
    "max_deviation_m",
    "max_deviation_inf_m",
    "min_separation_m",
    "min_boundary_distance_m",
    "violations",
    "fault",
];

const HEADER: &str = "tick,t,id,role,x,y,z,vx,vy,vz,x_ht,y_ht,z_ht";

fn orchestrator(args: &[&str]) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    c
}

fn path_str(p: &Path) -> &str {
    p.to_str()
        .unwrap_or_else(|| panic!("{} is not UTF-8", p.display()))
}

fn assert_exit(out: &Output, code: i32, what: &str) {
    assert_eq!(
        out.status.code(),
        Some(code),
        "{what}: expected exit {code}\n{}",
        describe(out)
    );
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()))
}

/// `orchestrator plan ARGS --json DIR/NAME.json`: the output and the certificate.
fn plan(dir: &Path, name: &str, args: &[&str]) -> (Output, Value) {
    let json = dir.join(format!("{name}.json"));
    let mut cmd = orchestrator(&["plan"]);
    cmd.args(args).arg("--json").arg(&json);
    let out = run(&mut cmd, DEADLINE);
    assert!(
        json.is_file(),
        "plan {args:?} wrote no certificate\n{}",
        describe(&out)
    );
    let c = read_json(&json);
    for k in CERTIFICATE_KEYS {
        assert!(c.get(k).is_some(), "certificate lacks `{k}`: {c:#}");
    }
    (out, c)
}

fn number(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("`{key}` is not a number: {v:#}"))
}

/// Every file of a directory with its contents.
fn contents(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .flatten()
        .map(|e| {
            let bytes = std::fs::read(e.path())
                .unwrap_or_else(|err| panic!("cannot read {}: {err}", e.path().display()));
            (e.file_name().to_string_lossy().into_owned(), bytes)
        })
        .collect()
}

fn telemetry_lines(run_dir: &Path) -> Vec<String> {
    let path = run_dir.join("telemetry.csv");
    std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
        .lines()
        .map(str::to_string)
        .collect()
}

/// paper40 at its t_total (200 s) is SAFE (exit 0); at 25 s, below T_threshold, it is UNSAFE
/// (exit 1) with a reason naming T_threshold.
#[test]
fn plan_certifies_paper40_and_refuses_a_plan_faster_than_t_threshold() {
    let dir = TempDir::new();
    let (out, safe) = plan(dir.path(), "safe", &["--builtin", "paper40"]);
    assert_exit(&out, 0, "plan paper40");
    assert_eq!(safe["verdict"], "SAFE", "{safe:#}");
    assert_eq!(safe["reasons"], Value::Array(vec![]), "{safe:#}");
    assert_eq!(number(&safe, "t_total_s"), 200.0);
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("verdict: SAFE"),
        "{}",
        describe(&out)
    );
    assert!(
        number(&safe, "max_follower_deviation_m") <= number(&safe, "delta_m")
            && number(&safe, "delta_m") <= number(&safe, "delta_max_m"),
        "a SAFE plan keeps E_max <= delta <= delta_max: {safe:#}"
    );

    let (out, fast) = plan(
        dir.path(),
        "fast",
        &["--builtin", "paper40", "--t-total", "25"],
    );
    assert_exit(&out, 1, "plan paper40 --t-total 25");
    assert_eq!(fast["verdict"], "UNSAFE", "{fast:#}");
    assert_eq!(number(&fast, "t_total_s"), 25.0);
    let threshold = number(&fast, "t_threshold_s");
    assert!(
        25.0 < threshold && threshold <= 200.0,
        "T_threshold {threshold} s must lie between the UNSAFE 25 s and the SAFE 200 s"
    );
    // T_threshold is found by bisection to 0.1 % (cdm_certificates::certificate::t_threshold), starting from
    // the scenario's t_total: two plans agree to that precision, not to the last bit.
    let other = number(&safe, "t_threshold_s");
    assert!(
        (threshold - other).abs() <= 1e-3 * threshold.max(other),
        "T_threshold {threshold} s at t_total 25 s, {other} s at 200 s"
    );
    let reasons: Vec<&str> = fast["reasons"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
        .collect();
    assert!(
        reasons
            .iter()
            .any(|r| r.contains("T_threshold") && r.contains("25")),
        "no reason names T_threshold and t_total 25: {reasons:?}"
    );
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("verdict: UNSAFE"),
        "{}",
        describe(&out)
    );
}

/// E_max, the largest follower deviation of the plan (eq. 34), falls as the travel time grows.
#[test]
fn the_largest_follower_deviation_falls_as_t_total_grows() {
    let dir = TempDir::new();
    let deviations: Vec<(&str, f64)> = ["100", "200", "300"]
        .into_iter()
        .map(|t| {
            let (out, c) = plan(dir.path(), t, &["--builtin", "paper40", "--t-total", t]);
            assert_exit(&out, 0, &format!("plan paper40 --t-total {t}"));
            assert_eq!(c["t_total_s"].as_f64(), t.parse().ok(), "{c:#}");
            (t, number(&c, "max_follower_deviation_m"))
        })
        .collect();
    assert!(
        deviations.windows(2).all(|w| w[1].1 < w[0].1),
        "max_follower_deviation_m (t_total, metres) is not strictly decreasing: {deviations:?}"
    );
}

/// `simulate` writes scenario.toml, telemetry.csv (one row per agent per kept tick) and
/// audit.json; `--every 10` keeps every tenth tick and changes nothing else.
#[test]
fn simulate_writes_a_run_directory_and_decimates_telemetry() {
    let dir = TempDir::new();
    let (all, tenth) = (dir.path().join("every1"), dir.path().join("every10"));
    let source = ["simulate", "--builtin", "paper40", "--t-total", "60"];
    let decimated = spawn(orchestrator(&source).args(["--every", "10", "--out", path_str(&tenth)]));
    let out = run(
        orchestrator(&source).args(["--every", "1", "--out", path_str(&all)]),
        DEADLINE,
    );
    assert_exit(&out, 0, "simulate --every 1");
    assert_exit(&decimated.finish(DEADLINE), 0, "simulate --every 10");

    for f in ["scenario.toml", "telemetry.csv", "audit.json"] {
        assert!(all.join(f).is_file(), "simulate wrote no {f}");
    }
    let audit = read_json(&all.join("audit.json"));
    for k in AUDIT_KEYS {
        assert!(audit.get(k).is_some(), "audit.json lacks `{k}`: {audit:#}");
    }
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    assert_eq!(audit["agents"], 40, "{audit:#}");
    assert_eq!(audit["ticks"], 6_001, "{audit:#}");
    assert_eq!(audit["fault"], Value::Null, "{audit:#}");
    let flown: ScenarioFile = toml::from_str(
        &std::fs::read_to_string(all.join("scenario.toml")).expect("read scenario.toml"),
    )
    .expect("scenario.toml parses as a scenario file");
    assert_eq!(flown.agents.len(), 40);
    assert_eq!(flown.t_total_s, 60.0);

    let rows = telemetry_lines(&all);
    assert_eq!(rows[0], HEADER);
    assert_eq!(
        rows.len(),
        40 * 6_001 + 1,
        "header + 40 agents x 6,001 ticks"
    );
    let kept = telemetry_lines(&tenth);
    assert_eq!(
        kept.len(),
        40 * 601 + 1,
        "header + 40 agents x ticks 0, 10, ..., 6000"
    );
    let every_tenth: Vec<&String> = rows
        .iter()
        .enumerate()
        .filter(|(k, line)| {
            *k == 0
                || line
                    .split(',')
                    .next()
                    .and_then(|t| t.parse::<u64>().ok())
                    .is_some_and(|t| t % 10 == 0)
        })
        .map(|(_, line)| line)
        .collect();
    assert!(
        every_tenth.len() == kept.len() && every_tenth.iter().zip(&kept).all(|(a, b)| *a == b),
        "--every 10 is not every tenth tick of --every 1"
    );
    for f in ["audit.json", "scenario.toml"] {
        assert_eq!(
            std::fs::read(all.join(f)).expect("read"),
            std::fs::read(tenth.join(f)).expect("read"),
            "{f} depends on --every"
        );
    }
}

/// An `--out` that exists and is not empty is refused (exit 2) and left as it was; `--force`
/// reuses it.
#[test]
fn simulate_refuses_a_non_empty_out_without_force() {
    let dir = TempDir::new();
    let simulate = |out: &Path, t_total: &str, force: bool| {
        let mut cmd = orchestrator(&["simulate", "--builtin", "paper40", "--every", "100"]);
        cmd.args(["--t-total", t_total, "--out", path_str(out)]);
        if force {
            cmd.arg("--force");
        }
        run(&mut cmd, DEADLINE)
    };
    let refused = |out: &Output, dir: &Path| {
        assert_exit(out, 2, "simulate into a non-empty --out");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(path_str(dir)) && err.contains("--force"),
            "the refusal names neither the directory nor --force\n{}",
            describe(out)
        );
    };

    // Someone else's directory.
    let other = dir.path().join("other");
    std::fs::create_dir(&other).expect("mkdir");
    write_text(&other, "keep.txt", "not a run\n");
    let before = contents(&other);
    refused(&simulate(&other, "60", false), &other);
    assert_eq!(contents(&other), before, "{} was touched", other.display());

    // A previous run: a run of another t_total would change every file.
    let previous = dir.path().join("previous");
    assert_exit(
        &simulate(&previous, "60", false),
        0,
        "simulate --t-total 60",
    );
    let before = contents(&previous);
    refused(&simulate(&previous, "20", false), &previous);
    assert_eq!(
        contents(&previous),
        before,
        "{} was overwritten",
        previous.display()
    );

    // --force replaces it (t_total 20 s is below T_threshold: UNSAFE, exit 1, still complete).
    assert_exit(&simulate(&previous, "20", true), 1, "simulate --force");
    let audit = read_json(&previous.join("audit.json"));
    assert_eq!(number(&audit, "t_total_s"), 20.0, "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    assert_eq!(
        telemetry_lines(&previous).len(),
        40 * 21 + 1,
        "header + 40 agents x ticks 0, 100, ..., 2000"
    );
}

/// `scenario export paper40` writes the scenario as flown (projected, graph synthesised): planned
/// from the file it gives the built-in's certificate, number for number, with nothing left to
/// project.
#[test]
fn an_exported_scenario_plans_exactly_as_the_builtin() {
    let dir = TempDir::new();
    let file = dir.path().join("paper40.toml");
    let out = run(
        &mut orchestrator(&["scenario", "export", "paper40", "--out", path_str(&file)]),
        DEADLINE,
    );
    assert_exit(&out, 0, "scenario export paper40");
    let exported: ScenarioFile =
        toml::from_str(&std::fs::read_to_string(&file).expect("read the export"))
            .expect("the export parses as a scenario file");
    assert_eq!(exported.agents.len(), 40);
    for a in &exported.agents {
        assert_eq!(
            a.in_neighbors.as_ref().map(Vec::len),
            (a.role == Role::Follower).then_some(3),
            "agent {} ({:?}): the export carries the synthesised graph",
            a.id,
            a.role
        );
    }

    let (out, builtin) = plan(dir.path(), "builtin", &["--builtin", "paper40"]);
    assert_exit(&out, 0, "plan --builtin paper40");
    let (out, from_file) = plan(dir.path(), "file", &["--scenario", path_str(&file)]);
    assert_exit(&out, 0, "plan --scenario <export>");

    let (Some(a), Some(b)) = (builtin.as_object(), from_file.as_object()) else {
        panic!("certificates are not JSON objects: {builtin:#} {from_file:#}");
    };
    let keys = |m: &serde_json::Map<String, Value>| m.keys().cloned().collect::<Vec<_>>();
    assert_eq!(keys(a), keys(b), "the certificates have different keys");
    let differ: Vec<String> = a
        .iter()
        .filter(|(k, v)| k.as_str() != "notes" && b.get(k.as_str()) != Some(*v))
        .map(|(k, v)| format!("{k}: built-in {v}, file {}", b[k.as_str()]))
        .collect();
    assert!(
        differ.is_empty(),
        "the export plans differently:\n{}",
        differ.join("\n")
    );
    // The built-in projects its secondary leaders onto the leaders' plane and says so; the
    // export is already projected.
    assert_ne!(builtin["notes"], Value::Array(vec![]), "{builtin:#}");
    assert_eq!(from_file["notes"], Value::Array(vec![]), "{from_file:#}");
}
