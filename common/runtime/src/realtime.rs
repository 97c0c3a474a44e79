//! A member in real time (`--realtime`) as a plain type with no I/O: events in (the clock
//! channel's start or stop, a neighbour's state, whether the orchestrator lives, "now" from a
//! clock the loop passes in), actions out (publish, ask about the orchestrator, wait, fail). The
//! core is the member core of lockstep too ([`MemberCore`]); this file is the timing
//! ([`Realtime`]) that paces it by the wall clock, and the one loop ([`crate::member_loop`])
//! flies it.
//!
//! How time flows (ARCHITECTURE.md): the orchestrator announces the start instant S; member i
//! has a phase offset phi_i in [0, dt) drawn from the announced seed, and its tick k is the
//! interval of simulation time [phi_i + k dt, phi_i + (k + 1) dt] on the common time line
//! t = wall - S. At the wall instant S + phi_i + k dt it publishes its state of that time (stamp
//! phi_i + k dt, carried as its tick: every member derives a neighbour's phase from the seed)
//! and flies the tick at once. No grant, no barrier: a follower never waits for a neighbour; it
//! brings the newest state it has of each to its own time with the cubic Taylor model the
//! lockstep tick uses inside a tick (`step::extrapolate_flat`). A neighbour whose newest state is
//! older than the bound (`--stale-after`, default 0.5 s) is a fault: the member reports it (its
//! state flagged `NeighborSilent` with the peer) and holds (it flies no further tick, so a real
//! vehicle would hover where it is) until the orchestrator stops the team.
//!
//! Over imperfect links (`--link-delay-ms`, `--link-jitter-ms`, `--link-loss`) a received state
//! is held back, or dropped, as lockstep's seeded draws say, in milliseconds of wall time
//! ([`crate::realtime_links`]); the follower extrapolates from the newest state it has.
//!
//! Losses (`--on-loss repair`): the orchestrator's notices ride on the clock channel as in
//! lockstep, and the member follows them with the same [`MemberLosses`] (the same repair, the
//! same ports to open, the same hand-over); a reader of a lost member flies its repaired link
//! from the notice's tick, which the orchestrator chose a lead ahead (`realtime/repair.rs`).

use std::time::Duration;

use cdm_math::Vec3;
use cdm_model::dynamics::{Flat, QuadState};
use cdm_model::formation::Member;
use cdm_model::link::{splitmix64, LinkModel};
use cdm_model::step::{extrapolate_flat, NeighborModel, TickAt};

use crate::member_core::{
    in_neighbors, Action, Deadlines, MemberCore, MemberFault, Shared, Timing, Wiring,
};
use crate::member_loss::MemberLosses;
use crate::member_protocol::WaitingFor;
use crate::messages::{
    ClockCommand, ClockMsg, FaultCode, StateMsg, SteerNotice, PHASES_ALIGNED, STATUS_PACING,
};
use crate::realtime_journal::{Flown, Journal, Switch, Switched};
use crate::realtime_links::DelayLine;
use crate::seams::Vehicle;

/// The default bound on a neighbour's age before it is a fault.
pub const STALE_AFTER: Duration = Duration::from_millis(500);

/// The phase offset of member `id`, in [0, dt): SplitMix64 of (seed, id) scaled to the period, so
/// members are not artificially aligned yet every process (and the monitor) derives the same
/// offsets from the seed announced with the start. [`PHASES_ALIGNED`] gives 0 to everyone.
pub fn phase_offset_s(seed: u32, id: u32, dt_s: f64) -> f64 {
    if seed == PHASES_ALIGNED {
        return 0.0;
    }
    let z = splitmix64(u64::from(seed) << 32 | u64::from(id));
    dt_s * ((z >> 11) as f64 / (1u64 << 53) as f64)
}

/// The simulation time of member `id`'s tick `tick` (its state's stamp).
pub fn stamp_s(tick: u64, phase_s: f64, dt_s: f64) -> f64 {
    tick as f64 * dt_s + phase_s
}

