//! `orchestrator report` and `plan --sweep` draw the paper's figures from a run directory alone:
//! every figure exists as a valid, non-trivial SVG and PNG, and the data behind Fig. 8 has the
//! audit's lambda_1 minimum.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{bin, describe, paper40, run, write_scenario, TempDir};
use serde_json::Value;

const DEADLINE: Duration = integration_tests::deadline::FLIGHT;
const PNG_MAGIC: &[u8] = b"\x89PNG\r\n\x1a\n";

fn orchestrator(args: &[&str]) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    c
}

fn ok(out: &Output) {
    assert_eq!(out.status.code(), Some(0), "{}", describe(out));
}

/// `<stem>.svg` and `<stem>.png` exist, have the right headers and some substance.
fn assert_figure(dir: &Path, stem: &str) {
    let svg = dir.join(format!("{stem}.svg"));
    let png = dir.join(format!("{stem}.png"));
    let text = std::fs::read_to_string(&svg).unwrap_or_else(|e| panic!("{}: {e}", svg.display()));
    assert!(
        text.trim_start().starts_with("<svg"),
        "{} is not SVG",
        svg.display()
    );
    assert!(
        text.trim_end().ends_with("</svg>"),
        "{} is cut short",
        svg.display()
    );
    assert!(
        text.len() > 5_000,
        "{} is only {} bytes",
        svg.display(),
        text.len()
    );
    assert!(
        text.contains("<text"),
        "{} has no text (axes, legend)",
        svg.display()
    );
    let bytes = std::fs::read(&png).unwrap_or_else(|e| panic!("{}: {e}", png.display()));
    assert!(bytes.starts_with(PNG_MAGIC), "{} is not PNG", png.display());
    assert!(
        bytes.ends_with(b"IEND\xaeB`\x82"),
        "{} is cut short",
        png.display()
    );
    assert!(
        bytes.len() > 10_000,
        "{} is only {} bytes",
        png.display(),
        bytes.len()
    );
}

fn figure_files(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("read run dir")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("fig_"))
        .collect();
    names.sort();
    names
}

#[test]
fn report_redraws_every_figure_and_fig8_has_the_audits_lambda1_minimum() {
    let dir = TempDir::new();
    let run_dir = dir.path().join("run");
    let mut c = orchestrator(&["simulate", "--quiet", "--no-figures", "--every", "5"]);
    c.arg("--out").arg(&run_dir);
    ok(&run(&mut c, DEADLINE));
    assert!(
        figure_files(&run_dir).is_empty(),
        "--no-figures drew figures"
    );

    let mut c = orchestrator(&["report"]);
    c.arg(&run_dir);
    let out = run(&mut c, DEADLINE);
    ok(&out);
    let files = figure_files(&run_dir);
    let agent = files
        .iter()
        .find(|n| n.starts_with("fig_agent_") && n.ends_with(".svg"))
        .unwrap_or_else(|| panic!("no fig_agent_<id>: {files:?}"))
        .trim_end_matches(".svg")
        .to_string();
    for stem in ["fig_eigenvalues", "fig_separation", "fig_formation", &agent] {
        assert_figure(&run_dir, stem);
    }
    assert!(
        !files.iter().any(|n| n.starts_with("fig_loss_transient")),
        "a run without losses drew a repair transient: {files:?}"
    );
    // The default follower is one of paper40's followers (ids 7-40).
    let id: u32 = agent["fig_agent_".len()..].parse().expect("agent id");
    assert!((7..=40).contains(&id), "{agent}");

    // Fig. 8's data: its lambda_1 minimum is the audit's (over the same ticks).
    let text = std::fs::read_to_string(run_dir.join("fig_eigenvalues.csv")).expect("csv");
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("tick,t,t_over_t_total,lambda1,lambda2,lambda3")
    );
    let min = lines
        .map(|l| {
            l.split(',')
                .nth(3)
                .expect("lambda1")
                .parse::<f64>()
                .expect("number")
        })
        .fold(f64::INFINITY, f64::min);
    let audit: Value = serde_json::from_str(
        &std::fs::read_to_string(run_dir.join("audit.json")).expect("audit.json"),
    )
    .expect("json");
    let lambda1_min = audit["lambda1_min"].as_f64().expect("lambda1_min");
    assert!(
        (min - lambda1_min).abs() < 1e-4,
        "Fig. 8 minimum {min} != audit lambda1_min {lambda1_min}"
    );

    // --follow picks another follower; an unknown id is bad input naming the file.
    let mut c = orchestrator(&["report", "--quiet", "--follow", "7"]);
    c.arg(&run_dir);
    ok(&run(&mut c, DEADLINE));
    assert_figure(&run_dir, "fig_agent_7");
    let mut c = orchestrator(&["report", "--follow", "99"]);
    c.arg(&run_dir);
    let out = run(&mut c, DEADLINE);
    assert_eq!(out.status.code(), Some(2), "{}", describe(&out));
    assert!(String::from_utf8_lossy(&out.stderr).contains("99"));
}

