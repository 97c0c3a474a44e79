//! Imperfect links, deterministic: `--link-delay-ms`, `--link-jitter-ms`,
//! `--link-loss` and `--seed` are part of the model, so lockstep `launch` (real processes over
//! iceoryx2) writes exactly the telemetry of `simulate`, byte for byte; members started by hand
//! take the same flags, and one with other links is refused. `plan` certifies the largest link
//! delay and sweeps E_max against it.
//!
//! Every test has its own team name and temporary directory, and every process runs under a
//! deadline.

use std::process::Command;
use std::time::Duration;

use cdm_model::formation::Role;
use cdm_scenario::ScenarioFile;
use integration_tests::{bin, describe, run, spawn, unique_team, write_scenario, TempDir};

use integration_tests::support;
use support::*;

/// A 10-agent team of 400 ticks as processes takes about a second; the rest is slack.
const DEADLINE: Duration = integration_tests::deadline::FLIGHT;
/// A refused member exits as soon as it has read the scenario and looked at the team.
const REFUSE_DEADLINE: Duration = integration_tests::deadline::REFUSE;

const IMPAIRED: [&str; 8] = [
    "--link-delay-ms",
    "30",
    "--link-jitter-ms",
    "40",
    "--link-loss",
    "0.2",
    "--seed",
    "7",
];

#[test]
fn lockstep_launch_equals_simulate_with_delay_jitter_and_loss() {
    let dir = TempDir::new();
    let base = ["--n", "10", "--max-ticks", "400", "--no-figures"];
    let source: Vec<&str> = base.iter().chain(&IMPAIRED).copied().collect();
    let sim = dir.path().join("sim");
    assert_exit(
        &run(&mut simulate(&sim, &source), DEADLINE),
        0,
        "simulate --n 10 impaired",
    );
    let perfect = dir.path().join("perfect");
    assert_exit(
        &run(&mut simulate(&perfect, &base), DEADLINE),
        0,
        "simulate --n 10",
    );
    let impaired = std::fs::read(sim.join("telemetry.csv")).expect("impaired telemetry");
    let clean = std::fs::read(perfect.join("telemetry.csv")).expect("perfect telemetry");
    assert_eq!(impaired.len() > 1000, clean.len() > 1000);
    assert_ne!(impaired, clean, "the impairments must change the flight");
    // The run directory's scenario carries the links (members started by hand read it).
    let flown = flown_scenario(&sim);
    let link = flown.link.expect("scenario.toml has a [link] table");
    assert_eq!(
        (link.delay_ms, link.jitter_ms, link.loss, link.seed),
        (30.0, 40.0, 0.2, 7)
    );

    // Strict lockstep and the default window: members buffer the states still in flight.
    assert_windows_match_simulate(dir.path(), &source, &sim, &["1", "256"], "lk", DEADLINE);
}

/// Links and a scripted loss together: follower 7 is lost at 2 s (its two readers
/// re-triangulate onto new in-neighbours, whose states reach them over the same delayed, lossy
/// links); lockstep `launch` (which kills the process) writes exactly `simulate`'s telemetry,
/// and both record the loss alike.
#[test]
fn lockstep_launch_equals_simulate_with_links_and_a_scripted_loss() {
    let dir = TempDir::new();
    let base = ["--n", "10", "--max-ticks", "400", "--no-figures"];
    let mut source: Vec<&str> = base.iter().chain(&IMPAIRED).copied().collect();
    source.extend(["--lose", "7@2"]);
    let sim = dir.path().join("sim");
    assert_exit(
        &run(&mut simulate(&sim, &source), DEADLINE),
        0,
        "simulate --n 10 impaired with a loss",
    );
    let audit = read_json(&sim.join("audit.json"));
    let losses = &audit["losses"];
    assert_eq!(losses.as_array().map(Vec::len), Some(1), "{audit:#}");
    assert_eq!(losses[0]["id"], 7, "{audit:#}");
    let rewired = losses[0]["retriangulated"].as_array().map_or(0, Vec::len);
    assert!(
        rewired >= 1,
        "7 had readers that take new links: {losses:#}"
    );
    assert_windows_match_simulate(dir.path(), &source, &sim, &["1", "256"], "lkl", DEADLINE);
}

