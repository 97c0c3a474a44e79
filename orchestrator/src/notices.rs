//! The orchestrator's sink for the libraries' notices: each on stdout, none under `--quiet`.

use std::fmt::Display;
use std::sync::Arc;

use cdm_team::notices::{NoticeSink, Silent, TickProgress};

/// Prints each notice as it comes (a full or closed stdout drops it, as every line here).
struct Stdout;

impl NoticeSink for Stdout {
    fn notice(&self, notice: &dyn Display) {
        out!("{notice}");
    }

    fn progress(&self, what: &'static str, last_tick: u64, dt_s: f64) -> Box<dyn TickProgress> {
        Box::new(crate::progress::Progress::new(what, last_tick, dt_s))
    }
}

/// The sink for a command: stdout, or nothing with `--quiet`.
pub fn sink(quiet: bool) -> Arc<dyn NoticeSink> {
    if quiet {
        Arc::new(Silent)
    } else {
        Arc::new(Stdout)
    }
}
