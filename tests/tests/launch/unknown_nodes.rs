//! Dead iceoryx2 nodes that name no team, and old files that carry a team's process ids.
//!
//! A process killed (SIGKILL, `timeout`) while iceoryx2 drops or cleans its node leaves only the
//! node's monitor files: no details, so no team name. Before, nothing removed them (they piled
//! up by the hundreds on a CI machine), and since process ids wrap, the "nothing of the team is
//! left" checks blamed a live test's team for an old node whose pid one of its processes held
//! now. Here:
//! - `orchestrator clean` removes such a node and says so, and a launch after it leaves /dev/shm
//!   as it was (in a private /dev/shm: a mount namespace, skipped where `unshare -m` is not
//!   allowed);
//! - the leftovers check (`support::TeamFootprint`) reports the files of a team's process, and not
//!   those minted before a process of the team took the same pid.
//!
//! The node is made by this test binary run as a child (`node_maker`): it creates an iceoryx2
//! node with the runtime's own configuration, the way every member does.

use integration_tests::support;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use cdm_iox::ids::{born_s, id_pid, id_seconds, monotonic_s};
use cdm_iox::{iox2_location, TeamName};
use iceoryx2::prelude::*;
use integration_tests::{bin, describe, run, spawn, unique_team, Running, TempDir};
use support::*;

/// Each step takes a second or two; the rest is slack for a loaded machine.
const DEADLINE: Duration = integration_tests::deadline::FLIGHT;
/// Set in the child that runs `node_maker`: `<team>:<file whose creation ends it>`.
const MAKER_ENV: &str = "CDM_NODE_MAKER";

/// Not a test on its own: the body of the child that makes a node. Creates the node of agent 0
/// of the team, prints `NODE <node id> <pid> END`, and holds it until the file appears (then drops
/// it, removing its files) or 60 s pass. In a normal run (no `CDM_NODE_MAKER`) it returns.
#[test]
fn node_maker() {
    let Ok(job) = std::env::var(MAKER_ENV) else {
        return;
    };
    let (team, until) = job.split_once(':').expect("<team>:<file>");
    let team = TeamName::new(team).expect("team name");
    let name = team.node_name(cdm_iox::TeamProcess::Agent(0));
    let node = NodeBuilder::new()
        .name(&NodeName::new(&name).expect("node name"))
        .config(&cdm_iox::iceoryx2_config())
        .create::<ipc::Service>()
        .expect("create the node");
    // ` END` closes the line: a reader that sees it has both numbers whole.
    println!("NODE {} {} END", node.id().value(), std::process::id());
    let end = Instant::now() + Duration::from_secs(60);
    while !Path::new(until).exists() && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `node_maker`'s name as this test binary's filter takes it: its path in the binary
/// (`unknown_nodes::node_maker` in the group's binary).
fn node_maker_test() -> String {
    match module_path!().split_once("::") {
        Some((_, module)) => format!("{module}::node_maker"),
        None => "node_maker".to_owned(),
    }
}

/// `node_maker` for `team` as a command; it ends when `until` is created.
fn maker(team: &str, until: &Path) -> Command {
    let mut c = Command::new(std::env::current_exe().expect("this test binary"));
    // The team among the arguments (a filter matching no test) marks the process as the team's.
    c.arg(node_maker_test())
        .args([team, "--exact", "--nocapture", "--test-threads=1"])
        .env(MAKER_ENV, format!("{team}:{}", until.display()));
    c
}

/// The node id and pid `node_maker` printed.
fn made_node(maker: &mut Running) -> (u128, u32) {
    maker.wait_for_output(" END", DEADLINE);
    let (out, _) = maker.output_so_far();
    let (_, rest) = out.split_once("NODE ").expect("NODE line");
    let mut words = rest.split_whitespace();
    let mut next = || words.next().and_then(|w| w.parse::<u128>().ok());
    match (next(), next()) {
        (Some(id), Some(pid)) => (id, pid as u32),
        _ => panic!("node_maker printed {out:?}"),
    }
}

/// The node's details directory and its monitor files (`<prefix><id>.node_monitor...`).
fn node_files(id: u128) -> (PathBuf, Vec<PathBuf>) {
    let nodes = Path::new(iox2_root()).join("nodes");
    let monitor = format!("{}{id}.node_monitor", iox2_location().prefix);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&nodes)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(&monitor))
        .map(|e| e.path())
        .collect();
    files.sort();
    (nodes.join(id.to_string()), files)
}

