//! `orchestrator launch` end to end: the real `orchestrator`, `leader` and `agent` binaries, one
//! process per quadcopter, over real iceoryx2 shared memory.
//!
//! - A team flown as processes writes exactly the telemetry of the in-process engine
//!   (`simulate`), byte for byte, and subscribes each follower to its three in-neighbours only.
//! - Two teams fly at once without seeing each other.
//! - A follower killed with SIGKILL, or the orchestrator interrupted with SIGINT, stops the whole
//!   team with a fault (exit 3): the telemetry keeps only complete ticks, no process of the team
//!   survives, and nothing of the team is left in /dev/shm or /tmp/iceoryx2.
//! - A hand-started team (`--no-spawn`) refuses members with a wrong id, the wrong binary or a
//!   different scenario (exit 2), then flies with the right ones.
//!
//! Every test has its own team name and temporary directory, and every process runs under a
//! deadline (the harness kills its process group when the deadline passes or a guard drops).
//!
//! "Nothing left behind" is checked by attribution, not by a plain before/after listing of
//! /dev/shm: other teams (another test, a benchmark) may create and remove iceoryx2 files at the
//! same time. While the team runs, the test records its processes (from /proc and from the node
//! files iceoryx2 writes) and its services' hashes; afterwards no service or node named after the
//! team, and no file named by one of those hashes or by an id minted by one of those processes,
//! may remain. The check is first shown to see the live team, so it cannot pass vacuously.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use common::formation::Role;
use common::scenario::ScenarioFile;
use common::transport::TeamName;
use integration_tests::{bin, describe, run, spawn, unique_team, write_scenario, Running, TempDir};
use serde_json::Value;

/// paper40 as processes takes ~10-20 s on two cores; the rest is slack for a loaded machine.
const PAPER40_DEADLINE: Duration = Duration::from_secs(180);
/// A 10-agent team of a few thousand ticks runs in about a second.
const SMALL_DEADLINE: Duration = Duration::from_secs(60);
/// How long a team may take to start and write its first ticks.
const PROGRESS_DEADLINE: Duration = Duration::from_secs(60);
/// The orchestrator notices a dead child within ~100 ms and stops the team in under a second.
const KILLED_STOP_DEADLINE: Duration = Duration::from_secs(10);
/// From SIGINT to the orchestrator's exit, with every member stopped and reaped: the stop is
/// bounded at ~1 s (stop message, SIGTERM, SIGKILL, 300 ms each); the rest is slack.
const INTERRUPTED_STOP_DEADLINE: Duration = Duration::from_secs(3);
/// A refused member exits as soon as it has read the scenario and looked at the team.
const REFUSE_DEADLINE: Duration = Duration::from_secs(30);
/// Rows of telemetry (over 20 ticks of a 10-agent team) to see before breaking a run.
const ROWS_BEFORE_FAULT: usize = 200;

// ---------------------------------------------------------------------------------------------
// Running the binaries
// ---------------------------------------------------------------------------------------------

/// `orchestrator launch SOURCE --team TEAM --out OUT --quiet`.
fn launch(team: &str, out: &Path, source: &[&str]) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.arg("launch")
        .args(source)
        .arg("--team")
        .arg(team)
        .arg("--out")
        .arg(out)
        .arg("--quiet");
    c
}

/// `orchestrator simulate SOURCE --out OUT --quiet`.
fn simulate(out: &Path, source: &[&str]) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.arg("simulate")
        .args(source)
        .arg("--out")
        .arg(out)
        .arg("--quiet");
    c
}

/// `leader` or `agent` (by `role`) joining `team` as `id` with `scenario`.
fn member(binary: &str, scenario: &Path, team: &str, id: u32) -> Command {
    let mut c = Command::new(bin(binary));
    c.arg("--scenario")
        .arg(scenario)
        .arg("--team")
        .arg(team)
        .arg("--id")
        .arg(id.to_string());
    c
}

fn binary_for(role: Role) -> &'static str {
    if role.is_leader() {
        "leader"
    } else {
        "agent"
    }
}

