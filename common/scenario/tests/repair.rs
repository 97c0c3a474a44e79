//! Graph repair on the paper's team and a generated one: eq. 18 and Theorem 1 after every loss,
//! determinism, degraded followers.

use std::collections::BTreeSet;

use cdm_math::{Real, Vec3};
use cdm_model::graph::DEFAULT_WEIGHT_FLOOR;
use cdm_model::repair::{repair, unreachable, Repair};
use cdm_scenario::Scenario;

fn lose(s: &Scenario, ids: &[u32]) -> Repair {
    repair(
        &s.formation,
        DEFAULT_WEIGHT_FLOOR,
        &ids.iter().copied().collect(),
    )
}

/// eq. 18: the new weights reproduce the follower's t0 position from its new in-neighbours'.
/// Theorem 1: with them r_i,HT(t) = sum_j w_ij r_j,HT(t) at every t, i.e. the survivors'
/// desired configuration is the fixed point of the repaired graph, unchanged.
fn check_repaired(s: &Scenario, r: &Repair) {
    let f = &r.formation;
    assert!(unreachable(f, &r.lost).is_empty());
    let mut ht = Vec::new();
    for m in &f.members {
        let Some(link) = m.link else { continue };
        if r.lost.contains(&m.id) {
            continue;
        }
        assert!(
            link.in_neighbors.iter().all(|j| !r.lost.contains(j)),
            "follower {} still reads a lost member",
            m.id
        );
        let sum: Real = link.weights.iter().sum();
        assert!((sum - 1.0).abs() < 1e-12);
        let mut p0 = Vec3::zeros();
        for (j, w) in link.in_neighbors.iter().zip(link.weights) {
            p0 += f.member(*j).map(|n| n.position).unwrap_or_default() * w;
        }
        assert!((p0 - m.position).norm() < 1e-9, "eq. 18 for {}", m.id);
    }
    for t in [0.0, 0.3, 0.5, 0.9, 1.2].map(|x| x * s.file.t_total_s) {
        s.desired_positions(t, &mut ht);
        for (k, m) in f.members.iter().enumerate() {
            let Some(link) = m.link else { continue };
            if r.lost.contains(&m.id) {
                continue;
            }
            let mut rd = Vec3::zeros();
            for (j, w) in link.in_neighbors.iter().zip(link.weights) {
                rd += ht[f.index_of(*j).unwrap()] * w;
            }
            assert!(
                (rd - ht[k]).norm() < 1e-7,
                "Theorem 1 for {} at t={t}",
                m.id
            );
        }
    }
}

#[test]
fn every_single_loss_of_paper40_repairs_with_eq18_and_theorem1() {
    let s = Scenario::builtin("paper40").unwrap();
    for m in &s.formation.members {
        let r = lose(&s, &[m.id]);
        check_repaired(&s, &r);
        let readers = s.formation.out_neighbors()[&m.id].len();
        assert_eq!(
            r.retriangulated.len() + r.degraded.len(),
            readers,
            "loss of {}",
            m.id
        );
        for x in &r.retriangulated {
            assert!(x.old.contains(&m.id) && !x.new.contains(&m.id));
            let w = r.formation.member(x.id).unwrap().link.unwrap().weights;
            assert!(w.iter().all(|w| *w >= DEFAULT_WEIGHT_FLOOR));
        }
    }
}

#[test]
fn repair_is_deterministic_and_keeps_unaffected_links() {
    let s = Scenario::generated(120).unwrap();
    let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
    let lost = [ids[1], ids[40], ids[77]];
    let a = lose(&s, &lost);
    let b = lose(&s, &[lost[2], lost[0], lost[1]]);
    assert_eq!(a, b);
    check_repaired(&s, &a);
    let changed: BTreeSet<u32> = a
        .retriangulated
        .iter()
        .map(|x| x.id)
        .chain(a.degraded.iter().copied())
        .collect();
    for (m, before) in a.formation.members.iter().zip(&s.formation.members) {
        if !changed.contains(&m.id) {
            assert_eq!(m.link, before.link, "follower {} changed", m.id);
        }
    }
}

#[test]
fn follower_without_a_valid_triangle_degrades_to_its_plan() {
    let s = Scenario::builtin("paper40").unwrap();
    // The smallest of three weights summing to 1 is at most 1/3: no triangle meets 0.34.
    let r = repair(&s.formation, 0.34, &[s.formation.members[0].id].into());
    check_repaired(&s, &r);
    assert!(!r.degraded.is_empty());
    for id in &r.degraded {
        assert!(r.formation.member(*id).unwrap().link.is_none());
    }
}

#[test]
fn no_loss_no_change() {
    let s = Scenario::builtin("paper40").unwrap();
    let r = lose(&s, &[]);
    assert_eq!(r.formation, s.formation);
    assert!(r.retriangulated.is_empty() && r.degraded.is_empty());
}
