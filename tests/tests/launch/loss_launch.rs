//! Losing members in flight with real processes: the orchestrator,
//! `leader` and `agent` binaries over real iceoryx2 shared memory, paper40 cut short with
//! `--max-ticks`.
//!
//! - `launch --lose` of a follower, a secondary leader and a primary leader (the orchestrator
//!   SIGKILLs each once it has published its tick): exit 0, the repairs recorded as `simulate`
//!   records them, and telemetry byte-identical to `simulate --lose`.
//! - A member that dies unannounced (SIGKILL at a chosen tick, `CDM_FAULT_INJECT`) - a follower,
//!   a secondary and a primary leader: exit 0, the loss recorded with cause `killed` and its
//!   last tick, the survivors' separation above 2 eps, nothing of the team left; and
//!   `simulate --lose ID@(last tick x dt)` replays the run byte for byte.
//! - A member that hangs (SIGSTOP at a chosen tick) is killed after `--agent-timeout`, repaired
//!   around, and replays the same way.
//! - `--lose` with `--no-spawn` is refused (exit 2).
//!
//! `--on-loss stop` keeping the old behaviour is `faults.rs` (killed leaders, hung agent).

use integration_tests::support;

use std::path::Path;
use std::process::Output;
use std::time::Duration;

use integration_tests::{describe, run, unique_team, TempDir};
use serde_json::Value;
use support::{
    assert_exit, assert_no_process_of, assert_no_team_resources, assert_same_file, launch,
    read_json, simulate,
};

/// A 801- to 1501-tick paper40 flight of 41 processes takes about a second; the rest is slack
/// for a loaded machine.
const DEADLINE: Duration = integration_tests::deadline::FLIGHT;

/// paper40: 1-3 primary leaders, 4-6 secondary, follower 20 read by follower 29; dt = 0.01 s.
const SOURCE: [&str; 2] = ["--builtin", "paper40"];
const DT_S: f64 = 0.01;

fn args<'a>(extra: &[&'a str]) -> Vec<&'a str> {
    let mut v: Vec<&str> = SOURCE.to_vec();
    v.push("--no-figures");
    v.extend_from_slice(extra);
    v
}

fn losses(audit: &Value) -> Vec<(u64, String, u64, u64, Value, Value)> {
    audit["losses"]
        .as_array()
        .expect("audit.json has losses")
        .iter()
        .map(|l| {
            (
                l["id"].as_u64().unwrap(),
                l["cause"].as_str().unwrap().to_string(),
                l["last_tick"].as_u64().unwrap(),
                l["tick"].as_u64().unwrap(),
                l["retriangulated"].clone(),
                l["degraded"].clone(),
            )
        })
        .collect()
}

/// The audit's verdict and the survivors' separation (the audit leaves lost bodies out).
fn assert_safe(audit: &Value, what: &str) {
    assert_eq!(audit["verdict"], "SAFE", "{what}: {audit:#}");
    let sep = audit["min_separation_m"].as_f64().unwrap();
    let eps = audit["eps_m"].as_f64().unwrap();
    assert!(sep > 2.0 * eps, "{what}: separation {sep} m <= 2 eps");
}

fn launched(team: &str, out: &Path, extra: &[&str], env: Option<String>) -> Output {
    let mut c = launch(team, out, &args(extra));
    if let Some(v) = env {
        c.env(cdm_process::fault_inject::ENV, v);
    }
    let o = run(&mut c, DEADLINE);
    assert_no_process_of(team);
    assert_no_team_resources(team);
    o
}

