//! One tick of a run as the bag's messages, pure: the same positions give the same bytes,
//! whether they come from a finished run's telemetry (`export rosbag2`) or from the run itself
//! (`--telemetry mcap`).

use serde_json::json;

use cdm_math::{Real, Vec3};
use cdm_model::airspace::Shape;
use cdm_model::formation::Role;
use cdm_model::step::tick_time;
use cdm_records::audit::{CommandSummary, SafetyNumbers};
use cdm_records::margins::{boundary_distance, lambdas_at, living_separation, max_deviation};
use cdm_scenario::Scenario;

use crate::msgs::{self, Marker, MsgType, Rgba, Stamp};

/// The frame every position is in.
pub const WORLD: &str = "world";

/// A topic of the bag: a member's pose (member index), `/tf`, `/cdm/formation`, `/cdm/audit`,
/// and `/cdm/commands` in a commanded run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Topic {
    Pose(usize),
    Tf,
    Formation,
    Audit,
    Commands,
}

impl Topic {
    /// Its place in [`Team::topics`] of a team of `members`: poses in member order, then
    /// `/tf`, `/cdm/formation` and `/cdm/audit` (the bag's channels, the live publishers).
    pub fn index(self, members: usize) -> usize {
        match self {
            Topic::Pose(k) => k,
            Topic::Tf => members,
            Topic::Formation => members + 1,
            Topic::Audit => members + 2,
            Topic::Commands => members + 3,
        }
    }
}

/// The limits the margins are measured against (audit.json's numbers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub eps_m: Real,
    pub delta_m: Real,
    pub lambda_cd_min: Real,
}

impl From<&SafetyNumbers> for Limits {
    fn from(n: &SafetyNumbers) -> Self {
        Limits {
            eps_m: n.eps_m,
            delta_m: n.delta_m,
            lambda_cd_min: n.lambda_cd_min,
        }
    }
}

/// One complete tick, in the scenario's member order.
pub struct Tick<'a> {
    pub tick: u64,
    pub t_s: Real,
    /// Actual positions r_i.
    pub pos: &'a [Vec3],
    /// Desired positions r_i,HT.
    pub ht: &'a [Vec3],
    /// Members still flying; a lost member has no pose or frame from its loss on.
    pub alive: &'a [bool],
}

/// One message: its topic, time (simulation time, ns) and CDR bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    pub topic: Topic,
    pub time_ns: u64,
    pub data: Vec<u8>,
}

/// What the messages of a team need, fixed for a run.
pub struct Team {
    scenario: Scenario,
    ids: Vec<u32>,
    frames: Vec<String>,
    roles: Vec<Role>,
    followers: Vec<usize>,
    limits: Limits,
    airspace: Vec<Solid>,
    /// The run's commands (`commands.json`), in switch tick order; none for a run without.
    commands: Vec<CommandSummary>,
    /// `/cdm/commands` is a topic even before any command: a live team may be commanded in
    /// flight ([`Team::add_command`]).
    commandable: bool,
}

/// A static marker of the airspace: the geofence's edges or one obstacle.
struct Solid {
    ns: &'static str,
    id: i32,
    kind: i32,
    position: Vec3,
    scale: Vec3,
    color: Rgba,
    points: Vec<Vec3>,
}

const FENCE_COLOR: Rgba = Rgba([0.37, 0.83, 0.95, 1.0]);
const OBSTACLE_COLOR: Rgba = Rgba([0.78, 0.49, 1.0, 0.35]);

