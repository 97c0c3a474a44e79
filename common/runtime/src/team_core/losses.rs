//! The team core's side of losing members, in both pacings: a scripted loss's member is killed
//! once it has published its tick (lockstep grants stop there meanwhile), a member found dead,
//! silent (lockstep) or stale (real time), or reporting its vehicle lost (real time), is lost,
//! and after one more drain of its states the loss is applied, here and nowhere else: the tick
//! its readers fly the repair from is the pacing's ([`LossPacing::repair_from`]), the notices
//! go out one at a time, each once the previous repair's new links are connected. With
//! `--on-loss stop` a loss is a fault (lockstep: after the ticks before it complete, as
//! `simulate` records it). A member's exit or silence just after the orchestrator itself
//! stalled is no loss but the stall's fault. Decisions only: the loop kills, reaps and asks the
//! transport.

use std::time::Duration;

use super::{FaultRank, LostMember, Pacing, TeamAction, TeamCore, TeamState, WAIT_SLICE};
use crate::messages::FaultCode;
use crate::process_exit::ProcessExit;
use crate::team_fault::TeamFault;
use crate::team_loss::{reported_loss, Dying, LossCause, TeamLosses};

/// What applying a loss asks of the pacing.
pub(super) trait LossPacing {
    /// The newest tick heard from member `id` (`book` holds what lockstep received).
    fn newest_tick(&self, book: &TeamLosses, id: u32) -> Option<u64>;

    /// The tick the repair of a loss found at `now` applies from, its member's newest tick
    /// being `last`; `after_earlier` is the tick after the previous repair's.
    fn repair_from(&self, now: Duration, last: Option<u64>, after_earlier: u64) -> u64;

    /// Member `id` is lost of `cause` after its tick `last` (`from`: its repair's tick; `None`
    /// under `--on-loss stop`): it is waited for no more.
    fn lost(
        &mut self,
        id: u32,
        cause: LossCause,
        last_from: (Option<u64>, Option<u64>),
        now: Duration,
    );

    /// A loss to hand to the audit now (real time).
    fn take_lost(&mut self) -> Option<LostMember>;

    /// How long a repair's new links may take to connect.
    fn link_timeout(&self) -> Duration;

    /// The tick (lockstep) or audit instant (real time) a fault found now names.
    fn position(&self) -> u64;

    /// The losses moved on (a repair linked): lockstep restarts its silence deadline.
    fn progressed(&mut self, now: Duration);
}

/// The losses of a run as the team core handles them.
#[derive(Debug)]
pub(super) struct LossEvents {
    pub(super) book: TeamLosses,
    /// Dead, silent or vehicle-lost members are lost and repaired around (`--on-loss repair`
    /// with spawned members); otherwise only scripted losses happen, each a fault.
    pub(super) repairs: bool,
    /// Killed or found dead, their last states not yet drained.
    dying: Dying,
    /// Members that reported their vehicle lost (their states are all in: a report follows).
    reported: Vec<(u32, LossCause)>,
    last_link_check: Duration,
    /// The loss notice changed: publish the clock message again.
    republish: bool,
    /// The latest repair tick given (real time gives each loss a tick of its own).
    last_given: Option<u64>,
}

impl LossEvents {
    /// A new turn of the loop: the transport is drained next.
    pub(super) fn turn(&mut self) {
        self.dying.turn();
    }
}

impl TeamCore {
    /// The same core handling `book`'s losses. `repairs`: dead, silent and vehicle-lost
    /// members are lost and repaired around (`--on-loss repair` with spawned members); otherwise
    /// only scripted losses happen, each a fault (`--on-loss stop`).
    pub fn with_losses(mut self, book: TeamLosses, repairs: bool) -> Self {
        if let Pacing::Lockstep(g) = &mut self.pacing {
            g.cap_first_grant(&book);
        }
        self.t.losses = Some(LossEvents {
            book,
            repairs,
            dying: Dying::default(),
            reported: Vec::new(),
            last_link_check: Duration::ZERO,
            republish: false,
            last_given: None,
        });
        self
    }

    /// The losses so far (the audit records them, telemetry leaves their rows out).
    pub fn losses(&self) -> Option<&TeamLosses> {
        self.t.losses.as_ref().map(|l| &l.book)
    }

    /// True once member `id` is lost, or being lost (killed or seen dead, its last states
    /// still to drain).
    pub fn is_gone(&self, id: u32) -> bool {
        self.t.is_gone(id)
    }

    /// The answer to [`TeamAction::CheckLinks`]: `linked(reader, writer)` tells whether a link
    /// is connected. Links that do not join within the pacing's timeout stop the team.
    pub fn on_links(&mut self, now: Duration, linked: impl FnMut(u32, u32) -> bool) {
        let p: &mut dyn LossPacing = match &mut self.pacing {
            Pacing::Lockstep(g) => g,
            Pacing::Realtime(w) => w,
        };
        let (timeout, tick) = (p.link_timeout(), p.position());
        let t = &mut self.t;
        let Some(l) = &mut t.losses else { return };
        match l.book.poll(now, timeout, linked) {
            Ok(changed) => {
                l.republish |= changed;
                if changed {
                    p.progressed(now);
                }
            }
            Err(e) => {
                t.halt.get_or_insert(TeamFault::RepairUnlinked {
                    id: e.id,
                    missing: e.missing,
                    timeout,
                    tick,
                });
            }
        }
    }
}