fn assert_exit(out: &Output, code: i32, what: &str) {
    assert_eq!(
        out.status.code(),
        Some(code),
        "{what}: expected exit {code}\n{}",
        describe(out)
    );
}

// ---------------------------------------------------------------------------------------------
// Run directories
// ---------------------------------------------------------------------------------------------

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()))
}

/// The scenario a run flew (`<run>/scenario.toml`: positions projected, in-neighbours filled in).
fn flown_scenario(run_dir: &Path) -> ScenarioFile {
    let path = run_dir.join("scenario.toml");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    toml::from_str(&text).unwrap_or_else(|e| panic!("{} does not parse: {e}", path.display()))
}

/// Asserts two files are byte-identical; on a difference, names the first differing line.
fn assert_same_file(a: &Path, b: &Path) {
    let read =
        |p: &Path| std::fs::read(p).unwrap_or_else(|e| panic!("cannot read {}: {e}", p.display()));
    let (x, y) = (read(a), read(b));
    if x == y {
        return;
    }
    let (xl, yl): (Vec<&[u8]>, Vec<&[u8]>) = (
        x.split(|&c| c == b'\n').collect(),
        y.split(|&c| c == b'\n').collect(),
    );
    let k = xl.iter().zip(&yl).take_while(|(p, q)| p == q).count();
    let line = |v: &[&[u8]]| {
        v.get(k)
            .map(|l| String::from_utf8_lossy(l).into_owned())
            .unwrap_or_else(|| "<end of file>".into())
    };
    panic!(
        "{} ({} lines) and {} ({} lines) first differ at line {}:\n  {}\n  {}",
        a.display(),
        xl.len(),
        b.display(),
        yl.len(),
        k + 1,
        line(&xl),
        line(&yl)
    );
}

/// Checks a telemetry file written every tick holds whole ticks only: ticks 0, 1, ..., k-1 in
/// order, each with one row per agent of `ids`. Returns k.
fn complete_ticks(path: &Path, ids: &BTreeSet<u32>) -> u64 {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("tick,t,id,role,x,y,z,vx,vy,vz,x_ht,y_ht,z_ht"),
        "{}: header",
        path.display()
    );
    assert!(
        text.is_empty() || text.ends_with('\n'),
        "{}: the last row is cut short",
        path.display()
    );
    let mut ticks = 0u64;
    let mut block: Vec<u32> = Vec::new();
    let close = |block: &mut Vec<u32>, ticks: &mut u64| {
        let got: BTreeSet<u32> = block.iter().copied().collect();
        assert!(
            block.len() == ids.len() && &got == ids,
            "{}: tick {ticks} has rows for agents {block:?}, expected one for each of {ids:?}",
            path.display()
        );
        block.clear();
        *ticks += 1;
    };
    for (k, line) in lines.enumerate() {
        let mut f = line.split(',');
        let parse = |v: Option<&str>| -> u64 {
            v.and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("{}: row {} is malformed: {line}", path.display(), k + 2))
        };
        let tick = parse(f.next());
        let _t = f.next();
        let id = parse(f.next()) as u32;
        if tick != ticks {
            close(&mut block, &mut ticks);
        }
        assert_eq!(
            tick,
            ticks,
            "{}: row {} jumps to tick {tick}",
            path.display(),
            k + 2
        );
        block.push(id);
    }
    if !block.is_empty() {
        close(&mut block, &mut ticks);
    }
    ticks
}

// ---------------------------------------------------------------------------------------------
// Processes of a team
// ---------------------------------------------------------------------------------------------

/// The arguments of process `pid` (empty for a zombie or a process that is gone).
fn cmdline(pid: u32) -> Vec<String> {
    std::fs::read(format!("/proc/{pid}/cmdline"))
        .map(|raw| {
            raw.split(|&b| b == 0)
                .filter(|a| !a.is_empty())
                .map(|a| String::from_utf8_lossy(a).into_owned())
                .collect()
        })
        .unwrap_or_default()
}

