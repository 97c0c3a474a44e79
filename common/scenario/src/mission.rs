//! Missions: take-off, further deformation segments and landing around the paper's
//! one manoeuvre, checked and turned into the plan's phases.
//!
//! Every phase is a homogeneous transformation of the reference formation (the agents'
//! `position`s): its primary leaders move between two waypoints on the quintic of eq. 15, rest to
//! rest, and every other member follows as the same affine combination (eq. 13), so the weights
//! of eq. 18, fixed at t0, hold in every phase. Take-off maps the formation to its ground spots
//! (x, y, ground): an affine map too, scaling heights above the ground.

use serde::{Deserialize, Serialize};

use super::{ScenarioErrorKind as E, ScenarioFile};
use crate::fields::{coordinate, finite, positive, MAX_TICKS, MIN_MOTION_TICKS};
use cdm_math::{vec3, Real, Vec3};
use cdm_model::formation::{Formation, Role};
use cdm_model::frame::{leader_sine, MIN_LEADER_SINE};
use cdm_model::plan::{Phase, PhaseKind, TeamPlan};

/// `[takeoff]` or `[landing]`: every member rises from, or lands on, the ground below it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundSpec {
    /// Height of the ground, metres (the same frame as the positions).
    pub ground_z_m: Real,
    /// Duration of the climb or descent (eq. 15 quintic, rest to rest), seconds.
    pub t_s: Real,
    /// Hover at the top: after take-off, before segment 1; before landing (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold_s: Option<Real>,
}

/// `[[segment]]`: one more deformation after the previous goal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentSpec {
    /// Hover before this segment starts, seconds (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold_s: Option<Real>,
    /// Travel time, seconds.
    pub t_s: Real,
    /// The primary leaders' positions at its end, in ascending id order.
    pub goals: Vec<[Real; 3]>,
}

/// True when the file has any mission table.
pub fn has_mission(f: &ScenarioFile) -> bool {
    f.takeoff.is_some() || !f.segments.is_empty() || f.landing.is_some()
}

/// The mission's phases in flight order, checked; `plan` is segment 1 (the agents' own goals).
/// Errors name the phase and its field.
pub(super) fn phases(
    f: &ScenarioFile,
    plan: &TeamPlan,
    formation: &Formation,
) -> Result<Vec<Phase>, E> {
    let ids = primary_ids(f);
    let order = primary_order(&ids);
    let mut out = Vec::new();
    let mut t = 0.0;
    if let Some(to) = &f.takeoff {
        let (t_s, hold) = timing(f, "takeoff", to.t_s, to.hold_s)?;
        let ground = ground_of(
            &plan.start,
            coordinate("takeoff.ground_z_m", to.ground_z_m)?,
        );
        check_ground(f, formation, "takeoff", to.ground_z_m, &plan.start)?;
        out.push(phase(PhaseKind::Takeoff, t, t_s, ground, plan.start));
        t += t_s + hold;
    }
    out.push(phase(
        PhaseKind::Segment(1),
        t,
        f.t_total_s,
        plan.start,
        plan.goal,
    ));
    t += f.t_total_s;
    for (k, seg) in f.segments.iter().enumerate() {
        let n = k as u32 + 2;
        let name = format!("segment {n}");
        let (t_s, hold) = timing(f, &name, seg.t_s, seg.hold_s)?;
        let goal = goals_of(seg, &name, &order)?;
        let from = out.last().map_or(plan.goal, |p: &Phase| p.goal);
        let p = phase(PhaseKind::Segment(n), t + hold, t_s, from, goal);
        check_collinear(ids, &p, &name)?;
        out.push(p);
        t += hold + t_s;
    }
    if let Some(la) = &f.landing {
        let (t_s, hold) = timing(f, "landing", la.t_s, la.hold_s)?;
        let from = out.last().map_or(plan.goal, |p| p.goal);
        let ground = ground_of(&from, coordinate("landing.ground_z_m", la.ground_z_m)?);
        check_ground(f, formation, "landing", la.ground_z_m, &from)?;
        out.push(phase(PhaseKind::Landing, t + hold, t_s, from, ground));
    }
    let ticks = out.last().map_or(0.0, Phase::t_end_s) * f.comm_hz;
    if ticks > MAX_TICKS {
        return Err(E::Invalid {
            field: "segment".into(),
            reason: format!(
                "the whole mission times comm_hz gives {ticks:.3e} ticks; at most {MAX_TICKS:e} are supported"
            ),
        });
    }
    Ok(out)
}

fn phase(kind: PhaseKind, t_start_s: Real, t_s: Real, start: [Vec3; 3], goal: [Vec3; 3]) -> Phase {
    Phase::rest_to_rest(kind, t_start_s, t_s, start, goal)
}

/// A phase's travel time and hold, checked (field names `NAME.t_s`, `NAME.hold_s`).
fn timing(f: &ScenarioFile, name: &str, t_s: Real, hold: Option<Real>) -> Result<(Real, Real), E> {
    let t_s = positive(&format!("{name}.t_s"), t_s)?;
    let ticks = t_s * f.comm_hz;
    if ticks < MIN_MOTION_TICKS {
        return Err(E::Invalid {
            field: format!("{name}.t_s"),
            reason: format!(
                "times comm_hz gives {ticks} ticks; at least {MIN_MOTION_TICKS} are needed"
            ),
        });
    }
    let hold = finite(format!("{name}.hold_s"), hold.unwrap_or(0.0))?;
    if hold < 0.0 {
        return Err(E::Invalid {
            field: format!("{name}.hold_s"),
            reason: format!("must be >= 0, got {hold}"),
        });
    }
    for (field, v) in [("t_s", t_s), ("hold_s", hold)] {
        let ticks = v * f.comm_hz;
        if ticks > MAX_TICKS {
            return Err(E::Invalid {
                field: format!("{name}.{field}"),
                reason: format!(
                    "= {v:.3e} s times comm_hz gives {ticks:.3e} ticks; at most {MAX_TICKS:e} are supported"
                ),
            });
        }
    }
    Ok((t_s, hold))
}

