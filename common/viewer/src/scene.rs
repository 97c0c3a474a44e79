//! What the viewer draws, as plain data: the team's static description ([`Scene`]) and one
//! [`ShownTick`] per shown tick with the four margins of the live audit. Pure: no I/O, the same code
//! feeds `replay.html` and the live `--serve` stream.

use serde::Serialize;

use cdm_math::Real;
use cdm_model::formation::Role;
use cdm_scenario::{GeofenceSpec, ObstacleSpec, Scenario};

use cdm_records::audit::CommandSummary;
use cdm_records::margins::{boundary_distance, lambdas_at, living_separation};
use cdm_report::data::{RepairRecord, TickPositions, ViolationMark};

/// One member as the viewer lists it.
#[derive(Debug, Clone, Serialize)]
pub struct AgentInfo {
    pub id: u32,
    pub role: &'static str,
}

/// The static part of a run: who flies, the graph, the limits the margins are measured against.
#[derive(Debug, Clone, Serialize)]
pub struct Scene {
    pub scenario: String,
    pub agents: Vec<AgentInfo>,
    /// Communication graph as (in-neighbour, follower) member indices (eq. 18).
    pub edges: Vec<[usize; 2]>,
    /// Member indices of the leading polygon, counter-clockwise.
    pub polygon: Vec<usize>,
    /// Theorem 3's prism half height, delta + eps.
    pub half_height_m: Real,
    pub eps_m: Real,
    pub delta_m: Real,
    pub lambda_cd_min: Real,
    pub dt_s: Real,
    pub last_tick: u64,
    /// `SAFE`, `UNSAFE`, `FAULT`, or `RUNNING` while a live team flies.
    pub verdict: String,
    pub violations: Vec<ViolationMark>,
    /// Replay only (empty live: frames arrive as events).
    pub frames: Vec<ShownTick>,
    /// How many ticks one replay frame stands for (1 live).
    pub stride: u64,
    /// The graph after each loss's repair, from the tick it applies (replay of a run with losses).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub graphs: Vec<GraphChange>,
    /// A mission's phases, marked on the replay's timeline; none for one manoeuvre.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub phases: Vec<PhaseMark>,
    /// The scenario's `[geofence]`, drawn as a wire prism.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub geofence: Option<GeofenceSpec>,
    /// The scenario's `[[obstacle]]`s, drawn as translucent solids with their names.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub obstacles: Vec<ObstacleSpec>,
    /// The run's commands (`commands.json`), marked on the timeline at their switch ticks and
    /// counted in the status by the shown tick; none for a run without.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub commands: Vec<CommandMark>,
}

/// One command to the team in flight as the viewer marks it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CommandMark {
    /// `hold`, `resume`, `land` or `goto`.
    pub command: String,
    /// Its switch tick (a refused command's motion was never flown).
    pub tick: u64,
    pub accepted: bool,
    /// Why it was refused.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub why: Option<String>,
}

impl From<&CommandSummary> for CommandMark {
    fn from(c: &CommandSummary) -> Self {
        CommandMark {
            command: c.command.clone(),
            tick: c.switch_tick,
            accepted: c.accepted,
            why: c.why.clone(),
        }
    }
}

/// One phase of a mission: its name and when its motion starts and ends (simulation seconds).
#[derive(Debug, Clone, Serialize)]
pub struct PhaseMark {
    pub name: String,
    pub t_start_s: Real,
    pub t_end_s: Real,
}

/// The communication graph in force from `tick` on, as (in-neighbour, follower) member indices.
#[derive(Debug, Clone, Serialize)]
pub struct GraphChange {
    pub tick: u64,
    pub edges: Vec<[usize; 2]>,
}

/// One shown tick.
#[derive(Debug, Clone, Serialize)]
pub struct ShownTick {
    pub tick: u64,
    pub t: Real,
    /// Positions in millimetres, x y z per member (integers keep replay.html small).
    pub p: Vec<i64>,
    /// Smallest distance between two members (limit 2 eps, Fig. 11).
    pub sep: Real,
    /// Largest follower deviation |r - r_HT| (limit delta, eq. 38).
    pub dev: Real,
    /// Smallest follower distance to the prism's sides (limit 0, Theorem 3, Fig. 11).
    pub bnd: Real,
    /// lambda_1(U_D) (limit lambda_CD,min, Fig. 8).
    pub l1: Real,
    /// Member indices no longer flying (lost) at this tick.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub lost: Vec<usize>,
    /// Ticks per second of wall time (live frames only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rate: Option<Real>,
}

