//! The in-process engine: the nonlinear team equals the linear model (feedback linearisation,
//! eqs. 43-46), determinism, and the error of exchanging states once per tick.

use common::dynamics::Plant;
use common::engine::{chain_engine, exchange_error, max_follower_deviation, quad_engine};
use common::scenario::{Checks, Scenario};
use common::step::NeighborModel;

fn paper40_with(t_total_s: f64) -> Scenario {
    let mut f = common::scenario::paper40();
    f.t_total_s = t_total_s;
    Scenario::from_file(f, "paper40", Checks::Member).unwrap()
}

#[test]
fn nonlinear_team_matches_linear_model_over_a_whole_plan() {
    let s = paper40_with(200.0);
    let mut quad = quad_engine(&s);
    let mut chain = chain_engine(&s);
    let mut worst: f64 = 0.0;
    while quad.tick() < s.last_tick() {
        quad.advance().unwrap();
        chain.advance().unwrap();
        for (q, c) in quad.states().iter().zip(chain.states()) {
            worst = worst.max((q.position() - c.flat().r).norm());
        }
    }
    println!("nonlinear vs linear team, paper40 T=200 s: max |dr| = {worst:.3e} m");
    assert!(worst < 1e-6, "{worst}");
}

#[test]
fn engine_is_deterministic() {
    let s = paper40_with(20.0);
    let run = || {
        let mut e = quad_engine(&s);
        while e.tick() < s.last_tick() {
            e.advance().unwrap();
        }
        e.states().iter().map(|q| q.0).collect::<Vec<_>>()
    };
    let (a, b) = (run(), run());
    assert!(a
        .iter()
        .zip(&b)
        .all(|(x, y)| x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits())));
}

#[test]
fn exchange_error_is_small_and_taylor_beats_hold() {
    let s = paper40_with(100.0);
    let taylor = exchange_error(&s, NeighborModel::Taylor).unwrap();
    let hold = exchange_error(&s, NeighborModel::Hold).unwrap();
    println!("exchange error vs continuous eqs. 24-25, paper40 T=100 s, dt=10 ms: taylor {taylor:.3e} m, hold {hold:.3e} m");
    assert!(taylor < hold, "taylor {taylor} hold {hold}");
    assert!(taylor < 1e-3, "{taylor}");
}

#[test]
fn deviation_falls_as_travel_time_grows() {
    let mut last = f64::INFINITY;
    for t in [50.0, 100.0, 200.0] {
        let t0 = std::time::Instant::now();
        let d = max_follower_deviation(&paper40_with(t)).unwrap();
        println!(
            "T_total = {t} s: max follower deviation {d:.4} m ({:?})",
            t0.elapsed()
        );
        assert!(d < last);
        last = d;
    }
}
