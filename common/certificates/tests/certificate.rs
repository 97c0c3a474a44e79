//! The certificate on the linear error dynamics (`linear_certificate.rs`): against the full
//! nonlinear flight on small teams, and against the numbers `plan --json` printed before it
//! existed (fixtures/certificate/*.json, written by the flying certificate of commit 6f83114).

use std::path::Path;

use cdm_certificates::certificate::{deviation_at, t_threshold, t_threshold_from};
use cdm_certificates::certify::certify;
use cdm_certificates::linear_certificate::{LinearTeam, NotLinear};
use cdm_records::audit::SafetyNumbers;
use cdm_scenario::{Checks, Scenario};

const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/certificate");

fn relative(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs())
}

/// Every number of today's certificate stays within 1e-3 (relative) of the recorded one.
fn assert_matches_fixture(s: &Scenario, fixture: &str) {
    let path = Path::new(FIXTURES).join(fixture);
    let text = std::fs::read_to_string(&path).unwrap();
    let want: serde_json::Value = serde_json::from_str(&text).unwrap();
    let got = serde_json::to_value(certify(s)).unwrap();
    assert_eq!(got["verdict"], want["verdict"], "{fixture}");
    let mut compared = 0;
    for (key, w) in want.as_object().unwrap() {
        let Some(w) = w.as_f64() else { continue };
        let g = got[key].as_f64().unwrap_or(f64::NAN);
        println!(
            "{fixture} {key}: {g} (recorded {w}, relative {:.1e})",
            relative(g, w)
        );
        assert!(relative(g, w) <= 1e-3, "{fixture} {key}: {g} against {w}");
        compared += 1;
    }
    assert!(
        compared >= 10,
        "{fixture}: only {compared} numbers compared"
    );
}

#[test]
fn paper40_certificate_matches_the_flying_certificate() {
    assert_matches_fixture(&Scenario::builtin("paper40").unwrap(), "paper40.json");
}

#[test]
fn tilted_goal_certificate_matches_the_flying_certificate() {
    let s = Scenario::load(&Path::new(FIXTURES).join("tilt40.toml"), Checks::Full).unwrap();
    assert_matches_fixture(&s, "tilt40.json");
}

#[test]
fn n1000_certificate_matches_the_flying_certificate() {
    assert_matches_fixture(&Scenario::generated(1000).unwrap(), "n1000.json");
}

/// T_threshold and E_max from the linear model against flying the nonlinear team (the
/// certificate's old method) on a small team.
#[test]
fn linear_certificate_matches_the_nonlinear_flight_on_a_small_team() {
    let s = Scenario::generated(12).unwrap();
    let team = LinearTeam::new(&s).unwrap();
    let delta = SafetyNumbers::of(&s).delta_m;
    for t in [20.0, 40.0, 80.0, s.file.t_total_s] {
        let (lin, flown) = (team.max_follower_deviation(t), deviation_at(&s, t));
        println!("T = {t} s: E_max linear {lin:.12} m, flown {flown:.12} m");
        assert!(
            relative(lin, flown) <= 1e-3,
            "T = {t}: {lin} against {flown}"
        );
    }
    let e = team.max_follower_deviation(s.file.t_total_s);
    let lin = t_threshold(&s, delta, e, |t| team.max_follower_deviation(t));
    let flown = t_threshold(&s, delta, e, |t| deviation_at(&s, t));
    println!("T_threshold linear {lin:.9} s, flown {flown:.9} s");
    assert!(relative(lin, flown) <= 1e-3, "{lin} against {flown}");
}

/// Whatever the numbers, the T_threshold search never asks for E(T) at a T longer than a
/// scenario may fly (1e8 ticks): a deviation a billion times delta, or a delta of 1e-300 m, is
/// an infinite threshold found without a single E(T) that long. Each E(T) costs its ticks:
/// before the bound a take-off from 1e12 m below ran for hours.
#[test]
fn the_threshold_search_never_tries_a_travel_time_longer_than_a_flight() {
    let comm_hz = 10.0;
    let t_max_s = cdm_scenario::MAX_TICKS / comm_hz;
    for (delta_m, e_m) in [(1.0, 1e18), (1e-300, 1.0), (1.0, f64::INFINITY)] {
        let longest = std::cell::Cell::new(0.0_f64);
        // E(T) ~ 1 / T^2 (Sec. VII-D), far above delta at every T a flight may last.
        let t = t_threshold_from(200.0, comm_hz, delta_m, e_m, |t| {
            longest.set(longest.get().max(t));
            e_m * (200.0 / t).powi(2)
        });
        assert_eq!(t, f64::INFINITY, "delta {delta_m}, E {e_m}");
        assert!(longest.get() <= t_max_s, "E({}) asked", longest.get());
    }
    // A threshold within reach is still found.
    let t = t_threshold_from(200.0, comm_hz, 1.0, 4.0, |t| 4.0 * (200.0 / t).powi(2));
    assert!((t - 400.0).abs() < 1.0, "{t}");
}

/// A cycle among followers (scenario files may give one) has no finite series: the linear model
/// says so and the certificate flies the plan.
#[test]
fn a_cyclic_graph_is_refused_by_the_linear_model() {
    let mut s = Scenario::builtin("paper40").unwrap();
    let members = &s.formation.members;
    // A follower b that reads follower a: make a read b too.
    let (a, b) = members
        .iter()
        .enumerate()
        .find_map(|(kb, m)| {
            let link = m.link?;
            link.in_neighbors.iter().find_map(|id| {
                let ka = members.iter().position(|x| x.id == *id)?;
                members[ka].link.map(|_| (ka, kb))
            })
        })
        .unwrap();
    let b_id = s.formation.members[b].id;
    if let Some(link) = s.formation.members[a].link.as_mut() {
        link.in_neighbors[0] = b_id;
    }
    assert!(
        matches!(LinearTeam::new(&s), Err(NotLinear::Cyclic { .. })),
        "{:?}",
        LinearTeam::new(&s)
    );
}
