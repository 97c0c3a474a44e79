//! Steering a team in flight: what `hold`, `resume`, `goto` and `land` make of the primary
//! leaders' plan from a switch instant on, as new phases of the same `TeamPlan`.
//!
//! Every command keeps each leader path a straight segment flown on a time scaling (eq. 15 with
//! some s(t)), and every other member the same affine combination of the leaders (eq. 13), so
//! the certificates of a mission apply to the new phases unchanged:
//! - *hold*: the segment being flown is cut at the switch and continued by a stop (`stop.rs`)
//!   along the same segment, never faster than that segment's own quintic; when the quintic
//!   itself comes to rest sooner (late in the segment), the hold keeps it. The leaders then
//!   hover where they stopped.
//! - *goto*: hold, then a rest-to-rest quintic to the three new goals.
//! - *resume*: hold, then back to the route the team left (the plan it flew before the first
//!   command that departed from it): a rest-to-rest quintic to the goal of the phase it was
//!   interrupted in, then that route's later phases, shifted in time, their hovers kept.
//! - *land*: hold, then the mission's landing (every member straight down) from where the team
//!   holds.
//!
//! A new segment's travel time, unless given, is the one at which its fastest leader's peak
//! acceleration equals the largest the route's own segments reach (eq. 16: a rest-to-rest
//! quintic over a distance d and a time T peaks at 10 d / (sqrt(3) T^2)).

use crate::plan::{Phase, PhaseKind, Quintic, Scaling, Segment, TeamPlan};
use crate::stop::{quintic_peak_acceleration, StopProfile};
use cdm_math::{Real, Vec3};

/// A command to a team in flight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TeamCommand {
    /// Come to rest along the current segment and hover.
    Hold,
    /// Fly on along the route left by the first departing command.
    Resume,
    /// Hold, then land every member straight below.
    Land,
    /// Hold, then fly the primary leaders (in the plan's order) to `goals`, in `travel_s` or
    /// the default travel time.
    Goto {
        goals: [Vec3; 3],
        travel_s: Option<Real>,
    },
}

impl TeamCommand {
    /// `hold`, `resume`, `land`, `goto`: how the files and the command line name it.
    pub fn name(&self) -> &'static str {
        match self {
            TeamCommand::Hold => "hold",
            TeamCommand::Resume => "resume",
            TeamCommand::Land => "land",
            TeamCommand::Goto { .. } => "goto",
        }
    }
}

/// Why a command cannot apply at its switch instant (its motion is not even proposed).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NotApplicable {
    /// The flight ended before the switch.
    #[error("the team's flight ended at t = {end_s:.3} s, before the switch at t = {at_s:.3} s")]
    Ended { at_s: Real, end_s: Real },
    /// `resume` while the team flies its route.
    #[error("nothing to resume: the team is flying its route")]
    NotHeld,
    /// `resume` with the route flown to its end.
    #[error("nothing to resume: the route the team left is flown to its end")]
    RouteFlown,
    /// A `goto` while taking off (before the take-off's top) or landing.
    #[error("the team is not airborne ({phase}): a goto waits until the take-off is done")]
    NotAirborne { phase: String },
    /// `land` or `resume` while the team lands.
    #[error("the team is already landing")]
    Landing,
    /// `land` with the team on the ground already.
    #[error("the team is on the ground (z = {z_m:.3} m) already")]
    OnGround { z_m: Real },
}

/// What the commands need besides the plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteerSettings {
    /// One tick: a stop lasts whole ticks.
    pub dt_s: Real,
    /// The shortest travel time a new segment may have (enough ticks to resolve its quintic).
    pub min_travel_s: Real,
    /// `[landing]`'s ground height (0 without one).
    pub ground_z_m: Real,
    /// `[landing]`'s descent time; without one, the default travel time's rule.
    pub landing_t_s: Option<Real>,
}

/// A command's motion, before it is certified: the whole plan with its new phases.
#[derive(Debug, Clone, PartialEq)]
pub struct Proposal {
    pub plan: TeamPlan,
    /// The index of the first phase the command added (earlier ones are flown or cut).
    pub first_new: usize,
    /// The switch instant (a tick's): the plan is the team's own before it.
    pub t_switch_s: Real,
    /// When the leaders are at rest after the hold every command starts with.
    pub t_rest_s: Real,
    /// Where the primary leaders hold (plan order).
    pub held_at: [Vec3; 3],
    route: Option<(TeamPlan, Real)>,
}

/// The steering of one team: its plan as commanded so far and the route `resume` goes back to.
#[derive(Debug, Clone, PartialEq)]
pub struct Steering {
    plan: TeamPlan,
    /// The route the team left, and the instant it left it (`None`: flying it).
    route: Option<(TeamPlan, Real)>,
    /// The flight the team was launched for ends no earlier than this.
    launched_end_s: Real,
    /// The largest peak acceleration of a leader on the launched plan (m/s^2).
    launched_peak_acc: Real,
    settings: SteerSettings,
}

