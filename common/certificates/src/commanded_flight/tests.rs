use super::*;
use cdm_engine::engine::quad_engine;
use cdm_model::formation::Role;
use cdm_model::steer::TeamCommand;
use cdm_scenario::{paper40, Checks};

/// The nonlinear engine's largest follower deviation over ticks `from..=` the last, and where.
fn flown_from(s: &Scenario, from: u64) -> (Real, u32, u64) {
    let mut e = quad_engine(s);
    let mut ht = Vec::new();
    let mut worst = (0.0, 0, 0);
    loop {
        if e.tick() >= from {
            s.desired_positions(tick_time(e.tick(), s.dt_s()), &mut ht);
            for (k, m) in s.formation.members.iter().enumerate() {
                let d = (e.states()[k].position() - ht[k]).norm();
                if m.role == Role::Follower && d > worst.0 {
                    worst = (d, m.id, e.tick());
                }
            }
        }
        if e.tick() >= s.last_tick() {
            return worst;
        }
        e.advance().expect("flies");
    }
}

/// paper40 held while moving, sent elsewhere, then landed: the linear model's deviation from
/// each switch on is the nonlinear engine's, every tick counted.
#[test]
fn the_commanded_deviation_is_the_engines() {
    let s = Scenario::from_file(paper40(), "paper40", Checks::Full).unwrap();
    let mut steering = s.steering();
    let t_hold = (0.3 * s.plan.flight_end_s() * 100.0).round() / 100.0;
    let hold = steering.propose(&TeamCommand::Hold, t_hold).unwrap();
    let held_at = hold.held_at;
    steering.accept(hold);
    let t_goto = (steering.plan().end_s() * 100.0).ceil() / 100.0 + 1.0;
    let goals = held_at.map(|p| p + Vec3::new(40.0, -20.0, 10.0));
    let goto = TeamCommand::Goto {
        goals,
        travel_s: Some(40.0),
    };
    let p = steering.propose(&goto, t_goto).unwrap();
    steering.accept(p);
    let t_land = (steering.plan().end_s() * 100.0).ceil() / 100.0 + 2.0;
    let p = steering.propose(&TeamCommand::Land, t_land).unwrap();
    steering.accept(p);
    let mut commanded = s.clone();
    commanded.plan = steering.plan().clone();
    for t in [0.0, t_hold, t_goto, t_land] {
        let from = (t * s.file.comm_hz).round() as u64;
        let linear = max_follower_deviation_from(&commanded, from, 0).unwrap();
        let (flown, agent, tick) = flown_from(&commanded, from);
        let rel = (linear.max_m - flown).abs() / flown;
        eprintln!(
            "from {t} s: linear {} m, flown {flown} m, relative {rel:.1e}",
            linear.max_m
        );
        assert!(
            rel < 1e-9,
            "from {t} s: {linear:?} vs {flown} (agent {agent}, tick {tick})"
        );
        assert_eq!((linear.agent, linear.tick), (agent, tick), "from {t} s");
    }
}

/// With every state late, the delayed chains match the engine flying `[link] delay_ms`.
#[test]
fn the_commanded_deviation_with_a_delay_is_the_engines() {
    let s = Scenario::from_file(paper40(), "paper40", Checks::Full).unwrap();
    let mut steering = s.steering();
    let t_hold = (0.4 * s.plan.flight_end_s() * 100.0).round() / 100.0;
    let p = steering.propose(&TeamCommand::Hold, t_hold).unwrap();
    steering.accept(p);
    let mut commanded = crate::delay::at_delay(&s, 150.0);
    commanded.plan = steering.plan().clone();
    let from = (t_hold * s.file.comm_hz).round() as u64;
    let linear = max_follower_deviation_from(&commanded, from, 15).unwrap();
    let (flown, _, _) = flown_from(&commanded, from);
    let rel = (linear.max_m - flown).abs() / flown;
    eprintln!(
        "150 ms late from {t_hold} s: linear {} m, flown {flown} m, relative {rel:.1e}",
        linear.max_m
    );
    assert!(rel < 1e-6, "{linear:?} vs {flown}");
}
