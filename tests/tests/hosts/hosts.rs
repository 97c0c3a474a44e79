//! One team over two "hosts": two network namespaces joined by a veth pair
//! (10.77.0.1/24 and 10.77.0.2/24). Host A runs the orchestrator and its share of the members;
//! host B runs `orchestrator host` and the other share with its own /dev/shm (a tmpfs mounted in
//! a private mount namespace), so only the network joins them, over mutual TLS with the team's
//! keys (`support::netns`) as a user runs it.
//!
//! - Lockstep over zenoh writes exactly `simulate`'s telemetry; the subscription graph, read on
//!   both hosts, is the communication graph, and the edges that cross hosts are recorded.
//! - A partition (the veth link down) stops both sides within the link deadline, named; the
//!   orchestrator keeps every complete tick.
//! - A daemon killed with SIGKILL: its members exit by themselves, the orchestrator stops the
//!   team naming them.
//! - Foreign daemons (another scenario, another team, a host already taken) are refused; the
//!   orchestrator killed with SIGKILL: the daemon and every member exit by themselves.
//! - Real time: a short plan paced on one wall-clock start instant on both hosts is SAFE, with
//!   every member's pacing counted; a daemon killed mid-flight is named with its members; a
//!   partition, or a daemon stopped with SIGSTOP, is the host's loss on both sides, named.
//! - Commands (a file, and `orchestrator command` live) steer a team over two hosts exactly as
//!   `simulate --commands` flies them.
//! - A killed daemon's work directory is removed by the next daemon.
//! - Nothing is left in /dev/shm on either side.
//!
//! Needs root (CI runs as root). Each test names its namespaces uniquely and deletes them on
//! drop; only when namespaces cannot be created does a test skip, printing why.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use integration_tests::{bin, describe, run, spawn, unique_team, Running, TempDir};
use serde_json::Value;

use integration_tests::support;
use support::netns::{left_on_b, Hosts};
use support::*;

/// A 10-agent team over two hosts runs a few thousand ticks in seconds; the rest is slack.
const RUN_DEADLINE: Duration = integration_tests::deadline::FLIGHT;
/// The link deadline given to the orchestrator (`--link-timeout`), in seconds.
const LINK_TIMEOUT_S: &str = "2";
/// From a fault (partition, kill) to every process of the team gone: the link deadline, the
/// team's bounded stop, and slack for a loaded machine.
const STOP_DEADLINE: Duration = integration_tests::deadline::REFUSE;
/// A daemon exits at once when it is refused.
const REFUSE_DEADLINE: Duration = integration_tests::deadline::REFUSE;

/// The orchestrator's `launch` on two hosts, over mutual TLS with the pair's keys.
pub(crate) fn launch_args(h: &Hosts, team: &str, out: &str, source: &[&str]) -> Vec<String> {
    let mut v = vec!["launch"];
    v.extend_from_slice(source);
    v.extend_from_slice(&[
        "--team",
        team,
        "--out",
        out,
        "--quiet",
        "--hosts",
        "2",
        "--link-timeout",
        LINK_TIMEOUT_S,
    ]);
    let mut v: Vec<String> = v.into_iter().map(str::to_owned).collect();
    v.extend(h.listen_args());
    v
}

/// Waits until no process names `team` (bounded).
fn wait_no_process_of(team: &str, deadline: Duration) {
    let until = Instant::now() + deadline;
    while !team_processes(team).is_empty() && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_no_process_of(team);
}

fn host_agents(hosts: &Value, k: usize) -> BTreeSet<u32> {
    hosts["hosts"][k - 1]["agents"]
        .as_array()
        .unwrap_or_else(|| panic!("hosts.json: no agents for host {k}: {hosts:#}"))
        .iter()
        .filter_map(Value::as_u64)
        .map(|v| v as u32)
        .collect()
}

fn names(v: &Value) -> Vec<String> {
    v.as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
        .map(str::to_owned)
        .collect()
}

