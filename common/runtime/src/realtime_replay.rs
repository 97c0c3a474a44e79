//! A real-time flight flown again in one process from what the wall clock decided
//! (`realtime_journal.rs`): every member's tick k is `step::step_at` at its own time
//! `k dt + phi_i`, on the in-neighbour states it flew on in the run (their ticks recorded),
//! brought to its time by the same cubic Taylor model (`step::extrapolate_flat`); the monitor's
//! audit instants are taken by the same [`MonitorCore`] from the same states. Nothing here
//! reads a clock: the same journals give the same telemetry, byte for byte, and other gains
//! ("what if") fly the same history with the change.
//!
//! Members fly in rounds: round k publishes every member's state of tick k, audits the
//! instants every member has then been heard at (as the monitor waits for them), and flies
//! every member's tick k. A state flown on at tick k is of a tick t <= k (it was stamped at or
//! before the reader's own time, and phases are under one period), so it is there.

use std::collections::BTreeMap;

use cdm_math::Vec3;
use cdm_model::dynamics::{Flat, QuadState};
use cdm_model::formation::{Member, Role};
use cdm_model::step::{extrapolate_flat, law_for, Law, NeighborModel, TickAt};
use cdm_records::audit::{Auditor, FaultRecord};
use cdm_records::record::TickRecorder;
use cdm_records::telemetry::TelemetrySink;
use cdm_scenario::Scenario;

use crate::member_core::in_neighbors;
use crate::messages::StateMsg;
use crate::realtime::{phase_offset_s, stamp_s};
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
    /// A tick flew on a state it could not have had: one of a later tick.
    #[error("agent {id} tick {tick}: flew on agent {peer}'s state of tick {used}, which is later")]
    FromTheFuture {
        id: u32,
        tick: u64,
        peer: u32,
        used: u64,
    },
}

/// How far a replay got.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReplayEnd {
    /// Audit instants recorded.
    pub audits: u64,
    /// Every audit instant of the run's plan was recorded.
    pub complete: bool,
    /// The fewest ticks any member's journal has (where a recording cut short ends).
    pub ticks_recorded: u64,
}

/// One member as the replay flies it.
struct Flier<'a> {
    member: Member,
    vehicle: ModelVehicle<'a>,
    phase_s: f64,
    /// Formation indices of the in-neighbours (followers only), in the order of the law.
    neighbors: Option<[usize; 3]>,
    /// The in-neighbours at rest where they start: their state before their first.
    initial: [Flat; 3],
    used: &'a [[Option<u64>; 3]],
    /// The flat outputs of every tick flown so far (tick k's before tick k is flown).
    flats: Vec<Flat>,
    state: [f64; 12],
}

/// Flies `s` again on `journals` (per member id, the neighbour ticks of each tick flown, from
/// tick 0), recording the audit instants into `audit` and `tel` as the run's monitor did. A
/// journal cut short ends the replay at the last instant every member's states cover.
pub fn replay(
    s: &Scenario,
    timing: ReplayTiming,
    journals: &BTreeMap<u32, Vec<[Option<u64>; 3]>>,
    audit: &mut Auditor,
    tel: &mut dyn TelemetrySink,
) -> Result<Result<ReplayEnd, FaultRecord>, ReplayInputError> {
    if let Some(id) = journals
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
        let used = journals
            .get(&m.id)
            .ok_or(ReplayInputError::Missing { id: m.id })?;
        let (law, ins) = law_for(m);
        let follower = matches!(law, Law::Follower { .. });
        let neighbors = follower.then(|| ins.map(|j| index_of(j).unwrap_or(usize::MAX)));
        let mut initial = [Flat::rest(Vec3::zeros()); 3];
        if follower {
            for (f, j) in initial.iter_mut().zip(ins) {
                if let Some(n) = s.formation.member(j) {
                    *f = Flat::rest(n.position);
                }
            }
        }
        let vehicle = ModelVehicle::new(cfg, &s.plan, m);
        let state = vehicle.state();
        fliers.push(Flier {
            member: m.clone(),
            vehicle,
            phase_s: phase_offset_s(timing.phase_seed, m.id, dt),
            neighbors,
            initial,
            used,
            flats: Vec::with_capacity(used.len() + 1),
            state,
        });
    }
    check_causal(&fliers)?;
    Ok(fly(s, timing, &mut fliers, audit, tel))
}

