//! `orchestrator replay`: a finished lockstep run flown again from its directory alone.
//!
//! - A `simulate` run with commands, a scripted loss, `--every` and `--max-ticks`, and a
//!   lockstep `launch` of 41 processes with a `--lose` and the same commands: the replay's
//!   telemetry.csv is the run's byte for byte and audit.json's safety figures are the run's;
//!   run.json records the options.
//! - What if: `--gains` re-flies the same history differently, and two such replays are
//!   identical; `--scenario` with the run's team and those gains flies the same bytes as
//!   `--gains`; another team (another comm_hz) is exit 2 naming what differs.
//! - `report --against` draws a run and its what-if side by side, each named by its directory
//!   in the CSV and the legend; their deviations differ.
//! - A tampered or foreign file (audit.json's losses, commands.json, another scenario.toml, a
//!   missing run.json) is exit 2 naming the file and its first bad record; nothing panics.
//!
//! How to run: `cargo test --release -p integration-tests --test replay -- replay::`.

use integration_tests::support;

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use integration_tests::{bin, run, unique_team, write_text, TempDir};
use serde_json::Value;
use support::{
    assert_exit, assert_no_process_of, assert_no_team_resources, assert_same_file, launch,
    read_json, replay, simulate, with_line,
};

const DEADLINE: Duration = integration_tests::deadline::FLIGHT;

/// A hold at 12 s and a resume at 18 s, inside the first 30 s of paper40.
const COMMANDS: &str = r#"[{"at_s": 12, "command": "hold"}, {"at_s": 18, "command": "resume"}]"#;

/// audit.json without what only says how a loss was noticed.
fn figures(dir: &Path) -> Value {
    let mut a = read_json(&dir.join("audit.json"));
    if let Some(Value::Array(losses)) = a.get_mut("losses") {
        for l in losses.iter_mut().filter_map(Value::as_object_mut) {
            l.remove("cause");
            l.remove("host");
        }
    }
    a
}

fn assert_replays(run_dir: &Path, tmp: &Path, what: &str) {
    let out = tmp.join(format!("{what}-replay"));
    let o = replay(run_dir, &out, &[]);
    assert_exit(&o, 0, &format!("replay of {what}"));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("telemetry.csv: identical to the run's"),
        "{said}"
    );
    assert_same_file(&run_dir.join("telemetry.csv"), &out.join("telemetry.csv"));
    assert_eq!(figures(run_dir), figures(&out), "{what}: audit.json");
}

/// paper40 simulated to tick `max_ticks` with [`COMMANDS`] and member 20 lost at 8 s, into
/// `tmp/sim`.
fn simulated(tmp: &Path, max_ticks: &str, extra: &[&str]) -> std::path::PathBuf {
    let commands = write_text(tmp, "commands.json", COMMANDS);
    let run_dir = tmp.join("sim");
    let flags = [
        "--builtin",
        "paper40",
        "--no-figures",
        "--max-ticks",
        max_ticks,
    ];
    let mut c = simulate(&run_dir, &flags);
    c.args(extra)
        .args(["--lose", "20@8", "--commands"])
        .arg(&commands);
    assert_exit(&run(&mut c, DEADLINE), 0, "simulate");
    run_dir
}

