//! Steering a team in flight with a command file (`simulate --commands`):
//!
//! - paper40 held, refused an UNSAFE goto (its triangle squeezed to a sliver: lambda_1 below
//!   lambda_CD,min, eq. 37), sent to a SAFE goto while still moving (it holds first), then
//!   landed: SAFE, every primary leader's plan ends on the ground, audit.json lists the four
//!   commands with their verdicts;
//! - the run's commands.json, given back as the command file, flies the same run byte for byte
//!   (telemetry.csv, audit.json, commands.json);
//! - bad command files are refused with exit 2, naming the command and the field, and leave no
//!   run directory.
//!
//! How to run: `cargo test --release -p integration-tests --test steering -- steering::`.

use integration_tests::support;

use std::path::Path;
use std::process::{Command, Output};

use integration_tests::{bin, run, TempDir};
use support::{assert_exit, assert_same_file, assert_stderr_has, read_json};

const DEADLINE: std::time::Duration = integration_tests::deadline::FLIGHT;

const COMMANDS: &str = support::STEERING_COMMANDS;

fn simulate(out: &Path, commands: &Path) -> Output {
    run(
        Command::new(bin("orchestrator")).args([
            "simulate",
            "--builtin",
            "paper40",
            "--no-figures",
            "--quiet",
            "--out",
            out.to_str().unwrap(),
            "--commands",
            commands.to_str().unwrap(),
        ]),
        DEADLINE,
    )
}

#[test]
fn held_refused_sent_elsewhere_and_landed_then_replayed_byte_for_byte() {
    let tmp = TempDir::new();
    let file = tmp.path().join("commands.json");
    std::fs::write(&file, COMMANDS).unwrap();
    let first = tmp.path().join("first");
    assert_exit(&simulate(&first, &file), 0, "simulate --commands");
    let audit = read_json(&first.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE");
    let listed: Vec<(String, String, bool)> = (audit["commands"].as_array().unwrap().iter())
        .map(|c| {
            (
                c["command"].as_str().unwrap().to_string(),
                c["verdict"].as_str().unwrap().to_string(),
                c["accepted"].as_bool().unwrap(),
            )
        })
        .collect();
    let want = [
        ("hold", "SAFE", true),
        ("goto", "UNSAFE", false),
        ("goto", "SAFE", true),
        ("land", "SAFE", true),
    ]
    .map(|(c, v, a)| (c.to_string(), v.to_string(), a));
    assert_eq!(listed, want);
    let why = audit["commands"][1]["why"].as_str().unwrap();
    assert!(why.contains("segment 2") && why.contains("eq. 37"), "{why}");
    let commands = read_json(&first.join("commands.json"));
    assert_eq!(commands[0]["switch_tick"], 6000);
    assert!(commands[2]["certificate"]["phases"].is_array());
    // The leaders' plan ends on the ground (z = 0 without [landing]).
    let tel = std::fs::read_to_string(first.join("telemetry.csv")).unwrap();
    let last_tick = tel.lines().last().unwrap().split(',').next().unwrap();
    let grounded = (tel.lines())
        .filter(|l| l.starts_with(&format!("{last_tick},")) && l.contains(",primary,"))
        .map(|l| l.rsplit(',').next().unwrap().parse::<f64>().unwrap())
        .collect::<Vec<_>>();
    assert_eq!(grounded, [0.0, 0.0, 0.0]);
    // The run's own commands.json is a command file: the same run, byte for byte.
    let again = tmp.path().join("again");
    assert_exit(
        &simulate(&again, &first.join("commands.json")),
        0,
        "simulate --commands RUN/commands.json",
    );
    for f in [
        "telemetry.csv",
        "audit.json",
        "commands.json",
        "scenario.toml",
    ] {
        assert_same_file(&first.join(f), &again.join(f));
    }
}

#[test]
fn bad_command_files_are_refused_naming_the_field() {
    let tmp = TempDir::new();
    for (k, (text, needles)) in [
        (
            r#"[{"at_s": 1, "command": "hover"}]"#,
            &["commands[0].command", "hover"][..],
        ),
        (
            r#"[{"at_s": 1, "command": "goto", "goals": [[0, 0, 1]]}]"#,
            &["commands[0].goals", "got 1"][..],
        ),
        (
            r#"[{"at_s": 5, "command": "hold"}, {"at_s": 5, "command": "land"}]"#,
            &["commands[1].at_s", "one command per switch"][..],
        ),
        (r#"{"at_s": 1}"#, &["a JSON list of commands"][..]),
    ]
    .into_iter()
    .enumerate()
    {
        let file = tmp.path().join(format!("bad{k}.json"));
        std::fs::write(&file, text).unwrap();
        let out = tmp.path().join(format!("run{k}"));
        let o = simulate(&out, &file);
        assert_exit(&o, 2, text);
        let mut all = vec![file.to_str().unwrap()];
        all.extend(needles);
        assert_stderr_has(&o, text, &all);
        assert!(!out.exists(), "{text}: a run directory was made");
    }
}
