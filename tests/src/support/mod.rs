//! Helpers shared by the integration tests: running `orchestrator launch`, reading run
//! directories, checking refusals, finding a team's processes, and the "nothing of the team is
//! left behind" checker (by attribution: see `launch.rs`'s module comment).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use crate::{bin, describe, Running};
use cdm_iox::TeamName;
use cdm_model::formation::Role;
use cdm_scenario::ScenarioFile;
use serde_json::Value;

/// The followers a loss of audit.json's `losses` re-triangulated, in its order.
pub fn retriangulated(loss: &Value) -> Vec<u64> {
    loss["retriangulated"]
        .as_array()
        .unwrap_or_else(|| panic!("no retriangulated list: {loss:#}"))
        .iter()
        .filter_map(|x| x["id"].as_u64())
        .collect()
}

/// How long a team may take to start and write its first ticks.
pub const PROGRESS_DEADLINE: Duration = crate::deadline::SHORT;

pub use crate::{launch, launch_loud, simulate};

pub mod airspace;
pub mod netns;
pub mod python;
pub mod steering;
pub mod users;

/// Commands to paper40 in flight (`steering.rs`, `steering_launch.rs`): a hold, an UNSAFE goto
/// (the leaders' triangle squeezed to a sliver: lambda_1 below lambda_CD,min, eq. 37), a SAFE
/// goto given while the team still brakes, a land given while it still moves.
pub const STEERING_COMMANDS: &str = r#"[
  {"at_s": 60, "command": "hold"},
  {"at_s": 120, "command": "goto", "goals": [[224, 434, 600], [220, 224, 600], [228, 224, 600]],
   "travel_s": 100},
  {"at_s": 121, "command": "goto", "goals": [[224, 434, 600], [126, 224, 600], [322, 224, 600]]},
  {"at_s": 200, "command": "land"}
]"#;

/// `leader` or `agent` (by `role`) joining `team` as `id` with `scenario`.
pub fn member(binary: &str, scenario: &Path, team: &str, id: u32) -> Command {
    let mut c = Command::new(bin(binary));
    c.arg("--scenario")
        .arg(scenario)
        .arg("--team")
        .arg(team)
        .arg("--id")
        .arg(id.to_string());
    c
}

pub fn binary_for(role: Role) -> &'static str {
    if role.is_leader() {
        "leader"
    } else {
        "agent"
    }
}

pub fn assert_exit(out: &Output, code: i32, what: &str) {
    assert_eq!(
        out.status.code(),
        Some(code),
        "{what}: expected exit {code}\n{}",
        describe(out)
    );
}

/// Asserts every needle is in `out`'s stderr (`what` names the command in the message).
pub fn assert_stderr_has(out: &Output, what: &str, needles: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    for n in needles {
        assert!(
            err.contains(n),
            "{what}: stderr lacks {n:?}\n{}",
            describe(out)
        );
    }
}

/// Asserts the team left nothing in iceoryx2's registry (no service, no node).
pub fn assert_no_team_resources(team: &str) {
    let t = TeamName::new(team).expect("team name");
    let services = team_services(&t);
    let nodes = team_nodes(&t);
    let channel = Path::new(iox2_root()).join(format!("{team}.command"));
    assert!(
        services.is_empty() && nodes.is_empty() && !channel.exists(),
        "team {team} left {services:?} {nodes:?}{}",
        if channel.exists() {
            format!(" and its command channel {}", channel.display())
        } else {
            String::new()
        }
    );
}

pub fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()))
}

/// `orchestrator replay RUN --out OUT --no-figures EXTRA...`, run to its end.
pub fn replay(run_dir: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut c = std::process::Command::new(crate::bin("orchestrator"));
    c.arg("replay")
        .arg(run_dir)
        .arg("--out")
        .arg(out)
        .arg("--no-figures")
        .args(extra);
    crate::run(&mut c, crate::deadline::FLIGHT)
}

/// The scenario a run flew (`<run>/scenario.toml`: positions projected, in-neighbours filled in).
pub fn flown_scenario(run_dir: &Path) -> ScenarioFile {
    flown_scenario_file(&run_dir.join("scenario.toml"))
}

