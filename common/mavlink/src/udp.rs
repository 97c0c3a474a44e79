//! The thin I/O around [`MavlinkVehicle`]: one UDP socket per member, bound to `H:(P + i)`.
//! It locks onto the address of the vehicle's first accepted message (its HEARTBEAT) and from
//! then on decodes only what comes from there and sends only there; datagrams from anywhere
//! else, and datagrams larger than any vehicle's, are dropped undecoded and counted. It decodes
//! and encodes with the `mavlink` crate; every decision about messages is the vehicle's.
//!
//! Bounded per call, so that a flood cannot hold a tick: at most [`MAX_DATAGRAMS_PER_RECEIVE`]
//! datagrams read (a dropped one costs a system call and at most [`DATAGRAM_BYTES`] of copy)
//! and at most [`MAX_DECODED_BYTES_PER_RECEIVE`] bytes decoded; the rest waits for the next
//! tick (or is dropped by the kernel when the socket's buffer is full).

use std::io;
use std::net::{IpAddr, SocketAddr, UdpSocket};
use std::time::Duration;

use mavlink::dialects::common::MavMessage;
use mavlink::error::MessageReadError;
use mavlink::{MAVLinkMessageRaw, MavHeader, MavlinkReader, Message, SigningData};

use crate::messages::{MEMBER_COMPONENT_ID, MEMBER_SYSTEM_ID};
use crate::vehicle::MavlinkVehicle;

/// PX4 multi-vehicle SITL sends instance k's offboard link to UDP 14540 + k.
pub const DEFAULT_BASE_PORT: u16 = 14540;

/// The largest datagram taken for a vehicle's: a MAVLink 2 frame is at most 280 bytes, and an
/// autopilot packs several into at most one network MTU (1500 bytes on Ethernet, PX4's
/// mavlink buffer). A datagram that fills this buffer is larger and dropped (the kernel cuts
/// what does not fit), so a 64 KiB flood costs a 4 KiB copy per datagram.
const DATAGRAM_BYTES: usize = 4096;
/// Datagrams one `receive` reads at most (a vehicle sends a few per tick).
pub const MAX_DATAGRAMS_PER_RECEIVE: usize = 1024;
/// Bytes one `receive` decodes at most (a vehicle sends well under 1 KiB per tick at 50 Hz).
pub const MAX_DECODED_BYTES_PER_RECEIVE: usize = 64 * 1024;
/// The receive buffer asked of the kernel for a member's socket. The default (212,992 bytes,
/// `net.core.rmem_default`) holds three 64 KiB datagrams: a flood fills it within a few
/// milliseconds the member is not scheduled, and the kernel then drops the vehicle's own
/// packets with the flood's. The kernel grants at most `net.core.rmem_max` (212,992 bytes on a
/// stock kernel, so nothing more there unless an operator raises it).
pub const RECEIVE_BUFFER_BYTES: usize = 4 << 20;

/// What one [`UdpLink::receive`] took in.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Received {
    /// MAVLink messages decoded from the vehicle's datagrams.
    pub decoded: usize,
    /// Datagrams dropped undecoded: from another address than the vehicle's, or too large.
    pub foreign: u64,
}

/// The link's signing state (`--mavlink-signing-key`), if any.
struct Signing(SigningData);

impl std::fmt::Debug for Signing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Signing(..)")
    }
}

/// Why the member's UDP link failed.
#[derive(Debug, thiserror::Error)]
pub enum UdpError {
    /// `P + i` does not fit in a port number.
    #[error("agent {agent}: --mavlink-base-port {base_port} + member index {index} exceeds 65535")]
    PortOutOfRange {
        agent: u32,
        base_port: u16,
        index: u32,
    },
    /// The socket could not be bound (address in use, bad host).
    #[error("agent {agent}: cannot bind UDP {addr} for its vehicle")]
    Bind {
        agent: u32,
        addr: SocketAddr,
        #[source]
        source: io::Error,
    },
    /// Receiving or sending failed.
    #[error("agent {agent}: UDP {op} on {addr} failed")]
    Io {
        agent: u32,
        op: &'static str,
        addr: SocketAddr,
        #[source]
        source: io::Error,
    },
}

/// The address member `index` (scenario order, from 0) listens on: `host:(base_port + index)`.
pub fn member_addr(
    agent: u32,
    host: IpAddr,
    base_port: u16,
    index: u32,
) -> Result<SocketAddr, UdpError> {
    let port = u32::from(base_port)
        .checked_add(index)
        .and_then(|p| u16::try_from(p).ok())
        .ok_or(UdpError::PortOutOfRange {
            agent,
            base_port,
            index,
        })?;
    Ok(SocketAddr::new(host, port))
}

