//! `--arm` on the team's order: the mode change and the arm command once all
//! vehicles report ready. A member joins its team only once its vehicle is heard, so the
//! orchestrator knows every vehicle is ready when every member has joined; it then sends
//! [`COMMAND_ARM`](cdm_runtime::messages::COMMAND_ARM) once. Each member switches its vehicle
//! to OFFBOARD/GUIDED and arms it (the plant's `--arm` sequence), answers with
//! [`StateMsg::arm_report`], and the orchestrator announces the start once every member has
//! answered. This is the member's side, between joining and the real-time core: the decisions
//! are in [`ArmWait`] (no I/O); [`before_start`] moves messages and sleeps.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use cdm_runtime::member_core::ALIVE_CHECK;
use cdm_runtime::member_loop::linger;
use cdm_runtime::messages::{AgentStatus, ClockCommand, ClockMsg, FaultCode, StateMsg};
use cdm_runtime::seams::{Clock, MemberTransport, Vehicle, VehicleFault};

use crate::plant::{ArmProgress, MavlinkPlant};

/// How long one wait for the clock lasts at most (bounds how late the vehicle is checked).
const POLL: Duration = Duration::from_millis(20);

/// Why a member stopped before its team started.
#[derive(Debug, thiserror::Error)]
pub enum TeamArmError<E: std::error::Error + 'static> {
    #[error("agent {agent}: the transport failed while waiting for the team's arm order")]
    Transport {
        agent: u32,
        #[source]
        source: E,
    },
    /// The vehicle was lost or refused the mode change or arming (`what` names the member).
    #[error("{what} (before the start)")]
    Vehicle { agent: u32, what: String },
    /// This member has `--arm` but the orchestrator started the flight without the arm order.
    #[error("agent {agent}: started with --arm, but the orchestrator started the flight without ordering the vehicles armed: launch it with --arm too")]
    NotOrdered { agent: u32 },
    #[error("agent {agent}: the orchestrator is gone (before the start); stopping")]
    OrchestratorLost { agent: u32 },
    #[error("agent {agent}: no arm order or start within {waited:?}; stopping")]
    Silent { agent: u32, waited: Duration },
    #[error("agent {agent}: interrupted before the start")]
    Interrupted { agent: u32 },
}

/// What the member does next, as [`ArmWait`] decides it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Next {
    /// Nothing yet: wait for the clock (at most `POLL`).
    Wait,
    /// The order arrived: start the plant's `--arm` sequence.
    OrderArm,
    /// Answer the order: `armed` (false: this member only streams).
    Answer { armed: bool },
    /// A clock message for the real-time core (the start, a stop, another scenario's order).
    HandOver(ClockMsg),
    /// `--arm` without the order: the team started without arming.
    NotOrdered,
    /// No order or start before the deadline.
    Silent,
}

/// The member's wait for the arm order, without I/O.
#[derive(Debug, Clone)]
pub struct ArmWait {
    hash: u64,
    /// This member has `--arm`.
    arms: bool,
    ordered: bool,
    answered: bool,
    /// When waiting (for the order, then for the start) gives up.
    deadline: Duration,
    join: Duration,
}

impl ArmWait {
    /// A member of the team with scenario `hash`; `join` bounds each wait (for the order, and
    /// after the answer for the start), counted from `now`.
    pub fn new(hash: u64, arms: bool, join: Duration, now: Duration) -> Self {
        ArmWait {
            hash,
            arms,
            ordered: false,
            answered: false,
            deadline: now.saturating_add(join),
            join,
        }
    }

    /// A clock message arrived.
    pub fn on_clock(&mut self, c: &ClockMsg) -> Next {
        match c.command() {
            ClockCommand::Arm if c.scenario_hash == self.hash => {
                if self.ordered {
                    return Next::Wait;
                }
                self.ordered = true;
                Next::OrderArm
            }
            ClockCommand::Realtime { .. } if self.arms && !self.answered => Next::NotOrdered,
            _ => Next::HandOver(*c),
        }
    }

    /// Nothing arrived at `now`; `progress` is the plant's `--arm` state.
    pub fn on_idle(&mut self, now: Duration, progress: ArmProgress) -> Next {
        if self.ordered && !self.answered {
            // The arming is bounded by the plant's own retries (a refusal is a link fault).
            let armed = match progress {
                ArmProgress::Pending => return Next::Wait,
                ArmProgress::Armed => true,
                ArmProgress::StreamOnly => false,
            };
            self.answered = true;
            self.deadline = now.saturating_add(self.join);
            return Next::Answer { armed };
        }
        if now >= self.deadline {
            return Next::Silent;
        }
        Next::Wait
    }
}

