//! fig_export_top_view: an exported team seen from above in the target frame: every member's
//! path (r_HT, eq. 13), its start and its goal, on equal axes in metres, so the scale and the
//! spacing that the certificate judges can be seen.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use cdm_math::{Real, Vec3};

use super::plot::{e, write_figure, DrawError, Figure, FAMILY, GREY, PALETTE};

/// One member's path from above.
pub struct TopPath {
    pub leader: bool,
    pub points: Vec<Vec3>,
}

struct TopView {
    title: String,
    paths: Vec<TopPath>,
}

impl TopView {
    /// Centre and side of a square that holds every point, with a margin.
    fn square(&self) -> (Real, Real, Real) {
        let (mut x0, mut x1, mut y0, mut y1) = (
            Real::INFINITY,
            Real::NEG_INFINITY,
            Real::INFINITY,
            Real::NEG_INFINITY,
        );
        for p in self.paths.iter().flat_map(|p| p.points.iter()) {
            x0 = x0.min(p.x);
            x1 = x1.max(p.x);
            y0 = y0.min(p.y);
            y1 = y1.max(p.y);
        }
        if !x0.is_finite() {
            return (0.0, 0.0, 1.0);
        }
        let span = (x1 - x0).max(y1 - y0).max(1e-3) * 1.1;
        (0.5 * (x0 + x1), 0.5 * (y0 + y1), span)
    }
}

impl Figure for TopView {
    fn size(&self) -> (u32, u32) {
        (820, 820)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError> {
        let (cx, cy, span) = self.square();
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, (FAMILY, 18))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d(
                (cx - span / 2.0)..(cx + span / 2.0),
                (cy - span / 2.0)..(cy + span / 2.0),
            )
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("x (m)")
            .y_desc("y (m)")
            .label_style((FAMILY, 13))
            .axis_desc_style((FAMILY, 15))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(e)?;
        let xy = |p: &Vec3| (p.x, p.y);
        let path_style = GREY.mix(0.7).stroke_width(1);
        chart
            .draw_series(
                self.paths.iter().map(|p| {
                    PathElement::new(p.points.iter().map(xy).collect::<Vec<_>>(), path_style)
                }),
            )
            .map_err(e)?
            .label("path of r_HT (eq. 13)")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], path_style));
        let ends = [(PALETTE[0], "start", true), (PALETTE[3], "goal", false)];
        for (color, name, first) in ends {
            let pick = move |p: &TopPath| {
                let q = if first {
                    p.points.first()
                } else {
                    p.points.last()
                };
                q.map(|q| (xy(q), if p.leader { 6 } else { 4 }))
            };
            chart
                .draw_series(
                    self.paths
                        .iter()
                        .filter_map(pick)
                        .map(|(c, r)| Circle::new(c, r, color.filled())),
                )
                .map_err(e)?
                .label(format!("{name} (leaders larger)"))
                .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font((FAMILY, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(e)
    }
}

/// Draw `<stem>.svg` and `<stem>.png` into `dir`.
pub fn top_view(
    dir: &Path,
    stem: &str,
    title: &str,
    paths: Vec<TopPath>,
) -> Result<Vec<PathBuf>, super::FigureError> {
    write_figure(
        dir,
        stem,
        &TopView {
            title: title.to_string(),
            paths,
        },
    )
}
