//! A real-time flight flown again in one process from what the wall clock decided
//! (`realtime_journal.rs`): every member's tick k is `step::step_at` at its own time
//! `k dt + phi_i`, on the in-neighbour states it flew on in the run (their ticks recorded),
//! brought to its time by the same cubic Taylor model (`step::extrapolate_flat`); the monitor's
//! audit instants are taken by the same [`MonitorCore`] from the same states. Nothing here
//! reads a clock: the same journals give the same telemetry, byte for byte, and other gains
//! ("what if") fly the same history with the change.
//!
//! A late member may have flown on a state stamped after its own time (a neighbour's of a
//! later tick), so members do not fly in rounds of ticks: each flies its next tick as soon as
//! the states it flew on in the run are there (the run's own wall-clock order is one such
//! order, so a whole recording always flies through). The audit instants are then taken from
//! every member's states as the monitor took them: each instant once every member has a state
//! at or after it.
//!
//! Losses and commands (`realtime_replay/switches.rs`): each member applies the repaired links
//! and the commanded plans at the ticks its recording says it did (the links themselves are the
//! repair of the run's losses, `cdm_model::repair`, as every member computed them from the
//! notices); a lost member's body leaves the audit at the instant the run's monitor took it out
//! (audit.json), with the same loss records.

use std::collections::BTreeMap;

use cdm_math::Vec3;
use cdm_model::dynamics::{Flat, QuadState};
use cdm_model::formation::Member;
use cdm_model::formation::Role;
use cdm_model::step::{extrapolate_flat, law_for, Law, NeighborModel, TickAt};
use cdm_records::audit::{Auditor, FaultRecord, LossRecord, Unheard};
use cdm_records::record::TickRecorder;
use cdm_records::telemetry::TelemetrySink;
use cdm_scenario::Scenario;

use crate::messages::StateMsg;
use crate::realtime::{phase_offset_s, stamp_s};
use crate::realtime_journal::Switch;
use crate::realtime_monitor::MonitorCore;
use crate::seams::{ModelVehicle, Vehicle, VehicleFault};

/// How the run was flown, besides the scenario.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReplayTiming {
    /// The phase seed announced with the start.
    pub phase_seed: u32,
    /// The monitor's audit rate (Hz).
    pub audit_hz: f64,
    /// The monitor's stale bound (s): how much history it kept.
    pub stale_after_s: f64,
    /// The run's `--max-ticks`.
    pub max_ticks: Option<u64>,
    /// What if the links were slower (positive) or faster (negative) by this many ticks: each
    /// neighbour state flown on is that much older or newer than the one the run flew on.
    pub link_shift_ticks: i64,
    /// The audit instant at which the run's monitor stopped the flight on a fault (a stale
    /// member, say: the wall clock decided it), if it did: no instant from it on is audited.
    pub stopped_at: Option<u64>,
}

/// Why a replay cannot fly a member's recorded tick.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ReplayInputError {
    /// A member of the scenario has no journal.
    #[error("agent {id}: no recording")]
    Missing { id: u32 },
    /// A journal names a member the scenario does not have.
    #[error("agent {id}: recorded, but not in the scenario")]
    Stranger { id: u32 },
    /// A tick flew on a state no order of the ticks gives (a neighbour's tick that needs this
    /// one first, or one past the neighbour's recording).
    #[error("agent {id} tick {tick}: flew on agent {peer}'s state of tick {used}, which the recordings cannot give before it")]
    Unflyable {
        id: u32,
        tick: u64,
        peer: u32,
        used: u64,
    },
    /// A leader's tick names a neighbour state.
    #[error("agent {id} tick {tick}: a leader flies on no neighbour")]
    LeaderWithNeighbors { id: u32, tick: u64 },
    /// A switch the run's losses or commands do not give.
    #[error("agent {id} tick {tick}: {why}")]
    Switch { id: u32, tick: u64, why: String },
}

/// One member's recording as the replay takes it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Recorded {
    /// For each tick flown from tick 0, the tick of the state each in-neighbour slot flew on.
    pub used: Vec<[Option<u64>; 3]>,
    /// The switches it applied (repaired links, commands), in order.
    pub switches: Vec<Switch>,
    /// False when the recording was cut short: a reader may then have flown on a state of this
    /// member it does not hold, and the replay ends there.
    pub whole: bool,
}

