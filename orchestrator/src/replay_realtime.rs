//! `orchestrator replay RUN_DIR --out DIR` of a real-time run (`launch --realtime`): the team
//! rebuilt in this process from the run directory (scenario.toml, run.json, audit.json's
//! real-time figures: phase seed, audit rate, stale bound; its losses as the monitor applied
//! them; commands.json) and the members' recordings (`recording/<id>.mcap`: the neighbour
//! states each tick flew on, and the ticks each repaired link and command was applied from),
//! flown again by cdm-runtime's `realtime_replay` and compared with the run. With `--gains`,
//! `--t-total`, `--scenario` (the same team) or `--link-delay-ms` the same history flies with
//! the change.
//!
//! Outcomes: exit 0/1 as the replay's verdict when it equals the run (or, with a change,
//! whatever it gives); 2 for a run directory or recording that does not belong (named, with its
//! first bad record); 3 when a recording is cut short (the replay flies up to where the
//! recordings end and says so) or when an unchanged replay differs from the run.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use cdm_certificates::command_certificate::CommandRecord;
use cdm_exit::{Exit, Failure};
use cdm_recording::Recording;
use cdm_records::audit::{Auditor, FaultRecord, Unheard};
use cdm_records::run_record::{RunMode, RunRecord};
use cdm_records::rundir::RunDir;
use cdm_runtime::realtime_replay::{
    replay, History, Recorded, ReplayEnd, ReplayLoss, ReplayTiming,
};
use cdm_scenario::{Checks, Scenario};
use cdm_simulate::realtime_losses::{loss_records, realtime_losses};
use cdm_simulate::replay::{commands_of, read_audit};

use crate::cli::ReplayArgs;

/// True when `dir` is a real-time run's directory (run.json says so).
pub fn is_realtime(dir: &Path) -> bool {
    RunRecord::read(dir).is_ok_and(|r| r.mode == RunMode::Realtime)
}

/// The replay of the real-time run `a.run`.
pub fn replay_realtime(a: &ReplayArgs, quiet: bool) -> Result<Exit, Failure> {
    let started = Instant::now();
    let run = &a.run;
    let s = Scenario::load(&run.join("scenario.toml"), Checks::Full).map_err(Failure::bad_input)?;
    let r = RunRecord::read(run).map_err(Failure::bad_input)?;
    let hash = s.content_hash();
    if r.scenario_hash != RunRecord::hash_text(hash) {
        return Err(Failure::bad_input(format!(
            "{}: scenario {}, but scenario.toml is {}",
            run.join("run.json").display(),
            r.scenario_hash,
            RunRecord::hash_text(hash)
        )));
    }
    let audit = read_audit(run).map_err(Failure::bad_input)?;
    let timing = timing_of(run, &audit, r.max_ticks)?;
    refuse_unsupported(a)?;
    let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
    let recordings = cdm_recording::read_dir(&run.join(cdm_recording::DIR), &ids, hash)
        .map_err(Failure::bad_input)?;
    let changed = crate::replay::changed(&s, a)?;
    let (flown, history, commanded) =
        history_of(run, (&s, changed), &audit, &recordings, a.what_if())?;
    let stop = run_fault(run, &audit)?;
    let timing = ReplayTiming {
        link_shift_ticks: link_shift_ticks(&s, &flown),
        stopped_at: stop.as_ref().map(|(_, at)| *at),
        ..timing
    };
    if crate::replay::same_dir(run, &a.out) {
        return Err(Failure::bad_input(format!(
            "--out {}: the run directory itself: the replay needs a directory of its own",
            a.out.display()
        )));
    }
    let format = r.telemetry_format().unwrap_or_default();
    cdm_team::telemetry::check_available(format).map_err(Failure::bad_input)?;
    let dir = RunDir::create(&a.out, a.force).map_err(Failure::from)?;
    dir.write_scenario(&flown).map_err(Failure::fault)?;
    RunRecord {
        mode: RunMode::RealtimeReplay,
        scenario_hash: RunRecord::hash_text(flown.content_hash()),
        ..r.clone()
    }
    .write(dir.path())
    .map_err(Failure::from)?;
    let mut tel =
        cdm_team::telemetry::open(&dir, format, r.every, &flown).map_err(Failure::bad_input)?;
    let mut auditor = Auditor::new(&flown);
    let end = replay(&flown, timing, &history, &mut auditor, tel.as_mut()).map_err(|e| {
        Failure::bad_input(format!("{}: {e}", run.join(cdm_recording::DIR).display()))
    })?;
    let end = match end {
        Ok(end) => Some(end),
        Err(fault) => {
            auditor.fault(fault);
            None
        }
    };
    // The run's monitor stopped the flight there: the same fault ends the replay.
    if let Some((f, _)) = stop.filter(|_| auditor.report().fault.is_none()) {
        auditor.fault(f);
    }
    let complete = end.is_some_and(|e| e.complete);
    tel.finish()
        .map_err(|e| Failure::fault(format!("{}: {e}", dir.path().display())))?;
    let report = write_audit(&dir, auditor.finish(complete), &commanded)?;
    crate::run_summary::summary("replay", &report, started, dir.path(), quiet);
    let cut: Vec<(u32, u64)> = (recordings.iter())
        .filter(|(_, rec)| rec.cut_short)
        .map(|(id, rec)| (*id, rec.used.len() as u64))
        .collect();
    if !cut.is_empty() {
        return Err(cut_short(run, &cut, end));
    }
    let differs = crate::replay::compare(run, dir.path(), format, quiet)?;
    crate::replay::outcome(a, a.what_if(), differs)?;
    Ok(crate::run_summary::exit_of(&report))
}

