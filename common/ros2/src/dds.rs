//! `--ros2 dds`: the topics over DDS/RTPS with ros2-client (RustDDS underneath; no ROS
//! install), as a node `/cdm_orchestrator` that ROS 2 nodes on rmw_fastrtps or rmw_cyclonedds
//! discover like any other. The messages are the bag's CDR bytes: ros2-client's CDR writer is
//! given the body after our 4-byte header (it writes the same CDR_LE header itself), byte for
//! byte, so what goes on the wire equals what the bag holds.

use std::net::{IpAddr, Ipv4Addr};

use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::dds::{Context, Node, Publisher};
use ros2_client::qos::{Durability, History, Reliability, WhenFull};
use ros2_client::{MessageTypeName, Name, NodeName, NodeOptions, QosProfile};
use serde::ser::{Serialize, SerializeTuple, Serializer};

use cdm_rosbag::msgs::MsgType;
use cdm_rosbag::Topic;

use crate::rmw_zenoh::NODE_NAME;
use crate::{Env, Publish, PublishError, Ros2Error};

/// A serialized message handed to ros2-client as is: its CDR body as a sequence of octets
/// written one after another (a tuple: no length, no padding), after the header ros2-client's
/// CDR_LE writer puts in front, which is the header our encoder wrote.
struct RawCdr(Vec<u8>);

/// The CDR_LE encapsulation header cdm-rosbag's encoder writes and RustDDS writes again.
const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

impl Serialize for RawCdr {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let body = self.0.get(CDR_LE.len()..).unwrap_or_default();
        let mut t = s.serialize_tuple(body.len())?;
        for b in body {
            t.serialize_element(b)?;
        }
        t.end()
    }
}

/// The participant, the node and a publisher per topic.
pub struct DdsOut {
    // Field order is drop order: the publishers go before the node and the participant.
    publishers: Vec<Publisher<RawCdr>>,
    _node: Node,
    _context: Context,
}

/// Reliable (a default rclpy or rclcpp subscription matches it), volatile, the last 10 kept:
/// rmw's default profile, which the bag records. A full send window drops the sample rather
/// than wait (the thread is ours alone, but a stalled reader must not back the queue up).
fn qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability(Reliability::Reliable {
            when_full: WhenFull::Fail,
        })
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
}

fn dds_error(
    what: impl Into<String>,
) -> impl FnOnce(Box<dyn std::error::Error + Send + Sync>) -> Ros2Error {
    let what = what.into();
    move |source| Ros2Error::Dds { what, source }
}

impl DdsOut {
    /// Joins DDS domain `ROS_DOMAIN_ID` (on loopback only with
    /// `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`) and offers each topic.
    pub fn open(env: &Env, topics: &[(Topic, String, MsgType)]) -> Result<Self, Ros2Error> {
        let mut builder = DomainParticipantBuilder::new(env.domain);
        if env.localhost_only {
            builder = builder.with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)]);
        }
        let participant = builder
            .build()
            .map_err(|e| dds_error(format!("a participant in domain {}", env.domain))(e.into()))?;
        let context = Context::from_domain_participant(participant)
            .map_err(|e| dds_error("a ROS 2 context")(e.into()))?;
        let name = NodeName::new("/", NODE_NAME).map_err(|e| dds_error("the node")(e.into()))?;
        // Output only: no rosout, no parameter services, nothing that could be written to.
        let options = NodeOptions::new()
            .enable_rosout(false)
            .start_parameter_services(false);
        let mut node = context
            .new_node(name, options)
            .map_err(|e| dds_error("the node")(e.into()))?;
        let mut publishers = Vec::with_capacity(topics.len());
        for (_, topic_name, msg) in topics {
            let what = || format!("a publisher on {topic_name}");
            let name = Name::parse(topic_name).map_err(|e| dds_error(what())(e.into()))?;
            let (package, ty) = crate::split_type(*msg);
            let topic = node
                .create_topic(&name, MessageTypeName::new(package, ty), &qos())
                .map_err(|e| dds_error(what())(e.into()))?;
            let publisher = node
                .create_publisher::<RawCdr>(&topic, None)
                .map_err(|e| dds_error(what())(e.into()))?;
            publishers.push(publisher);
        }
        Ok(DdsOut {
            publishers,
            _node: node,
            _context: context,
        })
    }
}

impl Publish for DdsOut {
    fn publish(&mut self, index: usize, cdr: &[u8]) -> Result<(), PublishError> {
        debug_assert_eq!(cdr.get(..4), Some(&CDR_LE[..]));
        let Some(p) = self.publishers.get(index) else {
            return Err(PublishError::NoTopic(index));
        };
        let sent = p.publish(RawCdr(cdr.to_vec()));
        sent.map_err(|e| PublishError::Dds(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use ros2_client::dds::rustdds::no_key::SerializerAdapter;
    use ros2_client::dds::rustdds::CDRSerializerAdapter;

    use cdm_math::Vec3;
    use cdm_records::audit::SafetyNumbers;
    use cdm_rosbag::{Limits, Team, Tick};
    use cdm_scenario::Scenario;

    use super::*;

    /// What the publishers' writer (RustDDS's CDR_LE adapter, as ros2-client's `Publisher`
    /// uses it) puts in a DATA submessage's payload: its encapsulation header, zero options,
    /// the body it serializes.
    fn on_the_wire(m: &RawCdr) -> Vec<u8> {
        let mut wire = CDRSerializerAdapter::<RawCdr>::output_encoding()
            .to_bytes()
            .to_vec();
        wire.extend_from_slice(&[0, 0]);
        wire.extend_from_slice(&CDRSerializerAdapter::<RawCdr>::to_bytes(m).unwrap());
        wire
    }

    #[test]
    fn the_wire_carries_the_bags_bytes_for_every_topic() {
        let s = Scenario::generated(6).unwrap();
        let team = Team::new(&s, Limits::from(&SafetyNumbers::of(&s)));
        let n = s.formation.members.len();
        let pos: Vec<Vec3> = (0..n)
            .map(|k| Vec3::new(k as f64 + 0.1, -2.5, 1.0 / 3.0))
            .collect();
        let alive = vec![true; n];
        let tick = Tick {
            tick: 12,
            t_s: 0.12,
            pos: &pos,
            ht: &pos,
            alive: &alive,
        };
        let mut messages = Vec::new();
        team.messages(&tick, &mut messages);
        assert_eq!(messages.len(), n + 3);
        for m in messages {
            assert_eq!(
                on_the_wire(&RawCdr(m.data.clone())),
                m.data,
                "{:?}",
                m.topic
            );
        }
    }
}
