//! A repair as a host's bridge sees it (plain data, no I/O): the loss notices that ride on the
//! clock, the links each repair opens, and which of them a host must carry.
//!
//! The orchestrator's bridge and every daemon keep the same [`LossLog`] from the same notices,
//! so they compute the same repaired graph as the members and `simulate` do (`repair::repair`
//! over the whole lost set, eq. 18's weights): no link travels on the wire, only the notice.

use std::collections::BTreeSet;

use cdm_model::repair::{repair_in_order, synthesis_order};
use cdm_records::loss_log::{links, LossLog};
use cdm_runtime::messages::LossNotice;
use cdm_runtime::notices::{NoticeGap, Notices};
use cdm_scenario::Scenario;

/// What one clock message's notice asks of a bridge.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct RepairStep {
    /// Links (reader, writer) the newly announced losses open, not seen before.
    pub new_links: Vec<(u32, u32)>,
    /// The count of connected repairs rose: publishers hand their history to new readers.
    pub hand_over: bool,
    /// The oldest tick whose states the repair just connected needs: its tick, less the
    /// longest link delay (a new reader's oldest candidate, `LinkModel::oldest_candidate`).
    pub needs_from: u64,
}

/// The losses announced so far, as a bridge follows them.
#[derive(Debug, Clone)]
pub struct CrossRepairs {
    notices: Notices,
    opened: BTreeSet<(u32, u32)>,
    /// The longest link delay, in ticks.
    delay: u64,
}

impl CrossRepairs {
    /// No loss yet.
    pub fn new(s: &Scenario) -> Self {
        Self {
            notices: Notices::new(LossLog::new(s)),
            opened: BTreeSet::new(),
            delay: s.link_model().max_ticks(),
        }
    }

    /// The notice of a clock message (None: no loss announced yet). A repeat changes nothing;
    /// a jump in the notice numbers is a [`NoticeGap`] (the bridges forward every clock message
    /// whose notice changed, and the team announces a loss only after the previous one's links
    /// connected, so a gap means a notice was lost on the way).
    pub fn on_notice(&mut self, n: Option<LossNotice>) -> Result<RepairStep, NoticeGap> {
        let Some(n) = n else {
            return Ok(RepairStep::default());
        };
        let mut step = RepairStep::default();
        let followed = self.notices.follow(n)?;
        if followed.lost.is_some() {
            let now: BTreeSet<(u32, u32)> = self.notices.log().new_links();
            step.new_links = now.difference(&self.opened).copied().collect();
            self.opened.extend(now);
        }
        if followed.linked {
            step.hand_over = true;
            step.needs_from = n.tick.saturating_sub(self.delay);
        }
        Ok(step)
    }
}

/// The links (reader, writer) that the loss of any single member opens: a daemon stands in,
/// from the start, for every member of another host that such a link joins to one of its own
/// (their services must exist on its shared memory before a repair needs them). Several losses
/// may need more; such a link is then refused by name (a member's fault), as a repair beyond
/// the services' room is on one host.
pub fn single_loss_links(s: &Scenario) -> BTreeSet<(u32, u32)> {
    let floor = s
        .file
        .weight_floor
        .unwrap_or(cdm_model::graph::DEFAULT_WEIGHT_FLOOR);
    let order = synthesis_order(&s.formation);
    let original = links(&s.formation, &BTreeSet::new());
    let mut out = BTreeSet::new();
    for m in &s.formation.members {
        let lost = BTreeSet::from([m.id]);
        let r = repair_in_order(&s.formation, floor, &lost, &order);
        out.extend(links(&r.formation, &lost).difference(&original));
    }
    out
}

/// The members of other hosts that a link of `links` joins to one of `mine`.
pub fn partners(links: &BTreeSet<(u32, u32)>, mine: &BTreeSet<u32>) -> BTreeSet<u32> {
    links
        .iter()
        .filter_map(|&(r, w)| match (mine.contains(&r), mine.contains(&w)) {
            (true, false) => Some(w),
            (false, true) => Some(r),
            _ => None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn notice(seq: u32, id: u32, tick: u64, linked: u32) -> Option<LossNotice> {
        Some(LossNotice {
            seq,
            id,
            tick,
            linked,
        })
    }

    #[test]
    fn a_notice_opens_the_links_of_the_members_repair_once() {
        let s = Scenario::builtin("paper40").unwrap();
        let lost = s.formation.members[20].id;
        let mut r = CrossRepairs::new(&s);
        assert_eq!(r.on_notice(None), Ok(RepairStep::default()));
        let step = r.on_notice(notice(1, lost, 30, 0)).unwrap();
        let mut log = LossLog::new(&s);
        log.add(lost, 30);
        let expected: Vec<(u32, u32)> = log.new_links().into_iter().collect();
        assert!(
            !expected.is_empty(),
            "losing {lost} re-triangulates someone"
        );
        assert_eq!(step.new_links, expected);
        assert!(!step.hand_over);
        assert_eq!(
            r.on_notice(notice(1, lost, 30, 0)),
            Ok(RepairStep::default())
        );
        let linked = r.on_notice(notice(1, lost, 30, 1)).unwrap();
        assert!(linked.hand_over && linked.new_links.is_empty());
        let all = single_loss_links(&s);
        assert!(expected.iter().all(|l| all.contains(l)));
    }

    #[test]
    fn partners_are_the_other_ends_on_other_hosts() {
        let links = BTreeSet::from([(1, 2), (3, 4), (5, 1), (6, 7)]);
        let mine = BTreeSet::from([1, 3, 4]);
        assert_eq!(partners(&links, &mine), BTreeSet::from([2, 5]));
    }
}