/// N = 10 over two hosts in lockstep: byte-identical to `simulate`; every edge is subscribed on
/// the host(s) that carry it; nothing left on either host.
#[test]
fn two_hosts_fly_lockstep_exactly_as_simulate() {
    let Some(h) = Hosts::create("ls") else { return };
    let dir = TempDir::new();
    let team = unique_team("hosts");
    let (out, sim) = (dir.path().join("launch"), dir.path().join("sim"));
    let source = ["--n", "10", "--t-total", "20"];
    let out_s = out.to_string_lossy().into_owned();
    let orch = spawn(&mut h.on_a(&launch_args(&h, &team, &out_s, &source)));
    let daemon = spawn(&mut h.daemon(&["--team", &team]));
    let s = run(&mut simulate(&sim, &source), RUN_DEADLINE);
    assert_exit(&s, 0, "simulate");
    let o = orch.finish(RUN_DEADLINE);
    let d = daemon.finish(RUN_DEADLINE);
    assert_exit(&o, 0, "launch --hosts 2");
    assert_exit(&d, 0, "orchestrator host");
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));

    let hosts = read_json(&out.join("hosts.json"));
    assert_eq!(hosts["hosts"][0]["outcome"], "stopped", "{hosts:#}");
    let on_b = host_agents(&hosts, 1);
    assert_eq!(on_b.len(), 5, "{hosts:#}");
    let flown = flown_scenario(&out);
    let subs_a = read_json(&out.join("subscriptions.json"));
    let subs_b = &hosts["hosts"][0]["subscriptions"];
    let mut crossing = vec![];
    for a in &flown.agents {
        for &j in a.in_neighbors.iter().flatten() {
            let (i, reader) = (a.id, format!("cdm/{team}/agent/{}", a.id));
            let (src_b, dst_b) = (on_b.contains(&j), on_b.contains(&i));
            let (seen_a, seen_b) = (names(&subs_a[j.to_string()]), names(&subs_b[j.to_string()]));
            match (src_b, dst_b) {
                (false, false) => assert!(seen_a.contains(&reader), "{j}->{i} on A: {seen_a:?}"),
                (true, true) => assert!(seen_b.contains(&reader), "{j}->{i} on B: {seen_b:?}"),
                (false, true) => {
                    // Read on A by host 1's relay of agent i.
                    let relay = format!("cdm/{team}/host/1/agent/{i}");
                    assert!(seen_a.contains(&relay), "{j}->{i} crosses: {seen_a:?}");
                    crossing.push((j, i));
                }
                (true, false) => {
                    assert!(seen_a.contains(&reader), "{j}->{i} crosses: {seen_a:?}");
                    crossing.push((j, i));
                }
            }
        }
    }
    crossing.sort_unstable();
    let recorded: Vec<(u32, u32)> = serde_json::from_value(hosts["crossing_edges"].clone())
        .unwrap_or_else(|e| panic!("hosts.json crossing_edges: {e}: {hosts:#}"));
    assert_eq!(recorded, crossing, "{hosts:#}");
    assert!(!crossing.is_empty(), "a split team has crossing edges");
    assert_no_team_resources(&team);
    assert_eq!(left_on_b(&d), Vec::<String>::new(), "{}", describe(&d));
}

/// A mission (take-off, three segments, landing: `support::mission`) over two hosts flies the
/// telemetry of `simulate`, byte for byte.
#[test]
fn a_mission_over_two_hosts_flies_as_simulate() {
    let Some(h) = Hosts::create("lm") else { return };
    let dir = TempDir::new();
    let team = unique_team("hmission");
    let scenario = integration_tests::write_scenario(dir.path(), "mission.toml", &mission());
    let (out, sim) = (dir.path().join("launch"), dir.path().join("sim"));
    let source = ["--scenario", scenario.to_str().unwrap(), "--no-figures"];
    let out_s = out.to_string_lossy().into_owned();
    let orch = spawn(&mut h.on_a(&launch_args(&h, &team, &out_s, &source)));
    let daemon = spawn(&mut h.daemon(&["--team", &team]));
    assert_exit(
        &run(&mut simulate(&sim, &source), RUN_DEADLINE),
        0,
        "simulate",
    );
    assert_exit(&orch.finish(RUN_DEADLINE), 0, "launch --hosts 2");
    assert_exit(&daemon.finish(RUN_DEADLINE), 0, "orchestrator host");
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
    assert_no_team_resources(&team);
}

