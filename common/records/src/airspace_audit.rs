//! The live audit of the airspace: every tick, each member's measured position
//! against the geofence and the obstacles, in every mode (`simulate`, `launch`, real time,
//! vehicles: the audit is one, `audit.rs`). A breach is the member's ball of radius eps
//! reaching beyond the fence or into an obstacle; it is a violation of its own kind
//! (`geofence`, `obstacle`) naming the side or the obstacle, recorded when it starts.
//!
//! During take-off and landing the floor is the ground the team stands on: the certificate
//! proves each desired path stays at or above it, and each member within delta of its path
//! (eq. 34), so there the audit requires the centre no lower than delta below the floor. The
//! vehicle model has no ground contact: a follower settling onto the ground after a landing
//! dips below it (0.1 m on paper40-mission with a fence whose floor is its ground).

use cdm_math::{Real, Vec3};
use cdm_model::airspace::{Boundary, Fence, Shape};
use cdm_model::outcome::ViolationKind;
use cdm_scenario::Scenario;

/// One breach that starts at this tick.
#[derive(Debug, Clone, PartialEq)]
pub struct Breach {
    pub kind: ViolationKind,
    /// The member (formation order).
    pub member: usize,
    /// The fence's side (`floor`, `ceiling`, `edge K`) or the obstacle's name.
    pub name: String,
    /// The ball's margin: negative, how far it reaches across.
    pub margin_m: Real,
}

/// Per member, which boundaries it breaches now: floor, ceiling, the polygon's sides, then
/// each obstacle.
const FENCE_SLOTS: usize = 3;

/// The live airspace audit of one run.
#[derive(Debug, Clone)]
pub struct AirspaceAudit {
    fence: Option<Fence>,
    obstacles: Vec<(String, Shape)>,
    eps_m: Real,
    /// delta (eq. 38): how far below the floor a centre may dip during take-off and landing.
    ground_slack_m: Real,
    failing: Vec<bool>,
    /// Smallest ball margins so far (infinite until measured).
    pub min_fence_margin_m: Real,
    pub min_obstacle_margin_m: Real,
}

impl AirspaceAudit {
    /// `None` without a fence or obstacles: the audit does nothing more than before.
    pub fn new(s: &Scenario, delta_m: Real) -> Option<Self> {
        if !cdm_scenario::has_airspace(&s.file) {
            return None;
        }
        let obstacles: Vec<(String, Shape)> = (s.file.obstacles.iter())
            .map(|o| (o.name.clone(), o.shape))
            .collect();
        Some(AirspaceAudit {
            fence: s.file.geofence.as_ref().map(|g| g.fence()),
            failing: vec![false; s.formation.members.len() * (FENCE_SLOTS + obstacles.len())],
            obstacles,
            eps_m: s.file.eps_m,
            ground_slack_m: delta_m.max(0.0),
            min_fence_margin_m: Real::INFINITY,
            min_obstacle_margin_m: Real::INFINITY,
        })
    }

    /// Whether the scenario has a fence.
    pub fn has_fence(&self) -> bool {
        self.fence.is_some()
    }

    /// Whether it has obstacles.
    pub fn has_obstacles(&self) -> bool {
        !self.obstacles.is_empty()
    }

    fn width(&self) -> usize {
        FENCE_SLOTS + self.obstacles.len()
    }

    /// A member is lost: it breaches nothing from now on.
    pub fn lose(&mut self, member: usize) {
        let w = self.width();
        self.failing[member * w..(member + 1) * w].fill(false);
    }

    /// One tick: `pos` in formation order, `alive` the members still audited, `ground` true in
    /// take-off and landing. `breach` gets every breach that starts now, member by member.
    pub fn observe(
        &mut self,
        pos: &[Vec3],
        alive: &[bool],
        ground: bool,
        mut breach: impl FnMut(Breach),
    ) {
        let w = self.width();
        for (k, p) in pos.iter().enumerate() {
            if !alive[k] {
                continue;
            }
            if let Some(f) = &self.fence {
                for (slot, (b, d)) in f.margins_at(p).into_iter().enumerate() {
                    let r = if b == Boundary::Floor && ground {
                        -self.ground_slack_m
                    } else {
                        self.eps_m
                    };
                    let m = d - r;
                    self.min_fence_margin_m = self.min_fence_margin_m.min(m);
                    let name = || match b {
                        Boundary::Floor => "floor".to_string(),
                        Boundary::Ceiling => "ceiling".to_string(),
                        Boundary::Edge(e) => format!("edge {}", e + 1),
                        Boundary::Obstacle(_) => String::new(),
                    };
                    note(
                        &mut self.failing[k * w + slot],
                        m,
                        || Breach {
                            kind: ViolationKind::Geofence,
                            member: k,
                            name: name(),
                            margin_m: m,
                        },
                        &mut breach,
                    );
                }
            }
            for (o, (name, shape)) in self.obstacles.iter().enumerate() {
                let m = shape.signed_distance(p) - self.eps_m;
                self.min_obstacle_margin_m = self.min_obstacle_margin_m.min(m);
                note(
                    &mut self.failing[k * w + FENCE_SLOTS + o],
                    m,
                    || Breach {
                        kind: ViolationKind::Obstacle,
                        member: k,
                        name: name.clone(),
                        margin_m: m,
                    },
                    &mut breach,
                );
            }
        }
    }
}