/// A scenario file as the runtime writes it.
pub fn flown_scenario_file(path: &Path) -> ScenarioFile {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    toml::from_str(&text).unwrap_or_else(|e| panic!("{} does not parse: {e}", path.display()))
}

/// `launch SOURCE --window W` writes exactly `sim`'s telemetry for every window in `windows`
/// (each run in `dir/<tag><W>` under its own team, within `deadline`).
pub fn assert_windows_match_simulate(
    dir: &Path,
    source: &[&str],
    sim: &Path,
    windows: &[&str],
    tag: &str,
    deadline: std::time::Duration,
) {
    for window in windows {
        let out = dir.join(format!("{tag}{window}"));
        let mut args = source.to_vec();
        args.extend(["--window", window]);
        let team = crate::unique_team(&format!("{tag}{window}"));
        let l = crate::run(&mut launch(&team, &out, &args), deadline);
        assert_exit(&l, 0, &format!("launch {args:?}"));
        assert_same_file(&out.join("telemetry.csv"), &sim.join("telemetry.csv"));
    }
}

/// Asserts two files are byte-identical; on a difference, names the first differing line.
pub fn assert_same_file(a: &Path, b: &Path) {
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
pub fn complete_ticks(path: &Path, ids: &BTreeSet<u32>) -> u64 {
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

/// The arguments of process `pid` (empty for a zombie or a process that is gone).
pub fn cmdline(pid: u32) -> Vec<String> {
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
pub fn team_processes(team: &str) -> BTreeMap<u32, Vec<String>> {
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
pub fn member_pid(team: &str, id: u32) -> Option<u32> {
    let id = id.to_string();
    team_processes(team).into_iter().find_map(|(pid, args)| {
        args.windows(4)
            .any(|w| w[0] == "--team" && w[1] == team && w[2] == "--id" && w[3] == id)
            .then_some(pid)
    })
}

pub fn signal(pid: u32, sig: libc::c_int) {
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
pub fn wait_for_rows(orch: &mut Running, telemetry: &Path, rows: usize) {
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

pub use cdm_iox::iox2_root;
pub const SHM: &str = "/dev/shm";

/// The value of `key = "value"` or `key = 123` in an iceoryx2 TOML file.
pub fn toml_value(text: &str, key: &str) -> Option<String> {
    text.lines().find_map(|l| {
        let (k, v) = l.split_once('=')?;
        (k.trim() == key).then(|| v.trim().trim_matches('"').to_string())
    })
}

/// Files under `dir`, recursively (directories included), sorted.
pub fn files_under(dir: &Path) -> Vec<PathBuf> {
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
/// `<IOX2_ROOT>/services/<prefix><hash>.service` (prefix: `cdm<uid>_`, see
/// `cdm_iox::iox2_location`) whose `service_name` belongs to `team`.
pub fn team_services(team: &TeamName) -> Vec<(String, String)> {
    let prefix = format!("cdm/{team}/");
    let mut out = vec![];
    for path in files_under(&Path::new(iox2_root()).join("services")) {
        let Some(hash) = path
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_prefix(cdm_iox::iox2_location().prefix.as_str()))
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
/// `<IOX2_ROOT>/nodes/<node id>/<prefix>node.details` whose node name belongs to `team`.
pub fn team_nodes(team: &TeamName) -> Vec<(String, u32)> {
    let mut out = vec![];
    for path in files_under(&Path::new(iox2_root()).join("nodes")) {
        let details = format!("{}node.details", cdm_iox::iox2_location().prefix);
        if path.file_name().and_then(|n| n.to_str()) != Some(details.as_str()) {
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

use cdm_iox::ids::{born_s, id_pid, id_seconds, ids_in};

/// A team's processes and services, recorded while it runs, to find what it leaves behind.
pub struct TeamFootprint {
    team: TeamName,
    /// The team's processes, each with the monotonic second it was born (`None`: it had
    /// exited when recorded).
    pids: BTreeMap<u32, Option<u32>>,
    service_hashes: BTreeSet<String>,
}

impl TeamFootprint {
    /// Record the live team: the given processes, those its iceoryx2 nodes name, and the hashes
    /// of its services.
    pub fn record(team: &str, pids: impl IntoIterator<Item = u32>) -> Self {
        let team = TeamName::new(team).unwrap_or_else(|e| panic!("team {team}: {e}"));
        let mut all: BTreeSet<u32> = pids.into_iter().collect();
        all.extend(team_nodes(&team).into_iter().map(|(_, pid)| pid));
        let service_hashes = team_services(&team).into_iter().map(|(h, _)| h).collect();
        TeamFootprint {
            team,
            pids: all.into_iter().map(|p| (p, born_s(p))).collect(),
            service_hashes,
        }
    }

    /// Adds what `other` recorded (a team recorded several times while it starts and runs).
    pub fn absorb(&mut self, other: TeamFootprint) {
        for (pid, born) in other.pids {
            let mine = self.pids.entry(pid).or_insert(born);
            *mine = (*mine).or(born);
        }
        self.service_hashes.extend(other.service_hashes);
    }

    /// Counts `pid` as the team's from the monotonic second `born_s` on, as if a process of the
    /// team held that pid now (pids are recycled: how a test shows old files are not blamed).
    pub fn assume_process(&mut self, pid: u32, born_s: u32) {
        self.pids.insert(pid, Some(born_s));
    }

    /// Whether `name` carries one of the team's service hashes or an id minted by one of its
    /// processes (`pids`) since that process was born: an older process that had the same pid
    /// is not the team's. A process that had exited when recorded counts from the birth of the
    /// team's first process.
    fn names_the_team(&self, name: &str, pids: &BTreeSet<u32>) -> bool {
        let first = self.pids.values().flatten().min().copied().unwrap_or(0);
        self.service_hashes
            .iter()
            .any(|h| name.contains(h.as_str()))
            || ids_in(name).any(|id| {
                let pid = id_pid(id);
                let born = self.pids.get(&pid).copied().flatten().unwrap_or(first);
                pids.contains(&pid) && id_seconds(id) >= born
            })
    }

    /// Everything of the team iceoryx2 still has: services and nodes named after the team, and
    /// files under /dev/shm and iox2_root() named by its services or processes.
    pub fn leftovers(&self) -> Vec<String> {
        let team = self.team.as_str();
        let pids: BTreeSet<u32> = self
            .pids
            .keys()
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
        // iox2_root() lies inside /dev/shm: each file is listed once.
        let mut files = files_under(Path::new(SHM));
        if !Path::new(iox2_root()).starts_with(SHM) {
            files.extend(files_under(Path::new(iox2_root())));
        }
        {
            for path in files {
                let name = path
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                // iceoryx2's one global management file is shared by every process; the
                // team's command channel (`<team>.command`) is named after the team.
                let channel = name == format!("{team}.command");
                if channel || !name.ends_with(".global_mgmt") && self.names_the_team(&name, &pids) {
                    out.push(path.display().to_string());
                }
            }
        }
        out
    }

    /// Asserts the checker sees the live team (its services, nodes and shared-memory files), so
    /// that an empty `leftovers` later means something.
    pub fn assert_visible(&self, processes: usize) {
        let live = self.leftovers();
        let count = |p: &str| live.iter().filter(|l| l.starts_with(p)).count();
        let segments = live
            .iter()
            .filter(|l| l.starts_with(SHM) && !l.starts_with(iox2_root()))
            .count();
        assert!(
            count("service ") > 0
                && count("node ") == processes
                && segments > 0
                && count(iox2_root()) > 0,
            "the live team {} does not show {processes} nodes, services and files: {live:#?}",
            self.team
        );
    }

    pub fn assert_nothing_left(&self) {
        let left = self.leftovers();
        assert!(
            left.is_empty(),
            "team {} left {} iceoryx2 resources behind: {left:#?}",
            self.team,
            left.len()
        );
    }
}

/// Whether this process may make a private mount namespace (`unshare -m`: needs root), for a
/// test that wants a /dev/shm of its own; when not, says that the test is skipped.
pub fn private_mounts_allowed() -> bool {
    let probe = Command::new("unshare").args(["-m", "true"]).output();
    let allowed = probe.is_ok_and(|o| o.status.success());
    if !allowed {
        eprintln!("skipped: `unshare -m` is not available here (needs root)");
    }
    allowed
}

/// Asserts no process of `team` is alive.
pub fn assert_no_process_of(team: &str) {
    let procs = team_processes(team);
    assert!(
        procs.is_empty(),
        "processes of team {team} survived: {procs:#?}"
    );
}

/// Resumes and kills a stopped process if the test fails before the orchestrator did.
pub struct Stopped(pub u32);

impl Drop for Stopped {
    fn drop(&mut self) {
        if let Ok(pid) = libc::pid_t::try_from(self.0) {
            // SAFETY: kill(2) takes no pointers; at worst the pid is already gone.
            unsafe {
                libc::kill(pid, libc::SIGCONT);
                libc::kill(pid, libc::SIGKILL);
            }
        }
    }
}

/// The ground of `mission()`.
pub const GROUND_Z: f64 = 500.0;
/// The paper's goals (segment 1) turned by 30 degrees about their centre and moved, then the
/// paper's goals moved 40 m along each axis (rigid motions: no more deformation than the
/// paper's descent).
pub const SEGMENT_2: [[f64; 3]; 3] = [
    [94.0, 295.2, 540.0],
    [114.1, 64.4, 540.0],
    [283.9, 162.4, 540.0],
];
pub const SEGMENT_3: [[f64; 3]; 3] = [
    [264.0, 474.0, 600.0],
    [166.0, 264.0, 600.0],
    [362.0, 264.0, 600.0],
];

/// Ten members of the paper's kind: take off from z = 500 m (40 s, 1 s hover), the paper's
/// descent (60 s), two more segments (30 s each after 1 s), land (30 s after 1 s): 194 s, and
/// 10 s more on the ground while the followers come to rest.
pub fn mission() -> ScenarioFile {
    let mut f = cdm_scenario::generated(10).expect("ten agents generate");
    f.name = "mission10".into();
    f.t_total_s = 60.0;
    let ground = |t_s| cdm_scenario::GroundSpec {
        ground_z_m: GROUND_Z,
        t_s,
        hold_s: Some(1.0),
    };
    f.takeoff = Some(ground(40.0));
    f.segments = [SEGMENT_2, SEGMENT_3]
        .into_iter()
        .map(|g| cdm_scenario::SegmentSpec {
            hold_s: Some(1.0),
            t_s: 30.0,
            goals: g.to_vec(),
        })
        .collect();
    f.landing = Some(ground(30.0));
    f
}

/// A lab-sized mission (for the real-time and MAVLink flights): four members 3 m apart take off from z = 0 to 1.5 m
/// (4 s), translate by (0.3, 0.2, 0.2) m (2.5 s), land (4 s after 0.5 s), then the plan's 10 s
/// on the ground: 21 s. Certified SAFE (delta 0.70 m: `orchestrator plan`).
pub const LAB_MISSION: &str = r#"
name = "lab4"
t_total_s = 2.5
eps_m = 0.15
comm_hz = 50.0
gains = [8.0, 24.0, 51.5625, 23.4375]

[takeoff]
ground_z_m = 0.0
t_s = 4.0

[landing]
ground_z_m = 0.0
t_s = 4.0
hold_s = 0.5

[[agents]]
id = 1
role = "primary"
position = [0.0, 0.0, 1.5]
goal = [0.3, 0.2, 1.7]

[[agents]]
id = 2
role = "primary"
position = [3.0, 0.0, 1.5]
goal = [3.3, 0.2, 1.7]

[[agents]]
id = 3
role = "primary"
position = [1.5, 2.6, 1.5]
goal = [1.8, 2.8, 1.7]

[[agents]]
id = 4
role = "follower"
position = [1.5, 0.9, 1.5]
in_neighbors = [1, 2, 3]
"#;

/// [`LAB_MISSION`] parsed.
pub fn lab_mission() -> ScenarioFile {
    toml::from_str(LAB_MISSION).expect("the lab mission parses")
}

/// `text` (a scenario file) with its line that starts with `prefix` replaced by `line`.
pub fn with_line(text: &str, prefix: &str, line: &str) -> String {
    assert!(
        text.lines().any(|l| l.starts_with(prefix)),
        "no line starts with {prefix:?}:\n{text}"
    );
    let lines: Vec<&str> = (text.lines())
        .map(|l| if l.starts_with(prefix) { line } else { l })
        .collect();
    lines.join("\n") + "\n"
}