/// `--no-spawn` with links: members started with the same flags fly the team exactly as
/// simulated; a member without them has another scenario hash and is refused (exit 2).
#[test]
fn hand_started_members_need_the_same_links() {
    let dir = TempDir::new();
    let team = unique_team("hlink");
    let exported = dir.path().join("exported.toml");
    let out = run(
        Command::new(bin("orchestrator"))
            .args(["scenario", "export", "--n", "10", "--out"])
            .arg(&exported),
        DEADLINE,
    );
    assert_exit(&out, 0, "scenario export --n 10");
    let text = std::fs::read_to_string(&exported).expect("read the exported scenario");
    let file: ScenarioFile = toml::from_str(&text).expect("the exported scenario parses");
    let scenario = write_scenario(dir.path(), "team.toml", &file);
    let path = scenario.to_str().expect("a UTF-8 path");
    let limits = ["--max-ticks", "400", "--no-figures"];

    let run_dir = dir.path().join("run");
    let mut orch = spawn(
        launch_loud(&team, &run_dir, &["--scenario", path])
            .args(["--no-spawn", "--join-timeout", "60"])
            .args(limits)
            .args(IMPAIRED),
    );
    orch.wait_for_output("waits for 10 processes", DEADLINE);

    let follower = file
        .agents
        .iter()
        .find(|a| a.role == Role::Follower)
        .map(|a| a.id)
        .expect("a follower");
    let o = run(
        &mut member("agent", &scenario, &team, follower),
        REFUSE_DEADLINE,
    );
    assert_exit(&o, 2, "agent without the team's link flags");
    assert_stderr_has(
        &o,
        "agent without the team's link flags",
        &[
            format!("cannot join team {team}").as_str(),
            "differs from the team's",
        ],
    );

    let members: Vec<(u32, integration_tests::Running)> = file
        .agents
        .iter()
        .map(|a| {
            let cmd = &mut member(binary_for(a.role), &scenario, &team, a.id);
            (a.id, spawn(cmd.args(IMPAIRED)))
        })
        .collect();
    assert_exit(&orch.finish(DEADLINE), 0, "launch --no-spawn impaired");
    for (id, m) in members {
        assert_exit(&m.finish(DEADLINE), 0, &format!("hand-started agent {id}"));
    }
    assert_no_process_of(&team);

    let sim = dir.path().join("sim");
    let source: Vec<&str> = ["--scenario", path]
        .iter()
        .chain(&limits)
        .chain(&IMPAIRED)
        .copied()
        .collect();
    assert_exit(
        &run(&mut simulate(&sim, &source), DEADLINE),
        0,
        "simulate impaired",
    );
    assert_same_file(&run_dir.join("telemetry.csv"), &sim.join("telemetry.csv"));
}

