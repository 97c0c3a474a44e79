//! The orchestrator's side of losing members, with no I/O: which scripted loss is due, how far
//! grants may go meanwhile, the notices to announce one at a time, when every new link of a
//! repair is connected, how many states complete a tick, and which losses the audit records at
//! which tick. The orchestrator's loop (`launch`) kills, reaps, drains and publishes around it.
//!
//! A lost member's last published state is tick L; its repair applies from L + 1 (the notice's
//! tick), exactly as `simulate --lose ID@(L dt)` flies it.

use std::collections::BTreeSet;
use std::time::Duration;

pub use cdm_model::outcome::LossCause;
use cdm_records::loss_log::LossLog;
use cdm_scenario::Scenario;

use crate::messages::{FaultCode, LossNotice};

/// The loss a member's fault report announces, if it is one: its real vehicle lost, taken over
/// or disarmed (the member stops flying it; the team repairs around it, real time).
pub fn reported_loss(code: FaultCode) -> Option<LossCause> {
    match code {
        FaultCode::VehicleLost => Some(LossCause::VehicleLost),
        FaultCode::VehicleMode => Some(LossCause::VehicleMode),
        FaultCode::VehicleDisarmed => Some(LossCause::VehicleDisarmed),
        _ => None,
    }
}

/// Members killed or found dead whose last states are still to be drained: each is lost
/// after one more drain of the transport (the loop marks a drain with [`Self::turn`]), so
/// every state it published is in first.
#[derive(Debug, Clone, Default)]
pub struct Dying(Vec<(u32, LossCause, bool)>);

impl Dying {
    /// Member `id` is dying of `cause` (a repeat changes nothing).
    pub fn push(&mut self, id: u32, cause: LossCause) {
        if !self.contains(id) {
            self.0.push((id, cause, false));
        }
    }

    /// True while `id` is dying.
    pub fn contains(&self, id: u32) -> bool {
        self.0.iter().any(|d| d.0 == id)
    }

    /// A new turn of the loop: the transport is drained next.
    pub fn turn(&mut self) {
        self.0.iter_mut().for_each(|d| d.2 = true);
    }

    /// The members drained once since they were pushed, taken (in the order they died).
    pub fn take_drained(&mut self) -> Vec<(u32, LossCause)> {
        let (drained, rest): (Vec<_>, Vec<_>) = self.0.drain(..).partition(|d| d.2);
        self.0 = rest;
        drained.into_iter().map(|(id, c, _)| (id, c)).collect()
    }
}

/// A repair whose new links did not all connect in time.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinksTimedOut {
    /// The loss being repaired.
    pub id: u32,
    /// Links (reader, writer) still missing.
    pub missing: Vec<(u32, u32)>,
}

/// A loss announced whose new links are awaited.
#[derive(Debug, Clone)]
struct Linking {
    links: BTreeSet<(u32, u32)>,
    since: Duration,
}

/// The team's losses.
#[derive(Debug, Clone)]
pub struct TeamLosses {
    log: LossLog,
    ids: Vec<u32>,
    /// Scripted losses not yet carried out: (last tick L, id), sorted.
    scripted: Vec<(u64, u32)>,
    /// Every loss: (first tick without it, id, cause): the announced ones in the order they
    /// were announced, then the others in tick order.
    lost: Vec<(u64, u32, LossCause)>,
    /// Losses announced so far (a prefix of `lost`) and how many have their links connected.
    announced: usize,
    linked: usize,
    linking: Option<Linking>,
    /// Links already connected (the original graph's and earlier repairs').
    connected: BTreeSet<(u32, u32)>,
    /// The highest tick received from each member (`ids` order).
    seen: Vec<Option<u64>>,
}

impl TeamLosses {
    /// No loss yet; `scripted` are the (id, last tick) of `--lose`.
    pub fn new(s: &Scenario, scripted: &[(u32, u64)]) -> Self {
        let mut sorted: Vec<(u64, u32)> = scripted.iter().map(|&(id, l)| (l, id)).collect();
        sorted.sort_unstable();
        TeamLosses {
            log: LossLog::new(s),
            ids: s.formation.members.iter().map(|m| m.id).collect(),
            scripted: sorted,
            lost: Vec::new(),
            announced: 0,
            linked: 0,
            linking: None,
            connected: cdm_records::loss_log::links(&s.formation, &BTreeSet::new()),
            seen: vec![None; s.formation.members.len()],
        }
    }

