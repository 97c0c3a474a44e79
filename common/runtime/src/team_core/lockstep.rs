//! Lockstep pacing of the team core: the orchestrator grants ticks and members run up to
//! `window` ticks ahead of the last tick completely received. What it decides: the grants,
//! which ticks are complete (one slot per tick and member), how long a reported fault waits for
//! the ticks before it (as long as a member that owes one of them may still send it: never by a
//! wall-clock grace, so a slow start under load records what `simulate` records), the tick an
//! exited member is blamed for, and the silence deadline.

use std::time::Duration;

use super::losses::LossPacing;
use super::{Exited, TeamAction, TeamState, FAULT_GRACE};
use crate::messages::{AgentStatus, StateMsg};
use crate::team_fault::{FaultRank, TeamFault, WhoseTick};
use crate::team_loss::{LossCause, TeamLosses};
use crate::team_slots::{IdIndex, TickSlots};

/// The longest wait of the orchestrator's loop: it bounds how late the deadlines run (states
/// and fault reports wake it at once).
pub const WAIT_SLICE: Duration = Duration::from_millis(20);

/// What the lockstep pacing needs to know of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct TeamConfig {
    /// Member ids in formation order (the order of a complete tick's states).
    pub ids: Vec<u32>,
    /// How many ticks members may run ahead of the last complete tick (1 is strict lockstep).
    pub window: u32,
    /// The last tick to fly.
    pub last_tick: u64,
    /// How long without a complete tick before the missing members are declared silent.
    pub agent_timeout: Duration,
}

/// One complete tick's states, in formation order: every slot is `Some` but a lost member's.
/// Hand the vector back with [`super::TeamCore::recycle`] so the next tick reuses it (no
/// allocation per tick).
pub type TickStates = Vec<Option<StateMsg>>;

/// The tick slots not complete yet.
#[derive(Debug)]
struct Slot {
    states: TickStates,
    count: usize,
}

/// The lockstep pacing's state (see the module doc).
#[derive(Debug)]
pub struct Grants {
    cfg: TeamConfig,
    index: IdIndex,
    window: u64,
    /// The ticks not complete yet, from `next_tick` on.
    pending: TickSlots<Slot>,
    spare: Vec<TickStates>,
    /// The next tick to hand out as complete.
    next_tick: u64,
    /// Every tick before this one has all its states.
    complete: u64,
    grant: u64,
    started: bool,
    progressed: bool,
    last_progress: Duration,
    /// A non-finite state: who sent it, its tick, when it was seen. It is never audited.
    non_finite: Option<(u32, u64, Duration)>,
    /// Per member (formation order): it sent its last usable state (it reported a fault, or
    /// sent a non-finite state). Its states before that came first on its one queue, so a tick
    /// it has not filled yet will never be filled by it.
    sends_no_more: Vec<bool>,
}

impl Grants {
    /// A team about to start at `now`.
    pub(super) fn new(cfg: TeamConfig, now: Duration) -> Self {
        let index = IdIndex::new(&cfg.ids);
        let window = u64::from(cfg.window.max(1));
        let grant = first_grant(window, cfg.last_tick);
        let sends_no_more = vec![false; cfg.ids.len()];
        Grants {
            cfg,
            index,
            window,
            pending: TickSlots::new(),
            spare: Vec::new(),
            next_tick: 0,
            complete: 0,
            grant,
            started: false,
            progressed: false,
            last_progress: now,
            non_finite: None,
            sends_no_more,
        }
    }

    /// The next tick to complete (the first tick the team has not completed).
    pub fn next_tick(&self) -> u64 {
        self.next_tick
    }

    /// The highest tick granted so far.
    pub fn granted(&self) -> u64 {
        self.grant
    }

    /// The grant window.
    pub fn window(&self) -> u64 {
        self.window
    }

    /// Scripted losses cap the first grant: a scripted loss's member must publish its tick L
    /// and nothing after it.
    pub(super) fn cap_first_grant(&mut self, book: &TeamLosses) {
        self.grant = first_grant(self.window, book.cap(self.cfg.last_tick));
    }

