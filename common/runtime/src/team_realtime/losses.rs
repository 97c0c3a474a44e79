//! The real-time monitor's side of losing members (`--on-loss repair`, on one host), with no
//! I/O: the counterpart of the lockstep team core's `team_core/loss_events.rs`, over the same
//! book ([`TeamLosses`]: the notices, one at a time, and when a repair's new links are in) and
//! the same repair (`cdm_model::repair`, which every member computes from the notices with its
//! `LossLog`, as `simulate` does).
//!
//! A member is lost when its process exits (`killed`, `exited`), when its newest state grows
//! older than `--stale-after` (`silent`: the monitor kills it), when it reports its vehicle
//! lost, taken over or disarmed (`vehicle-lost`, `vehicle-mode`, `vehicle-disarmed`: it flies
//! nothing more), or when `--lose ID@SECONDS` says so (`scripted`: killed once it has published
//! its tick of SECONDS).
//!
//! When its readers switch. Real-time members wait for nobody, so by the time the monitor knows
//! of a loss the team has flown past the lost member's last tick L: lockstep's L + 1 is gone.
//! The notice carries a tick ahead instead, T = the first tick at or after the instant the loss
//! was found plus a lead ([`REPAIR_LEAD_OF_STALE`] of the stale bound), and after any earlier
//! loss's tick. Every reader flies its repaired link (the eq. 18 weights of its new triangle)
//! from its own tick T, so who switches, to what and when follow from the scenario and the
//! notices alone. The lead covers the notice, the new subscriptions, the monitor's check that
//! they joined and the hand-over of the new in-neighbours' states. Meanwhile the readers bring
//! the lost member's last state forward (the cubic model of a tick, `step::extrapolate_flat`);
//! they wait on a silent neighbour [`MEMBER_STALE_FACTOR`] times the stale bound (`launch`
//! tells them), so the monitor decides first.

use std::collections::VecDeque;
use std::time::Duration;

use super::{MonitorAction, RealtimeTeam};
use crate::realtime_monitor::MonitorEvent;
use crate::team_core::WAIT_SLICE;
use crate::team_fault::TeamFault;
use crate::team_loss::{exit_cause, reported_loss, Dying, LossCause, TeamLosses};

/// The lead of a repair's tick over the instant its loss was found, as a share of the stale
/// bound (0.25 s of the default 0.5 s): the readers then switch about 1.5 bounds after a silent
/// member's last state at the latest, half a bound before they would find it stale themselves.
pub const REPAIR_LEAD_OF_STALE: f64 = 0.5;

/// How many times the stale bound a member waits on a silent in-neighbour when the team
/// repairs its losses: the monitor finds the silence at one bound, and the repair applies
/// before the readers give up.
pub const MEMBER_STALE_FACTOR: u32 = 2;

/// A member lost, as the audit records it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LostMember {
    pub id: u32,
    pub cause: LossCause,
    /// Its newest state heard (`None`: it published nothing).
    pub last_tick: Option<u64>,
    /// The first audit instant without it (from it on, it is out of the audit and telemetry),
    /// and that instant's time: the first after its newest state, unless audited already.
    pub index: u64,
    pub t_s: f64,
    /// The tick its readers fly the repair from.
    pub tick: u64,
}

/// The losses of a real-time flight.
#[derive(Debug, Clone)]
pub struct RealtimeLosses {
    book: TeamLosses,
    /// Lost members are repaired around (`--on-loss repair`); otherwise a scripted loss is a
    /// fault after its last tick and everything else stops the team as before.
    repairs: bool,
    dying: Dying,
    /// Members whose vehicle they reported lost (their states are all in: a report follows).
    reported: Vec<(u32, LossCause)>,
    /// Losses not yet handed to the audit.
    found: VecDeque<LostMember>,
    /// The notice changed: publish the clock message again.
    republish: bool,
    last_link_check: Duration,
    /// The latest repair tick given (each loss gets a tick of its own).
    last_given: Option<u64>,
    /// A repair whose links did not join in time.
    failed: Option<TeamFault>,
}

