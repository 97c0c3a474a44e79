//! `--ros2 zenoh`: the topics as rmw_zenoh publishes them (`rmw_zenoh.rs` names the keys),
//! over cdm-zenoh's session: a liveliness token for the node and one per publisher (how
//! rmw_zenoh nodes discover entities), and each message's CDR bytes with rmw_zenoh's
//! attachment (sequence number from 1, the wall clock of the publication, the publisher's GID).

use std::time::{SystemTime, UNIX_EPOCH};

use cdm_rosbag::msgs::MsgType;
use cdm_rosbag::Topic;
use cdm_zenoh::rmw::{Attachment, RmwPublisher, RmwSession};

use cdm_files::read_input;

use crate::rmw_zenoh::{gid, node_token, publisher_token, topic_key};
use crate::{Env, Publish, PublishError, Ros2Error};

/// The largest session configuration read (rmw_zenoh's default file is about 30 KiB).
const MAX_ZENOH_CONFIG_BYTES: u64 = 1 << 20;

/// One topic: its publisher, its GID and its last sequence number.
struct Out {
    publisher: RmwPublisher,
    gid: [u8; 16],
    sequence: i64,
}

/// The session (which holds the tokens) and the publishers.
pub struct ZenohOut {
    // Field order is drop order: the publishers go before the session and its tokens.
    topics: Vec<Out>,
    _session: RmwSession,
}

impl ZenohOut {
    /// Opens the session (`ZENOH_SESSION_CONFIG_URI` or rmw_zenoh's defaults), announces the
    /// node and a publisher per topic in domain `ROS_DOMAIN_ID`.
    pub fn open(env: &Env, topics: &[(Topic, String, MsgType)]) -> Result<Self, Ros2Error> {
        let config = match env.zenoh_config.as_deref() {
            Some(path) => Some((path, read_input(path, MAX_ZENOH_CONFIG_BYTES)?)),
            None => None,
        };
        let mut session = RmwSession::open(config.as_ref().map(|(p, t)| (*p, t.as_str())))?;
        let zid = session.zid();
        session.declare_token(&node_token(env.domain, &zid))?;
        let mut outs = Vec::with_capacity(topics.len());
        for (entity, (_, name, msg)) in (1..).zip(topics) {
            let token = publisher_token(env.domain, &zid, entity, name, *msg);
            let publisher = session.publisher(&topic_key(env.domain, name, *msg))?;
            session.declare_token(&token)?;
            outs.push(Out {
                publisher,
                gid: gid(&token),
                sequence: 0,
            });
        }
        Ok(ZenohOut {
            topics: outs,
            _session: session,
        })
    }
}

impl Publish for ZenohOut {
    fn publish(&mut self, index: usize, cdr: &[u8]) -> Result<(), PublishError> {
        let Some(out) = self.topics.get_mut(index) else {
            return Err(PublishError::NoTopic(index));
        };
        out.sequence += 1;
        let now_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX));
        let attachment = Attachment {
            sequence_number: out.sequence,
            source_timestamp_ns: now_ns,
            gid: out.gid,
        };
        Ok(out.publisher.put(cdr, &attachment)?)
    }
}