/// Every recorded state flown on is of a tick no later than the reader's.
fn check_causal(fliers: &[Flier]) -> Result<(), ReplayInputError> {
    for f in fliers {
        let ins = in_neighbors(&f.member);
        for (tick, used) in f.used.iter().enumerate() {
            for (slot, u) in used.iter().enumerate() {
                if let Some(t) = *u {
                    if t > tick as u64 || f.neighbors.is_none() {
                        return Err(ReplayInputError::FromTheFuture {
                            id: f.member.id,
                            tick: tick as u64,
                            peer: ins[slot],
                            used: t,
                        });
                    }
                }
            }
        }
    }
    Ok(())
}

/// The rounds (see the module doc).
fn fly(
    s: &Scenario,
    timing: ReplayTiming,
    fliers: &mut [Flier],
    audit: &mut Auditor,
    tel: &mut dyn TelemetrySink,
) -> Result<ReplayEnd, FaultRecord> {
    let dt = s.dt_s();
    let hash = s.content_hash();
    let members: Vec<_> = (s.formation.members.iter())
        .map(|m| (m.id, m.start, m.role == Role::Follower))
        .collect();
    let mut book = MonitorCore::new(
        &members,
        hash,
        (dt, timing.stale_after_s),
        timing.phase_seed,
    );
    let last = timing
        .max_ticks
        .map_or(s.last_tick(), |k| k.min(s.last_tick()));
    let period_s = 1.0 / timing.audit_hz;
    let last_audit = (last as f64 * dt / period_s + 1e-9).floor() as u64;
    let ticks_recorded = fliers
        .iter()
        .map(|f| f.used.len() as u64)
        .min()
        .unwrap_or(0);
    let mut rec = TickRecorder::new(s);
    let mut audits = 0u64;
    let n = fliers.len();
    let mut at = Vec::with_capacity(n);
    for tick in 0..=ticks_recorded {
        for f in fliers.iter_mut() {
            f.flats.push(QuadState(f.state).flat());
            book.on_state(&StateMsg::ok(tick, hash, f.member.id, f.state));
        }
        while audits <= last_audit && audits as f64 * period_s <= book.heard_until() {
            let t_s = audits as f64 * period_s;
            at.clear();
            at.extend((0..n).map(|k| book.state_at(k, t_s)));
            rec.record_at(s, (audits, t_s), audit, tel, |k| Some(at[k]))?;
            audits += 1;
        }
        if audits > last_audit || tick == ticks_recorded {
            break;
        }
        for k in 0..n {
            let flats = neighbors_of(fliers, k, tick, dt, timing.phase_seed);
            let f = &mut fliers[k];
            let at = TickAt {
                tick,
                offset_s: f.phase_s,
            };
            if let Err(e) = f.vehicle.fly_tick_at(at, &flats) {
                return Err(control_fault(f.member.id, tick, e));
            }
            f.state = f.vehicle.state();
        }
    }
    Ok(ReplayEnd {
        audits,
        complete: audits > last_audit,
        ticks_recorded,
    })
}

/// Member `k`'s in-neighbours at its own time of `tick`, from the states it flew on.
fn neighbors_of(fliers: &[Flier], k: usize, tick: u64, dt: f64, seed: u32) -> [Flat; 3] {
    let f = &fliers[k];
    let mut flats = f.initial;
    let Some(ins) = f.neighbors else {
        return flats;
    };
    let t_own = stamp_s(tick, f.phase_s, dt);
    for (slot, out) in flats.iter_mut().enumerate() {
        let (stamp, flat) = match (f.used[tick as usize][slot], fliers.get(ins[slot])) {
            (Some(t), Some(n)) => {
                let phase = phase_offset_s(seed, n.member.id, dt);
                (stamp_s(t, phase, dt), n.flats[t as usize])
            }
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
