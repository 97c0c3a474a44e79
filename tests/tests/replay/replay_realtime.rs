//! `orchestrator replay` of a real-time run: the members' recordings (which in-neighbour state
//! each tick flew on, decided by the wall clock) make a `launch --realtime` flight reproducible.
//!
//! One real-time flight of 10 processes over impaired links (delay, jitter and loss), 3 s of
//! plan, then in process only:
//! - the replay's telemetry.csv is the run's byte for byte and audit.json's safety figures are
//!   the run's; every member left a recording; the replay's run.json says it is one (and a
//!   replay of it is refused: the recordings are the run's);
//! - what if: `--gains`, `--scenario` (the same team with those gains: the same bytes) and
//!   `--link-delay-ms` fly the same history differently, and two such replays are identical;
//!   other jitter is refused;
//! - a recording cut short (as a killed member leaves it) replays up to where it ends and says
//!   so, exit 3; a tampered or foreign one is exit 2 naming the file and its first bad record
//!   (audit.json's states the monitor never heard, when of a stranger, naming the field);
//!   nothing panics.
//!
//! A second flight over the same links loses a member (`--lose`, repaired around): its readers'
//! recordings hold the tick each flew its repaired link from, and the replay is the run's byte
//! for byte (telemetry.csv and the safety figures, the loss's records among them).
//!
//! A third, started by hand (`--no-spawn`): `launch` prints `--record` among the members' flags,
//! and the members started with them record; the replay is the run's byte for byte.
//!
//! How to run: `cargo test --release -p integration-tests --test replay -- replay_realtime::`.

use integration_tests::support;

use std::path::{Path, PathBuf};

use std::time::Duration;

use integration_tests::{run, spawn, unique_team, TempDir};
use serde_json::Value;
use support::{
    assert_exit, assert_no_process_of, assert_same_file, assert_stderr_has, launch, read_json,
    replay, with_line,
};

const DEADLINE: Duration = integration_tests::deadline::FLIGHT;

/// The team of every flight here: 10 members in real time, 3 s of a 30 s plan.
const TEAM: [&str; 8] = [
    "--n",
    "10",
    "--t-total",
    "30",
    "--realtime",
    "--no-figures",
    "--max-ticks",
    "300",
];

/// audit.json without what the wall clock decided (the pacing figures).
fn figures(dir: &Path) -> Value {
    let mut a = read_json(&dir.join("audit.json"));
    if let Some(o) = a.as_object_mut() {
        o.remove("realtime");
    }
    a
}

/// A copy of the run directory `from` at `to` (flat, plus its recording folder).
fn copy_run(from: &Path, to: &Path) {
    for sub in ["", "recording"] {
        std::fs::create_dir_all(to.join(sub)).expect("mkdir");
        for e in std::fs::read_dir(from.join(sub)).expect("read_dir") {
            let p = e.expect("entry").path();
            if p.is_file() {
                let name = p.file_name().expect("name");
                std::fs::copy(&p, to.join(sub).join(name)).expect("copy");
            }
        }
    }
}

/// The 10-agent team over impaired links, 3 s of plan, into `dir/name` with `extra` flags:
/// exit 0, SAFE, complete.
fn flight(dir: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let team = unique_team("rt_replay");
    let out = dir.join(name);
    let mut args = TEAM.to_vec();
    args.extend([
        "--link-delay-ms",
        "15",
        "--link-jitter-ms",
        "10",
        "--link-loss",
        "0.1",
        "--seed",
        "5",
    ]);
    args.extend(extra);
    let o = run(&mut launch(&team, &out, &args), DEADLINE);
    assert_exit(&o, 0, "launch --realtime over impaired links");
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    assert_eq!(audit["complete"], true, "{audit:#}");
    assert_no_process_of(&team);
    out
}

