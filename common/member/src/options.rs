//! Command-line values shared by the binaries, validated before anything runs.

use std::time::Duration;

/// The longest timeout any option accepts: one day. Every wait has a deadline, and a deadline
/// beyond this is a typo (`1e308` used to panic converting to a `Duration`).
pub const MAX_TIMEOUT_S: f64 = 86_400.0;

/// A timeout option in seconds: finite, > 0 and at most [`MAX_TIMEOUT_S`]; the error names the
/// option and the value.
pub fn timeout(option: &str, seconds: f64) -> Result<Duration, String> {
    if seconds > 0.0 && seconds <= MAX_TIMEOUT_S {
        Ok(Duration::from_secs_f64(seconds))
    } else {
        // 1e308 as "1e308", not 309 digits.
        let shown = if seconds.abs() >= 1e6 {
            format!("{seconds:e}")
        } else {
            seconds.to_string()
        };
        Err(format!(
            "{option} must be a number of seconds in (0, {MAX_TIMEOUT_S}], got {shown}"
        ))
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
            let e = timeout("--x", bad).unwrap_err();
            assert!(e.starts_with("--x must be"), "{e}");
        }
    }
}

/// `--link-delay-ms`, `--link-jitter-ms`, `--link-loss` and `--seed`: imperfect links as part
/// of the model (`link.rs`), on `simulate`, lockstep `launch` and the member binaries. Each flag
/// given overrides that key of the scenario's `[link]` table. A member started by hand needs the
/// flags its team was launched with (or the run directory's scenario.toml, which has them): the
/// links are part of the scenario's hash, so a member with other links is refused.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct LinkArgs {
    /// Delay of every state between members, milliseconds (rounded to whole ticks).
    #[arg(long, value_name = "MS", allow_negative_numbers = true)]
    pub link_delay_ms: Option<f64>,
    /// Extra delay per state, drawn uniformly in [0, MS) per (link, tick) from --seed.
    #[arg(long, value_name = "MS", allow_negative_numbers = true)]
    pub link_jitter_ms: Option<f64>,
    /// Probability in [0, 1) that a state is lost, drawn per (link, tick) from --seed; a
    /// follower extrapolates from the newest state it has.
    #[arg(long, value_name = "P", allow_negative_numbers = true)]
    pub link_loss: Option<f64>,
    /// Seed of the link draws (0 ..= 2^63 - 1; default 0).
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
}

/// Why `--link-*` / `--seed` cannot be applied to a scenario.
#[derive(Debug, thiserror::Error)]
pub enum LinkArgsError {
    /// A flag's value is out of range (names the flag and the value).
    #[error("{flag} {value}: {reason}")]
    Flag {
        flag: &'static str,
        value: String,
        reason: String,
    },
    /// The scenario refused the resulting `[link]` table (names the scenario's field).
    #[error(transparent)]
    Scenario(#[from] cdm_scenario::ScenarioError),
}

impl LinkArgs {
    /// True when no flag was given (the scenario's `[link]` table stands).
    pub fn is_empty(&self) -> bool {
        self.link_delay_ms.is_none()
            && self.link_jitter_ms.is_none()
            && self.link_loss.is_none()
            && self.seed.is_none()
    }

    /// `s` with the flags given applied to its `[link]` table (unchanged when none is given).
    /// A bad value is refused naming its flag (or the scenario's field, when it came from there).
    pub fn apply(
        &self,
        s: &cdm_scenario::Scenario,
    ) -> Result<cdm_scenario::Scenario, LinkArgsError> {
        let flags = [
            ("link.delay_ms", "--link-delay-ms", self.link_delay_ms),
            ("link.jitter_ms", "--link-jitter-ms", self.link_jitter_ms),
            ("link.loss", "--link-loss", self.link_loss),
            ("link.seed", "--seed", self.seed.map(|v| v as f64)),
        ];
        if flags.iter().all(|f| f.2.is_none()) {
            return Ok(s.clone());
        }
        let old = s.file.link.unwrap_or_default();
        let spec = cdm_model::link::LinkSpec {
            delay_ms: self.link_delay_ms.unwrap_or(old.delay_ms),
            jitter_ms: self.link_jitter_ms.unwrap_or(old.jitter_ms),
            loss: self.link_loss.unwrap_or(old.loss),
            seed: self.seed.unwrap_or(old.seed),
        };
        if let Some((field, reason)) = spec.problem() {
            if let Some((_, flag, Some(v))) = flags.iter().find(|f| f.0 == field) {
                let shown = if field == "link.seed" {
                    spec.seed.to_string()
                } else {
                    v.to_string()
                };
                return Err(LinkArgsError::Flag {
                    flag,
                    value: shown,
                    reason,
                });
            }
        }
        Ok(s.with_link(Some(spec))?)
    }
}

/// Real time holds every state back by the link delay, so a delay at or beyond the stale bound
/// would make every neighbour a fault at its first tick: refused up front, naming both.
pub fn realtime_links_refusal(
    s: &cdm_scenario::Scenario,
    stale_after: std::time::Duration,
) -> Option<String> {
    let delay_ms = s.link_model().spec().delay_ms;
    let bound_ms = stale_after.as_secs_f64() * 1e3;
    (delay_ms >= bound_ms).then(|| {
        format!(
            "--link-delay-ms {delay_ms} (or the scenario's link.delay_ms) is not below --stale-after ({bound_ms} ms): in real time every neighbour would be stale"
        )
    })
}
