//! The target frame of an export: p -> S p + origin for every position and goal (a mission's
//! segment goals and ground heights too). A homogeneous deformation commutes with it (Q stays, d
//! becomes S d + (I - Q) origin), so Q and lambda(U_D) are unchanged while D_B, D_S and the linear
//! tracking error scale by S (eqs. 11, 34-38); the vehicles' radius does not shrink, so the
//! certificate is issued again on the scaled scenario.

use cdm_math::{Real, Vec3};
use cdm_model::airspace::Shape;
use cdm_scenario::ScenarioFile;

/// Scale and origin of the target frame (metres, z up, like the scenario's own frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetFrame {
    pub scale: Real,
    pub origin: Vec3,
}

/// The scales an export accepts: the paper's 300 m team from 3 cm (a tabletop) to 3,000 km.
/// Beyond them no vehicle flies the show, and the scaled positions lose the digits that the
/// float32 trajectories and the certificate need (1e300 printed a 300-digit scale, then blamed
/// collinear leaders).
pub const SCALE_RANGE: std::ops::RangeInclusive<Real> = 1e-4..=1e4;

/// A target frame that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    #[error("--scale must be a positive finite number, got {0}")]
    Scale(Real),
    #[error(
        "--scale {0:e} is out of range: it must lie in [{lo:e}, {hi:e}]",
        lo = SCALE_RANGE.start(),
        hi = SCALE_RANGE.end()
    )]
    ScaleRange(Real),
    #[error("--origin must be three finite numbers X,Y,Z in metres, got {0:?}")]
    Origin(String),
    #[error("--eps must be a positive finite radius in metres, got {0}")]
    Eps(Real),
}

impl TargetFrame {
    /// A checked frame.
    pub fn new(scale: Real, origin: Vec3) -> Result<Self, FrameError> {
        if !(scale.is_finite() && scale > 0.0) {
            return Err(FrameError::Scale(scale));
        }
        if !SCALE_RANGE.contains(&scale) {
            return Err(FrameError::ScaleRange(scale));
        }
        Ok(TargetFrame { scale, origin })
    }

    /// `X,Y,Z` in metres.
    pub fn parse_origin(text: &str) -> Result<Vec3, FrameError> {
        let v: Vec<Real> = text
            .split(',')
            .map(|p| p.trim().parse::<Real>())
            .collect::<Result<_, _>>()
            .map_err(|_| FrameError::Origin(text.to_string()))?;
        match v[..] {
            [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Vec3::new(x, y, z)),
            _ => Err(FrameError::Origin(text.to_string())),
        }
    }

    /// A point of the scenario's frame in the target frame.
    pub fn map(&self, p: [Real; 3]) -> [Real; 3] {
        let q = Vec3::from(p) * self.scale + self.origin;
        [q.x, q.y, q.z]
    }

    /// The scenario as flown, mapped into the target frame with the target vehicles' radius
    /// `eps_m`. Lengths the file fixes (delta_m, the plane tolerance) scale with it; the travel
    /// time, gains and graph stay.
    pub fn apply(&self, file: &ScenarioFile, eps_m: Real) -> Result<ScenarioFile, FrameError> {
        if !(eps_m.is_finite() && eps_m > 0.0) {
            return Err(FrameError::Eps(eps_m));
        }
        let mut f = file.clone();
        f.eps_m = eps_m;
        f.delta_m = f.delta_m.map(|d| d * self.scale);
        f.plane_tolerance_m = f.plane_tolerance_m.map(|d| d * self.scale);
        for a in &mut f.agents {
            a.position = self.map(a.position);
            a.goal = a.goal.map(|g| self.map(g));
        }
        // A mission's waypoints and ground heights are points of the same frame.
        for seg in &mut f.segments {
            for g in &mut seg.goals {
                *g = self.map(*g);
            }
        }
        for ground in [&mut f.takeoff, &mut f.landing].into_iter().flatten() {
            ground.ground_z_m = self.map_z(ground.ground_z_m);
        }
        // The airspace is of the same frame: the fence and the obstacles scale with
        // the plan, so the certificate at the target scale checks them again.
        if let Some(fence) = &mut f.geofence {
            for v in &mut fence.polygon {
                *v = self.map_xy(*v);
            }
            fence.min_z_m = self.map_z(fence.min_z_m);
            fence.max_z_m = self.map_z(fence.max_z_m);
        }
        for o in &mut f.obstacles {
            o.shape = self.map_shape(o.shape);
        }
        Ok(f)
    }

    fn map_z(&self, z: Real) -> Real {
        z * self.scale + self.origin.z
    }

    fn map_xy(&self, v: [Real; 2]) -> [Real; 2] {
        [
            v[0] * self.scale + self.origin.x,
            v[1] * self.scale + self.origin.y,
        ]
    }