/// One member's socket.
#[derive(Debug)]
pub struct UdpLink {
    agent: u32,
    socket: UdpSocket,
    local: SocketAddr,
    /// The vehicle's address: where its first accepted message came from. Only datagrams from
    /// there are decoded, and replies go only there.
    peer: Option<SocketAddr>,
    sequence: u8,
    buf: Vec<u8>,
    /// The frame being sent (reused: a setpoint and a HEARTBEAT go out every tick).
    frame: Vec<u8>,
    /// With a key: every frame in and out is signed, and an unsigned or badly signed one is
    /// dropped before the vehicle sees it (so it cannot lock the address either).
    signing: Option<Signing>,
}

impl UdpLink {
    /// Bind `addr` (non-blocking: the caller's loop paces itself); with `signing`, only frames
    /// signed with its key are taken and every frame sent is signed.
    pub fn bind(
        agent: u32,
        addr: SocketAddr,
        signing: Option<SigningData>,
    ) -> Result<Self, UdpError> {
        let bind_err = |source| UdpError::Bind {
            agent,
            addr,
            source,
        };
        let socket = UdpSocket::bind(addr).map_err(bind_err)?;
        socket.set_nonblocking(true).map_err(bind_err)?;
        let local = socket.local_addr().map_err(bind_err)?;
        // Best effort: the kernel caps the size silently; the size granted is only logged.
        let sock = socket2::SockRef::from(&socket);
        let granted = sock
            .set_recv_buffer_size(RECEIVE_BUFFER_BYTES)
            .and_then(|()| sock.recv_buffer_size());
        tracing::debug!(agent, %local, ?granted, "receive buffer");
        Ok(UdpLink {
            agent,
            socket,
            local,
            peer: None,
            sequence: 0,
            buf: vec![0; DATAGRAM_BYTES],
            frame: Vec::with_capacity(300),
            signing: signing.map(Signing),
        })
    }

    /// The bound address.
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// The vehicle's address, once it has been heard.
    pub fn peer(&self) -> Option<SocketAddr> {
        self.peer
    }

    fn io_err(&self, op: &'static str, source: io::Error) -> UdpError {
        UdpError::Io {
            agent: self.agent,
            op,
            addr: self.local,
            source,
        }
    }

    /// Hand the datagrams waiting on the socket to `vehicle` as received at `now`. Frames with
    /// a bad checksum are skipped by the reader. Datagrams from another address than the
    /// vehicle's (once known) or too large to be its are dropped undecoded, each counted by the
    /// vehicle as foreign.
    pub fn receive(
        &mut self,
        now: Duration,
        vehicle: &mut MavlinkVehicle,
    ) -> Result<Received, UdpError> {
        let mut got = Received::default();
        let mut decoded_bytes = 0;
        // Bounded: a flood cannot keep the caller's tick from ending; the rest waits for the
        // next tick.
        for _ in 0..MAX_DATAGRAMS_PER_RECEIVE {
            if decoded_bytes >= MAX_DECODED_BYTES_PER_RECEIVE {
                break;
            }
            let (n, from) = match self.socket.recv_from(&mut self.buf) {
                Ok(got) => got,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                // A previous reply hit a closed port (ICMP): nothing to read, not a failure;
                // the loss detector decides whether the vehicle is gone.
                Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => continue,
                Err(e) => return Err(self.io_err("receive", e)),
            };
            if n >= self.buf.len() || self.peer.is_some_and(|p| p != from) {
                vehicle.on_foreign_datagram();
                got.foreign += 1;
                continue;
            }
            decoded_bytes += n;
            let mut reader = MavlinkReader::new(&self.buf[..n]);
            // Each read consumes at least one byte of the datagram, so this ends. Frames are
            // read raw (checksum checked), their signature checked, then decoded.
            loop {
                let raw = match reader.read_any_raw_message::<MavMessage>() {
                    Ok(raw) => raw,
                    Err(MessageReadError::Io(_)) => break,
                    Err(MessageReadError::Parse(e)) => {
                        tracing::debug!(agent = self.agent, %from, error = ?e, "undecodable MAVLink frame skipped");
                        continue;
                    }
                };
                if let Some(Signing(signing)) = &self.signing {
                    let signed = match &raw {
                        MAVLinkMessageRaw::V2(m) => signing.verify_signature(m),
                        MAVLinkMessageRaw::V1(_) => false,
                    };
                    if !signed {
                        vehicle.on_bad_signature();
                        continue;
                    }
                }
                let header = MavHeader {
                    system_id: raw.system_id(),
                    component_id: raw.component_id(),
                    sequence: raw.sequence(),
                };
                match MavMessage::parse(raw.version(), raw.message_id(), raw.payload()) {
                    Ok(msg) => {
                        got.decoded += 1;
                        if vehicle.on_message(now, &header, &msg) && self.peer.is_none() {
                            self.peer = Some(from);
                        }
                    }
                    Err(e) => {
                        tracing::debug!(agent = self.agent, %from, error = ?e, "undecodable MAVLink frame skipped");
                    }
                }
            }
        }
        Ok(got)
    }