#[test]
fn a_real_time_run_replays_byte_for_byte_and_what_if_is_deterministic() {
    let dir = TempDir::new();
    let rt = flight(dir.path(), "rt", &[]);
    for id in 1..=10 {
        let p = rt.join("recording").join(format!("{id}.mcap"));
        assert!(p.is_file(), "no recording of agent {id}");
    }

    // The same flight, in process.
    let same = dir.path().join("same");
    let o = replay(&rt, &same, &[]);
    assert_exit(&o, 0, "replay of a real-time run");
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("telemetry.csv: identical to the run's"),
        "{said}"
    );
    assert_same_file(&rt.join("telemetry.csv"), &same.join("telemetry.csv"));
    assert_eq!(figures(&rt), figures(&same), "audit.json's safety figures");
    // Its run.json says what it is; its history is the run's recordings, so replaying the
    // replay is refused, pointing at the run.
    let r = read_json(&same.join("run.json"));
    assert_eq!(r["mode"], "realtime-replay", "{r:#}");
    assert_eq!(
        r["every"],
        read_json(&rt.join("run.json"))["every"],
        "{r:#}"
    );
    let o = replay(&same, &dir.path().join("again"), &[]);
    assert_exit(&o, 2, "replay of a real-time run's replay");
    assert_stderr_has(
        &o,
        "replay",
        &["the replay of a real-time run: replay the run's own directory"],
    );

    // What if: other gains on the same history differ from the run, and deterministically.
    let gains = ["--gains", "30,40,25,8"];
    let (a, b) = (dir.path().join("gains-a"), dir.path().join("gains-b"));
    for out in [&a, &b] {
        let o = replay(&rt, out, &gains);
        assert!(matches!(o.status.code(), Some(0 | 1)), "{o:?}");
    }
    let read = |p: &Path| std::fs::read(p.join("telemetry.csv")).expect("telemetry.csv");
    assert_ne!(read(&rt), read(&a), "other gains fly differently");
    assert_same_file(&a.join("telemetry.csv"), &b.join("telemetry.csv"));
    assert_eq!(figures(&a), figures(&b));

    // What if from a scenario file: the run's team with those gains flies as --gains does.
    let text = std::fs::read_to_string(rt.join("scenario.toml")).expect("scenario.toml");
    let soft = with_line(&text, "gains = ", "gains = [30.0, 40.0, 25.0, 8.0]");
    let soft = integration_tests::write_text(dir.path(), "soft.toml", &soft);
    let from_file = dir.path().join("from-file");
    let o = replay(
        &rt,
        &from_file,
        &["--scenario", soft.to_str().expect("path")],
    );
    assert!(matches!(o.status.code(), Some(0 | 1)), "{o:?}");
    assert_same_file(&a.join("telemetry.csv"), &from_file.join("telemetry.csv"));

    // What if the links were slower: 40 ms more than the run's 15 (every state flown on four
    // ticks older), twice; their jitter or losses cannot change (the recording is what they
    // delivered).
    let slow = ["--link-delay-ms", "55"];
    let (c, d) = (dir.path().join("slow-a"), dir.path().join("slow-b"));
    for out in [&c, &d] {
        let o = replay(&rt, out, &slow);
        assert!(matches!(o.status.code(), Some(0 | 1)), "{o:?}");
    }
    assert_ne!(read(&rt), read(&c), "slower links fly differently");
    assert_same_file(&c.join("telemetry.csv"), &d.join("telemetry.csv"));
    let o = replay(&rt, &dir.path().join("jitter"), &["--link-jitter-ms", "5"]);
    assert_exit(&o, 2, "replay --link-jitter-ms of a real-time run");
    assert_stderr_has(&o, "replay", &["only --link-delay-ms can change"]);

    // Cut short: agent 8's recording as a kill would leave it (no end, half its bytes).
    let cut = dir.path().join("cut");
    copy_run(&rt, &cut);
    let p = cut.join("recording").join("8.mcap");
    let bytes = std::fs::read(&p).expect("recording");
    std::fs::write(&p, &bytes[..bytes.len() / 2]).expect("cut");
    let o = replay(&cut, &dir.path().join("cut-replay"), &[]);
    assert_exit(&o, 3, "replay of a recording cut short");
    assert_stderr_has(
        &o,
        "replay",
        &["recording is cut short", "agent 8 after", "replayed"],
    );
    let rows = std::fs::read_to_string(dir.path().join("cut-replay").join("telemetry.csv"))
        .expect("telemetry.csv of what was replayed");
    let run_rows = std::fs::read_to_string(rt.join("telemetry.csv")).expect("telemetry.csv");
    assert!(rows.lines().count() > 1 && rows.lines().count() < run_rows.lines().count());
    assert!(
        run_rows.starts_with(&rows),
        "the replayed rows are the run's first ones"
    );

    // Tampered: an age made impossible in agent 9's recording.
    let bad = dir.path().join("bad");
    copy_run(&rt, &bad);
    let p = bad.join("recording").join("9.mcap");
    let mut bytes = std::fs::read(&p).expect("recording");
    let at = bytes
        .windows(7)
        .position(|w| w == b"\"age\":[")
        .expect("ages")
        + 7;
    // Tick 0 flies before any state could arrive over the 15 ms links: its age is null.
    assert_eq!(&bytes[at..at + 4], b"null");
    bytes[at..at + 4].copy_from_slice(b"77  ");
    std::fs::write(&p, &bytes).expect("tampered");
    let o = replay(&bad, &dir.path().join("bad-replay"), &[]);
    assert_exit(&o, 2, "replay of a tampered recording");
    assert_stderr_has(&o, "replay", &["9.mcap: record 2: tick 0 slot 0: age 77"]);

    // Foreign: agent 9's recording in agent 10's place.
    copy_run(&rt, &bad);
    std::fs::copy(rt.join("recording/9.mcap"), bad.join("recording/10.mcap")).expect("copy");
    let o = replay(&bad, &dir.path().join("foreign-replay"), &["--force"]);
    assert_exit(&o, 2, "replay of another member's recording");
    assert_stderr_has(
        &o,
        "replay",
        &["10.mcap: record 1: the recording of agent 9"],
    );

    // Tampered: audit.json says the monitor never heard states of a member the team lacks.
    copy_run(&rt, &bad);
    let path = bad.join("audit.json");
    let mut audit = read_json(&path);
    audit["realtime"]["unheard"] = serde_json::json!([{"id": 99, "from": 3, "to": 5}]);
    std::fs::write(&path, audit.to_string()).expect("tampered");
    let o = replay(&bad, &dir.path().join("unheard-replay"), &[]);
    assert_exit(
        &o,
        2,
        "replay of an audit.json with a stranger's unheard states",
    );
    assert_stderr_has(
        &o,
        "replay",
        &["realtime.unheard: agent 99 ticks 3..=5: not a member's ticks"],
    );
}

