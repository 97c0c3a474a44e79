//! The MAVLink vehicle link against an independent implementation: the
//! `follow_setpoints` example of `cdm-mavlink` (one member: binds `H:(P + i)`, streams a
//! straight-line plan at comm_hz, reads the measured state) talks over loopback UDP to
//! `tests/python/mavlink_vehicle.py`, a point-mass vehicle built on pymavlink. Real sockets,
//! loopback only; every process runs under a watchdog deadline.

use std::path::PathBuf;
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{describe, example, spawn, venv_python};
use serde_json::Value;

/// Generous: the machine is shared and the plan itself takes about 4 s (3 s motion, the
/// example's default 1 s hold).
const DEADLINE: Duration = integration_tests::deadline::SHORT;
const COMM_HZ: f64 = 50.0;
/// The member under test: agent 7, the 4th member in scenario order (listens on base + 3).
const AGENT: u32 = 7;
const INDEX: u16 = 3;
/// The vehicle's NED origin sits at (10, 20, 0) in the scenario; the line runs from 2 m above
/// it to (12, 21, 3): in the vehicle's NED frame that is (0, 0, -2) -> (1, 2, -3).
const ORIGIN: &str = "10,20,0";
const FROM: &str = "10,20,2";
const TO: &str = "12,21,3";
const START_NED: &str = "0,0,-2";
const GOAL_NED: [f64; 3] = [1.0, 2.0, -3.0];

fn vehicle_script() -> PathBuf {
    integration_tests::python_script("mavlink_vehicle.py")
}

/// A UDP port that was free a moment ago, at least `INDEX`, below the ephemeral range.
fn free_port() -> u16 {
    let port = integration_tests::free_udp_ports(1);
    assert!(port >= INDEX, "port {port} too small");
    port
}

fn member(port: u16, extra: &[&str]) -> Command {
    let mut c = Command::new(example("cdm-mavlink", "follow_setpoints"));
    c.args(["--agent", &AGENT.to_string(), "--index", &INDEX.to_string()])
        .args(["--mavlink-base-port", &(port - INDEX).to_string()])
        .args(["--vehicle-origin", ORIGIN, "--from", FROM, "--to", TO])
        .args(["--move-s", "3", "--comm-hz", &COMM_HZ.to_string()])
        .args(extra);
    c
}

fn vehicle(port: u16, extra: &[&str]) -> Command {
    let mut c = Command::new(venv_python());
    c.arg(vehicle_script())
        .args(["--port", &port.to_string(), "--start-ned", START_NED])
        .args(["--max-s", "40"])
        .args(extra);
    c
}

/// Start the member, wait until it listens, run the vehicle beside it; both outputs.
fn fly(member_args: &[&str], vehicle_args: &[&str]) -> (Output, Output) {
    let port = free_port();
    // Python and pymavlink may take seconds to start on a loaded machine: wait long for them.
    let mut args = vec!["--connect-timeout-s", "30"];
    args.extend_from_slice(member_args);
    let mut m = spawn(&mut member(port, &args));
    m.wait_for_output("listening on", DEADLINE);
    let v = spawn(&mut vehicle(port, vehicle_args));
    let m_out = m.finish(DEADLINE);
    let v_out = v.finish(DEADLINE);
    (m_out, v_out)
}

fn json(out: &Output, who: &str) -> Value {
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().last().unwrap_or_default();
    serde_json::from_str(line)
        .unwrap_or_else(|e| panic!("{who} printed no JSON summary ({e}):\n{}", describe(out)))
}

fn f(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("`{key}` is not a number in {v}"))
}

