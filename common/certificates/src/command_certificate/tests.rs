use super::*;
use cdm_math::Vec3;
use cdm_scenario::{paper40, Checks};

fn team() -> (Scenario, SafetyNumbers, Steering) {
    let s = Scenario::from_file(paper40(), "paper40", Checks::Full).unwrap();
    let n = SafetyNumbers::of(&s);
    let steering = s.steering();
    (s, n, steering)
}

fn accepted(o: &CommandOutcome) -> &CommandCertificate {
    match o {
        CommandOutcome::Accepted(c) => c,
        other => panic!("not accepted: {other:?}"),
    }
}

/// Held, refused an UNSAFE goto (nothing changes), sent to a SAFE goto, landed.
#[test]
fn held_refused_sent_and_landed() {
    let (s, n, mut steering) = team();
    let t_end = s.plan.flight_end_s();
    let hold = steer(&mut steering, &s, &n, &TeamCommand::Hold, 0.3 * t_end);
    let c = accepted(&hold);
    assert_eq!(c.phases.len(), 1, "{c:?}");
    assert!(c.phases[0].name.ends_with("(hold)"));
    assert!(c.max_follower_deviation_m <= n.delta_m);
    let held = steering.plan().clone();
    let at = |p: &cdm_model::plan::TeamPlan| {
        let t = p.end_s();
        p.primary_derivs(t, p.piece_at(t)).map(|d| d[0])
    };
    let here = at(&held);
    // Squeeze the triangle to a sliver: lambda_1 falls below lambda_CD,min.
    let mid = (here[1] + here[2]) * 0.5;
    let sliver = [
        here[0],
        mid + (here[1] - mid) * 0.05,
        mid + (here[2] - mid) * 0.05,
    ];
    let t1 = held.end_s() + 1.0;
    let unsafe_goto = TeamCommand::Goto {
        goals: sliver,
        travel_s: Some(100.0),
    };
    match steer(&mut steering, &s, &n, &unsafe_goto, t1) {
        CommandOutcome::Refused(c) => {
            assert_eq!(c.verdict, Verdict::Unsafe);
            assert!(c.reasons.iter().any(|r| r.contains("eq. 37")), "{c:?}");
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(steering.plan(), &held);
    // Too quick: the followers cannot keep up (T_threshold, eq. 34).
    let shift = here.map(|p| p + Vec3::new(200.0, 0.0, 0.0));
    let rushed = TeamCommand::Goto {
        goals: shift,
        travel_s: Some(1.0),
    };
    match steer(&mut steering, &s, &n, &rushed, t1) {
        CommandOutcome::Refused(c) => assert!(c.reasons.iter().any(|r| r.contains("eq. 34"))),
        other => panic!("{other:?}"),
    }
    assert_eq!(steering.plan(), &held);
    let safe_goto = TeamCommand::Goto {
        goals: shift,
        travel_s: None,
    };
    accepted(&steer(&mut steering, &s, &n, &safe_goto, t1));
    let there = at(steering.plan());
    for i in 0..3 {
        assert!((there[i] - shift[i]).norm() < 1e-9);
    }
    let t2 = steering.plan().end_s();
    let land = steer(&mut steering, &s, &n, &TeamCommand::Land, t2);
    let c = accepted(&land);
    assert!(c.phases.iter().any(|p| p.name == "landing"), "{c:?}");
    let down = at(steering.plan());
    assert!(down.iter().all(|p| p.z == 0.0));
}

/// A command file: checked fields, switch ticks, goals in ascending id order, and a run's
/// `commands.json` (with the fields a run adds) read back as it is.
#[test]
fn a_command_file_is_checked_and_read_back() {
    let (s, _, _) = team();
    let ok = r#"[{"at_s": 10.004, "command": "hold"},
                 {"at_s": 20, "command": "goto", "goals": [[0,0,500],[10,0,500],[0,10,500]],
                  "travel_s": 50, "switch_tick": 2000, "verdict": "SAFE", "accepted": true}]"#;
    let cs = cdm_scenario::parse_commands(ok, &s).unwrap();
    let hz = s.file.comm_hz;
    assert_eq!(cs[0].switch_tick, (10.004 * hz - 1e-9).ceil() as u64);
    assert!(matches!(cs[1].command, TeamCommand::Goto { travel_s: Some(t), .. } if t == 50.0));
    for (text, field) in [
        (
            r#"[{"at_s": 1, "command": "hover"}]"#,
            "commands[0].command",
        ),
        (r#"[{"at_s": -1, "command": "hold"}]"#, "commands[0].at_s"),
        (
            r#"[{"at_s": 1, "command": "goto", "goals": [[0,0,1]]}]"#,
            "commands[0].goals",
        ),
        (
            r#"[{"at_s": 1, "command": "hold", "goals": [[0,0,1]]}]"#,
            "commands[0].goals",
        ),
        (
            r#"[{"at_s": 1, "command": "hold"}, {"at_s": 1, "command": "land"}]"#,
            "commands[1].at_s",
        ),
        (
            r#"[{"at_s": 1, "command": "goto", "goals": [[0,0,1],[1,0,1],[0,1,1]], "travel_s": 0}]"#,
            "commands[0].travel_s",
        ),
    ] {
        let e = cdm_scenario::parse_commands(text, &s)
            .unwrap_err()
            .to_string();
        assert!(e.contains(field), "{text}: {e}");
    }
    let e = cdm_scenario::parse_commands(r#"[{"at_s": 1, "command": "hold", "when": 2}]"#, &s)
        .unwrap_err()
        .to_string();
    assert!(e.contains("when"), "{e}");
}

/// The vehicles' limits hold over a command's motion too: with a horizontal speed limit the
/// team's own plan meets, a goto that would need more is refused naming the limit, and the plan
/// is unchanged; given time enough it is accepted.
#[test]
fn a_goto_faster_than_the_vehicles_can_fly_is_refused() {
    let mut file = paper40();
    file.vehicle = Some(cdm_scenario::VehicleSpec {
        max_speed_xy_m_s: Some(20.0),
        ..Default::default()
    });
    let s = Scenario::from_file(file, "paper40", Checks::Full).unwrap();
    let n = SafetyNumbers::of(&s);
    let mut steering = s.steering();
    let t_end = s.plan.flight_end_s();
    accepted(&steer(
        &mut steering,
        &s,
        &n,
        &TeamCommand::Hold,
        0.3 * t_end,
    ));
    let held = steering.plan().clone();
    let t = held.end_s();
    let here = held.primary_derivs(t, held.piece_at(t)).map(|d| d[0]);
    // Every leader shifted by the same 300 m: each member's D_i, a combination of the leaders'
    // with weights summing to 1 (eq. 13), is that shift, so in 20 s each peaks at
    // 1.875 * 300 / 20 = 28.1 m/s horizontally.
    let shift = here.map(|p| p + Vec3::new(300.0, 0.0, 0.0));
    let rushed = TeamCommand::Goto {
        goals: shift,
        travel_s: Some(20.0),
    };
    match steer(&mut steering, &s, &n, &rushed, t + 1.0) {
        CommandOutcome::Refused(c) => {
            let why = c.reasons.join("; ");
            assert!(why.contains("vehicle limit max_speed_xy_m_s"), "{why}");
            assert!(c.vehicle.is_some());
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(steering.plan(), &held);
}

/// The team keeps the safety numbers it was launched with through commands: paper40-mission
/// landed during its take-off no longer flies the segment where its lambda_1 is smallest,
/// yet its lambda_CD,min and delta (eqs. 37-38), the audit's limits and the next command's, stay
/// the launched ones, in a live audit (`replan`) and in one of the commanded plan from the start
/// (`simulate --commands`) alike.
#[test]
fn a_commanded_team_keeps_the_numbers_it_was_launched_with() {
    use cdm_records::audit::Auditor;
    let s = Scenario::builtin("paper40-mission").unwrap();
    let n = SafetyNumbers::of(&s);
    let mut steering = s.steering();
    let first = (s.plan.phases().iter())
        .find(|p| p.kind == cdm_model::plan::PhaseKind::Segment(1))
        .copied()
        .unwrap();
    // During the take-off, before the segment: a phase cut short by a hold is still certified
    // over its whole segment (a superset of what is flown), so landing within the segment would
    // keep its smallest lambda_1.
    let t = (0.5 * first.t_start_s).round();
    accepted(&steer(&mut steering, &s, &n, &TeamCommand::Land, t));
    let mut flown = s.clone();
    flown.plan = steering.plan().clone();
    // The commanded plan's own smallest lambda_1 is not the launched one's.
    // (Here it has none: a take-off and a landing are ground phases.)
    let own = flown.plan.lambda1_min_segments().ok().map(|m| m.0.lambda1);
    assert!(
        own.is_none_or(|l| l > n.lambda1_min + 1e-6),
        "{own:?} vs {}",
        n.lambda1_min
    );
    assert_eq!(SafetyNumbers::of(&flown), n);
    let mut live = Auditor::new(&s);
    live.replan(&flown);
    assert_eq!(live.numbers(), &n);
    assert_eq!(Auditor::new(&flown).numbers(), &n);
}