/// The leftovers check reports every file of a team's live process (its node's details and
/// monitor files), and none of them once that pid is taken to belong to a process born after
/// the files were made (a recycled pid): that is what blamed live teams for old dead nodes.
#[test]
fn leftovers_name_a_process_files_but_not_older_files_of_a_recycled_pid() {
    let dir = TempDir::new();
    let team = unique_team("pidwrap");
    let done = dir.path().join("done");
    let mut child = spawn(&mut maker(&team, &done));
    let (id, pid) = made_node(&mut child);
    // The id carries the creator's pid and its CLOCK_MONOTONIC second (what the check relies on).
    let born = born_s(pid).expect("node_maker is alive");
    assert_eq!(id_pid(id), pid, "node id {id}");
    assert!(
        (born..=monotonic_s()).contains(&id_seconds(id)),
        "node id {id}: minted at second {}, the process was born at {born}",
        id_seconds(id)
    );
    let (details, monitors) = node_files(id);
    assert_eq!(
        monitors.len(),
        3,
        "monitor files of node {id}: {monitors:?}"
    );

    let fp = TeamFootprint::record(&team, [pid]);
    let left = fp.leftovers();
    let id_text = id.to_string();
    let named: Vec<&String> = left.iter().filter(|l| l.contains(&id_text)).collect();
    assert!(
        named.len() >= 4 && left.iter().any(|l| l.starts_with("node ")),
        "the check misses the node's files ({} and {monitors:?}): {left:#?}",
        details.display()
    );

    // The same pid, held by a process born two seconds after the node was made: none of the
    // node's files is blamed (the node's name still is: it names the team).
    let files = |fp: &TeamFootprint| -> Vec<String> {
        let left = fp.leftovers();
        left.into_iter().filter(|l| l.starts_with('/')).collect()
    };
    let mut recycled = TeamFootprint::record(&team, []);
    recycled.assume_process(pid, id_seconds(id) + 2);
    assert_eq!(files(&recycled), Vec::<String>::new());
    recycled.assume_process(pid, id_seconds(id));
    assert_eq!(files(&recycled), files(&fp));

    std::fs::write(&done, "").expect("write the end file");
    let o = child.finish(DEADLINE);
    assert!(o.status.success(), "{}", describe(&o));
    fp.assert_nothing_left();
}

/// A node killed after iceoryx2 removed its details (as in the middle of a drop): only its
/// three monitor files are left. `orchestrator clean` removes them and says so; so does the
/// clean-up a launch does first: after a second such node and a launch, /dev/shm is exactly as
/// before the first node was made. In a private /dev/shm, after a warm-up launch that creates
/// what iceoryx2 keeps for good (the root, the management segment).
#[test]
fn clean_and_launch_remove_a_dead_node_of_no_team_and_leave_nothing() {
    if !private_mounts_allowed() {
        return;
    }
    let dir = TempDir::new();
    let maker_team = unique_team("nodetails");
    let team = unique_team("afterclean");
    // `orphan FILE`: a node made by `node_maker`, its details removed, the maker SIGKILLed; the
    // node's files are listed in FILE.
    let script = r#"
set -eu
O="$0"; T="$1"; D="$2"; MAKER="$3"; TEAM="$4"; ROOT="$5"; PREFIX="$6"; TEST="$7"
orphan() {
  out="$1"
  CDM_NODE_MAKER="$MAKER:$D/never" "$T" "$TEST" "$MAKER" --exact --nocapture \
    --test-threads=1 > "$D/maker.txt" 2>/dev/null &
  i=0
  until grep -q "NODE [0-9][0-9]* [0-9][0-9]* END" "$D/maker.txt"; do
    i=$((i+1)); [ "$i" -lt 600 ] || { echo "node_maker never made its node"; exit 1; }
    sleep 0.1
  done
  set -- $(sed -n 's/.*NODE \([0-9]*\) \([0-9]*\) END.*/\1 \2/p' "$D/maker.txt")
  rm -r "$ROOT/nodes/$1"
  kill -9 "$2"
  wait || true
  ls "$ROOT/nodes" | grep "^$PREFIX$1\." | sort > "$D/$out"
}
mount -t tmpfs -o size=1g tmpfs /dev/shm
timeout 60 "$O" launch --n 4 --max-ticks 2 --no-figures --quiet --team warmup --out "$D/w" >/dev/null
find /dev/shm | sort > "$D/before.txt"
orphan orphan1.txt
"$O" clean > "$D/clean.txt"
find /dev/shm | sort > "$D/cleaned.txt"
orphan orphan2.txt
timeout 60 "$O" launch --n 4 --max-ticks 2 --no-figures --quiet --team "$TEAM" --out "$D/o" >/dev/null
find /dev/shm | sort > "$D/after.txt"
"#;
    let loc = iox2_location();
    let o = run(
        Command::new("unshare")
            .args(["-m", "sh", "-c", script])
            .arg(bin("orchestrator"))
            .arg(std::env::current_exe().expect("this test binary"))
            .arg(dir.path())
            .args([&maker_team, &team, &loc.root, &loc.prefix])
            .arg(node_maker_test()),
        DEADLINE,
    );
    assert!(o.status.success(), "{}", describe(&o));
    let read = |name: &str| {
        std::fs::read_to_string(dir.path().join(name))
            .unwrap_or_else(|e| panic!("{name}: {e}\n{}", describe(&o)))
    };
    for made in ["orphan1.txt", "orphan2.txt"] {
        let orphan: Vec<String> = read(made).lines().map(str::to_owned).collect();
        let kinds: Vec<&str> = orphan
            .iter()
            .filter_map(|f| f.split_once(".node_monitor").map(|(_, k)| k))
            .collect();
        assert_eq!(kinds, ["", "_context", "_owner_lock"], "{made}: {orphan:?}");
    }
    let clean = read("clean.txt");
    assert!(
        clean.contains("removed 1 dead iceoryx2 node(s) of unknown teams"),
        "clean said: {clean}"
    );
    let before = read("before.txt");
    assert_eq!(before, read("cleaned.txt"), "/dev/shm after clean");
    assert_eq!(
        before,
        read("after.txt"),
        "/dev/shm after the second node and a launch"
    );
}