/// Live processes that have `team` as one of their arguments, with their command lines.
fn team_processes(team: &str) -> BTreeMap<u32, Vec<String>> {
    let mut out = BTreeMap::new();
    let entries = std::fs::read_dir("/proc").unwrap_or_else(|e| panic!("cannot list /proc: {e}"));
    for e in entries.flatten() {
        let Some(pid) = e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()) else {
            continue;
        };
        let args = cmdline(pid);
        if args.iter().any(|a| a == team) {
            out.insert(pid, args);
        }
    }
    out
}

/// The process flying agent `id` of `team` (`... --team <team> --id <id>`).
fn member_pid(team: &str, id: u32) -> Option<u32> {
    let id = id.to_string();
    team_processes(team).into_iter().find_map(|(pid, args)| {
        args.windows(4)
            .any(|w| w[0] == "--team" && w[1] == team && w[2] == "--id" && w[3] == id)
            .then_some(pid)
    })
}

fn signal(pid: u32, sig: libc::c_int) {
    let pid = libc::pid_t::try_from(pid).expect("pid fits pid_t");
    // SAFETY: kill(2) takes no pointers; `pid` is a single process of the team under test.
    let rc = unsafe { libc::kill(pid, sig) };
    assert_eq!(
        rc,
        0,
        "kill({pid}, {sig}): {}",
        std::io::Error::last_os_error()
    );
}

/// Wait until `telemetry` holds more than `rows` rows, while the orchestrator keeps running.
fn wait_for_rows(orch: &mut Running, telemetry: &Path, rows: usize) {
    let until = Instant::now() + PROGRESS_DEADLINE;
    loop {
        let lines = std::fs::read(telemetry)
            .map(|b| b.iter().filter(|&&c| c == b'\n').count())
            .unwrap_or(0);
        if lines > rows + 1 {
            return;
        }
        let why = if orch.has_exited() {
            "exited"
        } else if Instant::now() >= until {
            "did not get there within the deadline"
        } else {
            std::thread::sleep(Duration::from_millis(10));
            continue;
        };
        let program = orch.program();
        let out = orch.kill();
        panic!(
            "{program} {why} before {} had {rows} rows ({lines} lines).\n{}",
            telemetry.display(),
            describe(&out)
        );
    }
}

// ---------------------------------------------------------------------------------------------
// What of a team iceoryx2 keeps on disk
// ---------------------------------------------------------------------------------------------

const IOX2_ROOT: &str = "/tmp/iceoryx2";
const SHM: &str = "/dev/shm";

/// The value of `key = "value"` or `key = 123` in an iceoryx2 TOML file.
fn toml_value(text: &str, key: &str) -> Option<String> {
    text.lines().find_map(|l| {
        let (k, v) = l.split_once('=')?;
        (k.trim() == key).then(|| v.trim().trim_matches('"').to_string())
    })
}

/// Files under `dir`, recursively (directories included), sorted.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = vec![];
    let mut dirs = vec![dir.to_path_buf()];
    while let Some(d) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            if e.file_type().is_ok_and(|t| t.is_dir()) {
                dirs.push(e.path());
            }
            out.push(e.path());
        }
    }
    out.sort();
    out
}

/// The team's services as iceoryx2 stores them: (hash, name) of each
/// `/tmp/iceoryx2/services/iox2_<hash>.service` whose `service_name` belongs to `team`.
fn team_services(team: &TeamName) -> Vec<(String, String)> {
    let prefix = format!("cdm/{team}/");
    let mut out = vec![];
    for path in files_under(&Path::new(IOX2_ROOT).join("services")) {
        let Some(hash) = path
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_prefix("iox2_"))
            .and_then(|n| n.strip_suffix(".service"))
        else {
            continue;
        };
        let name = std::fs::read_to_string(&path)
            .ok()
            .and_then(|t| toml_value(&t, "service_name"));
        if let Some(name) = name.filter(|n| n.starts_with(&prefix)) {
            out.push((hash.to_string(), name));
        }
    }
    out
}

