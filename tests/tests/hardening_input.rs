//! Bad input: clear errors, exit 2, no panic, no hang. Real binaries.

mod support;

use std::fs;
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{bin, describe, run, spawn, unique_team, TempDir};
use support::*;

/// Every refusal happens before any work; the deadline only stops a hang (a FIFO, /dev/zero).
const DEADLINE: Duration = integration_tests::deadline::SHORT;

fn orchestrator(args: &[&str]) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    c
}

/// Runs the command and asserts exit 2 with every needle in stderr.
fn refused(c: &mut Command, needles: &[&str]) -> Output {
    let what = format!("{c:?}");
    let o = run(c, DEADLINE);
    assert_exit(&o, 2, &what);
    assert_stderr_has(&o, &what, needles);
    assert!(
        !String::from_utf8_lossy(&o.stderr).contains("panicked"),
        "{}",
        describe(&o)
    );
    o
}

fn fifo(path: &Path) {
    let c = std::ffi::CString::new(path.to_str().expect("UTF-8")).expect("path");
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0, "mkfifo");
}

/// Item 10: /dev/zero, /dev/urandom or a FIFO as --scenario, and a FIFO as a run's
/// telemetry.csv for `report`: refused at once (regular files only), exit 2.
#[test]
fn special_files_are_refused_as_inputs() {
    let tmp = TempDir::new();
    let pipe = tmp.path().join("scenario.toml");
    fifo(&pipe);
    for source in ["/dev/zero", "/dev/urandom", pipe.to_str().expect("UTF-8")] {
        refused(
            &mut orchestrator(&["plan", "--scenario", source]),
            &[source, "not a regular file"],
        );
    }
    let out = tmp.path().join("run");
    let o = run(
        &mut simulate(&out, &["--max-ticks", "3", "--no-figures"]),
        DEADLINE,
    );
    assert_exit(&o, 0, "simulate");
    let tel = out.join("telemetry.csv");
    fs::remove_file(&tel).expect("rm");
    fifo(&tel);
    refused(
        orchestrator(&["report"]).arg(&out),
        &["telemetry.csv", "not a regular file"],
    );
}

/// Item 11: every duration option has a range; 1e308 is refused by name, not a panic.
#[test]
fn huge_durations_are_refused_naming_the_option() {
    let tmp = TempDir::new();
    for flag in ["--agent-timeout", "--join-timeout"] {
        let out = tmp.path().join("run");
        let team = unique_team("dur");
        refused(
            launch(&team, &out, &["--n", "4"]).args([flag, "1e308"]),
            &[&format!(
                "{flag} must be a number of seconds in (0, 86400], got 1e308"
            )],
        );
        assert!(!out.exists());
    }
    for flag in ["--silence-timeout", "--join-timeout"] {
        let mut c = member("agent", Path::new("s.toml"), "t", 4);
        refused(
            c.args([flag, "1e308"]),
            &[&format!("{flag} must be a number of seconds in (0, 86400]")],
        );
    }
}

/// Item 12: ticks that cannot resolve the motion are bad input with the reason: too few ticks
/// (`--t-total 0.005`), a clock too slow for the gains' fastest pole (`comm_hz = 0.001`), a
/// clock so fast the certificate would fly for hours (`comm_hz = 500000`).
#[test]
fn plans_whose_ticks_cannot_resolve_the_motion_are_refused() {
    let tmp = TempDir::new();
    let team = unique_team("ticks");
    let out = tmp.path().join("run");
    let needles = ["field `t_total_s`", "ticks over the motion"];
    refused(&mut orchestrator(&["plan", "--t-total", "0.005"]), &needles);
    refused(&mut simulate(&out, &["--t-total", "0.005"]), &needles);
    refused(&mut launch(&team, &out, &["--t-total", "0.005"]), &needles);
    assert!(!out.exists());
    for (hz, needles) in [
        ("0.001", &["field `comm_hz`", "fastest pole"][..]),
        ("500000", &["field `comm_hz`", "at most 10000 Hz"][..]),
    ] {
        let mut f = integration_tests::paper40();
        f.comm_hz = hz.parse().expect("number");
        let p = integration_tests::write_scenario(tmp.path(), "s.toml", &f);
        refused(
            &mut orchestrator(&["plan", "--scenario", p.to_str().expect("UTF-8")]),
            needles,
        );
    }
    assert_no_team_resources(&team);
}