/// Real time over two hosts: the start instant travels as a wall-clock time in the clock's
/// message, members on both hosts pace on it and states cross as they come. A 3 s plan
/// (301 audits) completes SAFE with its pacing figures; nothing left on either host; the
/// members' recordings of both hosts are in the run directory and `replay` flies the run again
/// byte for byte.
#[test]
fn two_hosts_fly_in_real_time() {
    let Some(h) = Hosts::create("rt") else { return };
    let dir = TempDir::new();
    let team = unique_team("hostsrt");
    let out = dir.path().join("rt");
    let out_s = out.to_string_lossy().into_owned();
    let source = [
        "--n",
        "10",
        "--t-total",
        "30",
        "--max-ticks",
        "300",
        "--realtime",
        // This test is about what crosses, not staleness: a loaded CI machine may starve a
        // process for longer than the default 0.5 s.
        "--stale-after",
        "2",
        "--no-figures",
    ];
    let orch = spawn(&mut h.on_a(&launch_args(&h, &team, &out_s, &source)));
    let daemon = spawn(&mut h.daemon(&["--team", &team]));
    let o = orch.finish(RUN_DEADLINE);
    let d = daemon.finish(RUN_DEADLINE);
    assert_exit(&o, 0, "launch --realtime --hosts 2");
    assert_exit(&d, 0, "orchestrator host (real time)");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    let rt = &audit["realtime"];
    assert_eq!(rt["audits"], 301, "{rt:#}");
    // Host B's members' pacing reports crossed: every member is counted, and the ticks are
    // those of ten members, not of host A's five.
    assert_eq!(rt["members_reported"], 10, "{rt:#}");
    let ticks = rt["ticks"].as_f64().unwrap_or_default();
    assert!(
        ticks >= 9.0 * 300.0,
        "both hosts' members flew the plan: {rt:#}"
    );
    let age = |k: &str| rt[k].as_f64().unwrap_or(f64::NAN);
    let (p50, p99, max) = (
        age("neighbor_age_ms_p50"),
        age("neighbor_age_ms_p99"),
        age("neighbor_age_ms_max"),
    );
    // Ages up to the stale bound (a SAFE flight had no stale neighbour), ordered.
    assert!(
        0.0 < p50 && p50 <= p99 && p99 <= max && max <= 2000.0,
        "{rt:#}"
    );
    assert_eq!(rt["stale_after_s"], 2.0, "{rt:#}");
    let flown = flown_scenario(&out);
    let ids: BTreeSet<u32> = flown.agents.iter().map(|a| a.id).collect();
    assert_eq!(complete_ticks(&out.join("telemetry.csv"), &ids), 301);
    let hosts = read_json(&out.join("hosts.json"));
    assert_eq!(hosts["hosts"][0]["outcome"], "stopped", "{hosts:#}");
    assert_no_team_resources(&team);
    assert_eq!(left_on_b(&d), Vec::<String>::new(), "{}", describe(&d));
    // Every member recorded, on either host (host B's daemon sent its members' recordings up
    // at the end), and the run replays in one process byte for byte.
    let recorded: BTreeSet<u32> = std::fs::read_dir(out.join("recording"))
        .expect("the run's recording folder")
        .flatten()
        .filter_map(|e| e.file_name().to_str()?.strip_suffix(".mcap")?.parse().ok())
        .collect();
    assert_eq!(
        recorded, ids,
        "every member's recording is in the run directory"
    );
    let again = dir.path().join("replay");
    assert_exit(
        &replay(&out, &again, &[]),
        0,
        "replay of a two-host real-time run",
    );
    assert_same_file(&out.join("telemetry.csv"), &again.join("telemetry.csv"));
}

/// A long flight: strict lockstep (`--window 1`: a round trip over the network per tick) keeps
/// the team flying for far longer than any test needs; a fault test ends it long before its
/// 60,000 ticks.
const LONG_LOCKSTEP: &[&str] = &["--n", "10", "--t-total", "600", "--window", "1"];
/// A long flight in real time (600 s of plan); `--stale-after 2`: a loaded CI machine may
/// starve a process for longer than the default 0.5 s before the fault under test.
const LONG_REALTIME: &[&str] = &[
    "--n",
    "10",
    "--t-total",
    "600",
    "--realtime",
    "--stale-after",
    "2",
    "--no-figures",
];

/// Starts the team (`source`) on both hosts and waits for some ticks of telemetry. The daemon's
/// temporary directory (`TMPDIR`, its work directory's parent) is `b_tmp`.
fn running(h: &Hosts, team: &str, out: &Path, source: &[&str], b_tmp: &Path) -> (Running, Running) {
    let out_s = out.to_string_lossy().into_owned();
    let mut orch = spawn(&mut h.on_a(&launch_args(h, team, &out_s, source)));
    std::fs::create_dir_all(b_tmp).expect("host B's TMPDIR");
    let daemon = spawn(h.daemon(&["--team", team]).env("TMPDIR", b_tmp));
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), 200);
    (orch, daemon)
}

/// The daemons' work directories in `tmp`.
fn work_dirs(tmp: &Path) -> Vec<String> {
    let entries = std::fs::read_dir(tmp).unwrap_or_else(|e| panic!("{}: {e}", tmp.display()));
    entries
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("cdm-host-"))
        .collect()
}

/// Kills the daemon of `team` with SIGKILL.
fn kill_daemon(team: &str) {
    signal(daemon_pid(team), libc::SIGKILL);
}

/// The pid of `team`'s daemon (`orchestrator host --connect ...`).
pub(crate) fn daemon_pid(team: &str) -> u32 {
    team_processes(team)
        .into_iter()
        .find(|(_, args)| {
            let daemon = args.first().is_some_and(|a| a.ends_with("orchestrator"));
            daemon && args.iter().any(|a| a == "--connect")
        })
        .map(|(pid, _)| pid)
        .expect("the daemon's process")
}

