//! A MAVLink team outdoors: a scenario with an `[origin]` (PX4's SITL home, +x 30 degrees east
//! of north) flown by `orchestrator launch --vehicles mavlink --arm` with no vehicle origin at
//! all. Each `tests/python/mavlink_vehicle.py` has GPS (`--home`: its local origin is its own
//! spawn point on the ground below its member, as in PX4's multi-vehicle SITL), beats at PX4's
//! 1 Hz, streams GLOBAL_POSITION_INT and flies SET_POSITION_TARGET_GLOBAL_INT through PX4's own
//! map projection. The members command latitude, longitude and altitude and read the GPS fix;
//! every vehicle ends at its goal's latitude and longitude (and altitude) within 0.5 m. A local
//! vehicle origin on such a scenario is refused (exit 2), naming the option.
//!
//! `--upload-fence`: with a `[geofence]` and two `[[obstacle]]`s, every vehicle holds the
//! uploaded fence (its fence side of the mission protocol, PX4's), read back and equal to the
//! scenario's polygon, the box's footprint and the cylinder's circle in latitude and longitude,
//! before it is armed; a vehicle that refuses the fence is named and no vehicle is armed.
//!
//! How to run: `cargo test --release -p integration-tests --test mavlink -- mavlink_global::`.

use integration_tests::support;

use std::process::Output;
use std::time::Duration;

use cdm_math::Vec3;
use cdm_model::airspace::Shape;
use cdm_scenario::{Checks, GeoOrigin, GeoPoint, ObstacleSpec, Scenario, ScenarioFile};
use integration_tests::{
    describe, free_udp_ports, python_script, run, spawn, unique_team, venv_python, write_scenario,
    Running, TempDir,
};
use serde_json::Value;
use support::{assert_no_team_resources, launch, read_json};

const N: usize = 4;
const DEADLINE: Duration = integration_tests::deadline::FLIGHT;

const ORIGIN: GeoOrigin = GeoOrigin {
    lat_deg: 47.397742,
    lon_deg: 8.545594,
    alt_m: 488.0,
    heading_deg: 30.0,
};

/// Four agents of the paper's kind translating by (1.5, 1, 0.5) m in 3 s at 50 Hz, anchored at
/// ORIGIN.
fn team() -> ScenarioFile {
    let mut f = cdm_scenario::generated(N).expect("four agents generate");
    f.name = "outdoors4".into();
    f.t_total_s = 3.0;
    f.comm_hz = 50.0;
    f.geo_origin = Some(ORIGIN);
    for a in &mut f.agents {
        if a.goal.is_some() {
            let p = a.position;
            a.goal = Some([p[0] + 1.5, p[1] + 1.0, p[2] + 0.5]);
        }
    }
    f
}

/// Vehicle i on port base + i, its home on the ground below its member's start (latitude,
/// longitude and altitude of scenario (x, y, 0)), starting at its member's height above it.
/// `extra(i)`: more options for vehicle i.
fn start_vehicles(
    s: &ScenarioFile,
    base: u16,
    extra: impl Fn(usize) -> Vec<String>,
) -> Vec<Running> {
    integration_tests::bin("orchestrator");
    let mut vehicles: Vec<Running> = (0..N)
        .map(|i| {
            let p = s.agents[i].position;
            let home = ORIGIN.geodetic(&Vec3::new(p[0], p[1], 0.0));
            let mut c = std::process::Command::new(venv_python());
            c.arg(python_script("mavlink_vehicle.py"))
                .args(["--port", &(base + i as u16).to_string()])
                .args(["--sysid", &(i + 1).to_string()])
                .arg(format!(
                    "--home={},{},{}",
                    home.lat_deg, home.lon_deg, home.alt_m
                ))
                .arg(format!("--start-ned=0,0,{}", -p[2]))
                .args(["--require-arm", "--heartbeat-hz", "1", "--max-s", "100"])
                .args(extra(i));
            spawn(&mut c)
        })
        .collect();
    for v in &mut vehicles {
        v.wait_for_output("sending to", DEADLINE);
    }
    vehicles
}

fn summary(out: &Output, who: &str) -> Value {
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().last().unwrap_or_default();
    serde_json::from_str(line)
        .unwrap_or_else(|e| panic!("{who} printed no JSON summary ({e}):\n{}", describe(out)))
}

