//! The repair transients of a run that lost members: the deviation |r - r_HT|
//! (eq. 13) of every follower a loss made switch triangles or fly its plan. Theorem 1 keeps
//! each survivor's r_HT, so this deviation is all a repair changes; the figure shows it over the
//! whole flight and around the loss that disturbed it most.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use plotters::prelude::SeriesLabelPosition;

use cdm_math::Real;

use super::data::{RunData, Transient};
use super::plot::{thin, write_figure, FigureError, Line, Panel, Rule, Stack, GREY, PALETTE};
use super::{csv, MAX_POINTS};

/// Followers drawn (the largest transients); the CSV keeps them all.
const SHOWN: usize = 5;
/// Seconds shown before and after the worst loss in the zoomed panel.
const ZOOM_BEFORE_S: Real = 5.0;
const ZOOM_AFTER_S: Real = 30.0;

/// `fig_loss_transient.{csv,svg,png}` for a run with losses; nothing for a run without.
pub fn loss_transient(dir: &Path, d: &RunData) -> Result<Vec<PathBuf>, FigureError> {
    if d.audit.repairs.is_empty() {
        return Ok(Vec::new());
    }
    let mut text = String::from("id,t,deviation_m\n");
    for tr in &d.transients {
        for (t, dev) in &tr.points {
            let _ = writeln!(text, "{},{t},{dev}", tr.id);
        }
    }
    let mut files = vec![csv(dir, "fig_loss_transient.csv", &text)?];
    let ranked = largest_transients(d);
    let Some(&(worst_dev, worst)) = ranked.first() else {
        return Ok(files);
    };
    let t_worst = worst.from_s;
    let zoom = (t_worst - ZOOM_BEFORE_S, t_worst + ZOOM_AFTER_S);
    let fig = Stack {
        width: 900,
        panel_height: 360,
        panels: vec![
            panel(
                d,
                &ranked,
                format!(
                    "Repaired followers' deviation (eq. 13), delta = {:.3} m",
                    d.audit.delta_m
                ),
                None,
            ),
            panel(
                d,
                &ranked,
                format!(
                    "Around the worst repair: follower {} peaks at {worst_dev:.4} m",
                    worst.id
                ),
                Some(zoom),
            ),
        ],
    };
    files.extend(write_figure(dir, "fig_loss_transient", &fig)?);
    Ok(files)
}

/// The [`SHOWN`] largest transients, by their peak deviation after the repair (ties: by id).
fn largest_transients(d: &RunData) -> Vec<(Real, &Transient)> {
    let peak = |tr: &Transient| {
        tr.points
            .iter()
            .filter(|p| p.0 >= tr.from_s)
            .map(|p| p.1)
            .fold(0.0, Real::max)
    };
    let mut ranked: Vec<(Real, &Transient)> = d.transients.iter().map(|t| (peak(t), t)).collect();
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.id.cmp(&b.1.id)));
    ranked.truncate(SHOWN);
    ranked
}

/// One panel: the ranked followers' deviation, and a rule at each loss, within `window` (s).
fn panel(
    d: &RunData,
    ranked: &[(Real, &Transient)],
    title: String,
    window: Option<(Real, Real)>,
) -> Panel {
    let inside = |t: Real| window.is_none_or(|(a, b)| (a..=b).contains(&t));
    let lines = ranked
        .iter()
        .enumerate()
        .map(|(i, (dev, tr))| Line {
            label: format!("follower {}: peak {dev:.4} m after its repair", tr.id),
            points: thin(
                &tr.points
                    .iter()
                    .copied()
                    .filter(|p| inside(p.0))
                    .collect::<Vec<_>>(),
                MAX_POINTS,
            ),
            color: PALETTE[i % PALETTE.len()],
            dashed: false,
        })
        .collect();
    let dt = d.scenario.dt_s();
    let rules = d
        .audit
        .repairs
        .iter()
        .map(|r| (r.id, r.tick as Real * dt))
        .filter(|(_, t)| inside(*t))
        .map(|(id, t)| Rule {
            label: format!("loss of {id}, t = {t:.2} s"),
            at: t,
            vertical: true,
            color: GREY,
        })
        .collect();
    Panel {
        title,
        x_desc: "t (s)".into(),
        y_desc: "|r - r_HT| (m)".into(),
        lines,
        rules,
        log_y: false,
        legend: SeriesLabelPosition::UpperRight,
    }
}