/// The orchestrator's fault after losing host B: `host-lost`, naming host 1, `cause`, and every
/// agent of host B; the fault's agent is one of them.
fn assert_lost_host_b(out: &Path, cause: &str) {
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "FAULT", "{audit:#}");
    assert_eq!(audit["fault"]["kind"], "host-lost", "{audit:#}");
    let hosts = read_json(&out.join("hosts.json"));
    let on_b = host_agents(&hosts, 1);
    let agent = audit["fault"]["agent"].as_u64().unwrap_or(u64::MAX) as u32;
    assert!(
        on_b.contains(&agent),
        "fault names agent {agent}, not one of host B's {on_b:?}: {audit:#}"
    );
    let message = audit["fault"]["message"].as_str().unwrap_or_default();
    let members = format!("{:?}", on_b.iter().collect::<Vec<_>>());
    for needle in ["host 1 ", cause, &members] {
        assert!(message.contains(needle), "no {needle:?} in: {audit:#}");
    }
    let flown = flown_scenario(out);
    let ids: BTreeSet<u32> = flown.agents.iter().map(|a| a.id).collect();
    let ticks = complete_ticks(&out.join("telemetry.csv"), &ids);
    assert!(ticks > 20, "only {ticks} complete ticks kept");
}

/// The link goes down mid-run: both sides stop within the link deadline, each naming the
/// other; the orchestrator keeps every complete tick; nothing is left on either host.
#[test]
fn a_partition_stops_both_sides_named() {
    let Some(h) = Hosts::create("pt") else { return };
    let dir = TempDir::new();
    let team = unique_team("part");
    let out = dir.path().join("run");
    let b_tmp = dir.path().join("tmp-b");
    let (orch, daemon) = running(&h, &team, &out, LONG_LOCKSTEP, &b_tmp);
    h.cut();
    let o = orch.finish(STOP_DEADLINE);
    let d = daemon.finish(STOP_DEADLINE);
    assert_exit(&o, 3, "launch after a partition");
    assert_exit(&d, 3, "orchestrator host after a partition");
    assert_stderr_has(&o, "launch", &["host 1 lost", "network partition"]);
    assert_stderr_has(
        &d,
        "host",
        &[
            "nothing heard from the orchestrator",
            "its members were stopped",
        ],
    );
    assert_lost_host_b(&out, "network partition");
    wait_no_process_of(&team, STOP_DEADLINE);
    assert_no_team_resources(&team);
    assert_eq!(left_on_b(&d), Vec::<String>::new(), "{}", describe(&d));
}

/// Lockstep, `--on-loss repair` (the default): the daemon is killed with SIGKILL mid-flight. Each
/// of its members is lost as if it had been SIGKILLed on one host: the team flies on around them
/// to the end, byte-identical to `simulate --lose` of all of them at the tick audit.json records,
/// and audit.json names each loss with its host. The killed daemon's work directory is removed
/// by the next daemon that starts.
#[test]
fn a_killed_daemon_is_like_killed_members() {
    let Some(h) = Hosts::create("kd") else { return };
    let dir = TempDir::new();
    let team = unique_team("kdaemon");
    let (out, sim) = (dir.path().join("run"), dir.path().join("sim"));
    let b_tmp = dir.path().join("tmp-b");
    // The team's size: 10 in CI; `CDM_TEST_KILLED_DAEMON_N=40` measures a larger host's loss
    // (README, "One team, several machines").
    let n = std::env::var("CDM_TEST_KILLED_DAEMON_N").unwrap_or_else(|_| "10".into());
    let n_members: usize = n.parse().expect("CDM_TEST_KILLED_DAEMON_N: a team size");
    let source = ["--n", n.as_str(), "--t-total", "600", "--max-ticks", "8000"];
    let (orch, mut daemon) = running(&h, &team, &out, &source, &b_tmp);
    kill_daemon(&team);
    let o = orch.finish(RUN_DEADLINE);
    assert_exit(
        &o,
        0,
        "launch after the daemon was killed (--on-loss repair)",
    );
    // Seen through zenoh's liveliness (the daemon's TCP connection closed), not by silence.
    assert_stderr_has(&o, "launch", &["host 1 lost", "zenoh session closed"]);
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    let on_b = host_agents(&read_json(&out.join("hosts.json")), 1);
    let losses = audit["losses"].as_array().cloned().unwrap_or_default();
    let lost: BTreeSet<u32> = losses
        .iter()
        .filter_map(|l| l["id"].as_u64())
        .map(|i| i as u32)
        .collect();
    assert_eq!(
        lost,
        on_b,
        "every member of host B lost, no other: {audit:#}\n{}",
        describe(&o)
    );
    // One host, the same members killed after the same ticks (each its own: members run up to
    // a window apart).
    let dt = cdm_scenario::Scenario::generated(n_members).unwrap().dt_s();
    let mut lose = vec![];
    for l in &losses {
        assert_eq!(
            (&l["cause"], &l["host"]),
            (&Value::from("killed"), &Value::from(1)),
            "{audit:#}"
        );
        let last = l["last_tick"].as_u64().expect("last_tick");
        lose.push(format!("{}@{}", l["id"], last as f64 * dt));
    }
    let mut replay = source.to_vec();
    for l in &lose {
        replay.extend(["--lose", l]);
    }
    let s = run(&mut simulate(&sim, &replay), RUN_DEADLINE);
    assert_exit(&s, 0, &format!("simulate {replay:?}"));
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
    wait_no_process_of(&team, STOP_DEADLINE);
    assert_no_team_resources(&team);
    let _ = daemon.kill();
    assert_eq!(
        work_dirs(&b_tmp).len(),
        1,
        "a SIGKILLed daemon leaves its work directory"
    );
    // The next daemon (here one that finds no orchestrator) removes it.
    let next = run(
        h.daemon(&["--join-timeout", "1"]).env("TMPDIR", &b_tmp),
        REFUSE_DEADLINE,
    );
    assert_exit(&next, 3, "a daemon with no orchestrator");
    assert_eq!(
        work_dirs(&b_tmp),
        Vec::<String>::new(),
        "{}",
        describe(&next)
    );
}

