//! What a run tells its operator as it goes, as values: a library hands each notice to a sink
//! the binary supplies, which prints it (or drops it under `--quiet`). No library prints.

use std::fmt::Display;

use cdm_records::audit::AuditReport;

/// Where a library's notices go. A notice's text is its `Display` (one or more lines of stdout).
pub trait NoticeSink: Send + Sync {
    fn notice(&self, notice: &dyn Display);

    /// The progress of a run of ticks 0..=`last_tick`, `dt_s` apart: not shown unless the
    /// binary shows it.
    fn progress(&self, what: &'static str, last_tick: u64, dt_s: f64) -> Box<dyn TickProgress> {
        let _ = (what, last_tick, dt_s);
        Box::new(Silent)
    }
}

/// The progress of a run of ticks, as the binary shows it (a bar, log lines).
pub trait TickProgress: Send {
    /// Tick `tick` is done; `audit` is the audit so far.
    fn tick(&mut self, tick: u64, audit: &AuditReport);
    /// The run is over (a bar is removed).
    fn finish(&mut self);
}

/// Drops every notice (`--quiet`, tests).
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl NoticeSink for Silent {
    fn notice(&self, _notice: &dyn Display) {}
}

impl TickProgress for Silent {
    fn tick(&mut self, _tick: u64, _audit: &AuditReport) {}
    fn finish(&mut self) {}
}
