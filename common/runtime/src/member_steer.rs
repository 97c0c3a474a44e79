//! A member's side of the commands to a team in flight: the clock messages announce each
//! accepted command with its switch tick ([`SteerNotice`], as a loss notice is announced), and
//! every member makes the same new plan of it with the same code as the orchestrator
//! (`cdm_model::steer::Steering`), before its first step that reaches the switch instant. The
//! commanded plan is the old one before the switch (the hold cuts the segment being flown
//! there), so a plan taken early flies the same ticks until then.
//!
//! In real time nobody waits for a grant, so a command is decided in two steps: the notice is
//! first *proposed* with its switch tick; a member that has not flown into that tick yet makes
//! the new plan, keeps it aside and (a leader) acknowledges; the orchestrator then announces it
//! *final* once every leader acknowledged, or *withdrawn* (nothing changes) when one did not in
//! time. A leader does not fly the switch tick while the command it acknowledged is undecided.
//! Followers do not acknowledge: their law reads no plan, only the flight's last tick, so they
//! take the decision whenever it comes.

use cdm_math::Real;
use cdm_model::plan::TeamPlan;
use cdm_model::steer::Steering;
use cdm_model::step::tick_time;
use cdm_scenario::last_tick_of;

use crate::messages::{SteerNotice, SteerPhase};

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
    /// A proposed command this leader acknowledged was neither decided nor withdrawn before
    /// its switch tick plus the stale bound.
    #[error("command notice {seq} switching at tick {tick} was acknowledged but never decided")]
    Undecided { seq: u32, tick: u64 },
}

/// What a clock message's command notice changed.
#[derive(Debug, Clone, PartialEq)]
pub enum Noticed {
    /// Nothing new (a repeat).
    Nothing,
    /// A decided command: the plan to fly from now on (boxed: a plan is large).
    Replan(Box<Replan>),
    /// Real time: a proposed command this member can still switch to at its tick (kept aside):
    /// a leader acknowledges it.
    Proposed { seq: u32 },
    /// Real time: a proposed command whose switch tick this member already flew into: it does
    /// not acknowledge, and the orchestrator withdraws it.
    TooLate { seq: u32 },
    /// Real time: the proposed command was withdrawn; nothing changed.
    Withdrawn { seq: u32 },
}

