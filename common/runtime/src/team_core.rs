//! The orchestrator's side of the team protocol as a plain type, with no I/O: events in (a
//! member's state or fault report, a member process seen exited, an interrupt, "now" from a
//! clock the caller drives), actions out (grant up to tick g, a complete tick to audit and
//! write, check the processes, poll again, wait, finish, stop with a fault). The loop around it
//! (`common/launch/src/launch.rs`) owns the iceoryx2 ports, the processes and the files, and
//! nothing else: every decision below is unit-tested with a fake clock (`team_core/core_tests.rs`).
//!
//! What it decides: the grant window (members run up to `window` ticks ahead of the last tick
//! completely received), which ticks are complete (one slot per tick and member), which fault
//! report names the root cause ([`FaultRank`]), how long a non-finite state or a reported fault
//! waits for the ticks before it ([`FAULT_GRACE`]), the tick an exited member is blamed for,
//! the silence deadline, and whether the orchestrator itself stalled ([`StallWatch`]).

use std::time::Duration;

use cdm_records::audit::FaultRecord;

use crate::messages::{AgentStatus, FaultCode, StateMsg, StopReason};
use crate::stall::StallWatch;
pub use crate::team_fault::FaultRank;
use crate::team_fault::{InterruptedAt, TeamFault, TickClock};
use crate::team_loss::{Dying, TeamLosses};
use crate::team_slots::{IdIndex, TickSlots};

/// Why a run stops early: the fault to record and the reason sent to the members.
pub type Stop = (FaultRecord, StopReason);

/// How long a non-finite state waits for a reader's fault report (which names both members),
/// and a reported fault for the complete ticks before it.
pub const FAULT_GRACE: Duration = Duration::from_millis(500);

/// How often the loop is asked to look for an exited member process while the team is stuck.
pub const EXIT_CHECK: Duration = Duration::from_millis(100);

/// The longest wait of the orchestrator's loop: it bounds how late the deadlines run (states
/// and fault reports wake it at once).
pub const WAIT_SLICE: Duration = Duration::from_millis(20);

/// What the team core needs to know of a run.
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
/// Hand the vector back with [`TeamCore::recycle`] so the next tick reuses it (no allocation
/// per tick).
pub type TickStates = Vec<Option<StateMsg>>;

/// What the loop must do next.
#[derive(Debug, Clone, PartialEq)]
pub enum TeamAction {
    /// Publish a grant of ticks up to this one on the clock channel (and wake the members).
    Grant(u64),
    /// Tick `tick` is complete: audit it and write its telemetry, then [`TeamCore::recycle`].
    Complete { tick: u64, states: TickStates },
    /// Look for an exited member process and tell [`TeamCore::on_exited`] (if one is found).
    CheckExited,
    /// The team progressed: receive again without sleeping.
    Poll,
    /// Sleep until woken or this long passes, then receive again.
    Wait(Duration),
    /// SIGKILL these members and reap them (a scripted loss, or silent past the timeout),
    /// then receive again: their last states are drained before their loss is announced.
    Kill(Vec<u32>),
    /// Ask the transport which of the awaited links of a repair are connected: answer with
    /// [`TeamCore::on_links`].
    CheckLinks,
    /// Every tick of the plan is complete: finish the files and stop the team.
    Finished,
    /// Stop the team: record the fault and send the reason.
    Stop(FaultRecord, StopReason),
}

/// The tick slots not complete yet.
#[derive(Debug)]
struct Slot {
    states: TickStates,
    count: usize,
}

/// The fault the team stops on once the ticks before it are complete, or its grace is over.
#[derive(Debug)]
struct Stopping {
    record: FaultRecord,
    since: Duration,
    rank: FaultRank,
}

/// A member process seen exited.
#[derive(Debug)]
struct Exited {
    id: u32,
    how: String,
    seen: Duration,
}

/// The orchestrator's protocol state (see the module doc).
#[derive(Debug)]
pub struct TeamCore {
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
    last_exit_check: Duration,
    /// A non-finite state: who sent it, its tick, when it was seen. It is never audited.
    non_finite: Option<(u32, u64, Duration)>,
    stopping: Option<Stopping>,
    exited: Option<Exited>,
    interrupt: Option<Stop>,
    stall: StallWatch,
    /// Losses (`with_losses`): `None` keeps every dead member a fault.
    losses: Option<LossEvents>,
}

