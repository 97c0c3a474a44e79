//! Graph repair after a loss: every follower that read a lost member picks a new enclosing
//! triangle among the survivors, with the rules of synthesis (`graph::best_triangle`).
//!
//! Why this keeps the team's desired configuration: the weights of eq. 18 depend only on the
//! t0 positions, and r_HT is an affine function of them (eq. 13), so for any triangle that
//! strictly contains follower i at t0, r_i,HT(t) = sum_j w_ij r_j,HT(t) at every t. Theorem 1
//! therefore still holds for the survivors with the new weights: only the tracking transient
//! changes, bounded by the new in-neighbours' own tracking errors.
//!
//! The result is a deterministic function of (formation, floor, set of lost members): the
//! affected followers are taken in synthesis order (farthest-point, `graph`), candidates sorted
//! by distance then id. A follower first looks among the survivors that do not read it, directly
//! or through others (no cycle: the acyclic graph stays acyclic), then among every survivor.
//! Reachability from the leaders (Assumption 2) follows from strict containment as in `graph`,
//! and is checked. A follower with no valid triangle is "degraded": it drops its link and tracks
//! its own r_HT from Q(t), d(t) open-loop, exactly as a leader does (`step::law_for`), so it
//! stays a valid in-neighbour for others.

use std::collections::BTreeSet;

use serde::Serialize;

use crate::formation::{Formation, Role};
use crate::graph::{best_triangle, farthest_point_order, nearest_candidates};
use cdm_math::{Real, Vec2};

/// A follower that switched to a new triangle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Retriangulation {
    pub id: u32,
    /// In-neighbours before the repair (one or more of them lost).
    pub old: [u32; 3],
    /// The new in-neighbours, all survivors, sorted.
    pub new: [u32; 3],
}

/// The survivors' graph after a set of members was lost.
#[derive(Debug, Clone, PartialEq)]
pub struct Repair {
    /// The formation with the repaired links: re-triangulated followers carry their new link
    /// (weights of eq. 18), degraded ones none; lost members keep theirs (they no longer fly).
    pub formation: Formation,
    pub lost: BTreeSet<u32>,
    /// Followers that switched triangles, by id.
    pub retriangulated: Vec<Retriangulation>,
    /// Followers with no valid triangle left: they fly their own plan (sorted ids).
    pub degraded: Vec<u32>,
}

/// Repair `formation` for the loss of `lost` (ids that are not members are ignored).
pub fn repair(formation: &Formation, floor: Real, lost: &BTreeSet<u32>) -> Repair {
    repair_in_order(formation, floor, lost, &synthesis_order(formation))
}

/// The followers in synthesis order (`graph::farthest_point_order` from every leader): what
/// [`repair_in_order`] takes. It depends on the t0 positions and roles only, not on the links
/// or the losses, so a caller repairing many loss sets computes it once (O(N^2)).
pub fn synthesis_order(formation: &Formation) -> Vec<(u32, Vec2)> {
    let leaders: Vec<(u32, Vec2)> = formation
        .members
        .iter()
        .filter(|m| m.role.is_leader())
        .map(|m| (m.id, m.planar))
        .collect();
    farthest_point_order(formation, &leaders)
}

/// [`repair`] with the synthesis order given (`order` must be [`synthesis_order`] of
/// `formation`): the same result.
pub fn repair_in_order(
    formation: &Formation,
    floor: Real,
    lost: &BTreeSet<u32>,
    order: &[(u32, Vec2)],
) -> Repair {
    let mut f = formation.clone();
    // Built once and kept current as links change: a table per walk was a third of the
    // orchestrator's start-up CPU at N = 1000 (its N single-loss repairs).
    let mut table = ReaderTable::of(&f);
    let (mut retriangulated, mut degraded) =
        relink_affected(&mut f, &mut table, floor, lost, order.iter().copied());
    // Strict containment makes every survivor reachable (see `graph`); should that ever fail,
    // the unreachable ones fly their plan rather than follow nobody.
    for id in unreachable_in(&f, &table, lost) {
        degrade(&mut f, id);
        degraded.push(id);
    }
    degraded.sort_unstable();
    retriangulated.sort_by_key(|x| x.id);
    Repair {
        formation: f,
        lost: lost.clone(),
        retriangulated,
        degraded,
    }
}

