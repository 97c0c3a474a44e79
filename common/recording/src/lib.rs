//! A real-time member's recording (`recording/<id>.mcap` in the run directory): for every tick
//! it flew, which state of each in-neighbour it flew on (`cdm_runtime::realtime_journal`), the
//! only part of a real-time flight the wall clock decided. MCAP (the maintained `mcap` crate)
//! with JSON messages, so `mcap cat`, Foxglove or Python's `mcap` package read it without us;
//! written as the member flies, without chunks, so a file cut short by a crash or a full disk
//! still holds every message written before ([`read`] says where it ends).
//!
//! Two channels:
//! - `/cdm/recording/member`, one message first: the format, the member, the scenario's hash
//!   and the period.
//! - `/cdm/recording/ages`, one message per second of flight: `tick` (the first tick of the
//!   batch), `ticks` (how many), and `age`: for each tick and each of the three in-neighbour
//!   slots (in the order of the law's weights), the tick flown minus the tick of the state it
//!   flew on (negative when the member flew late, on a state stamped after its own time), or
//!   null when it had none yet; empty for a leader.
//! - `/cdm/recording/switch`, one message per switch the member applied, written as it applies
//!   it: `tick` (the first tick flown after it) and `switch`, either `{"repair": {"at": T,
//!   "in_neighbors": [i, j, k] or null}}` (the repaired link the loss notices give from their
//!   tick T) or `{"command": {"seq": S, "at": T}}` (command notice S, switching at tick T).

mod reader;
mod writer;

pub use reader::{read, read_dir, Recording, RecordingError};
pub use writer::{McapJournal, WriterError};

/// The recording format, in each file's first message.
pub const FORMAT: &str = "cdm-recording/1";
/// The run directory's folder of recordings.
pub const DIR: &str = "recording";
/// The channel of the member's header.
pub const MEMBER_TOPIC: &str = "/cdm/recording/member";
/// The channel of the flown ticks' neighbour ages.
pub const AGES_TOPIC: &str = "/cdm/recording/ages";
/// The channel of the switches applied.
pub const SWITCH_TOPIC: &str = "/cdm/recording/switch";

/// The file of member `id`'s recording in a recording folder.
pub fn file_name(id: u32) -> String {
    format!("{id}.mcap")
}

/// The first message: whose recording this is.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Header {
    pub format: String,
    pub member: u32,
    /// The scenario's content hash, 16 hexadecimal digits (as run.json writes it).
    pub scenario_hash: String,
    pub dt_s: f64,
}

/// One batch of flown ticks.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Ages {
    member: u32,
    tick: u64,
    ticks: u64,
    age: Vec<Option<i64>>,
}

/// One switch applied.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct SwitchMsg {
    member: u32,
    tick: u64,
    switch: SwitchWhat,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
enum SwitchWhat {
    Repair {
        at: u64,
        in_neighbors: Option<[u32; 3]>,
    },
    Command {
        seq: u32,
        at: u64,
    },
}

impl SwitchMsg {
    fn of(member: u32, s: &cdm_runtime::realtime_journal::Switch) -> Self {
        use cdm_runtime::realtime_journal::Switched;
        let switch = match s.what {
            Switched::Repair { at, in_neighbors } => SwitchWhat::Repair { at, in_neighbors },
            Switched::Command { seq, at } => SwitchWhat::Command { seq, at },
        };
        SwitchMsg {
            member,
            tick: s.tick,
            switch,
        }
    }

    fn switch(&self) -> cdm_runtime::realtime_journal::Switch {
        use cdm_runtime::realtime_journal::{Switch, Switched};
        let what = match self.switch {
            SwitchWhat::Repair { at, in_neighbors } => Switched::Repair { at, in_neighbors },
            SwitchWhat::Command { seq, at } => Switched::Command { seq, at },
        };
        Switch {
            tick: self.tick,
            what,
        }
    }
}
