//! The team core's side of the commands to a team in flight: each accepted command is announced
//! on the clock channel before any member may step into its switch tick, as a loss notice is
//! (`losses.rs`). In lockstep the grants stop at the tick before the next command's switch
//! until its notice is out: a member steps from tick k only with tick k + 1 granted, so no
//! member flies past the switch on the old plan. Every later clock message repeats the latest
//! notice; members read every clock message, and a jump in the sequence is their fault.
//!
//! In real time nothing waits for a grant, so a command is proposed first with a switch tick
//! ahead of the flight ([`TeamCore::realtime_switch`]: measured delays plus a margin), every
//! leader that can still switch there acknowledges it, and it becomes final once all of them
//! did; a leader that did not by the tick before the switch withdraws it (nothing changes).

use std::collections::{BTreeSet, VecDeque};
use std::time::Duration;

use super::{Pacing, TeamAction, TeamCore, TeamState};
use crate::messages::{SteerNotice, SteerPhase};

/// The margin of a real-time switch tick beyond the measured round trip, in ticks (at least):
/// room for a leader's scheduling hiccup on a loaded machine; the monitor's turn and the
/// members' reading of the clock channel are a fraction of a tick on one host.
pub const SWITCH_MARGIN_TICKS: u64 = 10;

/// The margin as a share of the stale bound, when that is more: a leader late by a tenth of
/// the lateness the operator allows (`--stale-after`) is still healthy and must not lose the
/// command.
pub const SWITCH_MARGIN_OF_STALE: f64 = 0.1;

/// The margin of a real-time switch beyond the measured round trip (s), for ticks of `dt_s`
/// and the stale bound `stale_after`: [`SWITCH_MARGIN_TICKS`] ticks, or
/// [`SWITCH_MARGIN_OF_STALE`] of the stale bound when more.
pub fn switch_margin_s(dt_s: f64, stale_after: Duration) -> f64 {
    (SWITCH_MARGIN_TICKS as f64 * dt_s).max(SWITCH_MARGIN_OF_STALE * stale_after.as_secs_f64())
}

/// The earliest simulation time (s) a command file's command may switch at in real time
/// (`launch --realtime --commands`): it is proposed as the flight starts, and needs the switch
/// margin twice over before its switch: once for its proposal to reach every leader and their
/// acknowledgements to come back while no leader has measured a delay yet, once as the margin
/// itself.
pub fn earliest_file_switch_s(dt_s: f64, stale_after: Duration) -> f64 {
    2.0 * switch_margin_s(dt_s, stale_after)
}

/// A proposed real-time command waiting for the leaders' acknowledgements.
#[derive(Debug)]
struct Proposal {
    notice: SteerNotice,
    /// The leaders that must acknowledge it (those lost meanwhile are not waited for).
    leaders: Vec<u32>,
    acked: BTreeSet<u32>,
    /// The latest instant of the common time line at which it may become final: one tick
    /// before its switch, so the decision is out before any leader flies the switch tick.
    deadline_s: f64,
    announced: bool,
}

/// What became of a proposed real-time command.
#[derive(Debug, Clone, PartialEq)]
pub enum SteerOutcome {
    /// Every leader acknowledged it: it is final.
    Final(SteerNotice),
    /// These leaders did not acknowledge it in time: withdrawn, nothing changed.
    Withdrawn {
        notice: SteerNotice,
        missing: Vec<u32>,
    },
}

/// The commands of a run as the team core handles them.
#[derive(Debug, Default)]
pub(super) struct SteerEvents {
    /// Accepted commands not announced yet, in switch order.
    pending: VecDeque<SteerNotice>,
    /// The latest announced.
    latest: Option<SteerNotice>,
    /// Real time: the command proposed and not decided yet.
    proposal: Option<Proposal>,
    /// Real time: what became of the latest proposal, until taken.
    outcome: Option<SteerOutcome>,
}