/// Every follower of `candidates` (in synthesis order) that read a lost member picks a new
/// triangle, or is degraded: `f` and `table` are changed as it goes (a later follower must not
/// pick one that now reads it). Returns the re-triangulated and the degraded ones.
fn relink_affected(
    f: &mut Formation,
    table: &mut ReaderTable,
    floor: Real,
    lost: &BTreeSet<u32>,
    candidates: impl Iterator<Item = (u32, Vec2)>,
) -> (Vec<Retriangulation>, Vec<u32>) {
    let leader_ids: Vec<u32> = f
        .members
        .iter()
        .filter(|m| m.role.is_leader() && !lost.contains(&m.id))
        .map(|m| m.id)
        .collect();
    let mut retriangulated = Vec::new();
    let mut degraded = Vec::new();
    for (id, p) in candidates {
        let Some(old) = f.member(id).and_then(|m| m.link) else {
            continue;
        };
        if lost.contains(&id) || !old.in_neighbors.iter().any(|j| lost.contains(j)) {
            continue;
        }
        let downstream = reader_mask(f, table, id, lost);
        let (mut survivors, mut acyclic) = (Vec::new(), Vec::new());
        for (k, m) in f.members.iter().enumerate() {
            if m.id != id && !lost.contains(&m.id) {
                survivors.push((m.id, m.planar));
                if !downstream[k] {
                    acyclic.push((m.id, m.planar));
                }
            }
        }
        let near = |pts: &[(u32, Vec2)]| nearest_candidates(pts, &p, &leader_ids);
        let pick = best_triangle(&p, &near(&acyclic), &leader_ids, floor)
            .or_else(|_| best_triangle(&p, &near(&survivors), &leader_ids, floor));
        let set = pick
            .ok()
            .and_then(|new| f.set_link(id, new).ok().map(|()| new));
        match set {
            Some(new) => {
                table.relink(f, id, Some(old.in_neighbors), Some(new));
                retriangulated.push(Retriangulation {
                    id,
                    old: old.in_neighbors,
                    new,
                });
            }
            None => {
                degrade(f, id);
                table.relink(f, id, Some(old.in_neighbors), None);
                degraded.push(id);
            }
        }
    }
    (retriangulated, degraded)
}

/// The repairs of many single losses, one after another on one working copy of the formation
/// (each undone before the next): the re-triangulations of [`repair_in_order`] with one member
/// lost, without its copy of the formation, its reader table and its walk of every follower
/// per loss (sizing the services for each single loss of N = 1000 spent most of its time
/// there).
pub struct SingleLosses<'a> {
    original: &'a Formation,
    f: Formation,
    table: ReaderTable,
    floor: Real,
    /// Each follower's place in the synthesis order, by member index.
    rank: Vec<usize>,
    order: &'a [(u32, Vec2)],
}

impl<'a> SingleLosses<'a> {
    /// `order` must be [`synthesis_order`] of `formation`.
    pub fn new(formation: &'a Formation, floor: Real, order: &'a [(u32, Vec2)]) -> Self {
        let mut rank = vec![usize::MAX; formation.members.len()];
        for (r, (id, _)) in order.iter().enumerate() {
            if let Some(k) = formation.index_of(*id) {
                rank[k] = r;
            }
        }
        SingleLosses {
            original: formation,
            f: formation.clone(),
            table: ReaderTable::of(formation),
            floor,
            rank,
            order,
        }
    }