/// A member's own pacing figures, published as a [`STATUS_PACING`] message every second of
/// flight (so the monitor has them whatever stops the team) and when the stop arrives.
#[derive(Debug, Clone, PartialEq)]
pub struct MemberPacing {
    /// Ticks flown.
    pub ticks: u64,
    /// Ticks computed more than one period after their instant.
    pub late_ticks: u64,
    /// The latest a tick was computed after its instant (ms).
    pub max_late_ms: f64,
    /// Neighbour ages (own time minus the stamp of the newest state used), a histogram of
    /// [`AGE_BIN_MS`] bins; the last bin holds everything beyond.
    age_bins: Vec<u32>,
    /// The largest neighbour age (ms).
    pub age_max_ms: f64,
    /// In-neighbour states received, and how many of them the links lost (`realtime_links`).
    pub link_states: (u64, u64),
}

/// Width of a neighbour-age histogram bin (ms): percentiles are reported to this resolution.
pub const AGE_BIN_MS: f64 = 0.05;
const AGE_BINS: usize = 20_000; // 0 .. 1 s

/// The figures of a pacing message, as read back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PacingFigures {
    pub id: u32,
    pub ticks: u64,
    pub late_ticks: u64,
    pub max_late_ms: f64,
    pub age_p50_ms: f64,
    pub age_p99_ms: f64,
    pub age_max_ms: f64,
    /// How many neighbour ages were measured (0 for a leader).
    pub age_samples: u64,
    /// In-neighbour states received, and how many of them the links lost.
    pub link_states: (u64, u64),
}

impl Default for MemberPacing {
    fn default() -> Self {
        Self {
            ticks: 0,
            late_ticks: 0,
            max_late_ms: 0.0,
            age_bins: vec![0; AGE_BINS],
            age_max_ms: 0.0,
            link_states: (0, 0),
        }
    }
}

impl MemberPacing {
    fn tick(&mut self, late_s: f64, dt_s: f64) {
        self.ticks += 1;
        if late_s > dt_s {
            self.late_ticks += 1;
        }
        self.max_late_ms = self.max_late_ms.max(late_s * 1e3);
    }

    fn age(&mut self, age_s: f64) {
        let ms = age_s.max(0.0) * 1e3;
        let bin = ((ms / AGE_BIN_MS) as usize).min(AGE_BINS - 1);
        self.age_bins[bin] += 1;
        self.age_max_ms = self.age_max_ms.max(ms);
    }

    /// The `q`-quantile of the ages (upper edge of its bin), 0 without samples.
    fn age_quantile_ms(&self, q: f64) -> f64 {
        let n: u64 = self.age_bins.iter().map(|&c| u64::from(c)).sum();
        if n == 0 {
            return 0.0;
        }
        let want = (q * n as f64).ceil().max(1.0) as u64;
        let mut seen = 0;
        for (k, &c) in self.age_bins.iter().enumerate() {
            seen += u64::from(c);
            if seen >= want {
                return ((k + 1) as f64 * AGE_BIN_MS).min(self.age_max_ms);
            }
        }
        self.age_max_ms
    }

    /// The figures as a message: `tick` = ticks flown, `state` = [late ticks, max lateness ms,
    /// age p50 ms, age p99 ms, age max ms, age samples, states received, states lost, 0...].
    pub fn to_msg(&self, id: u32, hash: u64) -> StateMsg {
        let samples: u64 = self.age_bins.iter().map(|&c| u64::from(c)).sum();
        let mut f = [0.0; 12];
        f[0] = self.late_ticks as f64;
        f[1] = self.max_late_ms;
        f[2] = self.age_quantile_ms(0.5);
        f[3] = self.age_quantile_ms(0.99);
        f[4] = self.age_max_ms;
        f[5] = samples as f64;
        f[6] = self.link_states.0 as f64;
        f[7] = self.link_states.1 as f64;
        let mut m = StateMsg::ok(self.ticks, hash, id, f);
        m.status = STATUS_PACING;
        m
    }

