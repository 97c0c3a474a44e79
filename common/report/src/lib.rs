//! `orchestrator report RUN_DIR`: the paper's figures for one run, redrawn from the run
//! directory alone (telemetry.csv, audit.json, scenario.toml), as SVG and PNG, with the data of
//! the safety figures beside them as CSV.

mod compare;
pub mod data;
mod formation;
mod plot;
mod top_view;
mod transient;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use plotters::prelude::SeriesLabelPosition;

use cdm_math::Real;
use cdm_records::rundir::write_atomic;

pub use compare::compare;
pub use data::{read_run, ReadError, RunData};
pub use plot::FigureError;
use plot::{thin, thin_min, write_figure, Line, Panel, Rule, Stack, GREY, LIMIT, PALETTE};

/// An accepted command's line (a refused one is drawn in [`LIMIT`]'s red).
const ACCEPTED: plotters::style::RGBColor = plotters::style::RGBColor(0, 150, 60);
pub use top_view::{top_view, TopPath};

/// Points per plotted line (decimation keeps files small and drawing fast).
pub(crate) const MAX_POINTS: usize = 1500;

/// Why a report could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file of the run directory is missing or malformed (names the file).
    #[error(transparent)]
    Read(#[from] ReadError),
    /// Drawing or writing a figure failed (names the file).
    #[error(transparent)]
    Draw(#[from] FigureError),
}

/// Draw every figure of a run directory; returns the files written.
pub fn report(dir: &Path, follow: Option<u32>) -> Result<Vec<PathBuf>, ReportError> {
    let d = read_run(dir, follow)?;
    Ok(draw_all(dir, &d)?)
}

fn draw_all(dir: &Path, d: &RunData) -> Result<Vec<PathBuf>, FigureError> {
    let mut files = Vec::new();
    files.extend(eigenvalues(dir, d)?);
    files.extend(agent(dir, d)?);
    files.extend(separation(dir, d)?);
    files.extend(transient::loss_transient(dir, d)?);
    files.extend(write_figure(
        dir,
        "fig_formation",
        &formation::FormationFigure::new(d),
    )?);
    Ok(files)
}

/// A vertical line at the first violation, if the run had one.
fn first_violation(d: &RunData, scale: Real) -> Option<Rule> {
    d.audit.first_violation.map(|(kind, t)| Rule {
        label: format!("first violation: {kind}, t = {t:.2} s"),
        at: t / scale,
        vertical: true,
        color: PALETTE[4],
    })
}

/// A mission's phase boundaries: a vertical line where each phase after the first
/// starts, named; none for the paper's one manoeuvre.
fn phase_marks(d: &RunData, scale: Real) -> Vec<Rule> {
    let plan = &d.scenario.plan;
    if !plan.is_mission() {
        return Vec::new();
    }
    (plan.phases().iter().skip(1))
        .map(|p| Rule {
            label: format!("{} from t = {} s", p.kind.name(), p.t_start_s),
            at: p.t_start_s / scale,
            vertical: true,
            color: GREY,
        })
        .collect()
}

/// The switch of every command the run was given (`commands.json`): a green line for an
/// accepted one, a red one for a refused one (its motion never flown: the team went on as
/// before), named with the command and the time.
fn command_marks(d: &RunData, scale: Real) -> Vec<Rule> {
    let dt = d.scenario.dt_s();
    (d.commands.iter())
        .map(|c| {
            let t = cdm_model::step::tick_time(c.switch_tick, dt);
            let what = if c.accepted { "accepted" } else { "refused" };
            Rule {
                label: format!("{} {what}, t = {t:.2} s", c.command),
                at: t / scale,
                vertical: true,
                color: if c.accepted { ACCEPTED } else { LIMIT },
            }
        })
        .collect()
}

pub(crate) fn csv(dir: &Path, name: &str, text: &str) -> Result<PathBuf, FigureError> {
    let p = dir.join(name);
    write_atomic(&p, text.as_bytes())?;
    Ok(p)
}

/// Fig. 8: the eigenvalues of U_D versus t / T_total, with lambda_CD,min (eq. 37).
fn eigenvalues(dir: &Path, d: &RunData) -> Result<Vec<PathBuf>, FigureError> {
    let t_total = d.audit.t_total_s;
    let mut text = String::from("tick,t,t_over_t_total,lambda1,lambda2,lambda3\n");
    for s in &d.samples {
        let _ = writeln!(
            text,
            "{},{},{},{},{},{}",
            s.tick,
            s.t_s,
            s.t_s / t_total,
            s.lambdas[0],
            s.lambdas[1],
            s.lambdas[2]
        );
    }
    let mut files = vec![csv(dir, "fig_eigenvalues.csv", &text)?];
    let names = ["λ1 (smallest)", "λ2", "λ3 (normal, = 1)"];
    let lines = (0..3)
        .map(|k| Line {
            label: names[k].into(),
            points: thin(
                &d.samples
                    .iter()
                    .map(|s| (s.t_s / t_total, s.lambdas[k]))
                    .collect::<Vec<_>>(),
                MAX_POINTS,
            ),
            color: PALETTE[k],
            dashed: false,
        })
        .collect();
    let fig = Stack {
        width: 900,
        panel_height: 520,
        panels: vec![Panel {
            title: format!(
                "Eigenvalues of U_D (Fig. 8): min λ1 = {:.4}",
                d.audit.lambda1_min_run
            ),
            x_desc: "t / T_total (T_total = ".to_string() + &format!("{t_total} s)"),
            y_desc: "eigenvalue of U_D (dimensionless)".into(),
            lines,
            rules: std::iter::once(Rule {
                label: format!("λ_CD,min = {:.4}", d.audit.lambda_cd_min),
                at: d.audit.lambda_cd_min,
                vertical: false,
                color: LIMIT,
            })
            .chain(first_violation(d, t_total))
            .chain(phase_marks(d, t_total))
            .chain(command_marks(d, t_total))
            .collect(),
            log_y: false,
            legend: SeriesLabelPosition::MiddleLeft,
        }],
    };
    files.extend(write_figure(dir, "fig_eigenvalues", &fig)?);
    Ok(files)
}

/// Fig. 9: x, y, z of one follower versus time, actual against desired (r_HT, eq. 13).
fn agent(dir: &Path, d: &RunData) -> Result<Vec<PathBuf>, FigureError> {
    let axes = ["x", "y", "z"];
    let panels = (0..3)
        .map(|k| {
            let actual: Vec<(Real, Real)> =
                d.samples.iter().map(|s| (s.t_s, s.follow_r[k])).collect();
            let desired: Vec<(Real, Real)> =
                d.samples.iter().map(|s| (s.t_s, s.follow_ht[k])).collect();
            // The legend goes where the curve is not: below a rising one, above a falling one.
            let rising = match (actual.first(), actual.last()) {
                (Some(a), Some(b)) => b.1 > a.1,
                _ => false,
            };
            Panel {
                title: format!("agent {}: {} (Fig. 9)", d.follow, axes[k]),
                x_desc: "t (s)".into(),
                y_desc: format!("{} (m)", axes[k]),
                lines: vec![
                    Line {
                        label: format!("{} actual", axes[k]),
                        points: thin(&actual, MAX_POINTS),
                        color: PALETTE[0],
                        dashed: false,
                    },
                    Line {
                        label: format!("{} desired (r_HT)", axes[k]),
                        points: thin(&desired, MAX_POINTS),
                        color: PALETTE[1],
                        dashed: true,
                    },
                ],
                rules: phase_marks(d, 1.0)
                    .into_iter()
                    .chain(command_marks(d, 1.0))
                    .collect(),
                log_y: false,
                legend: if rising {
                    SeriesLabelPosition::LowerRight
                } else {
                    SeriesLabelPosition::UpperRight
                },
            }
        })
        .collect();
    let fig = Stack {
        width: 900,
        panel_height: 300,
        panels,
    };
    write_figure(dir, &format!("fig_agent_{}", d.follow), &fig)
}

/// Fig. 11: the smallest separation D_B(t) against 2 eps and the smallest distance of a
/// follower to the containment prism's sides D_S(t) against 0 (Theorem 3).
fn separation(dir: &Path, d: &RunData) -> Result<Vec<PathBuf>, FigureError> {
    let mut text = String::from("tick,t,min_separation_m,min_boundary_distance_m\n");
    for s in &d.samples {
        let _ = writeln!(
            text,
            "{},{},{},{}",
            s.tick, s.t_s, s.min_separation_m, s.min_boundary_m
        );
    }
    let mut files = vec![csv(dir, "fig_separation.csv", &text)?];
    let db: Vec<(Real, Real)> = d
        .samples
        .iter()
        .map(|s| (s.t_s, s.min_separation_m))
        .collect();
    let ds: Vec<(Real, Real)> = d
        .samples
        .iter()
        .map(|s| (s.t_s, s.min_boundary_m))
        .collect();
    let fig = Stack {
        width: 900,
        panel_height: 520,
        panels: vec![Panel {
            title: "Separation and containment (Fig. 11)".into(),
            x_desc: "t (s)".into(),
            y_desc: "distance (m)".into(),
            lines: vec![
                Line {
                    label: "D_B(t): smallest distance between two agents".into(),
                    points: thin_min(&db, MAX_POINTS),
                    color: PALETTE[0],
                    dashed: false,
                },
                Line {
                    label: "D_S(t): smallest follower distance to prism sides".into(),
                    points: thin_min(&ds, MAX_POINTS),
                    color: PALETTE[2],
                    dashed: false,
                },
            ],
            rules: vec![
                Rule {
                    label: format!("2 eps = {} m (collision)", 2.0 * d.audit.eps_m),
                    at: 2.0 * d.audit.eps_m,
                    vertical: false,
                    color: LIMIT,
                },
                Rule {
                    label: "0 m (containment)".into(),
                    at: 0.0,
                    vertical: false,
                    color: GREY,
                },
            ]
            .into_iter()
            .chain(first_violation(d, 1.0))
            .chain(phase_marks(d, 1.0))
            .chain(command_marks(d, 1.0))
            .collect(),
            log_y: false,
            legend: SeriesLabelPosition::UpperRight,
        }],
    };
    files.extend(write_figure(dir, "fig_separation", &fig)?);
    Ok(files)
}

/// Fig. 10: the largest follower deviation versus the travel time, with delta (eq. 38) and
/// T_threshold. `points` are (T_total, E_max) pairs; infinite E (a faulted flight) is skipped.
pub fn deviation_sweep(
    dir: &Path,
    points: &[(Real, Real)],
    delta_m: Real,
    t_threshold_s: Real,
) -> Result<Vec<PathBuf>, FigureError> {
    let sweep = Sweep {
        stem: "fig_deviation_sweep",
        x_column: "t_total_s",
        title: "Largest follower deviation versus travel time (Fig. 10)",
        x_desc: "T_total (s)",
        marker: t_threshold_s
            .is_finite()
            .then(|| (format!("T_threshold = {t_threshold_s:.2} s"), t_threshold_s)),
    };
    sweep_figure(dir, &sweep, points, delta_m)
}

/// Fig. 10's twin for link delay: E_max versus the delay of every state, with delta
/// and the certificate's largest safe delay. `points` are (delay ms, E_max) pairs.
pub fn delay_sweep(
    dir: &Path,
    points: &[(Real, Real)],
    delta_m: Real,
    max_link_delay_ms: Option<Real>,
) -> Result<Vec<PathBuf>, FigureError> {
    let sweep = Sweep {
        stem: "fig_delay_sweep",
        x_column: "link_delay_ms",
        title: "Largest follower deviation versus link delay (in the style of Fig. 10)",
        x_desc: "link delay (ms, whole ticks)",
        marker: max_link_delay_ms.map(|ms| (format!("max link delay = {ms} ms"), ms)),
    };
    sweep_figure(dir, &sweep, points, delta_m)
}

/// What a Fig. 10-style sweep varies.
struct Sweep<'a> {
    /// File stem of the CSV and the figure.
    stem: &'a str,
    /// CSV header of the varied quantity.
    x_column: &'a str,
    title: &'a str,
    x_desc: &'a str,
    /// A vertical rule (label, x): the certified limit.
    marker: Option<(String, Real)>,
}

