//! `--telemetry parquet`: pyarrow (the reader of pandas, polars and DuckDB users) reads
//! telemetry.parquet and finds exactly telemetry.csv's columns and values, for `simulate` and for
//! `launch` (determinism holds for every format), for a run cut short by `--stop-on-violation`,
//! and `report` draws the figures from a Parquet run.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{bin, describe, run, unique_team, venv_python, TempDir};

use integration_tests::support;
use support::*;

const DEADLINE: Duration = integration_tests::deadline::LONG;

/// Runs tests/python/parquet_equals_csv.py with the test virtual environment's pyarrow.
fn assert_parquet_equals_csv(csv: &Path, parquets: &[&Path]) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/parquet_equals_csv.py");
    let mut c = Command::new(venv_python());
    c.arg(script).arg(csv).args(parquets);
    let out = run(&mut c, DEADLINE);
    assert_eq!(
        out.status.code(),
        Some(0),
        "pyarrow check\n{}",
        describe(&out)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        stdout.matches(" equal, ").count(),
        parquets.len(),
        "{stdout}"
    );
    println!("{stdout}");
}

fn parquet(cmd: &mut Command) -> &mut Command {
    cmd.args(["--telemetry", "parquet", "--no-figures"])
}

fn ok(out: &Output, code: i32, what: &str) {
    assert_exit(out, code, what);
}

#[test]
fn parquet_telemetry_holds_the_csv_values_for_simulate_and_launch() {
    let dir = TempDir::new();
    let team = unique_team("parquet");
    let source = ["--n", "10", "--t-total", "40", "--every", "3"];
    let (csv, sim, fly) = (
        dir.path().join("csv"),
        dir.path().join("sim"),
        dir.path().join("launch"),
    );
    ok(
        &run(simulate(&csv, &source).arg("--no-figures"), DEADLINE),
        0,
        "simulate csv",
    );
    ok(
        &run(parquet(&mut simulate(&sim, &source)), DEADLINE),
        0,
        "simulate parquet",
    );
    ok(
        &run(parquet(&mut launch(&team, &fly, &source)), DEADLINE),
        0,
        "launch parquet",
    );
    assert_no_team_resources(&team);
    for d in [&sim, &fly] {
        assert!(
            !d.join("telemetry.csv").exists(),
            "{}: a parquet run writes no CSV",
            d.display()
        );
    }
    assert_parquet_equals_csv(
        &csv.join("telemetry.csv"),
        &[
            &sim.join("telemetry.parquet"),
            &fly.join("telemetry.parquet"),
        ],
    );

    // `report` reads the Parquet run and draws every figure of it.
    let out = run(
        Command::new(bin("orchestrator")).arg("report").arg(&sim),
        DEADLINE,
    );
    ok(&out, 0, "report on a parquet run");
    for stem in ["fig_eigenvalues", "fig_separation", "fig_formation"] {
        assert!(sim.join(format!("{stem}.png")).is_file(), "{stem}.png");
    }
}

/// A run that ends early still finishes its Parquet file: every complete tick, readable.
#[test]
fn a_parquet_run_stopped_on_a_violation_is_complete_and_equal_to_csv() {
    let dir = TempDir::new();
    let source = [
        "--builtin",
        "paper40",
        "--t-total",
        "25",
        "--stop-on-violation",
    ];
    let (csv, pq) = (dir.path().join("csv"), dir.path().join("pq"));
    ok(
        &run(simulate(&csv, &source).arg("--no-figures"), DEADLINE),
        1,
        "simulate csv",
    );
    ok(
        &run(parquet(&mut simulate(&pq, &source)), DEADLINE),
        1,
        "simulate parquet",
    );
    assert_parquet_equals_csv(&csv.join("telemetry.csv"), &[&pq.join("telemetry.parquet")]);
}

/// The ticks telemetry.csv holds, in file order.
fn csv_ticks(csv: &Path) -> Vec<u64> {
    let text = std::fs::read_to_string(csv).expect("telemetry.csv");
    let mut ticks: Vec<u64> = text
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .next()
                .and_then(|t| t.parse().ok())
                .expect("a tick")
        })
        .collect();
    ticks.dedup();
    ticks
}

/// Without `--every`, a team of more than 40 members writes one tick in ceil(N / 40) (about 40
/// rows a tick), says so before flying, and both formats keep the same ticks; `--every 1` still
/// keeps every tick.
#[test]
fn a_large_team_keeps_one_tick_in_n_over_40_by_default_and_says_so() {
    let dir = TempDir::new();
    let source = ["--n", "100", "--max-ticks", "30"];
    let (csv, pq, all) = (
        dir.path().join("csv"),
        dir.path().join("pq"),
        dir.path().join("all"),
    );
    // Not --quiet: the line is printed before the flight.
    let loud = |out: &Path| {
        let mut c = Command::new(bin("orchestrator"));
        c.arg("simulate")
            .args(source)
            .arg("--no-figures")
            .arg("--out")
            .arg(out);
        c
    };
    let o = run(&mut loud(&csv), DEADLINE);
    ok(&o, 0, "simulate --n 100");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("telemetry: one tick in 3 (the default for 100 members"),
        "{stdout}"
    );
    let want: Vec<u64> = (0..=30).step_by(3).collect();
    assert_eq!(csv_ticks(&csv.join("telemetry.csv")), want);
    ok(
        &run(parquet(&mut simulate(&pq, &source)), DEADLINE),
        0,
        "simulate --n 100 --telemetry parquet",
    );
    assert_parquet_equals_csv(&csv.join("telemetry.csv"), &[&pq.join("telemetry.parquet")]);
    let o = run(loud(&all).args(["--every", "1"]), DEADLINE);
    ok(&o, 0, "simulate --n 100 --every 1");
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("telemetry: every tick (--every)"),
        "{}",
        describe(&o)
    );
    assert_eq!(
        csv_ticks(&all.join("telemetry.csv")),
        (0..=30).collect::<Vec<u64>>()
    );
}