impl SteerEvents {
    /// The highest tick that may be granted before the next notice is out (`last` without one).
    pub(super) fn cap(&self, last: u64) -> u64 {
        self.pending
            .front()
            .map_or(last, |n| n.tick.saturating_sub(1).min(last))
    }
}

impl TeamCore {
    /// The same core announcing these accepted commands (ascending switch ticks, numbered from
    /// 1 in order) ahead of their switch.
    pub fn with_commands(mut self, notices: Vec<SteerNotice>) -> Self {
        self.t.steer.pending = notices.into();
        if let Pacing::Lockstep(g) = &mut self.pacing {
            let cap = self.t.steer.cap(u64::MAX);
            g.cap_first_grant_at(cap);
        }
        self
    }

    /// Announce `notice` too: an accepted command (its sequence number the next, its switch
    /// after every tick granted so far) and the flight's new last tick.
    pub fn command(&mut self, notice: SteerNotice, last_tick: u64) {
        self.t.steer.pending.push_back(notice);
        if let Pacing::Lockstep(g) = &mut self.pacing {
            g.set_last_tick(last_tick);
        }
    }

    /// The latest command announced (every clock message repeats it).
    pub fn steer_notice(&self) -> Option<SteerNotice> {
        self.t.steer.latest
    }

    /// True while a command is accepted but not announced yet, or (real time) proposed and
    /// not decided.
    pub fn announcing(&self) -> bool {
        !self.t.steer.pending.is_empty() || self.t.steer.proposal.is_some()
    }

    /// Real time: the switch tick of a command decided at `now` whose certificate is expected
    /// to take `certify`, and the latest instant (s) it may become final. The tick is the
    /// first at or after now + lead, the lead being the certificate's time, twice the largest
    /// delay measured so far from a leader's state stamp to its arrival here (the notice out
    /// and the acknowledgement back), and a margin ([`SWITCH_MARGIN_TICKS`], or
    /// [`SWITCH_MARGIN_OF_STALE`] of the stale bound when more); never at or before a switch
    /// already announced. `None` in lockstep.
    pub fn realtime_switch(&self, now: Duration, certify: Duration) -> Option<(u64, f64)> {
        let Pacing::Realtime(w) = &self.pacing else {
            return None;
        };
        let dt = w.plan.dt_s;
        let lead_s = certify.as_secs_f64() + 2.0 * w.leader_delay_s() + Self::margin_s(w);
        let ahead = ((w.time_s(now) + lead_s) / dt).ceil().max(1.0) as u64;
        let after = self.t.steer.latest.map_or(0, |n| n.tick + 1);
        let tick = ahead.max(after);
        Some((tick, Self::deadline_s(tick, dt)))
    }

    /// Real time: whether a command switching at `tick` can still be proposed at `now`: half
    /// its margin may have gone into its certificate, the round trip is still ahead of its
    /// deadline.
    pub fn realtime_in_time(&self, now: Duration, tick: u64) -> bool {
        let Pacing::Realtime(w) = &self.pacing else {
            return false;
        };
        let dt = w.plan.dt_s;
        let needed_s = 2.0 * w.leader_delay_s() + 0.5 * Self::margin_s(w);
        w.time_s(now) + needed_s <= Self::deadline_s(tick, dt)
    }

    /// The margin of a switch beyond the measured round trip (s).
    fn margin_s(w: &super::WallClock) -> f64 {
        switch_margin_s(w.plan.dt_s, w.plan.stale_after)
    }

    /// The latest instant a proposal switching at `tick` may become final.
    fn deadline_s(tick: u64, dt_s: f64) -> f64 {
        tick.saturating_sub(1) as f64 * dt_s
    }

    /// Real time: propose `notice` (its number the next, its switch from
    /// [`Self::realtime_switch`]) to the team; `leaders` must acknowledge it. The flight's
    /// last tick moves with [`Self::set_last_tick`] once it is final.
    pub fn propose(&mut self, notice: SteerNotice, leaders: Vec<u32>) {
        let dt = match &self.pacing {
            Pacing::Realtime(w) => w.plan.dt_s,
            // Lockstep decides on the spot (`command`): nothing to acknowledge.
            Pacing::Lockstep(_) => return,
        };
        self.t.steer.proposal = Some(Proposal {
            notice: notice.in_phase(SteerPhase::Proposed),
            leaders,
            acked: BTreeSet::new(),
            deadline_s: Self::deadline_s(notice.tick, dt),
            announced: false,
        });
    }