/// `--on-loss stop`: a killed daemon stops the team with `host-lost`, naming host B and its
/// agents; its members stop by themselves (their clock's publisher is gone).
#[test]
fn a_killed_daemon_under_on_loss_stop_stops_the_team() {
    let Some(h) = Hosts::create("ks") else { return };
    let dir = TempDir::new();
    let team = unique_team("kstop");
    let out = dir.path().join("run");
    let b_tmp = dir.path().join("tmp-b");
    let mut source = LONG_LOCKSTEP.to_vec();
    source.extend(["--on-loss", "stop"]);
    let (orch, mut daemon) = running(&h, &team, &out, &source, &b_tmp);
    kill_daemon(&team);
    let o = orch.finish(STOP_DEADLINE);
    assert_exit(&o, 3, "launch --on-loss stop after the daemon was killed");
    assert_lost_host_b(&out, "zenoh session closed");
    wait_no_process_of(&team, STOP_DEADLINE);
    assert_no_team_resources(&team);
    let _ = daemon.kill();
}

/// Real time: the daemon is killed with SIGKILL mid-flight. The monitor hears host B's members
/// through the bridge; the loss is named as the host's (`host-lost`, host 1 and its agents),
/// whether the bridge's verdict or a member's staleness came first.
#[test]
fn a_killed_daemon_in_real_time_is_named_with_its_members() {
    let Some(h) = Hosts::create("kr") else { return };
    let dir = TempDir::new();
    let team = unique_team("krt");
    let out = dir.path().join("run");
    let b_tmp = dir.path().join("tmp-b");
    let (orch, mut daemon) = running(&h, &team, &out, LONG_REALTIME, &b_tmp);
    kill_daemon(&team);
    let o = orch.finish(STOP_DEADLINE);
    assert_exit(&o, 3, "launch --realtime after the daemon was killed");
    assert_lost_host_b(&out, "zenoh session closed");
    let audit = read_json(&out.join("audit.json"));
    assert!(audit["realtime"]["ticks"].as_u64() > Some(0), "{audit:#}");
    wait_no_process_of(&team, STOP_DEADLINE);
    assert_no_team_resources(&team);
    let _ = daemon.kill();
}

/// Real time, the link cut mid-flight: the orchestrator names the host's loss (`host-lost`,
/// host 1 and every member of it), not one member's silence, although a member goes stale as
/// soon as the link's deadline passes; the daemon stops its members and exits 3, named.
#[test]
fn a_partition_in_real_time_is_the_hosts_loss_on_both_sides() {
    let Some(h) = Hosts::create("pr") else { return };
    let dir = TempDir::new();
    let team = unique_team("prt");
    let out = dir.path().join("run");
    let b_tmp = dir.path().join("tmp-b");
    let (orch, daemon) = running(&h, &team, &out, LONG_REALTIME, &b_tmp);
    h.cut();
    let o = orch.finish(STOP_DEADLINE);
    let d = daemon.finish(STOP_DEADLINE);
    assert_exit(&o, 3, "launch --realtime after a partition");
    assert_exit(&d, 3, "orchestrator host (real time) after a partition");
    assert_lost_host_b(&out, "network partition");
    assert_stderr_has(
        &d,
        "host",
        &[
            "nothing heard from the orchestrator",
            "its members were stopped",
        ],
    );
    wait_no_process_of(&team, STOP_DEADLINE);
    assert_no_team_resources(&team);
}

