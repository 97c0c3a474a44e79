//! What a launch sees of the team's other hosts, one seam for every team: [`OneHost`] when the
//! whole team runs here (`--hosts 1`, and every build without the `hosts` feature), the bridge
//! (`crate::Bridge`) when daemons on other machines run part of it. The launch asks the same
//! questions of both, so no code path of its own depends on how many hosts there are.

use cdm_iox::OrchestratorPorts;
use cdm_records::audit::FaultRecord;
use cdm_records::rundir::RunDir;
use cdm_runtime::process_exit::ProcessExit;

/// The other hosts of a team, as the launch asks about them.
pub trait OtherHosts {
    /// The team's fault, said in the terms of hosts (a remote member's silence names its host).
    fn explain(&self, f: FaultRecord) -> FaultRecord;
    /// True when member `id` runs on another host whose reports may still arrive.
    fn reporting(&self, id: u32) -> bool;
    /// The host member `id` runs on when the team has several (host 0 is this one); `None`
    /// with one host, where audit.json's losses name no host.
    fn host_of(&self, id: u32) -> Option<u32>;
    /// The team core's kill of member `id` (another host's member is its daemon's to kill).
    fn kill(&self, id: u32);
    /// A remote member that exited since the last call (`--on-loss repair`), with how.
    fn take_exited(&self) -> Option<(u32, ProcessExit)>;
    /// True when the link (reader, writer) a repair opened is connected.
    fn linked(&self, ports: &OrchestratorPorts, reader: u32, writer: u32) -> bool;
    /// After the team's stop: the other hosts stop their members; their record is written
    /// into the run directory (and their traffic told to the launch's notices).
    fn finish(self: Box<Self>, dir: &RunDir, ticks: u64);
}

/// The whole team on this host: no other host to ask, links only on this host's memory.
#[derive(Debug, Clone, Copy, Default)]
pub struct OneHost;

impl OtherHosts for OneHost {
    fn explain(&self, f: FaultRecord) -> FaultRecord {
        f
    }
    fn reporting(&self, _id: u32) -> bool {
        false
    }
    fn host_of(&self, _id: u32) -> Option<u32> {
        None
    }
    fn kill(&self, _id: u32) {}
    fn take_exited(&self) -> Option<(u32, ProcessExit)> {
        None
    }
    fn linked(&self, ports: &OrchestratorPorts, reader: u32, writer: u32) -> bool {
        ports.linked(reader, writer).unwrap_or(false)
    }
    fn finish(self: Box<Self>, _dir: &RunDir, _ticks: u64) {}
}
