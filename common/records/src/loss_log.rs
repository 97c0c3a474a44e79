//! The losses of a run as every process sees them: a list of (lost member, tick from which its
//! repair applies), and the links in force at any tick. Members and the orchestrator of a
//! `launch` each keep one, fed by the orchestrator's loss notices, and compute the same
//! repaired graph as `simulate` (`repair::repair` over the whole lost set, in tick order), with
//! no I/O.

use std::collections::BTreeSet;

use cdm_math::Real;
use cdm_model::formation::{Formation, Link};
use cdm_model::graph::DEFAULT_WEIGHT_FLOOR;
use cdm_model::repair::{repair, Repair};
use cdm_scenario::Scenario;

/// The losses announced so far, over the scenario's original formation.
#[derive(Debug, Clone, PartialEq)]
pub struct LossLog {
    original: Formation,
    floor: Real,
    /// (tick from which the repair applies, lost id), sorted.
    losses: Vec<(u64, u32)>,
}

impl LossLog {
    /// No loss yet.
    pub fn new(s: &Scenario) -> Self {
        LossLog {
            original: s.formation.clone(),
            floor: s.file.weight_floor.unwrap_or(DEFAULT_WEIGHT_FLOOR),
            losses: Vec::new(),
        }
    }

    /// Member `id` is lost from `tick` (the tick after its last published state). A repeat is
    /// ignored.
    pub fn add(&mut self, id: u32, tick: u64) {
        if self.losses.iter().all(|&(_, j)| j != id) {
            self.losses.push((tick, id));
            self.losses.sort_unstable();
        }
    }

    /// The formation before any loss.
    pub fn original(&self) -> &Formation {
        &self.original
    }

    /// Every loss, (tick, id), in tick order.
    pub fn losses(&self) -> &[(u64, u32)] {
        &self.losses
    }

    /// The members lost at or before `tick`.
    pub fn lost_at(&self, tick: u64) -> BTreeSet<u32> {
        self.losses
            .iter()
            .filter(|&&(t, _)| t <= tick)
            .map(|&(_, id)| id)
            .collect()
    }

    /// The repair in force at `tick` (the original graph before any loss).
    pub fn repair_at(&self, tick: u64) -> Repair {
        let mut r = repair(&self.original, self.floor, &BTreeSet::new());
        for (t, e) in self.epochs() {
            if t <= tick {
                r = e;
            }
        }
        r
    }

    /// The ticks at which the graph changes, each with the repair in force from it. Repairs are
    /// incremental, as `simulate` flies them (`loss::LossState`): each epoch repairs the graph
    /// of the one before for everyone lost so far, so only the readers of the members lost at
    /// that tick switch.
    pub fn epochs(&self) -> Vec<(u64, Repair)> {
        let mut ticks: Vec<u64> = self.losses.iter().map(|&(t, _)| t).collect();
        ticks.dedup();
        let mut current = self.original.clone();
        let mut out = Vec::with_capacity(ticks.len());
        for t in ticks {
            let r = repair(&current, self.floor, &self.lost_at(t));
            current = r.formation.clone();
            out.push((t, r));
        }
        out
    }

    /// Member `id`'s link in `f` (`None` for a leader or a degraded follower).
    pub fn link_in(f: &Formation, id: u32) -> Option<Link> {
        f.member(id).and_then(|m| m.link)
    }

    /// The same log without the losses of `ids` (those not announced yet, say).
    pub fn without(&self, ids: &BTreeSet<u32>) -> LossLog {
        let mut log = self.clone();
        log.losses.retain(|(_, id)| !ids.contains(id));
        log
    }

    /// Every reader-writer pair (reader, writer) of any epoch that the original graph lacks:
    /// the links a repair opens.
    pub fn new_links(&self) -> BTreeSet<(u32, u32)> {
        let original = links(&self.original, &BTreeSet::new());
        let mut out = BTreeSet::new();
        for (_, r) in self.epochs() {
            out.extend(links(&r.formation, &r.lost).difference(&original));
        }
        out
    }
}

/// Every (reader, writer) link of `f` among members not in `lost`.
pub fn links(f: &Formation, lost: &BTreeSet<u32>) -> BTreeSet<(u32, u32)> {
    f.members
        .iter()
        .filter(|m| !lost.contains(&m.id))
        .filter_map(|m| m.link.map(|l| (m.id, l)))
        .flat_map(|(id, l)| l.in_neighbors.into_iter().map(move |j| (id, j)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epochs_repair_the_whole_lost_set_in_tick_order() {
        let s = Scenario::builtin("paper40").unwrap();
        let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
        let mut log = LossLog::new(&s);
        log.add(ids[20], 50);
        log.add(ids[5], 30);
        log.add(ids[5], 90);
        assert_eq!(log.losses(), &[(30, ids[5]), (50, ids[20])]);
        let e = log.epochs();
        assert_eq!(e.len(), 2);
        assert_eq!(e[0].1.lost, [ids[5]].into());
        assert_eq!(e[1].1.lost, [ids[5], ids[20]].into());
        assert_eq!(log.repair_at(29).formation, s.formation);
        // The same function as simulate: the graph in force repaired for the lost set.
        let first = repair(&s.formation, DEFAULT_WEIGHT_FLOOR, &[ids[5]].into());
        assert_eq!(e[0].1, first);
        let direct = repair(
            &first.formation,
            DEFAULT_WEIGHT_FLOOR,
            &[ids[5], ids[20]].into(),
        );
        assert_eq!(e[1].1, direct);
        // Incremental: a follower that read neither loses nothing at the second.
        for (m, before) in direct
            .formation
            .members
            .iter()
            .zip(&first.formation.members)
        {
            let read = |l: Option<cdm_model::formation::Link>| {
                l.is_some_and(|l| l.in_neighbors.contains(&ids[20]))
            };
            if !read(before.link) && !direct.lost.contains(&m.id) {
                assert_eq!(m.link, before.link, "{} switched again", m.id);
            }
        }
        let new = log.new_links();
        for x in &direct.retriangulated {
            for j in x.new {
                if !x.old.contains(&j) {
                    assert!(new.contains(&(x.id, j)), "{} reads {j}", x.id);
                }
            }
        }
        assert!(new.iter().all(|&(i, j)| i != ids[5] && j != ids[5]));
    }
}
