//! Two runs side by side (`report RUN_DIR --against OTHER`): the largest deviation from the
//! desired positions against delta (eq. 38), the smallest separation against 2 eps and the
//! smallest containment margin over time, one line per run: a run and its "what if" replay.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use plotters::prelude::SeriesLabelPosition;

use cdm_math::Real;

use crate::data::{read_run, RunData, TickSample};
use crate::plot::{thin_min, write_figure, Line, Panel, Rule, Stack, GREY, LIMIT, PALETTE};
use crate::{csv, ReportError, MAX_POINTS};

/// Draw fig_compare (SVG, PNG and its CSV) into `dir`: `dir`'s run against `other`'s, each
/// named by its directory in the legend and in the CSV's `run` column.
pub fn compare(dir: &Path, other: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let [a, b] = names(dir, other);
    let runs = [(a, read_run(dir, None)?), (b, read_run(other, None)?)];
    let mut text =
        String::from("run,tick,t,max_deviation_m,min_separation_m,min_boundary_distance_m\n");
    for (label, d) in &runs {
        let label = csv_field(label);
        for s in &d.samples {
            let _ = writeln!(
                text,
                "{label},{},{},{},{},{}",
                s.tick, s.t_s, s.max_deviation_m, s.min_separation_m, s.min_boundary_m
            );
        }
    }
    let mut files = vec![csv(dir, "fig_compare.csv", &text)?];
    let a = &runs[0].1;
    let panel =
        |title: &str, y: &str, pick: fn(&TickSample) -> Real, rule: Rule, min: bool| Panel {
            title: title.into(),
            x_desc: "t (s)".into(),
            y_desc: y.into(),
            lines: (runs.iter().enumerate())
                .map(|(k, (label, d))| line(label, d, pick, k, min))
                .collect(),
            rules: vec![rule],
            log_y: false,
            legend: SeriesLabelPosition::UpperRight,
        };
    let fig = Stack {
        width: 900,
        panel_height: 360,
        panels: vec![
            panel(
                "Largest deviation from the desired positions",
                "||r_i - r_i,HT|| (m)",
                |s| s.max_deviation_m,
                limit(format!("delta = {:.4} m", a.audit.delta_m), a.audit.delta_m),
                false,
            ),
            panel(
                "Smallest separation D_B(t)",
                "distance (m)",
                |s| s.min_separation_m,
                limit(
                    format!("2 eps = {} m", 2.0 * a.audit.eps_m),
                    2.0 * a.audit.eps_m,
                ),
                true,
            ),
            panel(
                "Smallest containment margin D_S(t)",
                "distance (m)",
                |s| s.min_boundary_m,
                Rule {
                    label: "0 m (containment)".into(),
                    at: 0.0,
                    vertical: false,
                    color: GREY,
                },
                true,
            ),
        ],
    };
    files.extend(write_figure(dir, "fig_compare", &fig)?);
    Ok(files)
}

/// The two runs' names: their directories' names, or their paths when those are the same.
fn names(dir: &Path, other: &Path) -> [String; 2] {
    let name = |d: &Path| {
        d.file_name()
            .map_or_else(|| d.display().to_string(), |n| n.to_string_lossy().into())
    };
    let (a, b) = (name(dir), name(other));
    if a == b {
        return [dir.display().to_string(), other.display().to_string()];
    }
    [a, b]
}

/// A CSV field: quoted (its quotes doubled) when it holds a comma, a quote or a line break.
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

fn limit(label: String, at: Real) -> Rule {
    Rule {
        label,
        at,
        vertical: false,
        color: LIMIT,
    }
}

/// One run's line, thinned keeping each stretch's extreme: the minimum of a smallest-value
/// series, the maximum of a largest-value one.
fn line(label: &str, d: &RunData, pick: fn(&TickSample) -> Real, k: usize, min: bool) -> Line {
    let sign = if min { 1.0 } else { -1.0 };
    let signed: Vec<(Real, Real)> = (d.samples.iter())
        .map(|s| (s.t_s, sign * pick(s)))
        .collect();
    let points = (thin_min(&signed, MAX_POINTS).into_iter())
        .map(|(t, v)| (t, sign * v))
        .collect();
    Line {
        label: label.into(),
        points,
        color: PALETTE[k],
        dashed: k == 1,
    }
}