    /// A state of member `id` at `tick` arrived.
    pub fn saw(&mut self, id: u32, tick: u64) {
        if let Some(k) = self.ids.iter().position(|&j| j == id) {
            let s = &mut self.seen[k];
            *s = Some(s.map_or(tick, |t| t.max(tick)));
        }
    }

    /// [`Self::saw`] for the member at formation index `k` (no search; `id` checks the index
    /// matches this book's order, else it is searched as by `saw`).
    pub fn saw_at(&mut self, k: usize, id: u32, tick: u64) {
        if self.ids.get(k) != Some(&id) {
            return self.saw(id, tick);
        }
        let s = &mut self.seen[k];
        *s = Some(s.map_or(tick, |t| t.max(tick)));
    }

    /// The highest tick received from `id`.
    pub fn seen(&self, id: u32) -> Option<u64> {
        let k = self.ids.iter().position(|&j| j == id)?;
        self.seen[k]
    }

    /// The highest tick that may be granted: a scripted loss's member must publish its tick L
    /// and nothing after it, so grants stop at L until it is carried out.
    pub fn cap(&self, last: u64) -> u64 {
        self.scripted.first().map_or(last, |&(l, _)| l.min(last))
    }

    /// The scripted loss to carry out now: its member has published its tick L (`seen` gives
    /// a member's highest tick received).
    pub fn scripted_due(&self, seen: impl Fn(u32) -> Option<u64>) -> Option<u32> {
        let &(l, id) = self.scripted.first()?;
        seen(id).is_some_and(|t| t >= l).then_some(id)
    }

    /// Member `id` is lost after its tick-`last_tick` state (`None`: it published nothing).
    /// Returns the tick from which its repair applies.
    pub fn lose(&mut self, id: u32, last_tick: Option<u64>, cause: LossCause) -> u64 {
        self.lose_from(id, last_tick.map_or(0, |t| t + 1), cause)
    }

    /// Member `id` is lost, its repair applying from tick `from` (lockstep: the tick after its
    /// last state; real time: a lead after the loss was found, `team_realtime`).
    pub fn lose_from(&mut self, id: u32, from: u64, cause: LossCause) -> u64 {
        self.scripted.retain(|&(_, j)| j != id);
        if self.is_lost(id) {
            return from;
        }
        self.log.add(id, from);
        // Losses not announced yet go in tick order: members replay the log in tick order
        // (`LossLog::epochs`), so a loss announced after one of a later tick would change links
        // from a tick its readers' neighbours may have flown past. Several losses found at once
        // (a lost host's members, up to a window apart) are announced earliest first.
        let at = self.lost[self.announced..]
            .iter()
            .position(|&(t, _, _)| t > from)
            .map_or(self.lost.len(), |k| self.announced + k);
        self.lost.insert(at, (from, id, cause));
        from
    }

    /// True once `id` was lost (at any tick).
    pub fn is_lost(&self, id: u32) -> bool {
        self.lost.iter().any(|&(_, j, _)| j == id)
    }

    /// True when `id` has no state at `tick` because it was lost.
    pub fn lost_at(&self, id: u32, tick: u64) -> bool {
        self.lost.iter().any(|&(t, j, _)| j == id && t <= tick)
    }

    /// How many states complete `tick`.
    pub fn expected(&self, tick: u64) -> usize {
        self.ids.len() - self.lost.iter().filter(|&&(t, _, _)| t <= tick).count()
    }

