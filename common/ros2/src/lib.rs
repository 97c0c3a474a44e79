//! Live ROS 2: `launch --ros2 dds|zenoh` publishes, while the team flies, the topics
//! of the run's bag (cdm-rosbag: each member's PoseStamped, `/tf`, the formation's MarkerArray,
//! the margins on `/cdm/audit`) with the very bytes the bag holds, at most `--ros2-hz` ticks a
//! second. Output only: nothing is subscribed, so nothing on the ROS side can steer the team.
//!
//! The launch loop offers each audited tick to [`Live`] (`live.rs`): the rate limit (`pace.rs`)
//! decides, a copy of the positions goes into a bounded queue, and a thread of its own builds the
//! messages and publishes them, so a slow ROS side costs dropped ticks, never a slower team.
//! Where they go is the [`Publish`] seam: ros2-client over DDS/RTPS (`dds.rs`, feature `dds`),
//! or rmw_zenoh's format over cdm-zenoh's session (`zenoh.rs`, feature `zenoh`; the names are
//! `rmw_zenoh.rs`, pure). Only this crate names ros2-client.

pub mod live;
pub mod pace;
pub mod rmw_zenoh;

#[cfg(feature = "dds")]
mod dds;
#[cfg(feature = "zenoh")]
mod zenoh;

pub use live::{Live, Summary};

use cdm_rosbag::msgs::MsgType;

/// The middleware the topics go out on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// DDS/RTPS, as rmw_fastrtps and rmw_cyclonedds speak it (ROS 2's default).
    Dds,
    /// rmw_zenoh's key expressions, liveliness tokens and attachments.
    Zenoh,
}

impl std::fmt::Display for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Backend::Dds => "dds",
            Backend::Zenoh => "zenoh",
        })
    }
}

/// A `--ros2` value that names no backend.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0:?}: expected dds or zenoh")]
pub struct UnknownBackend(pub String);

impl std::str::FromStr for Backend {
    type Err = UnknownBackend;
    fn from_str(s: &str) -> Result<Self, UnknownBackend> {
        match s {
            "dds" => Ok(Backend::Dds),
            "zenoh" => Ok(Backend::Zenoh),
            _ => Err(UnknownBackend(s.to_owned())),
        }
    }
}

/// `--ros2` and `--ros2-hz`, validated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ros2Options {
    pub backend: Backend,
    /// Ticks published per second of wall time, at most.
    pub hz: f64,
}

