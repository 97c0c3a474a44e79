//! Checks of one number of a scenario file, shared by the file's validation and its mission's.

use cdm_math::Real;

use crate::ScenarioErrorKind as E;

/// The fewest ticks over the motion (T_total * comm_hz): fewer cannot resolve the quintic
/// (eq. 15), and the controller faults at tick 0.
pub const MIN_MOTION_TICKS: Real = 10.0;

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
