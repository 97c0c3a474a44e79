//! The bag on disk: a rosbag2 directory with metadata.yaml and one MCAP file (profile `ros2`,
//! schemas `ros2msg`, messages `cdr`), written a message at a time. The MCAP writer holds one
//! chunk (1 MiB) and the chunk index in memory, so a run of any length is written in bounded
//! memory. metadata.yaml is written last: a bag without it was not finished.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::metadata::{BagInfo, TopicCount, OFFERED_QOS};
use crate::msgs::MsgType;
use crate::room::{Room, Spool};
use crate::tick::{Message, Team};

/// Why a bag could not be written, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// The MCAP file could not be created or written.
    #[error("{path}: {source}")]
    Mcap {
        path: PathBuf,
        #[source]
        source: mcap::McapError,
    },
    /// metadata.yaml or the directory could not be written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A message after `finish`.
    #[error("{path}: the bag is already finished")]
    Finished { path: PathBuf },
}

/// One channel of the bag.
struct Channel {
    id: u16,
    name: String,
    msg: MsgType,
    count: u64,
}

/// A rosbag2 directory being written.
pub struct BagWriter {
    dir: PathBuf,
    file: String,
    mcap: Option<mcap::Writer<BufWriter<Spool>>>,
    /// The room kept free to end the MCAP file on a full disk.
    room: Arc<Room>,
    /// Pose channels in member order, then /tf, /cdm/formation, /cdm/audit.
    channels: Vec<Channel>,
    members: usize,
    first_ns: Option<u64>,
    last_ns: u64,
}

