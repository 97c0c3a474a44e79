//! Real-time pacing of the team core: members fly on the wall clock from the start instant
//! with no grant and no barrier, and the orchestrator audits common instants from their newest
//! states (`crate::realtime_monitor::MonitorCore`), writing telemetry through
//! `cdm_records::record::TickRecorder` as lockstep does.
//!
//! What it decides: when an audit instant is due (it lags the clock by one member period, and
//! waits until every member has been heard at or after it), which member is stale, that a
//! fault stops the flight at once (no tick waits for it), and the tick a loss is repaired from
//! (`team_core/realtime_losses.rs`).

use std::collections::VecDeque;
use std::time::Duration;

use super::{TeamAction, TeamState};
use crate::messages::{FaultCode, StateMsg};
use crate::realtime_monitor::{MonitorCore, MonitorEvent};
use crate::team_fault::{FaultRank, InterruptedAt, TeamFault, WhoseTick};

use super::LostMember;

/// The longest wait between two turns: fault reports are read at least this often.
pub const MAX_WAIT: Duration = Duration::from_millis(10);

/// The wait while a due instant waits for a late member.
pub const LATE_WAIT: Duration = Duration::from_millis(1);

/// The timing of a real-time flight's audits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RealtimePlan {
    /// Tick 0's instant on the caller's clock.
    pub start: Duration,
    /// Seconds between audit instants (1 / audit rate).
    pub period_s: f64,
    /// How far audit instants lag the clock: one member period (dt), so the state a member
    /// stamped just before an instant has been published by then.
    pub lag_s: f64,
    /// The last audit instant's index.
    pub last_audit: u64,
    /// The bound on a member's newest state's age.
    pub stale_after: Duration,
    /// The members' period (s).
    pub dt_s: f64,
}

impl RealtimePlan {
    /// Audits at `audit_hz` up to the last tick `last_tick` of period `dt_s`.
    pub fn new(
        start: Duration,
        (last_tick, dt_s): (u64, f64),
        audit_hz: f64,
        stale_after: Duration,
    ) -> Self {
        let period_s = 1.0 / audit_hz;
        let t_end = last_tick as f64 * dt_s;
        RealtimePlan {
            start,
            period_s,
            lag_s: dt_s,
            // The last audit instant at or before the end of the plan (1e-9: t_end may be a
            // hair below a multiple of the period after rounding).
            last_audit: (t_end / period_s + 1e-9).floor() as u64,
            stale_after,
            dt_s,
        }
    }

    /// The flight's last tick is now `last_tick` (a command to the team): the last audit
    /// instant moves with it.
    pub fn set_last_tick(&mut self, last_tick: u64) {
        let t_end = last_tick as f64 * self.dt_s;
        self.last_audit = (t_end / self.period_s + 1e-9).floor() as u64;
    }
}

/// The real-time pacing's state (see the module doc).
#[derive(Debug, Clone)]
pub struct WallClock {
    pub(super) plan: RealtimePlan,
    pub(super) book: MonitorCore,
    /// Audit instants done.
    pub(super) audits: u64,
    /// Losses applied, not yet handed to the audit.
    pub(super) found: VecDeque<LostMember>,
    /// The largest delay seen from a leader's state stamp to its arrival here (s): how far
    /// behind the common time line a leader is heard (its publishing, the transport, this
    /// loop's turn), measured on every state.
    leader_delay_s: f64,
}

impl WallClock {
    pub(super) fn new(plan: RealtimePlan, book: MonitorCore) -> Self {
        WallClock {
            plan,
            book,
            audits: 0,
            found: VecDeque::new(),
            leader_delay_s: 0.0,
        }
    }

    /// The largest delay measured so far from a leader's state stamp to its arrival (s).
    pub fn leader_delay_s(&self) -> f64 {
        self.leader_delay_s
    }

    /// The timing of the audits.
    pub fn plan(&self) -> &RealtimePlan {
        &self.plan
    }

    /// The members' states and reports.
    pub fn book(&self) -> &MonitorCore {
        &self.book
    }

    /// The members' states and reports, to take the final pacing reports after the stop.
    pub fn book_mut(&mut self) -> &mut MonitorCore {
        &mut self.book
    }

    /// Audit instants done.
    pub fn audits(&self) -> u64 {
        self.audits
    }

    /// Where an interrupt finds the flight: the next audit instant.
    pub(super) fn interrupted_at(&self) -> InterruptedAt {
        let index = self.audits;
        InterruptedAt::Instant {
            index,
            t_s: self.instant_s(index),
        }
    }

