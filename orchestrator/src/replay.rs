//! `orchestrator replay RUN_DIR --out DIR`: a finished lockstep run flown again in process from
//! its directory alone, and compared with it; with a change ("what if") the same history
//! (commands, losses) flown with other gains, another travel time or other links.

use std::path::{Path, PathBuf};

use cdm_records::run_record::RunMode;
use cdm_records::rundir::RunDir;
use cdm_records::telemetry::TelemetryFormat;
use cdm_scenario::{Checks, Scenario};
use cdm_simulate::replay::{first_audit_difference, first_line_difference, read_audit, RunInputs};
use cdm_team::{out, Exit, Failure};
use clap::Args;

use crate::cli::{OnLossArg, RunOptions};
use crate::commands::{after_run, exit_of, fly_in_process, InProcess};

/// The options of `orchestrator replay`.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The run directory to fly again (of `simulate`, a lockstep `launch` or a `replay`).
    #[arg(value_name = "RUN_DIR")]
    pub run: PathBuf,
    /// The replay's run directory (created; refused when it exists and is not empty, unless
    /// --force).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Reuse a non-empty --out directory.
    #[arg(long)]
    pub force: bool,
    /// What if: fly with these gains k1,k2,k3,k4 (eq. 18) instead of the scenario's.
    #[arg(long, value_name = "K1,K2,K3,K4", allow_hyphen_values = true)]
    pub gains: Option<String>,
    /// What if: fly with this travel time instead of the scenario's (the losses and commands
    /// keep their ticks and times).
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    pub t_total: Option<f64>,
    /// What if: other links (each flag overrides that key of the run's `[link]`).
    #[command(flatten)]
    pub link: cdm_member::options::LinkArgs,
    /// Do not draw the figures at the end of the replay.
    #[arg(long)]
    pub no_figures: bool,
}

impl ReplayArgs {
    /// Whether anything is changed: then the replay is expected to differ from the run.
    fn what_if(&self) -> bool {
        let l = &self.link;
        self.gains.is_some()
            || self.t_total.is_some()
            || l.link_delay_ms.is_some()
            || l.link_jitter_ms.is_some()
            || l.link_loss.is_some()
            || l.seed.is_some()
    }
}

/// `replay`: read and check the run directory, fly it (changed or not) into --out, compare.
pub fn replay_command(a: ReplayArgs, quiet: bool) -> Result<Exit, Failure> {
    let inputs = RunInputs::read(&a.run).map_err(Failure::bad_input)?;
    let r = &inputs.record;
    // Checked by RunRecord::read.
    let format = r.telemetry_format().unwrap_or_default();
    cdm_team::telemetry::check_available(format)?;
    let what_if = a.what_if();
    let s = changed(&inputs.scenario, &a)?;
    let run = RunOptions {
        link: Default::default(),
        stop_on_violation: r.stop_on_violation,
        max_ticks: r.max_ticks,
        no_figures: a.no_figures,
        follow: None,
        telemetry: format,
        lose: Vec::new(),
        on_loss: if r.stop_on_loss {
            OnLossArg::Stop
        } else {
            OnLossArg::Repair
        },
    };
    let losses = inputs
        .losses_for(&s, r.max_ticks)
        .map_err(Failure::bad_input)?;
    let steered = inputs
        .commands_for(&s, !what_if)
        .map_err(Failure::bad_input)?;
    if same_dir(&a.run, &a.out) {
        return Err(Failure::bad_input(format!(
            "--out {}: the run directory itself: the replay needs a directory of its own",
            a.out.display()
        )));
    }
    let dir = RunDir::create(&a.out, a.force).map_err(Failure::from)?;
    let (flown, records) = match steered {
        Some((flown, records)) => (flown, Some(records)),
        None => (s, None),
    };
    let flight = InProcess {
        what: "replay",
        mode: RunMode::Replay,
        records: records.as_deref(),
        losses,
        every: Some(r.every),
        run: &run,
        quiet,
    };
    let report = fly_in_process(&flown, &dir, flight)?;
    let differs = compare(&a.run, dir.path(), format, quiet)?;
    after_run(dir.path(), &report, &run, quiet);
    match differs {
        Some(why) if !what_if => Err(Failure::fault(format!(
            "replay of {} differs from the run: {why}",
            a.run.display()
        ))),
        _ => Ok(exit_of(&report)),
    }
}

