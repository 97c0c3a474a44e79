//! A run as a ROS 2 bag: a rosbag2 directory (metadata.yaml and one MCAP file, the
//! default storage since ROS 2 Iron) of standard messages with their `ros2msg` schemas embedded
//! and CDR payloads, for Foxglove and `ros2 bag play`:
//!
//! - `/cdm/agent_<id>/pose` (geometry_msgs/msg/PoseStamped, frame `world`, stamped with the
//!   simulation time), one per telemetry row;
//! - `/tf` (tf2_msgs/msg/TFMessage): a frame `agent_<id>` per member, parent `world`;
//! - `/cdm/formation` (visualization_msgs/msg/MarkerArray): a sphere per member coloured by
//!   role, the leading polygon (LINE_STRIP), and with a scenario's airspace the geofence
//!   (LINE_LIST, ns `geofence`) and each obstacle (CUBE or CYLINDER, ns `obstacles`, id in file
//!   order);
//! - `/cdm/audit` (std_msgs/msg/String): the tick's margins as JSON.
//!
//! `tick.rs` turns one tick into those messages (pure), `msgs.rs` encodes them with the one CDR
//! encoder (`cdr.rs`), `bag.rs` writes them with the `mcap` crate and `metadata.rs` writes
//! metadata.yaml. `export rosbag2` (cdm-export) feeds it a finished run; `BagSink` (`sink.rs`)
//! is the `--telemetry mcap` sink that writes the same bag during the run. Only this crate
//! depends on `mcap`.

pub mod bag;
pub mod cdr;
pub mod metadata;
pub mod msgs;
pub mod room;
pub mod sink;
pub mod tick;

pub use bag::{BagError, BagWriter};
pub use sink::BagSink;
pub use tick::{Limits, Message, Team, Tick, Topic};

/// The bag's directory inside a run directory written with `--telemetry mcap`.
pub const RUN_BAG_DIR: &str = "rosbag2";