    /// A message from a member's state service. A fault report or a non-finite state is kept
    /// when it names the root cause better than the one kept so far; a lost member's are not,
    /// nor (losses repaired) a member's report of its own vehicle's loss, which is a loss.
    pub(super) fn on_state(&mut self, t: &mut TeamState, msg: &StateMsg, now: Duration) {
        let event = self.book.on_state(msg);
        if t.is_gone(msg.id) {
            return;
        }
        if let Some(stamp) = (event == MonitorEvent::Nothing)
            .then(|| self.book.leader_stamp(msg))
            .flatten()
        {
            self.leader_delay_s = self.leader_delay_s.max(self.time_s(now) - stamp);
        }
        let (rank, fault) = match event {
            MonitorEvent::Nothing => return,
            MonitorEvent::Fault {
                id,
                tick,
                code,
                peer,
            } => {
                if t.lost_on_report(id, code) {
                    return;
                }
                let member = self.book.index_of(id).unwrap_or(usize::MAX);
                (
                    FaultRank::of_report(code, tick, member),
                    self.reported(t, id, tick, code, peer),
                )
            }
            MonitorEvent::NonFinite { id, tick } => {
                let clock = WhoseTick::Own;
                (
                    FaultRank::found(tick),
                    TeamFault::NonFinite { id, tick, clock },
                )
            }
        };
        t.keep_fault(rank, &fault, now);
    }

    /// A member's own report. A follower that found a neighbour stale names the neighbour: that
    /// one is the fault, the follower only saw it.
    fn reported(
        &self,
        t: &TeamState,
        id: u32,
        tick: u64,
        code: FaultCode,
        peer: Option<u32>,
    ) -> TeamFault {
        match (code, peer) {
            (FaultCode::NeighborSilent, Some(p)) => TeamFault::NeighborStale {
                peer: p,
                reporter: id,
                tick,
                bound_s: self.member_stale_after(t).as_secs_f64(),
            },
            _ => TeamFault::Reported {
                id,
                tick,
                code,
                peer,
                clock: WhoseTick::Own,
            },
        }
    }

    /// Seconds on the common time line at `now` (negative before the start instant).
    pub(super) fn time_s(&self, now: Duration) -> f64 {
        match now.checked_sub(self.plan.start) {
            Some(d) => d.as_secs_f64(),
            None => -(self.plan.start - now).as_secs_f64(),
        }
    }

    /// Audit instant `index`'s time.
    pub(super) fn instant_s(&self, index: u64) -> f64 {
        index as f64 * self.plan.period_s
    }