    /// An obstacle in the target frame: the scale is positive, so a box's corners stay ordered.
    fn map_shape(&self, shape: Shape) -> Shape {
        match shape {
            Shape::Box { min, max } => Shape::Box {
                min: self.map(min),
                max: self.map(max),
            },
            Shape::Cylinder {
                center,
                radius_m,
                min_z_m,
                max_z_m,
            } => Shape::Cylinder {
                center: self.map_xy(center),
                radius_m: radius_m * self.scale,
                min_z_m: self.map_z(min_z_m),
                max_z_m: self.map_z(max_z_m),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_scenario::{paper40, Checks, Scenario};

    #[test]
    fn scaling_keeps_lambda_and_scales_distances() {
        let base = Scenario::from_file(paper40(), "paper40", Checks::Member).unwrap();
        let frame = TargetFrame::new(0.01, Vec3::new(1.0, -2.0, -8.0)).unwrap();
        let f = frame.apply(&base.file, 0.1).unwrap();
        let scaled = Scenario::from_file(f, "scaled", Checks::Member).unwrap();
        let (l0, l1) = (
            base.plan.lambda1_min().unwrap(),
            scaled.plan.lambda1_min().unwrap(),
        );
        assert!((l0.lambda1 - l1.lambda1).abs() < 1e-9);
        let d0 = cdm_model::safety::d_b(&base.formation);
        let d1 = cdm_model::safety::d_b(&scaled.formation);
        assert!((d1 - 0.01 * d0).abs() < 1e-9 * d0);
        assert_eq!(scaled.file.eps_m, 0.1);
    }

    /// A mission's segment goals and ground heights move with the team.
    #[test]
    fn a_mission_scales_with_its_ground() {
        let base = Scenario::builtin("paper40-mission").unwrap();
        let frame = TargetFrame::new(0.01, Vec3::new(1.0, -2.0, 0.5)).unwrap();
        let f = frame.apply(&base.file, 0.1).unwrap();
        let scaled = Scenario::from_file(f, "scaled", Checks::Member).unwrap();
        let (p0, p1) = (base.plan.phases(), scaled.plan.phases());
        assert_eq!(p0.len(), p1.len());
        for (a, b) in p0.iter().zip(p1) {
            assert_eq!(a.t_start_s, b.t_start_s);
            for k in 0..3 {
                let want = Vec3::from(frame.map(a.goal[k].into()));
                assert!((b.goal[k] - want).norm() < 1e-9, "{:?}", b.kind);
            }
        }
        assert_eq!(scaled.file.takeoff.as_ref().unwrap().ground_z_m, 0.5);
        assert_eq!(scaled.file.landing.as_ref().unwrap().ground_z_m, 0.5);
    }

    /// The fence and the obstacles move with the team: every margin scales by S, so a point
    /// inside (outside) stays inside (outside) by S times as much.
    #[test]
    fn the_airspace_scales_with_the_team() {
        use cdm_scenario::{GeofenceSpec, ObstacleSpec};
        let mut file = paper40();
        file.geofence = Some(GeofenceSpec {
            polygon: vec![
                [-50.0, -50.0],
                [300.0, -50.0],
                [300.0, 200.0],
                [-50.0, 200.0],
            ],
            min_z_m: 0.0,
            max_z_m: 600.0,
        });
        let tower = Shape::Box {
            min: [75.0, 20.0, 0.0],
            max: [85.0, 45.0, 100.0],
        };
        let mast = Shape::Cylinder {
            center: [250.0, 150.0],
            radius_m: 4.0,
            min_z_m: 0.0,
            max_z_m: 80.0,
        };
        for (name, shape) in [("tower", tower), ("mast", mast)] {
            file.obstacles.push(ObstacleSpec {
                name: name.into(),
                shape,
            });
        }
        let frame = TargetFrame::new(0.02, Vec3::new(1.0, -2.0, 0.5)).unwrap();
        let f = frame.apply(&file, 0.1).unwrap();
        let (fence0, fence1) = (
            file.geofence.as_ref().unwrap().fence(),
            f.geofence.as_ref().unwrap().fence(),
        );
        for p in [
            [0.0, 0.0, 10.0],
            [80.0, 30.0, 50.0],
            [251.0, 149.0, 79.0],
            [310.0, 0.0, 5.0],
        ] {
            let q = Vec3::from(frame.map(p));
            let p = Vec3::from(p);
            for (a, b) in fence0.margins_at(&p).iter().zip(fence1.margins_at(&q)) {
                assert_eq!(a.0, b.0);
                assert!((a.1 * 0.02 - b.1).abs() < 1e-9, "{a:?} {b:?}");
            }
            for (o0, o1) in file.obstacles.iter().zip(&f.obstacles) {
                let (d0, d1) = (o0.shape.signed_distance(&p), o1.shape.signed_distance(&q));
                assert!((d0 * 0.02 - d1).abs() < 1e-9, "{}: {d0} {d1}", o0.name);
            }
        }
    }

    #[test]
    fn bad_frames_are_named() {
        assert!(TargetFrame::new(0.0, Vec3::zeros()).is_err());
        assert!(TargetFrame::new(Real::NAN, Vec3::zeros()).is_err());
        assert!(TargetFrame::parse_origin("1,2").is_err());
        assert!(TargetFrame::parse_origin("1,x,3").is_err());
        assert!(TargetFrame::parse_origin("1,2,inf").is_err());
        assert_eq!(
            TargetFrame::parse_origin(" 1, -2.5,3").unwrap(),
            Vec3::new(1.0, -2.5, 3.0)
        );
    }
}
