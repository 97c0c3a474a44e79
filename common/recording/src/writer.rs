//! The member's side: a [`Journal`] that writes the recording as the member flies.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use cdm_records::run_record::RunRecord;
use cdm_runtime::realtime_journal::{Flown, Journal, Switch};

use crate::{Ages, Header, SwitchMsg, AGES_TOPIC, FORMAT, MEMBER_TOPIC, SWITCH_TOPIC};

/// Why a recording cannot be started or written (the flight goes on without it; a replay then
/// says where it ends).
#[derive(Debug, thiserror::Error)]
pub enum WriterError {
    /// The file cannot be created.
    #[error(transparent)]
    Create(#[from] cdm_files::FileError),
    /// The MCAP writer failed (names the file).
    #[error("{path}: {reason}")]
    Write { path: PathBuf, reason: String },
}

/// A member's recording, written a batch of ticks (one second of flight) at a time, each batch
/// flushed to the file as it is complete.
pub struct McapJournal {
    path: PathBuf,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    channel: u16,
    switch_channel: u16,
    member: u32,
    leader: bool,
    /// Ticks per message.
    batch: u64,
    dt_ns: f64,
    first: u64,
    ticks: u64,
    age: Vec<Option<i64>>,
    sequence: u32,
}

impl std::fmt::Debug for McapJournal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapJournal")
            .field("path", &self.path)
            .field("ticks", &self.ticks)
            .finish()
    }
}

impl McapJournal {
    /// Member `member` (a leader when `leader`: it flies on no neighbour) of the scenario with
    /// content hash `hash`, flying at period `dt_s`: its recording created at `path` and its
    /// header written.
    pub fn create(
        path: &Path,
        (member, leader): (u32, bool),
        hash: u64,
        dt_s: f64,
    ) -> Result<Self, WriterError> {
        let file = cdm_files::create_file(path)?;
        let fail = |e: mcap::McapError| WriterError::Write {
            path: path.to_path_buf(),
            reason: e.to_string(),
        };
        // No chunks: every message is its own record in the file as soon as it is flushed, so
        // a crash loses at most the batch being filled.
        let mut w = mcap::WriteOptions::new()
            .use_chunks(false)
            .library(concat!("cdm-recording ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(fail)?;
        let none = BTreeMap::new();
        // One schema and channel per message kind (the schema a JSON schema, for tools).
        let mut channel_of = |name: &str, which: &str, topic: &str| {
            let schema = w
                .add_schema(name, "jsonschema", w_schema(which).as_bytes())
                .map_err(fail)?;
            w.add_channel(schema, topic, "json", &none).map_err(fail)
        };
        let header_channel = channel_of("cdm.recording.Member", "member", MEMBER_TOPIC)?;
        let channel = channel_of("cdm.recording.Ages", "ages", AGES_TOPIC)?;
        let switch_channel = channel_of("cdm.recording.Switch", "switch", SWITCH_TOPIC)?;
        let header = Header {
            format: FORMAT.into(),
            member,
            scenario_hash: RunRecord::hash_text(hash),
            dt_s,
        };
        let data = serde_json::to_vec(&header).map_err(|e| WriterError::Write {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        let at = mcap::records::MessageHeader {
            channel_id: header_channel,
            sequence: 0,
            log_time: 0,
            publish_time: 0,
        };
        w.write_to_known_channel(&at, &data).map_err(fail)?;
        w.flush().map_err(fail)?;
        let batch = (1.0 / dt_s).round().max(1.0) as u64;
        Ok(Self {
            path: path.to_path_buf(),
            writer: Some(w),
            channel,
            switch_channel,
            member,
            leader,
            batch,
            dt_ns: dt_s * 1e9,
            first: 0,
            ticks: 0,
            age: Vec::with_capacity(3 * batch as usize),
            sequence: 1,
        })
    }

    /// Writes the batch filled so far, if any, and flushes it to the file.
    fn write_batch(&mut self) {
        if self.ticks == 0 {
            return;
        }
        let msg = Ages {
            member: self.member,
            tick: self.first,
            ticks: self.ticks,
            age: std::mem::take(&mut self.age),
        };
        self.first += self.ticks;
        self.ticks = 0;
        let data = serde_json::to_vec(&msg).map_err(|e| e.to_string());
        self.write(self.channel, msg.tick, data);
        self.age = msg.age;
        self.age.clear();
    }

    /// Writes one message of `channel` stamped with tick `tick`'s time, and flushes it to the
    /// file.
    fn write(&mut self, channel: u16, tick: u64, data: Result<Vec<u8>, String>) {
        let Some(w) = self.writer.as_mut() else {
            return;
        };
        let time = (tick as f64 * self.dt_ns) as u64;
        let at = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: self.sequence,
            log_time: time,
            publish_time: time,
        };
        self.sequence += 1;
        let written = data.and_then(|data| {
            w.write_to_known_channel(&at, &data)
                .and_then(|()| w.flush())
                .map_err(|e| e.to_string())
        });
        if let Err(reason) = written {
            // The flight goes on; the recording ends here (a replay says so).
            tracing::warn!(path = %self.path.display(), %reason, "the recording stops");
            self.writer = None;
        }
    }
}

impl Journal for McapJournal {
    fn flown(&mut self, f: &Flown) {
        if self.writer.is_none() {
            return;
        }
        if self.ticks == 0 {
            self.first = f.tick;
        }
        if !self.leader {
            let age = |u: Option<u64>| u.map(|t| f.tick as i64 - t as i64);
            self.age.extend(f.used.map(age));
        }
        self.ticks += 1;
        if self.ticks >= self.batch {
            self.write_batch();
        }
    }

    /// Written at once, before the batch that holds its tick: a reader then knows of the
    /// switch before the ticks flown on it.
    fn switched(&mut self, s: &Switch) {
        let data = serde_json::to_vec(&SwitchMsg::of(self.member, s)).map_err(|e| e.to_string());
        self.write(self.switch_channel, s.tick, data);
    }
}

impl Drop for McapJournal {
    /// The last batch, and the file's summary and end: a recording that has them was finished.
    fn drop(&mut self) {
        self.write_batch();
        if let Some(mut w) = self.writer.take() {
            if let Err(e) = w.finish() {
                tracing::warn!(path = %self.path.display(), %e, "the recording's end not written");
            }
        }
    }
}

/// The JSON schema of a channel's messages (for tools that show them).
fn w_schema(which: &str) -> String {
    let props = match which {
        "member" => {
            r#""format":{"type":"string"},"member":{"type":"integer"},"scenario_hash":{"type":"string"},"dt_s":{"type":"number"}"#
        }
        "switch" => {
            r#""member":{"type":"integer"},"tick":{"type":"integer"},"switch":{"type":"object"}"#
        }
        _ => {
            r#""member":{"type":"integer"},"tick":{"type":"integer"},"ticks":{"type":"integer"},"age":{"type":"array","items":{"type":["integer","null"]}}"#
        }
    };
    format!(r#"{{"type":"object","properties":{{{props}}}}}"#)
}