/// The primary leaders' ids in the plan's order (file order; validation found exactly three).
pub(crate) fn primary_ids(f: &ScenarioFile) -> [u32; 3] {
    let mut ids = (f.agents.iter())
        .filter(|a| a.role == Role::Primary)
        .map(|a| a.id);
    std::array::from_fn(|_| ids.next().unwrap_or(0))
}

/// For each primary leader in the plan's order, its rank in ascending id order (the order of a
/// segment's `goals`).
pub(crate) fn primary_order(ids: &[u32; 3]) -> [usize; 3] {
    let mut sorted = *ids;
    sorted.sort_unstable();
    std::array::from_fn(|k| sorted.iter().position(|&id| id == ids[k]).unwrap_or(k))
}

fn goals_of(seg: &SegmentSpec, name: &str, order: &[usize; 3]) -> Result<[Vec3; 3], E> {
    if seg.goals.len() != 3 {
        return Err(E::Invalid {
            field: format!("{name}.goals"),
            reason: format!(
                "must list the 3 primary leaders' positions (ascending id), got {}",
                seg.goals.len()
            ),
        });
    }
    for (k, g) in seg.goals.iter().enumerate() {
        for (c, v) in g.iter().enumerate() {
            coordinate(format!("{name}.goals[{k}][{c}]"), *v)?;
        }
    }
    Ok(std::array::from_fn(|k| vec3(seg.goals[order[k]])))
}

/// The primary leaders stay a triangle along the segment and at its goal (eq. 7).
fn check_collinear(ids: [u32; 3], p: &Phase, name: &str) -> Result<(), E> {
    // The waypoint first (the likelier mistake, and the clearer message), then the way there.
    for k in std::iter::once(1000).chain(0..1000) {
        let s = k as Real / 1000.0;
        let r = p.primaries_at_s(s);
        let sine = leader_sine(&r[0], &r[1], &r[2]);
        if sine.is_nan() || sine < MIN_LEADER_SINE {
            let when = if k == 1000 {
                format!("at {name}'s goals")
            } else {
                format!(
                    "in {name} at t = {:.3} s",
                    p.t_start_s + p.quintic.time_of(s)
                )
            };
            return Err(E::Collinear { ids, when, sine });
        }
    }
    Ok(())
}

/// The primary leaders' ground spots below `at`.
fn ground_of(at: &[Vec3; 3], ground_z_m: Real) -> [Vec3; 3] {
    at.map(|p| Vec3::new(p.x, p.y, ground_z_m))
}

/// Take-off or landing from `at` (the primary leaders' positions at its top): the ground is
/// below every member, and the ground spots are at least 2 eps apart (the vertical paths are
/// then too: ARCHITECTURE.md, "Take-off and landing").
fn check_ground(
    f: &ScenarioFile,
    formation: &Formation,
    name: &str,
    ground_z_m: Real,
    at: &[Vec3; 3],
) -> Result<(), E> {
    let field = format!("{name}.ground_z_m");
    let top: Vec<(u32, Vec3)> = formation
        .members
        .iter()
        .map(|m| {
            let a = m.alpha;
            (m.id, at[0] * a[0] + at[1] * a[1] + at[2] * a[2])
        })
        .collect();
    if let Some((id, p)) = top.iter().min_by(|a, b| a.1.z.total_cmp(&b.1.z)) {
        if p.z <= ground_z_m {
            return Err(E::Invalid {
                field,
                reason: format!(
                    "= {ground_z_m} m is not below agent {id} (z = {:.3} m at the {name}'s top)",
                    p.z
                ),
            });
        }
    }
    let spots = ground_of(at, ground_z_m);
    if leader_sine(&spots[0], &spots[1], &spots[2]) < MIN_LEADER_SINE {
        return Err(E::Invalid {
            field,
            reason: "the primary leaders' ground spots are collinear (a vertical formation plane cannot take off or land)".into(),
        });
    }
    let (d, a, b) = closest_ground_pair(&top);
    if d < 2.0 * f.eps_m {
        return Err(E::Invalid {
            field,
            reason: format!(
                "agents {a} and {b} have ground spots {d:.3} m apart at the {name}, closer than 2 eps = {} m",
                2.0 * f.eps_m
            ),
        });
    }
    Ok(())
}

/// The smallest horizontal distance between two members and their ids (a sweep along x: the
/// pairs further apart in x than the best so far are skipped).
pub fn closest_ground_pair(at: &[(u32, Vec3)]) -> (Real, u32, u32) {
    let mut by_x: Vec<&(u32, Vec3)> = at.iter().collect();
    by_x.sort_by(|a, b| a.1.x.total_cmp(&b.1.x));
    let mut best = (Real::INFINITY, 0, 0);
    for (i, a) in by_x.iter().enumerate() {
        for b in &by_x[i + 1..] {
            if b.1.x - a.1.x >= best.0 {
                break;
            }
            let d = (a.1.x - b.1.x).hypot(a.1.y - b.1.y);
            if d < best.0 {
                best = (d, a.0.min(b.0), a.0.max(b.0));
            }
        }
    }
    best
}