    /// What became of the latest proposal, once decided (taken once).
    pub fn take_steer_outcome(&mut self) -> Option<SteerOutcome> {
        self.t.steer.outcome.take()
    }

    /// The flight's last tick as commanded (after a final command).
    pub fn set_last_tick(&mut self, last: u64) {
        match &mut self.pacing {
            Pacing::Lockstep(g) => g.set_last_tick(last),
            Pacing::Realtime(w) => w.plan.set_last_tick(last),
        }
    }
}

impl SteerEvents {
    /// Member `id` acknowledged proposed command `seq`.
    pub(super) fn ack(&mut self, id: u32, seq: u32) {
        if let Some(p) = self.proposal.as_mut().filter(|p| p.notice.seq == seq) {
            p.acked.insert(id);
        }
    }
}

impl TeamState {
    /// Real time at `now_s`: announce the proposal, then make it final once every leader
    /// still flying acknowledged it, or withdraw it at its deadline.
    pub(super) fn steer_realtime(&mut self, now_s: f64) -> Option<TeamAction> {
        let p = self.steer.proposal.as_mut()?;
        if !p.announced {
            p.announced = true;
            self.steer.latest = Some(p.notice);
            return Some(TeamAction::Steer(p.notice));
        }
        let missing: Vec<u32> = (p.leaders.iter().copied())
            .filter(|id| !p.acked.contains(id))
            .collect();
        let missing: Vec<u32> = missing
            .into_iter()
            .filter(|&id| !self.is_gone(id))
            .collect();
        let p = self.steer.proposal.as_ref()?;
        let (notice, outcome) = if missing.is_empty() {
            let n = p.notice.in_phase(SteerPhase::Final);
            (n, SteerOutcome::Final(n))
        } else if now_s >= p.deadline_s {
            let n = p.notice.in_phase(SteerPhase::Withdrawn);
            (n, SteerOutcome::Withdrawn { notice: n, missing })
        } else {
            return None;
        };
        self.steer.proposal = None;
        self.steer.latest = Some(notice);
        self.steer.outcome = Some(outcome);
        Some(TeamAction::Steer(notice))
    }

