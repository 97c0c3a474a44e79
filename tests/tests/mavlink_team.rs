//! A team flies MAVLink vehicles (issue 13): `orchestrator launch --vehicles mavlink` spawns ten
//! members, each drives one `tests/python/mavlink_vehicle.py` (a pymavlink point mass, an
//! implementation nobody here wrote) over loopback UDP on `P + i`, publishes the vehicle's
//! measured state, and the orchestrator audits it. Real processes and sockets; every process
//! runs under a watchdog deadline; a team name of its own.

mod support;

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

use common::scenario::{Checks, Scenario, ScenarioFile};
use integration_tests::{
    describe, spawn, unique_team, venv_python, write_scenario, Running, TempDir,
};
use serde_json::Value;
use support::{assert_no_team_resources, launch, read_json};

const N: usize = 10;
const COMM_HZ: f64 = 50.0;
/// Generous: the machine is shared, and ten Python processes start beside ten members.
const DEADLINE: Duration = Duration::from_secs(120);
/// The vehicles' NED origin in the scenario (ENU): every vehicle's frame is shifted by it.
const ORIGIN: [f64; 3] = [5.0, -3.0, 0.0];

/// Ten agents (the generated team of the paper's kind) flying a `t_total_s` translation of
/// (1.5, 1, 0.5) m at 50 Hz.
fn team(t_total_s: f64) -> ScenarioFile {
    let mut f = common::scenario::generated(N).expect("ten agents generate");
    f.name = "mavlink10".into();
    f.t_total_s = t_total_s;
    f.comm_hz = COMM_HZ;
    for a in &mut f.agents {
        if a.goal.is_some() {
            let p = a.position;
            a.goal = Some([p[0] + 1.5, p[1] + 1.0, p[2] + 0.5]);
        }
    }
    f
}

/// A base port with `N` free UDP ports above it (the kernel's pick, checked by binding all).
fn free_base_port() -> u16 {
    for _ in 0..50 {
        let probe = UdpSocket::bind("127.0.0.1:0").expect("bind an ephemeral UDP port");
        let base = probe.local_addr().expect("local address").port();
        drop(probe);
        let Some(last) = base.checked_add(N as u16) else {
            continue;
        };
        let held: Vec<_> = (base..last)
            .map_while(|p| UdpSocket::bind(("127.0.0.1", p)).ok())
            .collect();
        if held.len() == N {
            return base;
        }
    }
    panic!("no {N} consecutive free UDP ports found");
}

fn vehicle_script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("python/mavlink_vehicle.py")
}

/// ENU scenario point -> the vehicle's NED (origin subtracted; north = y, east = x, down = -z).
fn to_ned(p: [f64; 3]) -> [f64; 3] {
    [p[1] - ORIGIN[1], p[0] - ORIGIN[0], -(p[2] - ORIGIN[2])]
}

fn csv(p: [f64; 3]) -> String {
    format!("{},{},{}", p[0], p[1], p[2])
}

/// One vehicle per member, in scenario order (member i on `base + i`), each starting where its
/// member starts; `silent` = (index, seconds) makes one vehicle stop sending; `extra` goes to
/// every vehicle.
fn start_vehicles(
    s: &ScenarioFile,
    base: u16,
    silent: Option<(usize, f64)>,
    extra: &[&str],
) -> Vec<Running> {
    let mut vehicles: Vec<Running> = s
        .agents
        .iter()
        .enumerate()
        .map(|(i, a)| {
            let mut c = std::process::Command::new(venv_python());
            c.arg(vehicle_script())
                .args(["--port", &(base + i as u16).to_string()])
                .args(["--sysid", &(i + 1).to_string()])
                .arg(format!("--start-ned={}", csv(to_ned(a.position))))
                .args(["--max-s", "100"])
                .args(extra);
            if let Some((_, after)) = silent.filter(|(k, _)| *k == i) {
                c.args(["--silent-after", &format!("{after}"), "--mute", "position"]);
            }
            spawn(&mut c)
        })
        .collect();
    for v in &mut vehicles {
        v.wait_for_output("sending to", DEADLINE);
    }
    vehicles
}

fn launch_team(dir: &Path, team: &str, scenario: &Path, base: u16, extra: &[&str]) -> Running {
    let path = scenario.to_str().expect("utf-8 path");
    let mut c = launch(team, &dir.join("run"), &["--scenario", path]);
    c.args(["--realtime", "--vehicles", "mavlink"])
        .args(["--mavlink-base-port", &base.to_string()])
        .args(["--vehicle-origin", &csv(ORIGIN)])
        .args(extra);
    spawn(&mut c)
}

fn summary(out: &Output, who: &str) -> Value {
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().last().unwrap_or_default();
    serde_json::from_str(line)
        .unwrap_or_else(|e| panic!("{who} printed no JSON summary ({e}):\n{}", describe(out)))
}

fn num(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("`{key}` is not a number in {v}"))
}

/// Where each member must end: r_HT(T_total) (eqs. 13, 23), in member order.
fn goals(file: &ScenarioFile) -> Vec<[f64; 3]> {
    let s = Scenario::from_file(file.clone(), "mavlink10", Checks::Full).expect("valid");
    let mut out = Vec::new();
    s.desired_positions(s.file.t_total_s, &mut out);
    out.iter().map(|p| [p.x, p.y, p.z]).collect()
}

