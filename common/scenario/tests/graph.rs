//! Graph synthesis on built-in and generated teams: the farthest-point order and a fully linked
//! formation kept as given.

use cdm_math::{Real, Vec2};
use cdm_model::formation::{Formation, Role};
use cdm_model::graph::{farthest_point_order, synthesize, DEFAULT_WEIGHT_FLOOR};
use cdm_scenario::Scenario;

/// The order as first written (`Vec::remove` keeps the rest in id order, the first maximum
/// wins): the faster loop must give exactly this order, which fixes the graph and therefore
/// every flight.
fn reference_order(formation: &Formation, leaders: &[(u32, Vec2)]) -> Vec<(u32, Vec2)> {
    let mut left: Vec<(u32, Vec2, Real)> = formation
        .members
        .iter()
        .filter(|m| m.role == Role::Follower)
        .map(|m| {
            let d = leaders
                .iter()
                .map(|(_, q)| (q - m.planar).norm())
                .fold(Real::INFINITY, Real::min);
            (m.id, m.planar, d)
        })
        .collect();
    left.sort_by_key(|e| e.0);
    let mut order = Vec::new();
    while !left.is_empty() {
        let mut k = 0;
        for (i, e) in left.iter().enumerate() {
            if e.2 > left[k].2 {
                k = i;
            }
        }
        let (id, p, _) = left.remove(k);
        for e in &mut left {
            e.2 = e.2.min((e.1 - p).norm());
        }
        order.push((id, p));
    }
    order
}

#[test]
fn farthest_point_order_is_the_reference_order() {
    for s in [
        Scenario::builtin("paper40").unwrap(),
        Scenario::generated(300).unwrap(),
    ] {
        let leaders: Vec<(u32, Vec2)> = (s.formation.members.iter())
            .filter(|m| m.role.is_leader())
            .map(|m| (m.id, m.planar))
            .collect();
        assert_eq!(
            farthest_point_order(&s.formation, &leaders),
            reference_order(&s.formation, &leaders),
            "{}",
            s.origin
        );
    }
}

/// A member re-validates the orchestrator's scenario, every link given: synthesis keeps them.
#[test]
fn synthesis_keeps_a_fully_linked_formation() {
    let s = Scenario::generated(120).unwrap();
    let mut f = s.formation.clone();
    synthesize(&mut f, DEFAULT_WEIGHT_FLOOR).unwrap();
    assert_eq!(f, s.formation);
}