#[test]
fn plan_certifies_the_largest_link_delay_and_sweeps_it() {
    let dir = TempDir::new();
    let json = dir.path().join("cert.json");
    let out_dir = dir.path().join("sweep");
    let o = run(
        Command::new(bin("orchestrator"))
            .args(["plan", "--n", "10", "--sweep-delay", "0:400:100", "--json"])
            .arg(&json)
            .arg("--out")
            .arg(&out_dir),
        DEADLINE,
    );
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("max link delay"), "{stdout}");
    let cert = read_json(&json);
    let max_ms = cert["max_link_delay_ms"].as_f64().expect("a number");
    let delta = cert["delta_m"].as_f64().expect("delta_m");
    // Whole ticks at comm_hz.
    let comm_hz = 100.0;
    assert_eq!((max_ms * comm_hz / 1000.0).fract(), 0.0, "{max_ms}");

    // The sweep's CSV, read by the csv module of Python's standard library (not our code).
    let csv = out_dir.join("fig_delay_sweep.csv");
    let py = integration_tests::venv_python();
    let o = run(
        Command::new(py)
            .arg("-c")
            .arg(
                "import csv,sys\n\
             rows=list(csv.DictReader(open(sys.argv[1])))\n\
             print(' '.join(r['link_delay_ms']+'='+r['max_follower_deviation_m'] for r in rows))",
            )
            .arg(&csv),
        DEADLINE,
    );
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let points: Vec<(f64, f64)> = String::from_utf8_lossy(&o.stdout)
        .split_whitespace()
        .map(|p| {
            let (d, e) = p.split_once('=').expect("d=e");
            (d.parse().expect("delay"), e.parse().expect("E_max"))
        })
        .collect();
    assert_eq!(
        points.iter().map(|p| p.0).collect::<Vec<_>>(),
        vec![0.0, 100.0, 200.0, 300.0, 400.0]
    );
    // Every swept delay the certificate calls safe meets E_max <= delta, and conversely.
    for (d, e) in &points {
        assert_eq!(
            *d <= max_ms,
            *e <= delta,
            "delay {d} ms: E_max {e}, delta {delta}, max {max_ms}"
        );
    }
    for ext in ["svg", "png"] {
        let f = out_dir.join(format!("fig_delay_sweep.{ext}"));
        assert!(
            std::fs::metadata(&f)
                .map(|m| m.len() > 1000)
                .unwrap_or(false),
            "{}",
            f.display()
        );
    }
}

/// A bad link value is bad input (exit 2) naming its flag, on every command that takes it.
#[test]
fn bad_link_flags_are_refused_naming_the_flag() {
    let dir = TempDir::new();
    for (flag, value) in [
        ("--link-loss", "1.5"),
        ("--link-delay-ms", "-3"),
        ("--link-jitter-ms", "nan"),
        ("--seed", "18446744073709551615"),
    ] {
        let what = format!("simulate {flag} {value}");
        let out = dir.path().join(flag.trim_start_matches('-'));
        let o = run(&mut simulate(&out, &["--n", "4", flag, value]), DEADLINE);
        assert_exit(&o, 2, &what);
        assert_stderr_has(&o, &what, &[&format!("{flag} "), "must be"]);
    }
    let team = unique_team("badlink");
    let o = run(
        &mut launch(
            &team,
            &dir.path().join("l"),
            &["--n", "4", "--link-loss", "-0.5"],
        ),
        DEADLINE,
    );
    assert_exit(&o, 2, "launch --link-loss -0.5");
    assert_stderr_has(
        &o,
        "launch --link-loss -0.5",
        &["--link-loss -0.5", "[0, 1)"],
    );
    assert_no_process_of(&team);
    let o = run(
        Command::new(bin("orchestrator"))
            .args(["plan", "--n", "4", "--sweep-delay", "5:1:1", "--out"])
            .arg(dir.path().join("sw")),
        DEADLINE,
    );
    assert_exit(&o, 2, "plan --sweep-delay 5:1:1");
    assert_stderr_has(&o, "plan --sweep-delay 5:1:1", &["--sweep-delay 5:1:1"]);
    // A member binary refuses it before it looks for its team.
    let scenario = dir.path().join("paper40.toml");
    let o = run(
        Command::new(bin("orchestrator"))
            .args(["scenario", "export", "--out"])
            .arg(&scenario),
        DEADLINE,
    );
    assert_exit(&o, 0, "scenario export");
    let o = run(
        member("agent", &scenario, &team, 10).args(["--link-delay-ms", "1e9"]),
        REFUSE_DEADLINE,
    );
    assert_exit(&o, 2, "agent --link-delay-ms 1e9");
    assert_stderr_has(
        &o,
        "agent --link-delay-ms 1e9",
        &["--link-delay-ms 1000000000"],
    );
}
