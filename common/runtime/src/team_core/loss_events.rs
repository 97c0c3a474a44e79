//! The team core's side of losing members (`--on-loss repair`): a scripted loss's
//! member is killed once it has published its tick (grants stop there meanwhile), a member
//! found dead or silent is lost, and after one more drain of its states its loss is announced
//! with the tick after its last state; the next is announced once the repair's new links are
//! connected. With `--on-loss stop` a scripted loss is a fault, as `simulate` records it, and a
//! dead member stays the fault of `team_core.rs`. Decisions only: the loop kills, reaps and asks
//! the transport.

use std::time::Duration;

use super::{first_grant, FaultRank, LossEvents, Stopping, TeamAction, TeamCore, WAIT_SLICE};
use crate::team_fault::TeamFault;
use crate::team_loss::{exit_cause, Dying, LossCause, TeamLosses};

impl TeamCore {
    /// The same core handling `book`'s losses. `repairs`: dead or silent members are lost and
    /// repaired around (`--on-loss repair` with spawned members); otherwise only scripted losses
    /// happen, each a fault (`--on-loss stop`).
    pub fn with_losses(mut self, book: TeamLosses, repairs: bool) -> Self {
        self.grant = first_grant(self.window, book.cap(self.cfg.last_tick));
        self.losses = Some(LossEvents {
            book,
            repairs,
            dying: Dying::default(),
            last_link_check: Duration::ZERO,
            republish: false,
        });
        self
    }

    /// The losses so far (the loop's audit records them, telemetry leaves their rows out).
    pub fn losses(&self) -> Option<&TeamLosses> {
        self.losses.as_ref().map(|l| &l.book)
    }

    /// The answer to [`TeamAction::CheckLinks`]: `linked(reader, writer)` tells whether a link
    /// is connected.
    pub fn on_links(&mut self, now: Duration, linked: impl FnMut(u32, u32) -> bool) {
        let timeout = self.cfg.agent_timeout;
        let Some(l) = &mut self.losses else { return };
        match l.book.poll(now, timeout, linked) {
            Ok(changed) => {
                l.republish |= changed;
                if changed {
                    self.last_progress = now;
                }
            }
            Err(e) => {
                let fault = TeamFault::RepairUnlinked {
                    id: e.id,
                    missing: e.missing,
                    timeout,
                    tick: self.next_tick,
                };
                self.interrupt.get_or_insert(fault.stop());
            }
        }
    }

    /// How many states complete `tick` (fewer once members are lost).
    pub(super) fn expected(&self, tick: u64) -> usize {
        self.losses
            .as_ref()
            .map_or(self.cfg.ids.len(), |l| l.book.expected(tick))
    }

    /// The highest tick that may be granted.
    pub(super) fn cap(&self) -> u64 {
        let last = self.cfg.last_tick;
        self.losses.as_ref().map_or(last, |l| l.book.cap(last))
    }

    /// True when `id` has no state at `tick` because it was lost.
    pub(super) fn is_lost(&self, id: u32, tick: u64) -> bool {
        self.losses
            .as_ref()
            .is_some_and(|l| l.book.lost_at(id, tick))
    }

    /// Announce the dead, carry out a due scripted loss, republish a changed notice, ask about
    /// awaited links.
    pub(super) fn loss_action(&mut self, now: Duration) -> Option<TeamAction> {
        self.announce_dead(now);
        let l = self.losses.as_mut()?;
        if std::mem::take(&mut l.republish) {
            return Some(TeamAction::Grant(self.grant));
        }
        let book = &l.book;
        if let Some(id) = book.scripted_due(|id| book.seen(id)) {
            if !l.dying.contains(id) {
                l.dying.push(id, LossCause::Scripted);
                return Some(TeamAction::Kill(vec![id]));
            }
        }
        if l.book
            .links_to_check(now.saturating_sub(l.last_link_check), WAIT_SLICE)
        {
            l.last_link_check = now;
            return Some(TeamAction::CheckLinks);
        }
        None
    }