impl BagWriter {
    /// Create the bag in `dir` (created if missing; its files are replaced): the MCAP file
    /// `<dir name>_0.mcap` with every schema and channel of `team`.
    pub fn create(dir: &Path, team: &Team) -> Result<Self, BagError> {
        std::fs::create_dir_all(dir).map_err(|source| BagError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let stem = dir
            .file_name()
            .and_then(|s| s.to_str())
            .unwrap_or("rosbag2");
        let file = format!("{stem}_0.mcap");
        let path = dir.join(&file);
        let mcap_err = |source| BagError::Mcap {
            path: path.clone(),
            source,
        };
        // A metadata.yaml left by an earlier bag would describe the wrong file until `finish`.
        let meta = dir.join("metadata.yaml");
        if meta.exists() {
            std::fs::remove_file(&meta).map_err(|source| BagError::Io { path: meta, source })?;
        }
        // Every topic of the team: a pose per member, /tf, /cdm/formation and /cdm/audit (and
        // /cdm/commands in a commanded run).
        let (out, room) =
            Spool::create(&path, team.topics().len()).map_err(|e| mcap_err(e.into()))?;
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .compression(None)
            .create(BufWriter::with_capacity(1 << 16, out))
            .map_err(mcap_err)?;
        let mut schema_ids = BTreeMap::new();
        for m in MsgType::ALL {
            let id = w
                .add_schema(m.name(), "ros2msg", m.schema().as_bytes())
                .map_err(mcap_err)?;
            schema_ids.insert(m.name(), id);
        }
        let mut channels = Vec::new();
        for (_, name, msg) in team.topics() {
            let meta = BTreeMap::from([
                ("offered_qos_profiles".to_owned(), OFFERED_QOS.to_owned()),
                ("topic_type_hash".to_owned(), msg.hash().to_owned()),
            ]);
            let schema = schema_ids.get(msg.name()).copied().unwrap_or(0);
            let id = w
                .add_channel(schema, &name, "cdr", &meta)
                .map_err(mcap_err)?;
            channels.push(Channel {
                id,
                name,
                msg,
                count: 0,
            });
        }
        Ok(BagWriter {
            dir: dir.to_path_buf(),
            file,
            mcap: Some(w),
            room,
            channels,
            members: team.ids().len(),
            first_ns: None,
            last_ns: 0,
        })
    }

    fn path(&self) -> PathBuf {
        self.dir.join(&self.file)
    }

    /// Append one message (log and publish time: its simulation time).
    pub fn write(&mut self, m: &Message) -> Result<(), BagError> {
        let path = self.path();
        let k = m.topic.index(self.members);
        let Some(w) = self.mcap.as_mut() else {
            return Err(BagError::Finished { path });
        };
        let Some(ch) = self.channels.get_mut(k) else {
            return Ok(());
        };
        let header = mcap::records::MessageHeader {
            channel_id: ch.id,
            sequence: u32::try_from(ch.count).unwrap_or(u32::MAX),
            log_time: m.time_ns,
            publish_time: m.time_ns,
        };
        w.write_to_known_channel(&header, &m.data)
            .map_err(|source| BagError::Mcap { path, source })?;
        ch.count += 1;
        self.first_ns.get_or_insert(m.time_ns);
        self.last_ns = self.last_ns.max(m.time_ns);
        Ok(())
    }

    /// End the MCAP file (its summary, and the `rosbag2` metadata record rosbag2 writes) and
    /// write metadata.yaml. A second call does nothing.
    pub fn finish(&mut self) -> Result<(), BagError> {
        let path = self.path();
        let Some(mut w) = self.mcap.take() else {
            return Ok(());
        };
        let yaml = self.info().yaml();
        let record = mcap::records::Metadata {
            name: "rosbag2".to_owned(),
            metadata: BTreeMap::from([
                ("serialized_metadata".to_owned(), yaml.clone()),
                ("ros_distro".to_owned(), "humble".to_owned()),
            ]),
        };
        let mcap_err = |source| BagError::Mcap {
            path: path.clone(),
            source,
        };
        // The room kept for the end is the end's now (all of it on a full disk).
        self.room.give_back();
        w.write_metadata(&record).map_err(mcap_err)?;
        w.finish().map_err(mcap_err)?;
        let out = w.into_inner();
        out.into_inner()
            .map_err(|e| mcap_err(e.into_error().into()))?
            .file()
            .sync_all()
            .map_err(|e| mcap_err(e.into()))?;
        let meta = self.dir.join("metadata.yaml");
        std::fs::write(&meta, yaml).map_err(|source| BagError::Io { path: meta, source })
    }

    /// Give the bag up (its input could not be read): its files are removed, and the directory
    /// when that leaves it empty.
    pub fn abandon(mut self) {
        // Dropping the MCAP writer writes its summary into the file removed next.
        drop(self.mcap.take());
        self.room.give_back();
        let _ = std::fs::remove_file(self.path());
        let _ = std::fs::remove_file(self.dir.join("metadata.yaml"));
        let _ = std::fs::remove_dir(&self.dir);
    }

    /// The full disk the MCAP file met, naming it and the free space then: the bag ends at
    /// the end of this tick, in the room kept for it.
    pub fn full(&self) -> Option<String> {
        self.room.full()
    }

    /// What metadata.yaml says of the bag so far.
    fn info(&self) -> BagInfo<'_> {
        let start_ns = self.first_ns.unwrap_or(0);
        BagInfo {
            file: &self.file,
            start_ns,
            duration_ns: self.last_ns.saturating_sub(start_ns),
            topics: self
                .channels
                .iter()
                .map(|c| TopicCount {
                    name: &c.name,
                    type_name: c.msg.name(),
                    type_hash: c.msg.hash(),
                    count: c.count,
                })
                .collect(),
        }
    }

    /// How many messages each topic has, in the bag's order.
    pub fn counts(&self) -> Vec<(&str, u64)> {
        self.channels
            .iter()
            .map(|c| (c.name.as_str(), c.count))
            .collect()
    }
}

impl Drop for BagWriter {
    /// A bag dropped unfinished (an error elsewhere ended the run) is finished, best effort.
    fn drop(&mut self) {
        let _ = self.finish();
    }
}