/// `--lose 6@1` over the impaired links: secondary leader 6 is stopped once it has published
/// its tick of 1 s, and its readers 7, 9 and 10 fly the repaired graph from the ticks their
/// recordings say; the replay gives the run's telemetry and safety figures (the loss's audit
/// instant, repair tick and re-triangulations among them) byte for byte.
#[test]
fn a_real_time_run_with_a_loss_replays_byte_for_byte() {
    let dir = TempDir::new();
    let rt = flight(dir.path(), "lose", &["--lose", "6@1"]);
    let audit = read_json(&rt.join("audit.json"));
    let losses = audit["losses"].as_array().expect("losses");
    assert_eq!(losses.len(), 1, "{audit:#}");
    assert_eq!(losses[0]["id"], 6, "{audit:#}");
    for reader in [7, 9, 10] {
        let p = rt.join("recording").join(format!("{reader}.mcap"));
        let bytes = std::fs::read(&p).expect("recording");
        let needle = b"{\"repair\":{\"at";
        let relinked = bytes.windows(needle.len()).any(|w| w == needle);
        assert!(relinked, "agent {reader}'s recording has no repaired link");
    }
    let same = dir.path().join("same");
    let o = replay(&rt, &same, &[]);
    assert_exit(&o, 0, "replay of a real-time run with a loss");
    assert_same_file(&rt.join("telemetry.csv"), &same.join("telemetry.csv"));
    assert_eq!(figures(&rt), figures(&same), "audit.json's safety figures");
    let replayed = read_json(&same.join("audit.json"));
    assert_eq!(replayed["losses"], audit["losses"], "the loss as recorded");
}

