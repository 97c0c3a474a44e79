//! Real time: `launch --realtime` with the real binaries over real iceoryx2 shared
//! memory. Members tick on their own clocks from the announced start, with seeded phase
//! offsets; the orchestrator monitors. Short plans (3 s of a 10-agent team) keep CI fast; no
//! test asserts how fast anything ran (only that a paced flight cannot end before its plan).
//!
//! - A real-time run of a short plan is SAFE, its `realtime` figures are present and sane, its
//!   telemetry has a row per agent at every audit instant, and it tracks like `simulate`.
//! - Under `--on-loss stop`, a member stopped with SIGSTOP is named (agent-silent) and the team
//!   stopped, nothing left; a killed member is named (agent-exited) the same way.
//! - Under `--on-loss repair` (the default) a member lost in flight (`--lose`) is repaired
//!   around: its readers fly their new triangles, the team finishes SAFE, exit 0; two lost at
//!   the same instant are repaired as lockstep repairs them.
//! - SIGINT to the orchestrator stops the team, nothing left.
//! - A member started by hand in the other mode is refused with exit 2.
//! - `--rt-priority P` puts the orchestrator and every member under SCHED_FIFO at P (read back
//!   from /proc during the flight); without `--realtime` it is refused with exit 2.

use integration_tests::support;

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use integration_tests::{run, spawn, unique_team, TempDir};
use serde_json::Value;
use support::*;

/// A 10-agent team (leaders 1-6, followers 7-10) with a plan of 30 s.
const TEAM: [&str; 4] = ["--n", "10", "--t-total", "30"];
/// 3 s of that plan (301 ticks at comm_hz = 100).
const SHORT: [&str; 2] = ["--max-ticks", "300"];
/// Slack for a loaded machine around a few seconds of flight.
const DEADLINE: Duration = integration_tests::deadline::FLIGHT;

fn realtime_launch(team: &str, out: &Path, extra: &[&str]) -> Command {
    let mut args: Vec<&str> = TEAM.to_vec();
    args.extend(["--realtime", "--no-figures"]);
    args.extend(extra);
    launch(team, out, &args)
}

/// A real-time team of 10 flying a long plan under `--on-loss stop` (a dead or silent member
/// stops it), seen with its 11 processes: the orchestrator and the team's footprint (for the
/// "nothing left" check).
fn flying(team: &str, out: &Path) -> (integration_tests::Running, TeamFootprint) {
    let mut orch = spawn(&mut realtime_launch(team, out, &["--on-loss", "stop"]));
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), 100);
    let procs = team_processes(team);
    assert_eq!(procs.len(), 11, "{procs:#?}");
    (orch, TeamFootprint::record(team, procs.keys().copied()))
}

fn ids(n: u32) -> BTreeSet<u32> {
    (1..=n).collect()
}

fn num(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} is not a number: {v:#}"))
}