/// The team's nodes: (name, process id as iceoryx2 records it) from each
/// `/tmp/iceoryx2/nodes/<node id>/iox2_node.details` whose node name belongs to `team`.
fn team_nodes(team: &TeamName) -> Vec<(String, u32)> {
    let mut out = vec![];
    for path in files_under(&Path::new(IOX2_ROOT).join("nodes")) {
        if path.file_name().and_then(|n| n.to_str()) != Some("iox2_node.details") {
            continue;
        }
        let Ok(text) = std::fs::read_to_string(&path) else {
            continue;
        };
        let name = toml_value(&text, "name").filter(|n| team.owns_node(n));
        let pid = toml_value(&text, "process").and_then(|p| p.parse().ok());
        if let (Some(name), Some(pid)) = (name, pid) {
            out.push((name, pid));
        }
    }
    out.sort();
    out
}

/// The process id iceoryx2 packs into its 128-bit ids (node, port, service and event ids name
/// its files): bits 64..96.
fn id_pid(id: u128) -> u32 {
    (id >> 64) as u32
}

/// A team's processes and services, recorded while it runs, to find what it leaves behind.
struct Footprint {
    team: TeamName,
    pids: BTreeSet<u32>,
    service_hashes: BTreeSet<String>,
}

impl Footprint {
    /// Record the live team: the given processes, those its iceoryx2 nodes name, and the hashes
    /// of its services.
    fn record(team: &str, pids: impl IntoIterator<Item = u32>) -> Self {
        let team = TeamName::new(team).unwrap_or_else(|e| panic!("team {team}: {e}"));
        let mut all: BTreeSet<u32> = pids.into_iter().collect();
        all.extend(team_nodes(&team).into_iter().map(|(_, pid)| pid));
        let service_hashes = team_services(&team).into_iter().map(|(h, _)| h).collect();
        Footprint {
            team,
            pids: all,
            service_hashes,
        }
    }

    /// Whether `name` carries one of the team's service hashes or an id minted by one of its
    /// processes. A pid now held by a process outside the team (recycled) does not count.
    fn names_the_team(&self, name: &str, pids: &BTreeSet<u32>) -> bool {
        self.service_hashes
            .iter()
            .any(|h| name.contains(h.as_str()))
            || name
                .split(|c: char| !c.is_ascii_digit())
                .filter(|run| run.len() >= 20)
                .filter_map(|run| run.parse::<u128>().ok())
                .any(|id| pids.contains(&id_pid(id)))
    }

    /// Everything of the team iceoryx2 still has: services and nodes named after the team, and
    /// files under /dev/shm and /tmp/iceoryx2 named by its services or processes.
    fn leftovers(&self) -> Vec<String> {
        let team = self.team.as_str();
        let pids: BTreeSet<u32> = self
            .pids
            .iter()
            .copied()
            .filter(|&p| {
                let args = cmdline(p);
                args.is_empty() || args.iter().any(|a| a == team)
            })
            .collect();
        let mut out: Vec<String> = team_services(&self.team)
            .into_iter()
            .map(|(_, name)| format!("service {name}"))
            .collect();
        out.extend(
            team_nodes(&self.team)
                .into_iter()
                .map(|(name, pid)| format!("node {name} (process {pid})")),
        );
        for root in [SHM, IOX2_ROOT] {
            for path in files_under(Path::new(root)) {
                let name = path
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                // iceoryx2's one global management file is shared by every process.
                if !name.ends_with(".global_mgmt") && self.names_the_team(&name, &pids) {
                    out.push(path.display().to_string());
                }
            }
        }
        out
    }

    /// Asserts the checker sees the live team (its services, nodes and shared-memory files), so
    /// that an empty `leftovers` later means something.
    fn assert_visible(&self, processes: usize) {
        let live = self.leftovers();
        let count = |p: &str| live.iter().filter(|l| l.starts_with(p)).count();
        assert!(
            count("service ") > 0
                && count("node ") == processes
                && count(SHM) > 0
                && count(IOX2_ROOT) > 0,
            "the live team {} does not show {processes} nodes, services and files: {live:#?}",
            self.team
        );
    }

