//! The 12-state quadcopter model of Appendix A (eq. 42, with the drift of ERRATA 1) and the
//! linear 4th-order chain `r'''' = U` it is feedback-linearised into (eq. 43a). Both are plants
//! driven by a snap law `U = law(t, flat)` and integrated with classical RK4.
//!
//! Everything here is pure and allocation-free; the trigonometry of the attitude is evaluated
//! once per model evaluation (the private `Kinematics`).

use crate::guard::{ControlFault, SingularityGuard};
use cdm_math::{Mat3, Real, Vec3, GRAVITY_MPS2};

/// Names of the 12 components of [`QuadState`], in order (eq. 42, ERRATA 1).
pub const QUAD_STATE_NAMES: [&str; 12] = [
    "x", "y", "z", "vx", "vy", "vz", "F", "phi", "theta", "Fdot", "phidot", "thetadot",
];

/// Names of the 12 components of [`Flat`], in order (r, v, a, j).
pub const FLAT_NAMES: [&str; 12] = [
    "r.x", "r.y", "r.z", "v.x", "v.y", "v.z", "a.x", "a.y", "a.z", "j.x", "j.y", "j.z",
];

/// X = [x y z vx vy vz F phi theta Fdot phidot thetadot] (Appendix A, eq. 42, ERRATA 1); F is
/// thrust per mass (m/s^2), phi roll and theta pitch (rad), yaw held at zero (eqs. 40-41).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuadState(pub [Real; 12]);

/// Position and its first three time derivatives (the flat outputs of the 4th-order chain).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Flat {
    /// Position (m).
    pub r: Vec3,
    /// Velocity (m/s).
    pub v: Vec3,
    /// Acceleration (m/s^2).
    pub a: Vec3,
    /// Jerk (m/s^3).
    pub j: Vec3,
}

impl Flat {
    /// At rest at `p`: zero velocity, acceleration and jerk.
    pub fn rest(p: Vec3) -> Self {
        let z = Vec3::zeros();
        Flat {
            r: p,
            v: z,
            a: z,
            j: z,
        }
    }

    /// The 12 components in the order of [`FLAT_NAMES`].
    pub fn to_array(&self) -> [Real; 12] {
        let (r, v, a, j) = (&self.r, &self.v, &self.a, &self.j);
        [r.x, r.y, r.z, v.x, v.y, v.z, a.x, a.y, a.z, j.x, j.y, j.z]
    }

    /// Index of the first non-finite component ([`FLAT_NAMES`] order), if any.
    pub fn first_non_finite(&self) -> Option<usize> {
        self.to_array().iter().position(|c| !c.is_finite())
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.first_non_finite().is_none()
    }
}

/// Trigonometry of one state, evaluated once and shared by the acceleration, jerk, `M`, `N` and
/// the inverse of `M` (so one model evaluation costs one sin/cos pair per angle).
///
/// With q = (F, phi, theta) and a(q) = [0;0;-g] + F u(phi, theta) (eq. 42, ERRATA 1), the
/// columns of M = da/dq are `u`, `F e_phi` and `F d_theta` where `u`, `e_phi` are unit vectors and
/// `d_theta` has norm |cos phi|; the three are mutually orthogonal, so M^{-1} is closed-form.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Kinematics {
    /// Thrust per mass F (m/s^2).
    pub thrust: Real,
    /// Roll phi (rad), kept for the guard.
    pub roll: Real,
    /// qdot = (Fdot, phidot, thetadot).
    pub rates: Vec3,
    pub sin_phi: Real,
    pub cos_phi: Real,
    pub sin_theta: Real,
    pub cos_theta: Real,
}

impl Kinematics {
    /// Evaluates the trigonometry of `x` once.
    #[inline]
    pub fn of(x: &QuadState) -> Self {
        let s = &x.0;
        let (sin_phi, cos_phi) = s[7].sin_cos();
        let (sin_theta, cos_theta) = s[8].sin_cos();
        Kinematics {
            thrust: s[6],
            roll: s[7],
            rates: Vec3::new(s[9], s[10], s[11]),
            sin_phi,
            cos_phi,
            sin_theta,
            cos_theta,
        }
    }

