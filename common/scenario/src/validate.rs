//! Validation of a scenario file, in the order a user would want to hear about problems.

use std::collections::BTreeSet;

use super::{Checks, Scenario, ScenarioErrorKind as E, ScenarioFile, DEFAULT_PLANE_TOLERANCE_M};
use cdm_math::{vec3, Real, Vec3};
use cdm_model::formation::{Formation, MemberInput, Role};
use cdm_model::frame::{leader_sine, Frame, MIN_LEADER_SINE};
use cdm_model::gains::stability_margin;
use cdm_model::graph::{synthesize, DEFAULT_WEIGHT_FLOOR};
use cdm_model::plan::TeamPlan;

use crate::fields::{coordinate, finite, positive, MAX_COORD_M, MAX_TICKS, MIN_MOTION_TICKS};

fn check_numbers(f: &ScenarioFile) -> Result<(), E> {
    positive("t_total_s", f.t_total_s)?;
    positive("comm_hz", f.comm_hz)?;
    finite("eps_m", f.eps_m)?;
    if f.eps_m < 0.0 {
        return Err(E::Invalid {
            field: "eps_m".into(),
            reason: format!("must be >= 0, got {}", f.eps_m),
        });
    }
    for (k, g) in f.gains.iter().enumerate() {
        positive(&format!("gains[{k}] (k{})", k + 1), *g)?;
    }
    if f.name.trim().is_empty() {
        return Err(E::Invalid {
            field: "name".into(),
            reason: "must not be empty".into(),
        });
    }
    if f.lambda_cd_min.is_some() && f.delta_m.is_some() {
        return Err(E::Invalid {
            field: "lambda_cd_min".into(),
            reason: "and `delta_m` are exclusive (each fixes the other through eq. 38)".into(),
        });
    }
    if let Some(l) = f.lambda_cd_min {
        finite("lambda_cd_min", l)?;
        if !(l > 0.0 && l <= 1.0) {
            return Err(E::Invalid {
                field: "lambda_cd_min".into(),
                reason: format!("must be in (0, 1], got {l}"),
            });
        }
    }
    if let Some(d) = f.delta_m {
        positive("delta_m", d)?;
    }
    check_optional(f)?;
    super::airspace::check_tables(f)?;
    super::origin::check_table(f)?;
    if let Some(v) = &f.vehicle {
        super::vehicle::check(v)?;
    }
    if f.name.len() > MAX_NAME_BYTES {
        return Err(E::Invalid {
            field: "name".into(),
            reason: format!(
                "is {} bytes long; at most {MAX_NAME_BYTES} bytes are allowed",
                f.name.len()
            ),
        });
    }
    check_resolution(f)?;
    if f.comm_hz * f.t_total_s > MAX_TICKS {
        return Err(E::Invalid {
            field: "t_total_s".into(),
            reason: format!(
                "times comm_hz gives {:.3e} ticks; at most {MAX_TICKS:e} are supported",
                f.comm_hz * f.t_total_s
            ),
        });
    }
    Ok(())
}

/// The optional tables and fields: `[link]`, `substeps`, `weight_floor`, `plane_tolerance_m`.
fn check_optional(f: &ScenarioFile) -> Result<(), E> {
    if let Some((field, reason)) = f.link.and_then(|l| l.problem()) {
        return Err(E::Invalid {
            field: field.into(),
            reason,
        });
    }
    if let Some(s) = f.substeps {
        if !(1..=1000).contains(&s) {
            return Err(E::Invalid {
                field: "substeps".into(),
                reason: format!("must be in 1..=1000, got {s}"),
            });
        }
    }
    if let Some(w) = f.weight_floor {
        finite("weight_floor", w)?;
        if !(w > 0.0 && w < 1.0 / 3.0) {
            return Err(E::Invalid {
                field: "weight_floor".into(),
                reason: format!("must be in (0, 1/3), got {w}"),
            });
        }
    }
    if let Some(t) = f.plane_tolerance_m {
        finite("plane_tolerance_m", t)?;
        if t < 0.0 {
            return Err(E::Invalid {
                field: "plane_tolerance_m".into(),
                reason: format!("must be >= 0, got {t}"),
            });
        }
    }
    Ok(())
}

/// The longest scenario name (it is printed, hashed and carried by every member).
pub const MAX_NAME_BYTES: usize = 256;
/// The fastest clock: beyond it a tick is shorter than a process wake-up (BENCHMARKS.md), and
/// the certificate's flights grow without bound.
pub const MAX_COMM_HZ: Real = 10_000.0;
/// Largest h |lambda| for an RK4 step h and the gains' fastest pole lambda. RK4 is stable up to
/// about 2.8 on the real axis; 1 keeps the integration accurate, not merely stable.
pub const MAX_STEP_TIMES_POLE: Real = 1.0;

