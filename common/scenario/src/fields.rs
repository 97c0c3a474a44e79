//! Checks of one number of a scenario file, shared by the file's validation and its mission's.

use cdm_math::Real;

use crate::ScenarioErrorKind as E;

/// The fewest ticks over the motion (T_total * comm_hz): fewer cannot resolve the quintic
/// (eq. 15), and the controller faults at tick 0.
pub const MIN_MOTION_TICKS: Real = 10.0;

/// The most ticks a motion, a hold or a whole flight may last.
pub const MAX_TICKS: Real = 1e8;

/// How far from the origin a position, goal or ground may be, metres: a team spread over a
/// continent is not a team, and the certificate's cost grows with the distances flown (its
/// travel-time threshold grows as their square root, Sec. VII-D).
pub const MAX_COORD_M: Real = 1e6;

/// `value`, when finite.
pub(crate) fn finite(field: impl Into<String>, value: Real) -> Result<Real, E> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(E::NonFinite {
            field: field.into(),
            value,
        })
    }
}

/// `value`, when finite and above zero.
pub(crate) fn positive(field: &str, value: Real) -> Result<Real, E> {
    finite(field, value)?;
    if value > 0.0 {
        Ok(value)
    } else {
        Err(E::Invalid {
            field: field.into(),
            reason: format!("must be > 0, got {value}"),
        })
    }
}

/// A coordinate (a position, a goal, a ground height): finite and at most [`MAX_COORD_M`] from
/// the origin along each axis.
pub(crate) fn coordinate(field: impl Into<String>, value: Real) -> Result<Real, E> {
    let field = field.into();
    let value = finite(field.clone(), value)?;
    if value.abs() > MAX_COORD_M {
        return Err(E::Invalid {
            field,
            reason: format!("= {value:.3e} m is more than {MAX_COORD_M:e} m from the origin"),
        });
    }
    Ok(value)
}
