//! The orchestrator's side of the team protocol as one plain type, with no I/O, in lockstep and
//! in real time: events in (a member's state or fault report, a member process seen exited, an
//! interrupt, which links are connected, "now" from a clock the caller drives), actions out
//! (grant, record a tick or an audit instant, kill, announce a loss, check the processes or the
//! links, flush, poll, wait, finish, stop with a fault). The loop around it (`cdm-launch`'s
//! `fly.rs`) owns the iceoryx2 ports, the processes and the files, and nothing else: every
//! decision is unit-tested with a fake clock.
//!
//! One core, two pacings ([`Pacing`]), as the member side has two timings: in lockstep
//! (`team_core/lockstep.rs`) the orchestrator grants ticks, members run up to a window ahead, and
//! a tick is complete when every member's state of it arrived; in real time
//! (`team_core/realtime.rs`) the wall clock paces the members and the orchestrator audits common
//! instants from their newest states. What both do alike lives here: which fault report names
//! the root cause ([`FaultRank`]), an exited member, an interrupt, when to look for exited
//! members and when to flush, whether the orchestrator itself stalled ([`StallWatch`]: a
//! member's exit or silence just after is blamed on the stall), and the losses
//! (`team_core/losses.rs`: the one place a loss is applied).

use std::time::Duration;

use cdm_records::audit::FaultRecord;

use cdm_model::outcome::LossCause;

use crate::messages::{LossNotice, StateMsg, SteerNotice, StopReason};
use crate::process_exit::ProcessExit;
use crate::stall::StallWatch;
pub use crate::team_fault::FaultRank;
use crate::team_fault::{InterruptedAt, TeamFault};
use crate::team_slots::IdIndex;

mod lockstep;
mod losses;
mod realtime;
mod realtime_losses;
mod steer;

pub use lockstep::{
    first_grant, nap_before_wait, next_grant, Grants, TeamConfig, TickStates, NAP, WAIT_SLICE,
};
use losses::LossEvents;
pub use realtime::{RealtimePlan, WallClock, LATE_WAIT, MAX_WAIT};
pub use realtime_losses::{MEMBER_STALE_FACTOR, REPAIR_LEAD_OF_STALE};
pub use steer::{
    earliest_file_switch_s, switch_margin_s, SteerOutcome, SWITCH_MARGIN_OF_STALE,
    SWITCH_MARGIN_TICKS,
};

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

/// Why a run stops early: the fault to record and the reason sent to the members.
pub type Stop = (FaultRecord, StopReason);

/// How long a non-finite state waits for a reader's fault report (which names both members),
/// and a reported fault for the complete ticks before it (lockstep).
pub const FAULT_GRACE: Duration = Duration::from_millis(500);

/// How often the loop is asked to look for an exited member process.
pub const EXIT_CHECK: Duration = Duration::from_millis(100);

/// How often telemetry is flushed while the team flies: complete ticks reach the file at least
/// this often (and at every stop).
pub const FLUSH_EVERY: Duration = Duration::from_millis(100);

/// What the loop must do next.
#[derive(Debug, Clone, PartialEq)]
pub enum TeamAction {
    /// Lockstep: publish a grant of ticks up to this one on the clock channel (with the latest
    /// loss notice) and wake the members.
    Grant(u64),
    /// Lockstep: tick `tick` is complete: record its losses, audit it and write its telemetry,
    /// then hand the states back ([`TeamCore::recycle`]).
    Complete { tick: u64, states: TickStates },
    /// Real time: audit and write instant `index` at `t_s` of the common time line, from the
    /// members' states brought to it ([`crate::realtime_monitor::MonitorCore::state_at`]).
    Audit { index: u64, t_s: f64 },
    /// A member is lost (real time): record it in the audit; its body leaves the audit and
    /// telemetry from instant `index` on. Lockstep records its losses with the tick they apply
    /// from ([`crate::team_loss::TeamLosses::due_at`]).
    Lost(LostMember),
    /// Publish the clock message again with this loss notice (a new loss, or its links joined).
    Announce(LossNotice),
    /// Publish the clock message again with this command notice (an accepted command, before
    /// any member may step into its switch tick).
    Steer(SteerNotice),
    /// Look for an exited member process and tell [`TeamCore::on_exited`] (if one is found).
    CheckExited,
    /// Ask the transport which of the awaited links of a repair are connected: answer with
    /// [`TeamCore::on_links`].
    CheckLinks,
    /// SIGKILL these members and reap them (a scripted loss, or silent past the deadline),
    /// then receive again: their last states are drained before their loss is applied.
    Kill(Vec<u32>),
    /// Flush the telemetry.
    Flush,
    /// The team progressed: receive again without sleeping.
    Poll,
    /// Receive after waiting at most this long (lockstep: woken by the members; real time: a
    /// plain sleep, members do not wake the monitor).
    Wait(Duration),
    /// The whole plan was flown: finish the files and stop the team.
    Finished,
    /// Stop the team: record the fault and send the reason.
    Stop(FaultRecord, StopReason),
}