/// Whether the ticks can resolve the motion: enough ticks over T_total, and an RK4 step
/// (dt / substeps) short enough for the fastest pole of the leaders' tracking loop
/// s^4 + k1 s^3 + k2 s^2 + k3 s + k4 (eq. 26 with mu = -1).
fn check_resolution(f: &ScenarioFile) -> Result<(), E> {
    if f.comm_hz > MAX_COMM_HZ {
        return Err(E::Invalid {
            field: "comm_hz".into(),
            reason: format!("must be at most {MAX_COMM_HZ} Hz, got {}", f.comm_hz),
        });
    }
    let pole = cdm_model::gains::mode_roots(&f.gains, (-1.0, 0.0))
        .iter()
        .map(|&(re, im)| re.hypot(im))
        .fold(0.0, Real::max);
    let substeps = Real::from(f.substeps.unwrap_or(super::DEFAULT_SUBSTEPS).max(1));
    let h = 1.0 / f.comm_hz / substeps;
    // A NaN pole (gains too large to find the roots) is refused too.
    if h * pole > MAX_STEP_TIMES_POLE || pole.is_nan() {
        return Err(E::Invalid {
            field: "comm_hz".into(),
            reason: format!(
                "{} Hz is too coarse for the gains' fastest pole ({pole:.4} rad/s): an RK4 step dt / substeps = {h} s needs step x pole <= {MAX_STEP_TIMES_POLE}; raise comm_hz to at least {:.4} Hz or substeps",
                f.comm_hz,
                pole * substeps.recip() / MAX_STEP_TIMES_POLE
            ),
        });
    }
    let ticks = f.t_total_s * f.comm_hz;
    if ticks < MIN_MOTION_TICKS {
        return Err(E::Invalid {
            field: "t_total_s".into(),
            reason: format!(
                "times comm_hz gives {ticks} ticks over the motion; at least {MIN_MOTION_TICKS} are needed to resolve it (raise t_total_s or comm_hz)"
            ),
        });
    }
    Ok(())
}

pub(super) fn validate(mut file: ScenarioFile, checks: Checks) -> Result<Scenario, E> {
    check_numbers(&file)?;
    check_agents(&file)?;
    check_roles(&file)?;
    let (frame, plan) = leaders_plan(&file)?;
    let notes = project_onto_plane(&mut file, &frame)?;
    let mut formation = formation_of(&mut file, frame)?;
    let plan = if super::mission::has_mission(&file) {
        let phases = super::mission::phases(&file, &plan, &formation)?;
        if let Some(to) = &file.takeoff {
            // Every member starts on the ground below its place in the formation.
            for m in &mut formation.members {
                m.start = Vec3::new(m.position.x, m.position.y, to.ground_z_m);
            }
        }
        plan.with_phases(phases)
    } else {
        plan
    };
    super::airspace::check_starts(&file, &formation)?;
    let gains_margin = match checks {
        Checks::Member => None,
        Checks::Full => {
            let margin = stability_margin(&file.gains, &formation.l_block());
            if margin.is_nan() || margin <= 0.0 {
                return Err(E::UnstableGains {
                    gains: file.gains,
                    worst_real: -margin,
                });
            }
            Some(margin)
        }
    };
    Ok(Scenario {
        origin: String::new(),
        file,
        formation,
        plan,
        notes,
        gains_margin,
    })
}

/// The team's size, unique ids, finite positions and goals.
fn check_agents(file: &ScenarioFile) -> Result<(), E> {
    if file.agents.len() < 4 {
        return Err(E::Invalid {
            field: "agents".into(),
            reason: format!(
                "needs at least 4 agents (3 primary leaders and a follower), got {}",
                file.agents.len()
            ),
        });
    }
    if file.agents.len() > super::MAX_AGENTS {
        return Err(E::Invalid {
            field: "agents".into(),
            reason: format!(
                "has {} agents; at most {} are supported",
                file.agents.len(),
                super::MAX_AGENTS
            ),
        });
    }
    let mut ids = BTreeSet::new();
    for a in &file.agents {
        if !ids.insert(a.id) {
            return Err(E::DuplicateId { id: a.id });
        }
        // The field's name is formatted only for a bad value: every member of a team runs this
        // for every agent at start (3,000 names at N = 1000).
        for (c, v) in a.position.iter().enumerate() {
            if !v.is_finite() || v.abs() > MAX_COORD_M {
                coordinate(format!("agents[id={}].position[{c}]", a.id), *v)?;
            }
        }
        if let Some(g) = a.goal {
            for (c, v) in g.iter().enumerate() {
                if !v.is_finite() || v.abs() > MAX_COORD_M {
                    coordinate(format!("agents[id={}].goal[{c}]", a.id), *v)?;
                }
            }
        }
    }
    Ok(())
}