impl RealtimeTeam {
    /// The same monitor handling `book`'s losses. `repairs`: dead, stale and vehicle-lost
    /// members are lost and repaired around (`--on-loss repair`, members spawned on one host);
    /// otherwise only scripted losses happen, each a fault (`--on-loss stop`).
    pub fn with_losses(mut self, book: TeamLosses, repairs: bool) -> Self {
        self.losses = Some(RealtimeLosses {
            book,
            repairs,
            dying: Dying::default(),
            reported: Vec::new(),
            found: VecDeque::new(),
            republish: false,
            last_link_check: Duration::ZERO,
            last_given: None,
            failed: None,
        });
        self
    }

    /// The losses so far.
    pub fn losses(&self) -> Option<&TeamLosses> {
        self.losses.as_ref().map(|l| &l.book)
    }

    /// A new turn of the loop, before it drains the transport: members killed or seen dead
    /// before it are lost after this drain.
    pub fn on_turn(&mut self) {
        if let Some(l) = &mut self.losses {
            l.dying.turn();
        }
    }

    /// True once member `id` is lost, or being lost (killed or seen dead, its last states
    /// still to drain).
    pub fn is_gone(&self, id: u32) -> bool {
        let lost = self.book.index_of(id).is_some_and(|k| self.book.is_lost(k));
        lost || self.losses.as_ref().is_some_and(|l| l.dying.contains(id))
    }

    /// The bound the members apply to a silent in-neighbour.
    pub(super) fn member_stale_after(&self) -> Duration {
        match &self.losses {
            Some(l) if l.repairs => self.plan.stale_after * MEMBER_STALE_FACTOR,
            _ => self.plan.stale_after,
        }
    }

    /// A member's report of its own vehicle's loss is a loss, not a fault, when losses are
    /// repaired: true when `event` was taken so.
    pub(super) fn lost_on_report(&mut self, event: &MonitorEvent) -> bool {
        let MonitorEvent::Fault { id, code, .. } = *event else {
            return false;
        };
        let Some(cause) = reported_loss(code) else {
            return false;
        };
        let Some(l) = self.losses.as_mut().filter(|l| l.repairs) else {
            return false;
        };
        l.reported.push((id, cause));
        true
    }

    /// A member process seen exited is lost (`killed` by a signal, else `exited`) when losses
    /// are repaired: true when it was taken so.
    pub(super) fn lost_on_exit(&mut self, id: u32, how: &str) -> bool {
        let Some(l) = self.losses.as_mut().filter(|l| l.repairs) else {
            return false;
        };
        l.dying.push(id, exit_cause(how));
        true
    }

    /// The answer to [`MonitorAction::CheckLinks`]: `linked(reader, writer)` tells whether a
    /// link is connected. Links that do not join within the stale bound stop the team.
    pub fn on_links(&mut self, now: Duration, linked: impl FnMut(u32, u32) -> bool) {
        let (timeout, tick) = (self.plan.stale_after, self.audits);
        let Some(l) = &mut self.losses else { return };
        match l.book.poll(now, timeout, linked) {
            Ok(changed) => l.republish |= changed,
            Err(e) => {
                l.failed.get_or_insert(TeamFault::RepairUnlinked {
                    id: e.id,
                    missing: e.missing,
                    timeout,
                    tick,
                });
            }
        }
    }