/// Real time, the daemon stopped (SIGSTOP) mid-flight: its link falls silent, and the
/// orchestrator names the host's loss. Resumed (SIGCONT) after the orchestrator stopped, the
/// daemon says it did not run for longer than the link timeout, stops its members and exits 3
/// (before, it read the frames queued meanwhile, took the link for alive and exited 0).
#[test]
fn a_stopped_daemon_in_real_time_is_its_hosts_loss_and_says_so_once_resumed() {
    let Some(h) = Hosts::create("sr") else { return };
    let dir = TempDir::new();
    let team = unique_team("srt");
    let out = dir.path().join("run");
    let b_tmp = dir.path().join("tmp-b");
    let (orch, daemon) = running(&h, &team, &out, LONG_REALTIME, &b_tmp);
    let pid = daemon_pid(&team);
    signal(pid, libc::SIGSTOP);
    let o = orch.finish(STOP_DEADLINE);
    signal(pid, libc::SIGCONT);
    let d = daemon.finish(STOP_DEADLINE);
    assert_exit(&o, 3, "launch --realtime with its daemon stopped");
    assert_lost_host_b(&out, "nothing heard from host 1");
    assert_exit(&d, 3, "orchestrator host, stopped then resumed");
    assert_stderr_has(
        &d,
        "host",
        &["this daemon did not run for", "its members were stopped"],
    );
    wait_no_process_of(&team, STOP_DEADLINE);
    assert_no_team_resources(&team);
}

/// Foreign daemons are refused by name (another scenario, another team, a host already taken);
/// then the orchestrator is killed with SIGKILL: the daemon and every member exit by themselves.
#[test]
fn foreign_daemons_are_refused_and_a_killed_orchestrator_takes_the_team_down() {
    let Some(h) = Hosts::create("rf") else { return };
    let dir = TempDir::new();
    let team = unique_team("refuse");
    let out = dir.path().join("run");
    let other = dir.path().join("other.toml");
    let exported = run(
        Command::new(bin("orchestrator"))
            .args(["scenario", "export", "--n", "12", "--out"])
            .arg(&other),
        REFUSE_DEADLINE,
    );
    assert_exit(&exported, 0, "scenario export");
    let other_s = other.to_string_lossy().into_owned();
    let b_tmp = dir.path().join("tmp-b");
    let (mut orch, daemon) = running(&h, &team, &out, LONG_LOCKSTEP, &b_tmp);
    let refusals: [(&[&str], &str); 3] = [
        (
            &["--team", &team, "--scenario", &other_s],
            "the daemon's scenario has hash",
        ),
        (&["--team", "someone_else"], "asks for team someone_else"),
        (&["--team", &team, "--host", "1"], "host 1 of team"),
    ];
    for (extra, needle) in refusals {
        let mut args = vec!["--join-timeout", "20"];
        args.extend_from_slice(extra);
        let r = run(&mut h.daemon(&args), REFUSE_DEADLINE);
        assert_exit(&r, 2, &format!("host {extra:?}"));
        assert_stderr_has(&r, "host", &["refused by the orchestrator", needle]);
    }
    signal(orch.id(), libc::SIGKILL);
    let d = daemon.finish(STOP_DEADLINE);
    assert_exit(&d, 3, "orchestrator host after the orchestrator was killed");
    assert_stderr_has(
        &d,
        "host",
        &["the orchestrator is gone", "zenoh session closed"],
    );
    wait_no_process_of(&team, STOP_DEADLINE);
    assert_eq!(left_on_b(&d), Vec::<String>::new(), "{}", describe(&d));
    let _ = orch.kill();
    // Host A's leftovers of a SIGKILLed orchestrator are removed by the next launch or `clean`.
    let c = run(
        Command::new(bin("orchestrator")).arg("clean"),
        REFUSE_DEADLINE,
    );
    assert_exit(&c, 0, "clean");
    assert_no_team_resources(&team);
}

