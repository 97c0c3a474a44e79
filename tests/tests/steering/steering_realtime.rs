//! Steering a real-time team live (`orchestrator command TEAM ...` while `launch --realtime`
//! flies), with real processes: the orchestrator, `leader` and `agent` binaries over real
//! iceoryx2 shared memory paced by the wall clock, the commands over the team's channel.
//!
//! - The lab mission (four members, a long translation) is held after its take-off
//!   (accepted: every leader acknowledged the proposed switch tick); once it is at rest a
//!   primary leader is stopped (SIGSTOP), and a land given meanwhile is refused with exit 3
//!   (the stopped leader cannot acknowledge it before its switch tick), nothing changed; the
//!   leader resumes, the land is given again and accepted, and the team lands and ends as a
//!   mission does: exit 0, SAFE, every member on the ground, audit.json and commands.json
//!   listing the hold and the land (the withdrawn land is in neither); `replay` of the run
//!   gives its telemetry.csv and commands.json byte for byte.
//! - `--on-interrupt land`: SIGINT to the orchestrator lands the team (certified as a land),
//!   and the run ends as a mission does, exit 0, and `replay` of the run gives its
//!   telemetry.csv and commands.json byte for byte; a second SIGINT while it lands stops the team
//!   at once (exit 3, `interrupted`), nothing left.
//!
//! How to run: `cargo test --release -p integration-tests --test steering -- steering_realtime::`.

use integration_tests::support;

use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use integration_tests::{bin, run, spawn, unique_team, write_scenario, Running, TempDir};
use support::{
    assert_exit, assert_no_process_of, assert_no_team_resources, assert_stderr_has, launch_loud,
    member_pid, read_json, signal, Stopped,
};

/// The lab mission's members (primaries 1-3, follower 4).
const MEMBERS: usize = 4;

const DEADLINE: Duration = integration_tests::deadline::FLIGHT;
const SHORT: Duration = integration_tests::deadline::REFUSE;

/// The primary leader stopped while a command is given.
const STOPPED: u32 = 2;

