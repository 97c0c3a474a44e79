//! `launch --foxglove` and `view --foxglove`: the team in Foxglove, checked with Foxglove's own
//! client (`@foxglove/ws-protocol`'s FoxgloveClient over the `ws` package, run by Node from
//! tests/foxglove, pinned in its package-lock.json). The client sees every advertised channel
//! with its well-known schema, decodes the poses with the schema the server advertised, and every
//! pose it receives equals a telemetry.csv row. A client that stops reading its socket stays
//! connected throughout and a second client connects late, mid-flight: the team flies on and both
//! readers get their poses. An address in use is exit 2, before any team exists.

use integration_tests::support;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use serde_json::Value;

use integration_tests::{bin, describe, launch_loud, run, spawn, unique_team, Running, TempDir};

const DEADLINE: Duration = integration_tests::deadline::FLIGHT;
/// Seconds a client waits for its poses (its own deadline), well inside the plan.
const CLIENT_WAIT_S: &str = "60";
/// Poses each reading client waits for (the team's members, a few ticks each).
const POSES: &str = "30";
/// A small team in real time over a plan longer than any wait: interrupted once the clients
/// have their poses. Member 9 (a follower) is lost at 1 s.
const TEAM: [&str; 10] = [
    "--n",
    "10",
    "--t-total",
    "120",
    "--realtime",
    "--stale-after",
    "5",
    "--no-figures",
    "--lose",
    "9@1",
];

/// The Node client of tests/foxglove (its packages installed by scripts/test-deps.sh).
fn client(url: &str, mode: &str) -> Command {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("foxglove");
    assert!(
        dir.join("node_modules/@foxglove/ws-protocol").is_dir(),
        "the Foxglove client is not installed: run scripts/test-deps.sh"
    );
    let mut c = Command::new("node");
    c.arg(dir.join("client.mjs"))
        .args([url, mode, CLIENT_WAIT_S, POSES]);
    c
}

/// The JSON lines a client printed.
fn events(stdout: &[u8]) -> Vec<Value> {
    String::from_utf8_lossy(stdout)
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// telemetry.csv as (tick, id) -> (x, y, z), and dt.
fn telemetry(run_dir: &Path) -> BTreeMap<(u64, u32), [f64; 3]> {
    let text = std::fs::read_to_string(run_dir.join("telemetry.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (tick, id, x, y, z) = (col("tick"), col("id"), col("x"), col("y"), col("z"));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let v = |k: usize| f[k].parse::<f64>().unwrap();
            (
                (f[tick].parse().unwrap(), f[id].parse().unwrap()),
                [v(x), v(y), v(z)],
            )
        })
        .collect()
}

/// The address a launch or a view printed (`foxglove: ws://HOST:PORT`).
fn url_of(r: &mut Running) -> String {
    r.wait_for_output("foxglove: ws://", DEADLINE);
    let (out, _) = r.output_so_far();
    let line = out
        .lines()
        .find(|l| l.starts_with("foxglove: ws://"))
        .unwrap();
    line["foxglove: ".len()..]
        .split_whitespace()
        .next()
        .unwrap()
        .to_owned()
}

/// What a reading client must have seen: every topic with its schema, poses equal to
/// telemetry rows (the tick from the pose's simulation time), margins and a verdict.
fn check_client(events: &[Value], rows: &BTreeMap<(u64, u32), [f64; 3]>, dt_s: f64) {
    let channels: BTreeMap<&str, (&str, &str)> = events
        .iter()
        .filter(|e| e["event"] == "channel")
        .map(|e| {
            (
                e["topic"].as_str().unwrap(),
                (
                    e["encoding"].as_str().unwrap(),
                    e["schemaName"].as_str().unwrap(),
                ),
            )
        })
        .collect();
    for id in 1..=6 {
        assert_eq!(
            channels.get(format!("/cdm/agent_{id}/pose").as_str()),
            Some(&("protobuf", "foxglove.PoseInFrame")),
            "{channels:?}"
        );
    }
    assert_eq!(
        channels.get("/tf"),
        Some(&("protobuf", "foxglove.FrameTransforms"))
    );
    assert_eq!(
        channels.get("/cdm/formation"),
        Some(&("protobuf", "foxglove.SceneUpdate"))
    );
    assert_eq!(channels.get("/cdm/audit"), Some(&("json", "cdm.Margins")));
    assert_eq!(channels.get("/cdm/verdict"), Some(&("json", "cdm.Verdict")));
    assert_eq!(
        channels.get("/cdm/events"),
        Some(&("protobuf", "foxglove.Log"))
    );
    let poses: Vec<&Value> = events.iter().filter(|e| e["event"] == "pose").collect();
    assert!(poses.len() >= 30, "{} poses", poses.len());
    for p in poses {
        let id: u32 = p["topic"].as_str().unwrap()["/cdm/agent_".len()..]
            .trim_end_matches("/pose")
            .parse()
            .unwrap();
        let t_s = p["sec"].as_f64().unwrap() + p["nsec"].as_f64().unwrap() * 1e-9;
        let tick = (t_s / dt_s).round() as u64;
        let got = [
            p["x"].as_f64().unwrap(),
            p["y"].as_f64().unwrap(),
            p["z"].as_f64().unwrap(),
        ];
        assert_eq!(p["frame"], "world");
        assert_eq!(
            rows.get(&(tick, id)),
            Some(&got),
            "member {id} at tick {tick}"
        );
    }
    let margins = events
        .iter()
        .find(|e| e["event"] == "json" && e["topic"] == "/cdm/audit")
        .expect("a margin");
    for key in [
        "separation_margin_m",
        "deviation_margin_m",
        "lambda1_margin",
    ] {
        assert!(margins["value"][key].is_number(), "{margins}");
    }
}

#[test]
fn foxglove_clients_see_the_topics_and_poses_equal_to_telemetry_a_stalled_one_slows_nothing() {
    let tmp = TempDir::new();
    let run_dir: PathBuf = tmp.path().join("run");
    let mut orch = launch_loud(&unique_team("foxglove"), &run_dir, &TEAM);
    orch.args(["--foxglove", "127.0.0.1:0"]);
    let mut orch = spawn(&mut orch);
    let url = url_of(&mut orch);
    // A client that subscribes to everything and never reads again, connected throughout.
    let mut stalled = spawn(&mut client(&url, "stall"));
    stalled.wait_for_output("stalled", DEADLINE);
    let first = spawn(&mut client(&url, "check")).finish(DEADLINE);
    assert!(first.status.success(), "{}", describe(&first));
    // A late client: the team has flown for a while.
    let late = spawn(&mut client(&url, "check")).finish(DEADLINE);
    assert!(late.status.success(), "{}", describe(&late));
    support::signal(orch.id(), libc::SIGINT);
    let o = orch.finish(DEADLINE);
    support::assert_exit(&o, 3, "launch --foxglove after SIGINT");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("ticks published"), "{stdout}");
    drop(stalled.kill());
    let rows = telemetry(&run_dir);
    let audit = support::read_json(&run_dir.join("audit.json"));
    let dt_s = audit["dt_s"].as_f64().unwrap();
    for c in [&first, &late] {
        check_client(&events(&c.stdout), &rows, dt_s);
    }
}

