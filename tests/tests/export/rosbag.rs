//! `orchestrator export rosbag2` and `--telemetry mcap`: the bag of a run, read by
//! code nobody here wrote. `rosbags` opens the rosbag2 directory and decodes every message with
//! its ROS 2 Humble typestore (one PoseStamped topic per member with one message per telemetry
//! row, the last pose equal to telemetry to 1e-6 m; /tf, the MarkerArray, the margins), Foxglove's
//! `mcap` reads the summary, the schemas (equal to the ROS 2 definitions) and the channels; a
//! fenced paper40's geofence and obstacles are markers where its scenario.toml puts them. The
//! bag written during a run (`simulate` and `launch --telemetry mcap`) equals, message for
//! message, the export of that run. A bad RUN_DIR or an existing --out exits 2 naming it.
//!
//! Live (`launch --ros2`): a real ROS 2 node (rclpy from PyPI over rmw_fastrtps) receives
//! /cdm/agent_1/pose over DDS, and an eclipse-zenoh router stand-in receives it on rmw_zenoh's
//! key expression with rmw_zenoh's attachment and liveliness tokens; every pose received equals a
//! telemetry row. The team flies in real time (a long plan) until the subscriber has its poses,
//! then is interrupted: the flight lasts as long as discovery takes, not a guessed time.

use integration_tests::support;

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{
    bin, describe, fenced_paper40, free_udp_ports, launch, python_script, run, simulate, spawn,
    unique_team, venv_python, write_scenario, TempDir,
};

const DEADLINE: Duration = integration_tests::deadline::FLIGHT;
/// A small team over a short plan; member 9 (a follower) is lost at 2 s, so ticks after it have
/// fewer rows, frames and spheres.
const TEAM: [&str; 5] = ["--n", "10", "--t-total", "5", "--no-figures"];
const LOSS: [&str; 2] = ["--lose", "9@2"];

fn orchestrator(args: &[&str]) -> Output {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    run(&mut c, DEADLINE)
}

fn export(run_dir: &Path, out: &Path, extra: &[&str]) -> Output {
    let (r, o) = (run_dir.to_str().unwrap(), out.to_str().unwrap());
    orchestrator(&[&["export", "rosbag2", r, "--out", o][..], extra].concat())
}

/// Fly the team; at --t-total 5 the followers lag behind their plan (UNSAFE, exit 1): the bag
/// shows a run whatever its verdict.
fn fly(out: &Path, extra: &[&str]) {
    let o = run(&mut simulate(out, &[&TEAM[..], extra].concat()), DEADLINE);
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", describe(&o));
}

/// Run the checker; its output names what failed.
fn check(mode: &str, a: &Path, b: &Path) {
    let mut c = Command::new(venv_python());
    c.arg(python_script("check_rosbag2.py"))
        .args([mode.as_ref(), a.as_os_str(), b.as_os_str()])
        .env("PYTHONDONTWRITEBYTECODE", "1");
    let out = run(&mut c, DEADLINE);
    assert!(out.status.success(), "{}", describe(&out));
}

