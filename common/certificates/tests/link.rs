//! Imperfect links in the engine (`common/model/src/link.rs`): nothing lost and no delay is the
//! paper's model bit for bit; delay, jitter and loss change the flight deterministically.

use cdm_certificates::delay::deviation_at_delay;
use cdm_certificates::linear_certificate::LinearTeam;
use cdm_engine::engine::{max_follower_deviation, quad_engine};
use cdm_model::dynamics::QuadState;
use cdm_model::link::LinkSpec;
use cdm_scenario::{Checks, Scenario};

fn paper40_with(t_total_s: f64) -> Scenario {
    let mut f = cdm_scenario::paper40();
    f.t_total_s = t_total_s;
    Scenario::from_file(f, "paper40", Checks::Member).unwrap()
}

fn link(delay_ms: f64, jitter_ms: f64, loss: f64, seed: u64) -> Option<LinkSpec> {
    Some(LinkSpec {
        delay_ms,
        jitter_ms,
        loss,
        seed,
    })
}

fn fly(s: &Scenario) -> Vec<QuadState> {
    let mut e = quad_engine(s);
    while e.tick() < s.last_tick() {
        e.advance().unwrap();
    }
    e.states().to_vec()
}

fn bits(states: &[QuadState]) -> Vec<u64> {
    states
        .iter()
        .flat_map(|q| q.0.iter().map(|v| v.to_bits()).collect::<Vec<_>>())
        .collect()
}

#[test]
fn the_link_path_with_nothing_lost_or_late_is_the_perfect_path_bit_for_bit() {
    let s = paper40_with(20.0);
    // A loss probability this small takes the imperfect-link path without losing a state in
    // 2,000 ticks x 111 links (checked: every arrival is on time).
    let spec = link(0.0, 0.0, 1e-15, 3);
    let linked = s.with_link(spec).unwrap();
    let m = linked.link_model();
    assert!(!m.is_perfect());
    assert!((0..=s.last_tick()).all(|t| m.arrival(1, 2, t) == Some(t)));
    assert_eq!(bits(&fly(&s)), bits(&fly(&linked)));
}

#[test]
fn delay_jitter_and_loss_are_deterministic_and_matter() {
    let s = paper40_with(20.0);
    let impaired = s.with_link(link(30.0, 20.0, 0.2, 11)).unwrap();
    let a = bits(&fly(&impaired));
    assert_eq!(a, bits(&fly(&impaired)), "same flags, same flight");
    assert_ne!(a, bits(&fly(&s)), "impairments change the flight");
    let reseeded = s.with_link(link(30.0, 20.0, 0.2, 12)).unwrap();
    assert_ne!(a, bits(&fly(&reseeded)), "the seed changes the draws");
}

/// Followers extrapolate a late state from its own time (cubic Taylor), so on the slow paper40
/// plan a delay of 1 s barely moves E_max; at 2 s the delayed feedback destabilises the team.
#[test]
fn delay_is_compensated_up_to_a_point_then_breaks_the_team() {
    let s = paper40_with(200.0);
    let e = |ms: f64| {
        max_follower_deviation(&s.with_link(link(ms, 0.0, 0.0, 0)).unwrap())
            .unwrap_or(f64::INFINITY)
    };
    let (e0, e1000, e2000) = (e(0.0), e(1000.0), e(2000.0));
    println!("paper40: E_max at 0, 1000, 2000 ms = {e0:.4}, {e1000:.4}, {e2000:.4} m");
    assert!((e1000 - e0).abs() < 1e-2, "{e0} {e1000}");
    assert!(e2000 > 10.0 * e0, "{e0} {e2000}");
}

#[test]
fn a_perfect_spec_leaves_the_scenario_and_its_hash_alone() {
    let s = paper40_with(20.0);
    let same = s.with_link(link(0.0, 0.0, 0.0, 99)).unwrap();
    assert_eq!(same.file.link, None);
    assert_eq!(same.content_hash(), s.content_hash());
    let other = s.with_link(link(10.0, 0.0, 0.0, 0)).unwrap();
    assert_ne!(
        other.content_hash(),
        s.content_hash(),
        "links are part of the team's hash"
    );
    let back = Scenario::parse(&other.to_toml(), "round trip", Checks::Member).unwrap();
    assert_eq!(back.file.link, other.file.link);
    assert_eq!(back.content_hash(), other.content_hash());
}

#[test]
fn bad_links_name_the_field() {
    let s = paper40_with(20.0);
    let err = s.with_link(link(0.0, 0.0, 1.5, 0)).unwrap_err().to_string();
    assert!(err.contains("link.loss"), "{err}");
    let mut f = s.file.clone();
    f.link = link(-5.0, 0.0, 0.0, 0);
    let err = Scenario::from_file(f, "file.toml", Checks::Member)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("file.toml") && err.contains("link.delay_ms"),
        "{err}"
    );
}

/// The certificate's delay search runs on the linear team with the delay as a shift of the
/// neighbour terms (linear_certificate.rs); the nonlinear engine flying the same delay agrees.
#[test]
fn the_linear_team_with_a_delay_matches_the_engine_flying_it() {
    let s = paper40_with(60.0);
    let team = LinearTeam::new(&s).unwrap();
    for ticks in [0u64, 1, 7, 40, 100] {
        let lin = team.max_follower_deviation_delayed(60.0, ticks);
        let flown = deviation_at_delay(&s, ticks as f64 * 10.0, f64::INFINITY);
        println!("delay {ticks} ticks: linear {lin:.6} m, flown {flown:.6} m");
        assert!(flown.is_finite(), "delay {ticks} ticks: the flight faulted");
        assert!(
            (lin - flown).abs() <= 1e-6 * flown.max(1.0),
            "delay {ticks} ticks: linear {lin}, flown {flown}"
        );
    }
    // Where the delayed team diverges, the engine faults (singular control) and the linear
    // team grows without bound: both fail E_max <= delta (9.03 m).
    let flown = deviation_at_delay(&s, 1500.0, f64::INFINITY);
    let lin = team.max_follower_deviation_delayed(60.0, 150);
    assert!(!flown.is_finite() || flown > 100.0, "{flown}");
    assert!(lin > 100.0, "{lin}");
    assert_eq!(
        team.max_follower_deviation_delayed(60.0, 0),
        team.max_follower_deviation(60.0)
    );
}

/// `meets`, the delay search's question, agrees with the full E_max on both sides of delta.
#[test]
fn the_cheap_question_agrees_with_the_full_answer() {
    let s = paper40_with(60.0);
    let team = LinearTeam::new(&s).unwrap();
    for ticks in [0u64, 40, 100, 120, 150, 400] {
        let e = team.max_follower_deviation_delayed(60.0, ticks);
        for limit in [3.0, 4.0, 9.0276, 100.0] {
            assert_eq!(
                team.meets(60.0, ticks, limit),
                e <= limit,
                "delay {ticks} ticks, E_max {e}, limit {limit}"
            );
        }
    }
}
