//! Commands to a team in flight, as a file: a JSON list of objects with `at_s` (the simulation
//! time of the switch), `command` (`hold`, `resume`, `land`, `goto`), for `goto` the three
//! primary leaders' `goals` (ascending id order) and optionally `travel_s`. A run's
//! `commands.json` is that list with more fields (what became of each), and is read as it is.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{Scenario, ScenarioErrorKind as E};
use crate::fields::{coordinate, finite, positive, MIN_MOTION_TICKS};
use crate::mission::{primary_ids, primary_order};
use cdm_math::{vec3, Real};
use cdm_model::steer::{SteerSettings, Steering, TeamCommand};

/// The fields a run's `commands.json` adds to each command (ignored when read back).
const RECORD_FIELDS: [&str; 6] = [
    "arrived_s",
    "switch_tick",
    "verdict",
    "accepted",
    "why",
    "certificate",
];

/// One command as the file says it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandSpec {
    /// Simulation time of the switch, seconds (the first tick at or after it).
    pub at_s: Real,
    /// `hold`, `resume`, `land` or `goto`.
    pub command: String,
    /// `goto`: the primary leaders' new positions, ascending id order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goals: Option<Vec<[Real; 3]>>,
    /// `goto`: travel time, seconds (default: the plan's peak acceleration, `steer.rs`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub travel_s: Option<Real>,
}

/// One command checked against the scenario: its switch tick and its meaning.
#[derive(Debug, Clone, PartialEq)]
pub struct TimedCommand {
    pub spec: CommandSpec,
    pub switch_tick: u64,
    pub command: TeamCommand,
    /// When it arrived (simulation time), as a run's `commands.json` records a command given
    /// live (`orchestrator command`); `None`: at its switch, as a file's command.
    pub arrived_s: Option<Real>,
}

/// A command file that cannot be used; names the file, the command's index and its field.
#[derive(Debug, thiserror::Error)]
#[error("{origin}: {kind}")]
pub struct CommandsError {
    pub origin: String,
    pub kind: E,
}

/// Read and check a command file for `s`'s team.
pub fn load_commands(path: &Path, s: &Scenario) -> Result<Vec<TimedCommand>, CommandsError> {
    let origin = path.display().to_string();
    let err = |kind| CommandsError {
        origin: origin.clone(),
        kind,
    };
    let text = cdm_files::read_input(path, cdm_files::MAX_INPUT_BYTES)
        .map_err(|e| err(E::Io(e.reason())))?;
    parse_commands(&text, s).map_err(err)
}

/// Check a command file's text (see the module text).
pub fn parse_commands(text: &str, s: &Scenario) -> Result<Vec<TimedCommand>, E> {
    let items: Vec<serde_json::Map<String, serde_json::Value>> = serde_json::from_str(text)
        .map_err(|e| E::Parse(format!("a JSON list of commands: {e}")))?;
    let mut out: Vec<TimedCommand> = Vec::with_capacity(items.len());
    for (k, mut item) in items.into_iter().enumerate() {
        let arrived = item.get("arrived_s").cloned();
        item.retain(|key, _| !RECORD_FIELDS.contains(&key.as_str()));
        let spec: CommandSpec = serde_json::from_value(serde_json::Value::Object(item))
            .map_err(|e| E::Parse(format!("commands[{k}]: {e}")))?;
        let mut c = check_command(spec, s, &format!("commands[{k}]"))?;
        c.arrived_s = arrived_s(arrived, &c, k)?;
        if let Some(prev) = out.last() {
            if c.switch_tick <= prev.switch_tick {
                return Err(E::Invalid {
                    field: format!("commands[{k}].at_s"),
                    reason: format!(
                        "= {} s switches at tick {}, not after the command before it (tick {}): one command per switch, in time order",
                        c.spec.at_s, c.switch_tick, prev.switch_tick
                    ),
                });
            }
        }
        out.push(c);
    }
    Ok(out)
}