/// The run's scenario with the what-if changes, validated as a scenario file is.
fn changed(s: &Scenario, a: &ReplayArgs) -> Result<Scenario, Failure> {
    let mut file = s.file.clone();
    let mut origin = s.origin.clone();
    if let Some(text) = &a.gains {
        file.gains = parse_gains(text).map_err(Failure::bad_input)?;
        origin += &format!(" with --gains {text}");
    }
    if let Some(t) = a.t_total {
        file.t_total_s = t;
        origin += &format!(" with --t-total {t}");
    }
    let s = if a.gains.is_some() || a.t_total.is_some() {
        Scenario::from_file(file, &origin, Checks::Full).map_err(Failure::bad_input)?
    } else {
        s.clone()
    };
    a.link.apply(&s).map_err(Failure::bad_input)
}

/// `--gains K1,K2,K3,K4`: four finite numbers (their stability is the scenario's check).
fn parse_gains(text: &str) -> Result<[f64; 4], String> {
    let bad = || format!("--gains {text}: expected four numbers K1,K2,K3,K4, e.g. 200,150,80,20");
    let values: Vec<f64> = (text.split(','))
        .map(|v| v.trim().parse::<f64>().map_err(|_| bad()))
        .collect::<Result<_, _>>()?;
    let gains: [f64; 4] = values.try_into().map_err(|_| bad())?;
    if gains.iter().all(|g| g.is_finite()) {
        Ok(gains)
    } else {
        Err(bad())
    }
}

fn same_dir(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// Compare the replay's telemetry and audit with the run's and say so; the first difference,
/// if any.
fn compare(
    run: &Path,
    replay: &Path,
    format: TelemetryFormat,
    quiet: bool,
) -> Result<Option<String>, Failure> {
    let name = format.file_name();
    let read = |dir: &Path| {
        let p = dir.join(name);
        std::fs::read(&p).map_err(|e| Failure::bad_input(format!("{}: {e}", p.display())))
    };
    let (a, b) = (read(run)?, read(replay)?);
    let telemetry = match (format, first_line_difference(&a, &b)) {
        (_, None) => None,
        (TelemetryFormat::Parquet, Some(_)) => Some(format!("{name} differs")),
        (_, Some(line)) => Some(format!("{name} differs from line {line}")),
    };
    let audit = first_audit_difference(
        &read_audit(run).map_err(Failure::bad_input)?,
        &read_audit(replay).map_err(Failure::bad_input)?,
    );
    if !quiet {
        match &telemetry {
            None => out!("  {name}: identical to the run's ({} bytes)", b.len()),
            Some(why) => out!("  {why} ({} bytes, the run's {})", b.len(), a.len()),
        }
        match &audit {
            None => out!("  audit.json: safety figures identical to the run's"),
            Some(why) => out!("  audit.json: safety figures differ, first {why}"),
        }
    }
    Ok(telemetry.or(audit.map(|w| format!("audit.json: {w}"))))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gains_are_four_finite_numbers() {
        assert_eq!(parse_gains("1,2,3,4.5"), Ok([1.0, 2.0, 3.0, 4.5]));
        for bad in ["1,2,3", "1,2,3,4,5", "1,2,x,4", "1,2,3,inf", ""] {
            let e = parse_gains(bad).unwrap_err();
            assert!(e.starts_with(&format!("--gains {bad}:")), "{e}");
        }
    }
}
