//! Communication graph synthesis: the paper assumes a graph (Fig. 2); users need one made for
//! them. For every follower pick exactly three in-neighbours whose triangle strictly contains it
//! with every weight (eq. 18) at least a floor.
//!
//! The graph is acyclic (ERRATA 7 allows it): followers are taken in farthest-point order (next
//! the follower farthest from every member already placed, the leaders first), and each picks its
//! in-neighbours among the members placed before it. Early followers are spread over the polygon
//! and later ones fill in between, so at every step the placed members surround the next follower
//! at about its distance to the nearest of them: triangles stay local (no follower reaches across
//! the formation, no member has hundreds of readers) at every scale, like the levels of a
//! multigrid. A follower's state for a tick then never waits, through a cycle, on its
//! own state for that tick, so in the multi-process team every member can run a whole window of
//! ticks on one wake-up once its in-neighbours have; with cycles every tick costs a round trip
//! of wake-ups around the cycle. It also makes the followers' block of L triangular with
//! spec(L) = {-1}.
//!
//! Reachability (Assumption 2) follows from strict containment: in any set S of followers, a
//! vertex p of conv(S) is not a positive combination of points of conv(S), so one of p's
//! in-neighbours lies outside S; no set of followers can be closed off from the leaders. It is
//! still checked (`Formation::check_links`).

use crate::formation::{triangle_weights, Formation, FormationError, Role};
use cdm_math::{Real, Vec2};

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

/// Candidate set sizes tried in turn (nearest members first).
const CANDIDATES: [usize; 4] = [10, 16, 28, 48];

/// Give every follower without in-neighbours a triangle: among the members placed before it (in
/// farthest-point order) nearest to it (distance, then id: deterministic), the triangle that
/// maximises the smallest weight, subject to weight >= floor.
pub fn synthesize(formation: &mut Formation, floor: Real) -> Result<(), SynthesisError> {
    let leaders: Vec<(u32, Vec2)> = formation
        .members
        .iter()
        .filter(|m| m.role.is_leader())
        .map(|m| (m.id, m.planar))
        .collect();
    // Every follower linked already (members re-validating the orchestrator's scenario): the
    // O(N^2) order below would change nothing. At N = 1000 it was most of a member's start-up.
    if formation
        .members
        .iter()
        .all(|m| m.role.is_leader() || m.link.is_some())
    {
        return Ok(());
    }
    let leader_ids: Vec<u32> = leaders.iter().map(|(l, _)| *l).collect();
    let mut placed = leaders.clone();
    for (id, p) in farthest_point_order(formation, &leaders) {
        if formation.member(id).is_some_and(|m| m.link.is_some()) {
            // In-neighbours given in the file are kept; the follower still serves later ones.
            placed.push((id, p));
            continue;
        }
        let ids = best_triangle(
            &p,
            &nearest_candidates(&placed, &p, &leader_ids),
            &leader_ids,
            floor,
        )
        .map_err(|best| SynthesisError { id, floor, best })?;
        // best_triangle only returns weights >= floor > 0, which set_link accepts.
        formation
            .set_link(id, ids)
            .map_err(|_: FormationError| SynthesisError {
                id,
                floor,
                best: Real::NAN,
            })?;
        placed.push((id, p));
    }
    Ok(())
}