/// Item 13: `--follow` is checked before the flight; `--sweep` like `--t-total`.
#[test]
fn follow_and_sweep_are_checked_up_front() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let team = unique_team("follow");
    refused(
        &mut simulate(&out, &["--follow", "999"]),
        &["--follow 999", "no agent with this id"],
    );
    assert!(!out.exists(), "simulate flew before refusing --follow");
    refused(
        &mut launch(&team, &out, &["--n", "4", "--follow", "999"]),
        &["--follow 999", "no agent with this id"],
    );
    assert!(!out.exists(), "launch flew before refusing --follow");
    assert_no_team_resources(&team);
    let sweep = tmp.path().join("sweep");
    refused(
        orchestrator(&["plan", "--sweep", "30:1e9:1e8", "--out"]).arg(&sweep),
        &["--sweep travel time", "field `t_total_s`", "at most 1e8"],
    );
    assert!(!sweep.exists());
}

/// A named change to one agent's section of a file, and what the error must say.
type Edit = (&'static str, fn(&str) -> String, &'static str);

/// Item 14: in a 1000-agent file, an unknown key on an agent, an unknown role and a position
/// with two components are reported with the agent's id.
#[test]
fn malformed_agents_are_named_by_id() {
    let tmp = TempDir::new();
    let o = run(
        &mut orchestrator(&["scenario", "export", "--n", "1000"]),
        DEADLINE,
    );
    assert_exit(&o, 0, "scenario export --n 1000");
    let text = String::from_utf8(o.stdout).expect("UTF-8");
    let sections: Vec<&str> = text.split("[[agents]]").collect();
    // Section 701 is the 700th agent (index 699).
    let k = 700;
    let id = toml_value(sections[k], "id").expect("id");
    let edits: [Edit; 3] = [
        (
            "unknown key",
            |s| s.replacen("role =", "colour = 1\nrole =", 1),
            "unknown field `colour`",
        ),
        (
            "unknown role",
            |s| s.replacen("\"follower\"", "\"boss\"", 1),
            "unknown variant `boss`",
        ),
        (
            "two components",
            |s| {
                let start = s.find("position = [").expect("position") + 12;
                let end = start + s[start..].find(']').expect("]");
                let mut parts: Vec<&str> = s[start..end].split(',').collect();
                parts.pop();
                format!("{}{}{}", &s[..start], parts.join(","), &s[end..])
            },
            "invalid length 2",
        ),
    ];
    for (what, edit, needle) in edits {
        let mut parts: Vec<String> = sections.iter().map(|s| s.to_string()).collect();
        parts[k] = edit(&parts[k]);
        let p = tmp.path().join(format!("{}.toml", what.replace(' ', "_")));
        fs::write(&p, parts.join("[[agents]]")).expect("write");
        refused(
            &mut orchestrator(&["plan", "--scenario", p.to_str().expect("UTF-8")]),
            &[&format!("agent {id} (agents[{}])", k - 1), needle],
        );
    }
}

/// Item 15: `--no-spawn` with only leader 1 joining: the message lists the agents that did not
/// join (not leader 1), and leader 1 exits 3 saying its team was stopped before the end.
#[test]
fn a_partial_hand_started_team_names_only_the_missing_agents() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let team = unique_team("partial");
    let orch = spawn(
        launch(&team, &out, &["--n", "4", "--t-total", "30"])
            .args(["--no-spawn", "--join-timeout", "3"])
            .arg("--no-figures"),
    );
    let scenario = out.join("scenario.toml");
    let start = std::time::Instant::now();
    while !scenario.exists() {
        assert!(start.elapsed() < DEADLINE, "no scenario.toml");
        std::thread::sleep(Duration::from_millis(20));
    }
    let leader = run(&mut member("leader", &scenario, &team, 1), DEADLINE);
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 3, "launch with only leader 1");
    assert_stderr_has(&o, "launch", &["agents 2, 3, 4 did not join team"]);
    assert_exit(&leader, 3, "leader 1 of a team that never flew");
    assert_stderr_has(
        &leader,
        "leader 1",
        &["stopped by its orchestrator", "before the end of the plan"],
    );
    assert_no_team_resources(&team);
}

/// Item 16: a scenario name is at most 256 bytes; a 10 MB one is refused without being printed.
#[test]
fn long_names_are_refused_without_printing_them() {
    let tmp = TempDir::new();
    for len in [257, 10_000_000] {
        let mut f = integration_tests::paper40();
        f.name = "n".repeat(len);
        let p = integration_tests::write_scenario(tmp.path(), "s.toml", &f);
        let o = refused(
            &mut orchestrator(&["plan", "--scenario", p.to_str().expect("UTF-8")]),
            &[&format!("field `name` is {len} bytes long; at most 256")],
        );
        assert!(o.stderr.len() < 4096, "{} bytes of error", o.stderr.len());
    }
}
