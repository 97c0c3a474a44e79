//! A member's side of losing a team-mate, with no I/O: it takes the orchestrator's loss notices
//! (on the clock channel), keeps the run's [`LossLog`], and says which ports to open and from
//! which tick to fly which link. The repair is computed here, locally, by the same function as
//! `simulate` (`cdm_model::repair::repair` over the whole lost set), so no link travels on the wire.
//!
//! Timing (as `simulate`): member k lost after its tick-L state; its readers use that state for
//! their tick-L step and fly the repaired link from tick L + 1 = the notice's tick.

use std::collections::BTreeSet;

use cdm_model::formation::{Formation, Member};
use cdm_records::loss_log::LossLog;

use crate::inbox::Inbox;
use crate::messages::LossNotice;
use crate::notices::Notices;

/// What taking a loss notice asks of the member's loop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LossWork {
    /// Open subscriptions on these members' states and notifiers on these members' wake events
    /// (the new in- and out-neighbours of the repaired graph).
    Connect {
        subscribe: Vec<u32>,
        notify: Vec<u32>,
    },
    /// Every new link is connected: hand new readers the states they missed and wake them.
    HandOver,
}

/// Why a loss notice cannot be followed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LossFault {
    /// The notices jumped from `seen` to `got` (a notice was lost).
    Missed { seen: u32, got: u32 },
    /// This member itself was declared lost (it went silent): it must stop.
    SelfLost { tick: u64 },
    /// The repair changes this member's link from `tick`, which it has already flown past.
    Late { tick: u64, at: u64 },
}

/// The losses as this member knows them, and what follows for it.
#[derive(Debug)]
pub struct MemberLosses {
    id: u32,
    notices: Notices,
    /// The member (its link) the vehicle flies now.
    applied: Member,
    /// A link applied at tick T whose step T is not flown yet, with the member flown up to
    /// T - 1: several losses of one tick are announced one at a time (a lost host's members),
    /// so a later notice may still change the link at T (`replan`).
    unflown: Option<(u64, Member)>,
    /// Later links: (first tick, member with that link), ascending.
    schedule: Vec<(u64, Member)>,
    subscribed: BTreeSet<u32>,
    notifying: BTreeSet<u32>,
    /// States of future in-neighbours, kept until their link applies.
    ahead: Vec<(u32, Inbox)>,
    work: Vec<LossWork>,
}

impl MemberLosses {
    /// Member `me` of a team with no loss yet; `log` is the run's empty loss log.
    pub fn new(me: &Member, log: LossLog, subscribed: &[u32], notifying: &[u32]) -> Self {
        MemberLosses {
            id: me.id,
            notices: Notices::new(log),
            applied: me.clone(),
            unflown: None,
            schedule: Vec::new(),
            subscribed: subscribed.iter().copied().collect(),
            notifying: notifying.iter().copied().collect(),
            ahead: Vec::new(),
            work: Vec::new(),
        }
    }

    /// The notice of a clock message, this member being at `tick` (its next step). A repeat
    /// changes nothing.
    pub fn on_notice(&mut self, n: LossNotice, tick: u64) -> Result<(), LossFault> {
        if self.notices.is_next(&n) && n.id == self.id {
            return Err(LossFault::SelfLost { tick });
        }
        let step = self.notices.follow(n).map_err(|g| LossFault::Missed {
            seen: g.seen,
            got: g.got,
        })?;
        if step.lost.is_some() {
            self.replan(tick)?;
        }
        if step.linked {
            self.work.push(LossWork::HandOver);
        }
        Ok(())
    }

    /// The next piece of port work, oldest first.
    pub fn next_work(&mut self) -> Option<LossWork> {
        (!self.work.is_empty()).then(|| self.work.remove(0))
    }

    /// True when the link changes at `tick` (or before) but a loss this member knows is not
    /// linked yet: step `tick` must wait (see [`Self::due`]). A member over delayed links is
    /// not held up by its lost neighbour's missing state, so it must be held here.
    pub fn waits_at(&self, tick: u64) -> bool {
        self.notices.unlinked() && self.schedule.first().is_some_and(|(t, _)| *t <= tick)
    }