/// A real-time team started by hand (`--no-spawn`): `launch` prints `--record DIR` among the
/// members' flags, the members started with the printed flags record into the run directory, and
/// the run replays byte for byte.
#[test]
fn a_team_started_by_hand_records_as_told_and_replays_byte_for_byte() {
    let dir = TempDir::new();
    let team = unique_team("rt_by_hand");
    let out = dir.path().join("hand");
    let mut args = TEAM.to_vec();
    args.extend(["--no-spawn", "--join-timeout", "60"]);
    let mut orch = spawn(&mut integration_tests::launch_loud(&team, &out, &args));
    orch.wait_for_output("start each with:", DEADLINE);
    let (o, e) = orch.output_so_far();
    let line = (o.lines().chain(e.lines()))
        .find(|l| l.trim_start().starts_with("agent "))
        .expect("the agents' command line")
        .to_string();
    let flags = line.split("   (ids").next().expect("the flags");
    let words: Vec<&str> = flags.split_whitespace().skip(1).collect();
    let after = |flag: &str| {
        let k = words.iter().position(|w| *w == flag);
        k.and_then(|k| words.get(k + 1)).copied()
    };
    let record = after("--record").unwrap_or_else(|| panic!("no --record in {line:?}"));
    assert!(Path::new(record).ends_with("recording"), "{line}");
    let scenario = after("--scenario").expect("--scenario");
    let s = support::flown_scenario_file(Path::new(scenario));
    let mut members = Vec::new();
    for a in &s.agents {
        let id = a.id.to_string();
        let mut c = std::process::Command::new(integration_tests::bin(support::binary_for(a.role)));
        c.args(
            words
                .iter()
                .map(|w| if *w == "ID" { id.as_str() } else { w }),
        );
        members.push(spawn(&mut c));
    }
    for m in members {
        assert_exit(&m.finish(DEADLINE), 0, "a member started by hand");
    }
    assert_exit(&orch.finish(DEADLINE), 0, "launch --realtime --no-spawn");
    for a in &s.agents {
        let p = out.join("recording").join(format!("{}.mcap", a.id));
        assert!(p.is_file(), "no recording of agent {}", a.id);
    }
    let same = dir.path().join("same");
    assert_exit(
        &replay(&out, &same, &[]),
        0,
        "replay of a team started by hand",
    );
    assert_same_file(&out.join("telemetry.csv"), &same.join("telemetry.csv"));
    assert_no_process_of(&team);
}

/// A real-time run its monitor stopped on a fault (a stale bound of 20 ms under 15 ms links: a
/// member is soon stale): the instant it stopped at was the wall clock's decision, and the
/// replay stops there with the same fault; telemetry.csv and the safety figures are the run's.
#[test]
fn a_real_time_run_stopped_on_a_fault_replays_up_to_its_stop() {
    let dir = TempDir::new();
    let team = unique_team("rt_replay_stale");
    let rt = dir.path().join("stale");
    let mut args = TEAM.to_vec();
    args.extend([
        "--on-loss",
        "stop",
        "--link-delay-ms",
        "15",
        "--stale-after",
        "0.02",
    ]);
    let o = run(&mut launch(&team, &rt, &args), DEADLINE);
    assert_exit(
        &o,
        3,
        "launch --realtime with a stale bound below the links' delay",
    );
    let audit = read_json(&rt.join("audit.json"));
    assert!(audit["fault"].is_object(), "{audit:#}");
    let same = dir.path().join("same");
    let o = replay(&rt, &same, &[]);
    assert_exit(&o, 3, "replay of a run stopped on a fault");
    assert_same_file(&rt.join("telemetry.csv"), &same.join("telemetry.csv"));
    assert_eq!(figures(&rt), figures(&same), "audit.json's safety figures");
    assert_no_process_of(&team);
}
