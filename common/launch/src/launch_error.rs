//! Why a launch could not fly its team or keep its records: one typed error, which the binary
//! maps to its message and exit code (bad input, or a fault of this machine).

use std::path::PathBuf;

use cdm_records::rundir::RunDirError;

/// Why a launch ended before its team flew, or could not write what it flew.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    /// The member binaries are not beside this one (or this one cannot be located).
    #[error(transparent)]
    MemberBinaries(#[from] cdm_team::team::MemberBinaryError),
    /// `--rt-priority`: this machine does not allow SCHED_FIFO at that priority.
    #[error(transparent)]
    Priority(#[from] cdm_process::sched::SchedError),
    /// `--serve`: the live view cannot serve on its address.
    #[error(transparent)]
    LiveView(#[from] cdm_viewer::ServeError),
    /// `--ros2`: the live ROS 2 topics cannot start (the environment, the backend).
    #[error(transparent)]
    Ros2(#[from] cdm_ros2::Ros2Error),
    /// `--foxglove`: the Foxglove server cannot start.
    #[error(transparent)]
    Foxglove(#[from] cdm_foxglove::FoxgloveError),
    /// `--hosts`: the team cannot be split over the hosts asked for.
    #[error(transparent)]
    HostPlan(#[from] cdm_hosts::error::PlanError),
    /// The team's services cannot be created (a team of this name runs, a bad layout...).
    #[error(transparent)]
    Ports(cdm_iox::TransportError),
    /// The team's layout is refused by the transport.
    #[error(transparent)]
    Layout(cdm_iox::TransportError),
    /// The bridge to the other hosts cannot start (`--hosts`, `--listen`).
    #[error(transparent)]
    Bridge(#[from] cdm_hosts::error::BridgeError),
    /// `--out`: the run directory cannot be made.
    #[error(transparent)]
    RunDir(RunDirError),
    /// A file of the run directory cannot be written (the scenario, audit.json).
    #[error(transparent)]
    Write(RunDirError),
    /// commands.json cannot be written.
    #[error(transparent)]
    Commands(#[from] crate::steer::WriteCommandsError),
    /// The channel `orchestrator command` reaches the team by cannot be opened.
    #[error(transparent)]
    Channel(#[from] crate::channel::ChannelError),
    /// A member's process cannot be started (`what` says why).
    #[error("cannot start agent {id}: {what}")]
    Spawn { id: u32, what: String },
    /// The run directory's recording folder cannot be made (`reason` names why).
    #[error("{}: {reason}", path.display())]
    RecordingDir { path: PathBuf, reason: String },
}