/// Where the leaders come to rest from a switch: the phases up to there, when and where.
struct Rest {
    phases: Vec<Phase>,
    /// The first of `phases` that is not the plan's (the stop).
    first_new: usize,
    t_s: Real,
    at: [Vec3; 3],
    kind: PhaseKind,
    /// True when the phase it rests after was flown to its goal as planned.
    complete: bool,
}

impl Steering {
    /// The steering of a team launched with `plan`.
    pub fn new(plan: TeamPlan, settings: SteerSettings) -> Self {
        let launched_peak_acc = (plan.phases().iter())
            .map(|p| {
                max_distance(&p.start, &p.goal) * quintic_peak_acceleration(p.quintic.t_total_s)
            })
            .fold(0.0, Real::max);
        Steering {
            launched_end_s: plan.flight_end_s(),
            launched_peak_acc,
            // Not `commandable()` here: every member builds a steering at start, and the
            // launched plan's lambda_1 scan is needed only once a command replaces the plan.
            plan,
            route: None,
            settings,
        }
    }

    /// The plan as commanded so far.
    pub fn plan(&self) -> &TeamPlan {
        &self.plan
    }

    /// The motion `command` asks for from `t_switch_s` on (a tick's instant), or why it does
    /// not apply. Nothing changes until [`Steering::accept`].
    pub fn propose(
        &self,
        command: &TeamCommand,
        t_switch_s: Real,
    ) -> Result<Proposal, NotApplicable> {
        let end_s = self.plan.flight_end_s();
        if t_switch_s > end_s {
            return Err(NotApplicable::Ended {
                at_s: t_switch_s,
                end_s,
            });
        }
        let rest = self.to_rest(t_switch_s);
        let route = self
            .route
            .clone()
            .or_else(|| (*command != TeamCommand::Resume).then(|| (self.plan.clone(), t_switch_s)));
        let first_new = rest.first_new;
        let mut phases = rest.phases.clone();
        let mut route_after = route.clone();
        match command {
            TeamCommand::Hold => {}
            TeamCommand::Goto { goals, travel_s } => {
                let n = next_segment_number(&phases);
                phases.push(self.goto(&rest, goals, *travel_s, n)?);
            }
            TeamCommand::Land => phases.push(self.landing(&rest)?),
            TeamCommand::Resume => {
                let (route_plan, left_s) = route.ok_or(NotApplicable::NotHeld)?;
                if rest.kind == PhaseKind::Landing {
                    return Err(NotApplicable::Landing);
                }
                self.resume(&route_plan, left_s, &rest, &mut phases)?;
                route_after = None;
            }
        }
        let plan = self.plan.clone().commandable().with_phases(phases);
        let lands = plan.phases().last().map(|p| p.kind) == Some(PhaseKind::Landing);
        let plan = if lands {
            plan
        } else {
            plan.hovering_until(self.launched_end_s)
        };
        Ok(Proposal {
            plan,
            first_new,
            t_switch_s,
            t_rest_s: rest.t_s,
            held_at: rest.at,
            route: route_after,
        })
    }

    /// A goto's segment (numbered `n`) from where the team rests.
    fn goto(
        &self,
        rest: &Rest,
        goals: &[Vec3; 3],
        travel_s: Option<Real>,
        n: u32,
    ) -> Result<Phase, NotApplicable> {
        if rest.kind == PhaseKind::Landing || (rest.kind == PhaseKind::Takeoff && !rest.complete) {
            return Err(NotApplicable::NotAirborne {
                phase: rest.kind.name(),
            });
        }
        let t_s = travel_s.unwrap_or_else(|| self.travel_time(&rest.at, goals));
        Ok(Phase::rest_to_rest(
            PhaseKind::Segment(n),
            rest.t_s,
            t_s,
            rest.at,
            *goals,
        ))
    }

    /// The landing from where the team rests.
    fn landing(&self, rest: &Rest) -> Result<Phase, NotApplicable> {
        if rest.kind == PhaseKind::Landing {
            return Err(NotApplicable::Landing);
        }
        let ground = rest
            .at
            .map(|p| Vec3::new(p.x, p.y, self.settings.ground_z_m));
        let z_m = rest.at.iter().map(|p| p.z).fold(Real::INFINITY, Real::min);
        if z_m - self.settings.ground_z_m < 1e-9 {
            return Err(NotApplicable::OnGround { z_m });
        }
        let t_s =
            (self.settings.landing_t_s).unwrap_or_else(|| self.travel_time(&rest.at, &ground));
        Ok(Phase::rest_to_rest(
            PhaseKind::Landing,
            rest.t_s,
            t_s,
            rest.at,
            ground,
        ))
    }

    /// The proposal becomes the team's plan (its motion was certified).
    pub fn accept(&mut self, p: Proposal) {
        self.plan = p.plan;
        self.route = p.route;
    }