#[test]
fn report_of_a_directory_without_a_run_is_bad_input_naming_the_file() {
    let dir = TempDir::new();
    let mut c = orchestrator(&["report"]);
    c.arg(dir.path());
    let out = run(&mut c, DEADLINE);
    assert_eq!(out.status.code(), Some(2), "{}", describe(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("scenario.toml"),
        "{}",
        describe(&out)
    );
}

#[test]
fn simulate_draws_the_figures_at_the_end_of_a_run() {
    let dir = TempDir::new();
    let mut f = paper40();
    f.t_total_s = 60.0;
    let scenario = write_scenario(dir.path(), "short.toml", &f);
    let run_dir = dir.path().join("run");
    let mut c = orchestrator(&["simulate", "--quiet", "--every", "10", "--follow", "20"]);
    c.arg("--scenario")
        .arg(&scenario)
        .arg("--out")
        .arg(&run_dir);
    ok(&run(&mut c, DEADLINE));
    for stem in [
        "fig_eigenvalues",
        "fig_separation",
        "fig_formation",
        "fig_agent_20",
    ] {
        assert_figure(&run_dir, stem);
    }
}

#[test]
fn plan_sweep_draws_the_deviation_figure() {
    let dir = TempDir::new();
    let out_dir = dir.path().join("sweep");
    let mut c = orchestrator(&["plan", "--quiet", "--n", "4", "--sweep", "10:40:10"]);
    c.arg("--out").arg(&out_dir);
    ok(&run(&mut c, DEADLINE));
    assert_figure(&out_dir, "fig_deviation_sweep");
    let text = std::fs::read_to_string(out_dir.join("fig_deviation_sweep.csv")).expect("csv");
    let rows: Vec<(f64, f64)> = text
        .lines()
        .skip(1)
        .map(|l| {
            let (t, e) = l.split_once(',').expect("two fields");
            (t.parse().expect("T"), e.parse().expect("E"))
        })
        .collect();
    assert_eq!(
        rows.iter().map(|r| r.0).collect::<Vec<_>>(),
        vec![10.0, 20.0, 30.0, 40.0]
    );
    // E_max falls with the travel time (Sec. VII-D, about 1 / T^2).
    assert!(rows.windows(2).all(|w| w[1].1 < w[0].1), "{rows:?}");

    let mut c = orchestrator(&["plan", "--n", "4", "--sweep", "40:10:10"]);
    c.arg("--out").arg(&out_dir);
    let out = run(&mut c, DEADLINE);
    assert_eq!(out.status.code(), Some(2), "{}", describe(&out));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--sweep"));
}

/// A run that lost a primary leader: `report` draws the repaired followers' deviation
/// (fig_loss_transient) for exactly the followers audit.json says were re-triangulated or left
/// flying their plan, from the same telemetry the audit measured.
#[test]
fn report_of_a_run_with_a_loss_draws_the_repair_transient() {
    let dir = TempDir::new();
    let run_dir = dir.path().join("run");
    let mut c = orchestrator(&[
        "simulate",
        "--quiet",
        "--no-figures",
        "--max-ticks",
        "3000",
        "--lose",
        "1@10",
    ]);
    c.arg("--out").arg(&run_dir);
    ok(&run(&mut c, DEADLINE));
    let mut c = orchestrator(&["report"]);
    c.arg(&run_dir);
    ok(&run(&mut c, DEADLINE));
    assert_figure(&run_dir, "fig_loss_transient");

    let audit: Value = serde_json::from_str(
        &std::fs::read_to_string(run_dir.join("audit.json")).expect("audit.json"),
    )
    .expect("json");
    let loss = &audit["losses"][0];
    assert_eq!(loss["id"], 1, "{loss}");
    let mut expected: Vec<u64> = loss["retriangulated"]
        .as_array()
        .expect("retriangulated")
        .iter()
        .map(|r| r["id"].as_u64().expect("id"))
        .chain(
            loss["degraded"]
                .as_array()
                .expect("degraded")
                .iter()
                .map(|x| x.as_u64().expect("id")),
        )
        .collect();
    expected.sort_unstable();
    assert!(
        !expected.is_empty(),
        "losing leader 1 repaired nobody: {loss}"
    );

    let text = std::fs::read_to_string(run_dir.join("fig_loss_transient.csv")).expect("csv");
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("id,t,deviation_m"));
    let mut ids = Vec::new();
    let mut peak = 0.0f64;
    for l in lines {
        let f: Vec<&str> = l.split(',').collect();
        let id: u64 = f[0].parse().expect("id");
        let dev: f64 = f[2].parse().expect("deviation");
        assert!(dev.is_finite() && dev >= 0.0, "{l}");
        peak = peak.max(dev);
        if ids.last() != Some(&id) {
            ids.push(id);
        }
    }
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(
        ids, expected,
        "followers drawn against audit.json's repairs"
    );
    // Every drawn deviation is one the audit measured: none exceeds its largest.
    let max_dev = audit["max_follower_deviation_m"].as_f64().expect("max");
    assert!(
        peak > 0.0 && peak <= max_dev + 1e-9,
        "peak {peak}, audit {max_dev}"
    );
}
