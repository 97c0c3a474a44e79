//! Theorem 1 and 2 identities and graph synthesis on generated teams.

use cdm_model::formation::Role;
use cdm_model::graph::DEFAULT_WEIGHT_FLOOR;
use cdm_model::safety::{d_b, d_s};
use cdm_scenario::{Checks, Scenario};

#[test]
fn theorem_identities_on_generated_teams() {
    for n in [10usize, 40, 200] {
        let s = Scenario::generated(n).unwrap();
        assert_eq!(s.formation.members.len(), n);
        let c = s.formation.theorem_checks();
        assert!(c.l_max_real_eigenvalue < 0.0, "n={n}: L not Hurwitz: {c:?}");
        assert!(c.w_l_row_sum_error < 1e-10, "n={n}: {c:?}");
        assert!(c.w_l_alpha_error < 1e-10, "n={n}: {c:?}");
        assert!(c.eq21_relative_residual < 1e-10, "n={n}: {c:?}");
        for m in &s.formation.members {
            if m.role == Role::Follower {
                let link = m.link.expect("synthesised");
                assert!(
                    link.weights.iter().all(|w| *w >= DEFAULT_WEIGHT_FLOOR),
                    "n={n} agent {}: {:?}",
                    m.id,
                    link.weights
                );
                assert!((link.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            }
        }
        s.formation.check_links().unwrap();
        assert!(s.gains_margin.unwrap() > 0.0);
    }
}

/// The synthesised graph is acyclic (ERRATA 7): followers can be ordered so that each one's
/// in-neighbours are leaders or earlier followers, which is what lets every process of a team
/// run a whole window of ticks per wake-up. L's spectrum is then exactly {-1}.
#[test]
fn synthesised_graphs_are_acyclic_with_spectrum_minus_one() {
    for n in [10usize, 40, 250, 1000] {
        let s = Scenario::generated(n).unwrap();
        let mut done: std::collections::BTreeSet<u32> = s
            .formation
            .members
            .iter()
            .filter(|m| m.role.is_leader())
            .map(|m| m.id)
            .collect();
        let mut left: Vec<(u32, [u32; 3])> = s
            .formation
            .members
            .iter()
            .filter_map(|m| m.link.map(|l| (m.id, l.in_neighbors)))
            .collect();
        // Kahn's algorithm: peel off followers whose in-neighbours are all done.
        while !left.is_empty() {
            let before = left.len();
            left.retain(|(id, ins)| {
                let ready = ins.iter().all(|j| done.contains(j));
                if ready {
                    done.insert(*id);
                }
                !ready
            });
            assert!(left.len() < before, "n={n}: a cycle among {left:?}");
        }
        let c = s.formation.theorem_checks();
        assert_eq!(c.l_max_real_eigenvalue, -1.0, "n={n}: {c:?}");
    }
}

#[test]
fn paper40_projects_secondary_leaders_and_is_deterministic() {
    let a = Scenario::builtin("paper40").unwrap();
    let b = Scenario::builtin("paper40").unwrap();
    assert_eq!(a.to_toml(), b.to_toml());
    assert_eq!(a.content_hash(), b.content_hash());
    for id in [4, 5, 6] {
        assert!(
            a.notes
                .iter()
                .any(|n| n.starts_with(&format!("agent {id}: projected"))),
            "{:?}",
            a.notes
        );
    }
    // The flown file re-validates to the same scenario (idempotent).
    let again = Scenario::parse(&a.to_toml(), "roundtrip", Checks::Full).unwrap();
    assert_eq!(again.to_toml(), a.to_toml());
    assert!(d_b(&a.formation) > 3.0 && d_s(&a.formation) > 1.5);
    println!(
        "paper40: D_B = {:.4} m, D_S = {:.4} m",
        d_b(&a.formation),
        d_s(&a.formation)
    );
}

#[test]
#[ignore]
fn timing_generated() {
    for n in [10usize, 40, 200, 1000] {
        let t = std::time::Instant::now();
        let f = cdm_scenario::generated(n).unwrap();
        let t1 = t.elapsed();
        let s = Scenario::from_file(f, "x", Checks::Member).unwrap();
        let t2 = t.elapsed();
        let _ = cdm_model::gains::stability_margin(&s.file.gains, &s.formation.l_block());
        println!("n={n} gen {t1:?} member {t2:?} full {:?}", t.elapsed());
    }
}

/// `launch` hands its members scenario.json: read back, it is the very same scenario (same
/// canonical TOML, same hash), for the paper's team and a large generated one.
#[test]
fn a_scenario_read_back_from_json_has_the_same_hash() {
    for s in [
        Scenario::builtin("paper40").unwrap(),
        Scenario::generated(1000).unwrap(),
    ] {
        let back = Scenario::parse_json(&s.to_json(), "json", Checks::Member).unwrap();
        assert_eq!(back.to_toml(), s.to_toml(), "{}", s.file.name);
        assert_eq!(back.content_hash(), s.content_hash());
    }
    let err = Scenario::parse_json("{\"name\": 1}", "bad.json", Checks::Member).unwrap_err();
    assert!(
        err.to_string().starts_with("bad.json: malformed scenario"),
        "{err}"
    );
}

#[test]
fn readers_of_is_the_out_neighbors_entry() {
    let s = Scenario::generated(60).unwrap();
    let out = s.formation.out_neighbors();
    for m in &s.formation.members {
        assert_eq!(s.formation.readers_of(m.id), out[&m.id], "member {}", m.id);
    }
    assert!(out.values().any(|v| v.len() > 1));
    assert!(s.formation.readers_of(9999).is_empty());
}