/// Among `near` (candidates sorted by distance, then id), the triangle around `p` that maximises
/// the smallest weight (eq. 18), subject to weight >= floor: first among the k nearest for each k
/// of `CANDIDATES`, at last among the 16 nearest and every member of `leader_ids`. The outermost
/// followers along a straight edge of the polygon have nothing but the edge's ends (leaders)
/// beyond them, which is why leaders have the most readers (N = 1000: 36). Deterministic; the
/// ids come sorted. Err: the best smallest weight seen (for the message).
pub fn best_triangle(
    p: &Vec2,
    near: &[(Real, u32, Vec2)],
    leader_ids: &[u32],
    floor: Real,
) -> Result<[u32; 3], Real> {
    let mut best_any = Real::NEG_INFINITY;
    let passes = CANDIDATES
        .iter()
        .map(|&k| (k, false))
        .chain([(CANDIDATES[1], true)]);
    for (k, with_leaders) in passes {
        let cand: Vec<&(Real, u32, Vec2)> = near
            .iter()
            .enumerate()
            .filter(|(rank, (_, j, _))| *rank < k || (with_leaders && leader_ids.contains(j)))
            .map(|(_, c)| c)
            .collect();
        let kc = cand.len();
        let mut best: Option<([u32; 3], Real)> = None;
        for a in 0..kc {
            for b in a + 1..kc {
                for c in b + 1..kc {
                    let tri = [cand[a].2, cand[b].2, cand[c].2];
                    let Some(w) = triangle_weights(p, &tri) else {
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
        if let Some((ids, _)) = best {
            return Ok(ids);
        }
    }
    Err(best_any)
}

/// The followers in farthest-point order: each next one is the follower farthest from the
/// leaders and the followers before it (ties: the smaller id). O(N^2), deterministic.
pub fn farthest_point_order(formation: &Formation, leaders: &[(u32, Vec2)]) -> Vec<(u32, Vec2)> {
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
    let mut order = Vec::with_capacity(left.len());
    while !left.is_empty() {
        // The farthest, ties to the smaller id; `swap_remove` (not `remove`, which shifted the
        // rest on every pick) leaves `left` unordered, so the tie is decided by id here.
        let mut k = 0;
        for (i, e) in left.iter().enumerate() {
            let best = &left[k];
            if e.2 > best.2 || (e.2 == best.2 && e.0 < best.0) {
                k = i;
            }
        }
        let (id, p, _) = left.swap_remove(k);
        for e in &mut left {
            e.2 = e.2.min((e.1 - p).norm());
        }
        order.push((id, p));
    }
    order
}

/// `pts` by distance from `p`, then id.
pub fn nearest(pts: &[(u32, Vec2)], p: &Vec2) -> Vec<(Real, u32, Vec2)> {
    let mut near: Vec<(Real, u32, Vec2)> =
        pts.iter().map(|(j, q)| ((q - p).norm(), *j, *q)).collect();
    near.sort_by(by_distance_then_id);
    near
}

/// What [`best_triangle`] reads of [`nearest`]`(pts, p)`: its first `CANDIDATES`' largest
/// count, then the members of `leader_ids` ranked after them, in the same order (so
/// `best_triangle` sees the same candidates in the same order and picks the same triangle).
/// Selection instead of a sort of every point: repairing each single loss of N = 1000 to size
/// the services sorted all members for every follower it re-triangulated.
pub fn nearest_candidates(
    pts: &[(u32, Vec2)],
    p: &Vec2,
    leader_ids: &[u32],
) -> Vec<(Real, u32, Vec2)> {
    let mut near: Vec<(Real, u32, Vec2)> =
        pts.iter().map(|(j, q)| ((q - p).norm(), *j, *q)).collect();
    let k = CANDIDATES[CANDIDATES.len() - 1];
    if near.len() > k {
        near.select_nth_unstable_by(k, by_distance_then_id);
        let (head, tail) = near.split_at_mut(k);
        head.sort_by(by_distance_then_id);
        let mut leaders: Vec<(Real, u32, Vec2)> = tail
            .iter()
            .filter(|(_, j, _)| leader_ids.contains(j))
            .copied()
            .collect();
        leaders.sort_by(by_distance_then_id);
        near.truncate(k);
        near.extend(leaders);
    } else {
        near.sort_by(by_distance_then_id);
    }
    near
}

fn by_distance_then_id(a: &(Real, u32, Vec2), b: &(Real, u32, Vec2)) -> std::cmp::Ordering {
    a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
}
