//! What a red-team pass broke with inputs a user or an attacker controls, with the real binaries:
//! each is refused with exit 2 and a message naming the flag, file, field or line at fault,
//! never a panic, a hang, an endless read or a silently ignored value.
//!
//! - `--ros2-hz` outside its documented range (it panicked on a tiny rate);
//! - a zenoh session configuration (`ZENOH_SESSION_CONFIG_URI`) that never ends (/dev/zero),
//!   blocks (a FIFO) or is too large; a stop signal ends a launch waiting for its zenoh session;
//! - heights and durations of a mission far beyond any flight (`plan` ran for ever), and a huge
//!   segment time named by its field, without a 300-digit number;
//! - polygon vertices numbered from 1 in every message;
//! - NaN or infinity in a finished run's telemetry.csv, read by `report`, `view` and
//!   `export rosbag2`;
//! - a `--lose` after the last flown tick (`--max-ticks`), in `simulate`, lockstep `launch` and
//!   real time.

use integration_tests::support;

use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use cdm_scenario::{GroundSpec, ScenarioFile};
use integration_tests::{
    bin, describe, fenced_paper40, launch, run, simulate, spawn, unique_team, write_scenario,
    TempDir,
};
use support::{assert_exit, assert_no_team_resources, assert_stderr_has, mission};

/// Every refusal here comes before any flight; the deadline only stops a hang.
const DEADLINE: Duration = integration_tests::deadline::REFUSE;
/// A short flight of a small team, and a plan of the ten-member mission.
const FLIGHT: Duration = integration_tests::deadline::FLIGHT;

fn orchestrator(args: &[&str]) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    c
}

/// Asserts exit 2, every needle in stderr, and no panic.
fn refused(o: &Output, what: &str, needles: &[&str]) {
    assert!(
        !String::from_utf8_lossy(&o.stderr).contains("panicked"),
        "{what} panicked\n{}",
        describe(o)
    );
    assert_exit(o, 2, what);
    assert_stderr_has(o, what, needles);
}

fn path_str(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

// ---- ROS 2 --------------------------------------------------------------------------------

/// `--ros2-hz` below 0.01 or above 1000 (with either middleware) is refused naming the range;
/// before the fix 1e-20, 1e-19 and 5e-324 panicked ("cannot convert float seconds to
/// Duration", exit 101).
#[test]
fn ros2_hz_outside_its_range_is_refused() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    for (middleware, hz) in [
        ("dds", "1e-20"),
        ("dds", "5e-324"),
        ("zenoh", "1e-19"),
        ("dds", "0.001"),
        ("zenoh", "1001"),
        ("dds", "-1"),
    ] {
        let team = unique_team("ros2hz");
        let o = run(
            launch(&team, &out, &["--n", "4", "--no-figures"]).args([
                "--ros2",
                middleware,
                "--ros2-hz",
                hz,
            ]),
            DEADLINE,
        );
        let what = format!("--ros2 {middleware} --ros2-hz {hz}");
        refused(&o, &what, &["--ros2-hz must be in [0.01, 1000], got "]);
        assert!(!out.exists(), "{what}: a refused launch wrote its run");
        assert_no_team_resources(&team);
    }
}

/// `launch --n 4 --ros2 zenoh` with `ZENOH_SESSION_CONFIG_URI` set to `path`.
fn zenoh_launch(out: &Path, config: &Path) -> Command {
    let mut c = launch(&unique_team("zcfg"), out, &["--n", "4", "--no-figures"]);
    c.args(["--ros2", "zenoh"])
        .env("ZENOH_SESSION_CONFIG_URI", config);
    c
}

/// A session configuration that is /dev/zero, a FIFO nobody writes or a file larger than
/// 1 MiB is refused at once, naming the file. Before the fix /dev/zero was read until the
/// kernel's OOM killer (the launch runs here with 4 GiB of address space, so that it fails
/// fast instead) and the FIFO blocked the launch for good, deaf to SIGTERM and SIGINT.
#[test]
fn zenoh_configurations_that_never_end_or_block_are_refused() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let zero = Path::new("/dev/zero");
    let c = zenoh_launch(&out, zero);
    let mut capped = Command::new("sh");
    capped
        .args(["-c", "ulimit -v 4194304 && exec \"$@\"", "sh"])
        .arg(c.get_program())
        .args(c.get_args())
        .envs(c.get_envs().filter_map(|(k, v)| Some((k, v?))));
    let o = run(&mut capped, DEADLINE);
    refused(&o, "/dev/zero", &["/dev/zero", "not a regular file"]);
    let fifo = tmp.path().join("zenoh.json5");
    let c_path = std::ffi::CString::new(path_str(&fifo)).expect("path");
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c_path.as_ptr(), 0o600) }, 0, "mkfifo");
    let o = run(&mut zenoh_launch(&out, &fifo), DEADLINE);
    refused(
        &o,
        "a FIFO",
        &[path_str(&fifo), "a FIFO, not a regular file"],
    );
    let big = tmp.path().join("big.json5");
    let mut text = String::from("{\n");
    while text.len() <= 1 << 20 {
        text.push_str("  // padding padding padding padding padding padding padding\n");
    }
    text.push_str("}\n");
    std::fs::write(&big, text).expect("write");
    let o = run(&mut zenoh_launch(&out, &big), DEADLINE);
    refused(&o, "a 1 MiB file", &[path_str(&big), "larger than 1 MiB"]);
    assert!(!out.exists(), "a refused launch wrote its run");
}

