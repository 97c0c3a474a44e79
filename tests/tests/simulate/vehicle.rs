//! The vehicles' limits and downwash (`[vehicle]`), with the real `orchestrator`:
//!
//! - generated(4) (the paper's primaries descending 340 m) with speed and acceleration limits:
//!   `plan` SAFE at 60 s; at 20 s UNSAFE naming the member and the limit; `--suggest` gives a
//!   travel time that then passes. `simulate` audits the same limits on the flown velocities.
//! - Five members, two of them 4.5 m apart (eps 1 m, delta 0.5 m): on a vertical plane (one
//!   above the other) with a downwash ratio of 3 the pair is 1.5 m apart in the downwash
//!   metric, below 2 (eps + delta) = 3 m, and `plan` is UNSAFE naming the pair (SAFE without
//!   the ratio); flown, the audit records their collision in the downwash metric (1.5 m < 2 eps).
//!   The same formation on a horizontal plane (side by side) is SAFE, planned and flown. Both
//!   flights check the bound the certificate rests on, tick by tick and pair by pair:
//!   d(r_i - r_j) >= d(r_i,HT - r_j,HT) - |r_i - r_i,HT| - |r_j - r_j,HT|.
//!
//! How to run: `cargo test --release -p integration-tests --test simulate -- vehicle::`.

use integration_tests::support;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};

use cdm_model::formation::Role;
use cdm_model::limits::downwash_distance;
use cdm_scenario::{generated, AgentSpec, ScenarioFile, VehicleSpec};
use integration_tests::{bin, describe, run, write_scenario, TempDir};
use support::airspace::{four_members, plan};
use support::{assert_exit, read_json};

const DEADLINE: std::time::Duration = integration_tests::deadline::FLIGHT;

fn orchestrator(args: &[&str]) -> Output {
    run(Command::new(bin("orchestrator")).args(args), DEADLINE)
}

/// `simulate` into DIR/NAME and its audit.json.
fn simulate(
    dir: &Path,
    scenario: &Path,
    name: &str,
) -> (Output, serde_json::Value, std::path::PathBuf) {
    let run_dir = dir.join(name);
    let (s, o) = (scenario.to_str().unwrap(), run_dir.to_str().unwrap());
    let out = orchestrator(&["simulate", "--scenario", s, "--out", o, "--quiet"]);
    let audit = read_json(&run_dir.join("audit.json"));
    (out, audit, run_dir)
}

/// generated(4) flying its descent in `t_total_s`, with limits a light quadcopter has.
fn limited(t_total_s: f64) -> ScenarioFile {
    let mut f = four_members(t_total_s);
    f.vehicle = Some(VehicleSpec {
        max_speed_xy_m_s: Some(15.0),
        max_speed_up_m_s: Some(5.0),
        max_speed_down_m_s: Some(20.0),
        max_accel_xy_m_s2: Some(4.0),
        max_accel_z_m_s2: Some(3.0),
        downwash_ratio: None,
    });
    f
}