/// A short plan in real time: exit 0, SAFE and complete; the pacing figures are present and
/// consistent (every member reported, each flew at least the plan's ticks, ages ordered and
/// under the stale bound, the flight took at least the plan's 3 s); telemetry holds the 301
/// audit instants; the largest deviation is within 10 % of `simulate`'s for the same plan (the
/// phase offsets and extrapolated neighbours change it only slightly).
#[test]
fn a_short_plan_flies_safe_in_real_time_with_sane_pacing_figures() {
    let dir = TempDir::new();
    let team = unique_team("rt_safe");
    let out = dir.path().join("rt");
    let o = run(&mut realtime_launch(&team, &out, &SHORT), DEADLINE);
    assert_exit(&o, 0, "launch --realtime of a short plan");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    let rt = &audit["realtime"];
    assert_eq!(rt["members_reported"], 10, "{rt:#}");
    assert_eq!(rt["audits"], 301, "{rt:#}");
    assert_eq!(rt["phase_seed"], 1, "{rt:#}");
    let (ticks, late) = (num(rt, "ticks"), num(rt, "late_ticks"));
    assert!(ticks >= 10.0 * 300.0, "every member flew the plan: {rt:#}");
    assert!(late <= ticks, "{rt:#}");
    assert!((num(rt, "late_ticks_pct") - 100.0 * late / ticks).abs() < 1e-9);
    let (p50, p99, max) = (
        num(rt, "neighbor_age_ms_p50"),
        num(rt, "neighbor_age_ms_p99"),
        num(rt, "neighbor_age_ms_max"),
    );
    assert!(
        0.0 < p50 && p50 <= p99 && p99 <= max && max < 500.0,
        "{rt:#}"
    );
    assert!(num(rt, "wall_s") >= 3.0, "a paced plan of 3 s: {rt:#}");
    let slowest = rt["slowest_member"]["id"]
        .as_u64()
        .expect("a slowest member");
    assert!((1..=10).contains(&slowest), "{rt:#}");
    assert_eq!(complete_ticks(&out.join("telemetry.csv"), &ids(10)), 301);

    let sim = dir.path().join("sim");
    let mut args: Vec<&str> = TEAM.to_vec();
    args.extend(SHORT);
    args.push("--no-figures");
    let so = run(&mut simulate(&sim, &args), DEADLINE);
    assert_exit(&so, 0, "simulate of the same plan");
    let sim_audit = read_json(&sim.join("audit.json"));
    assert!(sim_audit.get("realtime").is_none(), "{sim_audit:#}");
    let (a, b) = (
        num(&audit, "max_deviation_m"),
        num(&sim_audit, "max_deviation_m"),
    );
    assert!(b > 0.1, "the short plan moves the team: {sim_audit:#}");
    assert!(
        (a - b).abs() <= 0.1 * b,
        "real time {a} m against simulate {b} m"
    );
}

/// Impaired real deliveries: with `--link-delay-ms 20 --link-loss 0.1` every member holds each
/// in-neighbour state back until 20 ms after its stamp and drops the ones the seeded draws lose;
/// the short plan still flies SAFE and complete, the median neighbour age is at least the delay
/// (a state is never used younger than its link allows; no upper bound is asserted), and about
/// a tenth of the states received were dropped (the draws are lockstep's, per link and tick). A
/// delay not below `--stale-after` is refused (every neighbour would be stale), exit 2.
#[test]
fn impaired_links_hold_real_deliveries_back_and_drop_some() {
    let dir = TempDir::new();
    let team = unique_team("rt_links");
    let out = dir.path().join("rt");
    let mut extra = SHORT.to_vec();
    extra.extend(["--link-delay-ms", "20", "--link-loss", "0.1", "--seed", "3"]);
    let o = run(&mut realtime_launch(&team, &out, &extra), DEADLINE);
    assert_exit(&o, 0, "launch --realtime over impaired links");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    let rt = &audit["realtime"];
    assert_eq!(rt["members_reported"], 10, "{rt:#}");
    let p50 = num(rt, "neighbor_age_ms_p50");
    assert!(p50 >= 20.0, "held back by the 20 ms delay: {rt:#}");
    assert!(num(rt, "neighbor_age_ms_max") < 500.0, "{rt:#}");
    let (received, lost) = (num(rt, "link_states_received"), num(rt, "link_states_lost"));
    // 4 followers x 3 in-neighbours x ~300 states.
    assert!(received >= 3000.0, "{rt:#}");
    let share = lost / received;
    assert!(
        (0.07..0.13).contains(&share),
        "lost {share} of the states: {rt:#}"
    );
    assert_no_process_of(&team);

    let team = unique_team("rt_links_bad");
    let bad = dir.path().join("bad");
    let o = run(
        &mut realtime_launch(&team, &bad, &["--link-delay-ms", "500"]),
        DEADLINE,
    );
    assert_exit(&o, 2, "a delay at the stale bound");
    assert_stderr_has(&o, "launch", &["--link-delay-ms 500", "--stale-after"]);
}

/// A short real-time flight of `team` into `out` that loses `lose` (values of `--lose`) under
/// the default `--on-loss repair`, the members logging their repairs: exit 0, SAFE and
/// complete. Its output and audit.json.
fn repaired_flight(team: &str, out: &Path, lose: &[&str]) -> (std::process::Output, Value) {
    let mut extra = SHORT.to_vec();
    for l in lose {
        extra.extend(["--lose", l]);
    }
    let mut cmd = realtime_launch(team, out, &extra);
    cmd.env("RUST_LOG", "warn,cdm_runtime::realtime::repair=info");
    let o = run(&mut cmd, DEADLINE);
    let what = format!("launch --realtime --lose {}", lose.join(" --lose "));
    assert_exit(&o, 0, &what);
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    (o, audit)
}