/// The generated team of `n` split as `launch --hosts 2` splits it (`cdm_hosts::Regions`), and
/// the follower (of host B when `on_b_only`) whose loss (alone) opens the most links across
/// hosts, preferring one that opens a link read on host B from host A: (its id, host B's
/// members, those links as (source, reader)).
fn loss_across_hosts(n: usize, on_b_only: bool) -> (u32, BTreeSet<u32>, Vec<(u32, u32)>) {
    use cdm_model::formation::Role;
    use cdm_records::loss_log::LossLog;
    let s = cdm_scenario::Scenario::generated(n).expect("a generated team");
    let placed: Vec<cdm_hosts::Placed> = s
        .formation
        .members
        .iter()
        .map(|m| cdm_hosts::Placed {
            id: m.id,
            planar: [m.planar[0], m.planar[1]],
            in_neighbors: m.link.map_or_else(Vec::new, |l| l.in_neighbors.to_vec()),
        })
        .collect();
    let regions = cdm_hosts::Regions::split(&placed, 2);
    let on_b: BTreeSet<u32> = regions.members(1).into_iter().collect();
    let crossing_of = |id: u32| -> Vec<(u32, u32)> {
        let mut log = LossLog::new(&s);
        log.add(id, 1);
        log.new_links()
            .into_iter()
            .filter(|(r, w)| on_b.contains(r) != on_b.contains(w))
            .map(|(r, w)| (w, r))
            .collect()
    };
    let best = s
        .formation
        .members
        .iter()
        .filter(|m| m.role == Role::Follower && (!on_b_only || on_b.contains(&m.id)))
        .map(|m| (m.id, crossing_of(m.id)))
        .max_by_key(|(_, c)| {
            let into_b = c.iter().any(|(w, r)| on_b.contains(r) && !on_b.contains(w));
            (into_b, c.len())
        })
        .expect("the team has followers");
    assert!(
        !best.1.is_empty(),
        "no follower's loss opens a link across hosts"
    );
    (best.0, on_b, best.1)
}

/// The edges a repair made cross hosts, from hosts.json.
fn added_crossing(hosts: &Value) -> BTreeSet<(u32, u32)> {
    serde_json::from_value(hosts["crossing_edges_added_by_repairs"].clone())
        .unwrap_or_else(|e| panic!("hosts.json crossing_edges_added_by_repairs: {e}: {hosts:#}"))
}

/// `launch --hosts 2 --lose ID@T` of a follower whose repair opens links across hosts: the
/// notice crosses on the clock, both bridges compute the same repair and carry the new links;
/// telemetry is byte-identical to `simulate --lose ID@T`, the new crossing edges are recorded,
/// nothing is left on either host.
#[test]
fn a_scripted_loss_across_hosts_flies_exactly_as_simulate() {
    let Some(h) = Hosts::create("sl") else { return };
    let (lost, on_b, opened) = loss_across_hosts(10, false);
    let dir = TempDir::new();
    let team = unique_team("hostlose");
    let (out, sim) = (dir.path().join("launch"), dir.path().join("sim"));
    let when = format!("{lost}@5");
    let source = ["--n", "10", "--t-total", "20", "--lose", &when];
    let out_s = out.to_string_lossy().into_owned();
    let orch = spawn(&mut h.on_a(&launch_args(&h, &team, &out_s, &source)));
    let daemon = spawn(&mut h.daemon(&["--team", &team]));
    let s = run(&mut simulate(&sim, &source), RUN_DEADLINE);
    assert_exit(&s, 0, "simulate --lose");
    let o = orch.finish(RUN_DEADLINE);
    let d = daemon.finish(RUN_DEADLINE);
    assert_exit(&o, 0, &format!("launch --hosts 2 --lose {when}"));
    assert_exit(&d, 0, "orchestrator host");
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["losses"][0]["id"], lost, "{audit:#}");
    let hosts = read_json(&out.join("hosts.json"));
    assert_eq!(host_agents(&hosts, 1), on_b, "{hosts:#}");
    let added = added_crossing(&hosts);
    for e in &opened {
        assert!(added.contains(e), "{e:?} not recorded: {hosts:#}");
    }
    assert_no_team_resources(&team);
    assert_eq!(left_on_b(&d), Vec::<String>::new(), "{}", describe(&d));
}