    /// u = da/dF = [cos(phi) sin(theta); -sin(phi); cos(phi) cos(theta)], the thrust direction.
    #[inline]
    pub fn thrust_dir(&self) -> Vec3 {
        Vec3::new(
            self.cos_phi * self.sin_theta,
            -self.sin_phi,
            self.cos_phi * self.cos_theta,
        )
    }

    /// e_phi = du/dphi = [-sin(phi) sin(theta); -cos(phi); -sin(phi) cos(theta)] (unit).
    #[inline]
    pub fn roll_dir(&self) -> Vec3 {
        Vec3::new(
            -self.sin_phi * self.sin_theta,
            -self.cos_phi,
            -self.sin_phi * self.cos_theta,
        )
    }

    /// d_theta = du/dtheta = [cos(phi) cos(theta); 0; -cos(phi) sin(theta)] (norm |cos phi|).
    #[inline]
    pub fn pitch_dir(&self) -> Vec3 {
        Vec3::new(
            self.cos_phi * self.cos_theta,
            0.0,
            -self.cos_phi * self.sin_theta,
        )
    }

    /// a = [0;0;-g] + F u (eq. 42: f4..f6, ERRATA 1).
    #[inline]
    pub fn acceleration(&self) -> Vec3 {
        let f = self.thrust;
        Vec3::new(
            f * (self.cos_phi * self.sin_theta),
            f * (-self.sin_phi),
            f * (self.cos_phi * self.cos_theta) - GRAVITY_MPS2,
        )
    }

    /// M = da/dq, q = (F, phi, theta) (eq. 43b, ERRATA 3).
    #[inline]
    pub fn decoupling_matrix(&self) -> Mat3 {
        let f = self.thrust;
        Mat3::from_columns(&[self.thrust_dir(), self.roll_dir() * f, self.pitch_dir() * f])
    }

    /// Jerk = M qdot (the time derivative of eq. 42's f4..f6 along the flow).
    #[inline]
    pub fn jerk(&self) -> Vec3 {
        let f = self.thrust;
        let q = &self.rates;
        self.thrust_dir() * q.x + self.roll_dir() * (f * q.y) + self.pitch_dir() * (f * q.z)
    }

    /// N = qdot^T (d^2 a / dq^2) qdot (eq. 43b with the sign of ERRATA 2: minus the printed
    /// N_{T phi theta}). Since d^2a/dF^2 = 0 and a is linear in F,
    /// N = 2 Fdot (phidot a_Fphi + thetadot a_Ftheta) + phidot^2 a_phiphi +
    /// thetadot^2 a_thetatheta + 2 phidot thetadot a_phitheta, where every pure-angle second
    /// derivative carries one factor F.
    #[inline]
    pub fn drift_term(&self) -> Vec3 {
        let (sp, cp, st, ct) = (self.sin_phi, self.cos_phi, self.sin_theta, self.cos_theta);
        let f = self.thrust;
        let (fd, pd, td) = (self.rates.x, self.rates.y, self.rates.z);
        // Mixed F-angle second derivatives: a_Fphi = e_phi, a_Ftheta = d_theta.
        let mixed = self.roll_dir() * pd + self.pitch_dir() * td;
        // Pure angle second derivatives divided by F.
        let a_pp = Vec3::new(-cp * st, sp, -cp * ct);
        let a_tt = Vec3::new(-cp * st, 0.0, -cp * ct);
        let a_pt = Vec3::new(-sp * ct, 0.0, sp * st);
        let angular = a_pp * (pd * pd) + a_tt * (td * td) + a_pt * (2.0 * pd * td);
        mixed * (2.0 * fd) + angular * f
    }