/// The scenario's fence as a LINE_LIST (each polygon edge at the floor and the ceiling, and a
/// post at each vertex) and its obstacles as CUBE and CYLINDER markers (RViz and Foxglove draw
/// both centred on `position`, `scale` being the full size, the cylinder's axis along z).
fn airspace(s: &Scenario, line_width: Real) -> Vec<Solid> {
    let mut out = Vec::new();
    if let Some(f) = &s.file.geofence {
        let m = f.polygon.len();
        let at = |k: usize, z: Real| Vec3::new(f.polygon[k % m][0], f.polygon[k % m][1], z);
        let points = (0..m)
            .flat_map(|k| {
                let (lo, hi) = (f.min_z_m, f.max_z_m);
                [
                    at(k, lo),
                    at(k + 1, lo),
                    at(k, hi),
                    at(k + 1, hi),
                    at(k, lo),
                    at(k, hi),
                ]
            })
            .collect();
        out.push(Solid {
            ns: "geofence",
            id: 0,
            kind: msgs::LINE_LIST,
            position: Vec3::zeros(),
            scale: Vec3::new(line_width, 0.0, 0.0),
            color: FENCE_COLOR,
            points,
        });
    }
    for (k, o) in s.file.obstacles.iter().enumerate() {
        let (kind, lo, hi) = match o.shape() {
            Shape::Box { min, max } => (msgs::CUBE, Vec3::from(min), Vec3::from(max)),
            Shape::Cylinder {
                center,
                radius_m,
                min_z_m,
                max_z_m,
            } => (
                msgs::CYLINDER,
                Vec3::new(center[0] - radius_m, center[1] - radius_m, min_z_m),
                Vec3::new(center[0] + radius_m, center[1] + radius_m, max_z_m),
            ),
        };
        out.push(Solid {
            ns: "obstacles",
            id: i32::try_from(k).unwrap_or(i32::MAX),
            kind,
            position: (lo + hi) / 2.0,
            scale: hi - lo,
            color: OBSTACLE_COLOR,
            points: Vec::new(),
        });
    }
    out
}

impl Team {
    pub fn new(scenario: &Scenario, limits: Limits) -> Self {
        let members = &scenario.formation.members;
        Team {
            scenario: scenario.clone(),
            ids: members.iter().map(|m| m.id).collect(),
            frames: members.iter().map(|m| format!("agent_{}", m.id)).collect(),
            roles: members.iter().map(|m| m.role).collect(),
            followers: (0..members.len())
                .filter(|&k| members[k].role == Role::Follower)
                .collect(),
            airspace: airspace(scenario, 0.5 * limits.eps_m),
            limits,
            commands: Vec::new(),
            commandable: false,
        }
    }

    /// The same team, with a `/cdm/commands` topic whether or not a command ever comes: the
    /// live topics of a team that takes commands in flight.
    pub fn commandable(mut self) -> Self {
        self.commandable = true;
        self
    }

    /// A command decided in flight: it goes out on `/cdm/commands` with the first shown tick
    /// at or after its switch, as a command known from the start does.
    pub fn add_command(&mut self, c: CommandSummary) {
        let at = self
            .commands
            .partition_point(|k| k.switch_tick <= c.switch_tick);
        self.commands.insert(at, c);
    }

    /// The same team with the run's commands: a `/cdm/commands` topic carries each, as the
    /// margins are carried on `/cdm/audit` (a run without commands has no such topic, and its
    /// bag the bytes it always had).
    pub fn with_commands(mut self, mut commands: Vec<CommandSummary>) -> Self {
        commands.sort_by_key(|c| c.switch_tick);
        self.commands = commands;
        self
    }

    /// The messages on `/cdm/commands` for the shown tick `t` when the tick shown before it was
    /// `shown_before` (none: `t` is the first): every command whose switch tick lies in between,
    /// as JSON, stamped with `t` (a bag that keeps every k-th tick still carries each command,
    /// once, in time order).
    pub fn command_messages(
        &self,
        shown_before: Option<u64>,
        t: &Tick<'_>,
        out: &mut Vec<Message>,
    ) {
        let time_ns = time_ns(t.t_s);
        let due = |c: &&CommandSummary| {
            c.switch_tick <= t.tick && shown_before.is_none_or(|b| c.switch_tick > b)
        };
        for c in self.commands.iter().filter(due) {
            let text = json!({
                "tick": c.switch_tick,
                "t_s": tick_time(c.switch_tick, self.scenario.dt_s()),
                "command": c.command,
                "accepted": c.accepted,
                "verdict": c.verdict.map(|v| v.as_str()),
                "why": c.why,
            });
            out.push(Message {
                topic: Topic::Commands,
                time_ns,
                data: msgs::string(&text.to_string()),
            });
        }
    }