#[test]
fn a_team_from_gps_coordinates_ends_at_its_goals_latitude_and_longitude() {
    let dir = TempDir::new();
    let file = team();
    let scenario = write_scenario(dir.path(), "outdoors4.toml", &file);
    let base = free_udp_ports(N as u16);
    let team_name = unique_team("mavgps");
    let vehicles = start_vehicles(&file, base, |_| Vec::new());
    let path = scenario.to_str().expect("utf-8 path");
    let mut c = launch(&team_name, &dir.path().join("run"), &["--scenario", path]);
    c.args(["--realtime", "--vehicles", "mavlink", "--arm"])
        .args(["--mavlink-base-port", &base.to_string()]);
    let o = spawn(&mut c).finish(DEADLINE);
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let outs: Vec<Output> = vehicles.into_iter().map(|v| v.finish(DEADLINE)).collect();
    let audit = read_json(&dir.path().join("run/audit.json"));
    assert_eq!(audit["verdict"], "SAFE", "{audit:#}");
    let s = Scenario::from_file(file.clone(), "outdoors4", Checks::Full).expect("valid");
    let mut goals = Vec::new();
    s.desired_positions(s.file.t_total_s, &mut goals);
    for (i, (out, goal)) in outs.iter().zip(&goals).enumerate() {
        assert_eq!(out.status.code(), Some(0), "vehicle {i}: {}", describe(out));
        let v = summary(out, &format!("vehicle {i}"));
        assert_eq!(v["armed"], true, "vehicle {i}: {v}");
        // Global targets only (MAV_FRAME_GLOBAL, position and velocity), every one flown.
        assert_eq!(v["frames"], serde_json::json!([0]), "vehicle {i}: {v}");
        assert_eq!(
            v["type_masks"],
            serde_json::json!([3520]),
            "vehicle {i}: {v}"
        );
        assert_eq!(v["global_targets_refused"], 0, "vehicle {i}: {v}");
        assert!(
            v["messages"]["SET_POSITION_TARGET_LOCAL_NED"].is_null(),
            "vehicle {i}: {v}"
        );
        let end: Vec<f64> = (v["final_position_global"].as_array())
            .unwrap_or_else(|| panic!("vehicle {i}: {v}"))
            .iter()
            .map(|x| x.as_f64().unwrap_or(f64::NAN))
            .collect();
        let want = ORIGIN.geodetic(goal);
        let at = ORIGIN.local(&GeoPoint {
            lat_deg: end[0],
            lon_deg: end[1],
            alt_m: end[2],
        });
        let off = at - goal;
        assert!(
            off.norm() < 0.5,
            "vehicle {i} ended at {end:?}, goal lat {} lon {} alt {}: {:.3} m off ({:.3} m across)",
            want.lat_deg,
            want.lon_deg,
            want.alt_m,
            off.norm(),
            off.xy().norm()
        );
    }
    assert_no_team_resources(&team_name);
}

