//! The certificate of a command to a team in flight (`cdm_model::steer`): the phases it adds,
//! certified as a mission's are, against the safety numbers the flight was launched with.
//!
//! Why the guarantee carries over: every leader path stays a straight segment and every other
//! member the same affine combination of the leaders (eq. 13), so
//! - a new rest-to-rest segment (goto, resume, landing) is a mission phase: lambda_1(U_D) over
//!   it against lambda_CD,min (eq. 37), E_max on the linear team from rest at its travel time
//!   (eq. 34), the link delay it tolerates, and for a landing the ground spots 2 (eps + delta)
//!   apart;
//! - a hold's stop flies part of a segment already flown, so lambda_1 over it is the
//!   deformation's along that part; its new time profile starts from the team's tracking error
//!   at the switch, so the tracking bound is the commanded flight's largest follower deviation
//!   from the switch on, computed exactly on the linear team (`commanded_flight.rs`: the error
//!   at the switch carried by the chains, every tick counted) and held against delta;
//! - the geofence and obstacles are certified over every path of the commanded plan.

use serde::Serialize;

use crate::airspace_certificate::{certify_airspace, AirspaceCertificate};
use crate::certificate::{verdict_of, PhaseCertificate};
use crate::commanded_flight::{max_follower_deviation_from, Deviation};
use crate::delay::{bound_ms, DelayBound};
use crate::mission_certificate::{certify_phase, tighter};
use crate::vehicle_certificate::{certify_vehicle, VehicleCertificate};
use cdm_engine::engine::max_follower_deviation_within;
use cdm_math::Real;
use cdm_model::outcome::Verdict;
use cdm_model::plan::{Phase, PhaseKind};
use cdm_model::steer::{NotApplicable, Proposal, Steering, TeamCommand};
use cdm_model::step::tick_time;
use cdm_records::audit::{CommandSummary, SafetyNumbers};
use cdm_scenario::{CommandSpec, Scenario, TimedCommand};

/// What a command's motion was certified to, and the verdict.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CommandCertificate {
    /// SAFE or UNSAFE.
    pub verdict: Verdict,
    /// Every UNSAFE reason, each naming its phase (and member, where one is at fault).
    pub reasons: Vec<String>,
    /// The flight's lambda_CD,min and delta (eqs. 37-38), unchanged by commands.
    pub lambda_cd_min: Real,
    pub delta_m: Real,
    /// The commanded flight's max follower deviation from the switch tick on (eq. 34), the
    /// error the flight so far left included.
    pub max_follower_deviation_m: Real,
    /// The largest link delay the new segments tolerate (ms); `None` when one fails without.
    pub max_link_delay_ms: Option<Real>,
    pub max_link_delay_at_least: bool,
    /// The phases the command adds, in flight order.
    pub phases: Vec<PhaseCertificate>,
    /// `[geofence]` and `[[obstacle]]`: every path of the commanded plan.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub airspace: Option<AirspaceCertificate>,
    /// `[vehicle]`: the limits and downwash over every phase of the commanded plan.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vehicle: Option<VehicleCertificate>,
}

/// The certificate of `proposal` for the team of `s` launched with the safety numbers `n`.
pub fn certify_command(s: &Scenario, n: &SafetyNumbers, proposal: &Proposal) -> CommandCertificate {
    let mut commanded = s.clone();
    commanded.plan = proposal.plan.clone();
    let s = &commanded;
    let mut reasons = Vec::new();
    let mut rows = Vec::new();
    let mut delay = DelayBound::AtLeast(u64::MAX);
    for p in &s.plan.phases()[proposal.first_new..] {
        let (mut row, d) = certify_phase(s, n, p);
        delay = tighter(delay, d);
        if p.kind == PhaseKind::Landing {
            if let Some(why) = below_ground(s, p) {
                row.reasons.push(why);
                row.verdict = Verdict::Unsafe;
            }
        }
        reasons.extend(row.reasons.iter().map(|r| format!("{}: {r}", row.name)));
        rows.push(row);
    }
    let flown = deviation_from_switch(s, n.delta_m, proposal.t_switch_s);
    if flown.max_m.is_nan() || flown.max_m > n.delta_m {
        reasons.push(format!(
            "the commanded flight from the switch on: agent {} deviates {:.4} m at t = {:.2} s, more than delta = {:.4} m (eq. 34)",
            flown.agent,
            flown.max_m,
            tick_time(flown.tick, s.dt_s()),
            n.delta_m
        ));
    }
    let flown = flown.max_m;
    let link_ticks = s.link_model().max_ticks();
    match delay {
        DelayBound::Ticks(d) if link_ticks > d => reasons.push(format!(
            "the links' delay of {link_ticks} ticks exceeds the {d} ticks the new segments tolerate"
        )),
        _ => {}
    }
    let airspace = certify_airspace(s, n.delta_m);
    if let Some(a) = &airspace {
        reasons.extend(a.reasons());
    }
    // The vehicles' limits and downwash over every phase of the commanded plan: a hold's stop
    // by its own cubic's extremes, a cut phase by its whole quintic's (it flies part of it).
    let vehicle = certify_vehicle(s, n.delta_m);
    if let Some(v) = &vehicle {
        reasons.extend(v.reasons());
    }
    let (max_link_delay_ms, max_link_delay_at_least) = bound_ms(delay, s.dt_s());
    CommandCertificate {
        verdict: verdict_of(&reasons),
        reasons,
        lambda_cd_min: n.lambda_cd_min,
        delta_m: n.delta_m,
        max_follower_deviation_m: flown,
        max_link_delay_ms,
        max_link_delay_at_least,
        phases: rows,
        airspace,
        vehicle,
    }
}

