//! Timeout options, validated before anything runs.

use std::time::Duration;

/// The longest timeout any option accepts: one day. Every wait has a deadline, and a deadline
/// beyond this is a typo (`1e308` used to panic converting to a `Duration`).
pub const MAX_TIMEOUT_S: f64 = 86_400.0;

/// A timeout option out of range (names the option and the value).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{option} must be a number of seconds in (0, {max}], got {shown}", max = MAX_TIMEOUT_S)]
pub struct TimeoutError {
    /// The option, `--join-timeout`.
    pub option: String,
    /// The value as given (`1e308` as "1e308", not 309 digits).
    pub shown: String,
}

/// A timeout option in seconds: finite, > 0 and at most [`MAX_TIMEOUT_S`].
pub fn timeout(option: &str, seconds: f64) -> Result<Duration, TimeoutError> {
    if seconds > 0.0 && seconds <= MAX_TIMEOUT_S {
        Ok(Duration::from_secs_f64(seconds))
    } else {
        let shown = if seconds.abs() >= 1e6 {
            format!("{seconds:e}")
        } else {
            seconds.to_string()
        };
        Err(TimeoutError {
            option: option.to_owned(),
            shown,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timeouts_have_a_range() {
        assert_eq!(timeout("--x", 2.5), Ok(Duration::from_millis(2500)));
        for bad in [
            0.0,
            -1.0,
            f64::NAN,
            f64::INFINITY,
            1e308,
            MAX_TIMEOUT_S * 2.0,
        ] {
            let e = timeout("--x", bad).unwrap_err().to_string();
            assert!(e.starts_with("--x must be"), "{e}");
        }
        let e = timeout("--x", 1e308).unwrap_err().to_string();
        assert_eq!(
            e,
            "--x must be a number of seconds in (0, 86400], got 1e308"
        );
    }
}
