use super::*;
use crate::plan::tests::paper_plan;
use crate::plan::Derivs;

const DT: Real = 0.01;

fn settings() -> SteerSettings {
    SteerSettings {
        dt_s: DT,
        min_travel_s: 0.5,
        ground_z_m: 0.0,
        landing_t_s: None,
    }
}

fn at(plan: &TeamPlan, t: Real) -> [Derivs; 3] {
    plan.primary_derivs(t, plan.piece_at(t))
}

/// The paper's plan with a take-off before it and a landing after it.
fn mission() -> TeamPlan {
    let one = paper_plan(100.0);
    let ground = |a: [Vec3; 3]| a.map(|p| Vec3::new(p.x, p.y, 0.0));
    let (a, b) = (one.start, one.goal);
    let phases = vec![
        Phase::rest_to_rest(PhaseKind::Takeoff, 0.0, 50.0, ground(a), a),
        Phase::rest_to_rest(PhaseKind::Segment(1), 55.0, 100.0, a, b),
        Phase::rest_to_rest(PhaseKind::Landing, 160.0, 60.0, b, ground(b)),
    ];
    one.with_phases(phases)
}

/// Position, velocity and acceleration are continuous everywhere; before the switch the plan
/// is the one flown, bit for bit.
fn assert_switches_smoothly(before: &TeamPlan, after: &TeamPlan, t_sw: Real) {
    for t in [0.0, 0.3 * t_sw, t_sw - DT, t_sw] {
        assert_eq!(at(before, t), at(after, t), "t = {t}");
    }
    for t in (1..40_000).map(|k| k as Real * DT * 0.5) {
        let (a, b) = (at(after, t - 1e-7), at(after, t + 1e-7));
        for i in 0..3 {
            for d in 0..3 {
                let scale = 1.0 + a[i][d].norm();
                assert!(
                    (a[i][d] - b[i][d]).norm() < 1e-4 * scale,
                    "t {t} leader {i} d{d}: {:?} vs {:?}",
                    a[i][d],
                    b[i][d]
                );
            }
        }
    }
}

#[test]
fn a_hold_stops_along_the_segment_no_faster_than_the_plan() {
    let plan = paper_plan(100.0);
    let steer = Steering::new(plan.clone(), settings());
    let t_sw = 30.0;
    let p = steer.propose(&TeamCommand::Hold, t_sw).unwrap();
    assert_switches_smoothly(&plan, &p.plan, t_sw);
    assert!(p.t_rest_s > t_sw && p.t_rest_s < 100.0, "{}", p.t_rest_s);
    // The run goes on hovering as long as the launched flight would have.
    assert_eq!(p.plan.flight_end_s(), 100.0);
    let peak = (0..10_000)
        .map(|k| at(&plan, k as Real * DT)[0][2].norm())
        .fold(0.0, Real::max);
    let seg = plan.goal[0] - plan.start[0];
    for k in 0..10_000 {
        let t = k as Real * DT;
        let d = at(&p.plan, t);
        assert!(d[0][2].norm() <= peak * (1.0 + 1e-6), "t {t}");
        // Still on the straight segment, and never back along it.
        let off = d[0][0] - plan.start[0];
        assert!(off.cross(&seg).norm() < 1e-9 * seg.norm_squared());
        assert!(d[0][1].dot(&seg) >= -1e-12);
        if t >= p.t_rest_s {
            assert!(d[0][1].norm() < 1e-12 && (d[0][0] - p.held_at[0]).norm() < 1e-9);
        }
    }
    // Late in the segment the quintic brakes sooner than any stop: the hold keeps it.
    let late = steer.propose(&TeamCommand::Hold, 70.0).unwrap();
    assert_eq!(late.t_rest_s, 100.0);
    assert_eq!(late.plan.phases(), plan.phases());
}

