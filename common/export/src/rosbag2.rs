//! `orchestrator export rosbag2 RUN_DIR --out DIR`: a finished run as a ROS 2 bag (crate
//! cdm-rosbag). The run is read back by cdm-report's reader (scenario.toml, audit.json, and
//! telemetry.csv or telemetry.parquet, one tick in memory at a time), each tick becomes the
//! bag's messages, and the limits of the margins are audit.json's. A run directory that cannot
//! be read is bad input (naming the file); the partial bag is removed.

use std::path::{Path, PathBuf};

use cdm_report::data::{read_audit, stream_ticks, AuditNumbers};
use cdm_rosbag::{BagError, BagWriter, Limits, Team, Tick};
use cdm_scenario::{Checks, Scenario};

use crate::{refuse_existing, ExportError};

/// What [`export_bag`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct BagExport {
    pub out: PathBuf,
    /// Messages per topic, in the bag's topic order.
    pub counts: Vec<(String, u64)>,
}

/// Write the bag of the run in `run` into `out` (absent, empty, or replaced with `force`).
pub fn export_bag(run: &Path, out: &Path, force: bool) -> Result<BagExport, ExportError> {
    refuse_existing(out, force)?;
    let (scenario, audit) = read_head(run)?;
    let limits = Limits {
        eps_m: audit.eps_m,
        delta_m: audit.delta_m,
        lambda_cd_min: audit.lambda_cd_min,
    };
    let commands = cdm_records::commands::read_commands(run)?;
    let team = Team::new(&scenario, limits).with_commands(commands);
    let mut shown = None;
    let mut bag = BagWriter::create(out, &team).map_err(ExportError::BagCreate)?;
    let mut messages = Vec::new();
    let mut failed: Option<BagError> = None;
    let read = stream_ticks(run, &scenario, &audit.losses, |tp| {
        if failed.is_some() {
            return;
        }
        let tick = Tick {
            tick: tp.tick,
            t_s: tp.t_s,
            pos: tp.pos,
            ht: tp.ht,
            alive: tp.alive,
        };
        messages.clear();
        team.messages(&tick, &mut messages);
        team.command_messages(shown, &tick, &mut messages);
        shown = Some(tp.tick);
        failed = messages.iter().find_map(|m| bag.write(m).err());
    });
    if let Err(e) = read {
        bag.abandon();
        return Err(e.into());
    }
    if let Some(e) = failed {
        bag.abandon();
        return Err(ExportError::Bag(e));
    }
    bag.finish().map_err(ExportError::Bag)?;
    Ok(BagExport {
        out: out.to_path_buf(),
        counts: bag
            .counts()
            .into_iter()
            .map(|(name, n)| (name.to_string(), n))
            .collect(),
    })
}

/// scenario.toml and audit.json of a run directory, each error naming its file.
fn read_head(run: &Path) -> Result<(Scenario, AuditNumbers), ExportError> {
    if !run.is_dir() {
        return Err(ExportError::NotARun {
            path: run.to_path_buf(),
        });
    }
    let scenario = Scenario::load(&run.join("scenario.toml"), Checks::Member)?;
    let audit = read_audit(&run.join("audit.json"))?;
    // A commanded run flew its commanded plan: its commands.json, read as the command file it
    // is, gives that plan again (deterministic), so the margins (lambda_1 of the plan) are the
    // ones the run's own bag carries.
    let commands = run.join(cdm_records::commands::COMMANDS_FILE);
    if commands.is_file() {
        let list = cdm_scenario::load_commands(&commands, &scenario)?;
        let (flown, _) = cdm_certificates::command_certificate::apply_commands(&scenario, &list);
        return Ok((flown, audit));
    }
    Ok((scenario, audit))
}