/// Why the live topics could not start.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// `ROS_DOMAIN_ID` is not a domain.
    #[error("ROS_DOMAIN_ID={value:?}: expected an integer in 0..=232")]
    Domain { value: String },
    /// This build has no such backend.
    #[error("--ros2 {0}: this orchestrator was built without it (cargo feature ros2)")]
    NotBuilt(Backend),
    /// The DDS participant, node or a publisher could not be made.
    #[error("--ros2 dds: cannot create {what}: {source}")]
    Dds {
        what: String,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The zenoh session, a token or a publisher could not be made.
    #[cfg(feature = "zenoh")]
    #[error("--ros2 zenoh: {0}")]
    Zenoh(#[from] cdm_zenoh::rmw::RmwError),
    /// `ZENOH_SESSION_CONFIG_URI` names no regular file, or one too large.
    #[cfg(feature = "zenoh")]
    #[error("--ros2 zenoh: ZENOH_SESSION_CONFIG_URI: {0}")]
    ZenohConfig(#[from] cdm_files::FileError),
    /// The publishing thread could not be started.
    #[error("--ros2: cannot start the publishing thread: {0}")]
    Thread(#[source] std::io::Error),
}

/// What the environment says, as a ROS 2 node reads it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Env {
    /// `ROS_DOMAIN_ID` (default 0).
    pub domain: u16,
    /// `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` (or the older `ROS_LOCALHOST_ONLY=1`): DDS
    /// discovery stays on this machine.
    pub localhost_only: bool,
    /// `ZENOH_SESSION_CONFIG_URI`: rmw_zenoh's session configuration file.
    pub zenoh_config: Option<std::path::PathBuf>,
}

impl Env {
    /// Reads the variables through `var` (the process environment in [`Env::of_process`]).
    pub fn read(var: impl Fn(&str) -> Option<String>) -> Result<Self, Ros2Error> {
        let domain = match var("ROS_DOMAIN_ID").filter(|v| !v.trim().is_empty()) {
            None => 0,
            Some(v) => v
                .trim()
                .parse::<u16>()
                .ok()
                .filter(|d| *d <= 232)
                .ok_or(Ros2Error::Domain { value: v })?,
        };
        let range = var("ROS_AUTOMATIC_DISCOVERY_RANGE").unwrap_or_default();
        let localhost_only = range.eq_ignore_ascii_case("LOCALHOST")
            || (range.is_empty() && var("ROS_LOCALHOST_ONLY").as_deref() == Some("1"));
        Ok(Env {
            domain,
            localhost_only,
            zenoh_config: var("ZENOH_SESSION_CONFIG_URI")
                .filter(|v| !v.is_empty())
                .map(Into::into),
        })
    }

    pub fn of_process() -> Result<Self, Ros2Error> {
        Env::read(|k| std::env::var(k).ok())
    }
}

/// Where a tick's messages go: one publisher per topic of the bag, in `Team::topics` order
/// (`Topic::index`). Implementations never wait on a subscriber.
pub trait Publish {
    /// Publishes one serialized message (CDR with its 4-byte header) on topic `index`.
    fn publish(&mut self, index: usize, cdr: &[u8]) -> Result<(), PublishError>;
}

/// Why a message was not published.
#[derive(Debug, thiserror::Error)]
pub enum PublishError {
    /// No publisher has this topic index.
    #[error("no topic {0}")]
    NoTopic(usize),
    /// rmw_zenoh's publisher refused it.
    #[cfg(feature = "zenoh")]
    #[error(transparent)]
    Zenoh(#[from] cdm_zenoh::rmw::RmwError),
    /// The DDS writer refused it (ros2-client's error, as its text).
    #[error("DDS: {0}")]
    Dds(String),
}

/// `geometry_msgs/msg/PoseStamped` -> (`geometry_msgs`, `PoseStamped`).
fn split_type(m: MsgType) -> (&'static str, &'static str) {
    let name = m.name();
    let (package, rest) = name.split_once('/').unwrap_or(("", name));
    (package, rest.rsplit('/').next().unwrap_or(rest))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(vars: &[(&str, &str)]) -> Result<Env, Ros2Error> {
        Env::read(|k| {
            vars.iter()
                .find(|(name, _)| *name == k)
                .map(|(_, v)| v.to_string())
        })
    }

    #[test]
    fn the_environment_is_read_as_a_ros_2_node_reads_it() {
        let e = env(&[]).unwrap();
        assert_eq!(
            (e.domain, e.localhost_only, e.zenoh_config),
            (0, false, None)
        );
        let e = env(&[
            ("ROS_DOMAIN_ID", "42"),
            ("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST"),
            ("ZENOH_SESSION_CONFIG_URI", "/etc/z.json5"),
        ])
        .unwrap();
        assert_eq!(e.domain, 42);
        assert!(e.localhost_only);
        assert_eq!(e.zenoh_config.as_deref(), Some("/etc/z.json5".as_ref()));
        assert!(env(&[("ROS_LOCALHOST_ONLY", "1")]).unwrap().localhost_only);
        // The newer variable wins over the older one.
        let both = [
            ("ROS_LOCALHOST_ONLY", "1"),
            ("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET"),
        ];
        assert!(!env(&both).unwrap().localhost_only);
        for bad in ["233", "-1", "zero"] {
            let e = env(&[("ROS_DOMAIN_ID", bad)]).unwrap_err();
            assert!(e.to_string().contains(bad), "{e}");
        }
    }

    #[test]
    fn backends_and_types_are_named_as_ros_names_them() {
        assert_eq!("dds".parse::<Backend>(), Ok(Backend::Dds));
        assert_eq!("zenoh".parse::<Backend>(), Ok(Backend::Zenoh));
        assert!("ros".parse::<Backend>().is_err());
        assert_eq!(
            split_type(MsgType::MarkerArray),
            ("visualization_msgs", "MarkerArray")
        );
    }
}