    /// Commands cap the first grant: no member steps into a switch before its notice.
    pub(super) fn cap_first_grant_at(&mut self, cap: u64) {
        self.grant = self.grant.min(cap);
    }

    /// A command changed the flight's end.
    pub(super) fn set_last_tick(&mut self, last: u64) {
        self.cfg.last_tick = last;
    }

    /// The orchestrator stalled: its members get a fresh silence timeout.
    pub(super) fn restart_silence(&mut self, now: Duration) {
        self.last_progress = now;
    }

    /// A received state or fault report. States outside the granted window are ignored (stale
    /// or foreign); a non-finite one is never used.
    pub(super) fn on_state(&mut self, t: &mut TeamState, msg: &StateMsg, now: Duration) {
        let Some(k) = self.index.get(msg.id) else {
            return;
        };
        if let AgentStatus::Fault { code, peer } = msg.status() {
            self.sends_no_more[k] = true;
            let rank = FaultRank::of_report(code, msg.tick, k);
            let fault = TeamFault::Reported {
                id: msg.id,
                tick: msg.tick,
                code,
                peer,
                clock: WhoseTick::Team,
            };
            let since = t.fault_since(now);
            t.keep_fault(rank, &fault, since);
            return;
        }
        if let Some(l) = &mut t.losses {
            l.book.saw_at(k, msg.id, msg.tick);
        }
        if !self.started || msg.tick < self.next_tick || msg.tick > self.grant {
            return;
        }
        if msg.state.iter().any(|v| !v.is_finite()) {
            self.sends_no_more[k] = true;
            self.non_finite.get_or_insert((msg.id, msg.tick, now));
            return;
        }
        let n = self.cfg.ids.len();
        let spare = &mut self.spare;
        let Some(slot) = self.pending.get_or_insert_with(msg.tick, || Slot {
            states: spare.pop().unwrap_or_else(|| vec![None; n]),
            count: 0,
        }) else {
            return;
        };
        if slot.states[k].is_none() {
            slot.count += 1;
        }
        slot.states[k] = Some(*msg);
    }

    /// Hands back a complete tick's states for a later tick.
    pub(super) fn recycle(&mut self, mut states: TickStates) {
        states.fill(None);
        self.spare.push(states);
    }

    /// The next action at `now`. Grants go out before complete ticks (members go on while the
    /// orchestrator audits and writes); a fault at tick k stops the team once ticks 0..=k are
    /// complete (as `simulate` keeps them), or once no member that owes one of them can still
    /// send it.
    pub(super) fn next_action(&mut self, t: &mut TeamState, now: Duration) -> TeamAction {
        if !self.started {
            self.started = true;
            return TeamAction::Grant(self.grant);
        }
        self.expire_non_finite(t, now);
        if let Some(a) = t.loss_action(self, now) {
            return a;
        }
        if let Some(a) = t.steer_action(self.grant) {
            return a;
        }
        while self
            .pending
            .get(self.complete)
            .is_some_and(|s| s.count == expected(t, self.cfg.ids.len(), self.complete))
        {
            self.complete += 1;
        }
        let cap = t
            .losses
            .as_ref()
            .map_or(self.cfg.last_tick, |l| l.book.cap(self.cfg.last_tick));
        let cap = t.steer.cap(cap);
        if let Some(want) = next_grant(self.complete, self.grant, self.window, cap) {
            self.grant = want;
            return TeamAction::Grant(want);
        }
        if let Some(done) = self.take_complete(t) {
            return done;
        }
        if let Some(s) = t.stopping.take() {
            if self.next_tick > s.record.tick || self.owed_never_come(t, now) {
                return TeamAction::Stop(s.record, s.reason);
            }
            t.stopping = Some(s);
        }
        if self.next_tick > self.cfg.last_tick {
            return TeamAction::Finished;
        }
        if self.progressed {
            if t.flush_due(now) {
                return TeamAction::Flush;
            }
            self.progressed = false;
            self.last_progress = now;
            return TeamAction::Poll;
        }
        self.when_stuck(t, now)
    }