    /// V = M^{-1} (U - N) (eq. 46) in closed form: M's columns are orthogonal with squared norms
    /// 1, F^2 and F^2 cos^2(phi), so M^{-1} = diag(1, 1/F, 1/(F cos^2 phi)) [u e_phi d_theta]^T.
    /// The guard (which bounds `|det M| = F^2 |cos phi|` away from 0, ERRATA 3) is checked first;
    /// the snap and the result are checked for finiteness (callers check the state).
    #[inline]
    pub fn input_for_snap(
        &self,
        snap: &Vec3,
        guard: &SingularityGuard,
    ) -> Result<Vec3, ControlFault> {
        if !(snap.x.is_finite() && snap.y.is_finite() && snap.z.is_finite()) {
            return Err(ControlFault::NonFiniteSnap {
                snap: [snap.x, snap.y, snap.z],
            });
        }
        // Written so that a NaN (in the state or in the guard) refuses rather than passes.
        let thrust_ok = self.thrust >= guard.min_thrust_mps2;
        if !thrust_ok {
            return Err(ControlFault::SingularThrust {
                thrust_mps2: self.thrust,
                min_thrust_mps2: guard.min_thrust_mps2,
            });
        }
        let roll_ok = self.roll.abs() <= guard.max_abs_roll_rad;
        if !roll_ok {
            return Err(ControlFault::SingularRoll {
                roll_rad: self.roll,
                max_abs_roll_rad: guard.max_abs_roll_rad,
            });
        }
        let w = snap - self.drift_term();
        let f = self.thrust;
        let v = Vec3::new(
            self.thrust_dir().dot(&w),
            self.roll_dir().dot(&w) / f,
            self.pitch_dir().dot(&w) / (f * (self.cos_phi * self.cos_phi)),
        );
        if v.x.is_finite() && v.y.is_finite() && v.z.is_finite() {
            Ok(v)
        } else {
            Err(ControlFault::NonFiniteInput {
                input: [v.x, v.y, v.z],
            })
        }
    }
}

impl QuadState {
    /// At rest at `p`: F = g, angles and rates 0 (an equilibrium of eq. 42 with V = 0).
    pub fn hover(p: Vec3) -> Self {
        QuadState([
            p.x,
            p.y,
            p.z,
            0.0,
            0.0,
            0.0,
            GRAVITY_MPS2,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
        ])
    }

    /// Position r = [x y z] (m), the output h(X) of eq. 42.
    pub fn position(&self) -> Vec3 {
        Vec3::new(self.0[0], self.0[1], self.0[2])
    }

    /// Velocity (m/s).
    pub fn velocity(&self) -> Vec3 {
        Vec3::new(self.0[3], self.0[4], self.0[5])
    }

    /// Thrust per mass F (m/s^2).
    pub fn thrust_mps2(&self) -> Real {
        self.0[6]
    }

    /// Roll phi (rad).
    pub fn roll_rad(&self) -> Real {
        self.0[7]
    }

    /// Pitch theta (rad).
    pub fn pitch_rad(&self) -> Real {
        self.0[8]
    }

    /// a = [0;0;-g] + F [cos(phi) sin(theta); -sin(phi); cos(phi) cos(theta)] (eq. 42, ERRATA 1).
    pub fn acceleration(&self) -> Vec3 {
        Kinematics::of(self).acceleration()
    }

    /// Jerk = M(F, phi, theta) qdot, qdot = (Fdot, phidot, thetadot).
    pub fn jerk(&self) -> Vec3 {
        Kinematics::of(self).jerk()
    }

    /// Position and its first three derivatives (one trigonometric evaluation).
    pub fn flat(&self) -> Flat {
        let k = Kinematics::of(self);
        Flat {
            r: self.position(),
            v: self.velocity(),
            a: k.acceleration(),
            j: k.jerk(),
        }
    }

    /// Index of the first non-finite component ([`QUAD_STATE_NAMES`] order), if any.
    pub fn first_non_finite(&self) -> Option<usize> {
        self.0.iter().position(|c| !c.is_finite())
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.first_non_finite().is_none()
    }

    /// Xdot = f(X) + g V with f = [v; a; Fdot; phidot; thetadot; 0; 0; 0], g = [0_{3x9}; I_3] and
    /// V = [Fddot, phiddot, thetaddot] (eq. 42, ERRATA 1).
    pub fn derivative(&self, input: &Vec3) -> [Real; 12] {
        self.derivative_with(&Kinematics::of(self), input)
    }

    /// [`Self::derivative`] with the trigonometry already evaluated.
    #[inline]
    fn derivative_with(&self, k: &Kinematics, input: &Vec3) -> [Real; 12] {
        let s = &self.0;
        let a = k.acceleration();
        [
            s[3], s[4], s[5], a.x, a.y, a.z, s[9], s[10], s[11], input.x, input.y, input.z,
        ]
    }

    /// `self + h * d`, component by component.
    #[inline]
    fn offset(&self, d: &[Real; 12], h: Real) -> Self {
        let mut out = self.0;
        for (o, di) in out.iter_mut().zip(d) {
            *o += h * di;
        }
        QuadState(out)
    }