/// One command checked: its time, its name, its goals and travel time (`name` prefixes the
/// fields in errors).
pub fn check_command(spec: CommandSpec, s: &Scenario, name: &str) -> Result<TimedCommand, E> {
    let at_s = finite(format!("{name}.at_s"), spec.at_s)?;
    if at_s < 0.0 {
        return Err(E::Invalid {
            field: format!("{name}.at_s"),
            reason: format!("must be >= 0, got {at_s}"),
        });
    }
    let has_goals = spec.goals.is_some() || spec.travel_s.is_some();
    let command = match spec.command.as_str() {
        "hold" => TeamCommand::Hold,
        "resume" => TeamCommand::Resume,
        "land" => TeamCommand::Land,
        "goto" => goto(&spec, s, name)?,
        other => {
            return Err(E::Invalid {
                field: format!("{name}.command"),
                reason: format!("`{other}` is none of hold, resume, land, goto"),
            })
        }
    };
    if has_goals && !matches!(command, TeamCommand::Goto { .. }) {
        return Err(E::Invalid {
            field: format!("{name}.goals"),
            reason: format!("only goto takes goals and travel_s, not {}", spec.command),
        });
    }
    let switch_tick = (at_s * s.file.comm_hz - 1e-9).ceil().max(0.0) as u64;
    Ok(TimedCommand {
        spec,
        switch_tick,
        command,
        arrived_s: None,
    })
}

/// A recorded `arrived_s` (a run's `commands.json`): a number from 0 to the command's `at_s`.
fn arrived_s(v: Option<serde_json::Value>, c: &TimedCommand, k: usize) -> Result<Option<Real>, E> {
    let Some(v) = v else { return Ok(None) };
    let field = format!("commands[{k}].arrived_s");
    let a = v.as_f64().ok_or_else(|| E::Invalid {
        field: field.clone(),
        reason: format!("must be a number, got {v}"),
    })?;
    if !(0.0..=c.spec.at_s).contains(&a) {
        return Err(E::Invalid {
            field,
            reason: format!(
                "= {a} s must be from 0 to the command's at_s = {} s",
                c.spec.at_s
            ),
        });
    }
    Ok(Some(a))
}

fn goto(spec: &CommandSpec, s: &Scenario, name: &str) -> Result<TeamCommand, E> {
    let field = format!("{name}.goals");
    let goals = spec.goals.as_ref().ok_or_else(|| E::Invalid {
        field: field.clone(),
        reason: "goto needs the 3 primary leaders' goals (ascending id)".into(),
    })?;
    if goals.len() != 3 {
        return Err(E::Invalid {
            field,
            reason: format!(
                "must list the 3 primary leaders' positions (ascending id), got {}",
                goals.len()
            ),
        });
    }
    for (k, g) in goals.iter().enumerate() {
        for (c, v) in g.iter().enumerate() {
            coordinate(format!("{field}[{k}][{c}]"), *v)?;
        }
    }
    let travel_s = match spec.travel_s {
        None => None,
        Some(t) => {
            let t = positive(&format!("{name}.travel_s"), t)?;
            if t * s.file.comm_hz < MIN_MOTION_TICKS {
                return Err(E::Invalid {
                    field: format!("{name}.travel_s"),
                    reason: format!(
                        "= {t} s times comm_hz gives fewer than {MIN_MOTION_TICKS} ticks"
                    ),
                });
            }
            Some(t)
        }
    };
    let order = primary_order(&primary_ids(&s.file));
    Ok(TeamCommand::Goto {
        goals: std::array::from_fn(|k| vec3(goals[order[k]])),
        travel_s,
    })
}

impl Scenario {
    /// The steering of this scenario's team: its plan, ticks, and `[landing]` (z = 0 without).
    pub fn steering(&self) -> Steering {
        let landing = self.file.landing.as_ref();
        Steering::new(
            self.plan.clone(),
            SteerSettings {
                dt_s: self.dt_s(),
                min_travel_s: MIN_MOTION_TICKS / self.file.comm_hz,
                ground_z_m: landing.map_or(0.0, |l| l.ground_z_m),
                landing_t_s: landing.map(|l| l.t_s),
            },
        )
    }
}