    fn assert_nothing_left(&self) {
        let left = self.leftovers();
        assert!(
            left.is_empty(),
            "team {} left {} iceoryx2 resources behind: {left:#?}",
            self.team,
            left.len()
        );
    }
}

/// Asserts no process of `team` is alive.
fn assert_no_process_of(team: &str) {
    let procs = team_processes(team);
    assert!(
        procs.is_empty(),
        "processes of team {team} survived: {procs:#?}"
    );
}

// ---------------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------------

/// paper40 (40 processes, 20,001 ticks, default window) flies exactly as the in-process engine
/// flies it, and iceoryx2 shows each follower subscribed to its three in-neighbours and nothing
/// else.
#[test]
fn paper40_as_processes_matches_simulate_over_the_designed_graph() {
    let dir = TempDir::new();
    let team = unique_team("paper40");
    let launched = dir.path().join("launch");
    let simulated = dir.path().join("simulate");
    let source = ["--builtin", "paper40"];

    let sim = spawn(&mut simulate(&simulated, &source));
    let out = run(&mut launch(&team, &launched, &source), PAPER40_DEADLINE);
    assert_exit(&out, 0, "launch paper40");
    let sim_out = sim.finish(PAPER40_DEADLINE);
    assert_exit(&sim_out, 0, "simulate paper40");

    let audit = read_json(&launched.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    assert_eq!(audit["agents"], 40, "{audit:#}");
    assert_eq!(audit["ticks"], 20_001, "{audit:#}");
    assert_eq!(audit["fault"], Value::Null, "{audit:#}");
    assert_eq!(audit["violations"], Value::Array(vec![]), "{audit:#}");
    assert_same_file(
        &launched.join("telemetry.csv"),
        &simulated.join("telemetry.csv"),
    );
    assert_same_file(
        &launched.join("scenario.toml"),
        &simulated.join("scenario.toml"),
    );

    // The subscription graph: the orchestrator reads every agent; a follower reads exactly its
    // three in-neighbours; a leader reads no one.
    let subs: BTreeMap<String, Vec<String>> =
        serde_json::from_value(read_json(&launched.join("subscriptions.json")))
            .unwrap_or_else(|e| panic!("subscriptions.json is not a map of lists of names: {e}"));
    let s = flown_scenario(&launched);
    let node = |id: u32| format!("cdm/{team}/agent/{id}");
    let mut expected: BTreeMap<String, Vec<String>> = s
        .agents
        .iter()
        .map(|a| (a.id.to_string(), vec![format!("cdm/{team}/orchestrator")]))
        .collect();
    for f in s.agents.iter().filter(|a| a.role == Role::Follower) {
        let ins = f.in_neighbors.as_deref().unwrap_or_default();
        let distinct: BTreeSet<&u32> = ins.iter().collect();
        assert_eq!(distinct.len(), 3, "follower {} in-neighbours {ins:?}", f.id);
        for n in ins {
            expected
                .get_mut(&n.to_string())
                .unwrap_or_else(|| panic!("follower {} reads unknown agent {n}", f.id))
                .push(node(f.id));
        }
    }
    for list in expected.values_mut() {
        list.sort();
    }
    let leaders: BTreeSet<String> = s
        .agents
        .iter()
        .filter(|a| a.role.is_leader())
        .map(|a| node(a.id))
        .collect();
    let leader_reads: Vec<&String> = subs
        .values()
        .flatten()
        .filter(|n| leaders.contains(*n))
        .collect();
    assert!(
        leader_reads.is_empty(),
        "leaders subscribe to states: {leader_reads:?}"
    );
    let orchestrator = format!("cdm/{team}/orchestrator");
    assert!(
        subs.values().all(|list| list.contains(&orchestrator)),
        "the orchestrator does not read every agent: {subs:#?}"
    );
    let wrong: Vec<String> = expected
        .iter()
        .filter(|(id, want)| subs.get(*id) != Some(*want))
        .map(|(id, want)| {
            format!(
                "agent {id}: subscribers {:?}, expected {want:?}",
                subs.get(id)
            )
        })
        .collect();
    assert!(
        wrong.is_empty() && subs.len() == expected.len(),
        "subscription graph differs from the scenario's ({} keys, expected {}):\n{}",
        subs.len(),
        expected.len(),
        wrong.join("\n")
    );
}

/// Two teams fly at the same time, each exactly as simulated: team names keep them apart.
#[test]
fn two_teams_fly_at_once_without_seeing_each_other() {
    let dir = TempDir::new();
    let source = ["--n", "10", "--t-total", "30"];
    let (a, b) = (unique_team("twin_a"), unique_team("twin_b"));
    let (out_a, out_b, sim) = (
        dir.path().join("a"),
        dir.path().join("b"),
        dir.path().join("sim"),
    );
    let first = spawn(&mut launch(&a, &out_a, &source));
    let second = spawn(&mut launch(&b, &out_b, &source));
    let s = run(&mut simulate(&sim, &source), SMALL_DEADLINE);
    assert_exit(&s, 0, "simulate --n 10");
    let ra = first.finish(SMALL_DEADLINE);
    let rb = second.finish(SMALL_DEADLINE);
    assert_exit(&ra, 0, &format!("launch team {a}"));
    assert_exit(&rb, 0, &format!("launch team {b}"));
    for (team, out) in [(&a, &out_a), (&b, &out_b)] {
        let audit = read_json(&out.join("audit.json"));
        assert_eq!(audit["verdict"], "SAFE", "team {team}: {audit:#}");
        assert_eq!(audit["complete"], true, "team {team}: {audit:#}");
        assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
        let subs = read_json(&out.join("subscriptions.json"));
        let foreign = subs
            .as_object()
            .into_iter()
            .flat_map(|m| m.values())
            .filter_map(Value::as_array)
            .flatten()
            .filter_map(Value::as_str)
            .filter(|n| !n.starts_with(&format!("cdm/{team}/")))
            .collect::<Vec<_>>();
        assert!(foreign.is_empty(), "team {team} sees {foreign:?}");
    }
}

/// Starts a 10-agent team and lets it write some ticks; returns the orchestrator, the flown
/// scenario and the team's footprint (checked to be visible: 11 processes).
fn running_team(team: &str, out: &Path) -> (Running, ScenarioFile, Footprint) {
    let mut orch = spawn(&mut launch(team, out, &["--n", "10", "--t-total", "600"]));
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), ROWS_BEFORE_FAULT);
    let s = flown_scenario(out);
    let procs = team_processes(team);
    assert_eq!(
        procs.len(),
        s.agents.len() + 1,
        "expected the orchestrator and {} members of team {team}: {procs:#?}",
        s.agents.len()
    );
    let footprint = Footprint::record(team, procs.keys().copied());
    footprint.assert_visible(s.agents.len() + 1);
    (orch, s, footprint)
}