#[test]
fn ten_members_arm_and_fly_ten_mavlink_vehicles_to_their_goals() {
    let dir = TempDir::new();
    let file = team(3.0);
    let scenario = write_scenario(dir.path(), "mavlink10.toml", &file);
    let base = free_base_port();
    let team_name = unique_team("mav10");
    // Vehicles that move only in OFFBOARD and armed, and refuse OFFBOARD without a setpoint
    // stream (like PX4): the members stream, switch and arm them before the team starts.
    let vehicles = start_vehicles(&file, base, None, &["--require-arm"]);
    let orch = launch_team(dir.path(), &team_name, &scenario, base, &["--arm"]);
    let o = orch.finish(DEADLINE);
    // (A failed launch drops, so kills, the vehicles.)
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let outs: Vec<Output> = vehicles.into_iter().map(|v| v.finish(DEADLINE)).collect();
    let audit = read_json(&dir.path().join("run/audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    for (i, (out, goal)) in outs.iter().zip(goals(&file)).enumerate() {
        assert_eq!(out.status.code(), Some(0), "vehicle {i}: {}", describe(out));
        let v = summary(out, &format!("vehicle {i}"));
        // pymavlink decoded everything with a valid checksum, as MAVLink 2, addressed to it.
        for key in ["bad_data", "receive_errors", "not_mavlink2", "wrong_target"] {
            assert_eq!(num(&v, key), 0.0, "vehicle {i} {key}: {v}");
        }
        assert_eq!(v["type_masks"], serde_json::json!([3072]), "{v}");
        assert_eq!(v["armed"], true, "vehicle {i} was not armed: {v}");
        // Setpoints at comm_hz within 10 %, on the member's stamps (the vehicle's own arrival
        // times jitter with this machine's load).
        let rate = num(&v, "setpoint_rate_by_stamp_hz");
        assert!(
            (rate - COMM_HZ).abs() <= 0.1 * COMM_HZ,
            "vehicle {i}: setpoints at {rate:.2} Hz, not {COMM_HZ} Hz +- 10 %: {v}"
        );
        let end = v["final_position_ned"]
            .as_array()
            .unwrap_or_else(|| panic!("{v}"))
            .iter()
            .map(|x| x.as_f64().unwrap_or(f64::NAN))
            .collect::<Vec<_>>();
        let want = to_ned(goal);
        let err = (0..3)
            .map(|k| (end[k] - want[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(
            err < 0.5,
            "vehicle {i} ended at {end:?} (NED), goal {want:?}: {err:.3} m off"
        );
    }
    assert_no_team_resources(&team_name);
}

#[test]
fn a_vehicle_that_stops_sending_is_named() {
    let dir = TempDir::new();
    // Long enough that the vehicle goes silent mid-flight even on a loaded machine.
    let file = team(20.0);
    let scenario = write_scenario(dir.path(), "mavlink10.toml", &file);
    let base = free_base_port();
    let team_name = unique_team("mav10lost");
    const SILENT: usize = 6;
    let silent_id = file.agents[SILENT].id;
    let vehicles = start_vehicles(&file, base, Some((SILENT, 8.0)), &[]);
    let orch = launch_team(dir.path(), &team_name, &scenario, base, &[]);
    let o = orch.finish(DEADLINE);
    assert_eq!(o.status.code(), Some(3), "{}", describe(&o));
    for v in vehicles {
        v.finish(DEADLINE);
    }
    let audit = read_json(&dir.path().join("run/audit.json"));
    assert_eq!(audit["verdict"], "FAULT", "{audit:#}");
    let fault = &audit["fault"];
    assert_eq!(fault["kind"], "vehicle-lost", "{audit:#}");
    assert_eq!(fault["agent"], silent_id, "{audit:#}");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains(&format!(
            "agent {silent_id}: vehicle lost: no LOCAL_POSITION_NED"
        )),
        "{}",
        describe(&o)
    );
    assert_no_team_resources(&team_name);
}

#[test]
fn bad_vehicle_options_exit_2_naming_them() {
    let dir = TempDir::new();
    let file = team(3.0);
    let scenario = write_scenario(dir.path(), "mavlink10.toml", &file);
    let path = scenario.to_str().expect("utf-8 path");
    let cases: [(&[&str], &str); 4] = [
        (&["--arm"], "need --vehicles mavlink"),
        (
            &["--vehicles", "mavlink"],
            "--vehicles mavlink needs --realtime",
        ),
        (
            &[
                "--realtime",
                "--vehicles",
                "mavlink",
                "--vehicle-origin",
                "1,x,3",
            ],
            "--vehicle-origin \"1,x,3\"",
        ),
        (
            &["--vehicles", "mavlink", "--mavlink-host", "nowhere"],
            "--mavlink-host",
        ),
    ];
    for (args, needle) in cases {
        let team_name = unique_team("mavbad");
        let out = integration_tests::run(
            launch(&team_name, &dir.path().join("run"), &["--scenario", path]).args(args),
            DEADLINE,
        );
        support::assert_exit(&out, 2, needle);
        support::assert_stderr_has(&out, needle, &[needle]);
    }
    // A hand-started member whose port P + i does not exist (member index 9 above 65535).
    let last = file.agents.last().expect("ten agents");
    let mut agent = support::member("agent", &scenario, &unique_team("mavbad"), last.id);
    agent.args([
        "--realtime",
        "--vehicles",
        "mavlink",
        "--mavlink-base-port",
        "65530",
    ]);
    let out = integration_tests::run(&mut agent, DEADLINE);
    support::assert_exit(&out, 2, "port out of range");
    let needle = format!(
        "agent {}: --mavlink-base-port 65530 + member index 9",
        last.id
    );
    support::assert_stderr_has(&out, "port out of range", &[&needle]);
}
