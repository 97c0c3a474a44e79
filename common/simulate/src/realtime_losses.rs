//! A real-time run's losses as its monitor applied them (audit.json's `losses`), read back for
//! `replay`: each member lost, why, the newest tick the monitor heard of it, the audit instant
//! its body left the audit from (`tick`, `t_s`) and the tick its readers' repaired link applies
//! from (`repair_tick`). The audit's records of them are computed again the way the monitor
//! computed them (`LossState::repair`, in the order the losses were found: ascending repair
//! ticks, one loss per tick), so a changed scenario ("what if") gets its own.

use std::collections::BTreeSet;
use std::path::Path;

use cdm_engine::loss::{LossAt, LossSchedule, LossState};
use cdm_model::outcome::LossCause;
use cdm_records::audit::LossRecord;
use cdm_scenario::Scenario;
use serde_json::Value;

use crate::replay::ReplayError;

/// One loss of a real-time run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RealtimeLoss {
    pub id: u32,
    pub cause: LossCause,
    /// When: its last tick heard, the audit instant (`at.tick`) and time its body left from,
    /// and its readers' repair tick (always `Some`).
    pub at: LossAt,
}

impl RealtimeLoss {
    /// The tick its readers' repaired link applies from.
    pub fn repair_tick(&self) -> u64 {
        self.at.repair_tick.unwrap_or(self.at.tick)
    }
}

/// audit.json's (at `path`) `losses` of a real-time run of `s`, in the order they were found.
pub fn realtime_losses(
    path: &Path,
    audit: &Value,
    s: &Scenario,
) -> Result<Vec<RealtimeLoss>, ReplayError> {
    let Some(list) = audit.get("losses") else {
        return Ok(Vec::new());
    };
    let bad = |why: String| ReplayError::File {
        path: path.to_path_buf(),
        reason: format!("{why} (a tampered or foreign file)"),
    };
    let items = list
        .as_array()
        .ok_or_else(|| bad("losses: expected a list".into()))?;
    let mut seen = BTreeSet::new();
    let mut out = Vec::with_capacity(items.len());
    for (k, l) in items.iter().enumerate() {
        let loss = one_loss(l, s).map_err(|why| bad(format!("losses[{k}]: {why}")))?;
        if !seen.insert(loss.id) {
            return Err(bad(format!(
                "losses[{k}]: member {} is lost twice",
                loss.id
            )));
        }
        out.push(loss);
    }
    if !out.is_empty() && seen.len() >= s.formation.members.len() {
        return Err(bad("losses: every member is lost".into()));
    }
    out.sort_by_key(RealtimeLoss::repair_tick);
    if let Some(w) = out
        .windows(2)
        .find(|w| w[0].repair_tick() == w[1].repair_tick())
    {
        return Err(bad(format!(
            "losses: members {} and {} repaired from the same tick {} (the monitor gives each loss a tick of its own)",
            w[0].id,
            w[1].id,
            w[0].repair_tick()
        )));
    }
    Ok(out)
}

/// What is wrong with one of audit.json's losses.
#[derive(Debug, thiserror::Error)]
enum BadLoss {
    #[error("{0}: expected a whole number")]
    NotWhole(&'static str),
    #[error("id {0} is not a member id")]
    NotAnId(u64),
    #[error("id {0}: no such member in scenario.toml")]
    NoMember(u32),
    #[error("cause {0} is not a cause of a loss")]
    Cause(Value),
    #[error("t_s: expected a time")]
    Time,
}

fn one_loss(l: &Value, s: &Scenario) -> Result<RealtimeLoss, BadLoss> {
    let whole = |name: &'static str| {
        l.get(name)
            .and_then(Value::as_u64)
            .ok_or(BadLoss::NotWhole(name))
    };
    let id = whole("id")?;
    let id = u32::try_from(id).map_err(|_| BadLoss::NotAnId(id))?;
    if s.formation.member(id).is_none() {
        return Err(BadLoss::NoMember(id));
    }
    let cause = l.get("cause").cloned().unwrap_or_default();
    let cause: LossCause =
        serde_json::from_value(cause.clone()).map_err(|_| BadLoss::Cause(cause))?;
    let t_s = (l.get("t_s").and_then(Value::as_f64))
        .filter(|t| t.is_finite() && *t >= 0.0)
        .ok_or(BadLoss::Time)?;
    Ok(RealtimeLoss {
        id,
        cause,
        at: LossAt {
            last_tick: whole("last_tick")?,
            tick: whole("tick")?,
            t_s,
            repair_tick: Some(whole("repair_tick")?),
        },
    })
}

/// The audit's records of `losses` (in the order found) for a flight of `s`, as the monitor
/// computed them: each repair of the graph the one before left.
pub fn loss_records(s: &Scenario, losses: &[RealtimeLoss]) -> Vec<Vec<LossRecord>> {
    let mut state = LossState::new(s, LossSchedule::default());
    losses
        .iter()
        .map(|l| state.repair(s, l.at, &[l.id], l.cause).1)
        .collect()
}