fn vec3(v: &Value, key: &str) -> [f64; 3] {
    let a = v[key]
        .as_array()
        .unwrap_or_else(|| panic!("`{key}` is not an array in {v}"));
    assert_eq!(a.len(), 3, "`{key}` in {v}");
    [0, 1, 2].map(|k| a[k].as_f64().unwrap_or_else(|| panic!("`{key}` in {v}")))
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

/// What every healthy flight must show on the vehicle's side.
fn assert_clean_link(v: &Value, m: &Value) {
    // pymavlink decoded everything with a valid checksum, as MAVLink 2, addressed to it.
    assert_eq!(f(v, "bad_data"), 0.0, "checksum failures: {v}");
    assert_eq!(f(v, "receive_errors"), 0.0, "{v}");
    assert_eq!(f(v, "not_mavlink2"), 0.0, "{v}");
    assert_eq!(f(v, "wrong_target"), 0.0, "{v}");
    assert_eq!(v["type_masks"], serde_json::json!([3072]), "{v}");
    assert_eq!(
        v["frames"],
        serde_json::json!([1]),
        "MAV_FRAME_LOCAL_NED: {v}"
    );
    // Loopback loses nothing: every setpoint the member sent arrived.
    assert_eq!(
        f(v, "setpoints_received"),
        f(m, "setpoints_sent"),
        "{v}\n{m}"
    );
    // At comm_hz within 10 %, on the sender's stamps (the vehicle's own arrival times are
    // printed too; on a loaded machine they jitter with this process's scheduling).
    let rate = f(v, "setpoint_rate_by_stamp_hz");
    assert!(
        (rate - COMM_HZ).abs() <= 0.1 * COMM_HZ,
        "setpoints at {rate:.2} Hz, not {COMM_HZ} Hz +- 10 %: {v}"
    );
    // The member read the vehicle's three streams and talked back with HEARTBEATs.
    for key in [
        "heartbeats_received",
        "positions_received",
        "attitudes_received",
    ] {
        assert!(f(m, key) > 0.0, "member received no {key}: {m}");
    }
    assert!(v["messages"]["HEARTBEAT"].as_u64().unwrap_or(0) >= 3, "{v}");
}

#[test]
fn a_vehicle_follows_a_straight_line_to_its_goal() {
    let (m_out, v_out) = fly(&[], &[]);
    assert_eq!(m_out.status.code(), Some(0), "{}", describe(&m_out));
    assert_eq!(v_out.status.code(), Some(0), "{}", describe(&v_out));
    let (m, v) = (json(&m_out, "member"), json(&v_out, "vehicle"));
    eprintln!("member: {m}\nvehicle: {v}");
    assert_clean_link(&v, &m);
    // The vehicle ends at the goal in its own NED frame (origin subtracted, axes swapped) ...
    let end_ned = vec3(&v, "final_position_ned");
    assert!(
        dist(end_ned, GOAL_NED) < 0.5,
        "vehicle ended at {end_ned:?}, goal {GOAL_NED:?}"
    );
    assert!(dist(vec3(&v, "last_setpoint_ned"), GOAL_NED) < 1e-6, "{v}");
    // ... and the member, converting its measured state back, sees it at the scenario goal.
    assert!(f(&m, "final_error_m") < 0.5, "{m}");
    assert_eq!(m["arm_stage"], "StreamOnly", "no --arm: no commands: {m}");
    assert_eq!(v["commands"], serde_json::json!([]), "{v}");
}

#[test]
fn arm_switches_px4_to_offboard_and_arms_it() {
    // This vehicle moves only when armed in OFFBOARD and refuses OFFBOARD without a stream.
    let (m_out, v_out) = fly(&["--arm", "--hold-s", "2"], &["--require-arm"]);
    assert_eq!(m_out.status.code(), Some(0), "{}", describe(&m_out));
    let (m, v) = (json(&m_out, "member"), json(&v_out, "vehicle"));
    assert_eq!(m["arm_stage"], "Armed", "{m}");
    assert_eq!(v["armed"], true, "{v}");
    let commands = v["commands"].as_array().expect("commands");
    let first = &commands[0];
    assert_eq!(first["command"], 176, "MAV_CMD_DO_SET_MODE first: {v}");
    assert_eq!(first["param2"], 6.0, "PX4 main mode OFFBOARD: {v}");
    assert!(
        commands
            .iter()
            .any(|c| c["command"] == 400 && c["param1"] == 1.0 && c["result"] == 0),
        "an accepted MAV_CMD_COMPONENT_ARM_DISARM: {v}"
    );
    assert!(dist(vec3(&v, "final_position_ned"), GOAL_NED) < 0.5, "{v}");
}

/// The member's stderr when its vehicle went quiet: it failed with exit 3 naming agent 7 and
/// the limit (`limit`, e.g. "limit 3 s, --heartbeat-timeout").
fn assert_named_loss(m_out: &Output, v: &Value, what: &str, limit: &str) {
    let stderr = String::from_utf8_lossy(&m_out.stderr);
    assert_eq!(m_out.status.code(), Some(3), "{}", describe(m_out));
    assert!(
        stderr.contains(&format!("agent {AGENT}: vehicle lost: no {what} for")),
        "the loss of {what} is not named:\n{}",
        describe(m_out)
    );
    assert!(
        stderr.contains(&format!("({limit})")),
        "{}",
        describe(m_out)
    );
    assert!(v["went_silent_at_s"].is_number(), "{v}");
    assert!(
        m_out.stdout.is_empty(),
        "no summary after a fault: {}",
        describe(m_out)
    );
}

#[test]
fn a_vehicle_that_stops_sending_positions_is_named() {
    let (m_out, v_out) = fly(&[], &["--silent-after", "1.0", "--mute", "all"]);
    // Positions stop with everything else; their 0.5 s limit is reached first.
    let limit = "limit 0.5 s, --position-timeout";
    assert_named_loss(
        &m_out,
        &json(&v_out, "vehicle"),
        "LOCAL_POSITION_NED",
        limit,
    );
}

#[test]
fn a_vehicle_whose_heartbeat_stops_is_named() {
    // The vehicle's last HEARTBEAT leaves before 1 s; the member names the loss 3 s later
    // (--heartbeat-timeout's default), so it must still be flying then: a 10 s hold.
    let (m_out, v_out) = fly(
        &["--hold-s", "10"],
        &["--silent-after", "1.0", "--mute", "heartbeat"],
    );
    let limit = "limit 3 s, --heartbeat-timeout";
    assert_named_loss(&m_out, &json(&v_out, "vehicle"), "HEARTBEAT", limit);
}

#[test]
fn the_link_timeouts_are_the_members_options() {
    // A shorter heartbeat limit is honoured (and named) ...
    let (m_out, v_out) = fly(
        &["--hold-s", "10", "--heartbeat-timeout", "1.5"],
        &["--silent-after", "1.0", "--mute", "heartbeat"],
    );
    let limit = "limit 1.5 s, --heartbeat-timeout";
    assert_named_loss(&m_out, &json(&v_out, "vehicle"), "HEARTBEAT", limit);
    // ... and a 2 Hz position stream, lost under the default 0.5 s, flies with a limit of
    // four of its periods.
    let (m_out, v_out) = fly(&["--position-timeout", "2"], &["--position-hz", "2"]);
    assert_eq!(m_out.status.code(), Some(0), "{}", describe(&m_out));
    let v = json(&v_out, "vehicle");
    assert!(dist(vec3(&v, "final_position_ned"), GOAL_NED) < 0.5, "{v}");
}

#[test]
fn no_vehicle_and_bad_ports_are_clear_errors() {
    let port = free_port();
    let mut alone = member(port, &["--connect-timeout-s", "1"]);
    let out = integration_tests::run(&mut alone, DEADLINE);
    assert_eq!(out.status.code(), Some(3), "{}", describe(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("agent 7: no vehicle heard within 1.0 s"),
        "{}",
        describe(&out)
    );
    let mut overflow = Command::new(example("cdm-mavlink", "follow_setpoints"));
    overflow.args([
        "--agent",
        "7",
        "--index",
        "3",
        "--mavlink-base-port",
        "65535",
    ]);
    overflow.args(["--from", FROM, "--to", TO]);
    let out = integration_tests::run(&mut overflow, DEADLINE);
    assert_eq!(out.status.code(), Some(2), "{}", describe(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr)
            .contains("agent 7: --mavlink-base-port 65535 + member index 3 exceeds 65535"),
        "{}",
        describe(&out)
    );
}