/// The phases of a mission, or none for the paper's one manoeuvre.
fn phase_marks(s: &Scenario) -> Vec<PhaseMark> {
    if !s.plan.is_mission() {
        return Vec::new();
    }
    (s.plan.phases().iter())
        .map(|p| PhaseMark {
            name: p.kind.name(),
            t_start_s: p.t_start_s,
            t_end_s: p.t_end_s(),
        })
        .collect()
}

impl Scene {
    /// The static scene of a scenario; `delta_m` and `eps_m` come from the audit.
    pub fn new(s: &Scenario, delta_m: Real, eps_m: Real, lambda_cd_min: Real) -> Self {
        let members = &s.formation.members;
        let index = |id: u32| members.iter().position(|m| m.id == id);
        let edges = members
            .iter()
            .enumerate()
            .filter_map(|(k, m)| m.link.map(|l| (k, l)))
            .flat_map(|(k, l)| {
                l.in_neighbors
                    .into_iter()
                    .filter_map(index)
                    .map(move |j| [j, k])
            })
            .collect();
        Scene {
            scenario: s.origin.clone(),
            agents: members
                .iter()
                .map(|m| AgentInfo {
                    id: m.id,
                    role: m.role.as_str(),
                })
                .collect(),
            edges,
            polygon: s.formation.polygon.clone(),
            half_height_m: delta_m + eps_m,
            eps_m,
            delta_m,
            lambda_cd_min,
            dt_s: s.dt_s(),
            last_tick: s.last_tick(),
            verdict: "RUNNING".to_owned(),
            violations: Vec::new(),
            frames: Vec::new(),
            stride: 1,
            graphs: Vec::new(),
            phases: phase_marks(s),
            geofence: s.file.geofence.clone(),
            obstacles: s.file.obstacles.clone(),
            commands: Vec::new(),
        }
    }

    /// Adds the graph each loss left (audit.json's repairs, in loss order): the lost member
    /// reads nobody any more, a re-triangulated follower reads its new triangle (eq. 18) and a
    /// degraded one, flying its plan, nobody. Ids the scenario lacks are skipped.
    pub fn with_repairs(mut self, s: &Scenario, repairs: &[RepairRecord]) -> Self {
        let members = &s.formation.members;
        let index = |id: u32| members.iter().position(|m| m.id == id);
        let mut reads: Vec<Vec<usize>> = members
            .iter()
            .map(|m| {
                m.link
                    .map(|l| l.in_neighbors.into_iter().filter_map(index).collect())
                    .unwrap_or_default()
            })
            .collect();
        for r in repairs {
            let emptied = std::iter::once(r.id).chain(r.degraded.iter().copied());
            for k in emptied.filter_map(index) {
                reads[k].clear();
            }
            for (id, new) in &r.retriangulated {
                if let Some(k) = index(*id) {
                    reads[k] = new.iter().copied().filter_map(index).collect();
                }
            }
            let edges = reads
                .iter()
                .enumerate()
                .flat_map(|(k, js)| js.iter().map(move |&j| [j, k]))
                .collect();
            self.graphs.push(GraphChange {
                tick: r.tick,
                edges,
            });
        }
        self
    }
}

/// Computes frames for one scenario (keeps the follower list between ticks).
pub struct ShownTickMaker {
    followers: Vec<usize>,
    half_height_m: Real,
}

impl ShownTickMaker {
    pub fn new(scenario: &Scenario, half_height_m: Real) -> Self {
        let followers = (0..scenario.formation.members.len())
            .filter(|&k| scenario.formation.members[k].role == Role::Follower)
            .collect();
        ShownTickMaker {
            followers,
            half_height_m,
        }
    }