    /// Encode `msgs` (MAVLink 2) and send them to the vehicle; nothing is sent before the
    /// vehicle has been heard (there is no address to send to).
    pub fn send(&mut self, msgs: &[MavMessage]) -> Result<(), UdpError> {
        let Some(peer) = self.peer else {
            return Ok(());
        };
        for msg in msgs {
            let header = MavHeader {
                system_id: u32::from(MEMBER_SYSTEM_ID),
                component_id: MEMBER_COMPONENT_ID,
                sequence: self.sequence,
            };
            self.sequence = self.sequence.wrapping_add(1);
            self.frame.clear();
            let signing = self.signing.as_ref().map(|Signing(s)| s);
            mavlink::write_v2_msg_signed(&mut self.frame, header, msg, signing)
                .map_err(|e| self.io_err("encode", io::Error::other(e.to_string())))?;
            match self.socket.send_to(&self.frame, peer) {
                Ok(_) => {}
                // A full socket buffer drops this frame: the next tick sends a fresher one.
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => {}
                Err(e) => return Err(self.io_err("send", e)),
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::VehicleConfig;
    use mavlink::dialects::common::{MavAutopilot, MavModeFlag, MavState, MavType, HEARTBEAT_DATA};
    use std::net::Ipv4Addr;

    fn beat_from(socket: &UdpSocket, to: SocketAddr, system_id: u32, autopilot: MavAutopilot) {
        let msg = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        });
        let header = MavHeader {
            system_id,
            component_id: 1,
            sequence: 0,
        };
        let mut frame = Vec::new();
        mavlink::write_v2_msg(&mut frame, header, &msg).unwrap();
        socket.send_to(&frame, to).unwrap();
    }

    /// Receive until `vehicle` has taken in `want` messages (bounded: loopback is immediate);
    /// returns the foreign datagrams the receives reported.
    fn receive_until(link: &mut UdpLink, vehicle: &mut MavlinkVehicle, want: u64) -> u64 {
        let mut foreign = 0;
        for _ in 0..1000 {
            foreign += link.receive(Duration::ZERO, vehicle).unwrap().foreign;
            let c = vehicle.counters();
            if c.heartbeats_received + c.ignored + c.foreign_packets >= want {
                return foreign;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        panic!("loopback heartbeats did not arrive");
    }

    #[test]
    fn replies_go_to_the_vehicle_not_to_other_senders() {
        let localhost = IpAddr::V4(Ipv4Addr::LOCALHOST);
        let mut link = UdpLink::bind(1, SocketAddr::new(localhost, 0), None).unwrap();
        let mut vehicle = MavlinkVehicle::new(VehicleConfig {
            agent: 1,
            frame: crate::VehicleFrame::default(),
            arm: false,
            connect_deadline: Duration::from_secs(5),
            timeouts: crate::health::LinkTimeouts::default(),
            min_battery_pct: None,
            takeoff: None,
            disarm_at_end: false,
        });
        let autopilot = UdpSocket::bind((localhost, 0)).unwrap();
        let gcs = UdpSocket::bind((localhost, 0)).unwrap();
        beat_from(
            &autopilot,
            link.local_addr(),
            1,
            MavAutopilot::MAV_AUTOPILOT_PX4,
        );
        receive_until(&mut link, &mut vehicle, 1);
        assert_eq!(link.peer(), Some(autopilot.local_addr().unwrap()));
        // A ground station on the same port does not steal the replies.
        beat_from(
            &gcs,
            link.local_addr(),
            255,
            MavAutopilot::MAV_AUTOPILOT_INVALID,
        );
        assert_eq!(receive_until(&mut link, &mut vehicle, 2), 1);
        assert_eq!(link.peer(), Some(autopilot.local_addr().unwrap()));
        // Another process sending the vehicle's own system id is not the vehicle either, nor is
        // a datagram larger than any vehicle's from the vehicle's address.
        beat_from(&gcs, link.local_addr(), 1, MavAutopilot::MAV_AUTOPILOT_PX4);
        autopilot.send_to(&[0u8; 9000], link.local_addr()).unwrap();
        assert_eq!(receive_until(&mut link, &mut vehicle, 4), 2);
        assert_eq!(vehicle.counters().heartbeats_received, 1);
        assert_eq!(vehicle.counters().foreign_packets, 3);
        assert_eq!(link.peer(), Some(autopilot.local_addr().unwrap()));
    }

    #[test]
    fn member_i_listens_on_base_plus_i() {
        let host = IpAddr::V4(Ipv4Addr::LOCALHOST);
        assert_eq!(
            member_addr(4, host, DEFAULT_BASE_PORT, 3).unwrap(),
            "127.0.0.1:14543".parse().unwrap()
        );
        let err = member_addr(4, host, 65_530, 6).unwrap_err();
        assert!(err
            .to_string()
            .starts_with("agent 4: --mavlink-base-port 65530"));
    }
}
