//! Communication graph synthesis: the paper assumes a graph (Fig. 2); users need one made for
//! them. For every follower pick exactly three in-neighbours whose triangle strictly contains it
//! with every weight (eq. 18) at least a floor.
//!
//! The graph is acyclic (ERRATA 7 allows it): followers are taken from the leading polygon's
//! boundary inwards (an "onion" order) and each picks its in-neighbours among the leaders and the
//! followers before it. A follower's state for a tick then never waits, through a cycle, on its
//! own state for that tick, so in the multi-process team every agent can run a whole window of
//! ticks on one wake-up once its in-neighbours have; with cycles every tick costs a round trip
//! of wake-ups around the cycle. It also makes the followers' block of L triangular with
//! spec(L) = {-1}.
//!
//! Reachability (Assumption 2) follows from strict containment: in any set S of followers, a
//! vertex p of conv(S) is not a positive combination of points of conv(S), so one of p's
//! in-neighbours lies outside S; no set of followers can be closed off from the leaders. It is
//! still checked (`Formation::check_links`).

use crate::formation::{triangle_weights, Formation, FormationError, Role};
use crate::geometry::signed_boundary_distance;
use crate::math::{Real, Vec2};

/// Default smallest communication weight a synthesised graph may use.
pub const DEFAULT_WEIGHT_FLOOR: Real = 0.05;

/// No triangle of candidates gives a follower weights above the floor.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("follower {id}: no three agents form a triangle around it with every weight >= {floor} (best smallest weight {best:.4}); move it away from the polygon's edge or lower weight_floor")]
pub struct SynthesisError {
    pub id: u32,
    pub floor: Real,
    pub best: Real,
}

/// Candidate set sizes tried in turn (nearest agents first).
const CANDIDATES: [usize; 4] = [10, 16, 28, 48];

/// Give every follower without in-neighbours a triangle: among its nearest agents (distance, then
/// id: deterministic) and the leaders, the triangle that maximises the smallest weight, subject to weight >= floor.
pub fn synthesize(formation: &mut Formation, floor: Real) -> Result<(), SynthesisError> {
    let leaders: Vec<u32> = formation
        .members
        .iter()
        .filter(|m| m.role.is_leader())
        .map(|m| m.id)
        .collect();
    let mut placed: Vec<(u32, Vec2)> = formation
        .members
        .iter()
        .filter(|m| m.role.is_leader())
        .map(|m| (m.id, m.planar))
        .collect();
    for (id, p) in onion_order(formation) {
        if formation.member(id).is_some_and(|m| m.link.is_some()) {
            // In-neighbours given in the file are kept; the follower still serves later ones.
            placed.push((id, p));
            continue;
        }
        let near = nearest(&placed, &p);
        let mut best: Option<([u32; 3], Real)> = None;
        let mut best_any = Real::NEG_INFINITY;
        for &k in &CANDIDATES {
            let k = k.min(near.len());
            // The k nearest agents plus every leader: a follower on the outer ring of a lattice
            // has nothing but leaders beyond it.
            let cand: Vec<&(Real, u32, Vec2)> = near
                .iter()
                .enumerate()
                .filter(|(rank, (_, j, _))| *rank < k || leaders.contains(j))
                .map(|(_, c)| c)
                .collect();
            let kc = cand.len();
            best = None;
            for a in 0..kc {
                for b in a + 1..kc {
                    for c in b + 1..kc {
                        let tri = [cand[a].2, cand[b].2, cand[c].2];
                        let Some(w) = triangle_weights(&p, &tri) else {
                            continue;
                        };
                        let min_w = w[0].min(w[1]).min(w[2]);
                        best_any = best_any.max(min_w);
                        if min_w >= floor && best.is_none_or(|(_, m)| min_w > m) {
                            let mut ids = [cand[a].1, cand[b].1, cand[c].1];
                            ids.sort_unstable();
                            best = Some((ids, min_w));
                        }
                    }
                }
            }
            if best.is_some() || k == near.len() {
                break;
            }
        }
        let Some((ids, _)) = best else {
            return Err(SynthesisError {
                id,
                floor,
                best: best_any,
            });
        };
        formation
            .set_link(id, ids)
            .map_err(|_: FormationError| SynthesisError {
                id,
                floor,
                best: best_any,
            })?;
        placed.push((id, p));
    }
    Ok(())
}

/// The followers from the leading polygon's boundary inwards (distance to the boundary, then
/// id: deterministic).
fn onion_order(formation: &Formation) -> Vec<(u32, Vec2)> {
    let polygon = formation.polygon_points();
    let mut order: Vec<(Real, u32, Vec2)> = formation
        .members
        .iter()
        .filter(|m| m.role == Role::Follower)
        .map(|m| {
            let depth = signed_boundary_distance(&m.planar, &polygon);
            (depth, m.id, m.planar)
        })
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    order.into_iter().map(|(_, id, p)| (id, p)).collect()
}

/// `pts` by distance from `p`, then id.
fn nearest(pts: &[(u32, Vec2)], p: &Vec2) -> Vec<(Real, u32, Vec2)> {
    let mut near: Vec<(Real, u32, Vec2)> =
        pts.iter().map(|(j, q)| ((q - p).norm(), *j, *q)).collect();
    near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    near
}