/// A member lost in the run, as its monitor applied it (audit.json's `losses`).
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayLoss {
    pub id: u32,
    /// The notice's tick: its readers' repaired link applies from it (each member's recording
    /// says when it flew it).
    pub repair_tick: u64,
    /// The first audit instant without its body.
    pub out_from: u64,
    /// What the audit records of it, from that instant.
    pub records: Vec<LossRecord>,
}

/// Everything of a run the wall clock decided, as the replay takes it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct History {
    /// Each member's recording, by id.
    pub recorded: BTreeMap<u32, Recorded>,
    /// The losses, in the order the monitor found them (ascending notice ticks).
    pub losses: Vec<ReplayLoss>,
    /// The switch ticks of the run's accepted commands, notice 1 first.
    pub commands: Vec<u64>,
    /// The members' states the run's monitor never received (audit.json's `unheard`): its
    /// audit instants went around them.
    pub unheard: Vec<Unheard>,
}

/// How far a replay got.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReplayEnd {
    /// Audit instants recorded.
    pub audits: u64,
    /// Every audit instant of the run's plan was recorded.
    pub complete: bool,
    /// The fewest ticks any member flew (where a recording cut short ends the replay).
    pub ticks_flown: u64,
}

/// One member as the replay flies it.
struct Flier<'a> {
    id: u32,
    vehicle: ModelVehicle<'a>,
    phase_s: f64,
    /// The in-neighbours' ids in the order of the law (as the member keeps them).
    neighbor_ids: [u32; 3],
    /// Formation indices of the in-neighbours (followers only), in the order of the law.
    neighbors: Option<[usize; 3]>,
    /// The in-neighbours at rest where they start: their state before their first.
    initial: [Flat; 3],
    rec: &'a Recorded,
    /// The repaired links it flew, each from its tick, and how many are applied.
    relinks: (Vec<(u64, Member)>, usize),
    /// [`ReplayTiming::link_shift_ticks`].
    shift: i64,
    /// The state of every tick so far (tick k's before tick k is flown), and its flat output.
    states: Vec<([f64; 12], Flat)>,
}

impl Flier<'_> {
    /// The next tick to fly.
    fn next(&self) -> u64 {
        self.states.len() as u64 - 1
    }

    /// Every recorded tick is flown.
    fn done(&self) -> bool {
        self.next() as usize >= self.rec.used.len()
    }
}

/// Flies `s` again on `history` (the members' recordings, the losses and commands), recording
/// the audit instants into `audit` and `tel` as the run's monitor did. A recording cut short
/// ends the replay at the last instant every member's states cover.
pub fn replay(
    s: &Scenario,
    timing: ReplayTiming,
    history: &History,
    audit: &mut Auditor,
    tel: &mut dyn TelemetrySink,
) -> Result<Result<ReplayEnd, FaultRecord>, ReplayInputError> {
    let recorded = &history.recorded;
    let epochs = switches::epochs(s, &history.losses);
    if let Some(id) = recorded
        .keys()
        .find(|id| s.formation.member(**id).is_none())
    {
        return Err(ReplayInputError::Stranger { id: *id });
    }
    let cfg = s.step_config();
    let dt = s.dt_s();
    let members = &s.formation.members;
    let index_of = |id: u32| members.iter().position(|m| m.id == id);
    let mut fliers = Vec::with_capacity(members.len());
    for m in members {
        let rec = recorded
            .get(&m.id)
            .ok_or(ReplayInputError::Missing { id: m.id })?;
        let (law, ins) = law_for(m);
        let follower = matches!(law, Law::Follower { .. });
        let neighbors = follower.then(|| ins.map(|j| index_of(j).unwrap_or(usize::MAX)));
        if !follower {
            if let Some(tick) = rec.used.iter().position(|u| u.iter().any(Option::is_some)) {
                let tick = tick as u64;
                return Err(ReplayInputError::LeaderWithNeighbors { id: m.id, tick });
            }
        }
        let mut initial = [Flat::rest(Vec3::zeros()); 3];
        if follower {
            for (f, j) in initial.iter_mut().zip(ins) {
                if let Some(n) = s.formation.member(j) {
                    *f = Flat::rest(n.position);
                }
            }
        }
        let vehicle = ModelVehicle::new(cfg, &s.plan, m);
        let x = vehicle.state();
        let mut states = Vec::with_capacity(rec.used.len() + 1);
        states.push((x, QuadState(x).flat()));
        let relinks = switches::relinks(m.id, rec, &epochs, &history.commands)?;
        fliers.push(Flier {
            id: m.id,
            vehicle,
            phase_s: phase_offset_s(timing.phase_seed, m.id, dt),
            neighbor_ids: ins,
            neighbors,
            initial,
            rec,
            relinks: (relinks, 0),
            shift: timing.link_shift_ticks,
            states,
        });
    }
    let fault = fly_all(s, &mut fliers)?;
    let end = audit_all(s, timing, (&fliers[..], history), audit, tel)?;
    Ok(match fault {
        Some(f) => Err(f),
        None => Ok(end),
    })
}

