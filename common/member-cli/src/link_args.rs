//! `--link-delay-ms`, `--link-jitter-ms`, `--link-loss` and `--seed`, on `simulate`, lockstep
//! `launch`, `replay` and the member binaries.

use cdm_member::options::{LinkOverrideError, LinkOverrides};

/// Imperfect links as part of the model (cdm-model `link.rs`). Each flag given overrides that
/// key of the scenario's `[link]` table. A member started by hand needs the flags its team was
/// launched with (or the run directory's scenario.toml, which has them): the links are part of
/// the scenario's hash, so a member with other links is refused.
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

impl LinkArgs {
    /// The flags as the library's plain values.
    pub fn overrides(&self) -> LinkOverrides {
        LinkOverrides {
            delay_ms: self.link_delay_ms,
            jitter_ms: self.link_jitter_ms,
            loss: self.link_loss,
            seed: self.seed,
        }
    }

    /// `s` with the flags given applied to its `[link]` table (unchanged when none is given).
    pub fn apply(
        &self,
        s: &cdm_scenario::Scenario,
    ) -> Result<cdm_scenario::Scenario, LinkOverrideError> {
        self.overrides().apply(s)
    }
}
