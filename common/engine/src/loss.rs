//! Losing members in flight, in-process: the scripted losses of `simulate --lose ID@SECONDS`,
//! the policy (`--on-loss repair|stop`) and the bookkeeping that turns "member k is lost after
//! its tick-L state" into a repaired engine and an audit record from tick L + 1.
//!
//! Timing: a member lost at SECONDS publishes its state of tick L, the first tick at or after
//! SECONDS; its readers still use that state for their tick-L step. From tick L + 1 the repair
//! applies (`repair`), and the body is out of the audit and telemetry.

use std::collections::BTreeSet;

use crate::engine::Engine;
use cdm_math::Real;
use cdm_model::dynamics::Plant;
use cdm_model::formation::Formation;
use cdm_model::graph::DEFAULT_WEIGHT_FLOOR;
use cdm_model::outcome::LossCause;
use cdm_model::repair::{repair, Repair, Retriangulation};
use cdm_model::step::tick_time;
use cdm_records::audit::{Auditor, LossRecord};
use cdm_scenario::Scenario;

/// What a loss does to the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OnLoss {
    /// Repair the graph and fly on (the default).
    #[default]
    Repair,
    /// A lost member is a fault: the run ends (exit 3), as before losses were survivable.
    Stop,
}

/// `--lose ID@SECONDS`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScriptedLoss {
    pub id: u32,
    pub at_s: Real,
}

/// A scripted loss that cannot happen.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LossError {
    #[error("--lose {text}: expected ID@SECONDS, e.g. 17@30.5")]
    Syntax { text: String },
    #[error("--lose {id}@{at_s}: no agent with id {id}")]
    UnknownAgent { id: u32, at_s: Real },
    #[error("--lose {id}@{at_s}: the time must be in [0, {end_s}) s: the flight's last tick is {last_tick} (t = {end_s} s)")]
    OutOfFlight {
        id: u32,
        at_s: Real,
        end_s: Real,
        last_tick: u64,
    },
    #[error("--lose {id}: given twice")]
    Twice { id: u32 },
    #[error("--lose names all {agents} agents of the team: nobody would be left to fly the plan")]
    Everyone { agents: usize },
}

impl std::str::FromStr for ScriptedLoss {
    type Err = LossError;

    fn from_str(text: &str) -> Result<Self, LossError> {
        let bad = || LossError::Syntax { text: text.into() };
        let (id, at) = text.split_once('@').ok_or_else(bad)?;
        let id = id.trim().parse::<u32>().map_err(|_| bad())?;
        let at_s = at.trim().parse::<Real>().map_err(|_| bad())?;
        Ok(ScriptedLoss { id, at_s })
    }
}

/// The losses of a run grouped by the tick their repair applies from, in tick order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LossSchedule {
    /// (tick L + 1, ids lost after publishing tick L), ids sorted.
    pub events: Vec<(u64, Vec<u32>)>,
}

impl LossSchedule {
    /// Validate scripted losses against a scenario flown to its last tick or to tick
    /// `max_ticks` (`--max-ticks`), whichever comes first: ids exist, times inside the flight
    /// (a loss after the last flown tick would never happen).
    pub fn new(
        s: &Scenario,
        losses: &[ScriptedLoss],
        max_ticks: Option<u64>,
    ) -> Result<Self, LossError> {
        let dt = s.dt_s();
        let last_tick = max_ticks.map_or(s.last_tick(), |k| k.min(s.last_tick()));
        let end_s = tick_time(last_tick, dt);
        let mut seen = BTreeSet::new();
        let mut events: Vec<(u64, Vec<u32>)> = Vec::new();
        for l in losses {
            if s.formation.member(l.id).is_none() {
                return Err(LossError::UnknownAgent {
                    id: l.id,
                    at_s: l.at_s,
                });
            }
            if !(l.at_s.is_finite() && l.at_s >= 0.0 && l.at_s < end_s) {
                return Err(LossError::OutOfFlight {
                    id: l.id,
                    at_s: l.at_s,
                    end_s,
                    last_tick,
                });
            }
            if !seen.insert(l.id) {
                return Err(LossError::Twice { id: l.id });
            }
            // The first tick at or after at_s (a hair of tolerance for at_s = k dt in decimal).
            let last = ((l.at_s / dt) - 1e-6).ceil().max(0.0) as u64;
            events.push((last + 1, vec![l.id]));
        }
        // A team with no member left has no formation to audit (simulate called it SAFE, the
        // processes stopped on "no state"): refused, the same in every mode.
        if seen.len() == s.formation.members.len() {
            return Err(LossError::Everyone { agents: seen.len() });
        }
        events.sort();
        let mut merged: Vec<(u64, Vec<u32>)> = Vec::new();
        for (tick, ids) in events {
            match merged.last_mut() {
                Some((t, v)) if *t == tick => v.extend(ids),
                _ => merged.push((tick, ids)),
            }
        }
        Ok(LossSchedule { events: merged })
    }

    /// A schedule of one loss after tick `last_tick` (the loss certificate's flights).
    pub fn single(id: u32, last_tick: u64) -> Self {
        LossSchedule {
            events: vec![(last_tick + 1, vec![id])],
        }
    }
}