    /// Reads a pacing message back (`None` when it is not one).
    pub fn from_msg(m: &StateMsg) -> Option<PacingFigures> {
        m.is_pacing().then(|| PacingFigures {
            id: m.id,
            ticks: m.tick,
            late_ticks: m.state[0] as u64,
            max_late_ms: m.state[1],
            age_p50_ms: m.state[2],
            age_p99_ms: m.state[3],
            age_max_ms: m.state[4],
            age_samples: m.state[5] as u64,
            link_states: (m.state[6] as u64, m.state[7] as u64),
        })
    }
}

/// The start as this member sees it.
#[derive(Debug, Clone, Copy)]
struct Start {
    /// Tick 0's instant (phase 0) on this member's clock.
    at: Duration,
    /// The phase seed announced with the start (a repair's new in-neighbours' phases).
    seed: u32,
    phase_s: f64,
    neighbor_phase_s: [f64; 3],
}

/// What the core needs of the scenario besides the member.
#[derive(Debug, Clone, Copy)]
pub struct RealtimeSetup {
    /// The scenario's content hash.
    pub hash: u64,
    /// The last tick of the plan.
    pub last: u64,
    /// The period (s).
    pub dt_s: f64,
    /// A neighbour older than this is a fault.
    pub stale_after: Duration,
    /// The join and silence deadlines (silence bounds the wait for the stop after the last tick).
    pub deadlines: Deadlines,
    /// The scenario's links: real deliveries are held back or dropped as they say.
    pub links: LinkModel,
}

/// A member flown in real time.
pub type RealtimeCore<V> = MemberCore<V, Realtime>;

/// Real time's side of a member: the start and the phases, what its links deliver, and its
/// pacing figures.
#[derive(Debug)]
pub struct Realtime {
    dt_s: f64,
    stale_after: Duration,
    /// The in-neighbours' initial positions at rest: their state before their first message.
    initial: [Flat; 3],
    /// The newest state heard of each in-neighbour: its tick and flat output.
    heard: [Option<(u64, Flat)>; 3],
    /// Received states the links still hold back.
    links: DelayLine,
    start: Option<Start>,
    pacing: MemberPacing,
    created: Duration,
    /// Loss notices and repairs (`None`: a loss notice is a fault).
    losses: Option<Box<MemberLosses>>,
    /// The repair tick whose wait for a new in-neighbour's state was logged.
    waited_at: Option<u64>,
    /// Where each flown tick's neighbour choices go (`realtime_journal.rs`), if anywhere.
    journal: Option<Box<dyn Journal>>,
}

impl<V: Vehicle> MemberCore<V, Realtime> {
    /// `member` flying `vehicle`; `neighbor_positions` are its in-neighbours' initial positions
    /// in the order of its law (ignored for a leader); `now` starts the join deadline.
    pub fn realtime(
        member: &Member,
        neighbor_positions: [Vec3; 3],
        setup: RealtimeSetup,
        vehicle: V,
        now: Duration,
    ) -> Self {
        let timing = Realtime {
            dt_s: setup.dt_s,
            stale_after: setup.stale_after,
            initial: neighbor_positions.map(Flat::rest),
            heard: [None; 3],
            links: DelayLine::new(setup.links, member.id, in_neighbors(member)),
            start: None,
            pacing: MemberPacing::default(),
            created: now,
            losses: None,
            waited_at: None,
            journal: None,
        };
        let plan = (setup.hash, setup.last);
        Self::with_timing(member, plan, vehicle, setup.deadlines, (timing, now))
    }

    /// The same core, following the orchestrator's loss notices with `losses` (repair in
    /// flight, `realtime/repair.rs`); without it a notice is a fault.
    pub fn with_losses(mut self, losses: MemberLosses) -> Self {
        self.timing.losses = Some(Box::new(losses));
        self
    }

    /// The same core, handing each flown tick's neighbour choices to `journal`.
    pub fn with_journal(mut self, journal: Box<dyn Journal>) -> Self {
        self.timing.journal = Some(journal);
        self
    }

    /// The pacing figures so far.
    pub fn pacing(&self) -> &MemberPacing {
        &self.timing.pacing
    }
}

impl<V: Vehicle> Timing<V> for Realtime {
    const WIRING: Wiring = Wiring {
        // Every one: a loss notice must not be skipped (the start and the stop are the only
        // other clock messages of a real-time flight).
        every_clock_message: true,
        flush_each_publish: true,
        fine_waits: true,
    };