/// The commands as this member knows them.
#[derive(Debug, Clone)]
pub struct MemberSteering {
    steering: Steering,
    comm_hz: Real,
    dt_s: Real,
    /// Notices followed (decided or withdrawn) so far.
    seen: u32,
    /// The proposed command kept aside (real time) until it is decided.
    proposed: Option<(SteerNotice, cdm_model::steer::Proposal)>,
    /// The proposed command number this member was too late for (said once).
    too_late: Option<u32>,
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
            proposed: None,
            too_late: None,
        }
    }

    /// True while a proposed command this member kept aside switches at or before `tick` and
    /// is not decided yet: a leader must not fly `tick`.
    pub fn undecided_at(&self, tick: u64) -> Option<(u32, u64)> {
        let (n, _) = self.proposed.as_ref()?;
        (n.tick <= tick).then_some((n.seq, n.tick))
    }

    /// The notice of a clock message, this member's next step being from `tick`. `late_ok`:
    /// a decided command may arrive after its switch (a follower in real time, whose law reads
    /// no plan); otherwise that is a fault.
    pub fn on_notice(
        &mut self,
        n: SteerNotice,
        tick: u64,
        late_ok: bool,
    ) -> Result<Noticed, SteerFault> {
        let proposed_seq = self.proposed.as_ref().map(|(p, _)| p.seq);
        let repeat = match n.phase {
            SteerPhase::Proposed => {
                n.seq == self.seen || proposed_seq == Some(n.seq) || self.too_late == Some(n.seq)
            }
            _ => n.seq == self.seen,
        };
        if repeat {
            return Ok(Noticed::Nothing);
        }
        if n.seq != self.seen + 1 {
            return Err(SteerFault::Missed {
                seen: self.seen,
                got: n.seq,
            });
        }
        match n.phase {
            SteerPhase::Unknown(_) => Err(SteerFault::Unknown { seq: n.seq }),
            SteerPhase::Withdrawn => {
                self.proposed = None;
                self.seen = n.seq;
                Ok(Noticed::Withdrawn { seq: n.seq })
            }
            SteerPhase::Proposed => {
                // The step from `tick` reaches (tick + 1) dt: flown with the old plan up to
                // the switch, so the switch may still be `tick` itself.
                if tick > n.tick {
                    self.too_late = Some(n.seq);
                    return Ok(Noticed::TooLate { seq: n.seq });
                }
                let proposal = self.propose(&n)?;
                self.proposed = Some((n, proposal));
                Ok(Noticed::Proposed { seq: n.seq })
            }
            SteerPhase::Final => {
                if tick > n.tick && !late_ok {
                    return Err(SteerFault::Late { tick, at: n.tick });
                }
                let proposal = match self.proposed.take() {
                    Some((p, proposal)) if p.seq == n.seq && p.tick == n.tick => proposal,
                    _ => self.propose(&n)?,
                };
                self.steering.accept(proposal);
                self.seen = n.seq;
                let plan = self.steering.plan().clone();
                let last_tick = last_tick_of(plan.flight_end_s(), self.comm_hz);
                Ok(Noticed::Replan(Box::new(Replan { plan, last_tick })))
            }
        }
    }

    /// The new motion of notice `n`, from this member's steering.
    fn propose(&self, n: &SteerNotice) -> Result<cdm_model::steer::Proposal, SteerFault> {
        let command = n.command.ok_or(SteerFault::Unknown { seq: n.seq })?;
        (self.steering)
            .propose(&command, tick_time(n.tick, self.dt_s))
            .map_err(|e| SteerFault::NotApplicable {
                seq: n.seq,
                why: e.to_string(),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_model::steer::TeamCommand;
    use cdm_scenario::Scenario;

    fn steering() -> MemberSteering {
        let s = Scenario::builtin("paper40").unwrap();
        MemberSteering::new(s.steering(), s.file.comm_hz)
    }

    #[test]
    fn a_proposed_command_is_kept_aside_until_it_is_final_or_withdrawn() {
        let mut m = steering();
        let hold = SteerNotice::decided(1, 3000, TeamCommand::Hold);
        let proposed = hold.in_phase(SteerPhase::Proposed);
        assert_eq!(
            m.on_notice(proposed, 2990, false),
            Ok(Noticed::Proposed { seq: 1 })
        );
        assert_eq!(m.undecided_at(2999), None);
        assert_eq!(m.undecided_at(3000), Some((1, 3000)));
        // Repeats change nothing.
        assert_eq!(m.on_notice(proposed, 2995, false), Ok(Noticed::Nothing));
        // Withdrawn: nothing changed, its number is spent.
        let withdrawn = hold.in_phase(SteerPhase::Withdrawn);
        assert_eq!(
            m.on_notice(withdrawn, 2996, false),
            Ok(Noticed::Withdrawn { seq: 1 })
        );
        assert_eq!(m.undecided_at(u64::MAX), None);
        // Number 2: proposed in time, then final: the plan kept aside is flown.
        let hold2 = SteerNotice::decided(2, 3100, TeamCommand::Hold);
        let proposed2 = hold2.in_phase(SteerPhase::Proposed);
        assert_eq!(
            m.on_notice(proposed2, 3050, false),
            Ok(Noticed::Proposed { seq: 2 })
        );
        let Ok(Noticed::Replan(r)) = m.on_notice(hold2, 3060, false) else {
            panic!("no replan");
        };
        let mut direct = steering();
        let first = SteerNotice::decided(1, 3100, TeamCommand::Hold);
        let Ok(Noticed::Replan(d)) = direct.on_notice(first, 3000, false) else {
            panic!("no replan");
        };
        assert_eq!(
            r, d,
            "the plan kept aside is the one a decided notice makes"
        );
        assert_eq!(m.undecided_at(u64::MAX), None);
    }

    #[test]
    fn a_proposal_past_its_switch_is_not_acknowledged_and_a_late_final_is_a_leader_s_fault() {
        let mut m = steering();
        let hold = SteerNotice::decided(1, 3000, TeamCommand::Hold);
        assert_eq!(
            m.on_notice(hold.in_phase(SteerPhase::Proposed), 3001, false),
            Ok(Noticed::TooLate { seq: 1 })
        );
        assert_eq!(
            m.on_notice(hold.in_phase(SteerPhase::Proposed), 3002, false),
            Ok(Noticed::Nothing)
        );
        assert_eq!(
            m.on_notice(hold, 3002, false),
            Err(SteerFault::Late {
                tick: 3002,
                at: 3000
            })
        );
        // A follower takes it late.
        assert!(matches!(
            m.on_notice(hold, 3002, true),
            Ok(Noticed::Replan(_))
        ));
        let jump = SteerNotice::decided(3, 4000, TeamCommand::Hold);
        assert_eq!(
            m.on_notice(jump, 3003, true),
            Err(SteerFault::Missed { seen: 1, got: 3 })
        );
    }
}