    /// The member to fly from `tick` on, when its link changes there (it may change again at
    /// the same tick while step `tick` is not flown: `unflown`).
    pub fn due(&mut self, tick: u64) -> Option<Member> {
        // Not before every announced loss is linked: the orchestrator announces the losses of
        // one tick back to back and links them together (`TeamLosses::poll`), so a link flown
        // from here on is the repair of all of them, not of the first few.
        if self.notices.unlinked() {
            return None;
        }
        if self.schedule.first().is_some_and(|(t, _)| *t == tick) {
            let (_, m) = self.schedule.remove(0);
            let flown = match self.unflown.take() {
                Some((t, before)) if t == tick => before,
                _ => self.applied.clone(),
            };
            self.unflown = Some((tick, flown));
            self.applied = m.clone();
            // States kept for a link that will not be flown (a neighbour dropped at an earlier
            // tick that did not come back) are forgotten; the applied link's are taken next.
            let keep: BTreeSet<u32> = self
                .links_from(tick)
                .chain(m.link.map(|l| l.in_neighbors).into_iter().flatten())
                .collect();
            self.ahead.retain(|(j, _)| keep.contains(j));
            return Some(m);
        }
        None
    }

    /// True when the notices so far say member `id` is lost.
    pub fn is_lost(&self, id: u32) -> bool {
        self.notices.log().losses().iter().any(|&(_, j)| j == id)
    }

    /// Drops the next link change, never flown, when a later one is scheduled (which replaces
    /// it: each scheduled member is the repair of every loss up to its tick); false otherwise.
    pub fn skip_upcoming(&mut self) -> bool {
        if self.schedule.len() < 2 {
            return false;
        }
        self.schedule.remove(0);
        true
    }

    /// The next link change, if any: its tick and the member with that link.
    pub fn upcoming(&self) -> Option<(u64, &Member)> {
        self.schedule.first().map(|(t, m)| (*t, m))
    }