/// The replay's audit.json, with the run's commands as they were decided (the replay flies
/// their switches): listed as the run's audit lists them, and commands.json beside, as a
/// commanded launch writes them.
fn write_audit(
    dir: &RunDir,
    mut report: cdm_records::audit::AuditReport,
    commanded: &[CommandRecord],
) -> Result<cdm_records::audit::AuditReport, Failure> {
    if !commanded.is_empty() {
        report.commands = commanded.iter().map(|r| r.summary()).collect();
        cdm_launch::steer::write_commands(dir, commanded).map_err(Failure::fault)?;
    }
    dir.write_audit(&report).map_err(Failure::fault)?;
    Ok(report)
}

/// The fault the run's monitor stopped the flight on (audit.json's `fault`), if any, and the
/// audit instant it stopped at (`ticks`: the instants audited before it): the wall clock
/// decided when, so the replay stops there too.
fn run_fault(run: &Path, audit: &serde_json::Value) -> Result<Option<(FaultRecord, u64)>, Failure> {
    let Some(f) = audit.get("fault").filter(|f| !f.is_null()) else {
        return Ok(None);
    };
    let bad = |why: String| {
        Failure::bad_input(format!(
            "{}: {why} (a tampered or foreign file)",
            run.join("audit.json").display()
        ))
    };
    let fault = serde_json::from_value(f.clone()).map_err(|e| bad(format!("fault: {e}")))?;
    let at = (audit.get("ticks").and_then(serde_json::Value::as_u64))
        .ok_or_else(|| bad("ticks: expected a whole number".into()))?;
    Ok(Some((fault, at)))
}

/// What the replay flies (the changed scenario `changed`, its plan the commanded one when the
/// run had commands) and the run's history: the recordings, the losses (audit.json) and the
/// commands' switch ticks. `check`: the commands must come out as the run recorded them.
fn history_of(
    run: &Path,
    (s, changed): (&Scenario, Scenario),
    audit: &serde_json::Value,
    recordings: &BTreeMap<u32, Recording>,
    what_if: bool,
) -> Result<(Scenario, History, Vec<CommandRecord>), Failure> {
    let losses = realtime_losses(&run.join("audit.json"), audit, s).map_err(Failure::bad_input)?;
    let (flown, commanded) = (commands_of(run, &changed, !what_if).map_err(Failure::bad_input)?)
        .unwrap_or((changed, Vec::new()));
    let commands = (commanded.iter().filter(|r| r.accepted))
        .map(|r| r.switch_tick)
        .collect();
    let records = loss_records(&flown, &losses);
    let losses = (losses.iter().zip(records))
        .map(|(l, records)| ReplayLoss {
            id: l.id,
            repair_tick: l.repair_tick(),
            out_from: l.at.tick,
            records,
        })
        .collect();
    let recorded = (recordings.iter())
        .map(|(id, rec)| {
            let r = Recorded {
                used: rec.used.clone(),
                switches: rec.switches.clone(),
                whole: !rec.cut_short,
            };
            (*id, r)
        })
        .collect();
    let history = History {
        recorded,
        losses,
        commands,
        unheard: unheard_of(run, audit, s)?,
    };
    Ok((flown, history, commanded))
}