/// A member on host B dies by SIGKILL mid-flight (at a chosen tick, `CDM_FAULT_INJECT` in the
/// daemon's environment): its daemon reports the exit, the team repairs around it as on one
/// host and completes; audit.json names it (`killed`, its last tick) and `simulate --lose` of
/// that tick replays the run byte for byte.
#[test]
fn a_killed_member_on_another_host_is_repaired() {
    let Some(h) = Hosts::create("km") else { return };
    let (victim, on_b, _) = loss_across_hosts(10, true);
    assert!(on_b.contains(&victim));
    let dir = TempDir::new();
    let team = unique_team("hostkill");
    let (out, sim) = (dir.path().join("launch"), dir.path().join("sim"));
    let at = 800u64;
    let source = ["--n", "10", "--t-total", "20"];
    let out_s = out.to_string_lossy().into_owned();
    let orch = spawn(&mut h.on_a(&launch_args(&h, &team, &out_s, &source)));
    let daemon = spawn(h.daemon(&["--team", &team]).env(
        cdm_process::fault_inject::ENV,
        format!("{victim}:kill@{at}"),
    ));
    let o = orch.finish(RUN_DEADLINE);
    let d = daemon.finish(RUN_DEADLINE);
    assert_exit(&o, 0, "launch --hosts 2 with a member killed on host B");
    assert_exit(&d, 0, "orchestrator host");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    let l = &audit["losses"][0];
    assert_eq!(
        (&l["id"], &l["cause"], &l["last_tick"]),
        (
            &Value::from(victim),
            &Value::from("killed"),
            &Value::from(at - 1)
        ),
        "{audit:#}"
    );
    let dt = cdm_scenario::Scenario::generated(10).unwrap().dt_s();
    let when = format!("{victim}@{}", (at - 1) as f64 * dt);
    let mut replay = source.to_vec();
    replay.extend(["--lose", &when]);
    let s = run(&mut simulate(&sim, &replay), RUN_DEADLINE);
    assert_exit(&s, 0, &format!("simulate --lose {when}"));
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
    assert_no_team_resources(&team);
    assert_eq!(left_on_b(&d), Vec::<String>::new(), "{}", describe(&d));
}

/// Commands over two hosts: their notices ride the clock's message, which the link carries
/// whole, so host B's members fly the commanded plan as host A's do. paper40 with a command
/// file (hold, an UNSAFE goto, a SAFE goto, land) writes `simulate --commands`'s telemetry and
/// commands.json byte for byte.
#[test]
fn a_commanded_flight_over_two_hosts_flies_as_simulate() {
    let Some(h) = Hosts::create("sf") else { return };
    let dir = TempDir::new();
    let team = unique_team("hsteerf");
    let file = dir.path().join("commands.json");
    std::fs::write(&file, STEERING_COMMANDS).expect("the command file");
    let (out, sim) = (dir.path().join("launch"), dir.path().join("sim"));
    let source = [
        "--builtin",
        "paper40",
        "--no-figures",
        "--commands",
        file.to_str().unwrap(),
    ];
    let out_s = out.to_string_lossy().into_owned();
    let orch = spawn(&mut h.on_a(&launch_args(&h, &team, &out_s, &source)));
    let daemon = spawn(&mut h.daemon(&["--team", &team]));
    assert_exit(
        &run(&mut simulate(&sim, &source), RUN_DEADLINE),
        0,
        "simulate --commands",
    );
    assert_exit(&orch.finish(RUN_DEADLINE), 0, "launch --hosts 2 --commands");
    assert_exit(&daemon.finish(RUN_DEADLINE), 0, "orchestrator host");
    for name in ["telemetry.csv", "commands.json"] {
        assert_same_file(&out.join(name), &sim.join(name));
    }
    assert_no_team_resources(&team);
}

/// `orchestrator command` to a team over two hosts, live: held with a follower stopped (the
/// grants wait for it), then landed; the team lands and ends, and `simulate --commands
/// RUN/commands.json` flies the same telemetry.
#[test]
fn a_team_over_two_hosts_is_steered_live() {
    let Some(h) = Hosts::create("sl") else { return };
    let dir = TempDir::new();
    let team = unique_team("hsteerl");
    let out = dir.path().join("launch");
    let source = [
        "--builtin",
        "paper40",
        "--no-figures",
        "--agent-timeout",
        "120",
    ];
    let out_s = out.to_string_lossy().into_owned();
    let mut orch = spawn(&mut h.on_a(&launch_args(&h, &team, &out_s, &source)));
    let daemon = spawn(&mut h.daemon(&["--team", &team]));
    let stopped = support::steering::stop_a_follower(&mut orch, &team, &out, 500);
    for what in ["hold", "land"] {
        let o = run(&mut h.on_a(&["command", &team, what]), REFUSE_DEADLINE);
        assert_exit(&o, 0, &format!("command {what} over two hosts"));
    }
    support::steering::resume(stopped);
    assert_exit(&orch.finish(RUN_DEADLINE), 0, "launch --hosts 2, steered");
    assert_exit(&daemon.finish(RUN_DEADLINE), 0, "orchestrator host");
    let list = out.join("commands.json");
    let commands = read_json(&list);
    assert_eq!(commands.as_array().map(Vec::len), Some(2), "{commands:#}");
    let sim = dir.path().join("sim");
    let again = [
        "--builtin",
        "paper40",
        "--no-figures",
        "--commands",
        list.to_str().unwrap(),
    ];
    assert_exit(
        &run(&mut simulate(&sim, &again), RUN_DEADLINE),
        0,
        "simulate --commands RUN/commands.json",
    );
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
    assert_no_team_resources(&team);
}