    /// The start places tick 0 on this member's clock (read as `now` while the system clock
    /// read `unix_now_ns`); a loss notice is followed (or is a fault); a lockstep grant is a
    /// mode mismatch.
    fn on_clock(
        &mut self,
        m: &mut Shared<V>,
        c: &ClockMsg,
        (now, unix_now_ns): (Duration, u64),
    ) -> Result<(), MemberFault> {
        if let Some(n) = c.loss() {
            self.on_notice(m, n);
        }
        match c.command() {
            ClockCommand::Run => Err(MemberFault::ModeMismatch {
                member_realtime: true,
            }),
            ClockCommand::Realtime {
                start_unix_ns,
                phase_seed,
            } => {
                if self.start.is_none() {
                    // The system clock is read once, here; from now on only the monotonic one.
                    let ahead_ns = start_unix_ns as i128 - unix_now_ns as i128;
                    let at = if ahead_ns >= 0 {
                        now + Duration::from_nanos(ahead_ns as u64)
                    } else {
                        now.saturating_sub(Duration::from_nanos(ahead_ns.unsigned_abs() as u64))
                    };
                    let dt = self.dt_s;
                    self.start = Some(Start {
                        at,
                        seed: phase_seed,
                        phase_s: phase_offset_s(phase_seed, m.id, dt),
                        neighbor_phase_s: m.neighbor_ids.map(|j| phase_offset_s(phase_seed, j, dt)),
                    });
                }
                Ok(())
            }
            ClockCommand::Arm | ClockCommand::Stop(_) => Ok(()),
        }
    }

    /// The switch goes into the journal, on the path of a repair's (the tick it was taken at):
    /// a replay flies the commanded plan from it.
    fn on_steered(&mut self, m: &mut Shared<V>, n: &SteerNotice) {
        if let Some(j) = self.journal.as_mut() {
            j.switched(&Switch {
                tick: m.tick,
                what: Switched::Command {
                    seq: n.seq,
                    at: n.tick,
                },
            });
        }
    }

    /// Kept, once its link delivers it, when it is the in-neighbour's newest.
    fn on_neighbor(&mut self, _: &mut Shared<V>, slot: usize, msg: &StateMsg) {
        let flat = QuadState(msg.state).flat();
        if let Some((tick, flat)) = self.links.receive(slot, msg.tick, flat) {
            hear(&mut self.heard[slot], tick, flat);
        }
        self.pacing.link_states = self.links.counts();
    }

    /// A repair's future in-neighbour: its newest states are kept until its link applies.
    fn on_stranger(&mut self, m: &mut Shared<V>, msg: &StateMsg) {
        self.keep_future_neighbor(m, msg);
    }

    /// Waits for the start, then for each tick's instant: publishes the state of that time and
    /// flies the tick at once (on a repaired link from its tick); after the last tick, waits
    /// for the stop. A loss's port work goes first.
    fn poll(&mut self, m: &mut Shared<V>, now: Duration) -> Action {
        if let Some(w) = self.losses.as_mut().and_then(|l| l.next_work()) {
            return Action::Repair(w);
        }
        let Some(mut start) = self.start else {
            let join = self.created.saturating_add(m.deadlines.join);
            return self.idle(m, now, Some(join), None);
        };
        let t_own = stamp_s(m.tick, start.phase_s, self.dt_s);
        let due = start.at + Duration::from_secs_f64(t_own.max(0.0));
        if now < due {
            return self.idle(m, now, None, Some(due));
        }
        if m.published != Some(m.tick) {
            return m.publish_tick();
        }
        if m.tick >= m.last {
            // The plan is flown: wait for the stop (bounded).
            let silence = due.saturating_add(m.deadlines.silence);
            return self.idle(m, now, Some(silence), None);
        }
        // A command this leader acknowledged and that switches now is decided first.
        if let Some(a) = m.wait_for_decision(now, due.saturating_add(self.stale_after)) {
            return a;
        }
        if let Some(a) = self.relink_if_due(m, t_own) {
            return a;
        }
        // A repair may have moved the in-neighbours' phases.
        start = self.start.unwrap_or(start);
        self.fly(m, start, t_own, (now - due).as_secs_f64())
    }

