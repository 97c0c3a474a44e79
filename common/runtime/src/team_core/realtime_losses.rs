//! The real-time pacing's side of losing members (`--on-loss repair`, on one host): when the
//! readers of a lost member switch, and what the audit records. The loss itself is applied by
//! the team core (`team_core/losses.rs`), over the same book as lockstep ([`TeamLosses`]: the
//! notices, one at a time, and when a repair's new links are in) and the same repair
//! (`cdm_model::repair`, which every member computes from the notices with its `LossLog`, as
//! `simulate` does).
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

use std::time::Duration;

use super::losses::LossPacing;
use super::realtime::WallClock;
use super::LostMember;
use super::TeamState;
use crate::team_loss::{LossCause, TeamLosses};

/// The lead of a repair's tick over the instant its loss was found, as a share of the stale
/// bound (0.25 s of the default 0.5 s): the readers then switch about 1.5 bounds after a silent
/// member's last state at the latest, half a bound before they would find it stale themselves.
pub const REPAIR_LEAD_OF_STALE: f64 = 0.5;

/// How many times the stale bound a member waits on a silent in-neighbour when the team
/// repairs its losses: the monitor finds the silence at one bound, and the repair applies
/// before the readers give up.
pub const MEMBER_STALE_FACTOR: u32 = 2;

impl WallClock {
    /// The bound the members apply to a silent in-neighbour.
    pub(super) fn member_stale_after(&self, t: &TeamState) -> Duration {
        if t.repairs() {
            self.plan.stale_after * MEMBER_STALE_FACTOR
        } else {
            self.plan.stale_after
        }
    }
}

impl LossPacing for WallClock {
    fn newest_tick(&self, _: &TeamLosses, id: u32) -> Option<u64> {
        self.book.newest_tick(id)
    }

    /// The first tick at or after `now` plus the lead, past the lost member's last state and
    /// past every earlier loss's tick (one loss per tick: every process then replays the same
    /// sequence of repairs, `LossLog::epochs`).
    fn repair_from(&self, now: Duration, last: Option<u64>, after_earlier: u64) -> u64 {
        let lead_s = self.plan.stale_after.as_secs_f64() * REPAIR_LEAD_OF_STALE;
        // Float to integer casts saturate: a loss found before the start gives tick 0.
        let ahead = ((self.time_s(now) + lead_s) / self.plan.dt_s)
            .ceil()
            .max(0.0) as u64;
        let after_last = last.map_or(0, |t| t + 1);
        ahead.max(after_last).max(after_earlier)
    }

    /// No audit instant waits for the lost member any more; repaired, its body leaves the
    /// audit from the first instant after its newest state (unless audited already).
    fn lost(
        &mut self,
        id: u32,
        cause: LossCause,
        (last_tick, from): (Option<u64>, Option<u64>),
        _now: Duration,
    ) {
        let k = self.book.index_of(id);
        let after_last = k
            .and_then(|k| self.book.newest_stamp_of(k))
            .map_or(0, |s| (s / self.plan.period_s).floor().max(0.0) as u64 + 1);
        if let Some(k) = k {
            self.book.lose(k);
        }
        let Some(tick) = from else { return };
        let index = self.audits.max(after_last);
        self.found.push_back(LostMember {
            id,
            cause,
            last_tick,
            index,
            t_s: self.instant_s(index),
            tick,
        });
    }

    fn take_lost(&mut self) -> Option<LostMember> {
        self.found.pop_front()
    }

    fn link_timeout(&self) -> Duration {
        self.plan.stale_after
    }

    fn position(&self) -> u64 {
        self.audits
    }