#[test]
fn foxglove_on_an_address_in_use_exits_2_before_the_team() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let team = unique_team("foxglovebusy");
    let mut c = launch_loud(&team, &out, &["--n", "6", "--t-total", "5"]);
    c.args(["--foxglove", &addr]);
    let o = run(&mut c, DEADLINE);
    support::assert_exit(&o, 2, "launch --foxglove on an address in use");
    support::assert_stderr_has(&o, "launch --foxglove", &["--foxglove", &addr]);
    assert!(
        !out.exists(),
        "{} written by a refused launch",
        out.display()
    );
    support::assert_no_team_resources(&team);
    let mut c = Command::new(bin("orchestrator"));
    c.args(["launch", "--n", "6", "--foxglove", "localhost"]);
    let o = run(&mut c, DEADLINE);
    support::assert_exit(&o, 2, "launch --foxglove localhost");
    support::assert_stderr_has(&o, "launch --foxglove localhost", &["--foxglove localhost"]);
}

#[test]
fn view_foxglove_plays_a_finished_run_to_a_client_equal_to_its_telemetry() {
    let tmp = TempDir::new();
    let run_dir = tmp.path().join("run");
    // A complete run, SAFE or not (this short plan breaks its tracking bound: exit 1).
    let o = run(
        &mut integration_tests::simulate(&run_dir, &["--n", "10", "--t-total", "5"]),
        DEADLINE,
    );
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", describe(&o));
    let mut view = Command::new(bin("orchestrator"));
    view.arg("view")
        .arg(&run_dir)
        .args(["--foxglove", "127.0.0.1:0"]);
    let mut view = spawn(&mut view);
    let url = url_of(&mut view);
    let c = spawn(&mut client(&url, "check")).finish(DEADLINE);
    assert!(c.status.success(), "{}", describe(&c));
    // The view plays to the end of the run (3 s of simulation time) and exits by itself.
    let v = view.finish(DEADLINE);
    support::assert_exit(&v, 0, "view --foxglove");
    let audit = support::read_json(&run_dir.join("audit.json"));
    let rows = telemetry(&run_dir);
    check_client(&events(&c.stdout), &rows, audit["dt_s"].as_f64().unwrap());
}
