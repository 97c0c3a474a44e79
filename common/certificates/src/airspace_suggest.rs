//! `plan --suggest`: what would clear the airspace certificate's breaches.
//!
//! - An altitude offset: every height above the ground raised (or lowered) by dz, a take-off's
//!   and a landing's ground spots kept. Every point of every path moves by at most |dz|, and
//!   every margin is a distance, so each margin is 1-Lipschitz in dz: from a margin m < 0 no
//!   offset closer than |m| can clear it. Stepping by |m| (at least `MIN_STEP_M`) from 0 finds
//!   the smallest clearing offset in each direction without skipping one, to within a
//!   millimetre; the plan so shifted is validated and certified again.
//! - A uniform time scaling: never. The paths do not depend on the travel times (each member's
//!   desired position runs along the same segment per phase, eqs. 13, 15) and the balls'
//!   radius eps + delta does not either (eq. 38), so the suggestion says so.

use crate::airspace_certificate::{
    certify_airspace, clearance, tracks, worst_margins, Offsets, Suggestion, NO_TIME_SCALING,
};
use cdm_math::Real;
use cdm_model::airspace::{Boundary, Shape};
use cdm_scenario::{Checks, Scenario, ScenarioErrorKind};

/// The smallest step of the offset search (metres): the suggested offset is within this of
/// the smallest one.
pub const MIN_STEP_M: Real = 1e-3;
/// The most margin evaluations one search makes.
const MAX_STEPS: usize = 10_000;

/// The suggestion for `s` with balls of `radius_m`; empty rows when nothing is breached.
pub fn suggest(s: &Scenario, radius_m: Real) -> Suggestion {
    let base = worst_margins(s, &tracks(s, 0.0), radius_m);
    let breached: Vec<Boundary> = (base.iter())
        .filter(|(_, w)| w.margin_m.is_nan() || w.margin_m < 0.0)
        .map(|(b, _)| *b)
        .collect();
    let mut out = Suggestion {
        offsets: Vec::new(),
        time_scale: None,
        time_scaling_note: NO_TIME_SCALING,
        notes: Vec::new(),
    };
    if breached.is_empty() {
        return out;
    }
    let limit = vertical_span(s, radius_m);
    let margins = |dz: Real| worst_margins(s, &tracks(s, dz), radius_m);
    let tr = tracks(s, 0.0);
    for b in &breached {
        let of = |dz: Real| margins(dz).get(b).map_or(Real::NAN, |w| w.margin_m);
        out.offsets.push(Offsets {
            what: clearance(s, &tr, *b, &base[b]).label(),
            raise_m: first_clear(1.0, limit, of),
            lower_m: first_clear(-1.0, limit, of),
        });
    }
    let all = |dz: Real| {
        (margins(dz).values())
            .map(|w| w.margin_m)
            .fold(Real::INFINITY, |a, m| if m.is_nan() { m } else { a.min(m) })
    };
    let mut whole = Offsets {
        what: "the whole airspace".into(),
        raise_m: first_clear(1.0, limit, all),
        lower_m: first_clear(-1.0, limit, all),
    };
    let delta = radius_m - s.file.eps_m;
    for (dz, sign) in [(&mut whole.raise_m, 1.0), (&mut whole.lower_m, -1.0)] {
        if let Some(d) = *dz {
            if let Err(why) = recertify(s, sign * d, delta) {
                out.notes.push(why.to_string());
                *dz = None;
            }
        }
    }
    out.offsets.push(whole);
    out
}

/// The smallest offset |dz| in direction `dir` (+1 up, -1 down) whose margin is >= 0, up to
/// `limit` (module docs: `margin` is 1-Lipschitz in dz).
fn first_clear(dir: Real, limit: Real, margin: impl Fn(Real) -> Real) -> Option<Real> {
    let mut dz = 0.0;
    for _ in 0..MAX_STEPS {
        let m = margin(dir * dz);
        if m >= 0.0 {
            return Some(dz);
        }
        if m.is_nan() {
            return None;
        }
        dz += (-m).max(MIN_STEP_M);
        if dz > limit {
            return None;
        }
    }
    None
}

