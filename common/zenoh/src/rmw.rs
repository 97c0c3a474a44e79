//! Live ROS 2 over zenoh (`launch --ros2 zenoh`): a zenoh session that speaks
//! rmw_zenoh's wire format, so ROS 2 nodes running `rmw_zenoh_cpp` see our topics. This module
//! only moves bytes: the key expressions, liveliness keys and GIDs are built by the caller
//! (cdm-ros2 `rmw_zenoh.rs`, pure); here are the session, the tokens, the publishers and the
//! message attachment, which is written with zenoh's own serializer (`zenoh-ext`), as
//! rmw_zenoh writes it with zenoh-cpp's (`docs/design.md`, "Publishers").

use std::path::{Path, PathBuf};

use zenoh::qos::CongestionControl;
use zenoh::Wait;

/// rmw_zenoh's session defaults (`DEFAULT_RMW_ZENOH_SESSION_CONFIG.json5`, design.md's table):
/// a peer that connects to the router on this host and listens on loopback only, with no
/// multicast scouting (the router's gossip introduces the peers).
const DEFAULTS: [(&str, &str); 4] = [
    ("mode", "\"peer\""),
    ("connect/endpoints", "[\"tcp/localhost:7447\"]"),
    ("listen/endpoints", "[\"tcp/localhost:0\"]"),
    ("scouting/multicast/enabled", "false"),
];

/// Why the rmw_zenoh session or one of its entities could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RmwError {
    /// The session configuration file (`ZENOH_SESSION_CONFIG_URI`) is unreadable or invalid.
    #[error("{path}: {detail}")]
    Config { path: PathBuf, detail: String },
    /// zenoh refused to open the session.
    #[error("cannot open a zenoh session ({config}): {detail}")]
    Open { config: String, detail: String },
    /// A token or publisher could not be declared.
    #[error("zenoh: cannot declare {what} on {key}: {detail}")]
    Declare {
        what: &'static str,
        key: String,
        detail: String,
    },
    /// A message could not be published.
    #[error("zenoh: cannot publish on {key}: {detail}")]
    Put { key: String, detail: String },
}

/// A zenoh session for ROS 2 entities, and the tokens that announce them.
pub struct RmwSession {
    session: zenoh::Session,
    tokens: Vec<zenoh::liveliness::LivelinessToken>,
}

impl RmwSession {
    /// Opens the session with the configuration `config`: the JSON5 text of rmw_zenoh's
    /// `ZENOH_SESSION_CONFIG_URI` and the file it was read from (the caller reads it, with a
    /// size limit and regular files only: zenoh's own `Config::from_file` reads whatever it is
    /// given, /dev/zero or a FIFO, for ever), or rmw_zenoh's defaults. A peer whose router is
    /// not up yet keeps trying in the background (zenoh's default for peers): opening never
    /// waits for one.
    pub fn open(config: Option<(&Path, &str)>) -> Result<Self, RmwError> {
        let (cfg, what) = match config {
            Some((path, json5)) => {
                let cfg = zenoh::Config::from_json5(json5).map_err(|e| RmwError::Config {
                    path: path.to_path_buf(),
                    detail: e.to_string(),
                })?;
                (cfg, path.display().to_string())
            }
            None => {
                let mut cfg = zenoh::Config::default();
                for (k, v) in DEFAULTS {
                    cfg.insert_json5(k, v).map_err(|e| RmwError::Open {
                        config: "rmw_zenoh's defaults".into(),
                        detail: format!("{k}: {e}"),
                    })?;
                }
                (cfg, "rmw_zenoh's defaults".to_owned())
            }
        };
        let session = zenoh::open(cfg).wait().map_err(|e| RmwError::Open {
            config: what,
            detail: e.to_string(),
        })?;
        Ok(RmwSession {
            session,
            tokens: Vec::new(),
        })
    }

    /// The session id, as rmw_zenoh writes it in liveliness keys.
    pub fn zid(&self) -> String {
        self.session.zid().to_string()
    }

    /// Declares a liveliness token on `key`, kept until the session is dropped.
    pub fn declare_token(&mut self, key: &str) -> Result<(), RmwError> {
        let token = self
            .session
            .liveliness()
            .declare_token(key.to_owned())
            .wait()
            .map_err(|e| declare("a liveliness token", key, e))?;
        self.tokens.push(token);
        Ok(())
    }

    /// A publisher on `key` that drops a sample rather than wait when the network is congested
    /// (rmw_zenoh's choice for KEEP_LAST): a slow subscriber never holds the caller.
    pub fn publisher(&self, key: &str) -> Result<RmwPublisher, RmwError> {
        let publisher = self
            .session
            .declare_publisher(key.to_owned())
            .congestion_control(CongestionControl::Drop)
            .wait()
            .map_err(|e| declare("a publisher", key, e))?;
        let key = key.to_owned();
        Ok(RmwPublisher { publisher, key })
    }
}

fn declare(what: &'static str, key: &str, e: impl std::fmt::Display) -> RmwError {
    RmwError::Declare {
        what,
        key: key.to_owned(),
        detail: e.to_string(),
    }
}

/// rmw_zenoh's message attachment: the sequence number, the source timestamp (ns since the
/// UNIX epoch) and the publisher's 16-byte GID, in that order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    pub sequence_number: i64,
    pub source_timestamp_ns: i64,
    pub gid: [u8; 16],
}

impl Attachment {
    /// The bytes: two little-endian i64 and the GID behind its length (33 bytes).
    pub fn to_bytes(&self) -> Vec<u8> {
        self.zbytes().to_bytes().into_owned()
    }

    fn zbytes(&self) -> zenoh::bytes::ZBytes {
        let mut s = zenoh_ext::ZSerializer::new();
        s.serialize(self.sequence_number);
        s.serialize(self.source_timestamp_ns);
        s.serialize(self.gid);
        s.finish()
    }
}

/// One topic's publisher.
pub struct RmwPublisher {
    publisher: zenoh::pubsub::Publisher<'static>,
    key: String,
}

impl RmwPublisher {
    /// Publishes one serialized message (CDR with its header) with its attachment.
    pub fn put(&self, payload: &[u8], attachment: &Attachment) -> Result<(), RmwError> {
        self.publisher
            .put(payload.to_vec())
            .attachment(attachment.zbytes())
            .wait()
            .map_err(|e| RmwError::Put {
                key: self.key.clone(),
                detail: e.to_string(),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_attachment_is_two_little_endian_i64_then_the_gid_behind_its_length() {
        let gid: [u8; 16] = std::array::from_fn(|i| i as u8);
        let a = Attachment {
            sequence_number: 7,
            source_timestamp_ns: 0x0102_0304_0506_0708,
            gid,
        };
        let mut want = 7i64.to_le_bytes().to_vec();
        want.extend_from_slice(&0x0102_0304_0506_0708i64.to_le_bytes());
        want.push(16);
        want.extend_from_slice(&gid);
        assert_eq!(a.to_bytes(), want);
    }

    #[test]
    fn a_configuration_that_is_not_json5_is_named() {
        let file = Path::new("/etc/zenoh.json5");
        let Err(e) = RmwSession::open(Some((file, "mode: peer\n"))) else {
            panic!("a bad configuration opened a session");
        };
        assert!(e.to_string().contains("/etc/zenoh.json5"), "{e}");
    }
}