    /// The closed-loop derivative at one RK4 stage: flat outputs, snap law, V from eq. 46.
    #[inline]
    fn closed_loop_derivative<F: FnMut(Real, &Flat) -> Vec3>(
        &self,
        t: Real,
        guard: &SingularityGuard,
        law: &mut F,
    ) -> Result<[Real; 12], ControlFault> {
        if let Some(index) = self.first_non_finite() {
            return Err(ControlFault::NonFiniteState {
                index,
                name: QUAD_STATE_NAMES[index],
            });
        }
        let k = Kinematics::of(self);
        let flat = Flat {
            r: self.position(),
            v: self.velocity(),
            a: k.acceleration(),
            j: k.jerk(),
        };
        let snap = law(t, &flat); // eq. 43a / 44
        let input = k.input_for_snap(&snap, guard)?; // eq. 46
        Ok(self.derivative_with(&k, &input))
    }

    /// One classical RK4 step like [`Plant::rk4_step`], with an explicit singularity guard.
    pub fn rk4_step_guarded<F: FnMut(Real, &Flat) -> Vec3>(
        &self,
        t: Real,
        h: Real,
        guard: &SingularityGuard,
        mut law: F,
    ) -> Result<Self, ControlFault> {
        let half = 0.5 * h;
        let k1 = self.closed_loop_derivative(t, guard, &mut law)?;
        let k2 = self
            .offset(&k1, half)
            .closed_loop_derivative(t + half, guard, &mut law)?;
        let k3 = self
            .offset(&k2, half)
            .closed_loop_derivative(t + half, guard, &mut law)?;
        let k4 = self
            .offset(&k3, h)
            .closed_loop_derivative(t + h, guard, &mut law)?;
        let sixth = h / 6.0;
        let mut out = self.0;
        for i in 0..12 {
            out[i] += sixth * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        let next = QuadState(out);
        match next.first_non_finite() {
            None => Ok(next),
            Some(index) => Err(ControlFault::NonFiniteState {
                index,
                name: QUAD_STATE_NAMES[index],
            }),
        }
    }
}

/// The plant models the team can fly: the nonlinear quadcopter and, as a reference, the linear
/// 4th-order chain r'''' = U of eq. 43a. Both are driven by a "snap law" U = law(t, flat).
pub trait Plant: Copy {
    /// Position and its first three derivatives.
    fn flat(&self) -> Flat;
    /// One classical RK4 step of length h from time t. `law(t_stage, &flat_at_stage)` returns
    /// the commanded snap U (eq. 43a/44); for the quadcopter the input is V = M^{-1}(U - N)
    /// (eq. 46) at every stage.
    fn rk4_step<F: FnMut(Real, &Flat) -> Vec3>(
        &self,
        t: Real,
        h: Real,
        law: F,
    ) -> Result<Self, ControlFault>;
    /// True when every state component is finite.
    fn is_finite(&self) -> bool;
}

impl Plant for QuadState {
    fn flat(&self) -> Flat {
        QuadState::flat(self)
    }

    /// Uses [`SingularityGuard::default`]; see [`QuadState::rk4_step_guarded`].
    fn rk4_step<F: FnMut(Real, &Flat) -> Vec3>(
        &self,
        t: Real,
        h: Real,
        law: F,
    ) -> Result<Self, ControlFault> {
        self.rk4_step_guarded(t, h, &SingularityGuard::default(), law)
    }

    fn is_finite(&self) -> bool {
        QuadState::is_finite(self)
    }
}

/// The linear reference plant r'''' = U (eq. 43a), state = the flat outputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Chain(pub Flat);

impl Chain {
    /// At rest at `p`.
    pub fn rest(p: Vec3) -> Self {
        Chain(Flat::rest(p))
    }

    /// The closed-loop derivative at one RK4 stage: (v, a, j, U).
    #[inline]
    fn closed_loop_derivative<F: FnMut(Real, &Flat) -> Vec3>(
        x: &Flat,
        t: Real,
        law: &mut F,
    ) -> Result<Flat, ControlFault> {
        if let Some(index) = x.first_non_finite() {
            return Err(ControlFault::NonFiniteState {
                index,
                name: FLAT_NAMES[index],
            });
        }
        let snap = law(t, x); // eq. 43a / 44
        if !(snap.x.is_finite() && snap.y.is_finite() && snap.z.is_finite()) {
            return Err(ControlFault::NonFiniteSnap {
                snap: [snap.x, snap.y, snap.z],
            });
        }
        Ok(Flat {
            r: x.v,
            v: x.a,
            a: x.j,
            j: snap,
        })
    }
}

/// `x + h * d`, component by component.
#[inline]
fn flat_offset(x: &Flat, d: &Flat, h: Real) -> Flat {
    Flat {
        r: x.r + d.r * h,
        v: x.v + d.v * h,
        a: x.a + d.a * h,
        j: x.j + d.j * h,
    }
}

impl Plant for Chain {
    fn flat(&self) -> Flat {
        self.0
    }

