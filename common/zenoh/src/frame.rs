//! What travels between hosts, named by direction of travel: [`Down`] from the orchestrator's
//! bridge to a host's daemon, [`Up`] back, [`JoinRequest`] / [`JoinReply`] once when a daemon
//! joins. Every frame goes through the one codec pair [`encode`] / [`decode`] (postcard), so the
//! codec can be swapped in one place. The clock and the states are the shared-memory messages
//! themselves ([`ClockMsg`], [`StateMsg`]): one definition for iceoryx2 and for zenoh.

use std::collections::BTreeMap;

use cdm_runtime::messages::{ClockMsg, StateMsg};
use cdm_runtime::process_exit::ProcessExit;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// Bumped whenever a frame changes shape: a daemon of another version is refused by name.
pub const PROTOCOL_VERSION: u32 = 8;

/// Orchestrator -> daemon.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Down {
    /// A grant or the stop. Every clock message whose loss notice changed is sent, in order
    /// (members must see each loss); of the others only the newest.
    Clock(ClockMsg),
    /// States of other hosts' members that this host's members read (crossing edges), in the
    /// order they were published.
    States(Vec<StateMsg>),
    /// Nothing new; proves the link alive.
    Heartbeat,
    /// Kill this member of the host with SIGKILL (a scripted loss, `launch --lose`, or a
    /// member silent past the deadline under `--on-loss repair`).
    Kill(u32),
}

/// How a member process ended, as a daemon saw it ([`ProcessExit`] on the wire).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum NetExit {
    Code(i32),
    Signal(i32),
    Ended,
}

impl NetExit {
    /// `exit` as a daemon reports it: a host's loss is the orchestrator's own finding and
    /// never travels, so it has no wire form ([`NetExit::Ended`]).
    pub fn of(exit: &ProcessExit) -> Self {
        match *exit {
            ProcessExit::Code(c) => NetExit::Code(c),
            ProcessExit::Signal(s) => NetExit::Signal(s),
            ProcessExit::Ended | ProcessExit::WithHost { .. } => NetExit::Ended,
        }
    }
}

impl From<NetExit> for ProcessExit {
    fn from(e: NetExit) -> Self {
        match e {
            NetExit::Code(c) => ProcessExit::Code(c),
            NetExit::Signal(s) => ProcessExit::Signal(s),
            NetExit::Ended => ProcessExit::Ended,
        }
    }
}

/// Daemon -> orchestrator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Up {
    /// Every member of the host has opened its ports; the readers (node names) of each member's
    /// state service on the host, for `hosts.json`.
    Ready {
        subscriptions: BTreeMap<u32, Vec<String>>,
    },
    /// States (and fault reports) of this host's members, in the order they were published.
    States(Vec<StateMsg>),
    /// A member process exited before the stop.
    Exited { id: u32, how: NetExit },
    /// Nothing new; proves the link alive.
    Heartbeat,
    /// The daemon stopped its members after the orchestrator's stop and leaves.
    Stopped,
    /// Links (reader, writer) a repair opened, whose reader runs on this host, now connected
    /// on its shared memory.
    Linked(Vec<(u32, u32)>),
    /// Part of member `id`'s real-time recording (its `<id>.mcap`), read on the host after its
    /// members stopped and sent before [`Up::Stopped`], in order: the bytes go at `offset` of
    /// the run directory's copy, so a recording of any size crosses in bounded frames.
    Recording {
        id: u32,
        offset: u64,
        bytes: Vec<u8>,
    },
}

/// A daemon asks to join. Every field it gives must match the team's.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct JoinRequest {
    pub version: u32,
    /// `--team`, when given.
    pub team: Option<String>,
    /// `--host`, when given: which host of the team it wants to be (1..K).
    pub host: Option<u32>,
    /// The hash of `--scenario`, when given.
    pub scenario_hash: Option<u64>,
    /// Who asks (host name and process id), for messages.
    pub who: String,
}