    /// The rest of `route` after `left_s`, from where the team rests.
    fn resume(
        &self,
        route: &TeamPlan,
        left_s: Real,
        rest: &Rest,
        phases: &mut Vec<Phase>,
    ) -> Result<(), NotApplicable> {
        let piece = route.piece_at(left_s);
        let all = route.phases();
        let base = all[piece.phase];
        let later = &all[piece.phase + 1..];
        let away = max_distance(&rest.at, &base.goal);
        if away < 1e-9 && later.is_empty() {
            return Err(NotApplicable::RouteFlown);
        }
        let mut t = rest.t_s;
        if away >= 1e-9 {
            let t_s = self.scaled_time(&base, &rest.at);
            phases.push(Phase::rest_to_rest(base.kind, t, t_s, rest.at, base.goal));
            t += t_s;
        }
        // The route's hovers after the interrupted phase are kept (what was left of them).
        let offset = t - left_s.max(base.t_end_s());
        phases.extend(later.iter().map(|p| Phase {
            t_start_s: p.t_start_s + offset,
            ..*p
        }));
        Ok(())
    }

    /// The phases up to the leaders' rest from `t` on (see the module text).
    fn to_rest(&self, t: Real) -> Rest {
        let all = self.plan.phases();
        let piece = self.plan.piece_at(t);
        let k = piece.phase;
        let p = all[k];
        let whole = |t_s: Real| Rest {
            phases: all[..=k].to_vec(),
            first_new: k + 1,
            t_s,
            at: p.goal,
            kind: p.kind,
            complete: !matches!(p.scaling, Scaling::Cut { .. } | Scaling::Stop(_)),
        };
        if piece.segment == Segment::Hold {
            return whole(t);
        }
        let tau = t - p.t_start_s;
        if matches!(p.scaling, Scaling::Stop(_)) || tau >= p.duration_s() {
            return whole(p.t_end_s().max(t));
        }
        let [s0, v0, a0, _, _] = p.s_derivatives(tau, Segment::Motion);
        let cut = Phase {
            scaling: Scaling::Cut { until_s: tau },
            ..p
        };
        let mut phases = all[..k].to_vec();
        phases.push(cut);
        if v0 <= 0.0 && a0 <= 0.0 {
            // At rest on it (its start): nothing to stop.
            return Rest {
                phases,
                first_new: k + 1,
                t_s: t,
                at: p.primaries_at_s(s0),
                kind: p.kind,
                complete: false,
            };
        }
        let peak = quintic_peak_acceleration(p.quintic.t_total_s);
        match StopProfile::quickest(s0, v0, a0, peak, self.settings.dt_s) {
            Some(stop) if t + stop.t_s < p.t_end_s() => {
                let at = p.primaries_at_s(s0 + stop.distance());
                phases.push(Phase {
                    kind: p.kind,
                    t_start_s: t,
                    quintic: Quintic {
                        t_total_s: stop.t_s,
                    },
                    start: p.primaries_at_s(s0),
                    goal: at,
                    scaling: Scaling::Stop(stop),
                });
                Rest {
                    phases,
                    first_new: k + 1,
                    t_s: t + stop.t_s,
                    at,
                    kind: p.kind,
                    complete: false,
                }
            }
            // The quintic comes to rest sooner: keep it.
            _ => whole(p.t_end_s()),
        }
    }

    /// The default travel time from `from` to `to`: the fastest leader's peak acceleration at
    /// most the largest any phase of the launched plan reaches.
    fn travel_time(&self, from: &[Vec3; 3], to: &[Vec3; 3]) -> Real {
        let peak = self.launched_peak_acc;
        let d = max_distance(from, to);
        let t = if peak > 0.0 {
            (d * quintic_peak_acceleration(1.0) / peak).sqrt()
        } else {
            0.0
        };
        t.max(self.settings.min_travel_s)
    }

    /// `base`'s travel time scaled to the rest of it from `from`: T sqrt(d / d_base), the
    /// same peak acceleration as `base` for its fastest leader.
    fn scaled_time(&self, base: &Phase, from: &[Vec3; 3]) -> Real {
        let full = max_distance(&base.start, &base.goal);
        let d = max_distance(from, &base.goal);
        let t = if full > 0.0 {
            base.quintic.t_total_s * (d / full).sqrt()
        } else {
            base.quintic.t_total_s
        };
        t.max(self.settings.min_travel_s)
    }
}

/// The largest distance between corresponding leaders.
fn max_distance(a: &[Vec3; 3], b: &[Vec3; 3]) -> Real {
    (0..3).map(|i| (b[i] - a[i]).norm()).fold(0.0, Real::max)
}

/// The next deformation segment's number (after the largest so far).
fn next_segment_number(phases: &[Phase]) -> u32 {
    (phases.iter())
        .filter_map(|p| match p.kind {
            PhaseKind::Segment(n) => Some(n),
            _ => None,
        })
        .max()
        .unwrap_or(0)
        + 1
}

#[cfg(test)]
mod tests;