    /// The next notice to announce, once the grants reached the tick before its switch.
    pub(super) fn steer_action(&mut self, granted: u64) -> Option<TeamAction> {
        let s = &mut self.steer;
        if s.cap(u64::MAX) > granted {
            return None;
        }
        let n = s.pending.pop_front()?;
        s.latest = Some(n);
        Some(TeamAction::Steer(n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::StateMsg;
    use crate::team_core::TeamConfig;
    use cdm_model::steer::TeamCommand;
    use std::time::Duration;

    fn ms(t: u64) -> Duration {
        Duration::from_millis(t)
    }

    fn notice(seq: u32, tick: u64) -> SteerNotice {
        SteerNotice::decided(seq, tick, TeamCommand::Hold)
    }

    /// The actions of one turn at `now`, up to a wait or a poll.
    fn turn(c: &mut TeamCore, now: Duration) -> Vec<TeamAction> {
        c.on_turn(now);
        let mut out = Vec::new();
        loop {
            let a = c.next_action(now);
            if let TeamAction::Complete { states, .. } = &a {
                c.recycle(states.clone());
            }
            let end = matches!(
                a,
                TeamAction::Wait(_) | TeamAction::Poll | TeamAction::Finished
            );
            out.push(a);
            if end {
                return out;
            }
        }
    }

    fn send(c: &mut TeamCore, ids: &[u32], ticks: std::ops::RangeInclusive<u64>) {
        for tick in ticks {
            for &id in ids {
                c.on_state(&StateMsg::ok(tick, 7, id, [0.0; 12]), ms(0));
            }
        }
    }

    #[test]
    fn grants_stop_before_a_switch_until_its_notice_is_out_and_then_go_on() {
        let ids = [1, 2, 3];
        let cfg = TeamConfig {
            ids: ids.to_vec(),
            window: 8,
            last_tick: 40,
            agent_timeout: Duration::from_secs(10),
        };
        let mut c = TeamCore::lockstep(cfg, ms(0)).with_commands(vec![notice(1, 5), notice(2, 6)]);
        let a = turn(&mut c, ms(1));
        // The first grant stops at tick 4; notice 1 goes out at once, then the grants go on
        // up to the tick before notice 2's switch, and it goes out: each notice in a message
        // of its own, before any grant past the tick before its switch.
        assert_eq!(a[0], TeamAction::Grant(4));
        assert_eq!(a[1], TeamAction::Steer(notice(1, 5)));
        assert_eq!(a[2], TeamAction::Grant(5));
        assert_eq!(a[3], TeamAction::Steer(notice(2, 6)));
        assert_eq!(c.steer_notice(), Some(notice(2, 6)));
        send(&mut c, &ids, 0..=4);
        let a = turn(&mut c, ms(2));
        assert!(a.contains(&TeamAction::Grant(12)), "{a:?}");
        // A live command: announced once the grants reach the tick before it.
        c.command(notice(3, 20), 30);
        send(&mut c, &ids, 5..=12);
        let a = turn(&mut c, ms(3));
        let grants: Vec<&TeamAction> = a
            .iter()
            .filter(|x| matches!(x, TeamAction::Grant(_) | TeamAction::Steer(_)))
            .collect();
        assert_eq!(
            grants,
            [&TeamAction::Grant(19), &TeamAction::Steer(notice(3, 20))]
        );
        // The new last tick ends the flight there.
        let mut a = Vec::new();
        for (k, ticks) in [13..=19, 20..=27, 28..=30].into_iter().enumerate() {
            send(&mut c, &ids, ticks);
            a = turn(&mut c, ms(4 + k as u64));
        }
        assert_eq!(a.last(), Some(&TeamAction::Finished), "{a:?}");
    }

    /// Three members at 10 Hz in real time (1 and 2 leaders, 3 a follower), starting at 1 s,
    /// stale after 5 s.
    fn realtime_team() -> TeamCore {
        use crate::realtime_monitor::MonitorCore;
        use crate::team_core::RealtimePlan;
        use cdm_math::Vec3;
        let members = [1, 2, 3].map(|id| (id, Vec3::new(id as f64, 0.0, 0.0), id == 3));
        let book = MonitorCore::new(&members, 7, (0.1, 5.0), 0);
        let plan = RealtimePlan::new(ms(1000), (100, 0.1), 10.0, ms(5000));
        TeamCore::realtime(plan, book, ms(0))
    }

    fn steers(actions: &[TeamAction]) -> Vec<SteerNotice> {
        (actions.iter())
            .filter_map(|a| match a {
                TeamAction::Steer(n) => Some(*n),
                _ => None,
            })
            .collect()
    }

    /// The actions of a real-time turn at `now`, up to a wait.
    fn rt_turn(c: &mut TeamCore, now: Duration) -> Vec<TeamAction> {
        c.on_turn(now);
        let mut out = Vec::new();
        for _ in 0..1000 {
            let a = c.next_action(now);
            let end = matches!(
                a,
                TeamAction::Wait(_) | TeamAction::Finished | TeamAction::Stop(..)
            );
            out.push(a);
            if end {
                break;
            }
        }
        out
    }

    #[test]
    fn a_realtime_command_is_proposed_ahead_and_final_once_every_leader_acknowledged() {
        let mut c = realtime_team();
        // Leader 1's state of tick 3 (0.3 s) arrives at 0.32 s: 20 ms late.
        c.on_state(&StateMsg::ok(3, 7, 1, [0.0; 12]), ms(1320));
        c.on_state(&StateMsg::ok(3, 7, 3, [0.0; 12]), ms(1400));
        let Pacing::Realtime(w) = c.pacing() else {
            panic!("real time")
        };
        assert!(
            (w.leader_delay_s() - 0.02).abs() < 1e-9,
            "followers do not count"
        );
        // At 0.5 s with a certificate of 100 ms: lead 0.1 + 2 x 0.02 + 10 ticks (1 s, more
        // than a tenth of the 5 s stale bound) = 1.14 s: tick 17 (the first at or after
        // 1.64 s), final by 1.6 s.
        let (tick, deadline_s) = c.realtime_switch(ms(1500), ms(100)).unwrap();
        assert_eq!(tick, 17);
        assert!((deadline_s - 1.6).abs() < 1e-9);
        c.propose(SteerNotice::decided(1, tick, TeamCommand::Hold), vec![1, 2]);
        assert!(c.announcing());
        let a = rt_turn(&mut c, ms(1500));
        let proposed =
            SteerNotice::decided(1, 17, TeamCommand::Hold).in_phase(SteerPhase::Proposed);
        assert_eq!(steers(&a), [proposed]);
        assert_eq!(c.steer_notice(), Some(proposed));
        c.on_state(&StateMsg::steer_ack(6, 7, 1, 1), ms(1510));
        assert!(
            steers(&rt_turn(&mut c, ms(1520))).is_empty(),
            "leader 2 has not acknowledged"
        );
        // An acknowledgement of another number does not count.
        c.on_state(&StateMsg::steer_ack(6, 7, 2, 9), ms(1530));
        assert!(steers(&rt_turn(&mut c, ms(1540))).is_empty());
        c.on_state(&StateMsg::steer_ack(6, 7, 2, 1), ms(1550));
        let a = rt_turn(&mut c, ms(1560));
        let fin = proposed.in_phase(SteerPhase::Final);
        assert_eq!(steers(&a), [fin]);
        assert_eq!(c.take_steer_outcome(), Some(SteerOutcome::Final(fin)));
        assert_eq!(c.take_steer_outcome(), None);
        assert!(!c.announcing());
        // Half the margin may go into the certificate: at 1.03 s a switch at 17 is in time (the
        // deadline 1.6 s minus 0.04 s and 0.5 s), at 1.07 s it is not.
        // (Asked of a fresh proposal: the core answers for any tick.)
        assert!(c.realtime_in_time(ms(2030), 17));
        assert!(!c.realtime_in_time(ms(2070), 17));
        // The next switch comes after this one, however early it is asked for.
        assert_eq!(c.realtime_switch(ms(1000), ms(0)).unwrap().0, 18);
    }

    #[test]
    fn a_realtime_command_a_leader_does_not_acknowledge_in_time_is_withdrawn() {
        let mut c = realtime_team();
        let (tick, _) = c.realtime_switch(ms(1000), ms(0)).unwrap();
        assert_eq!(tick, 10);
        c.propose(SteerNotice::decided(1, tick, TeamCommand::Land), vec![1, 2]);
        rt_turn(&mut c, ms(1000));
        c.on_state(&StateMsg::steer_ack(0, 7, 1, 1), ms(1100));
        // Its deadline is the tick before the switch: 0.9 s.
        assert!(steers(&rt_turn(&mut c, ms(1890))).is_empty());
        let a = rt_turn(&mut c, ms(1910));
        let withdrawn =
            SteerNotice::decided(1, 10, TeamCommand::Land).in_phase(SteerPhase::Withdrawn);
        assert_eq!(steers(&a), [withdrawn]);
        assert_eq!(
            c.take_steer_outcome(),
            Some(SteerOutcome::Withdrawn {
                notice: withdrawn,
                missing: vec![2]
            })
        );
        // A late acknowledgement changes nothing.
        c.on_state(&StateMsg::steer_ack(5, 7, 2, 1), ms(1920));
        assert!(steers(&rt_turn(&mut c, ms(1930))).is_empty());
        assert_eq!(c.take_steer_outcome(), None);
    }
}
