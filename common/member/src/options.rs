//! A member's options as plain values: the links it flies over (each given value overrides that
//! key of the scenario's `[link]`), and the check of those links against real time.

/// Imperfect links as part of the model (`link.rs`), on `simulate`, lockstep `launch` and the
/// member binaries (`--link-delay-ms`, `--link-jitter-ms`, `--link-loss`, `--seed`). Each value
/// given overrides that key of the scenario's `[link]` table. A member started by hand needs the
/// values its team was launched with (or the run directory's scenario.toml, which has them): the
/// links are part of the scenario's hash, so a member with other links is refused.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LinkOverrides {
    /// Delay of every state between members, milliseconds (rounded to whole ticks).
    pub delay_ms: Option<f64>,
    /// Extra delay per state, drawn uniformly in [0, MS) per (link, tick) from the seed.
    pub jitter_ms: Option<f64>,
    /// Probability in [0, 1) that a state is lost, drawn per (link, tick) from the seed.
    pub loss: Option<f64>,
    /// Seed of the link draws (0 ..= 2^63 - 1).
    pub seed: Option<u64>,
}

/// Why link overrides cannot be applied to a scenario.
#[derive(Debug, thiserror::Error)]
pub enum LinkOverrideError {
    /// A value is out of range (names its flag and the value).
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

impl LinkOverrides {
    /// True when no value is given (the scenario's links fly as they are).
    pub fn is_empty(&self) -> bool {
        *self == LinkOverrides::default()
    }

    /// `s` with the values given applied to its `[link]` table (unchanged when none is given).
    /// A bad value is refused naming its flag (or the scenario's field, when it came from there).
    pub fn apply(
        &self,
        s: &cdm_scenario::Scenario,
    ) -> Result<cdm_scenario::Scenario, LinkOverrideError> {
        let flags = [
            ("link.delay_ms", "--link-delay-ms", self.delay_ms),
            ("link.jitter_ms", "--link-jitter-ms", self.jitter_ms),
            ("link.loss", "--link-loss", self.loss),
            ("link.seed", "--seed", self.seed.map(|v| v as f64)),
        ];
        if flags.iter().all(|f| f.2.is_none()) {
            return Ok(s.clone());
        }
        let old = s.file.link.unwrap_or_default();
        let spec = cdm_model::link::LinkSpec {
            delay_ms: self.delay_ms.unwrap_or(old.delay_ms),
            jitter_ms: self.jitter_ms.unwrap_or(old.jitter_ms),
            loss: self.loss.unwrap_or(old.loss),
            seed: self.seed.unwrap_or(old.seed),
        };
        if let Some((field, reason)) = spec.problem() {
            if let Some((_, flag, Some(v))) = flags.iter().find(|f| f.0 == field) {
                let shown = if field == "link.seed" {
                    spec.seed.to_string()
                } else {
                    v.to_string()
                };
                return Err(LinkOverrideError::Flag {
                    flag,
                    value: shown,
                    reason,
                });
            }
        }
        Ok(s.with_link(Some(spec))?)
    }
}

/// A link delay at or beyond the real-time stale bound: every neighbour would be a fault at its
/// first tick.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("--link-delay-ms {delay_ms} (or the scenario's link.delay_ms) is not below --stale-after ({bound_ms} ms): in real time every neighbour would be stale")]
pub struct StaleLinks {
    pub delay_ms: f64,
    pub bound_ms: f64,
}

/// Real time holds every state back by the link delay, so a delay at or beyond the stale bound
/// would make every neighbour a fault at its first tick: refused up front, naming both.
pub fn realtime_links_refusal(
    s: &cdm_scenario::Scenario,
    stale_after: std::time::Duration,
) -> Option<StaleLinks> {
    let delay_ms = s.link_model().spec().delay_ms;
    let bound_ms = stale_after.as_secs_f64() * 1e3;
    (delay_ms >= bound_ms).then_some(StaleLinks { delay_ms, bound_ms })
}