/// What a daemon is told to run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Assignment {
    pub team: String,
    /// This daemon's host number (the orchestrator's host is 0).
    pub host: u32,
    /// Every member's host, in formation order.
    pub hosts_of: Vec<(u32, u32)>,
    /// The scenario as JSON (the members' form, same hash).
    pub scenario_json: String,
    pub scenario_hash: u64,
    pub window: u32,
    /// No frame from the orchestrator for this long: the link is lost.
    pub link_timeout_ms: u64,
    /// Real time (`launch --realtime`): the members' `--stale-after`, in seconds. The start
    /// instant comes later, as a wall-clock (UNIX) time in the clock's `Realtime` message, so
    /// members on every host pace on the same instant.
    pub realtime_stale_after_s: Option<f64>,
    /// Real time with `--rt-priority P`: the daemon and its members run under SCHED_FIFO at P,
    /// as the orchestrator's host does.
    pub realtime_priority: Option<u8>,
    /// `--on-loss repair`: the host's services keep room for repairs, and a member that exits
    /// is lost and repaired around rather than a fault.
    pub repair: bool,
    /// Real time with recording on (the default; `--no-recording` off): the members record
    /// the states their ticks flew on, and the daemon sends the recordings up at the end.
    pub record: bool,
}

/// The orchestrator's answer to a [`JoinRequest`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum JoinReply {
    Accepted(Box<Assignment>),
    /// Why not, naming the field at fault.
    Refused(String),
}

/// A frame that could not be decoded (another version, a foreign peer, garbage).
#[derive(Debug, thiserror::Error)]
#[error("undecodable frame ({len} bytes): {source}")]
pub struct DecodeError {
    len: usize,
    #[source]
    source: postcard::Error,
}

/// Encodes a frame (the one place that names the codec).
pub fn encode<T: Serialize>(frame: &T) -> Vec<u8> {
    // postcard fails only on types serde cannot describe as data; ours are plain data.
    postcard::to_stdvec(frame).unwrap_or_default()
}

/// Decodes a frame encoded by [`encode`].
pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, DecodeError> {
    postcard::from_bytes(bytes).map_err(|source| DecodeError {
        len: bytes.len(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_runtime::messages::LossNotice;

    #[test]
    fn frames_round_trip_bit_for_bit() {
        let s = StateMsg::ok(
            7,
            0xfeed,
            3,
            [
                0.1,
                -0.0,
                1e-300,
                f64::MAX,
                5.0,
                6.0,
                7.0,
                8.0,
                9.0,
                10.0,
                11.0,
                12.0,
            ],
        );
        let f = Down::States(vec![s]);
        let back: Down = decode(&encode(&f)).unwrap();
        let Down::States(v) = back else {
            panic!("not states")
        };
        let m = v[0];
        assert_eq!(m.tick, 7);
        for (a, b) in m.state.iter().zip(s.state.iter()) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
        let c = ClockMsg::run(9, 1);
        let back: Down = decode(&encode(&Down::Clock(c))).unwrap();
        assert_eq!(back, Down::Clock(c));
    }

    /// The bytes of protocol 7: the message encodes its fields in declaration order, and its
    /// padding never travels.
    #[test]
    fn the_clock_message_keeps_the_bytes_of_its_protocol() {
        let notice = LossNotice {
            seq: 2,
            id: 7,
            tick: 300,
            linked: 1,
        };
        let mut c = ClockMsg::run(9, 1).with_loss(Some(notice));
        c.reserved = 5;
        let bytes = encode(&Down::Clock(c));
        // variant 0, grant 9, hash 1, command 0, reason 0, loss tick 300 (varint), seq, id,
        // linked; then no command: its tick, seq and kind (varints), 10 f64 of 8 bytes
        assert_eq!(bytes[..13], [0, 9, 1, 0, 0, 0xac, 0x02, 2, 7, 1, 0, 0, 0]);
        assert_eq!(bytes.len(), 13 + 10 * 8);
        let back: Down = decode(&bytes).unwrap();
        c.reserved = 0;
        assert_eq!(back, Down::Clock(c));
        let s = StateMsg::ok(1, 2, 3, [0.5; 12]);
        let bytes = encode(&Up::States(vec![s]));
        // variant 1, one state: tick, hash, id, status, code, peer (varints), 12 f64 of 8 bytes
        // (the peer, none, is u32::MAX: a varint of 5 bytes)
        assert_eq!(bytes.len(), 2 + 5 + 5 + 12 * 8);
        assert_eq!(
            bytes[..12],
            [1, 1, 1, 2, 3, 0, 0, 0xff, 0xff, 0xff, 0xff, 0x0f]
        );
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        assert!(decode::<Up>(&[0xff, 0xff, 0xff]).is_err());
        assert!(decode::<JoinRequest>(&[]).is_err());
    }
}
