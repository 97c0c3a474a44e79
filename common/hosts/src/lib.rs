//! One team on several machines. `launch --hosts K --listen ENDPOINT` keeps host 0's
//! share of the formation on this machine and serves the others to `orchestrator host --connect
//! ENDPOINT` daemons over zenoh (crate cdm-zenoh, behind the default `hosts` feature).
//!
//! Members never see the network: every host runs the team's iceoryx2 services, and a bridge
//! re-publishes what crosses hosts into them through relay ports (`MemberPorts::open_relay`,
//! node `cdm/<team>/host/<k>/agent/<id>`): on the orchestrator's host the bridge stands in for
//! every remote member (its states, for the audit and for local readers); on host k the daemon
//! stands in for the other hosts' members that host k's members read, and publishes the clock.
//! `--hosts 1` (the default) opens no socket and changes nothing.

#[cfg(feature = "hosts")]
mod bridge;
#[cfg(feature = "hosts")]
mod bridge_core;
#[cfg(feature = "hosts")]
pub mod daemon;
#[cfg(feature = "hosts")]
mod daemon_core;
#[cfg(feature = "hosts")]
mod daemon_repair;
pub mod error;
#[cfg(feature = "hosts")]
mod handover;
pub mod host_link;
pub mod idle;
#[cfg(feature = "hosts")]
mod links;
pub mod notice;
mod other_hosts;
mod placed;
mod plan;
pub mod regions;
#[cfg(feature = "hosts")]
mod relay;
#[cfg(feature = "hosts")]
mod repairs;
#[cfg(feature = "hosts")]
mod security;
pub mod transport;
#[cfg(feature = "hosts")]
mod workdir;

#[cfg(feature = "hosts")]
pub use bridge::Bridge;
pub use notice::HostNotice;
pub use other_hosts::{OneHost, OtherHosts};
pub use plan::HostPlan;
pub use regions::{Placed, Regions};
pub use transport::Transport;

use std::time::Duration;

/// How the team flies, as a daemon needs to know it to start its members.
#[derive(Debug, Clone)]
pub struct TeamFlight {
    /// The clock window (ticks of states kept per subscriber).
    pub window: u32,
    /// `--realtime`: the members' `--stale-after`.
    pub realtime_stale_after: Option<Duration>,
    /// `--realtime --rt-priority P`: P.
    pub realtime_priority: Option<u8>,
    /// Lost members are repaired around (`--on-loss repair` with spawned members, lockstep:
    /// real time repairs nothing, an exit stays a fault there as on one host).
    pub repair: bool,
    /// Real time with recording on: where the other hosts' members' recordings go (the run
    /// directory's recording folder), as their daemons send them at the end.
    pub recording: Option<std::path::PathBuf>,
}

/// `launch`'s host options, validated.
#[derive(Debug, Clone)]
pub struct HostOptions {
    /// How many hosts share the team (1: this one only).
    pub hosts: u32,
    /// The zenoh endpoint daemons connect to (required when `hosts > 1`).
    pub listen: Option<String>,
    /// Silence on a host link for this long means the link is lost (a partition, a dead peer).
    pub link_timeout: Duration,
    /// Mutual TLS with `--keys`, or plain TCP with `--insecure`.
    pub transport: Transport,
}

impl Default for HostOptions {
    fn default() -> Self {
        Self {
            hosts: 1,
            listen: None,
            link_timeout: Duration::from_secs(3),
            transport: Transport::Insecure,
        }
    }
}