    fn rk4_step<F: FnMut(Real, &Flat) -> Vec3>(
        &self,
        t: Real,
        h: Real,
        mut law: F,
    ) -> Result<Self, ControlFault> {
        let x = &self.0;
        let half = 0.5 * h;
        let k1 = Chain::closed_loop_derivative(x, t, &mut law)?;
        let k2 = Chain::closed_loop_derivative(&flat_offset(x, &k1, half), t + half, &mut law)?;
        let k3 = Chain::closed_loop_derivative(&flat_offset(x, &k2, half), t + half, &mut law)?;
        let k4 = Chain::closed_loop_derivative(&flat_offset(x, &k3, h), t + h, &mut law)?;
        let sixth = h / 6.0;
        let comb = |x: Vec3, a: Vec3, b: Vec3, c: Vec3, d: Vec3| -> Vec3 {
            x + (a + b * 2.0 + c * 2.0 + d) * sixth
        };
        let next = Flat {
            r: comb(x.r, k1.r, k2.r, k3.r, k4.r),
            v: comb(x.v, k1.v, k2.v, k3.v, k4.v),
            a: comb(x.a, k1.a, k2.a, k3.a, k4.a),
            j: comb(x.j, k1.j, k2.j, k3.j, k4.j),
        };
        match next.first_non_finite() {
            None => Ok(Chain(next)),
            Some(index) => Err(ControlFault::NonFiniteState {
                index,
                name: FLAT_NAMES[index],
            }),
        }
    }

