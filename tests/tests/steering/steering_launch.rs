//! Steering a launched team with a command file (`launch --commands`), with real processes:
//! the orchestrator, `leader` and `agent` binaries over real iceoryx2 shared memory.
//!
//! - paper40 held, refused an UNSAFE goto, sent to a SAFE goto while still moving, then
//!   landed: the orchestrator certifies each command with the code `simulate` uses, announces
//!   each accepted one on the clock channel ahead of its switch tick, and every member flies
//!   the same commanded plan from it: telemetry.csv, audit.json and commands.json equal
//!   `simulate --commands` byte for byte, and nothing of the team is left.
//!
//! How to run: `cargo test --release -p integration-tests --test steering -- steering_launch::`.

use integration_tests::support;

use std::path::Path;
use std::process::Output;

use integration_tests::{run, unique_team, TempDir};
use support::{
    assert_exit, assert_no_process_of, assert_no_team_resources, assert_same_file, launch,
    read_json, simulate,
};

const DEADLINE: std::time::Duration = integration_tests::deadline::FLIGHT;

const COMMANDS: &str = support::STEERING_COMMANDS;

fn args<'a>(commands: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut v = vec![
        "--builtin",
        "paper40",
        "--no-figures",
        "--commands",
        commands,
    ];
    v.extend_from_slice(extra);
    v
}

fn launched(team: &str, out: &Path, commands: &str, extra: &[&str]) -> Output {
    let o = run(&mut launch(team, out, &args(commands, extra)), DEADLINE);
    assert_no_process_of(team);
    assert_no_team_resources(team);
    o
}

#[test]
fn a_launched_team_flies_the_commands_as_simulate_does_byte_for_byte() {
    let tmp = TempDir::new();
    let file = tmp.path().join("commands.json");
    std::fs::write(&file, COMMANDS).unwrap();
    let f = file.to_str().unwrap();
    let sim = tmp.path().join("sim");
    let o = run(&mut simulate(&sim, &args(f, &[])), DEADLINE);
    assert_exit(&o, 0, "simulate --commands");
    let team = unique_team("steer");
    let out = tmp.path().join("launch");
    assert_exit(&launched(&team, &out, f, &[]), 0, "launch --commands");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE");
    let verdicts: Vec<(&str, bool)> = (audit["commands"].as_array().unwrap().iter())
        .map(|c| {
            (
                c["command"].as_str().unwrap(),
                c["accepted"].as_bool().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        verdicts,
        [
            ("hold", true),
            ("goto", false),
            ("goto", true),
            ("land", true)
        ]
    );
    for name in ["telemetry.csv", "audit.json", "commands.json"] {
        assert_same_file(&sim.join(name), &out.join(name));
    }
}
