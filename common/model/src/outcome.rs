//! Typed outcomes of a run: the verdict, the kind of a fault that ended it, why a member was
//! lost and which condition a violation breaks. They are compared as enums everywhere and
//! become text only at the edge (audit.json, the certificate, stdout), with the very strings
//! those files had when they were `&str`.

use std::fmt;

use serde::{Deserialize, Serialize};

/// The verdict of a run (audit.json) or of a pre-flight certificate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Verdict {
    /// Every audited condition held over a complete run (or the certificate found no reason).
    #[serde(rename = "SAFE")]
    Safe,
    /// A safety condition failed (a violation, or a certificate reason).
    #[serde(rename = "UNSAFE")]
    Unsafe,
    /// The run did not complete: a runtime fault ended it.
    #[serde(rename = "FAULT")]
    Fault,
}

impl Verdict {
    /// The text audit.json and stdout carry.
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Safe => "SAFE",
            Verdict::Unsafe => "UNSAFE",
            Verdict::Fault => "FAULT",
        }
    }
}

/// What kind of runtime fault ended a run (`fault.kind` in audit.json, read back by `replay`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FaultKind {
    /// The controller refused to fly on, or a neighbour's state was non-finite (eq. 46).
    Control,
    /// A member reported a fault of its own (its wire code is in the message).
    AgentFault,
    /// A member published a non-finite state and no reader reported it.
    NonFiniteState,
    /// A member sent nothing for the next tick before the deadline.
    AgentSilent,
    /// A member was lost (`--lose`) and the policy is `--on-loss stop`.
    Lost,
    /// A spawned member process exited before the end.
    AgentExited,
    /// A member process could not be started.
    SpawnFailed,
    /// Members did not join the team before the deadline.
    JoinTimeout,
    /// The shared-memory transport failed.
    Transport,
    /// Writing the run directory failed.
    Io,
    /// SIGINT, SIGTERM, SIGHUP or SIGQUIT.
    Interrupted,
    /// A member lost its real vehicle (`--vehicles mavlink`: no HEARTBEAT for 1 s, no position
    /// for 0.5 s, or it refused to arm).
    VehicleLost,
    /// The orchestrator itself did not run for a while (stopped or starved): its clock stalled
    /// and the members stopped by themselves.
    OrchestratorStalled,
    /// Across hosts: a host's daemon was lost (killed, exited, or cut off by a partition), and
    /// every member it ran with it.
    HostLost,
}

impl FaultKind {
    /// The text audit.json carries.
    pub fn as_str(self) -> &'static str {
        match self {
            FaultKind::Control => "control",
            FaultKind::AgentFault => "agent-fault",
            FaultKind::NonFiniteState => "non-finite-state",
            FaultKind::AgentSilent => "agent-silent",
            FaultKind::Lost => "lost",
            FaultKind::AgentExited => "agent-exited",
            FaultKind::SpawnFailed => "spawn-failed",
            FaultKind::JoinTimeout => "join-timeout",
            FaultKind::Transport => "transport",
            FaultKind::Io => "io",
            FaultKind::Interrupted => "interrupted",
            FaultKind::OrchestratorStalled => "orchestrator-stalled",
            FaultKind::VehicleLost => "vehicle-lost",
            FaultKind::HostLost => "host-lost",
        }
    }
}

/// Why a member was lost in flight (`losses[].cause` in audit.json, read back by `replay`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LossCause {
    /// `--lose ID@SECONDS`: `simulate` drops it; `launch` kills it once it published that tick.
    Scripted,
    /// Killed by a signal from outside the team.
    Killed,
    /// Its process ended by itself.
    Exited,
    /// It sent nothing for `--agent-timeout` (real time: `--stale-after`); the orchestrator
    /// killed it.
    Silent,
    /// Its MAVLink vehicle was lost: no HEARTBEAT or position in time, a low battery, the
    /// autopilot's own failsafe state (real time, `--vehicles mavlink`).
    VehicleLost,
    /// Its MAVLink vehicle left OFFBOARD/GUIDED after it was engaged: a pilot, a mode switch or
    /// an autopilot failsafe took it over.
    VehicleMode,
    /// Its MAVLink vehicle was disarmed in flight.
    VehicleDisarmed,
}