/// Exactly three primary leaders, each with a goal; goals only on primaries, neighbours only on
/// followers.
fn check_roles(file: &ScenarioFile) -> Result<(), E> {
    let primaries: Vec<u32> = file
        .agents
        .iter()
        .filter(|a| a.role == Role::Primary)
        .map(|a| a.id)
        .collect();
    if primaries.len() != 3 {
        return Err(E::PrimaryCount { found: primaries });
    }
    for a in &file.agents {
        match (a.role, &a.goal, &a.in_neighbors) {
            (Role::Primary, None, _) => return Err(E::MissingGoal { id: a.id }),
            (Role::Secondary | Role::Follower, Some(_), _) => {
                return Err(E::GoalOnNonPrimary {
                    id: a.id,
                    role: a.role.as_str(),
                })
            }
            (Role::Primary | Role::Secondary, _, Some(_)) => {
                return Err(E::NeighborsOnLeader {
                    id: a.id,
                    role: a.role.as_str(),
                })
            }
            _ => {}
        }
    }
    Ok(())
}

/// The primary leaders' frame at t0 and their plan, refused when the three leaders are
/// collinear at t0, at their goals or anywhere along the plan.
fn leaders_plan(file: &ScenarioFile) -> Result<(Frame, TeamPlan), E> {
    let prim: Vec<&super::AgentSpec> = file
        .agents
        .iter()
        .filter(|a| a.role == Role::Primary)
        .collect();
    let pid = [prim[0].id, prim[1].id, prim[2].id];
    let start = [
        vec3(prim[0].position),
        vec3(prim[1].position),
        vec3(prim[2].position),
    ];
    let goal: [Vec3; 3] = std::array::from_fn(|k| vec3(prim[k].goal.unwrap_or_default()));
    let frame = Frame::new(&start[0], &start[1], &start[2]).map_err(|e| E::Collinear {
        ids: pid,
        when: "at t0".into(),
        sine: e.sine,
    })?;
    let sine_goal = leader_sine(&goal[0], &goal[1], &goal[2]);
    if sine_goal.is_nan() || sine_goal < MIN_LEADER_SINE {
        return Err(E::Collinear {
            ids: pid,
            when: "at their goals".into(),
            sine: sine_goal,
        });
    }
    let plan = TeamPlan::new(file.t_total_s, start, goal).map_err(|e| E::Collinear {
        ids: pid,
        when: "at t0".into(),
        sine: e.sine,
    })?;
    // Collinear during the plan: scan the path parameter.
    for k in 0..=1000 {
        let s = k as Real / 1000.0;
        let r = plan.primaries_at_s(s);
        let sine = leader_sine(&r[0], &r[1], &r[2]);
        if sine.is_nan() || sine < MIN_LEADER_SINE {
            return Err(E::Collinear {
                ids: pid,
                when: format!("at t = {:.3} s", plan.quintic.time_of(s)),
                sine,
            });
        }
    }
    Ok((frame, plan))
}

/// Projects every non-primary member onto the primary leaders' plane (ERRATA 10); one note per
/// member moved. A member farther than the tolerance is refused.
fn project_onto_plane(file: &mut ScenarioFile, frame: &Frame) -> Result<Vec<String>, E> {
    let tol = file.plane_tolerance_m.unwrap_or(DEFAULT_PLANE_TOLERANCE_M);
    let mut notes = Vec::new();
    for a in file.agents.iter_mut() {
        let p = vec3(a.position);
        let (g, b, off) = frame.coords(&p);
        if off.abs() > tol {
            return Err(E::OffPlane {
                id: a.id,
                distance_m: off.abs(),
                tolerance_m: tol,
            });
        }
        // Below 1e-9 m the point is on the plane up to rounding: leave its bits alone so that a
        // flown scenario re-validates to itself.
        if off.abs() > 1e-9 && a.role != Role::Primary {
            let q = frame.point(g, b);
            notes.push(format!(
                "agent {}: projected {:.3} m onto the primary leaders' plane (tolerance {tol} m)",
                a.id,
                off.abs()
            ));
            a.position = [q.x, q.y, q.z];
        }
    }
    Ok(notes)
}

/// The formation (weights eq. 18, synthesised in-neighbours written back into the file).
fn formation_of(file: &mut ScenarioFile, frame: Frame) -> Result<Formation, E> {
    let mut inputs = Vec::with_capacity(file.agents.len());
    for a in &file.agents {
        let in_neighbors = match &a.in_neighbors {
            None => None,
            Some(v) if v.len() == 3 => Some([v[0], v[1], v[2]]),
            Some(v) => {
                return Err(E::Formation(
                    cdm_model::formation::FormationError::NotThreeNeighbors {
                        id: a.id,
                        given: v.clone(),
                    },
                ))
            }
        };
        inputs.push(MemberInput {
            id: a.id,
            role: a.role,
            position: vec3(a.position),
            in_neighbors,
        });
    }
    let mut formation = Formation::new(frame, &inputs)?;
    synthesize(
        &mut formation,
        file.weight_floor.unwrap_or(DEFAULT_WEIGHT_FLOOR),
    )?;
    formation.check_links()?;
    for a in file.agents.iter_mut() {
        if let Some(link) = formation.member(a.id).and_then(|m| m.link) {
            a.in_neighbors = Some(link.in_neighbors.to_vec());
        }
    }
    Ok(formation)
}