/// Flies every member's recorded ticks, each as soon as the states it flew on are there (after
/// the switch it applied before it, if any). A control fault (a what-if's) ends the flight; so
/// does a reader of a recording cut short.
fn fly_all(s: &Scenario, fliers: &mut [Flier]) -> Result<Option<FaultRecord>, ReplayInputError> {
    let dt = s.dt_s();
    let mut progress = true;
    while progress {
        progress = false;
        for k in 0..fliers.len() {
            while !fliers[k].done() {
                switches::relink_if_due(s, fliers, k);
                if blocker(fliers, k).is_some() {
                    break;
                }
                let tick = fliers[k].next();
                let flats = neighbors_of(fliers, k, tick, dt);
                let f = &mut fliers[k];
                let at = TickAt {
                    tick,
                    offset_s: f.phase_s,
                };
                if let Err(e) = f.vehicle.fly_tick_at(at, &flats) {
                    return Ok(Some(control_fault(f.id, tick, e)));
                }
                let x = f.vehicle.state();
                f.states.push((x, QuadState(x).flat()));
                progress = true;
            }
        }
    }
    // Whatever is left waits for a state no order gives, unless a recording cut short ends it.
    for k in 0..fliers.len() {
        if let Some((slot, used)) = blocker(fliers, k).filter(|_| !fliers[k].done()) {
            let n = fliers[k].neighbors.map_or(usize::MAX, |ins| ins[slot]);
            let cut = fliers.get(n).is_some_and(|n| !n.rec.whole && n.done());
            if !cut {
                return Err(ReplayInputError::Unflyable {
                    id: fliers[k].id,
                    tick: fliers[k].next(),
                    peer: fliers.get(n).map_or(0, |n| n.id),
                    used,
                });
            }
        }
    }
    Ok(None)
}

/// The slot (and tick) of member `k`'s next tick whose state is not there yet, if any.
fn blocker(fliers: &[Flier], k: usize) -> Option<(usize, u64)> {
    let f = &fliers[k];
    let ins = f.neighbors?;
    let tick = f.next();
    (0..3).find_map(|slot| {
        let t = used_at(fliers, k, tick, slot)?;
        let have = fliers.get(ins[slot]).map_or(0, |n| n.states.len() as u64);
        (t >= have).then_some((slot, t))
    })
}

/// The tick of the state member `k` flies its tick `tick` on in `slot`: the one it flew on in
/// the run or, what if the links were slower, that many ticks older (none yet when there is no
/// such state) or, faster, newer (never past its own tick, unless the run's was, nor past the
/// neighbour's last state).
fn used_at(fliers: &[Flier], k: usize, tick: u64, slot: usize) -> Option<u64> {
    let f = &fliers[k];
    let t = f.rec.used.get(tick as usize)?[slot]?;
    match f.shift {
        0 => Some(t),
        d if d > 0 => t.checked_sub(d.unsigned_abs()),
        d => {
            let newest = (f.neighbors.and_then(|ins| fliers.get(ins[slot])))
                .map_or(t, |n| n.rec.used.len() as u64);
            let newer = t.saturating_add(d.unsigned_abs());
            Some(newer.min(tick.max(t)).min(newest.max(t)))
        }
    }
}