#[test]
fn limits_are_certified_suggested_and_audited() {
    let dir = TempDir::new();
    let safe = write_scenario(dir.path(), "slow.toml", &limited(60.0));
    let (out, cert) = plan(dir.path(), &safe);
    assert_exit(&out, 0, "plan within the limits");
    let limits = cert["vehicle"]["limits"].as_array().expect("limit rows");
    assert_eq!(limits.len(), 5, "{cert:#}");
    for l in limits {
        assert!(
            l["value"].as_f64().unwrap() <= l["max"].as_f64().unwrap(),
            "{l}"
        );
    }
    let (out, audit, _) = simulate(dir.path(), &safe, "slow");
    assert_exit(&out, 0, "simulate within the limits");
    let flown = audit["vehicle_limits"].as_array().expect("flown limits");
    assert_eq!(flown.len(), 5, "{audit:#}");
    // The flown peaks stay within the audit's allowance and near the certified commanded ones
    // (the leaders fly theirs exactly, the followers overshoot a little).
    for (f, c) in flown.iter().zip(limits) {
        let allowed = f["allowed"].as_f64().unwrap();
        let (f, c) = (f["flown"].as_f64().unwrap(), c["value"].as_f64().unwrap());
        assert!(f <= allowed, "flown {f} allowed {allowed}");
        assert!(
            c == 0.0 || (f - c).abs() <= 0.1 * c,
            "flown {f} commanded {c}"
        );
    }

    let fast = write_scenario(dir.path(), "fast.toml", &limited(20.0));
    let (out, cert) = plan(dir.path(), &fast);
    assert_exit(&out, 1, "plan too fast for the limits");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("vehicle limit max_speed_xy_m_s: member 1 in segment 1 commands"),
        "{}",
        describe(&out)
    );
    let row = &cert["vehicle"]["suggestion"][0];
    assert_eq!(row["key"], "t_total_s", "{cert:#}");
    let shortest = row["shortest_t_s"].as_f64().expect("a suggested time");
    assert!(shortest > 20.0 && shortest < 60.0, "{row}");
    let (out, audit, _) = simulate(dir.path(), &fast, "fast");
    assert_exit(&out, 1, "simulate too fast for the limits");
    let kinds: Vec<&str> = (audit["violations"].as_array().unwrap().iter())
        .filter(|v| v["kind"] == "limit")
        .map(|v| v["name"].as_str().unwrap())
        .collect();
    assert!(kinds.contains(&"max_speed_xy_m_s"), "{audit:#}");

    let suggested = write_scenario(dir.path(), "suggested.toml", &limited(shortest));
    let (out, cert) = plan(dir.path(), &suggested);
    assert_exit(&out, 0, "plan at the suggested time");
    assert_eq!(cert["vehicle"]["suggestion"][0]["shortest_t_s"], shortest);
}

/// Three primary leaders and two followers 4.5 m apart, on the plane spanned by x and `up`
/// (0, 0, 1): vertical; (0, 1, 0): horizontal), translating 40 m along x in 60 s.
fn pair(up: [f64; 3], ratio: Option<f64>) -> ScenarioFile {
    let mut f = generated(4).expect("four agents generate");
    let at = |u: f64, v: f64| [u, up[1] * v, 100.0 + up[2] * v];
    let member = |id: u32, role: Role, u: f64, v: f64, goal: bool| AgentSpec {
        id,
        role,
        position: at(u, v),
        goal: goal.then(|| at(u + 40.0, v)),
        in_neighbors: None,
    };
    f.name = "pair".into();
    f.t_total_s = 60.0;
    f.eps_m = 1.0;
    f.lambda_cd_min = None;
    f.delta_m = Some(0.5);
    f.agents = vec![
        member(1, Role::Primary, 0.0, 0.0, true),
        member(2, Role::Primary, 30.0, 0.0, true),
        member(3, Role::Primary, 15.0, 30.0, true),
        member(4, Role::Follower, 15.0, 8.0, false),
        member(5, Role::Follower, 15.0, 12.5, false),
    ];
    f.vehicle = ratio.map(|r| VehicleSpec {
        downwash_ratio: Some(r),
        ..VehicleSpec::default()
    });
    f
}

/// One member at one tick: its flown position r and its desired position r_HT.
type Flown = ([f64; 3], [f64; 3]);