#[test]
fn launch_lose_kills_three_members_and_equals_simulate_byte_for_byte() {
    let tmp = TempDir::new();
    let lose = [
        "--max-ticks",
        "800",
        "--lose",
        "20@3",
        "--lose",
        "5@4.5",
        "--lose",
        "1@6",
    ];
    let sim = tmp.path().join("sim");
    let o = run(&mut simulate(&sim, &args(&lose)), DEADLINE);
    assert_exit(&o, 0, "simulate --lose");
    let team = unique_team("lose3");
    let lau = tmp.path().join("launch");
    let o = launched(&team, &lau, &lose, None);
    assert_exit(&o, 0, "launch --lose");
    assert_same_file(&sim.join("telemetry.csv"), &lau.join("telemetry.csv"));
    let (a, b) = (
        read_json(&sim.join("audit.json")),
        read_json(&lau.join("audit.json")),
    );
    assert_eq!(losses(&a), losses(&b));
    let got: Vec<(u64, u64)> = losses(&b).iter().map(|l| (l.0, l.3)).collect();
    assert_eq!(got, [(20, 301), (5, 451), (1, 601)]);
    assert!(losses(&b).iter().all(|l| l.1 == "scripted"));
    assert_eq!(
        losses(&b)[0].4[0]["id"],
        29,
        "29 read 20: {:#}",
        b["losses"]
    );
    assert_safe(&b, "launch --lose");
}

/// A member that dies (`kill`) or hangs (`stop`, then killed after `--agent-timeout`) at tick
/// `at` instead of publishing it: lost after tick at - 1 with `cause`, repaired, and
/// `simulate --lose` of that tick replays the run byte for byte.
fn lost_unannounced(id: u32, (how, at): (&str, u64), cause: &str) {
    let tmp = TempDir::new();
    let team = unique_team(&format!("{how}{id}"));
    let lau = tmp.path().join("launch");
    let cut = ["--max-ticks", "1200", "--agent-timeout", "1.5"];
    let o = launched(&team, &lau, &cut, Some(format!("{id}:{how}@{at}")));
    assert_exit(&o, 0, &format!("launch with agent {id} {how} at tick {at}"));
    let audit = read_json(&lau.join("audit.json"));
    let l = losses(&audit);
    assert_eq!(l.len(), 1, "{:#}", audit["losses"]);
    assert_eq!(
        (l[0].0, l[0].1.as_str(), l[0].2, l[0].3),
        (id as u64, cause, at - 1, at)
    );
    let repaired = l[0].4.as_array().unwrap().len() + l[0].5.as_array().unwrap().len();
    assert!(
        repaired > 0,
        "nobody repaired around {id}: {:#}",
        audit["losses"]
    );
    assert_safe(&audit, &format!("agent {id} {how}"));
    let sim = tmp.path().join("replay");
    let when = format!("{id}@{}", (at - 1) as f64 * DT_S);
    let o = run(
        &mut simulate(&sim, &args(&["--max-ticks", "1200", "--lose", &when])),
        DEADLINE,
    );
    assert_exit(&o, 0, &format!("simulate --lose {when}"));
    assert_same_file(&sim.join("telemetry.csv"), &lau.join("telemetry.csv"));
}

#[test]
fn a_killed_follower_is_repaired_and_replays_in_simulate() {
    lost_unannounced(20, ("kill", 700), "killed");
}

#[test]
fn a_killed_secondary_leader_is_repaired_and_replays_in_simulate() {
    lost_unannounced(5, ("kill", 650), "killed");
}

#[test]
fn a_killed_primary_leader_is_repaired_and_replays_in_simulate() {
    lost_unannounced(1, ("kill", 600), "killed");
}

/// Follower 20 hangs (SIGSTOP, alive and silent): after `--agent-timeout 1.5` the orchestrator
/// kills it and repairs around it (`silent`); its reader 29 switches triangles.
#[test]
fn a_hung_member_is_killed_after_the_agent_timeout_and_repaired_around() {
    lost_unannounced(20, ("stop", 500), "silent");
}

#[test]
fn lose_needs_spawned_members() {
    let tmp = TempDir::new();
    let team = unique_team("lose_nospawn");
    let out = tmp.path().join("run");
    let o = run(
        &mut launch(&team, &out, &args(&["--no-spawn", "--lose", "20@3"])),
        DEADLINE,
    );
    assert_exit(&o, 2, "launch --no-spawn --lose");
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--lose needs members spawned"),
        "{}",
        describe(&o)
    );
    assert!(!out.exists(), "a refused launch wrote {}", out.display());
}