#[test]
fn a_local_vehicle_origin_on_a_scenario_with_an_origin_is_refused() {
    let dir = TempDir::new();
    let scenario = write_scenario(dir.path(), "outdoors4.toml", &team());
    let path = scenario.to_str().expect("utf-8 path");
    let team_name = unique_team("mavgpsbad");
    let mut c = launch(&team_name, &dir.path().join("run"), &["--scenario", path]);
    c.args(["--realtime", "--vehicles", "mavlink"])
        .args(["--vehicle-origin", "1,0,0"]);
    let o = run(&mut c, DEADLINE);
    assert_eq!(o.status.code(), Some(2), "{}", describe(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--vehicle-origin") && err.contains("[origin]"),
        "{}",
        describe(&o)
    );
    assert_no_team_resources(&team_name);
}

/// The team inside a fence, with a box and a cylinder well aside of its path.
fn fenced_team() -> ScenarioFile {
    let mut f = team();
    f.geofence = Some(support::airspace::fence());
    f.obstacles = vec![
        ObstacleSpec {
            name: "tower".into(),
            shape: Shape::Box {
                min: [400.0, 400.0, 0.0],
                max: [420.0, 430.0, 100.0],
            },
        },
        ObstacleSpec {
            name: "mast".into(),
            shape: Shape::Cylinder {
                center: [-50.0, 500.0],
                radius_m: 5.0,
                min_z_m: 0.0,
                max_z_m: 100.0,
            },
        },
    ];
    f
}

/// The fence the vehicles must hold, as the vehicle reports it: [command, param1, lat e7, lon
/// e7] per item (MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION 5001, ..._EXCLUSION 5002,
/// MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION 5004).
fn expected_fence() -> Vec<(u32, f64, i64, i64)> {
    let e7 = |x: f64, y: f64| {
        let g = ORIGIN.geodetic(&Vec3::new(x, y, 0.0));
        (
            (g.lat_deg * 1e7).round() as i64,
            (g.lon_deg * 1e7).round() as i64,
        )
    };
    let mut want = Vec::new();
    for [x, y] in [
        [-100.0, -200.0],
        [500.0, -200.0],
        [500.0, 600.0],
        [-100.0, 600.0],
    ] {
        let (lat, lon) = e7(x, y);
        want.push((5001, 4.0, lat, lon));
    }
    for [x, y] in [
        [400.0, 400.0],
        [420.0, 400.0],
        [420.0, 430.0],
        [400.0, 430.0],
    ] {
        let (lat, lon) = e7(x, y);
        want.push((5002, 4.0, lat, lon));
    }
    let (lat, lon) = e7(-50.0, 500.0);
    want.push((5004, 5.0, lat, lon));
    want
}

fn held_fence(v: &Value) -> Vec<(u32, f64, i64, i64)> {
    (v["fence"].as_array())
        .unwrap_or_else(|| panic!("no fence in {v}"))
        .iter()
        .map(|i| {
            (
                i[0].as_u64().unwrap_or(0) as u32,
                i[1].as_f64().unwrap_or(f64::NAN),
                i[2].as_i64().unwrap_or(0),
                i[3].as_i64().unwrap_or(0),
            )
        })
        .collect()
}

/// Whether a vehicle ever received an arm command (COMPONENT_ARM_DISARM with param1 1).
fn asked_to_arm(v: &Value) -> bool {
    (v["commands"].as_array().cloned().unwrap_or_default())
        .iter()
        .any(|c| c["command"] == 400 && c["param1"] == 1.0)
}

fn launch_fenced(dir: &std::path::Path, team_name: &str, base: u16) -> Output {
    let scenario = write_scenario(dir, "fenced4.toml", &fenced_team());
    let path = scenario.to_str().expect("utf-8 path");
    let mut c = launch(team_name, &dir.join("run"), &["--scenario", path]);
    c.args([
        "--realtime",
        "--vehicles",
        "mavlink",
        "--arm",
        "--upload-fence",
    ])
    .args(["--mavlink-base-port", &base.to_string()]);
    spawn(&mut c).finish(DEADLINE)
}

#[test]
fn every_vehicle_holds_the_scenarios_fence_before_it_is_armed() {
    let dir = TempDir::new();
    let file = fenced_team();
    let base = free_udp_ports(N as u16);
    let team_name = unique_team("mavfence");
    let vehicles = start_vehicles(&file, base, |_| Vec::new());
    let o = launch_fenced(dir.path(), &team_name, base);
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let want = expected_fence();
    for (i, v) in vehicles.into_iter().enumerate() {
        let out = v.finish(DEADLINE);
        let v = summary(&out, &format!("vehicle {i}"));
        assert_eq!(held_fence(&v), want, "vehicle {i}: {v}");
        // The read-back was closed, and the vehicle flew armed.
        assert_eq!(v["fence_acks_received"]["0"], 1, "vehicle {i}: {v}");
        assert_eq!(v["armed"], true, "vehicle {i}: {v}");
    }
    assert_no_team_resources(&team_name);
}

#[test]
fn a_vehicle_that_refuses_the_fence_is_named_and_nothing_arms() {
    let dir = TempDir::new();
    let file = fenced_team();
    let base = free_udp_ports(N as u16);
    let team_name = unique_team("mavfenceno");
    const REFUSES: usize = 2;
    let refuses_id = file.agents[REFUSES].id;
    let vehicles = start_vehicles(&file, base, |i| {
        if i == REFUSES {
            vec!["--refuse-fence".into()]
        } else {
            Vec::new()
        }
    });
    let o = launch_fenced(dir.path(), &team_name, base);
    assert_ne!(o.status.code(), Some(0), "{}", describe(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    let named = format!("agent {refuses_id}: its vehicle refused the fence (MAV_MISSION_DENIED)");
    assert!(err.contains(&named), "no `{named}` in:\n{}", describe(&o));
    for (i, v) in vehicles.into_iter().enumerate() {
        let out = v.finish(DEADLINE);
        let v = summary(&out, &format!("vehicle {i}"));
        assert!(
            !asked_to_arm(&v) && v["armed"] == false,
            "vehicle {i} armed: {v}"
        );
        if i == REFUSES {
            assert!(held_fence(&v).is_empty(), "vehicle {i}: {v}");
        }
    }
    assert_no_team_resources(&team_name);
}
