//! `orchestrator replay RUN_DIR --out DIR`: a finished lockstep run flown again in process from
//! its directory alone, and compared with it; with a change ("what if") the same history
//! (commands, losses) flown with other gains, another travel time or other links.

use std::path::Path;

use cdm_certificates::command_certificate::CommandRecord;
use cdm_engine::loss::LossSchedule;
use cdm_exit::Failure;
use cdm_records::rundir::RunDir;
use cdm_records::telemetry::TelemetryFormat;
use cdm_scenario::{Checks, Scenario};
use cdm_simulate::replay::{first_audit_difference, first_line_difference, read_audit, RunInputs};

use crate::cli::{OnLossArg, ReplayArgs, RunOptions};

/// A replay ready to fly: the run's inputs checked, the what-if applied, --out created.
pub struct Prepared {
    /// The scenario to fly, its plan the commanded one.
    pub flown: Scenario,
    /// The commands as applied, when the run had a command file.
    pub records: Option<Vec<CommandRecord>>,
    pub losses: LossSchedule,
    /// The run's options (run.json), as `simulate` takes them.
    pub run: RunOptions,
    pub every: u64,
    pub dir: RunDir,
    pub format: TelemetryFormat,
    pub what_if: bool,
}

/// Read and check the run directory, apply the change, create --out.
pub fn prepare(a: &ReplayArgs) -> Result<Prepared, Failure> {
    let inputs = RunInputs::read(&a.run).map_err(Failure::bad_input)?;
    let r = &inputs.record;
    // Checked by RunRecord::read.
    let format = r.telemetry_format().unwrap_or_default();
    cdm_team::telemetry::check_available(format).map_err(Failure::bad_input)?;
    let what_if = a.what_if();
    let s = changed(&inputs.scenario, a)?;
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
    Ok(Prepared {
        flown,
        records,
        losses,
        run,
        every: r.every,
        dir,
        format,
        what_if,
    })
}

/// A replay without a change that does not give the run's bytes is a fault of the replay (the
/// lockstep contract broken), named by its first difference.
pub fn outcome(a: &ReplayArgs, what_if: bool, differs: Option<String>) -> Result<(), Failure> {
    match differs {
        Some(why) if !what_if => Err(Failure::fault(format!(
            "replay of {} differs from the run: {why}",
            a.run.display()
        ))),
        _ => Ok(()),
    }
}

/// The run's scenario with the what-if changes, validated as a scenario file is: `--scenario`
/// (of the same team) in its place, then `--gains`, `--t-total` and `--link-*`.
pub(crate) fn changed(s: &Scenario, a: &ReplayArgs) -> Result<Scenario, Failure> {
    let base = match &a.scenario {
        Some(path) => {
            let other = Scenario::load(path, Checks::Full).map_err(Failure::bad_input)?;
            same_team(s, &other).map_err(|why| {
                Failure::bad_input(format!(
                    "--scenario {}: {why}: not the run's team",
                    path.display()
                ))
            })?;
            other
        }
        None => s.clone(),
    };
    let s = &base;
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
        base
    };
    a.link.apply(&s).map_err(Failure::bad_input)
}

/// Why `other` is not the team of the run's scenario `run`, if it is not: other ids, roles,
/// in-neighbours (the graph) or comm_hz (the run's ticks would be other instants).
fn same_team(run: &Scenario, other: &Scenario) -> Result<(), String> {
    let (a, b) = (&run.formation.members, &other.formation.members);
    if a.len() != b.len() {
        return Err(format!("{} agents, the run has {}", b.len(), a.len()));
    }
    for (x, y) in a.iter().zip(b) {
        if x.id != y.id {
            return Err(format!("agent {} where the run has agent {}", y.id, x.id));
        }
        if x.role != y.role {
            return Err(format!(
                "agent {} is a {}, in the run a {}",
                y.id,
                y.role.as_str(),
                x.role.as_str()
            ));
        }
        let ins = |m: &cdm_model::formation::Member| m.link.map(|l| l.in_neighbors);
        if ins(x) != ins(y) {
            return Err(format!(
                "agent {} reads {:?}, in the run {:?} (another graph)",
                y.id,
                ins(y),
                ins(x)
            ));
        }
    }
    if run.file.comm_hz != other.file.comm_hz {
        return Err(format!(
            "comm_hz {}, the run's {}",
            other.file.comm_hz, run.file.comm_hz
        ));
    }
    Ok(())
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

pub(crate) fn same_dir(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// Compare the replay's telemetry and audit with the run's and say so; the first difference,
/// if any.
pub fn compare(
    run: &Path,
    replay: &Path,
    format: TelemetryFormat,
    quiet: bool,
) -> Result<Option<String>, Failure> {
    let name = format.file_name();
    let open = |dir: &Path| {
        let p = dir.join(name);
        let f = std::fs::File::open(&p)
            .map_err(|e| Failure::bad_input(format!("{}: {e}", p.display())))?;
        let bytes = f.metadata().map_or(0, |m| m.len());
        Ok::<_, Failure>((std::io::BufReader::new(f), bytes))
    };
    let ((a, a_bytes), (b, b_bytes)) = (open(run)?, open(replay)?);
    let first = first_line_difference(a, b)
        .map_err(|e| Failure::bad_input(format!("{}: {e}", run.join(name).display())))?;
    let telemetry = match (format, first) {
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
            None => out!("  {name}: identical to the run's ({b_bytes} bytes)"),
            Some(why) => out!("  {why} ({b_bytes} bytes, the run's {a_bytes})"),
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