    fn is_finite(&self) -> bool {
        self.0.is_finite()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Deterministic pseudo-random numbers in [lo, hi) (splitmix64), so tests need no rand crate.
    pub(crate) struct SplitMix(pub u64);

    impl SplitMix {
        pub(crate) fn uniform(&mut self, lo: Real, hi: Real) -> Real {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            lo + (hi - lo) * ((z >> 11) as Real / (1u64 << 53) as Real)
        }
    }

    /// Non-trivial states (large angles, nonzero rates) plus an input V for each.
    pub(crate) fn sample_states(seed: u64, n: usize) -> Vec<(QuadState, Vec3)> {
        let mut g = SplitMix(seed);
        (0..n)
            .map(|_| {
                let x = QuadState([
                    g.uniform(-100.0, 100.0),
                    g.uniform(-100.0, 100.0),
                    g.uniform(0.0, 500.0),
                    g.uniform(-10.0, 10.0),
                    g.uniform(-10.0, 10.0),
                    g.uniform(-10.0, 10.0),
                    g.uniform(3.0, 20.0),
                    g.uniform(-1.2, 1.2),
                    g.uniform(-1.2, 1.2),
                    g.uniform(-5.0, 5.0),
                    g.uniform(-2.0, 2.0),
                    g.uniform(-2.0, 2.0),
                ]);
                let v = Vec3::new(
                    g.uniform(-10.0, 10.0),
                    g.uniform(-3.0, 3.0),
                    g.uniform(-3.0, 3.0),
                );
                (x, v)
            })
            .collect()
    }

    /// Relative error of `approx` against `exact`, scaled by max(|exact|, 1).
    pub(crate) fn rel_err(approx: &Vec3, exact: &Vec3) -> Real {
        (approx - exact).norm() / exact.norm().max(1.0)
    }

    #[test]
    fn hover_is_an_exact_equilibrium() {
        let x = QuadState::hover(Vec3::new(360.0, 0.0, 900.0));
        let d = x.derivative(&Vec3::zeros());
        assert_eq!(d, [0.0; 12]);
        let f = x.flat();
        assert_eq!(f, Flat::rest(Vec3::new(360.0, 0.0, 900.0)));
        assert_eq!(
            Kinematics::of(&x).input_for_snap(&Vec3::zeros(), &SingularityGuard::DEFAULT),
            Ok(Vec3::zeros())
        );
    }

    #[test]
    fn derivative_layout_follows_errata_1() {
        let (x, v) = sample_states(7, 1)[0];
        let d = x.derivative(&v);
        let a = x.acceleration();
        let s = &x.0;
        let expected = [
            s[3], s[4], s[5], a.x, a.y, a.z, s[9], s[10], s[11], v.x, v.y, v.z,
        ];
        assert_eq!(d, expected);
    }

    #[test]
    fn jerk_is_the_time_derivative_of_acceleration() {
        let h = 1e-5;
        let mut worst: Real = 0.0;
        for (x, v) in sample_states(42, 50) {
            let d = x.derivative(&v);
            let fd = (x.offset(&d, h).acceleration() - x.offset(&d, -h).acceleration()) / (2.0 * h);
            worst = worst.max(rel_err(&fd, &x.jerk()));
        }
        assert!(worst < 1e-7, "worst relative error {worst}");
    }

    /// A smooth non-trivial law so both plants exercise every stage.
    fn sine_law(_t: Real, f: &Flat) -> Vec3 {
        Vec3::new(0.3, -0.2, 0.1) - f.r * 1e-3
    }

    #[test]
    fn rk4_step_rejects_nan_state() {
        let mut x = QuadState::hover(Vec3::new(1.0, 2.0, 3.0));
        x.0[10] = Real::NAN;
        let r = x.rk4_step(0.0, 0.01, sine_law);
        assert!(
            matches!(
                r,
                Err(ControlFault::NonFiniteState {
                    index: 10,
                    name: "phidot"
                })
            ),
            "{r:?}"
        );
        let mut c = Chain::rest(Vec3::zeros());
        c.0.v.y = Real::INFINITY;
        let r = c.rk4_step(0.0, 0.01, sine_law);
        assert!(
            matches!(
                r,
                Err(ControlFault::NonFiniteState {
                    index: 4,
                    name: "v.y"
                })
            ),
            "{r:?}"
        );
    }

    #[test]
    fn rk4_step_rejects_nan_snap() {
        let x = QuadState::hover(Vec3::zeros());
        let nan_law = |_t: Real, _f: &Flat| Vec3::new(0.0, Real::NAN, 0.0);
        assert!(matches!(
            x.rk4_step(0.0, 0.01, nan_law),
            Err(ControlFault::NonFiniteSnap { .. })
        ));
        assert!(matches!(
            Chain::rest(Vec3::zeros()).rk4_step(0.0, 0.01, nan_law),
            Err(ControlFault::NonFiniteSnap { .. })
        ));
        // A law that only goes bad at a later stage must still give Err, not a NaN state.
        let late = |t: Real, _f: &Flat| {
            if t > 0.0 {
                Vec3::new(Real::INFINITY, 0.0, 0.0)
            } else {
                Vec3::zeros()
            }
        };
        assert!(x.rk4_step(0.0, 0.01, late).is_err());
    }

    #[test]
    fn rk4_step_rejects_overflow_to_non_finite_state() {
        // Finite but huge snap: every stage is finite, the result overflows.
        let x = QuadState::hover(Vec3::zeros());
        let huge = |_t: Real, _f: &Flat| Vec3::new(Real::MAX, 0.0, 0.0);
        let r = x.rk4_step(0.0, 10.0, huge);
        assert!(r.is_err(), "{r:?}");
        let r = Chain::rest(Vec3::zeros()).rk4_step(0.0, 10.0, huge);
        assert!(r.is_err(), "{r:?}");
    }

    #[test]
    fn chain_rk4_is_exact_for_constant_snap() {
        // r'''' = U constant: the solution is a quartic, which RK4 integrates exactly.
        let u = Vec3::new(0.5, -1.0, 2.0);
        let mut c = Chain::rest(Vec3::zeros());
        let h = 0.125; // exactly representable
        for k in 0..8 {
            c = c.rk4_step(k as Real * h, h, |_t, _f| u).expect("finite");
        }
        let t: Real = 1.0;
        let expected = u * (t.powi(4) / 24.0);
        assert!((c.0.r - expected).norm() < 1e-14, "{:?}", c.0.r);
        assert!((c.0.j - u * t).norm() < 1e-14);
    }
}