    /// [`Repair::retriangulated`] of [`repair_in_order`] for the loss of `id` alone.
    pub fn retriangulated(&mut self, id: u32) -> Vec<Retriangulation> {
        let Some(k) = self.f.index_of(id) else {
            return Vec::new();
        };
        // Only the lost member's readers are affected; walked in synthesis order as the full
        // repair walks them.
        let mut ranks: Vec<usize> = self.table.row(k).iter().map(|&r| self.rank[r]).collect();
        ranks.sort_unstable();
        let order = self.order;
        let affected = ranks.into_iter().filter_map(|r| order.get(r).copied());
        let lost = BTreeSet::from([id]);
        let (mut retriangulated, degraded) =
            relink_affected(&mut self.f, &mut self.table, self.floor, &lost, affected);
        // Undone in reverse, each member back to its original link.
        for x in retriangulated.iter().rev() {
            self.restore(x.id, Some(x.new));
        }
        for &d in degraded.iter().rev() {
            self.restore(d, None);
        }
        retriangulated.sort_by_key(|x| x.id);
        retriangulated
    }

    fn restore(&mut self, id: u32, now: Option<[u32; 3]>) {
        let Some(k) = self.original.index_of(id) else {
            return;
        };
        let link = self.original.members[k].link;
        self.f.members[k].link = link;
        self.table
            .relink(&self.f, id, now, link.map(|l| l.in_neighbors));
    }
}

fn degrade(f: &mut Formation, id: u32) {
    if let Some(k) = f.index_of(id) {
        f.members[k].link = None;
    }
}

/// Who reads whom, by member index (the rows of `Formation::out_neighbors` without a map).
/// `launch` repairs every single loss to size its services before it spawns anyone, and each
/// repair walks the graph several times: building `out_neighbors` for each walk was a sixth of
/// the orchestrator's start-up CPU at N = 1000 (BENCHMARKS.md, start-up).
struct ReaderTable {
    rows: Vec<Vec<usize>>,
}

impl ReaderTable {
    fn of(f: &Formation) -> Self {
        let mut rows = vec![Vec::new(); f.members.len()];
        for (k, m) in f.members.iter().enumerate() {
            for nb in m.link.into_iter().flat_map(|l| l.in_neighbors) {
                if let Some(j) = f.index_of(nb) {
                    rows[j].push(k);
                }
            }
        }
        ReaderTable { rows }
    }

    fn row(&self, j: usize) -> &[usize] {
        &self.rows[j]
    }

    /// Member `id` now reads `new` instead of `old` (`None`: no link).
    fn relink(&mut self, f: &Formation, id: u32, old: Option<[u32; 3]>, new: Option<[u32; 3]>) {
        let Some(k) = f.index_of(id) else {
            return;
        };
        for j in old.into_iter().flatten().filter_map(|nb| f.index_of(nb)) {
            self.rows[j].retain(|&r| r != k);
        }
        for j in new.into_iter().flatten().filter_map(|nb| f.index_of(nb)) {
            self.rows[j].push(k);
        }
    }
}

/// Survivors that read `id`, directly or through other survivors (`table`: `f`'s readers).
#[cfg(test)]
fn readers_of(f: &Formation, table: &ReaderTable, id: u32, lost: &BTreeSet<u32>) -> BTreeSet<u32> {
    let seen = reader_mask(f, table, id, lost);
    (0..f.members.len())
        .filter(|&k| seen[k])
        .map(|k| f.members[k].id)
        .collect()
}

/// Survivors that read `id`, directly or through other survivors (`table`: `f`'s readers), by
/// member index.
fn reader_mask(f: &Formation, table: &ReaderTable, id: u32, lost: &BTreeSet<u32>) -> Vec<bool> {
    let mut seen = vec![false; f.members.len()];
    let mut stack: Vec<usize> = f.index_of(id).into_iter().collect();
    while let Some(j) = stack.pop() {
        for &k in table.row(j) {
            if !seen[k] && !lost.contains(&f.members[k].id) {
                seen[k] = true;
                stack.push(k);
            }
        }
    }
    seen
}

/// Surviving followers not reachable from a surviving leader or a degraded follower through
/// survivors' links (Assumption 2).
pub fn unreachable(f: &Formation, lost: &BTreeSet<u32>) -> Vec<u32> {
    unreachable_in(f, &ReaderTable::of(f), lost)
}