#[test]
fn export_of_a_csv_run_is_read_by_rosbags_and_mcap() {
    let tmp = TempDir::new();
    let (run_dir, bag) = (tmp.path().join("run"), tmp.path().join("bag"));
    fly(&run_dir, &LOSS);
    let out = export(&run_dir, &bag, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    assert!(bag.join("metadata.yaml").is_file() && bag.join("bag_0.mcap").is_file());
    check("check", &bag, &run_dir);
}

/// paper40 in its airspace: the fence and the obstacles are markers too.
#[test]
fn export_of_a_parquet_run_with_every_is_read_by_rosbags_and_mcap() {
    let tmp = TempDir::new();
    let (run_dir, bag) = (tmp.path().join("run"), tmp.path().join("bag"));
    let fenced = write_scenario(tmp.path(), "fenced.toml", &fenced_paper40());
    let source = ["--scenario", fenced.to_str().unwrap(), "--max-ticks", "300"];
    let flags = ["--no-figures", "--telemetry", "parquet", "--every", "3"];
    let o = run(
        &mut simulate(&run_dir, &[&source[..], &flags[..]].concat()),
        DEADLINE,
    );
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let out = export(&run_dir, &bag, &["--quiet"]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    check("check", &bag, &run_dir);
}

#[test]
fn simulate_telemetry_mcap_equals_the_export_of_the_run() {
    let tmp = TempDir::new();
    let (run_dir, bag) = (tmp.path().join("run"), tmp.path().join("exported"));
    fly(
        &run_dir,
        &[&LOSS[..], &["--telemetry", "mcap", "--every", "2"]].concat(),
    );
    let live = run_dir.join("rosbag2");
    check("check", &live, &run_dir);
    let out = export(&run_dir, &bag, &["--quiet"]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    check("equal", &live, &bag);
    // A run reusing the directory in another format leaves no bag of the earlier run behind.
    fly(&run_dir, &["--force"]);
    assert!(!live.exists(), "{} left by the earlier run", live.display());
}

/// paper40 commanded (`simulate --commands`: held, refused a 1 s goto, landed): the bag written
/// during the run carries one `/cdm/commands` String per command of its commands.json (the
/// checker compares them), and `export rosbag2` of the run the very same messages.
#[test]
fn a_commanded_runs_bag_carries_its_commands() {
    let tmp = TempDir::new();
    let (run_dir, bag) = (tmp.path().join("run"), tmp.path().join("exported"));
    let file = tmp.path().join("commands.json");
    std::fs::write(
        &file,
        r#"[{"at_s": 30, "command": "hold"},
            {"at_s": 40, "command": "goto", "travel_s": 1,
             "goals": [[300, 500, 600], [300, 300, 600], [400, 300, 600]]},
            {"at_s": 50, "command": "land"}]"#,
    )
    .unwrap();
    let commands = ["--commands", file.to_str().unwrap()];
    let flags = [
        "--builtin",
        "paper40",
        "--no-figures",
        "--telemetry",
        "mcap",
        "--every",
        "50",
    ];
    let o = run(
        &mut simulate(&run_dir, &[&flags[..], &commands[..]].concat()),
        DEADLINE,
    );
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let live = run_dir.join("rosbag2");
    check("check", &live, &run_dir);
    let out = export(&run_dir, &bag, &["--quiet"]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    check("equal", &live, &bag);
}

#[test]
fn launch_telemetry_mcap_equals_the_export_of_the_run() {
    let tmp = TempDir::new();
    let (run_dir, bag) = (tmp.path().join("run"), tmp.path().join("exported"));
    let team = unique_team("rosbag");
    let args = [&TEAM[..], &["--telemetry", "mcap"]].concat();
    let o = run(&mut launch(&team, &run_dir, &args), DEADLINE);
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", describe(&o));
    let live = run_dir.join("rosbag2");
    check("check", &live, &run_dir);
    let out = export(&run_dir, &bag, &["--quiet"]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    check("equal", &live, &bag);
}

fn refused(out: &Output, names: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{}", describe(out));
    assert!(err.contains(names), "stderr should name {names}: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_run_dirs_and_an_existing_out_exit_2_naming_them() {
    let tmp = TempDir::new();
    let (run_dir, bag) = (tmp.path().join("run"), tmp.path().join("bag"));
    refused(&export(&tmp.path().join("nowhere"), &bag, &[]), "nowhere");
    fly(&run_dir, &[]);
    // An existing, non-empty --out is not overwritten without --force.
    std::fs::create_dir_all(&bag).unwrap();
    std::fs::write(bag.join("mine.txt"), "keep").unwrap();
    refused(&export(&run_dir, &bag, &[]), "--out");
    let forced = export(&run_dir, &bag, &["--force", "--quiet"]);
    assert_eq!(forced.status.code(), Some(0), "{}", describe(&forced));
    assert!(bag.join("mine.txt").is_file() && bag.join("metadata.yaml").is_file());
    // Broken files of the run: each named, and no partial bag left.
    let csv = run_dir.join("telemetry.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    std::fs::write(&csv, text.replacen(",follower,", ",follower,oops", 1)).unwrap();
    let partial = tmp.path().join("partial");
    refused(&export(&run_dir, &partial, &[]), "telemetry.csv");
    assert!(!partial.exists(), "a partial bag was left");
    std::fs::write(run_dir.join("audit.json"), "{").unwrap();
    refused(&export(&run_dir, &partial, &[]), "audit.json");
    std::fs::write(run_dir.join("scenario.toml"), "n = ").unwrap();
    refused(&export(&run_dir, &partial, &[]), "scenario.toml");
}

/// Poses the live subscriber waits for (about 0.7 s of the default 30 Hz).
const LIVE_POSES: &str = "20";
/// Seconds the subscriber waits for them (discovery included), well inside the plan.
const LIVE_WAIT_S: &str = "60";
/// A small team in real time over a plan longer than any wait: interrupted once the poses are
/// in. A member's state may be old by 5 s before it is a fault (a loaded machine).
const LIVE_TEAM: [&str; 8] = [
    "--n",
    "6",
    "--t-total",
    "120",
    "--realtime",
    "--stale-after",
    "5",
    "--no-figures",
];

/// A DDS domain of this test process (0..=232 are ROS 2's), so parallel runs do not meet.
fn ros_domain(offset: u32) -> String {
    (1 + (std::process::id() + offset) % 200).to_string()
}

/// A TCP port on 127.0.0.1 that nothing listens on (below the ephemeral range).
fn free_tcp_port() -> u16 {
    loop {
        let port = free_udp_ports(1);
        if std::net::TcpListener::bind(("127.0.0.1", port)).is_ok() {
            return port;
        }
    }
}

/// `launch --ros2 BACKEND` with the subscriber of `tests/python/ros2_live.py` started first, both
/// in `env`; the team is interrupted (exit 3) once the subscriber has its poses, which must equal
/// the run's telemetry.
fn live(backend: &str, extra: &[&str], env: &[(&str, String)]) {
    let tmp = TempDir::new();
    let (run_dir, got) = (tmp.path().join("run"), tmp.path().join("received.json"));
    let mut sub = Command::new(venv_python());
    sub.arg(python_script("ros2_live.py"))
        .args([backend, got.to_str().unwrap(), LIVE_POSES, LIVE_WAIT_S])
        .args(extra)
        .env("PYTHONDONTWRITEBYTECODE", "1");
    let mut orch = launch(&unique_team("ros2live"), &run_dir, &LIVE_TEAM);
    orch.args(["--ros2", backend]);
    for (k, v) in env {
        sub.env(k, v);
        orch.env(k, v);
    }
    let mut sub = spawn(&mut sub);
    sub.wait_for_output("subscribed", integration_tests::deadline::SHORT);
    let mut orch = spawn(&mut orch);
    let received = sub.finish(DEADLINE);
    assert!(
        received.status.success(),
        "ros2_live.py {backend}: {}",
        describe(&received)
    );
    support::signal(orch.id(), libc::SIGINT);
    let o = orch.finish(DEADLINE);
    support::assert_exit(&o, 3, "launch --ros2 after SIGINT");
    let mut c = Command::new(venv_python());
    c.arg(python_script("ros2_live.py"))
        .args(["check".as_ref(), got.as_os_str(), run_dir.as_os_str()])
        .env("PYTHONDONTWRITEBYTECODE", "1");
    let checked = run(&mut c, DEADLINE);
    assert!(checked.status.success(), "{}", describe(&checked));
}

/// DDS on loopback: rmw_fastrtps and RustDDS both discover by unicast to localhost with
/// `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` (no multicast, nothing leaves the machine).
#[test]
fn launch_ros2_dds_is_received_by_rclpy_equal_to_telemetry() {
    let env = [
        ("ROS_DOMAIN_ID", ros_domain(0)),
        ("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST".to_owned()),
    ];
    live("dds", &[], &env);
}

/// zenoh: the subscriber listens where rmw_zenohd would, and the launch's session connects to
/// it through rmw_zenoh's `ZENOH_SESSION_CONFIG_URI`.
#[test]
fn launch_ros2_zenoh_is_received_on_rmw_zenohs_key_expression() {
    let tmp = TempDir::new();
    let endpoint = format!("tcp/127.0.0.1:{}", free_tcp_port());
    let config = tmp.path().join("zenoh.json5");
    let text = format!(
        "{{ mode: \"peer\", connect: {{ endpoints: [\"{endpoint}\"] }}, listen: {{ endpoints: [] }}, scouting: {{ multicast: {{ enabled: false }} }} }}"
    );
    std::fs::write(&config, text).unwrap();
    let env = [
        ("ROS_DOMAIN_ID", ros_domain(1)),
        ("ZENOH_SESSION_CONFIG_URI", config.display().to_string()),
    ];
    live("zenoh", &[&endpoint], &env);
}

/// A bad `--ros2`, `--ros2-hz` or ROS 2 environment is refused before the team exists (exit 2,
/// naming it).
#[test]
fn bad_ros2_settings_exit_2_naming_them() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let refuse = |args: &[&str], env: &[(&str, &str)], names: &str| {
        let mut c = launch(&unique_team("ros2bad"), &out, &[&TEAM[..], args].concat());
        c.envs(env.iter().copied());
        refused(&run(&mut c, DEADLINE), names);
        assert!(
            !out.exists(),
            "{} written by a refused launch",
            out.display()
        );
    };
    refuse(&["--ros2", "ros1"], &[], "ros1");
    refuse(&["--ros2-hz", "10"], &[], "--ros2-hz needs --ros2");
    refuse(&["--ros2", "dds", "--ros2-hz", "0"], &[], "--ros2-hz");
    refuse(
        &["--ros2", "dds"],
        &[("ROS_DOMAIN_ID", "999")],
        "ROS_DOMAIN_ID",
    );
    let missing = tmp.path().join("no-such-zenoh.json5");
    let uri = missing.to_str().unwrap();
    refuse(
        &["--ros2", "zenoh"],
        &[("ZENOH_SESSION_CONFIG_URI", uri)],
        uri,
    );
}
