//! A member's side of the commands to a team in flight: the clock messages announce each
//! accepted command with its switch tick ([`SteerNotice`], as a loss notice is announced), and
//! every member makes the same new plan of it with the same code as the orchestrator
//! (`cdm_model::steer::Steering`), before its first step that reaches the switch instant. The
//! commanded plan is the old one before the switch (the hold cuts the segment being flown
//! there), so a plan taken early flies the same ticks until then.

use cdm_math::Real;
use cdm_model::plan::TeamPlan;
use cdm_model::steer::Steering;
use cdm_model::step::tick_time;
use cdm_scenario::last_tick_of;

use crate::messages::SteerNotice;

/// Why a command notice cannot be followed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SteerFault {
    /// The notices jumped from `seen` to `got` (one was lost).
    #[error("command notice {got} arrived after notice {seen}: one was missed")]
    Missed { seen: u32, got: u32 },
    /// The switch tick is already flown past.
    #[error("the command switching at tick {at} arrived with tick {tick} flown")]
    Late { tick: u64, at: u64 },
    /// A command code this build does not know.
    #[error("command notice {seq} carries a command this member does not know")]
    Unknown { seq: u32 },
    /// The command does not apply to this member's plan (the orchestrator's plan differs).
    #[error("command notice {seq} does not apply to this member's plan: {why}")]
    NotApplicable { seq: u32, why: String },
    /// The vehicle cannot change its plan in flight.
    #[error("this vehicle cannot change its plan in flight (command notice {seq})")]
    Unsupported { seq: u32 },
}

/// The commands as this member knows them.
#[derive(Debug, Clone)]
pub struct MemberSteering {
    steering: Steering,
    comm_hz: Real,
    dt_s: Real,
    /// Notices followed so far.
    seen: u32,
}

/// What a new notice changes: the plan to fly from now on and its last tick.
#[derive(Debug, Clone, PartialEq)]
pub struct Replan {
    pub plan: TeamPlan,
    pub last_tick: u64,
}

impl MemberSteering {
    /// The steering of a member launched with `steering` (`Scenario::steering`) at `comm_hz`.
    pub fn new(steering: Steering, comm_hz: Real) -> Self {
        MemberSteering {
            steering,
            comm_hz,
            dt_s: 1.0 / comm_hz,
            seen: 0,
        }
    }

    /// The notice of a clock message, this member's next step being from `tick`: `None` for a
    /// repeat, the new plan for the next notice.
    pub fn on_notice(&mut self, n: SteerNotice, tick: u64) -> Result<Option<Replan>, SteerFault> {
        if n.seq == self.seen {
            return Ok(None);
        }
        if n.seq != self.seen + 1 {
            return Err(SteerFault::Missed {
                seen: self.seen,
                got: n.seq,
            });
        }
        // The step from `tick` reaches (tick + 1) dt: flown with the old plan up to the switch.
        if tick > n.tick {
            return Err(SteerFault::Late { tick, at: n.tick });
        }
        let command = n.command.ok_or(SteerFault::Unknown { seq: n.seq })?;
        let proposal = (self.steering)
            .propose(&command, tick_time(n.tick, self.dt_s))
            .map_err(|e| SteerFault::NotApplicable {
                seq: n.seq,
                why: e.to_string(),
            })?;
        self.steering.accept(proposal);
        self.seen = n.seq;
        let plan = self.steering.plan().clone();
        let last_tick = last_tick_of(plan.flight_end_s(), self.comm_hz);
        Ok(Some(Replan { plan, last_tick }))
    }
}
