//! The live audit of the vehicles' limits (`[vehicle]`): every audited instant, each living
//! member's flown velocity (its state, as telemetry's `v`) against the speed limits, and its
//! acceleration over the last interval, (v_k - v_k-1) / (t_k - t_k-1), against the
//! acceleration limits. That mean is at most the largest acceleration flown over the interval
//! (the mean value theorem for integrals), so a breach it finds is a real one.
//!
//! The certificate bounds the commanded motion (r_HT's derivatives); a follower flies behind its
//! plan (ERRATA 8) and its velocity and acceleration overshoot the commanded ones by its
//! tracking error, so the audit allows [`SPEED_TOLERANCE`] above a speed limit and
//! [`ACCEL_TOLERANCE`] above an acceleration limit (the overshoot measured in the book's
//! certificates page, "The vehicles' limits").

use serde::Serialize;

use cdm_math::{Real, Vec3};
use cdm_model::limits::Limit;
use cdm_scenario::Scenario;

/// How far above a speed limit (relative) the flown speed may go before it is a violation: the
/// followers' overshoot of their commanded peak speed, 4.1 % on paper40 flown at its
/// T_threshold (36 s; 0.4 % at 120 s), with room to spare (cdm-certificates'
/// `the_followers_overshoot_stays_under_the_audits_tolerance`).
pub const SPEED_TOLERANCE: Real = 0.1;

/// The same for an acceleration limit: 12.8 % on paper40 at 36 s (0.9 % at 120 s).
pub const ACCEL_TOLERANCE: Real = 0.25;

/// The tolerance of a limit.
pub fn tolerance(l: Limit) -> Real {
    if l.is_accel() {
        ACCEL_TOLERANCE
    } else {
        SPEED_TOLERANCE
    }
}

/// One limit as flown.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FlownLimit {
    /// The `[vehicle]` key.
    pub limit: &'static str,
    pub max: Real,
    /// max (1 + tolerance): beyond it a member's motion is a violation.
    pub allowed: Real,
    /// The largest flown value and the member.
    pub flown: Real,
    pub agent: Option<u32>,
}

/// One breach that starts at this instant.
#[derive(Debug, Clone, PartialEq)]
pub struct LimitBreach {
    /// The member (formation order).
    pub member: usize,
    pub limit: Limit,
    pub value: Real,
    pub allowed: Real,
}

/// The live limits audit of one run.
#[derive(Debug, Clone)]
pub struct LimitAudit {
    limits: Vec<(Limit, Real)>,
    /// The previous instant and every member's velocity then.
    prev: Option<(Real, Vec<Vec3>)>,
    /// Per member and limit (member-major): breaching now.
    failing: Vec<bool>,
    pub flown: Vec<FlownLimit>,
}

impl LimitAudit {
    /// `None` without limits in `[vehicle]`: the audit does nothing more than before.
    pub fn new(s: &Scenario) -> Option<Self> {
        let limits = s.file.vehicle?.limits();
        if limits.is_empty() {
            return None;
        }
        Some(LimitAudit {
            failing: vec![false; s.formation.members.len() * limits.len()],
            flown: (limits.iter())
                .map(|&(l, max)| FlownLimit {
                    limit: l.key(),
                    max,
                    allowed: max * (1.0 + tolerance(l)),
                    flown: 0.0,
                    agent: None,
                })
                .collect(),
            limits,
            prev: None,
        })
    }

    /// Audit the velocities `vel` (formation order) at time `t`; `ids` name the members.
    pub fn observe(
        &mut self,
        t: Real,
        vel: &[Vec3],
        alive: &[bool],
        ids: &[u32],
        mut breach: impl FnMut(LimitBreach),
    ) {
        let acc_dt = self
            .prev
            .as_ref()
            .map(|(t0, _)| t - t0)
            .filter(|&d| d > 0.0);
        let width = self.limits.len();
        for (k, v) in vel.iter().enumerate() {
            if !alive[k] {
                continue;
            }
            for (j, &(limit, _)) in self.limits.iter().enumerate() {
                let value = if limit.is_accel() {
                    match (acc_dt, &self.prev) {
                        (Some(dt), Some((_, pv))) => limit.measure(&((v - pv[k]) / dt)),
                        _ => continue,
                    }
                } else {
                    limit.measure(v)
                };
                let f = &mut self.flown[j];
                if value > f.flown {
                    f.flown = value;
                    f.agent = Some(ids[k]);
                }
                let bad = value > f.allowed || value.is_nan();
                let slot = k * width + j;
                if bad && !self.failing[slot] {
                    breach(LimitBreach {
                        member: k,
                        limit,
                        value,
                        allowed: f.allowed,
                    });
                }
                self.failing[slot] = bad;
            }
        }
        match &mut self.prev {
            Some((t0, pv)) => {
                *t0 = t;
                pv.copy_from_slice(vel);
            }
            None => self.prev = Some((t, vel.to_vec())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_scenario::{paper40, Checks, VehicleSpec};

    #[test]
    fn a_breach_is_recorded_when_it_starts_and_accelerations_by_difference() {
        let mut f = paper40();
        f.vehicle = Some(VehicleSpec {
            max_speed_up_m_s: Some(1.0),
            max_accel_xy_m_s2: Some(1.0),
            ..VehicleSpec::default()
        });
        let s = Scenario::from_file(f, "t", Checks::Member).unwrap();
        let n = s.formation.members.len();
        let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
        let mut a = LimitAudit::new(&s).unwrap();
        let alive = vec![true; n];
        let mut vel = vec![Vec3::zeros(); n];
        let mut seen = Vec::new();
        a.observe(0.0, &vel, &alive, &ids, |b| seen.push(b));
        vel[3] = Vec3::new(0.0, 0.0, 1.2);
        vel[5] = Vec3::new(0.3, 0.4, 0.0);
        a.observe(0.1, &vel, &alive, &ids, |b| seen.push(b));
        a.observe(0.2, &vel, &alive, &ids, |b| seen.push(b));
        let got: Vec<(usize, Limit)> = seen.iter().map(|b| (b.member, b.limit)).collect();
        // Member 3 climbs at 1.2 m/s > 1.1 (once, while it lasts); member 5 gains 0.5 m/s of
        // horizontal speed in 0.1 s, 5 m/s^2 (member 3's climb is vertical).
        assert_eq!(got, vec![(3, Limit::SpeedUp), (5, Limit::AccelXy)]);
        assert!((a.flown[1].flown - 5.0).abs() < 1e-12 && a.flown[1].agent == Some(ids[5]));
    }
}