/// A zenoh session that waits for ever to open (a client whose router never answers, with no
/// timeout) stops on SIGTERM like every other wait of a launch. Before the fix the launch
/// caught the signal for its flight loop, which had not started, and kept waiting.
#[test]
fn a_stop_signal_ends_a_launch_waiting_for_its_zenoh_session() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let port = integration_tests::free_udp_ports(1);
    let config = tmp.path().join("client.json5");
    std::fs::write(
        &config,
        format!(
            "{{ mode: \"client\", connect: {{ endpoints: [\"tcp/127.0.0.1:{port}\"], timeout_ms: -1, exit_on_failure: true }}, scouting: {{ multicast: {{ enabled: false }} }} }}\n"
        ),
    )
    .expect("write");
    let mut waiting = spawn(&mut zenoh_launch(&out, &config));
    let pid = waiting.id();
    // The zenoh runtime's threads: the session is opening.
    let until = Instant::now() + DEADLINE;
    let threads = || std::fs::read_dir(format!("/proc/{pid}/task")).map_or(0, |d| d.count());
    while threads() < 3 && !waiting.has_exited() {
        assert!(
            Instant::now() < until,
            "the launch started no zenoh session"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(!waiting.has_exited(), "{}", describe(&waiting.kill()));
    support::signal(pid, libc::SIGTERM);
    let o = waiting.finish(DEADLINE);
    assert_ne!(o.status.code(), Some(0), "{}", describe(&o));
    assert!(!out.exists(), "an interrupted preflight wrote its run");
}

// ---- scenarios ----------------------------------------------------------------------------

/// `plan --scenario` of `f`.
fn plan(tmp: &Path, name: &str, f: &ScenarioFile) -> Output {
    let path = write_scenario(tmp, name, f);
    run(
        &mut orchestrator(&["plan", "--scenario", path_str(&path)]),
        FLIGHT,
    )
}

/// Heights and durations beyond any flight are refused naming the field and the limit, and a
/// huge time is written in scientific notation. Before the fix `[takeoff] ground_z_m = -1e12`
/// kept `plan` busy for ever (its certificate's cost grew with the distance), and `t_s = 1e300`
/// named the field `segment` with a 300-digit number of ticks.
#[test]
fn heights_and_durations_beyond_any_flight_are_refused_naming_the_field() {
    let tmp = TempDir::new();
    type Break = fn(&mut ScenarioFile);
    let cases: [(&str, Break, &[&str]); 8] = [
        (
            "ground",
            |f| f.takeoff.as_mut().expect("takeoff").ground_z_m = -1e12,
            &["takeoff.ground_z_m", "1e6 m from the origin"],
        ),
        (
            "landing",
            |f| f.landing.as_mut().expect("landing").ground_z_m = -1e7,
            &["landing.ground_z_m", "1e6 m from the origin"],
        ),
        (
            "goal",
            |f| f.segments[0].goals[0][2] = 1e12,
            &["segment 2.goals[0][2]", "1e6 m from the origin"],
        ),
        (
            "position",
            |f| f.agents[0].position[0] = -2e6,
            &["position[0]", "1e6 m from the origin"],
        ),
        (
            "segment-time",
            |f| f.segments[0].t_s = 1e300,
            &["segment 2.t_s", "at most 1e8"],
        ),
        (
            "segment-hold",
            |f| f.segments[1].hold_s = Some(1e12),
            &["segment 3.hold_s", "at most 1e8"],
        ),
        (
            "takeoff-time",
            |f| {
                f.takeoff = Some(GroundSpec {
                    ground_z_m: 0.0,
                    t_s: 1e12,
                    hold_s: None,
                })
            },
            &["takeoff.t_s", "at most 1e8"],
        ),
        (
            "total",
            |f| f.t_total_s = 1e300,
            &["t_total_s", "at most 1e8"],
        ),
    ];
    for (name, break_it, needles) in cases {
        let mut f = mission();
        break_it(&mut f);
        let o = plan(tmp.path(), &format!("{name}.toml"), &f);
        refused(&o, name, needles);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !err.contains("0000000000"),
            "{name}: a number of 10 digits or more\n{}",
            describe(&o)
        );
    }
}

