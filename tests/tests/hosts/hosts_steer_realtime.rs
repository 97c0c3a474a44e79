//! Steering a real-time team over two hosts (network namespaces, real zenoh over mutual TLS,
//! `support::netns`): a command's proposal rides the clock message over the link to host B's
//! members, and host B's leaders' acknowledgements come back in their states over the link.
//!
//! - The lab mission (four members, split over the two hosts) with a command file that holds
//!   it after its take-off: proposed in flight, final once every leader on both hosts
//!   acknowledged it. Then, live, a leader of host B is stopped (SIGSTOP) and `orchestrator
//!   command TEAM land` is refused with exit 3 naming it (its acknowledgement never came over
//!   the link; withdrawn, nothing changed); resumed, the land is given again and accepted, and
//!   the team lands and ends as a mission does on both hosts: exit 0, SAFE, every member on
//!   the ground, commands.json listing the hold and the land.
//! - `--on-interrupt land` across hosts: SIGINT to the orchestrator lands the team on both
//!   hosts, certified as a land, and the run ends as a mission does (exit 0 on both sides);
//!   `replay` of the run gives its telemetry.csv and commands.json byte for byte.
//!
//! Needs root (CI runs as root); skips, printing why, when namespaces cannot be created.

use std::path::Path;

use integration_tests::{run, spawn, unique_team, write_scenario, Running, TempDir};

use integration_tests::support;
use support::netns::Hosts;
use support::*;

use crate::hosts::{daemon_pid, launch_args};

const RUN_DEADLINE: std::time::Duration = integration_tests::deadline::FLIGHT;
const SHORT: std::time::Duration = integration_tests::deadline::REFUSE;

/// The lab mission's members (primaries 1-3, follower 4).
const MEMBERS: usize = 4;

/// The lab mission with a 30 s translation launched in real time over the two hosts with
/// `extra` (a stale bound of 5 s, so a leader stopped for a moment is not lost), and its
/// daemon on host B.
fn launched(h: &Hosts, dir: &Path, team: &str, extra: &[&str]) -> (Running, Running) {
    let mut file = support::lab_mission();
    file.t_total_s = 30.0;
    let scenario = write_scenario(dir, "lab4.toml", &file);
    let out = dir.join("launch").to_string_lossy().into_owned();
    let mut source = vec!["--scenario", scenario.to_str().unwrap(), "--realtime"];
    source.extend(["--stale-after", "5", "--no-figures"]);
    source.extend(extra);
    let orch = spawn(&mut h.on_a(&launch_args(h, team, &out, &source)));
    let daemon = spawn(&mut h.daemon(&["--team", team]));
    (orch, daemon)
}

/// A primary leader flying on host B (in the daemon's network namespace): its process id.
fn leader_on_b(team: &str) -> (u32, u32) {
    let ns = |pid: u32| std::fs::read_link(format!("/proc/{pid}/ns/net")).ok();
    let b = ns(daemon_pid(team));
    (1..=3)
        .filter_map(|id| Some((id, member_pid(team, id)?)))
        .find(|&(_, pid)| ns(pid) == b)
        .expect("a primary leader runs on host B")
}

/// The members' last telemetry rows are on the ground ([landing]'s z = 0), at rest.
fn assert_on_the_ground(telemetry: &Path) {
    let text = std::fs::read_to_string(telemetry).expect("telemetry.csv");
    let rows: Vec<Vec<f64>> = (text.lines().skip(1))
        .map(|l| (l.split(',').map(|f| f.parse().unwrap_or(f64::NAN))).collect())
        .collect();
    for f in &rows[rows.len() - MEMBERS..] {
        let v = (f[7].powi(2) + f[8].powi(2) + f[9].powi(2)).sqrt();
        assert!(
            f[6].abs() < 0.05 && v < 0.05,
            "ends at z = {}, speed {v}",
            f[6]
        );
    }
}

/// The commands audit.json lists: (command, accepted) each.
fn audited(out: &Path) -> Vec<(String, bool)> {
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    (audit["commands"].as_array().unwrap().iter())
        .map(|c| {
            let name = c["command"].as_str().unwrap().to_string();
            (name, c["accepted"].as_bool().unwrap())
        })
        .collect()
}

#[test]
fn a_realtime_team_over_two_hosts_is_steered_with_acknowledgements_over_the_link() {
    let Some(h) = Hosts::create("rs") else { return };
    let dir = TempDir::new();
    let team = unique_team("hrtsteer");
    let file = dir.path().join("commands.json");
    std::fs::write(&file, r#"[{"at_s": 5.0, "command": "hold"}]"#).unwrap();
    let (mut orch, daemon) = launched(
        &h,
        dir.path(),
        &team,
        &["--commands", file.to_str().unwrap()],
    );
    let out = dir.path().join("launch");
    // Held (t = 7 s at 50 instants a second, four rows each).
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), MEMBERS * 350);

    let (id, pid) = leader_on_b(&team);
    signal(pid, libc::SIGSTOP);
    let stopped = Stopped(pid);
    let refused = run(&mut h.on_a(&["command", &team, "land"]), SHORT);
    signal(stopped.0, libc::SIGCONT);
    std::mem::forget(stopped);
    assert_exit(&refused, 3, "command land with a leader of host B stopped");
    assert_stderr_has(
        &refused,
        "command land with a leader of host B stopped",
        &["did not acknowledge", &format!("[{id}]"), "nothing changed"],
    );
    let land = run(&mut h.on_a(&["command", &team, "land"]), SHORT);
    assert_exit(&land, 0, "command land over two hosts");

    assert_exit(&orch.finish(RUN_DEADLINE), 0, "launch --realtime --hosts 2");
    assert_exit(&daemon.finish(RUN_DEADLINE), 0, "orchestrator host");
    assert_eq!(
        audited(&out),
        [("hold".to_string(), true), ("land".to_string(), true)]
    );
    assert_on_the_ground(&out.join("telemetry.csv"));
    assert_no_team_resources(&team);
}

#[test]
fn sigint_lands_a_realtime_team_over_two_hosts() {
    let Some(h) = Hosts::create("ri") else { return };
    let dir = TempDir::new();
    let team = unique_team("hrtint");
    let (mut orch, daemon) = launched(&h, dir.path(), &team, &["--on-interrupt", "land"]);
    let out = dir.path().join("launch");
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), MEMBERS * 300);
    signal(orch.id(), libc::SIGINT);
    assert_exit(&orch.finish(RUN_DEADLINE), 0, "launch after SIGINT");
    assert_exit(&daemon.finish(RUN_DEADLINE), 0, "orchestrator host");
    assert_eq!(audited(&out), [("land".to_string(), true)]);
    assert_on_the_ground(&out.join("telemetry.csv"));
    assert_no_team_resources(&team);
    // Host B's members recorded when the land became final for them: the run replays in one
    // process byte for byte, its command with it.
    let again = dir.path().join("replay");
    let replayed = replay(&out, &again, &[]);
    assert_exit(
        &replayed,
        0,
        "replay of a two-host real-time run landed on SIGINT",
    );
    for name in ["telemetry.csv", "commands.json"] {
        assert_same_file(&out.join(name), &again.join(name));
    }
}
