//! Commands to a launched team: the orchestrator certifies each (the same code as `simulate`,
//! `cdm_certificates::command_certificate`), and announces each accepted one to every member
//! with its switch tick on the clock channel (`cdm_runtime::team_core`), where each member makes
//! the same new plan of it (`cdm_runtime::member_steer`).

use cdm_certificates::command_certificate::{apply_commands, CommandRecord};
use cdm_records::audit::CommandSummary;
use cdm_records::rundir::{RunDir, RunDirError};
use cdm_runtime::messages::SteerNotice;
use cdm_scenario::{Scenario, TimedCommand};

/// A file's commands, decided before the flight: what became of each, and the notices of the
/// accepted ones.
#[derive(Debug, Clone)]
pub struct FileCommands {
    pub records: Vec<CommandRecord>,
    pub notices: Vec<SteerNotice>,
}

impl FileCommands {
    /// `list` certified in order for the team of `s`: the scenario to audit (its plan the
    /// commanded one, the same before every switch) and the commands.
    pub fn decide(s: &Scenario, list: &[TimedCommand]) -> (Scenario, Self) {
        let (flown, records) = apply_commands(s, list);
        let notices = (list.iter().zip(&records))
            .filter(|(_, r)| r.accepted)
            .enumerate()
            .map(|(k, (c, r))| SteerNotice {
                seq: k as u32 + 1,
                tick: r.switch_tick,
                command: Some(c.command),
            })
            .collect();
        (flown, FileCommands { records, notices })
    }

    /// What audit.json lists.
    pub fn summaries(&self) -> Vec<CommandSummary> {
        self.records.iter().map(CommandRecord::summary).collect()
    }
}

/// Why commands.json could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteCommandsError {
    /// The records did not serialise.
    #[error("commands.json: {0}")]
    Json(#[from] serde_json::Error),
    /// The file could not be written.
    #[error(transparent)]
    Write(#[from] RunDirError),
}

/// The run's commands.json: every command and what became of it.
pub fn write_commands(dir: &RunDir, records: &[CommandRecord]) -> Result<(), WriteCommandsError> {
    let text = serde_json::to_string_pretty(records)?;
    let path = dir.path().join("commands.json");
    Ok(cdm_records::rundir::write_atomic(&path, text.as_bytes())?)
}