fn commanded(team: &str, args: &[&str]) -> Output {
    let mut c = Command::new(bin("orchestrator"));
    c.arg("command").arg(team).args(args);
    run(&mut c, SHORT)
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A member's row at one instant: its role, height and speed.
type Row = (String, f64, f64);

/// The latest instant of telemetry.csv that has every member's row: its time and each row.
fn latest_instant(telemetry: &Path, members: usize) -> Option<(f64, Vec<Row>)> {
    let text = std::fs::read_to_string(telemetry).ok()?;
    let rows: Vec<Vec<&str>> = (text.lines().skip(1))
        .filter(|l| l.ends_with(|c: char| c.is_ascii_digit() || c == 'N'))
        .map(|l| l.split(',').collect())
        .filter(|f: &Vec<&str>| f.len() >= 10)
        .collect();
    let newest = rows.last()?[0];
    let mut at: Vec<&Vec<&str>> = rows.iter().filter(|f| f[0] == newest).collect();
    if at.len() < members {
        let prev = (rows.iter().rev()).map(|f| f[0]).find(|t| *t != newest)?;
        at = rows.iter().filter(|f| f[0] == prev).collect();
    }
    let num = |s: &str| s.parse::<f64>().unwrap_or(f64::NAN);
    let t_s = num(at.first()?[1]);
    let out = (at.iter())
        .map(|f| {
            let v = (num(f[7]).powi(2) + num(f[8]).powi(2) + num(f[9]).powi(2)).sqrt();
            (f[3].to_string(), num(f[6]), v)
        })
        .collect();
    Some((t_s, out))
}

/// The lab mission (take-off 4 s, a translation of `t_total_s`, land 4 s) launched in real
/// time with `extra`; a stale bound of 5 s, so a leader stopped for a moment is not lost.
fn launched(dir: &Path, team: &str, t_total_s: f64, extra: &[&str]) -> Running {
    let mut file = support::lab_mission();
    file.t_total_s = t_total_s;
    let scenario = write_scenario(dir, "lab4.toml", &file);
    let path = scenario.to_str().expect("utf-8 path");
    let mut args = vec!["--scenario", path, "--realtime", "--no-figures"];
    args.extend(["--stale-after", "5"]);
    args.extend(extra);
    // Not quiet: the interrupt's notice is on its output.
    spawn(&mut launch_loud(team, &dir.join("launch"), &args))
}

/// Waits until the latest complete instant of telemetry.csv is at or past `t_s`.
fn wait_for_time(orch: &mut Running, telemetry: &Path, t_s: f64) {
    let until = Instant::now() + integration_tests::deadline::scaled(SHORT);
    loop {
        if latest_instant(telemetry, MEMBERS).is_some_and(|(t, _)| t >= t_s) {
            return;
        }
        assert!(!orch.has_exited(), "the launch ended before t = {t_s} s");
        assert!(
            Instant::now() < until,
            "no t = {t_s} s in {}",
            telemetry.display()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits until every leader of the latest complete instant is at rest (under 1 cm/s).
fn wait_at_rest(orch: &mut Running, telemetry: &Path) {
    let until = Instant::now() + integration_tests::deadline::scaled(SHORT);
    loop {
        if let Some((_, rows)) = latest_instant(telemetry, MEMBERS) {
            let leaders = rows.iter().filter(|(role, _, _)| role != "follower");
            if rows.len() == MEMBERS && leaders.clone().all(|(_, _, v)| *v < 0.01) {
                return;
            }
        }
        assert!(
            !orch.has_exited(),
            "the launch ended before the team was at rest"
        );
        assert!(Instant::now() < until, "the held team never came to rest");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_realtime_team_is_held_refused_while_a_leader_is_stopped_then_landed() {
    let tmp = TempDir::new();
    let team = unique_team("rt_steer");
    let out = tmp.path().join("launch");
    let mut orch = launched(tmp.path(), &team, 30.0, &[]);
    let telemetry = out.join("telemetry.csv");
    // Past the take-off (4 s).
    wait_for_time(&mut orch, &telemetry, 5.0);

    let hold = commanded(&team, &["hold"]);
    assert_exit(&hold, 0, "command hold");
    assert!(
        stdout(&hold).contains("hold accepted: switch at tick"),
        "{hold:?}"
    );
    wait_at_rest(&mut orch, &telemetry);

    // A leader that cannot acknowledge: the command is withdrawn before its switch tick.
    let pid = member_pid(&team, STOPPED).expect("the leader runs");
    signal(pid, libc::SIGSTOP);
    let stopped = Stopped(pid);
    let refused = commanded(&team, &["land"]);
    signal(stopped.0, libc::SIGCONT);
    std::mem::forget(stopped);
    assert_exit(&refused, 3, "command land with a leader stopped");
    assert_stderr_has(
        &refused,
        "command land with a leader stopped",
        &[
            "did not acknowledge",
            &format!("[{STOPPED}]"),
            "nothing changed",
        ],
    );
    assert!(
        !orch.has_exited(),
        "a refused command leaves the team flying"
    );

    let land = commanded(&team, &["land"]);
    assert_exit(&land, 0, "command land");
    assert!(
        stdout(&land).contains("land accepted: switch at tick"),
        "{land:?}"
    );
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 0, "launch --realtime held and landed");
    assert_no_process_of(&team);
    assert_no_team_resources(&team);

    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    assert_eq!(
        audited_commands(&audit),
        [("hold".to_string(), true), ("land".to_string(), true)],
        "{audit:#}"
    );
    let list = read_json(&out.join("commands.json"));
    assert_eq!(list.as_array().map(Vec::len), Some(2), "{list:#}");
    assert_on_the_ground(&telemetry);

    // The members recorded when each command became final for them, and the withdrawn one
    // changed nothing: the run replays in one process byte for byte, its commands with it.
    let again = tmp.path().join("replay");
    let replayed = support::replay(&out, &again, &[]);
    assert_exit(&replayed, 0, "replay of a commanded real-time run");
    for name in ["telemetry.csv", "commands.json"] {
        support::assert_same_file(&out.join(name), &again.join(name));
    }
}

/// Every member's last row is on the ground ([landing]'s z = 0), at rest.
fn assert_on_the_ground(telemetry: &Path) {
    let (_, rows) = latest_instant(telemetry, MEMBERS).expect("telemetry");
    assert_eq!(rows.len(), MEMBERS);
    for (role, z, v) in rows {
        assert!(
            z.abs() < 0.05 && v < 0.05,
            "{role} ends at z = {z}, speed {v}"
        );
    }
}

/// The commands audit.json lists: (command, accepted) each.
fn audited_commands(audit: &serde_json::Value) -> Vec<(String, bool)> {
    (audit["commands"].as_array().unwrap().iter())
        .map(|c| {
            (
                c["command"].as_str().unwrap().to_string(),
                c["accepted"].as_bool().unwrap(),
            )
        })
        .collect()
}

#[test]
fn under_on_interrupt_land_sigint_lands_the_team_and_the_run_ends_as_a_mission_does() {
    let tmp = TempDir::new();
    let team = unique_team("rt_int_land");
    let out = tmp.path().join("launch");
    let mut orch = launched(tmp.path(), &team, 30.0, &["--on-interrupt", "land"]);
    let telemetry = out.join("telemetry.csv");
    wait_for_time(&mut orch, &telemetry, 5.0);
    signal(orch.id(), libc::SIGINT);
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 0, "launch --on-interrupt land after SIGINT");
    let said = [&o.stdout, &o.stderr].map(|b| String::from_utf8_lossy(b).into_owned());
    assert!(
        said.iter().any(|t| t.contains("SIGINT: landing the team")),
        "{}",
        integration_tests::describe(&o)
    );
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(
        audited_commands(&audit),
        [("land".to_string(), true)],
        "{audit:#}"
    );
    assert_on_the_ground(&telemetry);
    assert_no_process_of(&team);
    assert_no_team_resources(&team);
    // The members recorded when the land became final for them: the run replays in one
    // process byte for byte, its command with it.
    let again = tmp.path().join("replay");
    let replayed = support::replay(&out, &again, &[]);
    assert_exit(&replayed, 0, "replay of a real-time run landed on SIGINT");
    for name in ["telemetry.csv", "commands.json"] {
        support::assert_same_file(&out.join(name), &again.join(name));
    }
}

#[test]
fn a_second_sigint_while_the_team_lands_stops_it_at_once() {
    let tmp = TempDir::new();
    let team = unique_team("rt_int_twice");
    let out = tmp.path().join("launch");
    let mut orch = launched(tmp.path(), &team, 30.0, &["--on-interrupt", "land"]);
    wait_for_time(&mut orch, &out.join("telemetry.csv"), 5.0);
    signal(orch.id(), libc::SIGINT);
    orch.wait_for_output("SIGINT: landing the team", SHORT);
    signal(orch.id(), libc::SIGINT);
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 3, "launch after a second SIGINT");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["fault"]["kind"], "interrupted", "{audit:#}");
    assert_no_process_of(&team);
    assert_no_team_resources(&team);
}
