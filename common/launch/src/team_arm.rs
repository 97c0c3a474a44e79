//! `launch --arm`: the vehicles are armed when ALL report ready. A MAVLink member
//! joins its team only once its vehicle is heard (HEARTBEAT and position), so once the team has
//! gathered every vehicle is ready: the orchestrator then sends the arm order
//! (`ClockMsg::arm`) once, waits until every member answers (`StateMsg::arm_report`: armed, or
//! streaming only without `--arm`), and only then announces the start. The decisions are in
//! [`ArmRoll`] (no I/O); [`arm_team`] moves messages and sleeps.

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use cdm_iox::OrchestratorPorts;
use cdm_member::vehicles::Vehicles;
use cdm_model::outcome::FaultKind;
use cdm_runtime::messages::{AgentStatus, ClockMsg, FaultCode, StateMsg, StopReason, STATUS_FAULT};
use cdm_runtime::team_fault::{InterruptedAt, TeamFault};
use cdm_scenario::Scenario;

use crate::launch::LaunchOptions;
use cdm_team::team::{check_children, fault, Spawned, Stop};

/// Who has answered the arm order.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmRoll {
    waiting: BTreeSet<u32>,
    /// Members that answered without arming (started without `--arm`).
    stream_only: BTreeSet<u32>,
}

/// What one message told the roll.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answer {
    /// Not an answer (or a repeated one).
    Nothing,
    /// Member `id` answered.
    Answered { id: u32, armed: bool },
    /// Member `id` reported a fault (its vehicle lost or refusing) instead.
    Fault { id: u32, code: FaultCode },
}

impl ArmRoll {
    /// Waiting for every member of `ids`.
    pub fn new(ids: impl IntoIterator<Item = u32>) -> Self {
        ArmRoll {
            waiting: ids.into_iter().collect(),
            stream_only: BTreeSet::new(),
        }
    }

    /// A member's message.
    pub fn on_state(&mut self, m: &StateMsg, hash: u64) -> Answer {
        if m.scenario_hash != hash {
            return Answer::Nothing;
        }
        if let Some(armed) = m.armed() {
            if !self.waiting.remove(&m.id) {
                return Answer::Nothing;
            }
            if !armed {
                self.stream_only.insert(m.id);
            }
            return Answer::Answered { id: m.id, armed };
        }
        // Only a real fault report stops the arming (pacing and vehicle reports are not states).
        match m.status() {
            AgentStatus::Fault { code, .. } if m.status == STATUS_FAULT => {
                Answer::Fault { id: m.id, code }
            }
            _ => Answer::Nothing,
        }
    }

    /// Every member answered.
    pub fn complete(&self) -> bool {
        self.waiting.is_empty()
    }

    /// Members still to answer.
    pub fn waiting(&self) -> &BTreeSet<u32> {
        &self.waiting
    }

    /// Members that answered without arming.
    pub fn stream_only(&self) -> &BTreeSet<u32> {
        &self.stream_only
    }
}

/// With `--arm`: orders the arming and waits (within `--join-timeout`) until every member
/// answered. Without `--arm`, or for the model, nothing.
pub fn arm_team(
    s: &Scenario,
    o: &LaunchOptions,
    ports: &mut OrchestratorPorts,
    children: &mut [Spawned],
    interrupted: &AtomicBool,
) -> Result<(), Stop> {
    let Vehicles::Mavlink(v) = &o.vehicles else {
        return Ok(());
    };
    if !v.arm {
        return Ok(());
    }
    let hash = s.content_hash();
    let mut roll = ArmRoll::new(s.formation.members.iter().map(|m| m.id));
    o.notices.notice(&crate::notice::LaunchNotice::Arming {
        vehicles: roll.waiting().len(),
    });
    ports.publish_clock(ClockMsg::arm(hash)).map_err(|e| {
        let f = fault(FaultKind::Transport, None, None, 0, e.to_string());
        (f, StopReason::AgentFault)
    })?;
    let started = Instant::now();
    while !roll.complete() {
        if interrupted.load(Ordering::Relaxed) {
            return Err(TeamFault::Interrupted {
                signal: cdm_process::signals::received().to_string(),
                at: InterruptedAt::Arming,
            }
            .stop());
        }
        let mut bad = None;
        let _ = ports.receive_states(|m| {
            if let Answer::Fault { id, code } = roll.on_state(&m, hash) {
                bad.get_or_insert((id, code));
            }
        });
        if let Some((id, code)) = bad {
            let what = format!("agent {id} reported {code:?} while arming its vehicle");
            let f = fault(code.kind(), Some(id), None, 0, what);
            return Err((f, StopReason::AgentFault));
        }
        check_children(children, 0)?;
        if started.elapsed() > o.join_timeout {
            return Err(not_armed(&roll, o.join_timeout));
        }
        let _ = ports.wait(Duration::from_millis(20));
    }
    tracing::info!(
        stream_only = ?roll.stream_only(),
        armed_s = started.elapsed().as_secs_f64(),
        "every member answered the arm order"
    );
    Ok(())
}

/// The stop when members did not answer in time (names them).
fn not_armed(roll: &ArmRoll, within: Duration) -> Stop {
    TeamFault::NotArmed {
        waiting: roll.waiting().iter().copied().collect(),
        within,
    }
    .stop()
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_runtime::messages::StateMsg;

    #[test]
    fn complete_once_every_member_answered_once() {
        let mut roll = ArmRoll::new([1, 2, 3]);
        assert_eq!(
            roll.on_state(&StateMsg::arm_report(0, 9, 2, true), 9),
            Answer::Answered { id: 2, armed: true }
        );
        // A repeat, another scenario's answer and a plain state are not answers.
        assert_eq!(
            roll.on_state(&StateMsg::arm_report(0, 9, 2, true), 9),
            Answer::Nothing
        );
        assert_eq!(
            roll.on_state(&StateMsg::arm_report(0, 8, 1, true), 9),
            Answer::Nothing
        );
        assert_eq!(
            roll.on_state(&StateMsg::ok(0, 9, 1, [0.0; 12]), 9),
            Answer::Nothing
        );
        assert!(!roll.complete());
        roll.on_state(&StateMsg::arm_report(0, 9, 1, false), 9);
        roll.on_state(&StateMsg::arm_report(0, 9, 3, true), 9);
        assert!(roll.complete());
        assert_eq!(roll.stream_only(), &BTreeSet::from([1]));
    }

    #[test]
    fn a_vehicle_lost_while_arming_is_named() {
        let mut roll = ArmRoll::new([1, 2]);
        let lost = StateMsg::ok(0, 9, 2, [0.0; 12]).with_status(AgentStatus::Fault {
            code: FaultCode::VehicleLost,
            peer: None,
        });
        assert_eq!(
            roll.on_state(&lost, 9),
            Answer::Fault {
                id: 2,
                code: FaultCode::VehicleLost
            }
        );
        assert_eq!(not_armed(&roll, Duration::from_secs(5)).0.agent, Some(1));
    }
}
