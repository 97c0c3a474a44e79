//! Steering a running team live (`orchestrator command TEAM ...`), with real processes: the
//! orchestrator, `leader` and `agent` binaries over real iceoryx2 shared memory, the commands
//! over the team's channel (a Unix socket).
//!
//! - paper40 launched in lockstep; with one follower stopped (SIGSTOP: the grants wait for it,
//!   so the commands surely arrive in flight) it is held, refused an UNSAFE goto and sent to a
//!   SAFE goto (both sent at once), then landed; the follower resumes and the team flies to
//!   the ground. audit.json lists the four commands with their verdicts, SAFE; and
//!   `simulate --commands RUN/commands.json` flies the same run byte for byte (telemetry.csv,
//!   audit.json, commands.json). A command after the team ended gets exit 3.
//! - A refused command leaves the flight as it was: telemetry.csv equals an uncommanded
//!   simulate's.
//! - Bad input (malformed or non-finite goals, goals for a hold, a bad team name) is exit 2
//!   and an unknown team exit 3, without a team.
//!
//! How to run: `cargo test --release -p integration-tests --test steering_live`.

mod support;

use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{bin, run, spawn, unique_team};
use support::steering::{resume, stopped_team};
use support::{
    assert_exit, assert_no_process_of, assert_no_team_resources, assert_same_file,
    assert_stderr_has, read_json, simulate,
};

const DEADLINE: Duration = integration_tests::deadline::FLIGHT;
const SHORT: Duration = integration_tests::deadline::REFUSE;

/// The squeezed goals of `STEERING_COMMANDS` (lambda_1 below lambda_CD,min: UNSAFE) and its
/// SAFE ones.
const UNSAFE_GOALS: [&str; 3] = ["224,434,600", "220,224,600", "228,224,600"];
const SAFE_GOALS: [&str; 3] = ["224,434,600", "126,224,600", "322,224,600"];

fn command(team: &str, args: &[&str]) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.arg("command").arg(team).args(args);
    c
}

fn commanded(team: &str, args: &[&str]) -> Output {
    run(&mut command(team, args), SHORT)
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn a_live_commanded_flight_is_held_refused_sent_and_landed_and_replays_byte_for_byte() {
    let (tmp, team, out, orch, stopped) = stopped_team("live");
    let hold = commanded(&team, &["hold"]);
    assert_exit(&hold, 0, "command hold");
    assert!(
        stdout(&hold).contains("hold accepted: switch at tick"),
        "{hold:?}"
    );
    // Two at once: each gets its own answer, one after the other.
    let goto = |goals: [&str; 3]| spawn(&mut command(&team, &[&["goto"][..], &goals].concat()));
    let (unsafe_goto, safe_goto) = (goto(UNSAFE_GOALS), goto(SAFE_GOALS));
    let (unsafe_goto, safe_goto) = (unsafe_goto.finish(SHORT), safe_goto.finish(SHORT));
    assert_exit(&unsafe_goto, 1, "command goto (squeezed)");
    let why = stdout(&unsafe_goto);
    assert!(why.contains("UNSAFE") && why.contains("lambda_1"), "{why}");
    assert_exit(&safe_goto, 0, "command goto");
    assert_exit(&commanded(&team, &["land"]), 0, "command land");
    resume(stopped);
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 0, "launch commanded live");
    assert_no_process_of(&team);
    assert_no_team_resources(&team);
    let after = commanded(&team, &["hold"]);
    assert_exit(&after, 3, "command after the team ended");
    assert_stderr_has(&after, "command after the end", &[&team]);

    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    let mut verdicts: Vec<(&str, bool)> = (audit["commands"].as_array().unwrap().iter())
        .map(|c| {
            (
                c["command"].as_str().unwrap(),
                c["accepted"].as_bool().unwrap(),
            )
        })
        .collect();
    verdicts.sort();
    assert_eq!(
        verdicts,
        [
            ("goto", false),
            ("goto", true),
            ("hold", true),
            ("land", true)
        ]
    );
    let sim = tmp.path().join("sim");
    let list = out.join("commands.json");
    let source = ["--builtin", "paper40", "--no-figures", "--commands"];
    let mut args = source.to_vec();
    args.push(list.to_str().unwrap());
    assert_exit(
        &run(&mut simulate(&sim, &args), DEADLINE),
        0,
        "simulate --commands",
    );
    for name in ["telemetry.csv", "audit.json", "commands.json"] {
        assert_same_file(&sim.join(name), &out.join(name));
    }
}

#[test]
fn a_refused_command_leaves_the_flight_as_it_was() {
    let (tmp, team, out, orch, stopped) = stopped_team("live_refused");
    let refused = commanded(&team, &[&["goto"][..], &UNSAFE_GOALS].concat());
    assert_exit(&refused, 1, "command goto (squeezed)");
    resume(stopped);
    assert_exit(&orch.finish(DEADLINE), 0, "launch refused a command");
    assert_no_process_of(&team);
    let sim = tmp.path().join("sim");
    let plain = ["--builtin", "paper40", "--no-figures"];
    assert_exit(&run(&mut simulate(&sim, &plain), DEADLINE), 0, "simulate");
    assert_same_file(&sim.join("telemetry.csv"), &out.join("telemetry.csv"));
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["commands"][0]["accepted"], false, "{audit:#}");
}

#[test]
fn bad_commands_are_refused_before_any_team_is_asked() {
    let team = unique_team("live_none");
    let bad: [(&[&str], &str); 5] = [
        (&["goto", "1,2,3", "4,5,6"], "3 primary leaders"),
        (&["goto", "1,2,3", "4,5,6", "7,NaN,9"], "not a finite"),
        (&["goto", "1,2,3", "4,5", "7,8,9"], "X,Y,Z"),
        (&["hold", "1,2,3"], "only goto"),
        (
            &["goto", "1,2,3", "4,5,6", "7,8,9", "--travel-s", "-1"],
            "--travel-s",
        ),
    ];
    for (args, needle) in bad {
        let o = commanded(&team, args);
        assert_exit(&o, 2, &format!("command {args:?}"));
        assert_stderr_has(&o, "command", &[needle]);
    }
    let o = commanded("no/such team", &["hold"]);
    assert_exit(&o, 2, "command to a bad team name");
    let o = commanded(&team, &["land"]);
    assert_exit(&o, 3, "command to no team");
    assert_stderr_has(&o, "command to no team", &[&team]);
}
