//! A launch's error as this command ends with it: the operator's input (exit 2), or a fault of
//! this machine or of the run (exit 3).

use cdm_launch::launch_error::LaunchError;
use cdm_team::team::MemberBinaryError;
use cdm_team::Failure;

/// The exit code of each launch error; the message is the error's own.
pub fn launch_failure(e: LaunchError) -> Failure {
    match e {
        LaunchError::MemberBinaries(MemberBinaryError::Missing { .. })
        | LaunchError::Priority(_)
        | LaunchError::LiveView(_)
        | LaunchError::Ros2(_)
        | LaunchError::Foxglove(_)
        | LaunchError::HostPlan(_)
        | LaunchError::Ports(_) => Failure::bad_input(e),
        LaunchError::Bridge(b) => Failure::from(b),
        // A full disk is a fault; a file in the way or a permission, the operator's input.
        LaunchError::RunDir(d) => Failure::from(d),
        LaunchError::MemberBinaries(MemberBinaryError::Locate(_))
        | LaunchError::Layout(_)
        | LaunchError::Write(_)
        | LaunchError::Commands(_)
        | LaunchError::Channel(_)
        | LaunchError::Spawn { .. }
        | LaunchError::RecordingDir { .. } => Failure::fault(e),
    }
}