    /// Member ids, in member order.
    pub fn ids(&self) -> &[u32] {
        &self.ids
    }

    /// Every topic with its name and type, in the bag's order.
    pub fn topics(&self) -> Vec<(Topic, String, MsgType)> {
        let poses = self.ids.iter().enumerate().map(|(k, id)| {
            (
                Topic::Pose(k),
                format!("/cdm/agent_{id}/pose"),
                MsgType::PoseStamped,
            )
        });
        poses
            .chain([
                (Topic::Tf, "/tf".to_owned(), MsgType::TfMessage),
                (
                    Topic::Formation,
                    "/cdm/formation".to_owned(),
                    MsgType::MarkerArray,
                ),
                (Topic::Audit, "/cdm/audit".to_owned(), MsgType::String),
            ])
            .chain(
                (self.commandable || !self.commands.is_empty())
                    .then(|| (Topic::Commands, "/cdm/commands".to_owned(), MsgType::String)),
            )
            .collect()
    }

    /// The messages of one tick: each living member's pose (id order), `/tf`, the formation's
    /// markers and the margins.
    pub fn messages(&self, t: &Tick<'_>, out: &mut Vec<Message>) {
        let time_ns = time_ns(t.t_s);
        let stamp = Stamp::from_ns(time_ns);
        let living = || (0..self.ids.len()).filter(|&k| t.alive[k]);
        for k in living() {
            out.push(Message {
                topic: Topic::Pose(k),
                time_ns,
                data: msgs::pose_stamped(stamp, WORLD, &t.pos[k]),
            });
        }
        let frames: Vec<(&str, Vec3)> = living()
            .map(|k| (self.frames[k].as_str(), t.pos[k]))
            .collect();
        out.push(Message {
            topic: Topic::Tf,
            time_ns,
            data: msgs::tf_message(stamp, WORLD, frames.into_iter()),
        });
        out.push(Message {
            topic: Topic::Formation,
            time_ns,
            data: self.formation(stamp, t),
        });
        out.push(Message {
            topic: Topic::Audit,
            time_ns,
            data: msgs::string(&self.margins(t).to_string()),
        });
    }

    /// The formation's markers of one tick, encoded.
    fn formation(&self, stamp: Stamp, t: &Tick<'_>) -> Vec<u8> {
        let polygon = self.polygon(t);
        msgs::marker_array(stamp, WORLD, &self.markers(t, &polygon))
    }

    /// The leading polygon through the leaders' positions, closed (the `points` of its marker).
    pub fn polygon(&self, t: &Tick<'_>) -> Vec<Vec3> {
        self.scenario
            .formation
            .polygon
            .iter()
            .chain(self.scenario.formation.polygon.first())
            .map(|&k| t.pos[k])
            .collect()
    }