#[test]
fn goto_after_a_hold_ends_at_the_goals_and_resume_returns_to_the_route() {
    let plan = paper_plan(100.0);
    let mut steer = Steering::new(plan.clone(), settings());
    let hold = steer.propose(&TeamCommand::Hold, 20.0).unwrap();
    steer.accept(hold.clone());
    let goals = hold.held_at.map(|p| p + Vec3::new(30.0, 0.0, 0.0));
    // While moving, a goto holds first: the same stop.
    let t_sw = 25.0;
    let goto = TeamCommand::Goto {
        goals,
        travel_s: Some(40.0),
    };
    let g = steer.propose(&goto, t_sw).unwrap();
    assert_eq!(g.t_rest_s, hold.t_rest_s);
    assert_switches_smoothly(&hold.plan, &g.plan, t_sw);
    let end = g.t_rest_s + 40.0;
    assert_eq!(g.plan.end_s(), end);
    let d = at(&g.plan, end + 1.0);
    for i in 0..3 {
        assert!((d[i][0] - goals[i]).norm() < 1e-9 && d[i][1].norm() < 1e-12);
    }
    assert_eq!(g.plan.phases()[g.first_new].kind, PhaseKind::Segment(2));
    steer.accept(g);
    // Resume: back to the goal of the interrupted segment, then hover until the flight's end.
    let t_r = end + 5.0;
    let r = steer.propose(&TeamCommand::Resume, t_r).unwrap();
    let last = *r.plan.phases().last().unwrap();
    assert_eq!(last.goal, plan.goal);
    assert_eq!(last.t_start_s, t_r);
    let d = at(&r.plan, r.plan.end_s());
    for (d, goal) in d.iter().zip(plan.goal) {
        assert!((d[0] - goal).norm() < 1e-9);
    }
    steer.accept(r);
    assert_eq!(
        steer.propose(&TeamCommand::Resume, steer.plan().end_s()),
        Err(NotApplicable::NotHeld)
    );
    // A default travel time: the fastest leader's peak acceleration is the plan's own.
    let back = TeamCommand::Goto {
        goals: plan.start,
        travel_s: None,
    };
    let g = steer.propose(&back, steer.plan().end_s()).unwrap();
    let t_s = g.plan.phases()[g.first_new].quintic.t_total_s;
    let full = max_distance(&plan.start, &plan.goal);
    assert!((t_s - 100.0).abs() < 1e-9 * 100.0, "{t_s} for {full} m");
}

#[test]
fn a_resumed_mission_keeps_its_later_phases_and_lands() {
    let plan = mission();
    let mut steer = Steering::new(plan.clone(), settings());
    let h = steer.propose(&TeamCommand::Hold, 80.0).unwrap();
    steer.accept(h.clone());
    let r = steer
        .propose(&TeamCommand::Resume, h.t_rest_s + 10.0)
        .unwrap();
    let kinds: Vec<PhaseKind> = r.plan.phases().iter().map(|p| p.kind).collect();
    use PhaseKind::*;
    assert_eq!(
        kinds,
        [Takeoff, Segment(1), Segment(1), Segment(1), Landing]
    );
    let back = r.plan.phases()[3];
    let landing = r.plan.phases()[4];
    // The 5 s hover before the landing is kept.
    assert!((landing.t_start_s - back.t_end_s() - 5.0).abs() < 1e-9);
    assert_eq!(landing.goal, plan.phases()[2].goal);
    assert_eq!(
        r.plan.flight_end_s(),
        landing.t_end_s() + crate::plan::LANDING_SETTLE_S
    );
    // Land from the air: straight down from where the team holds.
    let l = steer.propose(&TeamCommand::Land, 100.0).unwrap();
    let last = *l.plan.phases().last().unwrap();
    assert_eq!(last.kind, Landing);
    for i in 0..3 {
        assert_eq!(last.goal[i], Vec3::new(l.held_at[i].x, l.held_at[i].y, 0.0));
    }
}

#[test]
fn commands_that_do_not_apply_say_why() {
    let plan = mission();
    let steer = Steering::new(plan.clone(), settings());
    let goals = plan.goal;
    let goto = TeamCommand::Goto {
        goals,
        travel_s: None,
    };
    assert!(matches!(
        steer.propose(&goto, 10.0),
        Err(NotApplicable::NotAirborne { .. })
    ));
    assert!(matches!(
        steer.propose(&goto, 0.0),
        Err(NotApplicable::NotAirborne { .. })
    ));
    assert!(steer.propose(&goto, 52.0).is_ok());
    assert_eq!(
        steer.propose(&TeamCommand::Resume, 60.0),
        Err(NotApplicable::NotHeld)
    );
    assert_eq!(
        steer.propose(&TeamCommand::Land, 170.0),
        Err(NotApplicable::Landing)
    );
    assert!(matches!(
        steer.propose(&TeamCommand::Land, 0.0),
        Err(NotApplicable::OnGround { .. })
    ));
    assert!(matches!(
        steer.propose(&TeamCommand::Hold, 500.0),
        Err(NotApplicable::Ended { .. })
    ));
}