    /// The in-neighbours of the links still to come, and of the link flown before one applied
    /// at `tick` and not flown yet.
    fn links_from(&self, tick: u64) -> impl Iterator<Item = u32> + '_ {
        let before = self.unflown.as_ref().filter(|(t, _)| *t == tick);
        self.schedule
            .iter()
            .map(|(_, m)| m)
            .chain(before.map(|(_, m)| m))
            .filter_map(|m| m.link)
            .flat_map(|l| l.in_neighbors)
    }

    /// True when `id`'s states are kept while it is not an in-neighbour: it is one of a link
    /// still to come, or of the link flown before one applied at `tick` and not flown yet (a
    /// later notice of the same tick may bring it back).
    pub fn is_future_neighbor(&self, id: u32, tick: u64) -> bool {
        self.links_from(tick).any(|j| j == id)
    }

    /// Where member `id` started (the scenario's start), if it is in the team.
    pub(crate) fn start_of(&self, id: u32) -> Option<cdm_math::Vec3> {
        self.notices.log().original().member(id).map(|m| m.start)
    }

    /// Keeps the states of a neighbour the link applied now drops (see `due`).
    pub(crate) fn keep_all(&mut self, id: u32, states: Inbox) {
        self.kept(id).merge(states);
    }

    /// Keeps a future in-neighbour's state.
    pub(crate) fn keep(&mut self, id: u32, tick: u64, state: cdm_model::dynamics::Flat) {
        self.kept(id).insert(tick, state);
    }

    /// Keeps a future in-neighbour's state, and only its last `count` ticks (a real-time
    /// member flies on the newest state its links deliver).
    pub(crate) fn keep_last(
        &mut self,
        id: u32,
        (tick, state): (u64, cdm_model::dynamics::Flat),
        count: u64,
    ) {
        let kept = self.kept(id);
        kept.insert(tick, state);
        if let Some(last) = kept.last_tick() {
            kept.drop_before((last + 1).saturating_sub(count));
        }
    }

    /// The states kept of `id`, oldest first.
    pub(crate) fn kept_states(
        &self,
        id: u32,
    ) -> impl Iterator<Item = (u64, cdm_model::dynamics::Flat)> + '_ {
        let kept = self.ahead.iter().find(|(j, _)| *j == id).map(|(_, k)| k);
        kept.into_iter().flat_map(|k| k.upto(u64::MAX))
    }

    /// The states kept of `id` (a new, empty inbox the first time).
    fn kept(&mut self, id: u32) -> &mut Inbox {
        let k = match self.ahead.iter().position(|(j, _)| *j == id) {
            Some(k) => k,
            None => {
                self.ahead.push((id, Inbox::default()));
                self.ahead.len() - 1
            }
        };
        &mut self.ahead[k].1
    }

    /// The kept states of `id` (empty when none arrived), taken.
    pub(crate) fn take_kept(&mut self, id: u32) -> Inbox {
        match self.ahead.iter().position(|(j, _)| *j == id) {
            Some(k) => self.ahead.swap_remove(k).1,
            None => Inbox::default(),
        }
    }

    /// Recomputes this member's future links and the ports it lacks after a new loss.
    fn replan(&mut self, tick: u64) -> Result<(), LossFault> {
        let epochs = self.notices.log().epochs();
        let own = |f: &Formation| f.member(self.id).cloned();
        // The link flown for the steps already computed must not change: the link in force at
        // `tick` is either the one applied, or (changing exactly at `tick`, not applied yet) the
        // one in force before it.
        let in_force = |x: u64| {
            epochs
                .iter()
                .rev()
                .find(|(t, _)| *t <= x)
                .and_then(|(_, r)| own(&r.formation))
                .or_else(|| own(self.notices.log().original()))
                .unwrap_or_else(|| self.applied.clone())
        };
        let now_link = in_force(tick).link;
        // Applied at `tick` but not flown: the link flown up to tick - 1 is the one before it.
        let flown = match &self.unflown {
            Some((t, before)) if *t == tick => before.link,
            _ => self.applied.link,
        };
        let ok = now_link == self.applied.link
            || (tick > 0 && in_force(tick - 1).link == flown)
            || tick == 0;
        if !ok {
            let at = epochs
                .iter()
                .rev()
                .find(|(t, _)| *t < tick)
                .map_or(0, |e| e.0);
            return Err(LossFault::Late { tick, at });
        }
        let mut last = self.applied.clone();
        self.schedule.clear();
        let mut readers = BTreeSet::new();
        // Readers from the epoch in force now on: a member that runs ahead of a loss's tick
        // still writes to the followers that switched to it there.
        let now = epochs.iter().rposition(|(t, _)| *t <= tick).unwrap_or(0);
        for (t, r) in epochs.iter().skip(now) {
            if let Some(m) = own(&r.formation).filter(|m| *t >= tick && m.link != last.link) {
                last = m.clone();
                self.schedule.push((*t, m));
            }
            readers.extend(
                r.formation
                    .members
                    .iter()
                    .filter(|m| !r.lost.contains(&m.id))
                    .filter(|m| m.link.is_some_and(|l| l.in_neighbors.contains(&self.id)))
                    .map(|m| m.id),
            );
        }
        let ins: BTreeSet<u32> = self
            .schedule
            .iter()
            .filter_map(|(_, m)| m.link)
            .flat_map(|l| l.in_neighbors)
            .collect();
        let subscribe: Vec<u32> = ins.difference(&self.subscribed).copied().collect();
        let notify: Vec<u32> = readers.difference(&self.notifying).copied().collect();
        self.subscribed.extend(&subscribe);
        self.notifying.extend(&notify);
        if !subscribe.is_empty() || !notify.is_empty() {
            self.work.push(LossWork::Connect { subscribe, notify });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_scenario::Scenario;

    fn setup(s: &Scenario, id: u32) -> MemberLosses {
        let me = s.formation.member(id).unwrap();
        let ins: Vec<u32> = me.link.map(|l| l.in_neighbors.to_vec()).unwrap_or_default();
        let outs = s.formation.out_neighbors().remove(&id).unwrap_or_default();
        MemberLosses::new(me, LossLog::new(s), &ins, &outs)
    }

    #[test]
    fn a_reader_of_the_lost_member_connects_and_switches_at_the_notice_tick() {
        let s = Scenario::builtin("paper40").unwrap();
        let outs = s.formation.out_neighbors();
        let (&lost, readers) = outs.iter().find(|(_, r)| !r.is_empty()).unwrap();
        let reader = readers[0];
        let mut m = setup(&s, reader);
        let n = LossNotice {
            seq: 1,
            id: lost,
            tick: 20,
            linked: 0,
        };
        m.on_notice(n, 12).unwrap();
        m.on_notice(n, 13).unwrap(); // a repeat
        let Some(LossWork::Connect { subscribe, .. }) = m.next_work() else {
            panic!("no connect");
        };
        let r = cdm_model::repair::repair(
            &s.formation,
            cdm_model::graph::DEFAULT_WEIGHT_FLOOR,
            &[lost].into(),
        );
        let new = r.formation.member(reader).unwrap().clone();
        let old = s
            .formation
            .member(reader)
            .unwrap()
            .link
            .unwrap()
            .in_neighbors;
        let fresh: Vec<u32> = new
            .link
            .map(|l| {
                l.in_neighbors
                    .into_iter()
                    .filter(|j| !old.contains(j))
                    .collect()
            })
            .unwrap_or_default();
        assert_eq!(subscribe, fresh);
        assert_eq!(m.next_work(), None);
        assert_eq!(m.due(19), None);
        // Not flown before the repair is linked (losses of one tick are linked together).
        assert!(!m.waits_at(19) && m.waits_at(20));
        assert_eq!(m.due(20), None);
        m.on_notice(LossNotice { linked: 1, ..n }, 20).unwrap();
        assert_eq!(m.next_work(), Some(LossWork::HandOver));
        assert!(!m.waits_at(20));
        assert_eq!(m.due(20), Some(new));
    }

    #[test]
    fn a_new_in_neighbour_running_ahead_of_the_loss_still_notifies_its_new_reader() {
        let s = Scenario::builtin("paper40").unwrap();
        let lost = s.formation.members[0].id;
        let r = cdm_model::repair::repair(
            &s.formation,
            cdm_model::graph::DEFAULT_WEIGHT_FLOOR,
            &[lost].into(),
        );
        let x = r.retriangulated[0];
        let writer = *x.new.iter().find(|j| !x.old.contains(j)).unwrap();
        let mut m = setup(&s, writer);
        let n = LossNotice {
            seq: 1,
            id: lost,
            tick: 600,
            linked: 0,
        };
        // The writer is already at tick 650: its own link did not change, it must notify.
        m.on_notice(n, 650).unwrap();
        match m.next_work() {
            Some(LossWork::Connect { notify, .. }) => assert!(notify.contains(&x.id)),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_link_that_reads_a_member_lost_since_is_skipped_for_the_next() {
        // Real time: primaries 1 and 2 lost at once get repair ticks of their own, 127 and 128;
        // reader 7's repair of 1 reads 2, whose own repair (the next link) goes around it.
        let s = Scenario::generated(10).unwrap();
        let mut m = setup(&s, 7);
        let in_neighbors = |m: &MemberLosses| {
            m.upcoming()
                .and_then(|(t, x)| x.link.map(|l| (t, l.in_neighbors)))
        };
        let notice = |seq, id, tick, linked| LossNotice {
            seq,
            id,
            tick,
            linked,
        };
        m.on_notice(notice(1, 1, 127, 0), 120).unwrap();
        m.on_notice(notice(1, 1, 127, 1), 120).unwrap();
        let (t, ins) = in_neighbors(&m).unwrap();
        assert!(t == 127 && ins.contains(&2), "{ins:?}");
        assert!(!m.is_lost(2), "not known lost yet");
        assert!(!m.skip_upcoming(), "nothing replaces it yet");
        m.on_notice(notice(2, 2, 128, 1), 121).unwrap();
        m.on_notice(notice(2, 2, 128, 2), 121).unwrap();
        assert!(m.is_lost(2) && m.skip_upcoming());
        assert_eq!(in_neighbors(&m), Some((128, [3, 4, 9])));
        assert!(!m.skip_upcoming(), "the last link is never skipped");
        assert_eq!(
            m.due(128).and_then(|x| x.link).map(|l| l.in_neighbors),
            Some([3, 4, 9])
        );
    }

    /// Notices of the losses of `ids` at tick 952, in order, to a member at 952 (each linked
    /// before the next when `linked_each`); the links it applies at 952 meanwhile.
    fn notices_at_952(
        m: &mut MemberLosses,
        ids: &[u32],
        linked_each: bool,
    ) -> Vec<Option<[u32; 3]>> {
        let mut links = vec![];
        for (k, &id) in ids.iter().enumerate() {
            let seq = k as u32 + 1;
            let linked = if linked_each { seq } else { 0 };
            let n = LossNotice {
                seq,
                id,
                tick: 952,
                linked,
            };
            m.on_notice(n, 952).unwrap();
            links.extend(m.due(952).map(|x| x.link.map(|l| l.in_neighbors)));
        }
        links
    }

    #[test]
    fn a_link_applied_at_a_tick_not_flown_yet_follows_a_later_notice_of_that_tick() {
        // generated10: members 3, 5, 6 and 10 lost after tick 951, announced one at a time (a
        // lost host's members), and 9 earlier. Member 7 reads 6: at 952 it first flies [1, 8, 10],
        // then, 10 being lost at the same tick, no triangle (degraded), as `simulate` does with
        // all four lost at once.
        let s = Scenario::generated(10).unwrap();
        let mut m = setup(&s, 7);
        let original = s.formation.member(7).unwrap().link;
        let mut links = vec![];
        for (seq, (id, tick)) in [(9, 699), (3, 952), (5, 952), (6, 952), (10, 952)]
            .into_iter()
            .enumerate()
        {
            // Each linked before the next is found (a loss of that tick found late).
            let n = LossNotice {
                seq: seq as u32 + 1,
                id,
                tick,
                linked: seq as u32 + 1,
            };
            m.on_notice(n, 952).unwrap();
            // States of a neighbour a link of this tick drops are kept: it may come back.
            assert!(m.is_future_neighbor(4, 952) || links.is_empty());
            links.extend(m.due(952).map(|x| x.link.map(|l| l.in_neighbors)));
        }
        assert_eq!(links, [Some([1, 8, 10]), None], "{original:?}");
        // The same without an earlier loss (no epoch before the tick).
        let mut m = setup(&s, 7);
        let links = notices_at_952(&mut m, &[3, 5, 6, 10], true);
        assert_eq!(links, [Some([1, 8, 10]), None]);
        // As the orchestrator announces them: back to back, linked together. The member flies
        // the repair of all four at 952, never the first's.
        let mut m = setup(&s, 7);
        let links = notices_at_952(&mut m, &[3, 5, 6, 10], false);
        assert!(links.is_empty(), "{links:?}");
        let all = LossNotice {
            seq: 4,
            id: 10,
            tick: 952,
            linked: 4,
        };
        m.on_notice(all, 952).unwrap();
        assert_eq!(m.due(952).map(|x| x.link), Some(None));
        assert!(!m.is_future_neighbor(4, 953));
    }

    #[test]
    fn notices_that_cannot_be_followed_are_faults() {
        let s = Scenario::builtin("paper40").unwrap();
        let outs = s.formation.out_neighbors();
        let (&lost, readers) = outs.iter().find(|(_, r)| !r.is_empty()).unwrap();
        let mut m = setup(&s, readers[0]);
        let n = LossNotice {
            seq: 2,
            id: lost,
            tick: 20,
            linked: 0,
        };
        assert_eq!(
            m.on_notice(n, 5),
            Err(LossFault::Missed { seen: 0, got: 2 })
        );
        let late = LossNotice { seq: 1, ..n };
        assert_eq!(
            m.on_notice(late, 25),
            Err(LossFault::Late { tick: 25, at: 20 })
        );
        let mut me = setup(&s, lost);
        assert_eq!(
            me.on_notice(LossNotice { seq: 1, ..n }, 9),
            Err(LossFault::SelfLost { tick: 9 })
        );
    }
}

#[cfg(test)]
mod sequence_tests {
    use super::*;
    use cdm_scenario::Scenario;

    #[test]
    fn a_reader_of_the_second_loss_is_not_late_because_of_the_first() {
        let s = Scenario::builtin("paper40").unwrap();
        for id in [12u32, 28] {
            let me = s.formation.member(id).unwrap();
            let ins: Vec<u32> = me.link.map(|l| l.in_neighbors.to_vec()).unwrap_or_default();
            let outs = s.formation.out_neighbors().remove(&id).unwrap_or_default();
            let mut m = MemberLosses::new(me, LossLog::new(&s), &ins, &outs);
            let n1 = LossNotice {
                seq: 1,
                id: 20,
                tick: 301,
                linked: 0,
            };
            m.on_notice(n1, 320).unwrap();
            let n2 = LossNotice {
                seq: 2,
                id: 5,
                tick: 451,
                linked: 1,
            };
            m.on_notice(n2, 451).unwrap();
        }
    }
}
