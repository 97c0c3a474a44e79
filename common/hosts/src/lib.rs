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
pub mod daemon;
#[cfg(feature = "hosts")]
mod daemon_repair;
#[cfg(feature = "hosts")]
mod handover;
#[cfg(feature = "hosts")]
mod links;
#[cfg(feature = "hosts")]
mod placed;
#[cfg(feature = "hosts")]
mod plan;
#[cfg(feature = "hosts")]
mod repairs;
#[cfg(feature = "hosts")]
mod workdir;

#[cfg(feature = "hosts")]
pub use bridge::Bridge;
#[cfg(feature = "hosts")]
pub use plan::HostPlan;

use std::time::Duration;

/// How the team flies, as a daemon needs to know it to start its members.
#[derive(Debug, Clone, Copy)]
#[cfg_attr(not(feature = "hosts"), allow(dead_code))]
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
}

/// `launch`'s host options, validated.
#[derive(Debug, Clone)]
#[cfg_attr(not(feature = "hosts"), allow(dead_code))]
pub struct HostOptions {
    /// How many hosts share the team (1: this one only).
    pub hosts: u32,
    /// The zenoh endpoint daemons connect to (required when `hosts > 1`).
    pub listen: Option<String>,
    /// Silence on a host link for this long means the link is lost (a partition, a dead peer).
    pub link_timeout: Duration,
}

impl Default for HostOptions {
    fn default() -> Self {
        Self {
            hosts: 1,
            listen: None,
            link_timeout: Duration::from_secs(3),
        }
    }
}

/// Without the `hosts` feature: one host only, said clearly.
#[cfg(not(feature = "hosts"))]
mod single {
    use cdm_core::scenario::Scenario;
    use cdm_iox::TeamLayout;

    use super::HostOptions;
    use cdm_team::Failure;

    /// Every member runs here.
    pub struct HostPlan;

    /// Never built: no bridge without the feature.
    pub struct Bridge;

    impl HostPlan {
        pub fn remote_groups(&self) -> Vec<Vec<u32>> {
            Vec::new()
        }
        pub fn new(
            _s: &Scenario,
            h: &HostOptions,
            _team: &cdm_iox::TeamName,
            _quiet: bool,
        ) -> Result<Self, Failure> {
            if h.hosts > 1 {
                return Err(Failure::bad_input(
                    "--hosts: this orchestrator was built without the `hosts` feature (zenoh)",
                ));
            }
            Ok(HostPlan)
        }
        pub fn hide_remote_edges(&self, layout: TeamLayout) -> TeamLayout {
            layout
        }
        pub fn runs_here(&self, _id: u32) -> bool {
            true
        }
        pub fn start_bridge(
            &self,
            _s: &Scenario,
            _team: &cdm_iox::TeamName,
            _flight: super::TeamFlight,
        ) -> Result<Option<Bridge>, Failure> {
            Ok(None)
        }
    }

    impl Bridge {
        pub fn finish(self, _dir: &cdm_core::rundir::RunDir, _ticks: u64, _quiet: bool) {}
        pub fn explain(&self, f: cdm_core::audit::FaultRecord) -> cdm_core::audit::FaultRecord {
            f
        }
        pub fn reporting(&self, _id: u32) -> bool {
            false
        }
        pub fn kill(&self, _id: u32) {}
        pub fn host_of(&self, _id: u32) -> Option<u32> {
            None
        }
        pub fn take_exited(&self) -> Option<(u32, String)> {
            None
        }
        pub fn linked(&self, ports: &cdm_iox::OrchestratorPorts, reader: u32, writer: u32) -> bool {
            ports.linked(reader, writer).unwrap_or(false)
        }
    }
}
#[cfg(not(feature = "hosts"))]
pub use single::{Bridge, HostPlan};