/// `--lose 6@1` in real time (default `--on-loss repair`): the orchestrator kills secondary
/// leader 6 once it has published its tick of 1 s, records the loss (`scripted`, its last tick,
/// the repair tick a lead later) and announces it; its readers 7, 9 and 10 open their new
/// in-neighbours' states and each says it flies the repaired link; the short plan finishes
/// SAFE and complete, exit 0. telemetry.csv has all 10 members up to the audit instant the loss
/// gives and the 9 others from it on (the report's and the replay's reader accept it: no error).
#[test]
fn a_scripted_loss_in_real_time_is_repaired_and_the_team_finishes_safe() {
    let dir = TempDir::new();
    let team = unique_team("rt_lose");
    let out = dir.path().join("rt");
    let (o, audit) = repaired_flight(&team, &out, &["6@1"]);
    let losses = audit["losses"].as_array().expect("losses");
    assert_eq!(losses.len(), 1, "{audit:#}");
    let l = &losses[0];
    assert_eq!(
        (l["id"].as_u64(), l["cause"].as_str()),
        (Some(6), Some("scripted"))
    );
    let (last, from, repair) = (num(l, "last_tick"), num(l, "tick"), num(l, "repair_tick"));
    assert!(last >= 100.0 && from > last && repair > last, "{l:#}");
    let readers = retriangulated(l);
    assert_eq!(readers, [7, 9, 10], "{l:#}");
    let stderr = String::from_utf8_lossy(&o.stderr);
    for r in &readers {
        let said = stderr
            .lines()
            .any(|s| s.contains("flying the repaired link") && s.contains(&format!(" id={r} ")));
        assert!(said, "agent {r} never flew its repaired link:\n{stderr}");
    }
    // Rows: every member before the loss's instant, the nine others from it on.
    let text = std::fs::read_to_string(out.join("telemetry.csv")).expect("telemetry.csv");
    let mut rows: std::collections::BTreeMap<u64, BTreeSet<u32>> = Default::default();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let (tick, id) = (f[0].parse().expect("tick"), f[2].parse().expect("id"));
        rows.entry(tick).or_default().insert(id);
    }
    assert_eq!(rows.len(), 301);
    for (tick, ids_at) in &rows {
        let want: BTreeSet<u32> = ids(10)
            .into_iter()
            .filter(|&i| i != 6 || (*tick as f64) < from)
            .collect();
        assert_eq!(ids_at, &want, "tick {tick}");
    }
    assert!(!stderr.contains("not written"), "{stderr}");
    assert_no_process_of(&team);
}

/// `--lose 1@1 --lose 2@1` in real time: two primaries lost at the same instant, each given a
/// repair tick of its own. Follower 7 read both; the repair of 1 alone would have it read 2,
/// which is dead, so it flies the repair of both (the next link) instead, the triangle lockstep
/// and `simulate` fly: [3, 4, 9]. The short plan finishes SAFE and complete, exit 0, nothing
/// left.
#[test]
fn two_primaries_lost_at_the_same_instant_are_repaired_as_in_lockstep() {
    let dir = TempDir::new();
    let team = unique_team("rt_lose2");
    let out = dir.path().join("rt");
    let (o, audit) = repaired_flight(&team, &out, &["1@1", "2@1"]);
    let losses = audit["losses"].as_array().expect("losses");
    let lost: Vec<(Option<u64>, Option<&str>)> = losses
        .iter()
        .map(|l| (l["id"].as_u64(), l["cause"].as_str()))
        .collect();
    assert_eq!(
        lost,
        [(Some(1), Some("scripted")), (Some(2), Some("scripted"))],
        "{audit:#}"
    );
    let last = &losses[1]["retriangulated"][0];
    assert_eq!(last["id"], 7, "{audit:#}");
    assert_eq!(last["new"], serde_json::json!([3, 4, 9]), "{audit:#}");
    let stderr = String::from_utf8_lossy(&o.stderr);
    let flew = stderr.lines().any(|s| {
        s.contains("flying the repaired link")
            && s.contains(" id=7 ")
            && s.contains("in_neighbors=[3, 4, 9]")
    });
    assert!(flew, "agent 7 never flew [3, 4, 9]:\n{stderr}");
    assert_no_process_of(&team);
}