    /// Members killed or found dead whose states were drained since: lost after their last
    /// tick received. With `--on-loss stop` the first is a fault (ticks before it complete).
    fn announce_dead(&mut self, now: Duration) {
        let Some(l) = &mut self.losses else { return };
        for (id, cause) in l.dying.take_drained() {
            let from = l.book.lose(id, l.book.seen(id), cause);
            self.last_progress = now;
            if l.repairs {
                continue;
            }
            let rank = FaultRank {
                echo: false,
                tick: from,
                member: usize::MAX,
            };
            if rank.outranks(self.stopping.as_ref().map(|s| &s.rank)) {
                self.stopping = Some(Stopping {
                    record: TeamFault::LostStop { id, from }.record(),
                    since: now,
                    rank,
                });
            }
        }
    }

    /// A member process seen exited is lost (`killed` by a signal, else `exited`) when losses
    /// are repaired and the orchestrator did not stall just before (then it is a fault).
    /// `how` is `first_exited`'s wording ("was killed by signal 9", "exited with code 3").
    pub(super) fn lost_on_exit(&mut self, id: u32, how: &str, now: Duration) -> bool {
        let blamed = self.stall.blames(now);
        let Some(l) = self.losses.as_mut().filter(|l| l.repairs && !blamed) else {
            return false;
        };
        if !l.book.is_lost(id) {
            l.dying.push(id, exit_cause(how));
        }
        true
    }