/// Per tick, every pair: the flown downwash distance is at least the desired one less both
/// members' Euclidean tracking errors (the bound of the certificate). Returns the number of
/// pairs checked and the smallest flown distance.
fn check_bound_on_flight(run_dir: &Path, ratio: f64) -> (usize, f64) {
    let text = std::fs::read_to_string(run_dir.join("telemetry.csv")).expect("telemetry");
    let mut ticks: BTreeMap<u64, Vec<Flown>> = BTreeMap::new();
    for line in text.lines().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        let n = |k: usize| c[k].parse::<f64>().expect("a number");
        let tick = c[0].parse().expect("a tick");
        ticks
            .entry(tick)
            .or_default()
            .push(([n(4), n(5), n(6)], [n(10), n(11), n(12)]));
    }
    let v = |a: [f64; 3]| cdm_math::Vec3::new(a[0], a[1], a[2]);
    let (mut checked, mut smallest) = (0, f64::INFINITY);
    for rows in ticks.values() {
        for (i, (ri, hi)) in rows.iter().enumerate() {
            for (rj, hj) in &rows[i + 1..] {
                let flown = downwash_distance(&(v(*ri) - v(*rj)), ratio);
                let desired = downwash_distance(&(v(*hi) - v(*hj)), ratio);
                let errors = (v(*ri) - v(*hi)).norm() + (v(*rj) - v(*hj)).norm();
                assert!(
                    flown >= desired - errors - 1e-9,
                    "{flown} {desired} {errors}"
                );
                smallest = smallest.min(flown);
                checked += 1;
            }
        }
    }
    (checked, smallest)
}

#[test]
fn a_stack_inside_the_downwash_is_unsafe_and_the_same_spacing_side_by_side_is_safe() {
    let dir = TempDir::new();
    // Without a ratio the vertical stack is the paper's spheres, 6 m apart: SAFE.
    let spheres = write_scenario(dir.path(), "spheres.toml", &pair([0.0, 0.0, 1.0], None));
    let (out, _) = plan(dir.path(), &spheres);
    assert_exit(&out, 0, "plan of the stack with spheres");

    let stacked = write_scenario(
        dir.path(),
        "stacked.toml",
        &pair([0.0, 0.0, 1.0], Some(3.0)),
    );
    let (out, cert) = plan(dir.path(), &stacked);
    assert_exit(&out, 1, "plan of the stack in the downwash");
    let d = &cert["vehicle"]["downwash"];
    assert_eq!(d["agents"], serde_json::json!([4, 5]), "{cert:#}");
    assert!((d["min_m"].as_f64().unwrap() - 1.5).abs() < 1e-9, "{d}");
    assert!(
        (d["required_m"].as_f64().unwrap() - 3.0).abs() < 1e-12,
        "{d}"
    );
    let reasons = cert["reasons"].as_array().unwrap();
    assert_eq!(reasons.len(), 1, "{cert:#}");
    assert!(
        reasons[0]
            .as_str()
            .unwrap()
            .starts_with("downwash: members 4 and 5"),
        "{cert:#}"
    );
    // Flown, the stack's ellipsoids overlap (1.5 m < 2 eps): a collision in the downwash metric.
    let (out, audit, run_dir) = simulate(dir.path(), &stacked, "stacked");
    assert_exit(&out, 1, "simulate of the stack");
    let first = &audit["violations"][0];
    assert_eq!(first["kind"], "collision", "{audit:#}");
    assert_eq!(first["name"], "downwash", "{audit:#}");
    assert_eq!(first["agents"], serde_json::json!([4, 5]), "{audit:#}");
    assert!(
        audit["min_separation_m"].as_f64().unwrap() > 4.0,
        "{audit:#}"
    );
    let flown_min = audit["min_downwash_separation_m"].as_f64().unwrap();
    let (checked, smallest) = check_bound_on_flight(&run_dir, 3.0);
    assert!(checked > 10 * 6000, "{checked}");
    assert!(
        (smallest - flown_min).abs() < 1e-9,
        "{smallest} {flown_min}"
    );

    let side = write_scenario(dir.path(), "side.toml", &pair([0.0, 1.0, 0.0], Some(3.0)));
    let (out, cert) = plan(dir.path(), &side);
    assert_exit(&out, 0, "plan side by side");
    assert!((cert["vehicle"]["downwash"]["min_m"].as_f64().unwrap() - 4.5).abs() < 1e-9);
    let (out, audit, run_dir) = simulate(dir.path(), &side, "side");
    assert_exit(&out, 0, "simulate side by side");
    let (_, smallest) = check_bound_on_flight(&run_dir, 3.0);
    assert!(smallest >= 3.0, "{smallest} {audit:#}");
}