/// SIGSTOP of follower 9 in real time: its newest state ages past the bound (0.5 s), so the
/// monitor (or a follower that reads it) names agent 9; the team is stopped (the stopped
/// process killed), exit 3, nothing of the team left.
#[test]
fn a_stopped_member_is_named_and_the_team_stopped() {
    let dir = TempDir::new();
    let team = unique_team("rt_sigstop");
    let out = dir.path().join("run");
    let (orch, fp) = flying(&team, &out);
    let victim = 9;
    let pid = member_pid(&team, victim).expect("agent 9 runs");
    let _guard = Stopped(pid);
    signal(pid, libc::SIGSTOP);
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 3, "launch --realtime after SIGSTOP of a member");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "FAULT", "{audit:#}");
    let fault = &audit["fault"];
    assert_eq!(fault["kind"], "agent-silent", "{audit:#}");
    assert_eq!(fault["agent"], victim, "{audit:#}");
    let message = fault["message"].as_str().unwrap_or_default();
    assert!(message.contains("agent 9 sent no state"), "{fault:#}");
    assert!(audit["realtime"]["members_reported"].as_u64() >= Some(9));
    assert_no_process_of(&team);
    fp.assert_nothing_left();
}

/// SIGKILL of follower 8 in real time: the orchestrator sees its process exit and names it
/// (`agent-exited`, the signal), stops the team, exit 3, nothing left.
#[test]
fn a_killed_member_is_named_and_the_team_stopped() {
    let dir = TempDir::new();
    let team = unique_team("rt_kill");
    let out = dir.path().join("run");
    let (orch, fp) = flying(&team, &out);
    let pid = member_pid(&team, 8).expect("agent 8 runs");
    signal(pid, libc::SIGKILL);
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 3, "launch --realtime after SIGKILL of a member");
    let audit = read_json(&out.join("audit.json"));
    let fault = &audit["fault"];
    assert_eq!(fault["kind"], "agent-exited", "{audit:#}");
    assert_eq!(fault["agent"], 8, "{audit:#}");
    let message = fault["message"].as_str().unwrap_or_default();
    assert!(message.contains("killed by signal 9"), "{fault:#}");
    assert_no_process_of(&team);
    fp.assert_nothing_left();
}

/// SIGINT to the orchestrator in real time: the stop sequence, exit 3, `interrupted`, no
/// process and nothing in /dev/shm left.
#[test]
fn sigint_in_real_time_leaves_nothing_behind() {
    let dir = TempDir::new();
    let team = unique_team("rt_sigint");
    let out = dir.path().join("run");
    let (mut orch, fp) = flying(&team, &out);
    signal(orch.id(), libc::SIGINT);
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 3, "launch --realtime after SIGINT");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["fault"]["kind"], "interrupted", "{audit:#}");
    assert!(
        audit["fault"]["message"]
            .as_str()
            .unwrap_or_default()
            .contains("SIGINT"),
        "{audit:#}"
    );
    assert_no_process_of(&team);
    fp.assert_nothing_left();
}

/// The scheduling policy and real-time priority of a process (/proc/PID/stat fields 41 and 40).
fn sched_of(pid: u32) -> (u32, u32) {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let after_comm = stat.rsplit_once(')').map_or("", |(_, rest)| rest);
    let fields: Vec<&str> = after_comm.split_whitespace().collect();
    // Field 3 (state) is the first after the command name.
    let field = |n: usize| {
        fields
            .get(n - 3)
            .and_then(|f| f.parse().ok())
            .unwrap_or(u32::MAX)
    };
    (field(41), field(40))
}

/// Whether this test process may use SCHED_FIFO at `p` (root, or `ulimit -r` >= p; CI runs
/// as root). Checked without changing our own policy.
fn may_use_fifo(p: u64) -> bool {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `lim` is a valid rlimit for the call.
    let ok = unsafe { libc::getrlimit(libc::RLIMIT_RTPRIO, &mut lim) } == 0;
    // SAFETY: geteuid has no preconditions.
    (unsafe { libc::geteuid() } == 0) || (ok && lim.rlim_cur >= p)
}