#[test]
fn a_simulate_run_with_commands_and_a_loss_replays_byte_for_byte_and_what_if_is_deterministic() {
    let tmp = TempDir::new();
    let run_dir = simulated(tmp.path(), "3000", &["--every", "3"]);
    let r = read_json(&run_dir.join("run.json"));
    assert_eq!(r["mode"], "simulate");
    assert_eq!(
        (r["every"].as_u64(), r["max_ticks"].as_u64()),
        (Some(3), Some(3000))
    );
    assert_eq!(r["losses"], serde_json::json!([[801, [20]]]));
    assert_replays(&run_dir, tmp.path(), "simulate");

    // What if: other (stable) gains on the same history, twice.
    let gains = ["--gains", "30,40,25,8"];
    let (a, b) = (tmp.path().join("gains-a"), tmp.path().join("gains-b"));
    for out in [&a, &b] {
        let o = replay(&run_dir, out, &gains);
        assert!(
            matches!(o.status.code(), Some(0 | 1)),
            "{}",
            integration_tests::describe(&o)
        );
        let said = String::from_utf8_lossy(&o.stdout);
        assert!(said.contains("telemetry.csv differs from line"), "{said}");
    }
    assert_same_file(&a.join("telemetry.csv"), &b.join("telemetry.csv"));
    assert_same_file(&a.join("audit.json"), &b.join("audit.json"));
    let g =
        toml::from_str::<toml::Table>(&std::fs::read_to_string(a.join("scenario.toml")).unwrap())
            .unwrap();
    assert_eq!(g["gains"].as_array().unwrap()[0].as_float(), Some(30.0));
    // The same losses and commands were flown.
    assert_eq!(read_json(&a.join("audit.json"))["losses"][0]["tick"], 801);
    assert!(a.join("commands.json").exists());

    // What if from a scenario file: the run's team with those gains flies as --gains does.
    let text = std::fs::read_to_string(run_dir.join("scenario.toml")).unwrap();
    let soft = with_line(&text, "gains = ", "gains = [30.0, 40.0, 25.0, 8.0]");
    let soft = write_text(tmp.path(), "soft.toml", &soft);
    let from_file = tmp.path().join("from-file");
    let o = replay(
        &run_dir,
        &from_file,
        &["--scenario", soft.to_str().unwrap()],
    );
    assert!(matches!(o.status.code(), Some(0 | 1)), "{o:?}");
    assert_same_file(&a.join("telemetry.csv"), &from_file.join("telemetry.csv"));
    // Another team is refused, naming what differs.
    let other = with_line(&text, "comm_hz = ", "comm_hz = 50.0");
    let other = write_text(tmp.path(), "other.toml", &other);
    let o = replay(
        &run_dir,
        &tmp.path().join("other"),
        &["--scenario", other.to_str().unwrap()],
    );
    assert_exit(&o, 2, "replay --scenario of another team");
    support::assert_stderr_has(
        &o,
        "replay --scenario",
        &["other.toml: comm_hz 50, the run's 100: not the run's team"],
    );

    // The two side by side: each run named by its directory, in the CSV and the figure.
    let mut c = Command::new(bin("orchestrator"));
    c.args(["report", "--quiet"])
        .arg(&a)
        .arg("--against")
        .arg(&run_dir);
    assert_exit(&run(&mut c, DEADLINE), 0, "report --against");
    let table = std::fs::read_to_string(a.join("fig_compare.csv")).unwrap();
    let rows = |k: &str| table.lines().filter(|l| l.starts_with(k)).count();
    assert_eq!(
        (rows("gains-a,"), rows("sim,")),
        (1001, 1001),
        "every third tick of 0..=3000"
    );
    let svg = std::fs::read_to_string(a.join("fig_compare.svg")).unwrap();
    let texts: Vec<&str> = svg.split(['<', '>']).map(str::trim).collect();
    for name in ["gains-a", "sim"] {
        assert!(texts.contains(&name), "the legend names {name}");
    }
    assert!(a.join("fig_compare.png").exists());
    // The deviations differ where the gains do, at the same ticks.
    let column = |name: &str| -> Vec<(String, String)> {
        (table.lines().filter(|l| l.starts_with(&format!("{name},"))))
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                (f[1].to_string(), f[3].to_string())
            })
            .collect()
    };
    let (soft, stiff) = (column("gains-a"), column("sim"));
    let ticks = |c: &[(String, String)]| c.iter().map(|x| x.0.clone()).collect::<Vec<_>>();
    assert_eq!(ticks(&soft), ticks(&stiff));
    assert_eq!(soft[0], stiff[0], "tick 0: the same start");
    let differ = soft.iter().zip(&stiff).filter(|(x, y)| x.1 != y.1).count();
    assert!(differ > 100, "{differ} of 1001 deviations differ");
}