/// The faulted run's audit and telemetry: a fault of `kind` at the first tick the telemetry
/// does not hold; the telemetry holds only whole ticks.
fn assert_stopped_with(out: &Path, s: &ScenarioFile, kind: &str) -> Value {
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "FAULT", "{audit:#}");
    assert_eq!(audit["complete"], false, "{audit:#}");
    let fault = &audit["fault"];
    assert_eq!(fault["kind"], kind, "{audit:#}");
    let ids: BTreeSet<u32> = s.agents.iter().map(|a| a.id).collect();
    let ticks = complete_ticks(&out.join("telemetry.csv"), &ids);
    assert!(
        ticks as usize * ids.len() > ROWS_BEFORE_FAULT,
        "only {ticks} ticks"
    );
    assert_eq!(
        fault["tick"], ticks,
        "the fault's tick is the first tick missing from telemetry.csv: {audit:#}"
    );
    fault.clone()
}

/// SIGKILL of one follower mid-run: the orchestrator stops the team with a fault naming the
/// agent and the tick, keeps only whole ticks, and leaves no process and no shared memory.
#[test]
fn a_killed_follower_stops_the_team_and_leaves_nothing_behind() {
    let dir = TempDir::new();
    let team = unique_team("kill");
    let out = dir.path().join("run");
    let (orch, s, footprint) = running_team(&team, &out);
    let victim = s
        .agents
        .iter()
        .find(|a| a.role == Role::Follower)
        .map(|a| a.id)
        .expect("the team has a follower");
    let pid = member_pid(&team, victim)
        .unwrap_or_else(|| panic!("no process flies agent {victim} of team {team}"));
    signal(pid, libc::SIGKILL);

    let o = orch.finish(KILLED_STOP_DEADLINE);
    assert_exit(&o, 3, "launch after a follower was killed");
    let fault = assert_stopped_with(&out, &s, "agent-exited");
    assert_eq!(fault["agent"], victim, "{fault:#}");
    let message = fault["message"].as_str().unwrap_or_default();
    assert!(
        message.contains(&format!("agent {victim}")) && message.contains("signal 9"),
        "{fault:#}"
    );
    assert_no_process_of(&team);
    footprint.assert_nothing_left();
}