    /// The formation as markers, whatever encodes them (the bag's MarkerArray, the live
    /// Foxglove scene): a sphere of the safety ball's size (2 eps) per member coloured by role
    /// (deleted once lost), the leading polygon (`polygon`, from [`Team::polygon`]) and the
    /// airspace.
    pub fn markers<'a>(&'a self, t: &Tick<'_>, polygon: &'a [Vec3]) -> Vec<Marker<'a>> {
        let d = 2.0 * self.limits.eps_m;
        let mut markers: Vec<Marker<'_>> = (0..self.ids.len())
            .map(|k| Marker {
                ns: "members",
                id: i32::try_from(self.ids[k]).unwrap_or(i32::MAX),
                kind: msgs::SPHERE,
                action: if t.alive[k] { msgs::ADD } else { msgs::DELETE },
                position: t.pos[k],
                scale: Vec3::new(d, d, d),
                color: role_color(self.roles[k]),
                points: &[],
            })
            .collect();
        markers.push(Marker {
            ns: "polygon",
            id: 0,
            kind: msgs::LINE_STRIP,
            action: msgs::ADD,
            position: Vec3::zeros(),
            scale: Vec3::new(d / 4.0, 0.0, 0.0),
            color: Rgba([1.0, 1.0, 1.0, 1.0]),
            points: polygon,
        });
        markers.extend(self.airspace.iter().map(|a| Marker {
            ns: a.ns,
            id: a.id,
            kind: a.kind,
            action: msgs::ADD,
            position: a.position,
            scale: a.scale,
            color: a.color,
            points: &a.points,
        }));
        markers
    }

    /// The tick's four margins, each with its value and its distance to the limit (positive:
    /// safe), as JSON: D_B against 2 eps, the largest follower deviation against delta, D_S
    /// against 0 and lambda_1(U_D) against lambda_CD,min. Infinite values (no follower) are null.
    pub fn margins(&self, t: &Tick<'_>) -> serde_json::Value {
        let l = &self.limits;
        let sep = living_separation(t.pos, t.alive).0;
        let dev = max_deviation(&self.followers, t.pos, t.ht, t.alive);
        let half = l.delta_m + l.eps_m;
        let bnd = boundary_distance(&self.scenario, &self.followers, half, t.pos, t.ht, t.alive);
        let l1 = lambdas_at(&self.scenario, t.t_s)[0];
        json!({
            "tick": t.tick,
            "t_s": t.t_s,
            "separation_m": sep,
            "separation_margin_m": sep - 2.0 * l.eps_m,
            "deviation_m": dev,
            "deviation_margin_m": l.delta_m - dev,
            "boundary_margin_m": bnd,
            "lambda1": l1,
            "lambda1_margin": l1 - l.lambda_cd_min,
        })
    }
}

/// Simulation time in nanoseconds (a time before 0 is 0).
pub fn time_ns(t_s: Real) -> u64 {
    (t_s * 1e9).round().max(0.0) as u64
}

fn role_color(role: Role) -> Rgba {
    match role {
        Role::Primary => Rgba([0.9, 0.2, 0.2, 1.0]),
        Role::Secondary => Rgba([1.0, 0.6, 0.1, 1.0]),
        Role::Follower => Rgba([0.2, 0.5, 1.0, 1.0]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn team() -> (Scenario, Team) {
        let s = Scenario::generated(10).expect("a team of 10");
        let t = Team::new(&s, Limits::from(&SafetyNumbers::of(&s)));
        (s, t)
    }

    #[test]
    fn a_tick_has_a_pose_per_living_member_then_tf_markers_and_margins() {
        let (s, team) = team();
        let n = s.formation.members.len();
        let pos: Vec<Vec3> = (0..n).map(|k| Vec3::new(k as Real, 0.0, 1.0)).collect();
        let mut alive = vec![true; n];
        alive[n - 1] = false;
        let tick = Tick {
            tick: 7,
            t_s: 0.07,
            pos: &pos,
            ht: &pos,
            alive: &alive,
        };
        let mut out = Vec::new();
        team.messages(&tick, &mut out);
        let topics: Vec<Topic> = out.iter().map(|m| m.topic).collect();
        let mut want: Vec<Topic> = (0..n - 1).map(Topic::Pose).collect();
        want.extend([Topic::Tf, Topic::Formation, Topic::Audit]);
        assert_eq!(topics, want);
        assert!(out.iter().all(|m| m.time_ns == 70_000_000));
        let margins = team.margins(&tick);
        assert_eq!(margins["tick"], 7);
        assert_eq!(margins["deviation_m"], 0.0);
        // The same tick gives the same bytes.
        let mut again = Vec::new();
        team.messages(&tick, &mut again);
        assert_eq!(out, again);
    }

    #[test]
    fn every_topic_is_named_once_and_typed() {
        let (s, team) = team();
        let topics = team.topics();
        assert_eq!(topics.len(), s.formation.members.len() + 3);
        let names: std::collections::BTreeSet<&str> = topics.iter().map(|t| t.1.as_str()).collect();
        assert_eq!(names.len(), topics.len());
        assert_eq!(topics[0].2, MsgType::PoseStamped);
        assert_eq!(topics[0].1, format!("/cdm/agent_{}/pose", team.ids()[0]));
        for (k, (topic, _, _)) in topics.iter().enumerate() {
            assert_eq!(topic.index(team.ids().len()), k, "{topic:?}");
        }
    }
}