/// Between joining and the real-time core: answers the team's arm order, and returns the first
/// clock message that is the core's (the start, or a stop). The wait is bounded by `join`
/// before the order and after the answer, and by the plant's retries in between. A vehicle
/// lost meanwhile is reported to the team (a `VehicleLost` fault) before the error returns.
pub fn before_start<T, K>(
    plant: &MavlinkPlant<'_>,
    hash: u64,
    transport: &mut T,
    clock: &K,
    join: Duration,
    interrupted: &AtomicBool,
) -> Result<ClockMsg, TeamArmError<T::Error>>
where
    T: MemberTransport,
    T::Error: std::error::Error + 'static,
    K: Clock,
{
    let agent = plant.agent();
    let mut wait = ArmWait::new(hash, plant.arms(), join, clock.now());
    let mut last_alive_check = clock.now();
    let io = |source| TeamArmError::Transport { agent, source };
    loop {
        if interrupted.load(Ordering::Relaxed) {
            return Err(TeamArmError::Interrupted { agent });
        }
        let progress = match plant.arm_progress() {
            Ok(p) => p,
            Err(fault) => {
                let who = (plant, hash);
                return Err(report_fault(who, transport, clock, interrupted, fault));
            }
        };
        let next = match transport.latest_clock().map_err(io)? {
            Some(c) => wait.on_clock(&c),
            None => wait.on_idle(clock.now(), progress),
        };
        match next {
            Next::Wait => {}
            Next::OrderArm => {
                tracing::info!(agent, "the team's arm order: switching mode and arming");
                plant.order_arm();
            }
            Next::Answer { armed } => {
                tracing::info!(agent, armed, "answering the arm order");
                transport
                    .publish(StateMsg::arm_report(0, hash, agent, armed))
                    .map_err(io)?;
            }
            Next::HandOver(c) => return Ok(c),
            Next::NotOrdered => return Err(TeamArmError::NotOrdered { agent }),
            Next::Silent => {
                let waited = join;
                return Err(TeamArmError::Silent { agent, waited });
            }
        }
        if clock.now().saturating_sub(last_alive_check) >= ALIVE_CHECK {
            last_alive_check = clock.now();
            if !transport.orchestrator_alive() {
                return Err(TeamArmError::OrchestratorLost { agent });
            }
        }
        transport.wait(POLL).map_err(io)?;
    }
}

/// Tells the team the vehicle is lost (its last measured state, flagged), keeps the report
/// readable until the orchestrator stops the team (bounded), and returns the error.
fn report_fault<T, K, E>(
    (plant, hash): (&MavlinkPlant<'_>, u64),
    transport: &mut T,
    clock: &K,
    interrupted: &AtomicBool,
    fault: VehicleFault,
) -> TeamArmError<E>
where
    T: MemberTransport,
    K: Clock,
    E: std::error::Error + 'static,
{
    let agent = plant.agent();
    let lost = AgentStatus::Fault {
        code: FaultCode::VehicleLost,
        peer: None,
    };
    let msg = StateMsg::ok(0, hash, agent, plant.state()).with_status(lost);
    if transport.publish(msg).is_ok() {
        linger(transport, clock, interrupted);
    }
    TeamArmError::Vehicle {
        agent,
        what: fault.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HASH: u64 = 77;

    fn s(v: f64) -> Duration {
        Duration::from_secs_f64(v)
    }

    #[test]
    fn the_order_then_the_answer_then_the_start() {
        let mut w = ArmWait::new(HASH, true, s(10.0), s(0.0));
        assert_eq!(w.on_idle(s(1.0), ArmProgress::Pending), Next::Wait);
        assert_eq!(w.on_clock(&ClockMsg::arm(HASH)), Next::OrderArm);
        // A repeated order changes nothing; no answer before the vehicle is armed.
        assert_eq!(w.on_clock(&ClockMsg::arm(HASH)), Next::Wait);
        assert_eq!(w.on_idle(s(30.0), ArmProgress::Pending), Next::Wait);
        assert_eq!(
            w.on_idle(s(31.0), ArmProgress::Armed),
            Next::Answer { armed: true }
        );
        assert_eq!(w.on_idle(s(32.0), ArmProgress::Armed), Next::Wait);
        let start = ClockMsg::realtime(5, HASH, 1);
        assert_eq!(w.on_clock(&start), Next::HandOver(start));
    }

    #[test]
    fn a_member_without_arm_answers_at_once_and_hands_over_an_unordered_start() {
        let mut w = ArmWait::new(HASH, false, s(10.0), s(0.0));
        let start = ClockMsg::realtime(5, HASH, 1);
        assert_eq!(w.clone().on_clock(&start), Next::HandOver(start));
        assert_eq!(w.on_clock(&ClockMsg::arm(HASH)), Next::OrderArm);
        assert_eq!(
            w.on_idle(s(1.0), ArmProgress::StreamOnly),
            Next::Answer { armed: false }
        );
    }

    #[test]
    fn arm_without_the_order_is_refused_and_waits_are_bounded() {
        let mut w = ArmWait::new(HASH, true, s(10.0), s(0.0));
        assert_eq!(
            w.on_clock(&ClockMsg::realtime(5, HASH, 1)),
            Next::NotOrdered
        );
        assert_eq!(w.on_idle(s(9.9), ArmProgress::Pending), Next::Wait);
        assert_eq!(w.on_idle(s(10.0), ArmProgress::Pending), Next::Silent);
        // Another scenario's order goes to the core, which names the mismatch.
        let foreign = ClockMsg::arm(HASH + 1);
        assert_eq!(w.on_clock(&foreign), Next::HandOver(foreign));
        // A stop is the core's too.
        let stop = ClockMsg::stop(0, HASH, cdm_runtime::messages::StopReason::Interrupted);
        assert_eq!(w.on_clock(&stop), Next::HandOver(stop));
    }
}
