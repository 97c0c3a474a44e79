//! A finished run read back from its directory, to be flown again (`orchestrator replay`): the
//! scenario as flown (scenario.toml), how it was flown (run.json), its commands
//! (commands.json) and its losses as applied (audit.json). A lockstep run is deterministic, so
//! `simulate` with these gives the run's telemetry and safety figures byte for byte.
//!
//! Every file is checked against the others before anything flies: a file that does not belong
//! (another scenario's, edited by hand) is refused naming the file and its first bad record.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use cdm_certificates::command_certificate::{apply_commands, CommandRecord};
use cdm_engine::loss::LossSchedule;
use cdm_records::run_record::{RunMode, RunRecord, RunRecordError};
use cdm_scenario::{Checks, Scenario, ScenarioError};
use serde_json::Value;

/// audit.json is at most this large (a few hundred violations are about 60 KiB).
const MAX_AUDIT_BYTES: u64 = 16 << 20;

/// Why a run directory cannot be replayed; each names the file and, for a file that does not
/// belong to the run, its first bad record.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// scenario.toml cannot be read or is not a valid scenario.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// run.json is missing or invalid.
    #[error(transparent)]
    Record(#[from] RunRecordError),
    /// A file cannot be read, or one of its records is malformed or contradicts the others.
    #[error("{path}: {reason}")]
    File { path: PathBuf, reason: String },
    /// A real-time run: which neighbour state each member used was decided by the wall clock,
    /// and the run directory does not record it.
    #[error("{path}: a real-time run (`launch --realtime`): its replay needs a recording of the neighbour states each member used, which this run directory does not have")]
    Realtime { path: PathBuf },
    /// The replay of a real-time run: its history is the run's recordings.
    #[error("{path}: the replay of a real-time run: replay the run's own directory, which holds its recordings")]
    RealtimeReplay { path: PathBuf },
}

/// A run directory's inputs, checked against one another.
#[derive(Debug, Clone)]
pub struct RunInputs {
    pub dir: PathBuf,
    /// scenario.toml, validated as `simulate` validates a scenario file.
    pub scenario: Scenario,
    /// run.json.
    pub record: RunRecord,
    /// commands.json's text, when the run had commands.
    pub commands: Option<String>,
    /// The losses as the run applied them (audit.json; run.json's scripted ones with
    /// `--on-loss stop`, whose audit lists none).
    pub losses: LossSchedule,
}

impl RunInputs {
    /// Read and cross-check `dir`'s scenario.toml, run.json, audit.json and commands.json.
    pub fn read(dir: &Path) -> Result<Self, ReplayError> {
        let scenario = Scenario::load(&dir.join("scenario.toml"), Checks::Full)?;
        let record = RunRecord::read(dir)?;
        if record.mode == RunMode::RealtimeReplay {
            let path = dir.join(cdm_records::run_record::RUN_RECORD_FILE);
            return Err(ReplayError::RealtimeReplay { path });
        }
        let audit_path = dir.join("audit.json");
        let audit = read_json(&audit_path)?;
        if record.mode == RunMode::Realtime || audit.get("realtime").is_some() {
            return Err(ReplayError::Realtime { path: audit_path });
        }
        let hash = RunRecord::hash_text(scenario.content_hash());
        if record.scenario_hash != hash {
            return Err(file_error(
                &dir.join("run.json"),
                format!(
                    "scenario_hash {} but scenario.toml's is {hash} (a tampered or foreign file)",
                    record.scenario_hash
                ),
            ));
        }
        check_audit_header(&audit_path, &audit, &scenario)?;
        let losses = if record.stop_on_loss {
            scripted_losses(&dir.join("run.json"), &record, &scenario)?
        } else {
            applied_losses(&audit_path, &audit, &scenario)?
        };
        let commands_path = dir.join("commands.json");
        let commands = match commands_path.exists() {
            true => Some(read_text(&commands_path, cdm_files::MAX_INPUT_BYTES)?),
            false => None,
        };
        Ok(RunInputs {
            dir: dir.to_path_buf(),
            scenario,
            record,
            commands,
            losses,
        })
    }

    /// The losses, for a flight of `s` (the run's scenario, or a changed one): each inside the
    /// flight and of a member of the team.
    pub fn losses_for(
        &self,
        s: &Scenario,
        max_ticks: Option<u64>,
    ) -> Result<LossSchedule, ReplayError> {
        let last = max_ticks.map_or(s.last_tick(), |k| k.min(s.last_tick()));
        for (tick, ids) in &self.losses.events {
            if *tick > last {
                return Err(file_error(
                    &self.dir.join("audit.json"),
                    format!(
                        "the loss of {ids:?} after tick {} is past the end of the flight replayed (tick {last})",
                        tick - 1
                    ),
                ));
            }
        }
        Ok(self.losses.clone())
    }

    /// The run's commands applied to `s`: the plan to fly and what became of each. For the run's
    /// own scenario (`check`), each must come out as the run recorded it: a command file that
    /// does not is another run's, or edited.
    pub fn commands_for(
        &self,
        s: &Scenario,
        check: bool,
    ) -> Result<Option<(Scenario, Vec<CommandRecord>)>, ReplayError> {
        let Some(text) = &self.commands else {
            return Ok(None);
        };
        apply_run_commands(&self.dir.join("commands.json"), text, s, check).map(Some)
    }
}