/// How far an offset can matter: beyond the vertical span of the fence, the obstacles and the
/// team's paths (and a ball), every obstacle is cleared or none can be.
fn vertical_span(s: &Scenario, radius_m: Real) -> Real {
    let mut zs: Vec<Real> = tracks(s, 0.0).iter().flat_map(|t| [t.a.z, t.b.z]).collect();
    if let Some(g) = &s.file.geofence {
        zs.extend([g.min_z_m, g.max_z_m]);
    }
    for o in &s.file.obstacles {
        match o.shape {
            Shape::Box { min, max } => zs.extend([min[2], max[2]]),
            Shape::Cylinder {
                min_z_m, max_z_m, ..
            } => zs.extend([min_z_m, max_z_m]),
        }
    }
    let lo = zs.iter().copied().fold(Real::INFINITY, Real::min);
    let hi = zs.iter().copied().fold(Real::NEG_INFINITY, Real::max);
    hi - lo + 2.0 * radius_m + 1.0
}

/// Why moving every height does not clear the airspace (a note of the suggestion).
#[derive(Debug, thiserror::Error)]
enum ShiftRefused {
    /// The shifted plan fails validation.
    #[error("moving every height by {dz_m:+.3} m is refused: {kind}")]
    Invalid { dz_m: Real, kind: ScenarioErrorKind },
    /// The shifted plan validates but still breaches a boundary.
    #[error("moved by {dz_m:+.3} m the plan still breaches {reason}")]
    Breaches { dz_m: Real, reason: String },
}

/// The plan with every height above the ground moved by `dz_m`, validated and certified again
/// (with the same delta: a translation changes no D_B, D_S or lambda_1); the reason when it is
/// refused or still breaches.
fn recertify(s: &Scenario, dz_m: Real, delta_m: Real) -> Result<(), ShiftRefused> {
    let mut f = s.file.clone();
    for a in &mut f.agents {
        a.position[2] += dz_m;
        if let Some(g) = &mut a.goal {
            g[2] += dz_m;
        }
    }
    for seg in &mut f.segments {
        for g in &mut seg.goals {
            g[2] += dz_m;
        }
    }
    let shifted = Scenario::from_file(f, &s.origin, Checks::Member)
        .map_err(|e| ShiftRefused::Invalid { dz_m, kind: e.kind })?;
    let reasons = certify_airspace(&shifted, delta_m).map_or(Vec::new(), |c| c.reasons());
    match reasons.first() {
        None => Ok(()),
        Some(r) => Err(ShiftRefused::Breaches {
            dz_m,
            reason: r.clone(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_scenario::{paper40, ObstacleSpec};

    /// A box across paper40's descent: lifting the team over it takes its top plus the ball
    /// above the lowest path that crosses it; a fence ceiling can forbid the lift.
    #[test]
    fn the_smallest_lift_clears_a_box_and_a_ceiling_can_forbid_it() {
        let mut f = paper40();
        // Goals are at z = 560; the box spans the goal area up to 600 m.
        f.obstacles = vec![ObstacleSpec {
            name: "block".into(),
            shape: Shape::Box {
                min: [100.0, 200.0, 0.0],
                max: [350.0, 450.0, 600.0],
            },
        }];
        let s = Scenario::from_file(f.clone(), "t", Checks::Member).unwrap();
        let r = 5.0;
        let got = suggest(&s, r);
        let whole = got.offsets.last().unwrap();
        // Every goal is at 560 m inside the box's footprint: the lift is 600 + r - 560.
        let lift = whole.raise_m.unwrap();
        assert!((lift - 45.0).abs() <= 2.0 * MIN_STEP_M, "{got:?}");
        assert!(got.notes.is_empty(), "{got:?}");
        assert_eq!(got.offsets[0].what, "obstacle \"block\"");
        // With a ceiling 30 m above the highest start the lift breaches it instead.
        f.geofence = Some(cdm_scenario::GeofenceSpec {
            polygon: vec![
                [-300.0, -200.0],
                [500.0, -200.0],
                [500.0, 600.0],
                [-300.0, 600.0],
            ],
            min_z_m: 0.0,
            max_z_m: 1230.0,
        });
        let s = Scenario::from_file(f, "t", Checks::Member).unwrap();
        let got = suggest(&s, r);
        assert_eq!(got.offsets.len(), 2, "{got:?}");
        assert_eq!(got.offsets[1].raise_m, None, "{got:?}");
        assert_eq!(got.time_scale, None);
    }
}
