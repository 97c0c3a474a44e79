//! Where the decoupling matrix M of the feedback linearisation (eq. 43b) is refused: the guard
//! that keeps M away from singular (|det M| = F^2 |cos phi|, ERRATA 3) and the fault a refused
//! state or input becomes. Below both the plant (`dynamics`, which steps under the control law)
//! and the law (`control`), so neither has to import the other for it.

use cdm_math::Real;

/// Limits that keep M = da/dq well away from singular (|det M| = F^2 |cos phi|, ERRATA 3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SingularityGuard {
    /// Smallest accepted thrust per mass F (m/s^2); lower (including negative) thrust is refused.
    pub min_thrust_mps2: Real,
    /// Largest accepted |roll| (rad); must be below pi/2, where cos(phi) = 0.
    pub max_abs_roll_rad: Real,
}

impl SingularityGuard {
    /// 0.5 m/s^2 and 80 degrees: |det M| >= 0.25 * cos(80 deg) ~ 0.043 on the accepted set.
    pub const DEFAULT: SingularityGuard = SingularityGuard {
        min_thrust_mps2: 0.5,
        max_abs_roll_rad: 80.0 * (core::f64::consts::PI / 180.0),
    };
}

impl Default for SingularityGuard {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why the feedback-linearising controller (or a plant step that uses it) refused to act.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ControlFault {
    /// Thrust per mass is below the guard: M loses rank as F -> 0 (ERRATA 3).
    #[error(
        "thrust per mass {thrust_mps2} m/s^2 is below the guard {min_thrust_mps2} m/s^2: \
         the decoupling matrix M is (near) singular, |det M| = F^2 |cos phi|"
    )]
    SingularThrust {
        /// The state's thrust per mass F (m/s^2).
        thrust_mps2: Real,
        /// The guard's lower limit (m/s^2).
        min_thrust_mps2: Real,
    },
    /// |roll| exceeds the guard: M loses rank as cos(phi) -> 0 (ERRATA 3).
    #[error(
        "roll {roll_rad} rad exceeds the guard of +-{max_abs_roll_rad} rad: \
         the decoupling matrix M is (near) singular, |det M| = F^2 |cos phi|"
    )]
    SingularRoll {
        /// The state's roll phi (rad).
        roll_rad: Real,
        /// The guard's limit on |phi| (rad).
        max_abs_roll_rad: Real,
    },
    /// A state component is NaN or infinite.
    #[error("state component {index} ({name}) is not finite")]
    NonFiniteState {
        /// Index into the state array.
        index: usize,
        /// Name of that component.
        name: &'static str,
    },
    /// The commanded snap U is NaN or infinite.
    #[error("commanded snap U = {snap:?} m/s^4 is not finite")]
    NonFiniteSnap {
        /// The commanded snap.
        snap: [Real; 3],
    },
    /// The computed input V = M^{-1}(U - N) overflowed to a non-finite value.
    #[error("computed input V = [Fddot, phiddot, thetaddot] = {input:?} is not finite")]
    NonFiniteInput {
        /// The computed input.
        input: [Real; 3],
    },
}