/// A run directory's commands (commands.json, if any) applied to `s`, as
/// [`RunInputs::commands_for`] applies them: for a real-time run, whose other inputs its replay
/// reads itself.
pub fn commands_of(
    dir: &Path,
    s: &Scenario,
    check: bool,
) -> Result<Option<(Scenario, Vec<CommandRecord>)>, ReplayError> {
    let path = dir.join("commands.json");
    if !path.exists() {
        return Ok(None);
    }
    let text = read_text(&path, cdm_files::MAX_INPUT_BYTES)?;
    apply_run_commands(&path, &text, s, check).map(Some)
}

/// commands.json's `text` (at `path`) applied to `s`; `check`: each must come out as recorded.
fn apply_run_commands(
    path: &Path,
    text: &str,
    s: &Scenario,
    check: bool,
) -> Result<(Scenario, Vec<CommandRecord>), ReplayError> {
    let list = cdm_scenario::parse_commands(text, s)
        .map_err(|e| file_error(path, format!("{e} (a tampered or foreign file)")))?;
    let (flown, records) = apply_commands(s, &list);
    if check {
        check_commands(path, text, &records)?;
    }
    Ok((flown, records))
}

fn file_error(path: &Path, reason: String) -> ReplayError {
    ReplayError::File {
        path: path.to_path_buf(),
        reason,
    }
}

fn read_text(path: &Path, limit: u64) -> Result<String, ReplayError> {
    cdm_files::read_input(path, limit).map_err(|e| file_error(path, e.reason()))
}

fn read_json(path: &Path) -> Result<Value, ReplayError> {
    let text = read_text(path, MAX_AUDIT_BYTES)?;
    serde_json::from_str(&text).map_err(|e| file_error(path, format!("malformed JSON: {e}")))
}

/// The audit is of this scenario's team: its name, size and tick.
fn check_audit_header(path: &Path, audit: &Value, s: &Scenario) -> Result<(), ReplayError> {
    let foreign = |field: &str, found: &Value, expected: String| {
        file_error(
            path,
            format!(
                "{field} {found} but scenario.toml gives {expected} (a tampered or foreign file)"
            ),
        )
    };
    let name = audit.get("scenario").unwrap_or(&Value::Null);
    if name.as_str() != Some(s.file.name.as_str()) {
        return Err(foreign("scenario", name, format!("{:?}", s.file.name)));
    }
    let agents = audit.get("agents").unwrap_or(&Value::Null);
    if agents.as_u64() != Some(s.formation.members.len() as u64) {
        return Err(foreign(
            "agents",
            agents,
            s.formation.members.len().to_string(),
        ));
    }
    let dt = audit.get("dt_s").unwrap_or(&Value::Null);
    if dt.as_f64() != Some(s.dt_s()) {
        return Err(foreign("dt_s", dt, s.dt_s().to_string()));
    }
    Ok(())
}

/// audit.json's `losses` as a schedule: each of a member of the team, once, its repair from the
/// tick after its last state (lockstep), in tick order.
fn applied_losses(path: &Path, audit: &Value, s: &Scenario) -> Result<LossSchedule, ReplayError> {
    let Some(list) = audit.get("losses") else {
        return Ok(LossSchedule::default());
    };
    let items = list
        .as_array()
        .ok_or_else(|| file_error(path, "losses: expected a list".into()))?;
    let mut seen = BTreeSet::new();
    let mut events: Vec<(u64, Vec<u32>)> = Vec::new();
    for (k, l) in items.iter().enumerate() {
        let bad = |why: String| {
            file_error(
                path,
                format!("losses[{k}]: {why} (a tampered or foreign file)"),
            )
        };
        let field = |name: &str| l.get(name).and_then(Value::as_u64);
        let (Some(id), Some(last), Some(tick)) = (field("id"), field("last_tick"), field("tick"))
        else {
            return Err(bad("expected whole numbers id, last_tick and tick".into()));
        };
        let id = u32::try_from(id).map_err(|_| bad(format!("id {id} is not a member id")))?;
        if s.formation.member(id).is_none() {
            return Err(bad(format!("id {id}: no such member in scenario.toml")));
        }
        if tick != last + 1 || tick > s.last_tick() {
            return Err(bad(format!(
                "tick {tick} after last_tick {last}: a lockstep repair applies from the next tick, inside the flight (last tick {})",
                s.last_tick()
            )));
        }
        if !seen.insert(id) {
            return Err(bad(format!("member {id} is lost twice")));
        }
        match events.last_mut() {
            Some((t, ids)) if *t == tick => ids.push(id),
            Some((t, _)) if *t > tick => {
                return Err(bad(format!(
                    "tick {tick} before the loss listed before it (tick {t})"
                )))
            }
            _ => events.push((tick, vec![id])),
        }
    }
    if seen.len() >= s.formation.members.len() {
        return Err(file_error(path, "losses: every member is lost".into()));
    }
    for (_, ids) in &mut events {
        ids.sort_unstable();
    }
    Ok(LossSchedule { events })
}