/// A fence polygon's vertices are numbered from 1 in every message, as its edges are: a
/// repeated 3rd vertex is "vertices 2 and 3", a closing vertex that repeats the first is
/// "vertices 5 and 1", a NaN 3rd vertex is "vertex 3". Before the fix these said "vertices 1 and
/// 2", "vertices 4 and 0" and `polygon[2][0]`.
#[test]
fn polygon_vertices_are_numbered_from_1() {
    let tmp = TempDir::new();
    let square = [
        [-400.0, -300.0],
        [600.0, -300.0],
        [600.0, 700.0],
        [-400.0, 700.0],
    ];
    let cases: [(Vec<[f64; 2]>, &str); 3] = [
        (
            vec![square[0], square[1], square[1], square[2], square[3]],
            "`polygon` vertices 2 and 3 are the same point (edge 2 has no length",
        ),
        (
            vec![square[0], square[1], square[2], square[3], square[0]],
            "`polygon` vertices 5 and 1 are the same point (edge 5 has no length",
        ),
        (
            vec![square[0], square[1], [f64::NAN, 700.0], square[3]],
            "`polygon` vertex 3 `x` must be a finite number",
        ),
    ];
    for (k, (polygon, says)) in cases.into_iter().enumerate() {
        let mut f = fenced_paper40();
        f.geofence.as_mut().expect("fence").polygon = polygon;
        let o = plan(tmp.path(), &format!("fence{k}.toml"), &f);
        refused(&o, says, &["geofence", says]);
    }
}

// ---- telemetry ----------------------------------------------------------------------------

/// A NaN or an infinity put in a finished run's telemetry.csv is refused by every reader, naming
/// the file and the line, as text is. Before the fix `report`, `view` and `export rosbag2`
/// exited 0 and the bag carried x = NaN.
#[test]
fn nan_or_infinity_in_a_runs_telemetry_is_refused_by_its_readers() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let o = run(
        &mut simulate(&out, &["--n", "4", "--max-ticks", "3", "--no-figures"]),
        FLIGHT,
    );
    assert_exit(&o, 0, "simulate");
    let tel = out.join("telemetry.csv");
    let text = std::fs::read_to_string(&tel).expect("telemetry.csv");
    for bad in ["NaN", "inf", "-inf"] {
        // Line 3 (the second row): its x.
        let changed: Vec<String> = text
            .lines()
            .enumerate()
            .map(|(k, l)| {
                if k != 2 {
                    return l.to_owned();
                }
                let mut f: Vec<&str> = l.split(',').collect();
                f[4] = bad;
                f.join(",")
            })
            .collect();
        std::fs::write(&tel, changed.join("\n") + "\n").expect("write");
        let bag = tmp.path().join(format!("bag-{bad}"));
        let readers: [(&str, Vec<&str>); 3] = [
            ("report", vec!["report", path_str(&out)]),
            ("view", vec!["view", path_str(&out)]),
            (
                "export rosbag2",
                vec!["export", "rosbag2", path_str(&out), "--out", path_str(&bag)],
            ),
        ];
        for (what, args) in readers {
            let o = run(&mut orchestrator(&args), FLIGHT);
            let what = format!("{what} with {bad}");
            refused(&o, &what, &["telemetry.csv", "line 3: not a finite number"]);
        }
        assert!(!bag.exists(), "a refused export left {}", bag.display());
    }
}

// ---- losses -------------------------------------------------------------------------------

/// `--lose` at a time after the last tick `--max-ticks` lets fly is refused naming that tick, in
/// `simulate`, lockstep `launch` and real time, before anything is written or started. Before
/// the fix the flight ended at tick 300 with no loss, exit 0.
#[test]
fn a_loss_after_the_last_flown_tick_is_refused() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let team_args = ["--n", "10", "--t-total", "30", "--max-ticks", "300"];
    let lose = ["--lose", "7@3.01", "--no-figures"];
    let says = ["--lose 7@3.01", "the flight's last tick is 300"];
    let o = run(
        &mut simulate(&out, &[&team_args[..], &lose].concat()),
        FLIGHT,
    );
    refused(&o, "simulate", &says);
    assert!(!out.exists(), "a refused simulate wrote its run");
    for realtime in [false, true] {
        let team = unique_team("loselate");
        let mut c = launch(&team, &out, &[&team_args[..], &lose].concat());
        if realtime {
            c.arg("--realtime");
        }
        let o = run(&mut c, FLIGHT);
        refused(&o, &format!("launch, real time {realtime}"), &says);
        assert!(!out.exists(), "a refused launch wrote its run");
        assert_no_team_resources(&team);
    }
    // Within the flown ticks the same loss flies.
    let o = run(
        &mut simulate(
            &out,
            &[&team_args[..], &["--lose", "7@2.5", "--no-figures"]].concat(),
        ),
        FLIGHT,
    );
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", describe(&o));
    let audit = support::read_json(&out.join("audit.json"));
    assert_eq!(audit["losses"][0]["id"], 7, "{audit}");
}
