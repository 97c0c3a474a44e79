//! `simulate`: fly a scenario with the in-process engine into a run directory, audited tick by
//! tick, with scripted losses.
//!
//! Layer 7, the top of the shared crates below the processes (see `cdm-model`'s docs): the
//! engine, the records and the scenario together. The pre-flight certificate of `plan` is
//! `cdm_certificates::certificate`.

pub mod realtime_losses;
pub mod replay;

use cdm_engine::engine::{quad_engine, AgentFault};
use cdm_engine::loss::{LossSchedule, LossState, OnLoss};
use cdm_model::outcome::FaultKind;
use cdm_records::audit::{AuditReport, Auditor, CommandSummary, FaultRecord};
use cdm_records::record::{write_fault, TickRecorder};
use cdm_records::rundir::{RunDir, RunDirError};
use cdm_records::telemetry::{TelemetryFormat, TelemetrySink};
use cdm_scenario::Scenario;

/// How `simulate` runs.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SimulateOptions {
    /// Write every K-th tick to telemetry.csv.
    pub every: u64,
    /// End the run at the tick of its first safety violation (telemetry kept, verdict UNSAFE).
    pub stop_on_violation: bool,
    /// Fly only ticks 0..=K of the plan.
    pub max_ticks: Option<u64>,
    /// The format `tel` writes (names the file in errors).
    pub telemetry: TelemetryFormat,
    /// Members lost in flight (`--lose`), validated against the scenario.
    pub losses: LossSchedule,
    /// What a loss does (`--on-loss`).
    pub on_loss: OnLoss,
    /// Commands to the team in flight (`--commands`), already applied to the plan flown:
    /// audit.json lists them.
    pub commands: Vec<CommandSummary>,
}

/// Fly `s` in-process, streaming telemetry (every `every` ticks) and auditing every tick.
/// `on_tick` sees each tick and the audit so far (for progress). A control fault ends the run
/// with the fault recorded; every complete tick stays in telemetry.csv. Scripted losses repair
/// the graph (or end the run as a fault with `OnLoss::Stop`); a lost member's rows leave
/// telemetry from the tick its loss applies.
/// `tel` is the run's telemetry file (`RunDir::telemetry` for CSV), opened with `opts.every`.
pub fn simulate(
    s: &Scenario,
    dir: &RunDir,
    opts: SimulateOptions,
    tel: &mut dyn TelemetrySink,
    mut on_tick: impl FnMut(u64, &Auditor),
) -> Result<AuditReport, RunDirError> {
    dir.write_scenario(s)?;
    let mut audit = Auditor::new(s);
    let mut e = quad_engine(s);
    let mut losses = LossState::new(s, opts.losses.clone());
    let mut rec = TickRecorder::new(s);
    let last = opts
        .max_ticks
        .map_or(s.last_tick(), |k| k.min(s.last_tick()));
    let complete = loop {
        let tick = e.tick();
        if let Some(ids) = losses.due(tick) {
            if opts.on_loss == OnLoss::Stop {
                audit.fault(lost_fault(tick, &ids));
                break false;
            }
            losses.apply(s, tick, &ids, &mut e, &mut audit);
        }
        let member = |k: usize| {
            let q = &e.states()[k];
            e.alive()[k].then(|| (q.position(), q.velocity()))
        };
        if let Err(f) = rec.record(s, tick, &mut audit, tel, member) {
            audit.fault(f);
            break false;
        }
        on_tick(tick, &audit);
        if opts.stop_on_violation && audit.violation_count() > 0 {
            audit.stop_on_violation();
            break tick >= last;
        }
        if tick >= last {
            break true;
        }
        if let Err(f) = e.advance() {
            audit.fault(control_fault(&f));
            break false;
        }
    };
    let complete = match tel.finish() {
        Ok(()) => complete,
        Err(e) => {
            let tick = audit.report().ticks;
            audit.fault(write_fault(tick, &e));
            false
        }
    };
    let mut report = audit.finish(complete);
    report.commands = opts.commands;
    dir.write_audit(&report)?;
    Ok(report)
}

fn control_fault(f: &AgentFault) -> FaultRecord {
    FaultRecord {
        kind: FaultKind::Control,
        agent: Some(f.id),
        peer: match f.fault {
            cdm_model::step::StepFault::NeighborNonFinite { peer } => Some(peer),
            _ => None,
        },
        tick: f.tick,
        message: f.to_string(),
    }
}

/// `--on-loss stop`: a lost member is a fault, as when losses were not survivable.
fn lost_fault(tick: u64, ids: &[u32]) -> FaultRecord {
    FaultRecord {
        kind: FaultKind::Lost,
        agent: ids.first().copied(),
        peer: None,
        tick,
        message: format!(
            "agent(s) {ids:?} lost after tick {} (--on-loss stop)",
            tick.saturating_sub(1)
        ),
    }
}
