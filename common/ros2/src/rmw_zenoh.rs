//! rmw_zenoh's names for our entities, pure (`launch --ros2 zenoh`). We follow rmw_zenoh_cpp
//! 0.2.10 (ROS 2 Jazzy; the attachment's positional format dates from 0.2.4), as its
//! `docs/design.md` documents it ("Topic and Service name mapping to Zenoh key expressions",
//! "Graph Cache", "Publishers"):
//!
//! - data: `<domain_id>/<fully qualified name without its leading slash>/<DDS type name>/<type hash>`,
//!   e.g. `0/cdm/agent_1/pose/geometry_msgs::msg::dds_::PoseStamped_/RIHS01_10f3...`;
//! - the node's liveliness token: `@ros2_lv/<domain_id>/<session id>/<node id>/<node id>/NN/
//!   <enclave>/<namespace>/<node name>`, each name mangled (`/` -> `%`, empty -> `%`);
//! - a publisher's: `@ros2_lv/<domain_id>/<session id>/<node id>/<entity id>/MP/<enclave>/
//!   <namespace>/<node name>/<mangled topic>/<DDS type name>/<type hash>/<qos>`;
//! - its GID: the XXH3-128 of its liveliness key, low 64 bits then high 64 bits, little endian
//!   (rmw_zenoh's `liveliness_utils.cpp`), carried in every message's attachment.

use cdm_rosbag::msgs::MsgType;

/// rmw_zenoh's admin space: a verbatim chunk that wildcards never match.
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// Our node's name (namespace `/`, no enclave).
pub const NODE_NAME: &str = "cdm_orchestrator";

/// The node's id in its context; its entities count from 1.
pub const NODE_ID: u64 = 0;

/// The QoS every live topic is offered with, in rmw_zenoh's compact form
/// (`<reliability>:<durability>:<history>,<depth>:<deadline>:<lifespan>:<liveliness>`, a field
/// left empty when it is rmw's default; the depth is always written): reliable, volatile,
/// keep last 10, as the bag records them.
pub const QOS: &str = "::,10:,:,:,,";

/// A ROS 2 type's DDS name: `geometry_msgs/msg/PoseStamped` -> `geometry_msgs::msg::dds_::PoseStamped_`.
pub fn dds_type(m: MsgType) -> String {
    let (package, name) = crate::split_type(m);
    format!("{package}::msg::dds_::{name}_")
}

/// `/` -> `%`; an empty name is `%` (zenoh key chunks cannot be empty).
fn mangle(name: &str) -> String {
    if name.is_empty() {
        "%".to_owned()
    } else {
        name.replace('/', "%")
    }
}

/// The data key expression of topic `fqn` (e.g. `/cdm/agent_1/pose`) of type `m`.
pub fn topic_key(domain: u16, fqn: &str, m: MsgType) -> String {
    format!(
        "{domain}/{}/{}/{}",
        fqn.trim_start_matches('/'),
        dds_type(m),
        m.hash()
    )
}

/// The node's liveliness key in session `zid`.
pub fn node_token(domain: u16, zid: &str) -> String {
    format!(
        "{ADMIN_SPACE}/{domain}/{zid}/{NODE_ID}/{NODE_ID}/NN/{}/{}/{NODE_NAME}",
        mangle(""),
        mangle("/")
    )
}

/// The liveliness key of the node's publisher `entity` on topic `fqn` of type `m`.
pub fn publisher_token(domain: u16, zid: &str, entity: u64, fqn: &str, m: MsgType) -> String {
    format!(
        "{ADMIN_SPACE}/{domain}/{zid}/{NODE_ID}/{entity}/MP/{}/{}/{NODE_NAME}/{}/{}/{}/{QOS}",
        mangle(""),
        mangle("/"),
        mangle(fqn),
        dds_type(m),
        m.hash()
    )
}

/// An entity's GID from its liveliness key.
pub fn gid(token: &str) -> [u8; 16] {
    xxhash_rust::xxh3::xxh3_128(token.as_bytes()).to_le_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_follow_the_documented_form() {
        // design.md's example: `0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...`.
        assert_eq!(
            topic_key(0, "/chatter", MsgType::String),
            "0/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
        );
        assert_eq!(
            topic_key(3, "/cdm/agent_1/pose", MsgType::PoseStamped),
            format!(
                "3/cdm/agent_1/pose/geometry_msgs::msg::dds_::PoseStamped_/{}",
                MsgType::PoseStamped.hash()
            )
        );
        assert_eq!(
            node_token(2, "aac3"),
            "@ros2_lv/2/aac3/0/0/NN/%/%/cdm_orchestrator"
        );
        let t = publisher_token(2, "aac3", 4, "/cdm/audit", MsgType::String);
        assert_eq!(
            t,
            format!(
                "@ros2_lv/2/aac3/0/4/MP/%/%/cdm_orchestrator/%cdm%audit/std_msgs::msg::dds_::String_/{}/::,10:,:,:,,",
                MsgType::String.hash()
            )
        );
        assert_eq!(
            dds_type(MsgType::TfMessage),
            "tf2_msgs::msg::dds_::TFMessage_"
        );
    }

    #[test]
    fn the_gid_is_the_xxh3_128_of_the_token_low_half_first() {
        let h = xxhash_rust::xxh3::xxh3_128(b"@ros2_lv/0/z/0/1/MP");
        let g = gid("@ros2_lv/0/z/0/1/MP");
        assert_eq!(g[..8], (h as u64).to_le_bytes());
        assert_eq!(g[8..], ((h >> 64) as u64).to_le_bytes());
        assert_ne!(gid("a"), gid("b"));
    }
}