/// What paces the team: the part of the protocol in which lockstep and real time differ.
#[derive(Debug)]
pub enum Pacing {
    /// The orchestrator grants ticks; a tick is complete once every member's state arrived.
    Lockstep(Grants),
    /// The wall clock paces the members; the orchestrator audits common instants.
    Realtime(WallClock),
}

/// The fault the team stops on: at once in real time; in lockstep once the ticks before it are
/// complete, or its grace is over.
#[derive(Debug)]
struct Stopping {
    record: FaultRecord,
    reason: StopReason,
    since: Duration,
    rank: FaultRank,
}

/// A member process seen exited.
#[derive(Debug)]
struct Exited {
    id: u32,
    how: ProcessExit,
    seen: Duration,
}

/// The team's state both pacings share.
#[derive(Debug)]
pub(crate) struct TeamState {
    index: IdIndex,
    interrupt: Option<String>,
    /// A fault that stops the team at once (a repair whose links never joined).
    halt: Option<TeamFault>,
    stopping: Option<Stopping>,
    exited: Option<Exited>,
    last_exit_check: Duration,
    last_flush: Duration,
    stall: StallWatch,
    /// Losses (`with_losses`): `None` keeps every dead member a fault.
    losses: Option<LossEvents>,
    /// Commands to announce (`with_commands`, `command`).
    steer: steer::SteerEvents,
}

/// The orchestrator's protocol state (see the module doc).
#[derive(Debug)]
pub struct TeamCore {
    t: TeamState,
    pacing: Pacing,
}

impl TeamCore {
    /// A lockstep team about to start at `now` (time since the caller's clock started).
    pub fn lockstep(cfg: TeamConfig, now: Duration) -> Self {
        let ids = cfg.ids.clone();
        Self::new(&ids, Pacing::Lockstep(Grants::new(cfg, now)), now)
    }

    /// A real-time flight about to be monitored at `now`, with the members' state book.
    pub fn realtime(
        plan: RealtimePlan,
        book: crate::realtime_monitor::MonitorCore,
        now: Duration,
    ) -> Self {
        let ids = book.ids();
        Self::new(&ids, Pacing::Realtime(WallClock::new(plan, book)), now)
    }

    fn new(ids: &[u32], pacing: Pacing, now: Duration) -> Self {
        let t = TeamState {
            index: IdIndex::new(ids),
            interrupt: None,
            halt: None,
            stopping: None,
            exited: None,
            last_exit_check: now,
            last_flush: now,
            stall: StallWatch::new(now),
            losses: None,
            steer: steer::SteerEvents::default(),
        };
        TeamCore { t, pacing }
    }

    /// What paces the team.
    pub fn pacing(&self) -> &Pacing {
        &self.pacing
    }

    /// The real-time pacing, to read the members' states at an audit instant and their final
    /// pacing reports after the stop (`None` in lockstep).
    pub fn wall_clock_mut(&mut self) -> Option<&mut WallClock> {
        match &mut self.pacing {
            Pacing::Realtime(w) => Some(w),
            Pacing::Lockstep(_) => None,
        }
    }

    /// Where the run is: the next tick to complete (lockstep) or the next instant to audit
    /// (real time). A fault found now names it.
    pub fn position(&self) -> u64 {
        match &self.pacing {
            Pacing::Lockstep(g) => g.next_tick(),
            Pacing::Realtime(w) => w.audits(),
        }
    }

    /// A new turn of the loop at `now`, before it receives. A long gap since the last turn
    /// means the orchestrator itself did not run: a member that stopped meanwhile is blamed on
    /// the stall (lockstep members also get a fresh silence timeout). Members killed or seen
    /// dead before it are lost after this drain.
    pub fn on_turn(&mut self, now: Duration) {
        let at = self.position();
        if self.t.stall.turn(now, at) {
            if let Pacing::Lockstep(g) = &mut self.pacing {
                g.restart_silence(now);
            }
        }
        if let Some(l) = &mut self.t.losses {
            l.turn();
        }
    }