/// The losses of a run as the team core handles them (`team_core/loss_events.rs`).
#[derive(Debug)]
struct LossEvents {
    book: TeamLosses,
    /// Dead or silent members are lost and repaired around (`--on-loss repair`, spawned team).
    repairs: bool,
    /// Killed or found dead, their last states not yet drained.
    dying: Dying,
    last_link_check: Duration,
    /// The loss notice changed: grant again so the clock carries it.
    republish: bool,
}

impl TeamCore {
    /// A team about to start at `now` (time since the caller's clock started).
    pub fn new(cfg: TeamConfig, now: Duration) -> Self {
        let index = IdIndex::new(&cfg.ids);
        let window = u64::from(cfg.window.max(1));
        let grant = first_grant(window, cfg.last_tick);
        TeamCore {
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
            last_exit_check: now,
            non_finite: None,
            stopping: None,
            exited: None,
            interrupt: None,
            stall: StallWatch::new(now),
            losses: None,
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

    /// A new turn of the loop at `now`, before it receives. A long gap since the last turn
    /// means the orchestrator itself did not run: its members get a fresh silence timeout, and
    /// a member that stopped meanwhile is blamed on the stall.
    pub fn on_turn(&mut self, now: Duration) {
        if self.stall.turn(now, self.next_tick) {
            self.last_progress = now;
        }
        if let Some(l) = &mut self.losses {
            l.dying.turn();
        }
    }

    /// A received state or fault report. States outside the granted window are ignored (stale
    /// or foreign); a non-finite one is never used.
    pub fn on_state(&mut self, msg: StateMsg, now: Duration) {
        let Some(k) = self.index.get(msg.id) else {
            return;
        };
        if let AgentStatus::Fault { code, peer } = msg.status() {
            self.on_report(&msg, k, code, peer, now);
            return;
        }
        if let Some(l) = &mut self.losses {
            l.book.saw_at(k, msg.id, msg.tick);
        }
        if !self.started || msg.tick < self.next_tick || msg.tick > self.grant {
            return;
        }
        if msg.state.iter().any(|v| !v.is_finite()) {
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
        slot.states[k] = Some(msg);
    }

    /// A fault report of member `k`: kept when it names the root cause better than the one
    /// kept so far (whose grace started earlier and goes on).
    fn on_report(
        &mut self,
        msg: &StateMsg,
        k: usize,
        code: FaultCode,
        peer: Option<u32>,
        now: Duration,
    ) {
        let rank = FaultRank::of_report(code, msg.tick, k);
        if !rank.outranks(self.stopping.as_ref().map(|s| &s.rank)) {
            return;
        }
        let fault = TeamFault::Reported {
            id: msg.id,
            tick: msg.tick,
            code,
            peer,
            clock: TickClock::Team,
        };
        let since = self.stopping.as_ref().map_or(now, |s| s.since);
        self.stopping = Some(Stopping {
            record: fault.record(),
            since,
            rank,
        });
    }

    /// Member `id`'s process was seen exited (`how`: "exited with code 1", "was killed by
    /// signal 9"). Its published states are still audited; its fault is the first tick it never
    /// sent. Ignored while the team stops on a reported fault (the reporter's own exit).
    pub fn on_exited(&mut self, id: u32, how: String, now: Duration) {
        if self.lost_on_exit(id, &how, now) {
            return;
        }
        if self.exited.is_none() && self.stopping.is_none() && self.index.get(id).is_some() {
            self.exited = Some(Exited { id, how, seen: now });
        }
    }

    /// The run was interrupted by `signal` (SIGINT, ...): the next action stops the team.
    pub fn on_interrupt(&mut self, signal: &str) {
        let fault = TeamFault::Interrupted {
            signal: signal.into(),
            at: InterruptedAt::Tick(self.next_tick),
        };
        self.interrupt.get_or_insert_with(|| fault.stop());
    }

    /// Hands back a complete tick's states for a later tick.
    pub fn recycle(&mut self, mut states: TickStates) {
        states.fill(None);
        self.spare.push(states);
    }

    /// The next action at `now`. Grants go out before complete ticks (members go on while the
    /// orchestrator audits and writes); a fault at tick k stops the team once ticks 0..=k are
    /// complete (as `simulate` keeps them) or its grace is over.
    pub fn next_action(&mut self, now: Duration) -> TeamAction {
        if let Some((f, reason)) = self.interrupt.take() {
            return TeamAction::Stop(f, reason);
        }
        if !self.started {
            self.started = true;
            return TeamAction::Grant(self.grant);
        }
        self.expire_non_finite(now);
        if let Some(a) = self.loss_action(now) {
            return a;
        }
        while self
            .pending
            .get(self.complete)
            .is_some_and(|s| s.count == self.expected(self.complete))
        {
            self.complete += 1;
        }
        if let Some(want) = next_grant(self.complete, self.grant, self.window, self.cap()) {
            self.grant = want;
            return TeamAction::Grant(want);
        }
        if let Some(done) = self.take_complete() {
            return done;
        }
        if let Some(s) = self.stopping.take() {
            if self.next_tick > s.record.tick || now.saturating_sub(s.since) >= FAULT_GRACE {
                return TeamAction::Stop(s.record, StopReason::AgentFault);
            }
            self.stopping = Some(s);
        }
        if self.next_tick > self.cfg.last_tick {
            return TeamAction::Finished;
        }
        if std::mem::take(&mut self.progressed) {
            self.last_progress = now;
            return TeamAction::Poll;
        }
        self.when_stuck(now)
    }

    /// The next complete tick, unless the team stops at an earlier fault.
    fn take_complete(&mut self) -> Option<TeamAction> {
        let tick = self.next_tick;
        if tick >= self.complete || self.stopping.as_ref().is_some_and(|s| tick > s.record.tick) {
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

    /// A non-finite state nobody reported within the grace: the orchestrator names its sender
    /// (a member without out-neighbours has no reader to report it).
    fn expire_non_finite(&mut self, now: Duration) {
        let Some((id, tick, seen)) = self.non_finite else {
            return;
        };
        if self.stopping.is_some() || now.saturating_sub(seen) <= FAULT_GRACE {
            return;
        }
        let clock = TickClock::Team;
        self.stopping = Some(Stopping {
            record: TeamFault::NonFinite { id, tick, clock }.record(),
            since: now.checked_sub(FAULT_GRACE).unwrap_or(now),
            rank: FaultRank::found(tick),
        });
    }

    /// No tick completed this turn: look for exited members, then the deadlines, then wait.
    fn when_stuck(&mut self, now: Duration) -> TeamAction {
        if self.stopping.is_some() {
            return TeamAction::Wait(WAIT_SLICE);
        }
        if self.exited.is_none() && now.saturating_sub(self.last_exit_check) > EXIT_CHECK {
            self.last_exit_check = now;
            return TeamAction::CheckExited;
        }
        // Members run up to a window ahead of the audit: the states a dead member published
        // are audited first, and its fault is the first tick it never sent.
        if let Some(e) = &self.exited {
            let lacks = self.index.get(e.id).is_none_or(|k| {
                self.pending
                    .get(self.next_tick)
                    .is_none_or(|s| s.states[k].is_none())
            });
            if lacks && now.saturating_sub(e.seen) >= FAULT_GRACE {
                let (f, reason) = exited_fault(e.id, &e.how, self.next_tick);
                return TeamAction::Stop(self.stall.explain(f, now), reason);
            }
        }
        if now.saturating_sub(self.last_progress) > self.cfg.agent_timeout {
            if let Some(a) = self.kill_silent(now) {
                return a;
            }
            let f = self.silent_fault();
            return TeamAction::Stop(self.stall.explain(f, now), StopReason::AgentSilent);
        }
        TeamAction::Wait(WAIT_SLICE)
    }

    /// The members that sent no state for the next tick (lost ones aside), in formation order.
    fn missing(&self) -> Vec<u32> {
        let tick = self.next_tick;
        let have = self.pending.get(tick);
        (self.cfg.ids.iter().enumerate())
            .filter(|(k, _)| have.is_none_or(|s| s.states[*k].is_none()))
            .map(|(_, &id)| id)
            .filter(|&id| !self.is_lost(id, tick))
            .collect()
    }

    /// The members that sent no state for the next tick, named in formation order.
    fn silent_fault(&self) -> FaultRecord {
        TeamFault::Silent {
            missing: self.missing(),
            tick: self.next_tick,
            timeout: self.cfg.agent_timeout,
        }
        .record()
    }
}

/// The fault of a member process that exited before the end, named with its id and `tick`.
pub fn exited_fault(id: u32, how: &str, tick: u64) -> Stop {
    let how = how.to_owned();
    TeamFault::Exited { id, how, tick }.stop()
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
/// at N = 40 it woke about 6,800 times a second, once per 4 ticks (issue 28). Near the grant,
/// or with a narrow window, where the members soon wait for the orchestrator, it does not nap.
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

mod loss_events;

#[cfg(test)]
mod core_tests;

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