/// The commanded flight's largest follower deviation from the switch tick on (eq. 34), with the
/// error the flight so far leaves at the switch: on the linear team (`commanded_flight.rs`)
/// when the links are perfect or only delay, else (jitter, loss, or a graph the linear model
/// does not cover) by flying the nonlinear engine from t = 0, ending once it exceeds delta.
fn deviation_from_switch(s: &Scenario, delta_m: Real, t_switch_s: Real) -> Deviation {
    let from_tick = (t_switch_s / s.dt_s()).round() as u64;
    let link = s.link_model();
    let spec = link.spec();
    if spec.jitter_ms == 0.0 && spec.loss == 0.0 {
        match max_follower_deviation_from(s, from_tick, link.max_ticks()) {
            Ok(d) => return d,
            Err(why) => tracing::info!(%why, "the command certificate flies the commanded flight"),
        }
    }
    let max_m = max_follower_deviation_within(s, delta_m).unwrap_or(Real::INFINITY);
    Deviation {
        max_m,
        agent: 0,
        tick: 0,
    }
}

/// A landing whose ground is not below every member at its top.
fn below_ground(s: &Scenario, p: &Phase) -> Option<String> {
    let ground = p.goal[0].z;
    (s.formation.members.iter())
        .map(|m| {
            let a = m.alpha;
            (
                m.id,
                (p.start[0] * a[0] + p.start[1] * a[1] + p.start[2] * a[2]).z,
            )
        })
        .find(|&(_, z)| z <= ground)
        .map(|(id, z)| {
            format!(
                "the ground z = {ground} m is not below agent {id} (z = {z:.3} m where it holds)"
            )
        })
}

/// What became of a command.
#[derive(Debug, Clone, PartialEq)]
pub enum CommandOutcome {
    /// Certified SAFE: the team's plan is the commanded one from the switch on.
    Accepted(CommandCertificate),
    /// Certified UNSAFE: nothing changed.
    Refused(CommandCertificate),
    /// It does not apply at its switch instant: nothing changed.
    NotApplicable(NotApplicable),
}

/// Propose `command` at `t_switch_s`, certify its motion and accept it only when SAFE.
pub fn steer(
    steering: &mut Steering,
    s: &Scenario,
    n: &SafetyNumbers,
    command: &TeamCommand,
    t_switch_s: Real,
) -> CommandOutcome {
    match steering.propose(command, t_switch_s) {
        Err(why) => CommandOutcome::NotApplicable(why),
        Ok(p) => {
            let c = certify_command(s, n, &p);
            if c.verdict == Verdict::Safe {
                steering.accept(p);
                CommandOutcome::Accepted(c)
            } else {
                CommandOutcome::Refused(c)
            }
        }
    }
}

/// One command of a file and what became of it: an entry of a run's `commands.json` (the
/// command's own fields first, so the file reads back as a command file).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CommandRecord {
    #[serde(flatten)]
    pub spec: CommandSpec,
    /// When it arrived (simulation time): a file's command arrives at its `at_s`.
    pub arrived_s: Real,
    pub switch_tick: u64,
    /// The certificate's verdict; `None` when the command did not apply at all.
    pub verdict: Option<Verdict>,
    pub accepted: bool,
    /// Why it was refused: the certificate's reasons, or why it did not apply.
    pub why: Option<String>,
    pub certificate: Option<CommandCertificate>,
}

impl CommandRecord {
    /// What audit.json lists of it.
    pub fn summary(&self) -> CommandSummary {
        CommandSummary {
            command: self.spec.command.clone(),
            arrived_s: self.arrived_s,
            switch_tick: self.switch_tick,
            verdict: self.verdict,
            accepted: self.accepted,
            why: self.why.clone(),
        }
    }
}

/// A file's commands applied in order to the team of `s`, each certified at its switch tick
/// against the plan as commanded before it: the scenario to fly (its plan the commanded one,
/// the same before every switch, so flying it is flying the switches) and what became of each.
pub fn apply_commands(s: &Scenario, commands: &[TimedCommand]) -> (Scenario, Vec<CommandRecord>) {
    let n = SafetyNumbers::of(s);
    let mut steering = s.steering();
    let records = (commands.iter())
        .map(|c| decide(&mut steering, s, &n, c))
        .collect();
    let mut flown = s.clone();
    flown.plan = steering.plan().clone();
    (flown, records)
}

/// Command `c` certified at its switch tick against `steering`'s plan (the team of `s`
/// launched with the safety numbers `n`), applied to it when SAFE: what became of it.
pub fn decide(
    steering: &mut Steering,
    s: &Scenario,
    n: &SafetyNumbers,
    c: &TimedCommand,
) -> CommandRecord {
    let t_switch_s = tick_time(c.switch_tick, s.dt_s());
    let outcome = steer(steering, s, n, &c.command, t_switch_s);
    let (verdict, accepted, why, certificate) = match outcome {
        CommandOutcome::Accepted(cert) => (Some(cert.verdict), true, None, Some(cert)),
        CommandOutcome::Refused(cert) => (
            Some(cert.verdict),
            false,
            Some(cert.reasons.join("; ")),
            Some(cert),
        ),
        CommandOutcome::NotApplicable(why) => (None, false, Some(why.to_string()), None),
    };
    CommandRecord {
        spec: c.spec.clone(),
        arrived_s: c.arrived_s.unwrap_or(c.spec.at_s),
        switch_tick: c.switch_tick,
        verdict,
        accepted,
        why,
        certificate,
    }
}

#[cfg(test)]
mod tests;