    /// The next complete tick, unless the team stops at an earlier fault.
    fn take_complete(&mut self, t: &TeamState) -> Option<TeamAction> {
        let tick = self.next_tick;
        let stops_before = t.stopping.as_ref().is_some_and(|s| tick > s.record.tick);
        if tick >= self.complete || stops_before {
            return None;
        }
        let slot = self.pending.take_first(tick)?;
        self.next_tick += 1;
        self.progressed = true;
        Some(TeamAction::Complete {
            tick,
            states: slot.states,
        })
    }

    /// True when the next tick, incomplete, can no longer be completed: every member it lacks
    /// is lost, killed or sends no more, it was never granted, or nothing completed within the silence
    /// deadline (a member
    /// that owes it hangs). Waiting on members still alive, rather than for a fixed grace, keeps
    /// every tick before a fault however slowly the members start or run.
    fn owed_never_come(&self, t: &TeamState, now: Duration) -> bool {
        if now.saturating_sub(self.last_progress) > self.cfg.agent_timeout {
            return true;
        }
        let tick = self.next_tick;
        if tick > self.grant {
            // Never granted (a scripted loss caps the grants): nobody flies it.
            return true;
        }
        let have = self.pending.get(tick);
        !(self.cfg.ids.iter().enumerate()).any(|(k, &id)| {
            have.is_none_or(|s| s.states[k].is_none()) && !self.sends_no_more[k] && !t.is_gone(id)
        })
    }

    /// A non-finite state nobody reported within the grace: the orchestrator names its sender
    /// (a member without out-neighbours has no reader to report it).
    fn expire_non_finite(&mut self, t: &mut TeamState, now: Duration) {
        let Some((id, tick, seen)) = self.non_finite else {
            return;
        };
        if t.stopping.is_some() || now.saturating_sub(seen) <= FAULT_GRACE {
            return;
        }
        let clock = WhoseTick::Team;
        let since = now.checked_sub(FAULT_GRACE).unwrap_or(now);
        let fault = TeamFault::NonFinite { id, tick, clock };
        t.keep_fault(FaultRank::found(tick), &fault, since);
    }

    /// No tick completed this turn: look for exited members, then the deadlines, then wait.
    fn when_stuck(&mut self, t: &mut TeamState, now: Duration) -> TeamAction {
        if t.stopping.is_some() {
            return TeamAction::Wait(WAIT_SLICE);
        }
        if t.exited.is_none() && t.exit_check_due(now) {
            return TeamAction::CheckExited;
        }
        // Members run up to a window ahead of the audit: the states a dead member published
        // are audited first, and its fault is the first tick it never sent.
        if let Some(Exited { id, how, seen }) = &t.exited {
            let lacks = self.index.get(*id).is_none_or(|k| {
                self.pending
                    .get(self.next_tick)
                    .is_none_or(|s| s.states[k].is_none())
            });
            if lacks && now.saturating_sub(*seen) >= FAULT_GRACE {
                let (id, how, tick) = (*id, how.clone(), self.next_tick);
                return t.explained(&TeamFault::Exited { id, how, tick }, now);
            }
        }
        if now.saturating_sub(self.last_progress) > self.cfg.agent_timeout {
            let missing = self.missing(t);
            if let Some(a) = t.kill_silent(&missing, now) {
                self.last_progress = now;
                return a;
            }
            let fault = TeamFault::Silent {
                missing,
                tick: self.next_tick,
                timeout: self.cfg.agent_timeout,
            };
            return t.explained(&fault, now);
        }
        TeamAction::Wait(WAIT_SLICE)
    }

    /// The members that sent no state for the next tick (lost ones aside), in formation order.
    fn missing(&self, t: &TeamState) -> Vec<u32> {
        let tick = self.next_tick;
        let have = self.pending.get(tick);
        let lost = |id: u32| t.losses.as_ref().is_some_and(|l| l.book.lost_at(id, tick));
        (self.cfg.ids.iter().enumerate())
            .filter(|(k, _)| have.is_none_or(|s| s.states[*k].is_none()))
            .map(|(_, &id)| id)
            .filter(|&id| !lost(id))
            .collect()
    }
}

/// How many states complete `tick` (fewer once members are lost).
fn expected(t: &TeamState, n: usize, tick: u64) -> usize {
    t.losses.as_ref().map_or(n, |l| l.book.expected(tick))
}

