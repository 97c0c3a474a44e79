//! A command file flown in real time (`launch --realtime --commands FILE`), with real
//! processes: the orchestrator, `leader` and `agent` binaries over real iceoryx2 shared memory
//! paced by the wall clock.
//!
//! - The lab mission (four members, a long translation) with a file that holds it after its
//!   take-off, asks for an UNSAFE goto (refused by its certificate, nothing changes), sends it
//!   to a SAFE goto and lands it: each command is certified at its own switch tick, proposed
//!   to the leaders in flight and made final by their acknowledgements; the team lands and
//!   ends as a mission does (exit 0, SAFE, every member on the ground, long before the plan's
//!   own end). commands.json and audit.json's `commands` are those `simulate --commands FILE`
//!   writes, byte for byte (the certificates are computed at the same ticks on the same
//!   plans; the telemetry is not: real time audits the members' newest states), and `replay`
//!   of the run gives its telemetry.csv and commands.json byte for byte.
//! - A file command switching before the lead a proposal needs is refused up front, exit 2,
//!   naming the file and the command; nothing is made.
//!
//! How to run: `cargo test --release -p integration-tests --test steering -- steering_realtime_file::`.

use integration_tests::support;

use std::path::Path;

use integration_tests::{run, unique_team, write_scenario, TempDir};
use support::{
    assert_exit, assert_no_process_of, assert_no_team_resources, assert_same_file,
    assert_stderr_has, launch, read_json, simulate,
};

const DEADLINE: std::time::Duration = integration_tests::deadline::FLIGHT;

/// Held at 5 s (past the 4 s take-off), an UNSAFE goto (the three primaries nearly on one
/// line), a SAFE goto (the triangle moved by 0.4 m), then landed.
pub const LAB_COMMANDS: &str = r#"[
  {"at_s": 5.0, "command": "hold"},
  {"at_s": 6.0, "command": "goto", "goals": [[0.3, 0.2, 1.7], [3.3, 0.2, 1.7], [1.8, 0.25, 1.7]]},
  {"at_s": 6.5, "command": "goto", "goals": [[0.7, 0.2, 1.7], [3.7, 0.2, 1.7], [2.2, 2.8, 1.7]],
   "travel_s": 3.0},
  {"at_s": 10.5, "command": "land"}
]"#;

/// The lab mission with a 30 s translation, written to `dir`.
fn scenario(dir: &Path) -> std::path::PathBuf {
    let mut file = support::lab_mission();
    file.t_total_s = 30.0;
    write_scenario(dir, "lab4.toml", &file)
}

/// The members' last telemetry rows: (time, height, speed) each.
fn last_rows(telemetry: &Path, members: usize) -> Vec<(f64, f64, f64)> {
    let text = std::fs::read_to_string(telemetry).expect("telemetry.csv");
    let rows: Vec<Vec<f64>> = (text.lines().skip(1))
        .map(|l| (l.split(',').map(|f| f.parse().unwrap_or(f64::NAN))).collect())
        .collect();
    (rows[rows.len() - members..].iter())
        .map(|f| {
            let v = (f[7].powi(2) + f[8].powi(2) + f[9].powi(2)).sqrt();
            (f[1], f[6], v)
        })
        .collect()
}

#[test]
fn a_realtime_team_flies_a_command_file_decided_as_simulate_decides_it() {
    let tmp = TempDir::new();
    let file = tmp.path().join("commands.json");
    std::fs::write(&file, LAB_COMMANDS).unwrap();
    let scenario = scenario(tmp.path());
    let (f, s) = (file.to_str().unwrap(), scenario.to_str().unwrap());
    let sim = tmp.path().join("sim");
    let o = run(
        &mut simulate(&sim, &["--scenario", s, "--no-figures", "--commands", f]),
        DEADLINE,
    );
    assert_exit(&o, 0, "simulate --commands");

    let team = unique_team("rt_file");
    let out = tmp.path().join("launch");
    let args = [
        "--scenario",
        s,
        "--no-figures",
        "--commands",
        f,
        "--realtime",
    ];
    let o = run(
        &mut launch(&team, &out, &[&args[..], &["--stale-after", "5"]].concat()),
        DEADLINE,
    );
    assert_exit(&o, 0, "launch --realtime --commands");
    assert_no_process_of(&team);
    assert_no_team_resources(&team);

    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    let sim_audit = read_json(&sim.join("audit.json"));
    assert_eq!(audit["commands"], sim_audit["commands"], "{audit:#}");
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
    assert_same_file(&sim.join("commands.json"), &out.join("commands.json"));
    let list = read_json(&out.join("commands.json"));
    let ticks: Vec<u64> = (list.as_array().unwrap().iter())
        .map(|c| c["switch_tick"].as_u64().unwrap())
        .collect();
    // At 50 Hz: each switch at the tick of its at_s.
    assert_eq!(ticks, [250, 300, 325, 525]);

    // Landed where the land put it: on the ground, at rest, long before the plan's own end
    // (4 s take-off, 30 s translation, 4.5 s landing).
    for (t, z, v) in last_rows(&out.join("telemetry.csv"), 4) {
        assert!(
            t < 30.0,
            "the flight ends at t = {t} s: the land did not switch"
        );
        assert!(z.abs() < 0.05 && v < 0.05, "ends at z = {z}, speed {v}");
    }

    let again = tmp.path().join("replay");
    let replayed = support::replay(&out, &again, &[]);
    assert_exit(
        &replayed,
        0,
        "replay of a real-time run with a command file",
    );
    for name in ["telemetry.csv", "commands.json"] {
        assert_same_file(&out.join(name), &again.join(name));
    }
}

#[test]
fn a_file_command_too_early_for_a_realtime_proposal_is_refused_naming_it() {
    let tmp = TempDir::new();
    let file = tmp.path().join("early.json");
    // The margin is 0.5 s with --stale-after 5 (a tenth of it): a file's command needs 1 s.
    std::fs::write(&file, r#"[{"at_s": 0.5, "command": "hold"}]"#).unwrap();
    let scenario = scenario(tmp.path());
    let (f, s) = (file.to_str().unwrap(), scenario.to_str().unwrap());
    let team = unique_team("rt_file_early");
    let out = tmp.path().join("rt");
    let args = ["--scenario", s, "--commands", f, "--realtime"];
    let o = run(
        &mut launch(&team, &out, &[&args[..], &["--stale-after", "5"]].concat()),
        DEADLINE,
    );
    assert_exit(&o, 2, "launch --realtime --commands with an early command");
    assert_stderr_has(
        &o,
        "an early command",
        &["early.json", "commands[0]", "switches too early"],
    );
    assert!(!out.exists(), "a run directory was made");
    assert_no_process_of(&team);
}