    /// The final pacing figures.
    fn final_report(&self, m: &Shared<V>) -> Option<StateMsg> {
        Some(self.pacing.to_msg(m.id, m.hash))
    }
}

impl Realtime {
    /// Flies tick `m.tick` (own time `t_own`, computed `late_s` after its instant).
    fn fly<V: Vehicle>(
        &mut self,
        m: &mut Shared<V>,
        start: Start,
        t_own: f64,
        late_s: f64,
    ) -> Action {
        let dt = self.dt_s;
        let mut flats = self.initial;
        if m.is_follower {
            if let Some(stale) = self.neighbors_at(m, start, t_own, &mut flats) {
                return stale;
            }
        }
        let at = TickAt {
            tick: m.tick,
            offset_s: start.phase_s,
        };
        if let Err(fault) = m.vehicle.fly_tick_at(at, &flats) {
            return m.vehicle_failed(m.tick, fault);
        }
        self.pacing.tick(late_s, dt);
        if let Some(j) = self.journal.as_mut() {
            let used = if m.is_follower {
                self.heard.map(|h| h.map(|(tick, _)| tick))
            } else {
                [None; 3]
            };
            j.flown(&Flown { tick: m.tick, used });
        }
        m.tick += 1;
        // A pacing report every second of flight, so the monitor has one whatever stops the team.
        let per_second = (1.0 / dt).round().max(1.0) as u64;
        if m.tick.is_multiple_of(per_second) {
            return Action::Publish(self.pacing.to_msg(m.id, m.hash));
        }
        Action::Poll
    }

    /// The in-neighbours' states brought to own time `t_own` into `flats`, from the newest
    /// state the links delivered of each; a stale one is a fault reported to the team (the
    /// action returned).
    fn neighbors_at<V: Vehicle>(
        &mut self,
        m: &Shared<V>,
        start: Start,
        t_own: f64,
        flats: &mut [Flat; 3],
    ) -> Option<Action> {
        let dt = self.dt_s;
        let heard = &mut self.heard;
        self.links.release(
            t_own,
            |slot, tick| stamp_s(tick, start.neighbor_phase_s[slot], dt),
            |slot, tick, flat| hear(&mut heard[slot], tick, flat),
        );
        for (slot, out) in flats.iter_mut().enumerate() {
            let (stamp, flat) = match self.heard[slot] {
                Some((t, f)) => (stamp_s(t, start.neighbor_phase_s[slot], dt), f),
                None => (0.0, self.initial[slot]),
            };
            let age_s = t_own - stamp;
            if age_s > self.stale_after.as_secs_f64() {
                let peer = m.neighbor_ids[slot];
                let fault = MemberFault::NeighborStale {
                    tick: m.tick,
                    peer,
                    age: Duration::from_secs_f64(age_s),
                };
                return Some(m.fail(FaultCode::NeighborSilent, peer, fault));
            }
            self.pacing.age(age_s);
            *out = extrapolate_flat(&flat, age_s, NeighborModel::Taylor);
        }
        None
    }

    /// Nothing to do before `until` (the next tick's instant), or at all: give up at
    /// `deadline` (the start or the stop did not come).
    fn idle<V: Vehicle>(
        &self,
        m: &mut Shared<V>,
        now: Duration,
        deadline: Option<Duration>,
        until: Option<Duration>,
    ) -> Action {
        if let Some(a) = m.idle(now, deadline, until) {
            return a;
        }
        let waiting_for = if self.start.is_none() {
            WaitingFor::Start
        } else {
            WaitingFor::Stop
        };
        m.silent(now.saturating_sub(self.created), waiting_for)
    }
}

/// Keeps `(tick, flat)` in `slot` when it is newer than what the slot holds.
fn hear(slot: &mut Option<(u64, Flat)>, tick: u64, flat: Flat) {
    if slot.is_none_or(|(t, _)| tick > t) {
        *slot = Some((tick, flat));
    }
}

mod repair;
#[cfg(test)]
mod tests;