/// The audit instants, each from every member's newest state at or before it once every member
/// has a state at or after it (the monitor's rule), until the plan's last or the states end.
/// The states the run's monitor never received are never handed to it here either.
fn audit_all(
    s: &Scenario,
    timing: ReplayTiming,
    (fliers, history): (&[Flier], &History),
    audit: &mut Auditor,
    tel: &mut dyn TelemetrySink,
) -> Result<ReplayEnd, ReplayInputError> {
    let losses = &history.losses[..];
    let unheard = |id: u32, tick: u64| {
        (history.unheard.iter()).any(|u| u.id == id && (u.from..=u.to).contains(&tick))
    };
    let dt = s.dt_s();
    let hash = s.content_hash();
    let members: Vec<_> = (s.formation.members.iter())
        .map(|m| (m.id, m.start, m.role == Role::Follower))
        .collect();
    let history = (dt, timing.stale_after_s);
    let mut book = MonitorCore::new(&members, hash, history, timing.phase_seed);
    let last = timing
        .max_ticks
        .map_or(s.last_tick(), |k| k.min(s.last_tick()));
    let period_s = 1.0 / timing.audit_hz;
    let last_audit = (last as f64 * dt / period_s + 1e-9).floor() as u64;
    let mut rec = TickRecorder::new(s);
    let n = fliers.len();
    // Per member: the states handed to the monitor so far, and the newest it received.
    let mut pushed = vec![0usize; n];
    let mut heard: Vec<Option<usize>> = vec![None; n];
    let mut at = Vec::with_capacity(n);
    let mut audits = 0u64;
    let mut out = switches::Out::new(s, losses);
    let last_audit = timing
        .stopped_at
        .map_or(last_audit, |k| last_audit.min(k.saturating_sub(1)));
    let stopped = timing.stopped_at == Some(0);
    'instants: while audits <= last_audit && !stopped {
        let t_s = audits as f64 * period_s;
        out.hand(audits, audit);
        for (k, f) in fliers.iter().enumerate() {
            if out.is_out(k) {
                continue;
            }
            let stamp = |tick: usize| stamp_s(tick as u64, f.phase_s, dt);
            while heard[k].is_none_or(|h| stamp(h) < t_s) {
                let Some((x, _)) = f.states.get(pushed[k]) else {
                    break 'instants;
                };
                let tick = pushed[k] as u64;
                if !unheard(f.id, tick) {
                    book.on_state(&StateMsg::ok(tick, hash, f.id, *x));
                    heard[k] = Some(pushed[k]);
                }
                pushed[k] += 1;
            }
        }
        at.clear();
        at.extend((0..n).map(|k| book.state_at(k, t_s)));
        let member = |k: usize| (!out.is_out(k)).then(|| at[k]);
        if let Err(f) = rec.record_at(s, (audits, t_s), audit, tel, member) {
            audit.fault(f);
            break;
        }
        audits += 1;
    }
    // The monitor records every loss it found when the flight ends, audited or not.
    out.hand(u64::MAX, audit);
    let lost = |f: &&Flier| losses.iter().any(|l| l.id == f.id);
    Ok(ReplayEnd {
        audits,
        complete: timing.stopped_at.is_none() && audits > last_audit,
        ticks_flown: (fliers.iter().filter(|f| !lost(f)))
            .map(|f| f.next())
            .min()
            .unwrap_or(0),
    })
}

/// Member `k`'s in-neighbours at its own time of `tick`, from the states it flew on.
fn neighbors_of(fliers: &[Flier], k: usize, tick: u64, dt: f64) -> [Flat; 3] {
    let f = &fliers[k];
    let mut flats = f.initial;
    let Some(ins) = f.neighbors else {
        return flats;
    };
    let t_own = stamp_s(tick, f.phase_s, dt);
    for (slot, out) in flats.iter_mut().enumerate() {
        let (stamp, flat) = match (used_at(fliers, k, tick, slot), fliers.get(ins[slot])) {
            (Some(t), Some(n)) => (stamp_s(t, n.phase_s, dt), n.states[t as usize].1),
            _ => (0.0, f.initial[slot]),
        };
        *out = extrapolate_flat(&flat, t_own - stamp, NeighborModel::Taylor);
    }
    flats
}

fn control_fault(id: u32, tick: u64, e: VehicleFault) -> FaultRecord {
    let (kind, peer, message) = match e {
        VehicleFault::Step(f) => {
            let peer = match f {
                cdm_model::step::StepFault::NeighborNonFinite { peer } => Some(peer),
                _ => None,
            };
            (cdm_model::outcome::FaultKind::Control, peer, f.to_string())
        }
        VehicleFault::Link { what, .. } => (cdm_model::outcome::FaultKind::Control, None, what),
    };
    FaultRecord {
        kind,
        agent: Some(id),
        peer,
        tick,
        message: format!("agent {id} tick {tick}: {message}"),
    }
}

mod switches;
