//! A MAVLink team outdoors: a scenario with an `[origin]` (PX4's SITL home, +x 30 degrees east
//! of north) flown by `orchestrator launch --vehicles mavlink --arm` with no vehicle origin at
//! all. Each `tests/python/mavlink_vehicle.py` has GPS (`--home`: its local origin is its own
//! spawn point on the ground below its member, as in PX4's multi-vehicle SITL), beats at PX4's
//! 1 Hz, streams GLOBAL_POSITION_INT and flies SET_POSITION_TARGET_GLOBAL_INT through PX4's own
//! map projection. The members command latitude, longitude and altitude and read the GPS fix;
//! every vehicle ends at its goal's latitude and longitude (and altitude) within 0.5 m. A local
//! vehicle origin on such a scenario is refused (exit 2), naming the option.
//!
//! How to run: `cargo test --release -p integration-tests --test mavlink_global`.

mod support;

use std::process::Output;
use std::time::Duration;

use cdm_math::Vec3;
use cdm_scenario::{Checks, GeoOrigin, GeoPoint, Scenario, ScenarioFile};
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
fn start_vehicles(s: &ScenarioFile, base: u16) -> Vec<Running> {
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
                .args(["--require-arm", "--heartbeat-hz", "1", "--max-s", "100"]);
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
    let vehicles = start_vehicles(&file, base);
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