/// [`unreachable`] with `f`'s readers given.
fn unreachable_in(f: &Formation, table: &ReaderTable, lost: &BTreeSet<u32>) -> Vec<u32> {
    let alive = |k: usize| !lost.contains(&f.members[k].id);
    let mut seen: Vec<bool> = f
        .members
        .iter()
        .enumerate()
        .map(|(k, m)| alive(k) && (m.role.is_leader() || m.link.is_none()))
        .collect();
    let mut stack: Vec<usize> = (0..f.members.len()).filter(|&k| seen[k]).collect();
    while let Some(j) = stack.pop() {
        for &k in table.row(j) {
            let links_alive = f.members[k]
                .link
                .is_some_and(|l| l.in_neighbors.iter().all(|n| !lost.contains(n)));
            if !seen[k] && alive(k) && links_alive {
                seen[k] = true;
                stack.push(k);
            }
        }
    }
    f.members
        .iter()
        .enumerate()
        .filter(|&(k, m)| m.role == Role::Follower && alive(k) && !seen[k])
        .map(|(_, m)| m.id)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formation::MemberInput;
    use crate::frame::Frame;
    use crate::graph::{nearest, synthesize};
    use crate::link::splitmix64;
    use cdm_math::Vec3;

    /// The weight floor of [`team`]'s graph: a grid's middle followers get thin triangles.
    const FLOOR: Real = 0.005;

    /// A team of `n` built here, below the scenario files: three primary leaders and a secondary
    /// at a square's corners, followers on a jittered grid inside, links synthesised as a
    /// scenario's are.
    fn team(n: usize) -> Formation {
        let corner = |id, role, x, y| MemberInput {
            id,
            role,
            position: Vec3::new(x, y, 0.0),
            in_neighbors: None,
        };
        let mut inputs = vec![
            corner(1, Role::Primary, 0.0, 0.0),
            corner(2, Role::Primary, 100.0, 0.0),
            corner(3, Role::Primary, 0.0, 100.0),
            corner(4, Role::Secondary, 100.0, 100.0),
        ];
        let side = ((n - 4) as Real).sqrt().ceil() as usize;
        for k in 0..n - 4 {
            // Within the middle half of its cell: no three members near a line.
            let jitter =
                |salt: u64| 0.25 + 0.5 * (splitmix64(k as u64 * 2 + salt) % 1000) as Real / 1000.0;
            let x = 5.0 + 90.0 * ((k % side) as Real + jitter(0)) / side as Real;
            let y = 5.0 + 90.0 * ((k / side) as Real + jitter(1)) / side as Real;
            inputs.push(corner(5 + k as u32, Role::Follower, x, y));
        }
        let frame = Frame::new(
            &inputs[0].position,
            &inputs[1].position,
            &inputs[2].position,
        );
        let mut f = Formation::new(frame.unwrap(), &inputs).unwrap();
        synthesize(&mut f, FLOOR).unwrap();
        f
    }

    /// The walks as first written, over `Formation::out_neighbors`: the flat table must give
    /// the same sets.
    fn reference_readers(f: &Formation, id: u32, lost: &BTreeSet<u32>) -> BTreeSet<u32> {
        let out = f.out_neighbors();
        let (mut seen, mut stack) = (BTreeSet::new(), vec![id]);
        while let Some(j) = stack.pop() {
            for &k in out.get(&j).into_iter().flatten() {
                if !lost.contains(&k) && seen.insert(k) {
                    stack.push(k);
                }
            }
        }
        seen
    }

    #[test]
    fn reader_table_walks_match_the_map_walks() {
        let team = team(120);
        let f = &team;
        let ids: Vec<u32> = f.members.iter().map(|m| m.id).collect();
        let mut found = 0;
        for lost in [
            vec![],
            vec![ids[0]],
            vec![ids[5], ids[60]],
            vec![ids[3], ids[4], ids[90]],
        ] {
            let lost: BTreeSet<u32> = lost.into_iter().collect();
            for &id in &ids {
                let table = ReaderTable::of(f);
                assert_eq!(
                    readers_of(f, &table, id, &lost),
                    reference_readers(f, id, &lost)
                );
            }
            // Degraded followers are roots; the lost members' readers lose their links.
            let mut cut = f.clone();
            for &id in &ids[10..14] {
                degrade(&mut cut, id);
            }
            let got: BTreeSet<u32> = unreachable(&cut, &lost).into_iter().collect();
            assert_eq!(got, unreachable_by_map(&cut, &lost));
            found += got.len();
        }
        assert!(found > 0, "no case had an unreachable follower");
    }

    #[test]
    fn single_losses_repair_as_the_full_repair_does() {
        // Larger than the most candidates a triangle is picked from, so the selection is
        // exercised; each loss is undone before the next, so any leftover would show here.
        let team = team(300);
        let order = synthesis_order(&team);
        let mut singles = SingleLosses::new(&team, FLOOR, &order);
        let mut switched = 0;
        for m in &team.members {
            let full = repair_in_order(&team, FLOOR, &[m.id].into(), &order);
            let got = singles.retriangulated(m.id);
            assert_eq!(got, full.retriangulated, "loss of {}", m.id);
            switched += got.len();
        }
        assert!(switched > team.members.len(), "{switched} switches");
    }

    #[test]
    fn the_nearest_candidates_pick_the_triangles_all_points_pick() {
        let team = team(300);
        let leader_ids: Vec<u32> = team
            .members
            .iter()
            .filter(|m| m.role.is_leader())
            .map(|m| m.id)
            .collect();
        let pts: Vec<(u32, Vec2)> = team.members.iter().map(|m| (m.id, m.planar)).collect();
        let mut refused = 0;
        for m in team.members.iter().filter(|m| !m.role.is_leader()) {
            let others: Vec<(u32, Vec2)> =
                pts.iter().filter(|(j, _)| *j != m.id).copied().collect();
            // A floor no triangle reaches: every pass runs, the leaders' included.
            for floor in [FLOOR, 0.34] {
                let all =
                    best_triangle(&m.planar, &nearest(&others, &m.planar), &leader_ids, floor);
                let few = nearest_candidates(&others, &m.planar, &leader_ids);
                let got = best_triangle(&m.planar, &few, &leader_ids, floor);
                assert_eq!(got, all, "follower {}, floor {floor}", m.id);
                refused += usize::from(got.is_err());
            }
        }
        assert!(refused > 0);
    }

    #[test]
    fn a_relinked_reader_table_is_the_table_of_the_new_graph() {
        let team = team(120);
        let lost: BTreeSet<u32> = team.members.iter().map(|m| m.id).take(1).collect();
        let r = repair(&team, FLOOR, &lost);
        assert!(!r.retriangulated.is_empty());
        let mut f = team.clone();
        let mut table = ReaderTable::of(&f);
        for x in &r.retriangulated {
            f.set_link(x.id, x.new).unwrap();
            table.relink(&f, x.id, Some(x.old), Some(x.new));
        }
        let follower = f.members.iter().rev().find(|m| m.link.is_some()).unwrap();
        let (id, old) = (follower.id, follower.link.unwrap().in_neighbors);
        degrade(&mut f, id);
        table.relink(&f, id, Some(old), None);
        let fresh = ReaderTable::of(&f);
        for j in 0..f.members.len() {
            let mut a = table.row(j).to_vec();
            a.sort_unstable();
            assert_eq!(a, fresh.row(j), "row {j}");
        }
    }

    fn unreachable_by_map(f: &Formation, lost: &BTreeSet<u32>) -> BTreeSet<u32> {
        let out = f.out_neighbors();
        let mut seen: BTreeSet<u32> = f
            .members
            .iter()
            .filter(|m| !lost.contains(&m.id) && (m.role.is_leader() || m.link.is_none()))
            .map(|m| m.id)
            .collect();
        let mut stack: Vec<u32> = seen.iter().copied().collect();
        while let Some(j) = stack.pop() {
            for &k in out.get(&j).into_iter().flatten() {
                let alive = f
                    .member(k)
                    .and_then(|m| m.link)
                    .is_some_and(|l| l.in_neighbors.iter().all(|n| !lost.contains(n)));
                if !lost.contains(&k) && alive && seen.insert(k) {
                    stack.push(k);
                }
            }
        }
        f.members
            .iter()
            .filter(|m| m.role == Role::Follower && !lost.contains(&m.id) && !seen.contains(&m.id))
            .map(|m| m.id)
            .collect()
    }
}