    /// Losses whose repair applies from `tick`, grouped by cause (the audit records them before
    /// it observes `tick`).
    pub fn due_at(&self, tick: u64) -> Vec<(LossCause, Vec<u32>)> {
        let mut out: Vec<(LossCause, Vec<u32>)> = Vec::new();
        let mut at: Vec<(LossCause, u32)> = self
            .lost
            .iter()
            .filter(|&&(t, _, _)| t == tick)
            .map(|&(_, id, c)| (c, id))
            .collect();
        at.sort_unstable();
        for (c, id) in at {
            match out.last_mut() {
                Some((k, v)) if *k == c => v.push(id),
                _ => out.push((c, vec![id])),
            }
        }
        out
    }

    /// The notice every clock message carries (the latest loss announced), if any.
    pub fn notice(&self) -> Option<LossNotice> {
        let k = self.announced.checked_sub(1)?;
        let (tick, id, _) = self.lost[k];
        Some(LossNotice {
            seq: self.announced as u32,
            id,
            tick,
            linked: self.linked as u32,
        })
    }

    /// Moves the announcements on at `now`: the next loss is announced once the previous one's
    /// links are connected (`linked(reader, writer)`), or at once when it has the same tick:
    /// losses of one tick make one repair (`LossLog::epochs`), and members fly none of it
    /// before all its losses are announced and linked (`MemberLosses::due`). True when the
    /// notice changed (publish a clock message). Fails when a repair's links are not connected
    /// within `timeout`.
    pub fn poll(
        &mut self,
        now: Duration,
        timeout: Duration,
        mut linked: impl FnMut(u32, u32) -> bool,
    ) -> Result<bool, LinksTimedOut> {
        let same_tick =
            |k: usize| k > 0 && k < self.lost.len() && self.lost[k].0 == self.lost[k - 1].0;
        if self.linking.is_some() && same_tick(self.announced) {
            let since = self.linking.as_ref().map_or(now, |l| l.since);
            let mut before = self.linking.take().map(|l| l.links).unwrap_or_default();
            before.retain(|&(r, w)| !self.is_lost(r) && !self.is_lost(w));
            self.announce_next(since);
            if let Some(l) = &mut self.linking {
                l.links.extend(before);
            }
            return Ok(true);
        }
        if let Some(l) = &mut self.linking {
            // A link to a member lost since it was awaited never connects, and needs not: the
            // next announcement's repair goes around that member (several losses at once, as a
            // lost host's members are).
            let lost = &self.lost;
            let gone = |id: u32| lost.iter().any(|&(_, j, _)| j == id);
            l.links
                .retain(|&(r, w)| !gone(r) && !gone(w) && !linked(r, w));
            if !l.links.is_empty() {
                if now.saturating_sub(l.since) > timeout {
                    return Err(LinksTimedOut {
                        id: self.lost[self.announced - 1].1,
                        missing: l.links.iter().copied().collect(),
                    });
                }
                return Ok(false);
            }
            self.linking = None;
            self.linked = self.announced;
            return Ok(true);
        }
        if self.announced == self.lost.len() {
            return Ok(false);
        }
        self.announce_next(now);
        Ok(true)
    }

    /// Announces the next loss and starts waiting for its repair's new links.
    fn announce_next(&mut self, now: Duration) {
        self.announced += 1;
        let dead: BTreeSet<u32> = self.lost.iter().map(|&(_, id, _)| id).collect();
        // Members know the announced losses only: their links are the ones to wait for.
        let unknown: BTreeSet<u32> = self.lost[self.announced..].iter().map(|l| l.1).collect();
        let links: BTreeSet<(u32, u32)> = self
            .log
            .without(&unknown)
            .new_links()
            .into_iter()
            .filter(|(r, w)| !dead.contains(r) && !dead.contains(w))
            .filter(|l| !self.connected.contains(l))
            .collect();
        self.connected.extend(&links);
        self.linking = Some(Linking { links, since: now });
    }

    /// The links of the announced repair not seen connected yet (reader, writer).
    pub fn awaited(&self) -> Vec<(u32, u32)> {
        self.linking
            .as_ref()
            .map_or_else(Vec::new, |l| l.links.iter().copied().collect())
    }

    /// True when the loop should ask which awaited links are connected, `since` the last time
    /// it asked: a loss to announce (or a repair with no new link) at once; awaited links
    /// every `slice`.
    pub fn links_to_check(&self, since: Duration, slice: Duration) -> bool {
        self.busy() && (self.awaited().is_empty() || since >= slice)
    }