/// E_max against one varied quantity: `<stem>.csv` and the figure, with delta (eq. 38).
fn sweep_figure(
    dir: &Path,
    sweep: &Sweep,
    points: &[(Real, Real)],
    delta_m: Real,
) -> Result<Vec<PathBuf>, FigureError> {
    let mut text = format!("{},max_follower_deviation_m\n", sweep.x_column);
    for (t, e) in points {
        let _ = writeln!(text, "{t},{e}");
    }
    let mut files = vec![csv(dir, &format!("{}.csv", sweep.stem), &text)?];
    let mut rules = vec![Rule {
        label: format!("δ = {delta_m:.4} m (eq. 38)"),
        at: delta_m,
        vertical: false,
        color: LIMIT,
    }];
    if let Some((label, at)) = &sweep.marker {
        rules.push(Rule {
            label: label.clone(),
            at: *at,
            vertical: true,
            color: GREY,
        });
    }
    let fig = Stack {
        width: 900,
        panel_height: 520,
        panels: vec![Panel {
            title: sweep.title.into(),
            x_desc: sweep.x_desc.into(),
            y_desc: "E_max = max ||r - r_HT||_2 (m, log)".into(),
            lines: vec![Line {
                label: "E_max (simulated)".into(),
                points: points.to_vec(),
                color: PALETTE[0],
                dashed: false,
            }],
            rules,
            log_y: true,
            legend: SeriesLabelPosition::UpperRight,
        }],
    };
    files.extend(write_figure(dir, sweep.stem, &fig)?);
    Ok(files)
}