/// SIGINT to the orchestrator mid-run: it stops every member, exits 3 with an `interrupted`
/// fault within a bounded time, and leaves no process and no shared memory.
#[test]
fn an_interrupted_orchestrator_stops_its_team_and_leaves_nothing_behind() {
    let dir = TempDir::new();
    let team = unique_team("sigint");
    let out = dir.path().join("run");
    let (mut orch, s, footprint) = running_team(&team, &out);
    signal(orch.id(), libc::SIGINT);

    let o = orch.finish(INTERRUPTED_STOP_DEADLINE);
    assert_exit(&o, 3, "launch after SIGINT");
    assert_no_process_of(&team);
    let fault = assert_stopped_with(&out, &s, "interrupted");
    assert_eq!(fault["agent"], Value::Null, "{fault:#}");
    footprint.assert_nothing_left();
}

/// `--no-spawn`: members started by hand. A wrong id, the wrong binary for the role, a
/// different scenario and a team that does not exist are refused (exit 2) without disturbing the
/// team; the right members then fly it exactly as simulated.
#[test]
fn a_hand_started_team_refuses_wrong_members_and_flies_with_the_right_ones() {
    let dir = TempDir::new();
    let team = unique_team("hand");
    let exported = dir.path().join("exported.toml");
    let out = run(
        Command::new(bin("orchestrator"))
            .args(["scenario", "export", "--n", "10", "--out"])
            .arg(&exported),
        SMALL_DEADLINE,
    );
    assert_exit(&out, 0, "scenario export --n 10");
    let text = std::fs::read_to_string(&exported).expect("read the exported scenario");
    let mut file: ScenarioFile = toml::from_str(&text).expect("the exported scenario parses");
    file.t_total_s = 30.0;
    let scenario = write_scenario(dir.path(), "team.toml", &file);
    file.t_total_s = 31.0;
    let other = write_scenario(dir.path(), "other.toml", &file);

    let run_dir = dir.path().join("run");
    let mut orch = spawn(
        Command::new(bin("orchestrator"))
            .arg("launch")
            .arg("--scenario")
            .arg(&scenario)
            .args([
                "--team",
                &team,
                "--no-spawn",
                "--join-timeout",
                "60",
                "--out",
            ])
            .arg(&run_dir),
    );
    orch.wait_for_output("waits for 10 processes", SMALL_DEADLINE);

    let follower = file
        .agents
        .iter()
        .find(|a| a.role == Role::Follower)
        .map(|a| a.id)
        .expect("a follower");
    let refused = |cmd: &mut Command, what: &str, needles: &[&str]| {
        let o = run(cmd, REFUSE_DEADLINE);
        assert_exit(&o, 2, what);
        let err = String::from_utf8_lossy(&o.stderr);
        for n in needles {
            assert!(
                err.contains(n),
                "{what}: stderr lacks {n:?}\n{}",
                describe(&o)
            );
        }
    };
    refused(
        &mut member("agent", &scenario, &team, 999),
        "agent --id 999",
        &["agent 999 is not in scenario"],
    );
    refused(
        &mut member("leader", &scenario, &team, follower),
        "leader with a follower's id",
        &[
            format!("agent {follower} is a follower").as_str(),
            "`leader` binary flies primary and secondary leaders",
        ],
    );
    refused(
        &mut member("agent", &other, &team, follower),
        "agent with another scenario",
        &[
            format!("cannot join team {team}").as_str(),
            "differs from the team's",
        ],
    );
    let absent = unique_team("absent");
    refused(
        &mut member("agent", &scenario, &absent, follower),
        "agent of a team that does not exist",
        &[format!("team {absent} does not exist").as_str()],
    );
    assert!(
        !orch.has_exited(),
        "the orchestrator gave up after refused members: {:?}",
        orch.output_so_far()
    );

    let members: Vec<(u32, Running)> = file
        .agents
        .iter()
        .map(|a| {
            let cmd = &mut member(binary_for(a.role), &scenario, &team, a.id);
            (a.id, spawn(cmd))
        })
        .collect();
    let o = orch.finish(SMALL_DEADLINE);
    assert_exit(&o, 0, "launch --no-spawn");
    for (id, m) in members {
        assert_exit(
            &m.finish(SMALL_DEADLINE),
            0,
            &format!("hand-started agent {id}"),
        );
    }
    assert_no_process_of(&team);

    let sim = dir.path().join("sim");
    let so = run(
        &mut simulate(
            &sim,
            &["--scenario", scenario.to_str().expect("a UTF-8 path")],
        ),
        SMALL_DEADLINE,
    );
    assert_exit(&so, 0, "simulate the hand-started team's scenario");
    let audit = read_json(&run_dir.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    assert_same_file(&run_dir.join("telemetry.csv"), &sim.join("telemetry.csv"));
}

/// A plan far too fast for the quadcopters makes a member's controller refuse (eq. 46 near a
/// singular M). As processes the run must end exactly as in-process: every tick up to the fault
/// in telemetry, byte for byte, the same agent and tick named, exit 3.
#[test]
fn a_control_fault_ends_a_launch_exactly_like_simulate() {
    let dir = TempDir::new();
    let source = ["--n", "40", "--t-total", "10", "--no-figures"];
    let (out, sim) = (dir.path().join("launch"), dir.path().join("sim"));
    let s = run(&mut simulate(&sim, &source), SMALL_DEADLINE);
    assert_exit(&s, 3, "simulate of a 10 s paper40");
    let l = run(
        &mut launch(&unique_team("ctlfault"), &out, &source),
        SMALL_DEADLINE,
    );
    assert_exit(&l, 3, "launch of a 10 s paper40");
    let (fs, fl) = (
        read_json(&sim.join("audit.json")),
        read_json(&out.join("audit.json")),
    );
    for key in ["kind", "agent", "tick"] {
        assert_eq!(
            fs["fault"][key], fl["fault"][key],
            "fault.{key}: {fs:#} vs {fl:#}"
        );
    }
    assert_eq!(fl["fault"]["kind"], "control", "{fl:#}");
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
}

/// Scale regression: 250 processes start, fly a few ticks of their plan, and match the engine.
#[test]
fn a_250_process_team_flies_a_few_ticks_like_simulate() {
    let dir = TempDir::new();
    let source = ["--n", "250", "--max-ticks", "20", "--no-figures"];
    let (out, sim) = (dir.path().join("launch"), dir.path().join("sim"));
    let s = run(&mut simulate(&sim, &source), SMALL_DEADLINE);
    assert_exit(&s, 0, "simulate --n 250");
    let l = run(
        &mut launch(&unique_team("n250"), &out, &source),
        Duration::from_secs(120),
    );
    assert_exit(&l, 0, "launch --n 250");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["agents"], 250, "{audit:#}");
    assert_eq!(audit["ticks"], 21, "{audit:#}");
    assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
}