    fn progressed(&mut self, _now: Duration) {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::{AgentStatus, FaultCode, StateMsg};
    use crate::process_exit::ProcessExit;
    use crate::realtime_monitor::MonitorCore;
    use crate::team_core::{RealtimePlan, TeamAction, TeamCore};
    use cdm_model::outcome::FaultKind;
    use cdm_scenario::Scenario;

    fn ms(t: u64) -> Duration {
        Duration::from_millis(t)
    }

    /// generated10 at 10 Hz (dt 0.1 s), audited at 10 Hz up to tick 100, starting at 1 s on the
    /// fake clock (the monitor made at 0.9 s: its first turns are no stall), stale after 0.5 s,
    /// aligned phases; `scripted` as `--lose`.
    fn team(scripted: &[(u32, u64)], repairs: bool) -> (TeamCore, Scenario) {
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
        let core = TeamCore::realtime(plan, book, ms(900)).with_losses(losses, repairs);
        (core, s)
    }

    const HASH: u64 = 7;

    fn states(c: &mut TeamCore, ids: impl Iterator<Item = u32> + Clone, ticks: u64) {
        for tick in 0..=ticks {
            for id in ids.clone() {
                c.on_state(&StateMsg::ok(tick, HASH, id, [id as f64; 12]), ms(0));
            }
        }
    }

    /// One turn at `now`, as the loop runs it (links answered with `linked`): every action up
    /// to a wait, a finish or a stop.
    fn turn(c: &mut TeamCore, now: Duration, linked: bool) -> Vec<TeamAction> {
        c.on_turn(now);
        let mut out = Vec::new();
        for _ in 0..10_000 {
            let a = c.next_action(now);
            if a == TeamAction::CheckLinks {
                c.on_links(now, |_, _| linked);
            }
            let end = matches!(
                a,
                TeamAction::Wait(_)
                    | TeamAction::Finished
                    | TeamAction::Stop(..)
                    | TeamAction::Kill(_)
            );
            out.push(a);
            if end {
                return out;
            }
        }
        panic!("the monitor never waited");
    }

    fn lost(actions: &[TeamAction]) -> Vec<LostMember> {
        actions
            .iter()
            .filter_map(|a| match a {
                TeamAction::Lost(x) => Some(*x),
                _ => None,
            })
            .collect()
    }

    fn notices(actions: &[TeamAction]) -> Vec<(u32, u32, u64, u32)> {
        actions
            .iter()
            .filter_map(|a| match a {
                TeamAction::Announce(n) => Some((n.seq, n.id, n.tick, n.linked)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn an_exited_member_is_lost_after_a_drain_and_repaired_a_lead_ahead() {
        let (mut c, _) = team(&[], true);
        states(&mut c, 1..=10, 12);
        turn(&mut c, ms(2100), true);
        c.on_exited(8, ProcessExit::Signal(9), ms(0));
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
                .any(|x| matches!(x, TeamAction::Audit { index, .. } if *index == i))
        };
        assert!(audited(13), "{a:?}");
        assert!(!a.iter().any(|x| matches!(x, TeamAction::Stop(..))));
    }

    #[test]
    fn a_stale_member_is_killed_then_lost_as_silent_and_losses_get_ticks_of_their_own() {
        let (mut c, _) = team(&[], true);
        states(&mut c, (1..=10).filter(|&i| i != 7), 15);
        states(&mut c, 7..=7, 10);
        // Member 7's newest (1.0 s) is 0.6 s old at 1.6 s: killed, then lost after a drain.
        let a = turn(&mut c, ms(2600), true);
        assert_eq!(a.last(), Some(&TeamAction::Kill(vec![7])), "{a:?}");
        // Member 8 exits meanwhile: both lost, each at a tick of its own (8's the one after 7's,
        // though found at the same instant).
        c.on_exited(8, ProcessExit::Code(3), ms(0));
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
        c.on_state(&report, ms(0));
        let a = turn(&mut c, ms(1400), true);
        let got: Vec<(u32, LossCause, Option<u64>)> = lost(&a)
            .iter()
            .map(|x| (x.id, x.cause, x.last_tick))
            .collect();
        assert_eq!(got, [(6, LossCause::VehicleMode, Some(30))]);
        let (mut c, _) = team(&[], false);
        states(&mut c, 1..=10, 30);
        c.on_state(&report, ms(0));
        match turn(&mut c, ms(1400), true).last() {
            Some(TeamAction::Stop(f, _)) => {
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
            assert!(!a.contains(&TeamAction::Kill(vec![4])), "{a:?}");
            states(&mut c, 1..=10, 13);
            let a = turn(&mut c, ms(2300), true);
            assert_eq!(a.last(), Some(&TeamAction::Kill(vec![4])));
            let a = turn(&mut c, ms(2310), true);
            if repairs {
                let x = lost(&a);
                assert_eq!(
                    (x[0].id, x[0].cause, x[0].last_tick),
                    (4, LossCause::Scripted, Some(13))
                );
            } else {
                match a.last() {
                    Some(TeamAction::Stop(f, _)) => {
                        assert_eq!((f.kind, f.agent, f.tick), (FaultKind::Lost, Some(4), 14));
                    }
                    other => panic!("{other:?}"),
                }
            }
        }
    }

    #[test]
    fn just_after_a_stall_of_the_monitor_an_exit_or_a_silence_is_the_stall_s_fault() {
        let (mut c, _) = team(&[], true);
        states(&mut c, 1..=10, 12);
        turn(&mut c, ms(2100), true);
        states(&mut c, 1..=10, 40);
        // The monitor did not run for 3 s (SIGSTOP, a starved machine): member 8's exit
        // just after is no loss to repair but the stall's consequence.
        let a = turn(&mut c, ms(5100), true);
        assert!(
            !a.iter().any(|x| matches!(x, TeamAction::Stop(..))),
            "{a:?}"
        );
        c.on_exited(8, ProcessExit::Signal(9), ms(5110));
        assert!(!c.is_gone(8));
        match turn(&mut c, ms(5120), true).last() {
            Some(TeamAction::Stop(f, _)) => {
                assert_eq!((f.kind, f.agent), (FaultKind::OrchestratorStalled, None));
                assert!(
                    f.message.contains("agent 8 was killed by signal 9"),
                    "{f:?}"
                );
            }
            other => panic!("{other:?}"),
        }
        // A stale member just after a stall is not killed: the stall is named.
        let (mut c, _) = team(&[], true);
        states(&mut c, 1..=10, 12);
        turn(&mut c, ms(2100), true);
        match turn(&mut c, ms(5100), true).last() {
            Some(TeamAction::Stop(f, _)) => {
                assert_eq!(f.kind, FaultKind::OrchestratorStalled);
            }
            other => panic!("{other:?}"),
        }
    }
}