    /// Past the silence deadline: the silent members are killed and lost (when losses are
    /// repaired and the orchestrator did not stall just before).
    pub(super) fn kill_silent(&mut self, now: Duration) -> Option<TeamAction> {
        let missing = self.missing();
        let blamed = self.stall.blames(now);
        let l = self.losses.as_mut().filter(|l| l.repairs && !blamed)?;
        if missing.is_empty() {
            return None;
        }
        for &id in &missing {
            l.dying.push(id, LossCause::Silent);
        }
        self.last_progress = now;
        Some(TeamAction::Kill(missing))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::{StateMsg, StopReason};
    use crate::team_core::TeamConfig;
    use cdm_model::outcome::FaultKind;
    use cdm_scenario::Scenario;

    fn ms(t: u64) -> Duration {
        Duration::from_millis(t)
    }

    /// The actions of one turn at `now`, up to a wait or a poll (`linked` answers link checks).
    fn turn(c: &mut TeamCore, now: Duration, linked: bool) -> Vec<TeamAction> {
        c.on_turn(now);
        let mut out = Vec::new();
        loop {
            let a = c.next_action(now);
            match &a {
                TeamAction::CheckLinks => c.on_links(now, |_, _| linked),
                TeamAction::Complete { states, .. } => c.recycle(states.clone()),
                TeamAction::Wait(_) | TeamAction::Poll | TeamAction::Kill(_) => {
                    out.push(a);
                    return out;
                }
                TeamAction::Stop(..) | TeamAction::Finished => {
                    out.push(a);
                    return out;
                }
                _ => {}
            }
            out.push(a);
        }
    }

    fn send(c: &mut TeamCore, ids: &[u32], ticks: std::ops::RangeInclusive<u64>) {
        for tick in ticks {
            for &id in ids {
                c.on_state(StateMsg::ok(tick, 7, id, [0.0; 12]), ms(0));
            }
        }
    }

    fn paper_core(scripted: &[(u32, u64)], repairs: bool) -> (TeamCore, Vec<u32>) {
        let s = Scenario::builtin("paper40").unwrap();
        let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
        let cfg = TeamConfig {
            ids: ids.clone(),
            window: 4,
            last_tick: 30,
            agent_timeout: Duration::from_secs(10),
        };
        let core = TeamCore::new(cfg, ms(0)).with_losses(TeamLosses::new(&s, scripted), repairs);
        (core, ids)
    }

    #[test]
    fn a_scripted_loss_is_killed_at_its_tick_then_announced_linked_and_flown_around() {
        let (mut c, ids) = paper_core(&[(20, 5)], true);
        let grants = |a: &[TeamAction]| -> Vec<u64> {
            a.iter()
                .filter_map(|x| match x {
                    TeamAction::Grant(g) => Some(*g),
                    _ => None,
                })
                .collect()
        };
        assert_eq!(grants(&turn(&mut c, ms(1), false)), [3]);
        send(&mut c, &ids, 0..=3);
        // Grants stop at the scripted tick 5 (not 3 + 4).
        assert_eq!(grants(&turn(&mut c, ms(2), false)), [5]);
        send(&mut c, &ids, 4..=5);
        let a = turn(&mut c, ms(3), false);
        assert_eq!(a.last(), Some(&TeamAction::Kill(vec![20])));
        // After one more drain the loss is lost from tick 6 and announced on the clock.
        let a = turn(&mut c, ms(4), false);
        assert!(!grants(&a).is_empty(), "{a:?}");
        let n = c.losses().unwrap().notice().unwrap();
        assert_eq!((n.seq, n.id, n.tick, n.linked), (1, 20, 6, 0));
        let others: Vec<u32> = ids.iter().copied().filter(|&i| i != 20).collect();
        send(&mut c, &others, 6..=8);
        let a = turn(&mut c, ms(30), true);
        let done: Vec<u64> = a
            .iter()
            .filter_map(|x| match x {
                TeamAction::Complete { tick, states } => {
                    let k = ids.iter().position(|&i| i == 20).unwrap();
                    assert_eq!(states[k].is_none(), *tick >= 6);
                    Some(*tick)
                }
                _ => None,
            })
            .collect();
        assert_eq!(done, [6, 7, 8], "ticks 0-5 completed before the kill");
        assert_eq!(c.losses().unwrap().notice().unwrap().linked, 1);
        assert_eq!(
            c.losses().unwrap().due_at(6),
            [(LossCause::Scripted, vec![20])]
        );
    }

    #[test]
    fn with_on_loss_stop_a_scripted_loss_is_a_fault_after_its_last_tick() {
        let (mut c, ids) = paper_core(&[(20, 5)], false);
        turn(&mut c, ms(1), false);
        send(&mut c, &ids, 0..=3);
        turn(&mut c, ms(2), false);
        send(&mut c, &ids, 4..=5);
        let a = turn(&mut c, ms(3), false);
        assert_eq!(a.last(), Some(&TeamAction::Kill(vec![20])));
        turn(&mut c, ms(4), false);
        let a = turn(&mut c, ms(600), false);
        match a.last() {
            Some(TeamAction::Stop(f, StopReason::AgentFault)) => {
                assert_eq!((f.kind, f.agent, f.tick), (FaultKind::Lost, Some(20), 6));
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_dead_or_silent_member_is_lost_when_repairs_are_on() {
        let (mut c, ids) = paper_core(&[], true);
        turn(&mut c, ms(1), false);
        send(&mut c, &ids, 0..=2);
        turn(&mut c, ms(2), false);
        c.on_exited(20, "was killed by signal 9".into(), ms(3));
        turn(&mut c, ms(4), false);
        assert_eq!(c.losses().unwrap().losses(), [(3, 20, LossCause::Killed)]);
        // Member 29 goes silent at tick 3: killed and lost after the agent timeout.
        let others: Vec<u32> = ids
            .iter()
            .copied()
            .filter(|&i| i != 20 && i != 29)
            .collect();
        send(&mut c, &others, 3..=3);
        turn(&mut c, ms(40), true);
        assert_eq!(c.losses().unwrap().notice().unwrap().linked, 1);
        // Turns a second apart (a longer gap is a stall of the orchestrator itself).
        let mut a = Vec::new();
        for t in 1..=12 {
            a.extend(turn(&mut c, ms(40 + 1000 * t), true));
        }
        assert!(a.contains(&TeamAction::Kill(vec![29])), "{a:?}");
        turn(&mut c, ms(12_100), true);
        let l = c.losses().unwrap().losses();
        assert_eq!(l[1], (3, 29, LossCause::Silent));
    }
}
