//! A launch's error as this command ends with it: the operator's input (exit 2), or a fault of
//! this machine or of the run (exit 3).

use cdm_exit::Failure;
use cdm_hosts::error::BridgeError;
use cdm_launch::launch_error::LaunchError;
use cdm_team::team::MemberBinaryError;

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
        // An endpoint or its keys are the operator's to fix; the rest the bridge's fault.
        LaunchError::Bridge(b) => match b {
            #[cfg(feature = "hosts")]
            BridgeError::Endpoint(_) | BridgeError::Security(_) => Failure::bad_input(b),
            _ => Failure::fault(b),
        },
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
