//! Progress of long runs: a bar on a terminal (tick, simulated time, ticks per second, the worst
//! safety margins so far), plain `tracing` INFO lines every few seconds otherwise (`--quiet`
//! shows none: its sink, [`crate::notices::sink`], makes no [`Progress`]).

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use cdm_records::audit::AuditReport;
use cdm_team::notices::TickProgress;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Seconds between plain log lines when stderr is not a terminal.
const LOG_EVERY: Duration = Duration::from_secs(5);
/// Redraw the bar at most this often.
const DRAW_EVERY: Duration = Duration::from_millis(100);

enum Mode {
    Bar(ProgressBar),
    Log,
}

/// Progress of a run of ticks 0..=last.
pub struct Progress {
    mode: Mode,
    what: &'static str,
    last_tick: u64,
    dt_s: f64,
    started: Instant,
    shown: Instant,
}

/// The safety margins so far, as one short text: separation above 2 eps, tracking under delta,
/// containment (distance to the prism's sides), lambda_1 above lambda_CD,min.
pub fn margins(r: &AuditReport) -> String {
    let sep = r.min_separation_m - 2.0 * r.numbers.eps_m;
    let track = r.numbers.delta_m - r.max_deviation_m;
    let side = r.min_boundary_distance_m;
    let lambda = r.lambda1_min_run - r.numbers.lambda_cd_min;
    let v = r.violations.len() as u64 + r.violations_dropped;
    let mut text =
        format!("margin sep {sep:+.2} m, track {track:+.2} m, side {side:+.2} m, λ1 {lambda:+.3}");
    // The airspace, only when the scenario has one.
    if let Some(m) = r.min_fence_margin_m {
        text.push_str(&format!(", fence {m:+.2} m"));
    }
    if let Some(m) = r.min_obstacle_margin_m {
        text.push_str(&format!(", obstacle {m:+.2} m"));
    }
    if v > 0 {
        text.push_str(&format!(", {v} VIOLATION(S)"));
        // Name what the airspace's first breach was (a fence side, an obstacle).
        if let Some(b) = r.violations.iter().find(|b| b.name.is_some()) {
            text.push_str(&format!(" ({} by agent {:?})", b.label(), b.agents));
        }
    }
    text
}

impl Progress {
    /// A bar when stderr is a terminal, log lines otherwise.
    pub fn new(what: &'static str, last_tick: u64, dt_s: f64) -> Self {
        let mode = if std::io::stderr().is_terminal() {
            let bar = ProgressBar::with_draw_target(
                Some(last_tick + 1),
                ProgressDrawTarget::stderr_with_hz(10),
            );
            if let Ok(style) = ProgressStyle::with_template("{prefix} [{bar:20}] {msg}") {
                bar.set_style(style.progress_chars("=> "));
            }
            bar.set_prefix(what);
            Mode::Bar(bar)
        } else {
            Mode::Log
        };
        let now = Instant::now();
        Progress {
            mode,
            what,
            last_tick,
            dt_s,
            started: now,
            shown: now,
        }
    }

    /// Tick `tick` is done; `r` is the audit so far.
    pub fn tick(&mut self, tick: u64, r: &AuditReport) {
        let every = match self.mode {
            Mode::Bar(_) => DRAW_EVERY,
            Mode::Log => LOG_EVERY,
        };
        if self.shown.elapsed() < every && tick < self.last_tick {
            return;
        }
        self.shown = Instant::now();
        let rate = (tick + 1) as f64 / self.started.elapsed().as_secs_f64().max(1e-9);
        let t = tick as f64 * self.dt_s;
        match &self.mode {
            Mode::Bar(bar) => {
                bar.set_position(tick + 1);
                bar.set_message(format!(
                    "tick {tick}/{}, t {t:.2} s, {rate:.0}/s, {}",
                    self.last_tick,
                    margins(r)
                ));
            }
            Mode::Log => tracing::info!(
                tick,
                last = self.last_tick,
                t_s = t,
                ticks_per_s = rate.round(),
                "{} progress, {}",
                self.what,
                margins(r)
            ),
        }
    }

    /// Remove the bar.
    pub fn finish(&self) {
        if let Mode::Bar(bar) = &self.mode {
            bar.finish_and_clear();
        }
    }
}

impl TickProgress for Progress {
    fn tick(&mut self, tick: u64, audit: &AuditReport) {
        Progress::tick(self, tick, audit);
    }
    fn finish(&mut self) {
        Progress::finish(self);
    }
}

impl Drop for Progress {
    /// A run that ends on an error path leaves no half-drawn bar behind.
    fn drop(&mut self) {
        self.finish();
    }
}

/// A spinner for work without ticks (`plan`): a terminal spinner with elapsed time, or one log
/// line, or nothing when quiet.
pub struct Spinner(Option<ProgressBar>);

impl Spinner {
    pub fn new(message: &str, quiet: bool) -> Self {
        if quiet {
            return Spinner(None);
        }
        if !std::io::stderr().is_terminal() {
            tracing::info!("{message}");
            return Spinner(None);
        }
        let bar = ProgressBar::new_spinner();
        if let Ok(style) = ProgressStyle::with_template("{spinner} {msg} ({elapsed})") {
            bar.set_style(style);
        }
        bar.set_message(message.to_string());
        bar.enable_steady_tick(Duration::from_millis(120));
        Spinner(Some(bar))
    }

    pub fn set_message(&self, message: String) {
        match &self.0 {
            Some(b) => b.set_message(message),
            None => tracing::debug!("{message}"),
        }
    }

    pub fn finish(&self) {
        if let Some(b) = &self.0 {
            b.finish_and_clear();
        }
    }
}