#[test]
fn a_lockstep_launch_with_a_loss_and_commands_replays_byte_for_byte() {
    let tmp = TempDir::new();
    let team = unique_team("replay");
    let run_dir = tmp.path().join("launch");
    let commands = write_text(tmp.path(), "commands.json", COMMANDS);
    let flags = [
        "--builtin",
        "paper40",
        "--no-figures",
        "--max-ticks",
        "2000",
        "--lose",
        "5@4",
        "--commands",
        commands.to_str().unwrap(),
    ];
    let o = run(&mut launch(&team, &run_dir, &flags), DEADLINE);
    assert_no_process_of(&team);
    assert_no_team_resources(&team);
    assert_exit(&o, 0, "launch");
    assert_eq!(read_json(&run_dir.join("run.json"))["mode"], "lockstep");
    let accepted = read_json(&run_dir.join("commands.json"));
    let accepted = accepted.as_array().expect("commands.json: a list");
    assert_eq!(accepted.len(), 2, "{accepted:?}");
    assert!(
        accepted.iter().all(|c| c["accepted"] == true),
        "{accepted:?}"
    );
    assert_replays(&run_dir, tmp.path(), "launch");
}

/// Copies `src`'s files into a new directory `dst`.
fn copy_run(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), dst.join(e.file_name())).unwrap();
        }
    }
}

fn edit(dir: &Path, name: &str, from: &str, to: &str) {
    let p = dir.join(name);
    let text = std::fs::read_to_string(&p).unwrap();
    assert!(text.contains(from), "{name} has {from:?}");
    std::fs::write(&p, text.replacen(from, to, 1)).unwrap();
}

#[test]
fn a_tampered_or_foreign_file_is_refused_naming_it_and_its_first_bad_record() {
    let tmp = TempDir::new();
    let run_dir = simulated(tmp.path(), "2500", &[]);
    let other = tmp.path().join("other");
    let mut c = simulate(&other, &["--n", "12", "--no-figures", "--max-ticks", "100"]);
    assert_exit(&run(&mut c, DEADLINE), 0, "simulate --n 12");

    type Tamper = fn(&Path, &Path);
    let cases: [(&str, Tamper, &[&str]); 5] = [
        (
            "a loss of nobody",
            |d, _| edit(d, "audit.json", "\"id\": 20", "\"id\": 999"),
            &["audit.json", "losses[0]", "999"],
        ),
        (
            "a moved loss",
            |d, _| edit(d, "audit.json", "\"tick\": 801", "\"tick\": 900"),
            &["audit.json", "losses[0]", "tick 900"],
        ),
        (
            "a moved command",
            |d, _| {
                edit(
                    d,
                    "commands.json",
                    "\"switch_tick\": 1200",
                    "\"switch_tick\": 1300",
                )
            },
            &["commands.json", "commands[0].switch_tick", "1300"],
        ),
        (
            "another team's scenario",
            |d, o| {
                std::fs::copy(o.join("scenario.toml"), d.join("scenario.toml")).unwrap();
            },
            &["run.json", "scenario_hash"],
        ),
        (
            "no run.json",
            |d, _| std::fs::remove_file(d.join("run.json")).unwrap(),
            &["run.json"],
        ),
    ];
    for (k, (what, tamper, needles)) in cases.iter().enumerate() {
        let d = tmp.path().join(format!("tampered-{k}"));
        copy_run(&run_dir, &d);
        tamper(&d, &other);
        let out = tmp.path().join(format!("replay-{k}"));
        let o = replay(&d, &out, &[]);
        assert_exit(&o, 2, what);
        support::assert_stderr_has(&o, what, needles);
        assert!(!out.exists(), "{what}: nothing written");
    }
}
