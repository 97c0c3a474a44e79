//! `--telemetry mcap`: the bag written during the run from each tick's telemetry rows, the very
//! messages `export rosbag2` writes from the finished run's telemetry.

use std::collections::BTreeMap;
use std::io;
use std::path::Path;

use cdm_math::Vec3;
use cdm_records::audit::{CommandSummary, SafetyNumbers};
use cdm_records::telemetry::{Row, TelemetrySink};
use cdm_scenario::Scenario;

use crate::bag::{BagError, BagWriter};
use crate::tick::{Limits, Message, Team, Tick};

/// The bag of a run in progress, fed the same rows as its telemetry file.
pub struct BagSink {
    team: Team,
    bag: BagWriter,
    every: u64,
    index: BTreeMap<u32, usize>,
    /// The latest position of each member (a lost member keeps its last one, as when a
    /// finished run is read back).
    pos: Vec<Vec3>,
    ht: Vec<Vec3>,
    alive: Vec<bool>,
    messages: Vec<Message>,
    /// The last tick written (the commands since go out with the next).
    shown: Option<u64>,
}

impl BagSink {
    /// Start the bag in `dir` for a run of `scenario` keeping every `every`-th tick; the margins'
    /// limits are the audit's (`SafetyNumbers`, as audit.json records them).
    pub fn create(dir: &Path, scenario: &Scenario, every: u64) -> Result<Self, BagError> {
        Self::with_commands(dir, scenario, every, Vec::new())
    }

    /// [`BagSink::create`] for a commanded run: its commands on `/cdm/commands`.
    pub fn with_commands(
        dir: &Path,
        scenario: &Scenario,
        every: u64,
        commands: Vec<CommandSummary>,
    ) -> Result<Self, BagError> {
        let team =
            Team::new(scenario, Limits::from(&SafetyNumbers::of(scenario))).with_commands(commands);
        let bag = BagWriter::create(dir, &team)?;
        let n = team.ids().len();
        Ok(BagSink {
            index: team
                .ids()
                .iter()
                .enumerate()
                .map(|(k, &id)| (id, k))
                .collect(),
            team,
            bag,
            every: every.max(1),
            pos: vec![Vec3::zeros(); n],
            ht: vec![Vec3::zeros(); n],
            alive: vec![false; n],
            messages: Vec::new(),
            shown: None,
        })
    }
}

impl TelemetrySink for BagSink {
    fn keeps(&self, tick: u64) -> bool {
        tick.is_multiple_of(self.every)
    }

    fn write_tick(&mut self, rows: &[Row]) -> io::Result<()> {
        let Some(first) = rows.first() else {
            return Ok(());
        };
        if !self.keeps(first.tick) {
            return Ok(());
        }
        self.alive.iter_mut().for_each(|a| *a = false);
        for r in rows {
            let Some(&k) = self.index.get(&r.id) else {
                return Err(io::Error::other(format!(
                    "tick {}: agent {} is not in the scenario",
                    r.tick, r.id
                )));
            };
            self.pos[k] = r.r;
            self.ht[k] = r.ht;
            self.alive[k] = true;
        }
        let tick = Tick {
            tick: first.tick,
            t_s: first.t_s,
            pos: &self.pos,
            ht: &self.ht,
            alive: &self.alive,
        };
        self.messages.clear();
        self.team.messages(&tick, &mut self.messages);
        self.team
            .command_messages(self.shown, &tick, &mut self.messages);
        self.shown = Some(first.tick);
        for m in &self.messages {
            self.bag.write(m).map_err(io::Error::other)?;
        }
        // A full disk met during this tick: the tick is in the bag whole (the room kept for the
        // end took the rest), and the run stops here.
        match self.bag.full() {
            Some(e) => Err(io::Error::new(io::ErrorKind::StorageFull, e)),
            None => Ok(()),
        }
    }

    /// Nothing to force: chunks go to the file as they fill (1 MiB), and an MCAP file is read
    /// through its summary, written by `finish`; forcing a chunk out every flush (`launch`
    /// flushes every 100 ms) would only make the chunks, and the file's index, many and small.
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }

    fn finish(&mut self) -> io::Result<()> {
        self.bag.finish().map_err(io::Error::other)
    }
}