impl TeamState {
    /// True once member `id` is lost, or being lost.
    pub(super) fn is_gone(&self, id: u32) -> bool {
        self.losses
            .as_ref()
            .is_some_and(|l| l.book.is_lost(id) || l.dying.contains(id))
    }

    /// True when losses are repaired and the orchestrator did not stall just before `now`.
    fn repairs_now(&self, now: Duration) -> bool {
        let blamed = self.stall.blames(now);
        self.losses.as_ref().is_some_and(|l| l.repairs) && !blamed
    }

    /// Member `id` is lost of `cause`, its states all drained, found at `now`: the one place a
    /// loss is applied. Repaired: its repair gets the pacing's tick. Under `--on-loss stop`: the
    /// fault after its last tick.
    fn apply_loss(&mut self, p: &mut impl LossPacing, id: u32, cause: LossCause, now: Duration) {
        let Some(l) = self.losses.as_mut() else {
            return;
        };
        let last = p.newest_tick(&l.book, id);
        if !l.repairs {
            let from = l.book.lose(id, last, cause);
            p.lost(id, cause, (last, None), now);
            let rank = FaultRank {
                echo: false,
                tick: from,
                member: usize::MAX,
            };
            self.keep_fault(rank, &TeamFault::LostStop { id, from }, now);
            return;
        }
        let after_earlier = l.last_given.map_or(0, |t| t + 1);
        let from = p.repair_from(now, last, after_earlier);
        l.last_given = Some(from);
        l.book.lose_from(id, from, cause);
        p.lost(id, cause, (last, Some(from)), now);
    }

    /// Apply the drained losses, hand one to the audit, republish a changed notice, carry out
    /// a due scripted loss, ask about awaited links.
    pub(super) fn loss_action(
        &mut self,
        p: &mut impl LossPacing,
        now: Duration,
    ) -> Option<TeamAction> {
        let l = self.losses.as_mut()?;
        let mut taken = std::mem::take(&mut l.reported);
        taken.extend(l.dying.take_drained());
        for (id, cause) in taken {
            self.apply_loss(p, id, cause, now);
        }
        if let Some(lost) = p.take_lost() {
            return Some(TeamAction::Lost(lost));
        }
        let l = self.losses.as_mut()?;
        if std::mem::take(&mut l.republish) {
            if let Some(n) = l.book.notice() {
                return Some(TeamAction::Announce(n));
            }
        }
        let book = &l.book;
        if let Some(id) = book.scripted_due(|id| p.newest_tick(book, id)) {
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

    /// A member process seen exited is lost (`how` says whether it was killed) when losses are
    /// repaired and the orchestrator did not stall just before (then it is a fault): true when
    /// it was taken so.
    pub(super) fn lost_on_exit(&mut self, id: u32, how: &ProcessExit, now: Duration) -> bool {
        if !self.repairs_now(now) {
            return false;
        }
        if let Some(l) = self.losses.as_mut().filter(|l| !l.book.is_lost(id)) {
            l.dying.push(id, how.loss_cause());
        }
        true
    }

    /// A member's report of its own vehicle's loss (`code`) is a loss, not a fault, when losses
    /// are repaired: true when it was taken so.
    pub(super) fn lost_on_report(&mut self, id: u32, code: FaultCode) -> bool {
        let Some(cause) = reported_loss(code) else {
            return false;
        };
        let Some(l) = self.losses.as_mut().filter(|l| l.repairs) else {
            return false;
        };
        l.reported.push((id, cause));
        true
    }

    /// Members silent past the deadline are killed and lost when losses are repaired and the
    /// orchestrator did not stall just before; `None` leaves them the pacing's fault.
    pub(super) fn kill_silent(&mut self, silent: &[u32], now: Duration) -> Option<TeamAction> {
        if silent.is_empty() || !self.repairs_now(now) {
            return None;
        }
        let l = self.losses.as_mut()?;
        for &id in silent {
            l.dying.push(id, LossCause::Silent);
        }
        Some(TeamAction::Kill(silent.to_vec()))
    }

    /// True when losses are repaired (`--on-loss repair` with spawned members).
    pub(super) fn repairs(&self) -> bool {
        self.losses.as_ref().is_some_and(|l| l.repairs)
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
                TeamAction::Flush => {}
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
                c.on_state(&StateMsg::ok(tick, 7, id, [0.0; 12]), ms(0));
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
        let core =
            TeamCore::lockstep(cfg, ms(0)).with_losses(TeamLosses::new(&s, scripted), repairs);
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
        let n = c.losses().unwrap().notice().unwrap();
        assert!(a.contains(&TeamAction::Announce(n)), "{a:?}");
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
        let a = turn(&mut c, ms(4), false);
        assert!(
            !a.iter().any(|x| matches!(x, TeamAction::Stop(..))),
            "the others may still send tick 6: {a:?}"
        );
        // The others fly tick 6; member 20 never will: the team stops at once, no grace.
        let others: Vec<u32> = ids.iter().copied().filter(|&i| i != 20).collect();
        send(&mut c, &others, 6..=6);
        let a = turn(&mut c, ms(5), false);
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
        c.on_exited(20, ProcessExit::Signal(9), ms(3));
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