    /// The next action at `now`: the losses; a fault report, a stale member, an exited member
    /// stop the flight in that order (a stale member is killed and lost instead when losses
    /// are repaired); then the audit instants due; then a flush; then a wait.
    pub(super) fn next_action(&mut self, t: &mut TeamState, now: Duration) -> TeamAction {
        if let Some(a) = t.loss_action(self, now) {
            return a;
        }
        if let Some(a) = t.steer_realtime(self.time_s(now)) {
            return a;
        }
        let (now_s, bound_s) = (self.time_s(now), self.plan.stale_after.as_secs_f64());
        let stale = self.book.stale(now_s, bound_s);
        if let Some((id, _, _)) = stale {
            if let Some(kill) = t.kill_silent(&[id], now) {
                return kill;
            }
        }
        if let Some(s) = t.stopping.take() {
            return TeamAction::Stop(s.record, s.reason);
        }
        let index = self.audits;
        if let Some((id, newest, age_s)) = stale {
            let fault = TeamFault::Stale {
                id,
                newest,
                age_s,
                index,
            };
            return t.explained(&fault, now);
        }
        if let Some(e) = t.exited.take() {
            let fault = TeamFault::Exited {
                id: e.id,
                how: e.how,
                tick: index,
            };
            return t.explained(&fault, now);
        }
        if t.exit_check_due(now) {
            return TeamAction::CheckExited;
        }
        let instant = self.instant_s(index);
        // Audit instants lag the clock by one member period: the state a member stamped just
        // before an instant has then been published. An instant also waits until every member
        // has been heard at or after it, so a member that is late (starved, or behind a slow
        // link) is audited from the states around the instant instead of extrapolated from an
        // old one; the wait is bounded by the stale rule (--stale-after).
        if index <= self.plan.last_audit
            && instant + self.plan.lag_s <= now_s
            && instant <= self.book.heard_until()
        {
            self.audits += 1;
            return TeamAction::Audit {
                index,
                t_s: instant,
            };
        }
        if index > self.plan.last_audit {
            return TeamAction::Finished;
        }
        if t.flush_due(now) {
            return TeamAction::Flush;
        }
        // A plain sleep to the next audit instant (at most MAX_WAIT, so fault reports are read
        // promptly; LATE_WAIT while a due instant waits for a late member): members do not wake
        // the monitor in real time.
        let next = instant + self.plan.lag_s - now_s;
        TeamAction::Wait(if next > 0.0 {
            Duration::from_secs_f64(next).min(MAX_WAIT)
        } else {
            LATE_WAIT
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_math::Vec3;
    use cdm_model::outcome::FaultKind;

    use crate::messages::{AgentStatus, StopReason};
    use crate::process_exit::ProcessExit;
    use crate::realtime_monitor::MonitorCore;
    use crate::team_core::{Stop, TeamCore};

    const HASH: u64 = 7;
    const IDS: [u32; 3] = [1, 2, 3];

    fn ms(t: u64) -> Duration {
        Duration::from_millis(t)
    }

    /// Three members at 10 Hz, audited at 10 Hz up to tick 10 (instants 0..=10), starting at 1 s
    /// on the fake clock, stale after 0.5 s, aligned phases.
    fn team() -> TeamCore {
        let members: Vec<(u32, Vec3, bool)> = IDS
            .iter()
            .map(|&id| (id, Vec3::new(id as f64, 0.0, 0.0), id == 3))
            .collect();
        let book = MonitorCore::new(&members, HASH, (0.1, 0.5), 0);
        let plan = RealtimePlan::new(ms(1000), (10, 0.1), 10.0, ms(500));
        TeamCore::realtime(plan, book, ms(0))
    }

    fn state(id: u32, tick: u64) -> StateMsg {
        StateMsg::ok(tick, HASH, id, [id as f64; 12])
    }

    fn report(id: u32, tick: u64, code: FaultCode, peer: Option<u32>) -> StateMsg {
        state(id, tick).with_status(AgentStatus::Fault { code, peer })
    }

    /// Every member's states of ticks `0..=last`.
    fn heard(c: &mut TeamCore, ids: &[u32], last: u64) {
        for tick in 0..=last {
            for &id in ids {
                c.on_state(&state(id, tick), ms(0));
            }
        }
    }

    /// What one turn did: the instants audited, the exit checks and flushes, and how it ended.
    #[derive(Debug, Default)]
    struct Turn {
        audits: Vec<u64>,
        exit_checks: usize,
        flushes: usize,
        end: Option<TeamAction>,
    }

    /// Runs the monitor at `now` until it waits, finishes or stops, as the loop does (an exit
    /// check finds `exited`).
    fn turn(c: &mut TeamCore, now: Duration, exited: Option<(u32, ProcessExit)>) -> Turn {
        let mut t = Turn::default();
        for _ in 0..10_000 {
            match c.next_action(now) {
                TeamAction::Audit { index, t_s } => {
                    assert_eq!(t_s, index as f64 * 0.1);
                    t.audits.push(index);
                }
                TeamAction::CheckExited => {
                    t.exit_checks += 1;
                    if let Some((id, how)) = &exited {
                        c.on_exited(*id, how.clone(), now);
                    }
                }
                TeamAction::Flush => t.flushes += 1,
                end => {
                    t.end = Some(end);
                    return t;
                }
            }
        }
        panic!("the monitor never waited");
    }

    fn stopped(t: &Turn) -> Stop {
        match &t.end {
            Some(TeamAction::Stop(f, r)) => (f.clone(), *r),
            other => panic!("no stop: {other:?}"),
        }
    }

    #[test]
    fn audit_instants_lag_the_clock_by_a_period_and_wait_for_the_slowest_member() {
        let mut c = team();
        // Before the start instant: nothing is due; the wait is bounded.
        let t = turn(&mut c, ms(500), None);
        assert!(t.audits.is_empty());
        assert_eq!(t.end, Some(TeamAction::Wait(MAX_WAIT)));
        heard(&mut c, &IDS, 2);
        // At t = 0.25 s: instants 0 and 1 are a period old, instant 2 is not yet.
        let t = turn(&mut c, ms(1250), None);
        assert_eq!(t.audits, [0, 1]);
        assert_eq!(t.end, Some(TeamAction::Wait(MAX_WAIT)));
        // Instant 2 is due at 0.3 s, but member 3 was last heard at tick 2 (0.2 s): due, audited.
        heard(&mut c, &[1, 2], 4);
        let t = turn(&mut c, ms(1420), None);
        assert_eq!(t.audits, [2]);
        // Instant 3 waits for member 3 (heard until 0.2 s), polled often.
        assert_eq!(t.end, Some(TeamAction::Wait(LATE_WAIT)));
        c.on_state(&state(3, 3), ms(0));
        assert_eq!(turn(&mut c, ms(1421), None).audits, [3]);
    }

    #[test]
    fn every_instant_audited_finishes_the_flight_and_telemetry_is_flushed_meanwhile() {
        let mut c = team();
        heard(&mut c, &IDS, 10);
        let t = turn(&mut c, ms(1550), None);
        assert_eq!(t.audits, [0, 1, 2, 3, 4]);
        assert_eq!((t.flushes, t.exit_checks), (1, 1));
        let t = turn(&mut c, ms(2200), None);
        assert_eq!(t.audits, (5..=10).collect::<Vec<_>>());
        assert_eq!(t.end, Some(TeamAction::Finished));
        assert_eq!(c.position(), 11);
    }

    #[test]
    fn a_member_heard_too_long_ago_is_stale() {
        let mut c = team();
        heard(&mut c, &[1, 2], 7);
        heard(&mut c, &[3], 1);
        // Instant 1 is audited (member 3 heard until 0.1 s), instant 2 waits for member 3.
        assert_eq!(turn(&mut c, ms(1300), None).audits, [0, 1]);
        // Its newest is 0.55 s old: the fault names the next instant.
        let t = turn(&mut c, ms(1650), None);
        assert!(t.audits.is_empty());
        let (f, reason) = stopped(&t);
        assert_eq!(
            (f.kind, f.agent, f.tick, reason),
            (FaultKind::AgentSilent, Some(3), 2, StopReason::AgentSilent)
        );
        assert_eq!(
            f.message,
            "agent 3 sent no state for 550 ms (its newest is its tick 1): stopped or hung"
        );
    }

    #[test]
    fn the_root_cause_outranks_its_echo_whatever_arrived_first() {
        let mut c = team();
        c.on_state(&report(1, 3, FaultCode::NeighborFault, Some(2)), ms(0));
        c.on_state(&report(2, 4, FaultCode::Control, None), ms(0));
        c.on_state(&report(3, 4, FaultCode::NeighborFault, Some(2)), ms(0));
        let t = turn(&mut c, ms(100), None);
        let (f, reason) = stopped(&t);
        assert_eq!(
            (f.kind, f.agent, f.tick, reason),
            (FaultKind::Control, Some(2), 4, StopReason::AgentFault)
        );
        assert_eq!(f.message, "agent 2 reported Control at its tick 4");
    }

    #[test]
    fn a_follower_that_found_a_neighbour_stale_names_the_neighbour() {
        let mut c = team();
        c.on_state(&report(3, 9, FaultCode::NeighborSilent, Some(2)), ms(0));
        let t = turn(&mut c, ms(100), None);
        let (f, reason) = stopped(&t);
        assert_eq!(
            (f.kind, f.agent, f.peer, reason),
            (
                FaultKind::AgentSilent,
                Some(2),
                Some(3),
                StopReason::AgentSilent
            )
        );
        assert_eq!(
            f.message,
            "agent 2 sent no state for more than 500 ms (reported by agent 3 at its tick 9, which holds position)"
        );
    }

    #[test]
    fn a_non_finite_state_is_never_audited_and_stops_the_flight() {
        let mut c = team();
        c.on_state(&StateMsg::ok(2, HASH, 1, [f64::NAN; 12]), ms(0));
        let (f, _) = stopped(&turn(&mut c, ms(100), None));
        assert_eq!(
            (f.kind, f.agent, f.tick),
            (FaultKind::NonFiniteState, Some(1), 2)
        );
        assert_eq!(
            f.message,
            "agent 1 published a non-finite state at its tick 2"
        );
    }

    #[test]
    fn an_exited_member_is_looked_for_every_exit_check_and_stops_the_flight() {
        let mut c = team();
        heard(&mut c, &IDS, 3);
        let t = turn(&mut c, ms(50), Some((2, ProcessExit::Code(1))));
        assert_eq!(t.exit_checks, 0, "checked before EXIT_CHECK passed");
        let t = turn(&mut c, ms(1300), Some((2, ProcessExit::Code(1))));
        assert_eq!(t.exit_checks, 1);
        // Checked before the instants: none audited, the fault names the next one.
        let (f, reason) = stopped(&t);
        assert_eq!(
            (f.kind, f.agent, f.tick, reason),
            (FaultKind::AgentExited, Some(2), 0, StopReason::AgentFault)
        );
        assert_eq!(f.message, "agent 2 exited with code 1 at tick 0");
    }

    #[test]
    fn an_interrupt_stops_the_flight_at_the_next_instant() {
        let mut c = team();
        heard(&mut c, &IDS, 3);
        assert_eq!(turn(&mut c, ms(1250), None).audits, [0, 1]);
        c.on_interrupt("SIGTERM");
        let (f, reason) = stopped(&turn(&mut c, ms(1260), None));
        assert_eq!(
            (f.kind, f.tick, reason),
            (FaultKind::Interrupted, 2, StopReason::Interrupted)
        );
        assert_eq!(f.message, "interrupted by SIGTERM at t = 0.200 s");
    }
}