    /// What the losses ask for now: a stop (links that never joined; `--on-loss stop`'s
    /// scripted loss), a loss for the audit, a notice to publish, a member to kill (scripted,
    /// or stale), a look at awaited links.
    pub(super) fn loss_action(&mut self, now: Duration) -> Option<MonitorAction> {
        let now_s = self.time_s(now);
        let l = self.losses.as_mut()?;
        if let Some(f) = l.failed.take() {
            return Some(MonitorAction::Stop(f.stop()));
        }
        let mut taken = std::mem::take(&mut l.reported);
        taken.extend(l.dying.take_drained());
        for (id, cause) in taken {
            if let Some(stop) = self.take_loss(id, cause, now_s) {
                return Some(MonitorAction::Stop(stop.stop()));
            }
        }
        let bound_s = self.plan.stale_after.as_secs_f64();
        let (book, l) = (&self.book, self.losses.as_mut()?);
        if let Some(lost) = l.found.pop_front() {
            return Some(MonitorAction::Lost(lost));
        }
        if std::mem::take(&mut l.republish) {
            if let Some(n) = l.book.notice() {
                return Some(MonitorAction::Announce(n));
            }
        }
        let scripted = l.book.scripted_due(|id| book.newest_tick(id));
        let silent = l.repairs.then(|| book.stale(now_s, bound_s)).flatten();
        let kill = match (scripted, silent) {
            (Some(id), _) if !l.dying.contains(id) => Some((id, LossCause::Scripted)),
            (_, Some((id, _, _))) => Some((id, LossCause::Silent)),
            _ => None,
        };
        if let Some((id, cause)) = kill {
            l.dying.push(id, cause);
            return Some(MonitorAction::Kill(vec![id]));
        }
        if l.book
            .links_to_check(now.saturating_sub(l.last_link_check), WAIT_SLICE)
        {
            l.last_link_check = now;
            return Some(MonitorAction::CheckLinks);
        }
        None
    }

    /// Member `id` is lost of `cause`, found at `now_s` of the common time line: no audit
    /// instant waits for it any more, its body leaves the audit from the next instant, its
    /// repair gets its tick ([`Self::repair_tick`]). Under `--on-loss stop` (a scripted loss) it
    /// is the fault returned.
    fn take_loss(&mut self, id: u32, cause: LossCause, now_s: f64) -> Option<TeamFault> {
        let last = self.book.newest_tick(id);
        let tick = self.repair_tick(now_s, last);
        let k = self.book.index_of(id);
        let after_last = k
            .and_then(|k| self.book.newest_stamp_of(k))
            .map_or(0, |s| (s / self.plan.period_s).floor().max(0.0) as u64 + 1);
        if let Some(k) = k {
            self.book.lose(k);
        }
        let index = self.audits.max(after_last);
        let t_s = self.instant_s(index);
        let l = self.losses.as_mut()?;
        if !l.repairs {
            l.book.lose(id, last, cause);
            let from = last.map_or(0, |t| t + 1);
            return Some(TeamFault::LostStop { id, from });
        }
        l.last_given = Some(tick);
        l.book.lose_from(id, tick, cause);
        l.found.push_back(LostMember {
            id,
            cause,
            last_tick: last,
            index,
            t_s,
            tick,
        });
        None
    }