/// The states the run's monitor never received (audit.json's `realtime.unheard`; absent: none),
/// each of a member of the scenario.
fn unheard_of(
    run: &Path,
    audit: &serde_json::Value,
    s: &Scenario,
) -> Result<Vec<Unheard>, Failure> {
    let Some(v) = audit.get("realtime").and_then(|rt| rt.get("unheard")) else {
        return Ok(Vec::new());
    };
    let bad = |why: String| {
        Failure::bad_input(format!(
            "{}: realtime.unheard: {why} (a tampered or foreign file)",
            run.join("audit.json").display()
        ))
    };
    let list: Vec<Unheard> = serde_json::from_value(v.clone()).map_err(|e| bad(e.to_string()))?;
    if let Some(u) = (list.iter()).find(|u| u.from > u.to || s.formation.member(u.id).is_none()) {
        return Err(bad(format!(
            "agent {} ticks {}..={}: not a member's ticks",
            u.id, u.from, u.to
        )));
    }
    Ok(list)
}

/// The phase seed, audit rate and stale bound of the run (audit.json's `realtime`).
fn timing_of(
    run: &Path,
    audit: &serde_json::Value,
    max_ticks: Option<u64>,
) -> Result<ReplayTiming, Failure> {
    let path = run.join("audit.json");
    let rt = audit.get("realtime").ok_or_else(|| {
        Failure::bad_input(format!(
            "{}: no `realtime` figures: not a real-time run's audit",
            path.display()
        ))
    })?;
    let number = |k: &str| {
        rt.get(k)
            .and_then(serde_json::Value::as_f64)
            .ok_or_else(|| {
                Failure::bad_input(format!(
                    "{}: realtime.{k} is missing or not a number",
                    path.display()
                ))
            })
    };
    let (seed, audit_hz, stale_after_s) = (
        number("phase_seed")?,
        number("audit_hz")?,
        number("stale_after_s")?,
    );
    let good = seed >= 0.0
        && seed <= f64::from(u32::MAX)
        && seed.fract() == 0.0
        && audit_hz.is_finite()
        && audit_hz > 0.0
        && stale_after_s.is_finite()
        && stale_after_s > 0.0;
    if !good {
        return Err(Failure::bad_input(format!(
            "{}: realtime figures out of range (phase_seed {seed}, audit_hz {audit_hz}, stale_after_s {stale_after_s})",
            path.display()
        )));
    }
    Ok(ReplayTiming {
        phase_seed: seed as u32,
        audit_hz,
        stale_after_s,
        max_ticks,
        link_shift_ticks: 0,
        stopped_at: None,
    })
}

/// What this replay cannot fly: other jitter, loss or draws (the recording is what the links
/// delivered; only their delay can be changed, as a shift of every state flown on).
fn refuse_unsupported(a: &ReplayArgs) -> Result<(), Failure> {
    let l = &a.link;
    if l.link_jitter_ms.is_some() || l.link_loss.is_some() || l.seed.is_some() {
        return Err(Failure::bad_input(
            "--link-jitter-ms/--link-loss/--seed: a real-time run's recording is what its links delivered; of its links only --link-delay-ms can change in a replay",
        ));
    }
    Ok(())
}

/// The what-if's link delay over the run's, in whole ticks (as the links round it).
fn link_shift_ticks(run: &Scenario, flown: &Scenario) -> i64 {
    let ms = flown.link_model().spec().delay_ms - run.link_model().spec().delay_ms;
    (ms / 1e3 / run.dt_s()).round() as i64
}

/// A recording cut short: what was replayed, and which recordings end early.
fn cut_short(run: &Path, cut: &[(u32, u64)], end: Option<ReplayEnd>) -> Failure {
    let shown: Vec<String> = cut
        .iter()
        .map(|(id, ticks)| format!("agent {id} after {ticks} ticks"))
        .collect();
    let upto = end.map_or(String::new(), |e| {
        format!(
            ": replayed {} audit instants, up to where the recordings end (tick {})",
            e.audits, e.ticks_flown
        )
    });
    Failure::fault(format!(
        "{}: the recording is cut short ({}){upto}",
        run.join(cdm_recording::DIR).display(),
        shown.join(", ")
    ))
}