    /// True while an announced repair waits for its links, or a loss waits to be announced.
    pub fn busy(&self) -> bool {
        self.linking.is_some() || self.announced < self.lost.len()
    }

    /// Every loss so far: (first tick without it, id, cause).
    pub fn losses(&self) -> &[(u64, u32, LossCause)] {
        &self.lost
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> Scenario {
        Scenario::builtin("paper40").unwrap()
    }

    #[test]
    fn a_scripted_loss_caps_grants_until_its_member_published_its_tick() {
        let s = paper();
        let id = s.formation.members[7].id;
        let mut t = TeamLosses::new(&s, &[(id, 30)]);
        assert_eq!(t.cap(1000), 30);
        assert_eq!(t.scripted_due(|_| Some(29)), None);
        assert_eq!(t.scripted_due(|j| (j == id).then_some(30)), Some(id));
        assert_eq!(t.lose(id, Some(30), LossCause::Scripted), 31);
        assert_eq!(t.cap(1000), 1000);
        assert_eq!(t.expected(30), 40);
        assert_eq!(t.expected(31), 39);
        assert!(t.lost_at(id, 31) && !t.lost_at(id, 30));
        assert_eq!(t.due_at(31), vec![(LossCause::Scripted, vec![id])]);
        assert!(t.due_at(30).is_empty());
    }

    #[test]
    fn a_link_to_a_member_lost_while_it_is_awaited_is_not_awaited_any_more() {
        let s = paper();
        let first = s.formation.members[7].id;
        let mut t = TeamLosses::new(&s, &[]);
        t.lose(first, Some(10), LossCause::Killed);
        let sec = Duration::from_secs;
        assert!(t.poll(sec(0), sec(5), |_, _| false).unwrap());
        let awaited = t.awaited();
        let &(_, writer) = awaited.first().expect("a repair opens links");
        // Its writer is lost too (as a lost host's members are, one exit after another).
        t.lose(writer, Some(10), LossCause::Killed);
        let mut asked = BTreeSet::new();
        let _ = t.poll(sec(1), sec(5), |r, w| {
            asked.insert((r, w));
            false
        });
        assert!(
            asked.iter().all(|&(r, w)| r != writer && w != writer),
            "{asked:?}"
        );
        assert!(t.awaited().iter().all(|&(r, w)| r != writer && w != writer));
    }

    #[test]
    fn losses_of_one_tick_are_announced_back_to_back_and_linked_together() {
        let s = paper();
        let readers: Vec<u32> = s
            .formation
            .out_neighbors()
            .into_iter()
            .filter(|(_, r)| !r.is_empty())
            .map(|(id, _)| id)
            .take(3)
            .collect();
        let mut t = TeamLosses::new(&s, &[]);
        t.lose(readers[0], Some(40), LossCause::Killed);
        t.lose(readers[1], Some(40), LossCause::Killed);
        t.lose(readers[2], Some(41), LossCause::Killed);
        let sec = Duration::from_secs;
        let notice = |t: &TeamLosses| t.notice().map(|n| (n.seq, n.tick, n.linked));
        assert!(t.poll(sec(0), sec(5), |_, _| false).unwrap());
        assert_eq!(notice(&t), Some((1, 41, 0)));
        // The second of tick 41 goes without waiting for the first's links.
        assert!(t.poll(sec(0), sec(5), |_, _| false).unwrap());
        assert_eq!(notice(&t), Some((2, 41, 0)));
        // Tick 42's waits until both are linked, which they are together.
        assert!(!t.poll(sec(1), sec(5), |_, _| false).unwrap());
        assert!(t.poll(sec(1), sec(5), |_, _| true).unwrap());
        assert_eq!(notice(&t), Some((2, 41, 2)));
        assert!(t.poll(sec(1), sec(5), |_, _| false).unwrap());
        assert_eq!(notice(&t), Some((3, 42, 2)));
    }

    #[test]
    fn losses_found_together_are_announced_earliest_tick_first() {
        // A lost host's members, handed over at once, up to a window apart: announced in tick
        // order whatever order they were found in, after what was already announced.
        let s = paper();
        let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
        let mut t = TeamLosses::new(&s, &[]);
        t.lose(ids[30], Some(500), LossCause::Killed);
        let sec = Duration::from_secs;
        assert!(t.poll(sec(0), sec(5), |_, _| true).unwrap());
        for (id, last) in [
            (ids[9], 1015),
            (ids[3], 768),
            (ids[12], 1015),
            (ids[4], 900),
        ] {
            t.lose(id, Some(last), LossCause::Killed);
        }
        let order: Vec<(u64, u32)> = t.losses().iter().map(|&(k, id, _)| (k, id)).collect();
        assert_eq!(
            order,
            [
                (501, ids[30]),
                (769, ids[3]),
                (901, ids[4]),
                (1016, ids[9]),
                (1016, ids[12])
            ]
        );
        let mut announced = vec![];
        for k in 1..10 {
            let _ = t.poll(sec(k), sec(5), |_, _| true).unwrap();
            announced.extend(t.notice().map(|n| n.id));
        }
        announced.dedup();
        assert_eq!(announced, [ids[30], ids[3], ids[4], ids[9], ids[12]]);
    }

    #[test]
    fn losses_are_announced_one_at_a_time_and_linked_when_every_new_link_is_in() {
        let s = paper();
        let outs = s.formation.out_neighbors();
        let readers: Vec<u32> = outs
            .iter()
            .filter(|(_, r)| !r.is_empty())
            .map(|(&id, _)| id)
            .take(2)
            .collect();
        let mut t = TeamLosses::new(&s, &[]);
        assert_eq!(t.notice(), None);
        t.lose(readers[0], Some(10), LossCause::Killed);
        t.lose(readers[1], Some(12), LossCause::Exited);
        let sec = Duration::from_secs;
        assert!(t.poll(sec(0), sec(5), |_, _| false).unwrap());
        let n = t.notice().unwrap();
        assert_eq!((n.seq, n.id, n.tick, n.linked), (1, readers[0], 11, 0));
        // Waiting for the links: the second loss is not announced yet.
        let mut asked = BTreeSet::new();
        assert!(!t
            .poll(sec(1), sec(5), |r, w| {
                asked.insert((r, w));
                false
            })
            .unwrap());
        assert!(!asked.is_empty(), "a repair opens links");
        assert!(asked
            .iter()
            .all(|&(r, w)| r != readers[0] && w != readers[0]));
        // A third loss found meanwhile: its links are not awaited before it is announced.
        let third = s
            .formation
            .members
            .iter()
            .map(|m| m.id)
            .find(|id| !readers.contains(id));
        let third = third.unwrap();
        t.lose(third, Some(14), LossCause::Scripted);
        let mut asked_now = BTreeSet::new();
        let _ = t.poll(sec(1), sec(5), |r, w| {
            asked_now.insert((r, w));
            false
        });
        assert_eq!(asked, asked_now, "links of an unannounced loss awaited");
        let err = t.poll(sec(9), sec(5), |_, _| false).unwrap_err();
        assert_eq!(err.id, readers[0]);
        assert!(t.poll(sec(9), sec(5), |_, _| true).unwrap());
        assert_eq!(t.notice().unwrap().linked, 1);
        assert!(t.poll(sec(9), sec(5), |_, _| true).unwrap());
        let n = t.notice().unwrap();
        assert_eq!((n.seq, n.id, n.tick, n.linked), (2, readers[1], 13, 1));
        assert!(t.poll(sec(9), sec(5), |_, _| true).unwrap());
        assert_eq!(t.notice().unwrap().linked, 2);
        assert!(t.poll(sec(9), sec(5), |_, _| true).unwrap());
        assert!(t.poll(sec(9), sec(5), |_, _| true).unwrap());
        assert!(!t.poll(sec(9), sec(5), |_, _| true).unwrap());
        assert_eq!(t.notice().unwrap().linked, 3);
    }
}