    /// The tick a loss found at `now_s` (the lost member's newest tick `last`) is repaired
    /// from: the first tick at or after `now_s` plus the lead, past its last state and past
    /// every earlier loss's tick (one loss per tick: every process then replays the same
    /// sequence of repairs, `LossLog::epochs`).
    fn repair_tick(&self, now_s: f64, last: Option<u64>) -> u64 {
        let lead_s = self.plan.stale_after.as_secs_f64() * REPAIR_LEAD_OF_STALE;
        // Float to integer casts saturate: a loss found before the start gives tick 0.
        let ahead = ((now_s + lead_s) / self.plan.dt_s).ceil().max(0.0) as u64;
        let after_last = last.map_or(0, |t| t + 1);
        let after_earlier = self
            .losses
            .as_ref()
            .and_then(|l| l.last_given)
            .map_or(0, |t| t + 1);
        ahead.max(after_last).max(after_earlier)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::{AgentStatus, FaultCode, StateMsg};
    use crate::realtime_monitor::MonitorCore;
    use crate::team_realtime::RealtimePlan;
    use cdm_model::outcome::FaultKind;
    use cdm_scenario::Scenario;

    fn ms(t: u64) -> Duration {
        Duration::from_millis(t)
    }

    /// generated10 at 10 Hz (dt 0.1 s), audited at 10 Hz up to tick 100, starting at 1 s on the
    /// fake clock, stale after 0.5 s, aligned phases; `scripted` as `--lose`.
    fn team(scripted: &[(u32, u64)], repairs: bool) -> (RealtimeTeam, Scenario) {
        let s = Scenario::generated(10).unwrap();
        let members: Vec<_> = s
            .formation
            .members
            .iter()
            .map(|m| (m.id, m.start, !m.role.is_leader()))
            .collect();
        let book = MonitorCore::new(&members, HASH, (0.1, 0.5), 0);
        let plan = RealtimePlan::new(ms(1000), (100, 0.1), 10.0, ms(500));
        let losses = TeamLosses::new(&s, scripted);
        let core = RealtimeTeam::new(plan, book, ms(0)).with_losses(losses, repairs);
        (core, s)
    }

    const HASH: u64 = 7;

    fn states(c: &mut RealtimeTeam, ids: impl Iterator<Item = u32> + Clone, ticks: u64) {
        for tick in 0..=ticks {
            for id in ids.clone() {
                c.on_state(&StateMsg::ok(tick, HASH, id, [id as f64; 12]));
            }
        }
    }

    /// One turn at `now`, as the loop runs it (links answered with `linked`): every action up
    /// to a wait, a finish or a stop.
    fn turn(c: &mut RealtimeTeam, now: Duration, linked: bool) -> Vec<MonitorAction> {
        c.on_turn();
        let mut out = Vec::new();
        for _ in 0..10_000 {
            let a = c.next_action(now);
            if a == MonitorAction::CheckLinks {
                c.on_links(now, |_, _| linked);
            }
            let end = matches!(
                a,
                MonitorAction::Wait(_)
                    | MonitorAction::Finished
                    | MonitorAction::Stop(_)
                    | MonitorAction::Kill(_)
            );
            out.push(a);
            if end {
                return out;
            }
        }
        panic!("the monitor never waited");
    }

    fn lost(actions: &[MonitorAction]) -> Vec<LostMember> {
        actions
            .iter()
            .filter_map(|a| match a {
                MonitorAction::Lost(x) => Some(*x),
                _ => None,
            })
            .collect()
    }

    fn notices(actions: &[MonitorAction]) -> Vec<(u32, u32, u64, u32)> {
        actions
            .iter()
            .filter_map(|a| match a {
                MonitorAction::Announce(n) => Some((n.seq, n.id, n.tick, n.linked)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn an_exited_member_is_lost_after_a_drain_and_repaired_a_lead_ahead() {
        let (mut c, _) = team(&[], true);
        states(&mut c, 1..=10, 12);
        turn(&mut c, ms(2100), true);
        c.on_exited(8, "was killed by signal 9".into());
        assert!(c.is_gone(8));
        // The next turn drains its last states (tick 12), then loses it: found at t = 1.2 s,
        // its readers switch at the first tick at or after 1.2 + 0.25 s; it leaves the audit
        // after its newest state (1.2 s).
        let a = turn(&mut c, ms(2200), false);
        let found = LostMember {
            id: 8,
            cause: LossCause::Killed,
            last_tick: Some(12),
            index: 13,
            t_s: 1.3,
            tick: 15,
        };
        assert_eq!(lost(&a)[0].index, found.index);
        assert!((lost(&a)[0].t_s - found.t_s).abs() < 1e-12);
        assert_eq!(
            lost(&a),
            [LostMember {
                t_s: lost(&a)[0].t_s,
                ..found
            }]
        );
        assert_eq!(notices(&a), [(1, 8, 15, 0)]);
        // Not linked yet: no second notice; once linked, the notice says so.
        let a = turn(&mut c, ms(2230), true);
        assert_eq!(notices(&a), [(1, 8, 15, 1)]);
        // The audits go on without it: instant 13 is heard by every member still flying.
        states(&mut c, (1..=10).filter(|&i| i != 8), 14);
        let a = turn(&mut c, ms(2500), true);
        let audited = |i| {
            a.iter()
                .any(|x| matches!(x, MonitorAction::Audit { index, .. } if *index == i))
        };
        assert!(audited(13), "{a:?}");
        assert!(!a.iter().any(|x| matches!(x, MonitorAction::Stop(_))));
    }

    #[test]
    fn a_stale_member_is_killed_then_lost_as_silent_and_losses_get_ticks_of_their_own() {
        let (mut c, _) = team(&[], true);
        states(&mut c, (1..=10).filter(|&i| i != 7), 15);
        states(&mut c, 7..=7, 10);
        // Member 7's newest (1.0 s) is 0.6 s old at 1.6 s: killed, then lost after a drain.
        let a = turn(&mut c, ms(2600), true);
        assert_eq!(a.last(), Some(&MonitorAction::Kill(vec![7])), "{a:?}");
        // Member 8 exits meanwhile: both lost, each at a tick of its own (8's the one after 7's,
        // though found at the same instant).
        c.on_exited(8, "exited with code 3".into());
        let a = turn(&mut c, ms(2610), false);
        let got: Vec<(u32, LossCause, u64)> =
            lost(&a).iter().map(|x| (x.id, x.cause, x.tick)).collect();
        assert_eq!(
            got,
            [(7, LossCause::Silent, 19), (8, LossCause::Exited, 20)]
        );
        // One notice at a time (both repairs open links: 8 and 10 read 7, 9 reads 8): the
        // second once the first is linked.
        assert_eq!(notices(&a), [(1, 7, 19, 0)]);
        let a = turn(&mut c, ms(2640), true);
        assert_eq!(notices(&a), [(1, 7, 19, 1), (2, 8, 20, 1)]);
        let a = turn(&mut c, ms(2670), true);
        assert_eq!(notices(&a), [(2, 8, 20, 2)]);
    }

    #[test]
    fn a_vehicle_taken_over_is_a_loss_under_repair_and_a_fault_under_stop() {
        let report = StateMsg::ok(30, HASH, 6, [0.0; 12]).with_status(AgentStatus::Fault {
            code: FaultCode::VehicleMode,
            peer: None,
        });
        let (mut c, _) = team(&[], true);
        states(&mut c, 1..=10, 30);
        c.on_state(&report);
        let a = turn(&mut c, ms(4000), true);
        let got: Vec<(u32, LossCause, Option<u64>)> = lost(&a)
            .iter()
            .map(|x| (x.id, x.cause, x.last_tick))
            .collect();
        assert_eq!(got, [(6, LossCause::VehicleMode, Some(30))]);
        let (mut c, _) = team(&[], false);
        states(&mut c, 1..=10, 30);
        c.on_state(&report);
        match turn(&mut c, ms(4000), true).last() {
            Some(MonitorAction::Stop((f, _))) => {
                assert_eq!((f.kind, f.agent), (FaultKind::VehicleLost, Some(6)));
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_scripted_loss_is_killed_once_its_tick_is_heard_and_under_stop_is_a_fault() {
        for repairs in [true, false] {
            let (mut c, _) = team(&[(4, 12)], repairs);
            states(&mut c, 1..=10, 11);
            let a = turn(&mut c, ms(2150), true);
            assert!(!a.contains(&MonitorAction::Kill(vec![4])), "{a:?}");
            states(&mut c, 1..=10, 13);
            let a = turn(&mut c, ms(2300), true);
            assert_eq!(a.last(), Some(&MonitorAction::Kill(vec![4])));
            let a = turn(&mut c, ms(2310), true);
            if repairs {
                let x = lost(&a);
                assert_eq!(
                    (x[0].id, x[0].cause, x[0].last_tick),
                    (4, LossCause::Scripted, Some(13))
                );
            } else {
                match a.last() {
                    Some(MonitorAction::Stop((f, _))) => {
                        assert_eq!((f.kind, f.agent, f.tick), (FaultKind::Lost, Some(4), 14));
                    }
                    other => panic!("{other:?}"),
                }
            }
        }
    }
}