/// A breach is reported on the tick it starts (a NaN position breaches too).
fn note(
    failing: &mut bool,
    margin_m: Real,
    make: impl FnOnce() -> Breach,
    breach: &mut impl FnMut(Breach),
) {
    let bad = margin_m.is_nan() || margin_m < 0.0;
    if bad && !*failing {
        breach(make());
    }
    *failing = bad;
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_scenario::{paper40, Checks, GeofenceSpec, ObstacleSpec};

    #[test]
    fn a_breach_is_reported_once_when_it_starts_and_again_after_it_ended() {
        let mut f = paper40();
        f.geofence = Some(GeofenceSpec {
            polygon: vec![
                [-300.0, -200.0],
                [500.0, -200.0],
                [500.0, 600.0],
                [-300.0, 600.0],
            ],
            min_z_m: 0.0,
            max_z_m: 1300.0,
        });
        f.obstacles = vec![ObstacleSpec {
            name: "tower".into(),
            shape: Shape::Box {
                min: [0.0, 300.0, 0.0],
                max: [10.0, 310.0, 100.0],
            },
        }];
        let s = Scenario::from_file(f, "t", Checks::Member).unwrap();
        let mut a = AirspaceAudit::new(&s, 1.0).unwrap();
        let n = s.formation.members.len();
        let alive = vec![true; n];
        let mut pos: Vec<Vec3> = s.formation.members.iter().map(|m| m.position).collect();
        let mut seen = Vec::new();
        let tick = |a: &mut AirspaceAudit, pos: &[Vec3], seen: &mut Vec<Breach>| {
            a.observe(pos, &alive, false, |b| seen.push(b));
        };
        tick(&mut a, &pos, &mut seen);
        assert!(seen.is_empty(), "{seen:?}");
        // Member 2 into the tower (1 m from its face: the ball of eps = 1.5 m reaches 2.5 m in).
        pos[1] = Vec3::new(5.0, 301.0, 50.0);
        tick(&mut a, &pos, &mut seen);
        tick(&mut a, &pos, &mut seen);
        assert_eq!(seen.len(), 1, "{seen:?}");
        assert_eq!(
            (seen[0].kind, seen[0].member, seen[0].name.as_str()),
            (ViolationKind::Obstacle, 1, "tower")
        );
        assert!((seen[0].margin_m + 2.5).abs() < 1e-12);
        // Out through the ceiling, then back: the ceiling once, the tower not again.
        pos[1] = Vec3::new(5.0, 301.0, 1299.0);
        tick(&mut a, &pos, &mut seen);
        assert_eq!(seen.len(), 2, "{seen:?}");
        assert_eq!(
            (seen[1].kind, seen[1].name.as_str()),
            (ViolationKind::Geofence, "ceiling")
        );
        assert!((a.min_obstacle_margin_m + 2.5).abs() < 1e-12);
        pos[1] = Vec3::new(5.0, 301.0, 50.0);
        tick(&mut a, &pos, &mut seen);
        assert_eq!(seen.len(), 3);
        assert_eq!(seen[2].name, "tower");
        // Landing: 0.5 m below a floor at the ground is within delta = 1 m; in flight it is not.
        pos[1] = Vec3::new(5.0, 250.0, -0.5);
        a.observe(&pos, &alive, true, |b| seen.push(b));
        assert_eq!(seen.len(), 3, "{seen:?}");
        a.observe(&pos, &alive, false, |b| seen.push(b));
        assert_eq!(
            (seen[3].kind, seen[3].name.as_str()),
            (ViolationKind::Geofence, "floor")
        );
        assert!((seen[3].margin_m + 2.0).abs() < 1e-12);
    }
}
