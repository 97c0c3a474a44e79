//! One tick as Foxglove's well-known messages, pure: the member poses and frames, and the
//! formation's markers (cdm-rosbag's [`Team::markers`], the very content of the bag's
//! `/cdm/formation`) as a `foxglove.SceneUpdate`. The margins are the bag's `/cdm/audit` JSON
//! ([`Team::margins`]); nothing here computes them again.

use foxglove::schemas::{
    line_primitive, scene_entity_deletion, Color, CubePrimitive, CylinderPrimitive, FrameTransform,
    FrameTransforms, LinePrimitive, Point3, Pose, PoseInFrame, Quaternion, SceneEntity,
    SceneEntityDeletion, SceneUpdate, SpherePrimitive, Timestamp, Vector3,
};

use cdm_math::Vec3;
use cdm_rosbag::msgs::{self, Marker};
use cdm_rosbag::tick::{time_ns, WORLD};
use cdm_rosbag::{Team, Tick};

/// The messages of one tick.
pub struct SceneFrame {
    /// Simulation time of the tick, ns (every message's log time).
    pub time_ns: u64,
    /// (member index, pose) of each member still flying, in member order.
    pub poses: Vec<(usize, PoseInFrame)>,
    pub tf: FrameTransforms,
    pub formation: SceneUpdate,
}

/// `t` as a protocol timestamp.
pub fn stamp(time_ns: u64) -> Timestamp {
    let sec = u32::try_from(time_ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, (time_ns % 1_000_000_000) as u32)
}

fn vector(v: &Vec3) -> Vector3 {
    Vector3 {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

fn identity() -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    }
}

fn pose(at: &Vec3) -> Pose {
    Pose {
        position: Some(vector(at)),
        orientation: Some(identity()),
    }
}

/// Each living member's pose and frame, and the formation's scene, at `t`.
pub fn frame(team: &Team, t: &Tick<'_>) -> SceneFrame {
    let time_ns = time_ns(t.t_s);
    let timestamp = Some(stamp(time_ns));
    let living: Vec<usize> = (0..team.ids().len()).filter(|&k| t.alive[k]).collect();
    let poses = living
        .iter()
        .map(|&k| {
            let p = PoseInFrame {
                timestamp,
                frame_id: WORLD.to_owned(),
                pose: Some(pose(&t.pos[k])),
            };
            (k, p)
        })
        .collect();
    let tf = FrameTransforms {
        transforms: living
            .iter()
            .map(|&k| FrameTransform {
                timestamp,
                parent_frame_id: WORLD.to_owned(),
                child_frame_id: format!("agent_{}", team.ids()[k]),
                translation: Some(vector(&t.pos[k])),
                rotation: Some(identity()),
            })
            .collect(),
    };
    let polygon = team.polygon(t);
    let mut formation = SceneUpdate::default();
    for m in team.markers(t, &polygon) {
        let id = format!("{}/{}", m.ns, m.id);
        if m.action == msgs::DELETE {
            formation.deletions.push(SceneEntityDeletion {
                timestamp,
                r#type: scene_entity_deletion::Type::MatchingId as i32,
                id,
            });
        } else {
            formation.entities.push(entity(id, timestamp, &m));
        }
    }
    SceneFrame {
        time_ns,
        poses,
        tf,
        formation,
    }
}

/// One marker as a scene entity of the same shape, size and colour (the marker types the bag
/// uses: SPHERE, CUBE, CYLINDER, LINE_STRIP, LINE_LIST).
fn entity(id: String, timestamp: Option<Timestamp>, m: &Marker<'_>) -> SceneEntity {
    let [r, g, b, a] = m.color.0.map(f64::from);
    let color = Some(Color { r, g, b, a });
    let (at, size) = (Some(pose(&m.position)), Some(vector(&m.scale)));
    let mut e = SceneEntity {
        timestamp,
        frame_id: WORLD.to_owned(),
        id,
        ..SceneEntity::default()
    };
    let line = |kind: line_primitive::Type| LinePrimitive {
        r#type: kind as i32,
        pose: at,
        thickness: m.scale.x,
        scale_invariant: false,
        points: m
            .points
            .iter()
            .map(|p| Point3 {
                x: p.x,
                y: p.y,
                z: p.z,
            })
            .collect(),
        color,
        ..LinePrimitive::default()
    };
    match m.kind {
        msgs::SPHERE => e.spheres.push(SpherePrimitive {
            pose: at,
            size,
            color,
        }),
        msgs::CUBE => e.cubes.push(CubePrimitive {
            pose: at,
            size,
            color,
        }),
        msgs::CYLINDER => e.cylinders.push(CylinderPrimitive {
            pose: at,
            size,
            bottom_scale: 1.0,
            top_scale: 1.0,
            color,
        }),
        msgs::LINE_STRIP => e.lines.push(line(line_primitive::Type::LineStrip)),
        _ => e.lines.push(line(line_primitive::Type::LineList)),
    }
    e
}

#[cfg(test)]
mod tests {
    use cdm_records::audit::SafetyNumbers;
    use cdm_rosbag::Limits;
    use cdm_scenario::Scenario;

    use super::*;

    #[test]
    fn a_tick_is_each_living_pose_its_frame_and_the_bags_markers_as_entities() {
        let s = Scenario::generated(8).unwrap();
        let team = Team::new(&s, Limits::from(&SafetyNumbers::of(&s)));
        let n = team.ids().len();
        let pos: Vec<Vec3> = (0..n).map(|k| Vec3::new(k as f64, 0.5, 2.0)).collect();
        let mut alive = vec![true; n];
        alive[1] = false;
        let t = Tick {
            tick: 150,
            t_s: 1.5,
            pos: &pos,
            ht: &pos,
            alive: &alive,
        };
        let f = frame(&team, &t);
        assert_eq!(f.time_ns, 1_500_000_000);
        let members: Vec<usize> = f.poses.iter().map(|p| p.0).collect();
        assert_eq!(members, (0..n).filter(|&k| k != 1).collect::<Vec<_>>());
        let (k, p) = &f.poses[1];
        let at = p.pose.unwrap().position.unwrap();
        assert_eq!((at.x, at.y, at.z), (pos[*k].x, pos[*k].y, pos[*k].z));
        assert_eq!(p.timestamp, Some(Timestamp::new(1, 500_000_000)));
        assert_eq!(f.tf.transforms.len(), n - 1);
        assert_eq!(
            f.tf.transforms[0].child_frame_id,
            format!("agent_{}", team.ids()[0])
        );
        // Every marker of the bag is here: the lost member's sphere as a deletion.
        let polygon = team.polygon(&t);
        let markers = team.markers(&t, &polygon);
        assert_eq!(
            f.formation.entities.len() + f.formation.deletions.len(),
            markers.len()
        );
        assert_eq!(
            f.formation.deletions[0].id,
            format!("members/{}", team.ids()[1])
        );
        let spheres: usize = f.formation.entities.iter().map(|e| e.spheres.len()).sum();
        assert_eq!(spheres, n - 1);
        let lines: Vec<&LinePrimitive> =
            f.formation.entities.iter().flat_map(|e| &e.lines).collect();
        assert_eq!(lines[0].points.len(), polygon.len());
    }
}