/// Applies a schedule to a flight: call `due` at the start of every tick, before the audit.
pub struct LossState {
    schedule: LossSchedule,
    next: usize,
    floor: Real,
    current: Formation,
    lost: BTreeSet<u32>,
}

impl LossState {
    pub fn new(s: &Scenario, schedule: LossSchedule) -> Self {
        LossState {
            schedule,
            next: 0,
            floor: s.file.weight_floor.unwrap_or(DEFAULT_WEIGHT_FLOOR),
            current: s.formation.clone(),
            lost: BTreeSet::new(),
        }
    }

    /// The ids whose loss applies from `tick`, if any.
    pub fn due(&mut self, tick: u64) -> Option<Vec<u32>> {
        let (t, ids) = self.schedule.events.get(self.next)?;
        if *t != tick {
            return None;
        }
        self.next += 1;
        Some(ids.clone())
    }

    /// Lose `ids` from `tick` on: repair the graph for every member lost so far, switch the
    /// engine to it, and take the bodies out of the audit. Returns the repair.
    pub fn apply<P: Plant>(
        &mut self,
        s: &Scenario,
        tick: u64,
        ids: &[u32],
        engine: &mut Engine<P>,
        audit: &mut Auditor,
    ) -> Repair {
        let r = self.record(s, tick, ids, LossCause::Scripted, audit);
        engine.apply_repair(&r);
        r
    }

    /// Lose `ids` from `tick` on in the audit only (`launch`: the members repair themselves):
    /// repair the graph for every member lost so far and record why. Returns the repair.
    pub fn record(
        &mut self,
        s: &Scenario,
        tick: u64,
        ids: &[u32],
        cause: LossCause,
        audit: &mut Auditor,
    ) -> Repair {
        let at = LossAt {
            last_tick: tick.saturating_sub(1),
            tick,
            t_s: tick_time(tick, s.dt_s()),
            repair_tick: None,
        };
        self.record_at(s, at, ids, cause, audit)
    }

    /// [`Self::record`] for a loss found after the fact (real time: `at` says when).
    pub fn record_at(
        &mut self,
        s: &Scenario,
        at: LossAt,
        ids: &[u32],
        cause: LossCause,
        audit: &mut Auditor,
    ) -> Repair {
        let (r, records) = self.repair(s, at, ids, cause);
        for rec in records {
            audit.lose(rec);
        }
        r
    }

    /// Lose `ids`: the repair of the graph in force for every member lost so far, and the
    /// records the audit takes (`Auditor::lose`) once its body leaves (real time: at
    /// `at.tick`, which may come after a later loss's).
    pub fn repair(
        &mut self,
        s: &Scenario,
        at: LossAt,
        ids: &[u32],
        cause: LossCause,
    ) -> (Repair, Vec<LossRecord>) {
        self.lost.extend(ids.iter().copied());
        // Incremental: the graph in force is repaired, so only the readers of the members lost
        // now switch (a process that ran ahead never has to change a link it already flew).
        let r = repair(&self.current, self.floor, &self.lost);
        let out = records(s, (at, cause), ids, &self.current, &r);
        self.current = r.formation.clone();
        (r, out)
    }
}

/// When a loss happened, as the audit records it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossAt {
    /// The lost member's last state.
    pub last_tick: u64,
    /// The first tick (real time: audit instant) without its body in the audit and telemetry.
    pub tick: u64,
    /// That tick's (instant's) time.
    pub t_s: Real,
    /// Real time: the tick (the members' own) from which its readers fly the repair, a lead
    /// after the loss was found; `None` in lockstep, where it is `tick`.
    pub repair_tick: Option<u64>,
}

/// One record per id lost at `at`; a follower whose link changed is told under the lost
/// member it read (under the first id when it read none of them: a follower degraded because
/// it was left unreachable).
fn records(
    s: &Scenario,
    (at, cause): (LossAt, LossCause),
    ids: &[u32],
    before: &Formation,
    r: &Repair,
) -> Vec<LossRecord> {
    let mut out: Vec<LossRecord> = ids
        .iter()
        .map(|&id| LossRecord {
            id,
            role: s.role_of(id),
            cause,
            last_tick: at.last_tick,
            tick: at.tick,
            t_s: at.t_s,
            repair_tick: at.repair_tick,
            retriangulated: Vec::new(),
            degraded: Vec::new(),
            host: None,
        })
        .collect();
    for (m, old) in r.formation.members.iter().zip(&before.members) {
        if m.link == old.link || r.lost.contains(&m.id) {
            continue;
        }
        let old_nb = old.link.map(|l| l.in_neighbors);
        let slot = old_nb
            .and_then(|nb| ids.iter().position(|id| nb.contains(id)))
            .unwrap_or(0);
        match (old_nb, m.link) {
            (Some(old_nb), Some(new)) => out[slot].retriangulated.push(Retriangulation {
                id: m.id,
                old: old_nb,
                new: new.in_neighbors,
            }),
            (_, None) => out[slot].degraded.push(m.id),
            (None, Some(_)) => {}
        }
    }
    for rec in &mut out {
        rec.retriangulated.sort_by_key(|x| x.id);
        rec.degraded.sort_unstable();
    }
    out
}