/// run.json's scripted losses (`--on-loss stop`), checked against the team.
fn scripted_losses(path: &Path, r: &RunRecord, s: &Scenario) -> Result<LossSchedule, ReplayError> {
    for (k, (tick, ids)) in r.losses.iter().enumerate() {
        let bad = ids.iter().find(|&&id| s.formation.member(id).is_none());
        if *tick == 0 || *tick > s.last_tick() || ids.is_empty() || bad.is_some() {
            return Err(file_error(
                path,
                format!("losses[{k}]: ({tick}, {ids:?}) is not a loss of a member of scenario.toml's team inside its flight (a tampered or foreign file)"),
            ));
        }
    }
    Ok(LossSchedule {
        events: r.losses.clone(),
    })
}

/// Each command re-certified as commands.json recorded it (switch tick, verdict, accepted).
fn check_commands(path: &Path, text: &str, records: &[CommandRecord]) -> Result<(), ReplayError> {
    let recorded: Vec<Value> =
        serde_json::from_str(text).map_err(|e| file_error(path, format!("malformed JSON: {e}")))?;
    for (k, (was, now)) in recorded.iter().zip(records).enumerate() {
        let now = serde_json::to_value(now).unwrap_or(Value::Null);
        for field in ["switch_tick", "verdict", "accepted"] {
            let (a, b) = (was.get(field), now.get(field));
            if a != b {
                let shown = |v: Option<&Value>| v.map_or("nothing".to_string(), Value::to_string);
                return Err(file_error(
                    path,
                    format!(
                        "commands[{k}].{field}: recorded {} but the run's scenario gives {} (a tampered or foreign file)",
                        shown(a),
                        shown(b)
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The audit's safety figures: every field but the losses' cause and host and the pacing's
/// (a lockstep launch says why a member was lost; the replay only that it was).
pub fn safety_figures(audit: &Value) -> Value {
    let mut v = audit.clone();
    if let Some(o) = v.as_object_mut() {
        o.remove("realtime");
        o.remove("vehicles");
        if let Some(Value::Array(losses)) = o.get_mut("losses") {
            for l in losses.iter_mut().filter_map(Value::as_object_mut) {
                l.remove("cause");
                l.remove("host");
            }
        }
        // A fault's message says who noticed it (the engine or a process).
        if let Some(Value::Object(f)) = o.get_mut("fault") {
            f.remove("message");
        }
    }
    v
}

/// The first safety figure of audit.json that differs between two runs, `None` when all agree.
pub fn first_audit_difference(run: &Value, replay: &Value) -> Option<String> {
    let (fa, fb) = (safety_figures(run), safety_figures(replay));
    let (Some(a), Some(b)) = (fa.as_object(), fb.as_object()) else {
        return (fa != fb).then(|| "audit.json is not an object".into());
    };
    let keys: BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    let shown = |v: Option<&Value>| v.map_or("nothing".to_string(), Value::to_string);
    let first = keys
        .into_iter()
        .find(|k| a.get(*k) != b.get(*k))
        .map(|k| format!("{k}: run {} replay {}", shown(a.get(k)), shown(b.get(k))));
    first
}

/// The first line at which two telemetry texts differ (1-based), `None` when they are equal;
/// read as streams, a line at a time (a run's telemetry can be larger than memory).
pub fn first_line_difference(
    mut run: impl std::io::BufRead,
    mut replay: impl std::io::BufRead,
) -> std::io::Result<Option<usize>> {
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut line = 1;
    loop {
        a.clear();
        b.clear();
        let (n, m) = (
            run.read_until(b'\n', &mut a)?,
            replay.read_until(b'\n', &mut b)?,
        );
        if a != b {
            return Ok(Some(line));
        }
        if n == 0 && m == 0 {
            return Ok(None);
        }
        line += 1;
    }
}

/// Read audit.json for comparison.
pub fn read_audit(dir: &Path) -> Result<Value, ReplayError> {
    read_json(&dir.join("audit.json"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_difference_is_named() {
        let first = |a: &[u8], b: &[u8]| first_line_difference(a, b).unwrap();
        assert_eq!(first(b"a\nb\n", b"a\nb\n"), None);
        assert_eq!(first(b"a\nb\nc", b"a\nx\nc"), Some(2));
        assert_eq!(first(b"a\nb\n", b"a\nb\nc\n"), Some(3));
        assert_eq!(first(b"a\nb", b"a\nb\n"), Some(2));
        let run: Value = serde_json::json!({"verdict": "SAFE", "max_deviation_m": 0.25,
            "losses": [{"id": 3, "cause": "killed", "tick": 5}]});
        let mut replay = run.clone();
        replay["losses"][0]["cause"] = "scripted".into();
        assert_eq!(first_audit_difference(&run, &replay), None);
        replay["max_deviation_m"] = 0.5.into();
        assert_eq!(
            first_audit_difference(&run, &replay).as_deref(),
            Some("max_deviation_m: run 0.25 replay 0.5")
        );
    }
}