    /// The frame of one tick from actual (`pos`) and desired (`ht`) positions in member order;
    /// only living members (`alive`) count for deviation, separation and containment.
    pub fn frame(&self, s: &Scenario, tp: &TickPositions<'_>) -> ShownTick {
        let (tick, t, pos, ht, alive) = (tp.tick, tp.t_s, tp.pos, tp.ht, tp.alive);
        let dev = self
            .followers
            .iter()
            .filter(|&&k| alive[k])
            .map(|&k| (pos[k] - ht[k]).norm())
            .fold(0.0, Real::max);
        ShownTick {
            tick,
            t,
            p: pos
                .iter()
                .flat_map(|r| [r.x, r.y, r.z])
                .map(|v| (v * 1000.0).round() as i64)
                .collect(),
            sep: finite_or(living_separation(pos, alive).0, -1.0),
            dev,
            bnd: finite_or(
                boundary_distance(s, &self.followers, self.half_height_m, pos, ht, alive),
                -1.0,
            ),
            l1: lambdas_at(s, t)[0],
            lost: (0..alive.len()).filter(|&k| !alive[k]).collect(),
            rate: None,
        }
    }
}

/// JSON has no infinity: a team without a pair or a polygon shows `fallback`.
fn finite_or(v: Real, fallback: Real) -> Real {
    if v.is_finite() {
        v
    } else {
        fallback
    }
}

/// Frames kept so that replay.html stays within `budget_bytes` at `agents` members: each frame
/// costs about 7 bytes per coordinate; 3 MB are left for three.js and the page.
pub fn frame_stride(ticks: u64, agents: usize, budget_bytes: usize) -> u64 {
    let per_frame = agents * 3 * 7 + 120;
    let frames = (budget_bytes.saturating_sub(3 << 20) / per_frame).clamp(2, 3000) as u64;
    ticks.div_ceil(frames).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stride_keeps_a_thousand_agents_within_twenty_megabytes() {
        let budget = 20 << 20;
        let ticks = 10_001;
        let stride = frame_stride(ticks, 1000, budget);
        let frames = ticks.div_ceil(stride) + 1;
        assert!(frames as usize * (1000 * 3 * 7 + 120) + (3 << 20) <= budget);
        assert_eq!(frame_stride(100, 40, budget), 1);
    }

    #[test]
    fn paper40_scene_has_three_in_neighbours_per_follower() {
        let s = Scenario::builtin("paper40").expect("paper40");
        let scene = Scene::new(&s, 0.1, 0.2, 0.5);
        let followers = s
            .formation
            .members
            .iter()
            .filter(|m| m.role == Role::Follower)
            .count();
        assert_eq!(scene.edges.len(), 3 * followers);
        assert_eq!(scene.agents.len(), 40);
        assert!(scene.phases.is_empty());
    }

    /// A mission's phases reach the replay's timeline, in flight order.
    #[test]
    fn a_mission_scene_names_its_phases() {
        let s = Scenario::builtin("paper40-mission").expect("paper40-mission");
        let scene = Scene::new(&s, 0.1, 0.2, 0.5);
        let names: Vec<&str> = scene.phases.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["takeoff", "segment 1", "segment 2", "landing"]);
        assert_eq!(scene.phases[1].t_start_s, 205.0);
        assert_eq!(scene.phases[3].t_end_s, 715.0);
    }

    #[test]
    fn a_repair_replaces_the_switched_followers_edges_and_drops_the_lost_ones() {
        let s = Scenario::builtin("paper40").expect("paper40");
        let members = &s.formation.members;
        let idx = |id: u32| members.iter().position(|m| m.id == id).expect("member");
        // A follower that reads the lost member switches to another triangle; one degrades.
        let reader = members
            .iter()
            .find(|m| m.link.is_some_and(|l| l.in_neighbors.contains(&1)))
            .expect("a reader of 1");
        let lost = members
            .iter()
            .find(|m| m.role == Role::Follower && m.id != reader.id)
            .expect("another follower");
        let repair = RepairRecord {
            id: lost.id,
            tick: 77,
            retriangulated: vec![(reader.id, [2, 3, 4])],
            degraded: Vec::new(),
        };
        let scene = Scene::new(&s, 0.1, 0.2, 0.5).with_repairs(&s, &[repair]);
        let g = &scene.graphs[0];
        assert_eq!(g.tick, 77);
        assert!(g.edges.iter().all(|e| e[1] != idx(lost.id)));
        let reads: Vec<usize> = g
            .edges
            .iter()
            .filter(|e| e[1] == idx(reader.id))
            .map(|e| e[0])
            .collect();
        assert_eq!(reads, vec![idx(2), idx(3), idx(4)]);
        assert_eq!(g.edges.len(), scene.edges.len() - 3);
    }
}