    /// A message from a member's state service: a state, a fault report, a pacing report, an
    /// acknowledgement of a proposed command.
    pub fn on_state(&mut self, msg: &StateMsg, now: Duration) {
        if let Some(seq) = msg.steer_acked() {
            self.t.steer.ack(msg.id, seq);
            return;
        }
        match &mut self.pacing {
            Pacing::Lockstep(g) => g.on_state(&mut self.t, msg, now),
            Pacing::Realtime(w) => w.on_state(&mut self.t, msg, now),
        }
    }

    /// Member `id`'s process was seen exited (`how`). A loss when losses are repaired and the
    /// orchestrator did not stall just before; else the fault that stops the team (lockstep:
    /// its published states are still audited, its fault is the first tick it never sent).
    /// Ignored for a member already lost or being lost, and while the team stops on a fault
    /// (the reporter's own exit).
    pub fn on_exited(&mut self, id: u32, how: ProcessExit, now: Duration) {
        let t = &mut self.t;
        if t.is_gone(id) || t.lost_on_exit(id, &how, now) {
            return;
        }
        if t.exited.is_none() && t.stopping.is_none() && t.index.get(id).is_some() {
            t.exited = Some(Exited { id, how, seen: now });
        }
    }

    /// The run was interrupted by `signal` (SIGINT, ...): the next action stops the team.
    pub fn on_interrupt(&mut self, signal: &str) {
        self.t.interrupt.get_or_insert_with(|| signal.to_owned());
    }

    /// Hands back a complete tick's states for a later tick (lockstep).
    pub fn recycle(&mut self, states: TickStates) {
        if let Pacing::Lockstep(g) = &mut self.pacing {
            g.recycle(states);
        }
    }

    /// The next action at `now`: a signal, then a repair that failed, stop the team; the rest
    /// is the pacing's order.
    pub fn next_action(&mut self, now: Duration) -> TeamAction {
        if let Some(signal) = self.t.interrupt.take() {
            let at = match &self.pacing {
                Pacing::Lockstep(g) => InterruptedAt::Tick(g.next_tick()),
                Pacing::Realtime(w) => w.interrupted_at(),
            };
            return stop(&TeamFault::Interrupted { signal, at });
        }
        if let Some(f) = self.t.halt.take() {
            return stop(&f);
        }
        match &mut self.pacing {
            Pacing::Lockstep(g) => g.next_action(&mut self.t, now),
            Pacing::Realtime(w) => w.next_action(&mut self.t, now),
        }
    }
}

/// The fault of a member process that exited (`how`) before the end, named with its id and
/// `tick`.
pub fn exited_fault(id: u32, how: ProcessExit, tick: u64) -> Stop {
    TeamFault::Exited { id, how, tick }.stop()
}

/// The stop on `fault`.
fn stop(fault: &TeamFault) -> TeamAction {
    let (record, reason) = fault.stop();
    TeamAction::Stop(record, reason)
}

impl TeamState {
    /// Keeps `fault` (ranked `rank`, seen since `since`) when it names the root cause better
    /// than the one kept so far.
    fn keep_fault(&mut self, rank: FaultRank, fault: &TeamFault, since: Duration) {
        if !rank.outranks(self.stopping.as_ref().map(|s| &s.rank)) {
            return;
        }
        let (record, reason) = fault.stop();
        self.stopping = Some(Stopping {
            record,
            reason,
            since,
            rank,
        });
    }

    /// The fault kept so far was seen since (`now` when none is).
    fn fault_since(&self, now: Duration) -> Duration {
        self.stopping.as_ref().map_or(now, |s| s.since)
    }

    /// True every [`EXIT_CHECK`]: look for exited members now.
    fn exit_check_due(&mut self, now: Duration) -> bool {
        let due = now.saturating_sub(self.last_exit_check) > EXIT_CHECK;
        if due {
            self.last_exit_check = now;
        }
        due
    }

    /// True every [`FLUSH_EVERY`]: flush the telemetry now.
    fn flush_due(&mut self, now: Duration) -> bool {
        let due = now.saturating_sub(self.last_flush) > FLUSH_EVERY;
        if due {
            self.last_flush = now;
        }
        due
    }

    /// The stop on a member `fault` found at `now`: blamed on the orchestrator when it stalled
    /// just before.
    fn explained(&self, fault: &TeamFault, now: Duration) -> TeamAction {
        let (record, reason) = fault.stop();
        TeamAction::Stop(self.stall.explain(record, now), reason)
    }
}

#[cfg(test)]
mod core_tests;
