//! metadata.yaml, as rosbag2 writes it (version 8, ROS 2 Iron's: `offered_qos_profiles` as one
//! YAML string, `type_description_hash`, `custom_data`, `ros_distro`), which rosbag2 from Humble
//! on and the `rosbags` reader read.

use std::fmt::Write as _;

/// The rosbag2 metadata version written.
pub const VERSION: u32 = 8;

/// The QoS a topic was offered with, as rosbag2 records it for a publisher with the default
/// profile (reliable, volatile, keep last; no deadline, lifespan or lease: their "infinite").
pub const OFFERED_QOS: &str = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  \
    deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    \
    nsec: 854775807\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    \
    nsec: 854775807\n  avoid_ros_namespace_conventions: false";

/// One topic's entry.
pub struct TopicCount<'a> {
    pub name: &'a str,
    pub type_name: &'a str,
    pub type_hash: &'a str,
    pub count: u64,
}

/// The whole bag: one storage file.
pub struct BagInfo<'a> {
    pub file: &'a str,
    pub start_ns: u64,
    pub duration_ns: u64,
    pub topics: Vec<TopicCount<'a>>,
}

/// A YAML double-quoted scalar.
fn quoted(s: &str) -> String {
    serde_json::Value::from(s).to_string()
}

impl BagInfo<'_> {
    /// The text of metadata.yaml.
    pub fn yaml(&self) -> String {
        let count: u64 = self.topics.iter().map(|t| t.count).sum();
        let mut y = String::from("rosbag2_bagfile_information:\n");
        let _ = write!(
            y,
            "  version: {VERSION}\n  storage_identifier: mcap\n  duration:\n    nanoseconds: {}\n  \
             starting_time:\n    nanoseconds_since_epoch: {}\n  message_count: {count}\n  \
             topics_with_message_count:\n",
            self.duration_ns, self.start_ns
        );
        for t in &self.topics {
            let _ = write!(
                y,
                "    - topic_metadata:\n        name: {}\n        type: {}\n        \
                 serialization_format: cdr\n        offered_qos_profiles: {}\n        \
                 type_description_hash: {}\n      message_count: {}\n",
                quoted(t.name),
                quoted(t.type_name),
                quoted(OFFERED_QOS),
                quoted(t.type_hash),
                t.count
            );
        }
        let _ = write!(
            y,
            "  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n    \
             - {file}\n  files:\n    - path: {file}\n      starting_time:\n        \
             nanoseconds_since_epoch: {}\n      duration:\n        nanoseconds: {}\n      \
             message_count: {count}\n  custom_data: ~\n  ros_distro: humble\n",
            self.start_ns,
            self.duration_ns,
            file = quoted(self.file),
        );
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_times_and_the_file_are_written_where_rosbag2_reads_them() {
        let info = BagInfo {
            file: "b_0.mcap",
            start_ns: 5,
            duration_ns: 10,
            topics: vec![TopicCount {
                name: "/tf",
                type_name: "tf2_msgs/msg/TFMessage",
                type_hash: "RIHS01_x",
                count: 3,
            }],
        };
        let y = info.yaml();
        for line in [
            "  version: 8\n",
            "  storage_identifier: mcap\n",
            "  message_count: 3\n",
            "        name: \"/tf\"\n",
            "      message_count: 3\n",
            "  relative_file_paths:\n    - \"b_0.mcap\"\n",
            "    nanoseconds_since_epoch: 5\n",
            "    nanoseconds: 10\n",
        ] {
            assert!(y.contains(line), "{line:?} not in\n{y}");
        }
        assert!(
            !OFFERED_QOS.contains("  \n"),
            "continuation lines kept their indent"
        );
    }
}