/// `--rt-priority 7`: while the short plan flies, the orchestrator and all 10 members run under
/// SCHED_FIFO (policy 1) at priority 7; the flight ends SAFE. Where this machine does not allow
/// it, the same launch is refused up front with exit 2 naming the flag. Without `--realtime`
/// the flag is refused (exit 2) on launch and on a hand-started member.
#[test]
fn rt_priority_runs_the_team_under_sched_fifo() {
    let dir = TempDir::new();
    let team = unique_team("rt_fifo");
    let out = dir.path().join("rt");
    let mut cmd = realtime_launch(&team, &out, &["--rt-priority", "7", "--max-ticks", "300"]);
    if !may_use_fifo(7) {
        let o = run(&mut cmd, DEADLINE);
        assert_exit(
            &o,
            2,
            "launch --rt-priority where SCHED_FIFO is not allowed",
        );
        assert_stderr_has(&o, "launch --rt-priority 7", &["--rt-priority 7"]);
        return;
    }
    let mut orch = spawn(&mut cmd);
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), 50);
    let procs = team_processes(&team);
    assert_eq!(procs.len(), 11, "{procs:#?}");
    for pid in procs.keys() {
        assert_eq!(sched_of(*pid), (1, 7), "pid {pid}: {:?}", procs[pid]);
    }
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 0, "launch --realtime --rt-priority 7");
    assert_eq!(read_json(&out.join("audit.json"))["verdict"], "SAFE");

    let o = run(
        &mut launch(
            &unique_team("rt_fifo_ls"),
            &dir.path().join("ls"),
            &["--n", "10", "--rt-priority", "7"],
        ),
        DEADLINE,
    );
    assert_exit(&o, 2, "lockstep launch --rt-priority");
    assert_stderr_has(&o, "--rt-priority", &["--rt-priority needs --realtime"]);
    let o = run(
        Command::new(integration_tests::bin("agent")).args([
            "--scenario",
            "no-such.toml",
            "--team",
            "rt_fifo_by_hand",
            "--id",
            "7",
            "--rt-priority",
            "7",
        ]),
        DEADLINE,
    );
    assert_exit(&o, 2, "agent --rt-priority without --realtime");
    assert_stderr_has(&o, "--rt-priority", &["--rt-priority needs --realtime"]);
}

/// A member started by hand without --realtime for a real-time team (and one with --realtime
/// for a lockstep team) is refused with exit 2 and told which flag to use.
#[test]
fn a_member_in_the_other_mode_is_refused() {
    for (team_flags, member_flag, fix) in [
        (vec!["--realtime"], None, "with --realtime"),
        (vec![], Some("--realtime"), "without --realtime"),
    ] {
        let dir = TempDir::new();
        let team = unique_team("rt_mode");
        let out = dir.path().join("run");
        let mut args: Vec<&str> = TEAM.to_vec();
        args.extend(["--no-spawn", "--join-timeout", "30"]);
        args.extend(&team_flags);
        let mut orch = spawn(&mut launch(&team, &out, &args));
        let scenario = out.join("scenario.toml");
        let s = wait_for_file(&mut orch, &scenario);
        let mut members = Vec::new();
        for a in &s.agents {
            let mut c = member(binary_for(a.role), &scenario, &team, a.id);
            c.args(["--join-timeout", "30"]);
            if a.id == 10 {
                c.args(member_flag);
            } else {
                c.args(&team_flags);
            }
            members.push((a.id, spawn(&mut c)));
        }
        for (id, m) in members {
            let o = m.finish(DEADLINE);
            if id == 10 {
                assert_exit(&o, 2, "a member in the other mode");
                assert_stderr_has(&o, "member 10", &["agent 10", fix]);
            }
        }
        let _ = orch.finish(DEADLINE);
        assert_no_process_of(&team);
    }
}

/// Waits for the orchestrator to write the flown scenario (a --no-spawn team prints it first).
fn wait_for_file(orch: &mut integration_tests::Running, path: &Path) -> cdm_scenario::ScenarioFile {
    let until = std::time::Instant::now() + DEADLINE;
    while !path.exists() {
        assert!(
            !orch.has_exited(),
            "the orchestrator exited before writing {}",
            path.display()
        );
        assert!(std::time::Instant::now() < until, "no {}", path.display());
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(100));
    flown_scenario_file(path)
}