impl LossCause {
    /// The text audit.json carries.
    pub fn as_str(self) -> &'static str {
        match self {
            LossCause::Scripted => "scripted",
            LossCause::Killed => "killed",
            LossCause::Exited => "exited",
            LossCause::Silent => "silent",
            LossCause::VehicleLost => "vehicle-lost",
            LossCause::VehicleMode => "vehicle-mode",
            LossCause::VehicleDisarmed => "vehicle-disarmed",
        }
    }
}

/// Which safety condition a violation breaks (`violations[].kind` in audit.json; Sec. VI).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ViolationKind {
    /// Two members closer than 2 eps.
    Collision,
    /// A follower outside the containment prism (Theorem 3).
    Containment,
    /// ||r_i - r_i,HT||_2 > delta (eq. 34).
    Tracking,
    /// lambda_1(U_D) < lambda_CD,min (eq. 37).
    Deformation,
    /// A member's ball of radius eps beyond the geofence.
    Geofence,
    /// A member's ball of radius eps inside an obstacle.
    Obstacle,
    /// A member flew faster or accelerated harder than its `[vehicle]` limit (named by key).
    Limit,
}

impl ViolationKind {
    /// The text audit.json carries.
    pub fn as_str(self) -> &'static str {
        match self {
            ViolationKind::Collision => "collision",
            ViolationKind::Containment => "containment",
            ViolationKind::Tracking => "tracking",
            ViolationKind::Deformation => "deformation",
            ViolationKind::Geofence => "geofence",
            ViolationKind::Obstacle => "obstacle",
            ViolationKind::Limit => "limit",
        }
    }
}

/// Each outcome displays as the text audit.json carries (`as_str`).
macro_rules! display_as_str {
    ($($t:ty),*) => {$(
        impl fmt::Display for $t {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.as_str())
            }
        }
    )*};
}

display_as_str!(Verdict, FaultKind, LossCause, ViolationKind);

#[cfg(test)]
mod tests {
    use super::*;

    const KINDS: [FaultKind; 14] = [
        FaultKind::Control,
        FaultKind::AgentFault,
        FaultKind::NonFiniteState,
        FaultKind::AgentSilent,
        FaultKind::AgentExited,
        FaultKind::SpawnFailed,
        FaultKind::JoinTimeout,
        FaultKind::Transport,
        FaultKind::Io,
        FaultKind::Interrupted,
        FaultKind::OrchestratorStalled,
        FaultKind::Lost,
        FaultKind::VehicleLost,
        FaultKind::HostLost,
    ];

    #[test]
    fn serialised_text_is_the_display_text() {
        for k in KINDS {
            assert_eq!(
                serde_json::to_string(&k).unwrap(),
                format!("\"{}\"", k.as_str())
            );
        }
        for c in [
            LossCause::Scripted,
            LossCause::Killed,
            LossCause::Exited,
            LossCause::Silent,
            LossCause::VehicleLost,
            LossCause::VehicleMode,
            LossCause::VehicleDisarmed,
        ] {
            assert_eq!(
                serde_json::to_string(&c).unwrap(),
                format!("\"{}\"", c.as_str())
            );
        }
        for v in [
            ViolationKind::Collision,
            ViolationKind::Containment,
            ViolationKind::Tracking,
            ViolationKind::Deformation,
            ViolationKind::Geofence,
            ViolationKind::Obstacle,
            ViolationKind::Limit,
        ] {
            assert_eq!(
                serde_json::to_string(&v).unwrap(),
                format!("\"{}\"", v.as_str())
            );
        }
        for v in [Verdict::Safe, Verdict::Unsafe, Verdict::Fault] {
            assert_eq!(
                serde_json::to_string(&v).unwrap(),
                format!("\"{}\"", v.as_str())
            );
        }
    }

    #[test]
    fn audit_json_strings_are_unchanged() {
        // The strings audit.json had before the enums (readers and tests match on them).
        let text: Vec<&str> = KINDS.iter().map(|k| k.as_str()).collect();
        assert_eq!(
            text,
            [
                "control",
                "agent-fault",
                "non-finite-state",
                "agent-silent",
                "agent-exited",
                "spawn-failed",
                "join-timeout",
                "transport",
                "io",
                "interrupted",
                "orchestrator-stalled",
                "lost",
                "vehicle-lost",
                "host-lost"
            ]
        );
        assert_eq!(
            serde_json::to_string(&Verdict::Unsafe).unwrap(),
            "\"UNSAFE\""
        );
    }
}