impl LossPacing for Grants {
    fn newest_tick(&self, book: &TeamLosses, id: u32) -> Option<u64> {
        book.seen(id)
    }

    /// Lockstep repairs apply from the tick after the lost member's last state, exactly as
    /// `simulate --lose ID@(L dt)` flies it.
    fn repair_from(&self, _now: Duration, last: Option<u64>, _after_earlier: u64) -> u64 {
        last.map_or(0, |t| t + 1)
    }

    fn lost(&mut self, _: u32, _: LossCause, _: (Option<u64>, Option<u64>), now: Duration) {
        self.last_progress = now;
    }

    fn take_lost(&mut self) -> Option<super::LostMember> {
        None
    }

    fn link_timeout(&self) -> Duration {
        self.cfg.agent_timeout
    }

    fn position(&self) -> u64 {
        self.next_tick
    }

    fn progressed(&mut self, now: Duration) {
        self.last_progress = now;
    }
}

/// The first grant: a window of ticks (0..window), at most the last tick.
pub fn first_grant(window: u64, last: u64) -> u64 {
    (window.max(1) - 1).min(last)
}

/// The grant to send once ticks before `complete` are complete, or `None` to keep `grant`.
/// Members may run up to a window ahead; grants go out in steps of half a window (at least 1):
/// every grant wakes every member, so fewer, larger grants mean fewer wake-ups per tick. The
/// last tick is always granted.
pub fn next_grant(complete: u64, grant: u64, window: u64, last: u64) -> Option<u64> {
    let window = window.max(1);
    let want = (complete + window - 1).min(last);
    let step = (window / 2).max(1);
    (want > grant && (want >= grant + step || want == last)).then_some(want)
}

/// How long the orchestrator naps before it waits for the members' wake-ups, given the highest
/// tick `granted`, the `next` tick to complete and the `window`. Every member wakes `wake/orch`
/// whenever it goes to sleep; iceoryx2 sends one datagram for all the wake-ups that come before
/// the listener drains them. With the members more than a quarter window from the grant, a
/// short nap lets those wake-ups pile up (a bit each) and the orchestrator reads them in one go:
/// at N = 40 it woke about 6,800 times a second, once per 4 ticks. Near the grant, or with a
/// narrow window, where the members soon wait for the orchestrator, it does not nap.
pub fn nap_before_wait(granted: u64, next: u64, window: u64) -> Duration {
    if window >= 16 && granted.saturating_sub(next) > window / 4 {
        NAP
    } else {
        Duration::ZERO
    }
}

/// The nap of [`nap_before_wait`]: at most about 25 ticks of N = 40 at full speed, a tenth of
/// the default window's slack.
pub const NAP: Duration = Duration::from_millis(1);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_orchestrator_naps_only_far_from_the_grant_with_a_wide_window() {
        assert_eq!(nap_before_wait(300, 100, 256), NAP);
        assert_eq!(nap_before_wait(164, 100, 256), Duration::ZERO);
        assert_eq!(nap_before_wait(300, 100, 8), Duration::ZERO);
        assert_eq!(nap_before_wait(100, 300, 256), Duration::ZERO);
    }

    #[test]
    fn grant_window_grants_half_windows_and_always_the_last_tick() {
        assert_eq!(first_grant(4, 100), 3);
        assert_eq!(first_grant(1, 100), 0);
        assert_eq!(first_grant(8, 2), 2);
        // Window 4: from grant 3, tick 0 complete wants 4, a step of 2 is not reached yet.
        assert_eq!(next_grant(1, 3, 4, 100), None);
        assert_eq!(next_grant(2, 3, 4, 100), Some(5));
        // Window 1 is lockstep: every completed tick grants the next.
        assert_eq!(next_grant(1, 0, 1, 100), Some(1));
        assert_eq!(next_grant(1, 1, 1, 100), None);
        // The last tick is granted even when it is less than a step away.
        assert_eq!(next_grant(98, 99, 4, 100), Some(100));
        assert_eq!(next_grant(100, 100, 4, 100), None);
    }
}
