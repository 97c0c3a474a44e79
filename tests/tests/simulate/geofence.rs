//! Geofences and obstacles, on a 4-member team of the paper's kind flying its
//! descent in 20 s (2,001 ticks; T_threshold 8.26 s, delta 32.03 m):
//!
//! - A box across primary leader 1's path makes `plan` UNSAFE (exit 1) naming the obstacle, the
//!   member, the time and the depth; `--suggest` gives the lift that clears it; `simulate`
//!   records an `obstacle` violation naming it, and a lockstep `launch` records the same one.
//! - The same box moved aside: `plan` SAFE with its margin, `simulate` SAFE.
//! - The team climbing to goals above the fence's ceiling: UNSAFE naming `fence ceiling`.
//!
//! How to run: `cargo test --release -p integration-tests --test simulate -- geofence::`.

use integration_tests::support;

use cdm_model::airspace::Shape;
use cdm_scenario::{ObstacleSpec, ScenarioFile};
use integration_tests::{describe, run, write_scenario, TempDir};
use support::airspace::{fence, four_members, plan};
use support::{assert_exit, read_json, simulate};

const DEADLINE: std::time::Duration = integration_tests::deadline::FLIGHT;

/// generated(4) in 20 s inside the fence: primary 1 flies (360, 0, 900) -> (224, 434, 560),
/// through (292, 217, 730) at t = 10 s.
fn team() -> ScenarioFile {
    let mut f = four_members(20.0);
    f.geofence = Some(fence());
    f
}

/// A 20 m x 20 m tower up to 740 m around (292 + dx, 217).
fn tower(dx: f64) -> ObstacleSpec {
    ObstacleSpec {
        name: "tower".into(),
        shape: Shape::Box {
            min: [282.0 + dx, 207.0, 0.0],
            max: [302.0 + dx, 227.0, 740.0],
        },
    }
}

/// The airspace row of `name` in a certificate.
fn clearance<'a>(cert: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    (cert["airspace"]["clearances"].as_array())
        .and_then(|rows| rows.iter().find(|r| r["name"] == name))
        .unwrap_or_else(|| panic!("no clearance {name:?} in {cert:#}"))
}

#[test]
fn a_path_through_a_box_is_unsafe_before_and_during_the_flight() {
    let dir = TempDir::new();
    let mut f = team();
    f.obstacles = vec![tower(0.0)];
    let scenario = write_scenario(dir.path(), "cross.toml", &f);
    let (out, cert) = plan(dir.path(), &scenario);
    assert_exit(&out, 1, "plan of a path through the tower");
    let stdout = String::from_utf8_lossy(&out.stdout);
    // Member 1 passes the tower's centre at t = 10 s: 10 m from its faces, plus the ball.
    let radius = cert["airspace"]["radius_m"].as_f64().unwrap();
    let depth = 10.0 + radius;
    let reason =
        format!("obstacle \"tower\": member 1 at t = 10.00 s (segment 1), {depth:.2} m inside");
    assert!(
        stdout.contains(&reason),
        "no `{reason}` in:\n{}",
        describe(&out)
    );
    let row = clearance(&cert, "tower");
    assert!(
        (row["margin_m"].as_f64().unwrap() + depth).abs() < 1e-9,
        "{row:#}"
    );
    assert_eq!(
        (row["agent"].as_u64(), row["kind"].as_str()),
        (Some(1), Some("obstacle"))
    );
    // --suggest: a lift over the tower exists, and the ceiling forbids it for the whole airspace.
    let offsets = &cert["airspace"]["suggestion"]["offsets"];
    assert_eq!(offsets[0]["what"], "obstacle \"tower\"", "{cert:#}");
    let lift = offsets[0]["raise_m"]
        .as_f64()
        .expect("a lift clears the tower");
    assert!(lift > depth, "{offsets:#}");
    assert!(offsets[1]["raise_m"].is_null(), "{offsets:#}");
    assert!(
        stdout.contains("no uniform time scaling clears it"),
        "{}",
        describe(&out)
    );

    let source = ["--scenario", scenario.to_str().unwrap(), "--no-figures"];
    let sim = dir.path().join("sim");
    assert_exit(&run(&mut simulate(&sim, &source), DEADLINE), 1, "simulate");
    let audit = read_json(&sim.join("audit.json"));
    let breaches: Vec<&serde_json::Value> = (audit["violations"].as_array().unwrap().iter())
        .filter(|v| v["kind"] == "obstacle")
        .collect();
    assert_eq!(breaches.len(), 1, "{audit:#}");
    assert_eq!(
        (breaches[0]["name"].as_str(), &breaches[0]["agents"]),
        (Some("tower"), &serde_json::json!([1]))
    );
    assert!(
        audit["min_obstacle_margin_m"].as_f64().unwrap() < 0.0,
        "{audit:#}"
    );
    // The processes audit alike (lockstep: the very same audit.json).
    let team = integration_tests::unique_team("geofence");
    let launched = dir.path().join("launch");
    let l = run(
        &mut integration_tests::launch(&team, &launched, &source),
        DEADLINE,
    );
    assert_exit(&l, 1, "launch");
    support::assert_same_file(&launched.join("audit.json"), &sim.join("audit.json"));
}

#[test]
fn the_box_moved_aside_is_safe() {
    let dir = TempDir::new();
    let mut f = team();
    f.obstacles = vec![tower(150.0)];
    let scenario = write_scenario(dir.path(), "aside.toml", &f);
    let (out, cert) = plan(dir.path(), &scenario);
    assert_exit(&out, 0, "plan with the tower aside");
    let margin = clearance(&cert, "tower")["margin_m"].as_f64().unwrap();
    assert!(margin > 0.0, "{cert:#}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("obstacle \"tower\"") && stdout.contains("nothing to clear"),
        "{}",
        describe(&out)
    );
    let source = ["--scenario", scenario.to_str().unwrap(), "--no-figures"];
    let sim = dir.path().join("sim");
    assert_exit(&run(&mut simulate(&sim, &source), DEADLINE), 0, "simulate");
    let audit = read_json(&sim.join("audit.json"));
    assert!(
        audit["min_obstacle_margin_m"].as_f64().unwrap() > margin,
        "{audit:#}"
    );
}

#[test]
fn a_ceiling_below_a_goal_is_unsafe_naming_the_fence() {
    let dir = TempDir::new();
    let mut f = team();
    // Climb instead: start at the descent's goals, end at its start (up to z = 1080).
    for a in f.agents.iter_mut().filter(|a| a.goal.is_some()) {
        let goal = a.goal.replace(a.position).unwrap();
        a.position = goal;
    }
    let centroid: [f64; 3] = std::array::from_fn(|c| {
        (f.agents.iter().take(3))
            .map(|a| a.position[c])
            .sum::<f64>()
            / 3.0
    });
    f.agents[3].position = centroid;
    f.geofence.as_mut().unwrap().max_z_m = 1000.0;
    let scenario = write_scenario(dir.path(), "climb.toml", &f);
    let (out, cert) = plan(dir.path(), &scenario);
    assert_exit(&out, 1, "plan of a climb through the ceiling");
    let radius = cert["airspace"]["radius_m"].as_f64().unwrap();
    let beyond = 1080.0 + radius - 1000.0;
    let reason =
        format!("fence ceiling: member 3 at t = 20.00 s (segment 1), {beyond:.2} m beyond it");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains(&reason),
        "no `{reason}` in:\n{}",
        describe(&out)
    );
    assert_eq!(clearance(&cert, "ceiling")["kind"], "fence");
}
