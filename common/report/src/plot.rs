//! Drawing: every figure goes to SVG and PNG through the same code (plotters, one generic
//! `draw` per figure). Text uses the committed DejaVu Sans through plotters' pure-Rust
//! `ab_glyph` renderer, so no system font library is needed.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;

use cdm_math::Real;
use cdm_records::rundir::write_atomic;

/// DejaVu Sans (assets/DejaVuSans-LICENSE.txt: Bitstream Vera license, redistributable).
const FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

pub const FAMILY: &str = "sans-serif";

/// Colours of the series, in order.
pub const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];
pub const LIMIT: RGBColor = RGBColor(200, 0, 0);
pub const GREY: RGBColor = RGBColor(150, 150, 150);

/// A drawing failure. plotters' errors are generic over the backend (SVG, bitmap), so one type
/// carries any of them, as its message.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct DrawError(String);

/// Any backend's drawing failure as a [`DrawError`].
pub fn e(x: impl std::fmt::Display) -> DrawError {
    DrawError(x.to_string())
}

/// Why a figure could not be made (each variant names the file).
#[derive(Debug, thiserror::Error)]
pub enum FigureError {
    /// The embedded font could not be registered with plotters.
    #[error("the embedded font DejaVuSans.ttf could not be loaded")]
    Font,
    /// Drawing failed.
    #[error("{}: {detail}", file.display())]
    Draw {
        file: PathBuf,
        #[source]
        detail: DrawError,
    },
    /// The PNG encoder refused the image.
    #[error("{}: {source}", file.display())]
    Png {
        file: PathBuf,
        #[source]
        source: png::EncodingError,
    },
    /// Writing the file failed (names the file).
    #[error(transparent)]
    Write(#[from] cdm_records::rundir::RunDirError),
}

/// Register the font once per process.
pub fn ensure_font() -> Result<(), FigureError> {
    static OK: OnceLock<bool> = OnceLock::new();
    let ok =
        *OK.get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok {
        Ok(())
    } else {
        Err(FigureError::Font)
    }
}

/// A figure that can draw itself on any plotters backend.
pub trait Figure {
    /// Pixel size of the PNG (and the SVG's view box).
    fn size(&self) -> (u32, u32);
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError>;
}

/// Write `<stem>.svg` and `<stem>.png` into `dir`; returns both paths. Both are drawn in memory
/// and written atomically (`write_atomic`: never through a link, never half a file, the old
/// figure kept when the disk is full).
pub fn write_figure<F: Figure>(
    dir: &Path,
    stem: &str,
    fig: &F,
) -> Result<Vec<PathBuf>, FigureError> {
    ensure_font()?;
    let svg = dir.join(format!("{stem}.svg"));
    let png = dir.join(format!("{stem}.png"));
    let named = |p: &Path, detail: DrawError| FigureError::Draw {
        file: p.to_path_buf(),
        detail,
    };
    let (w, h) = fig.size();
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|x| named(&svg, e(x)))?;
        fig.draw(&root).map_err(|x| named(&svg, x))?;
        root.present().map_err(|x| named(&svg, e(x)))?;
    }
    write_atomic(&svg, text.as_bytes())?;
    let mut rgb = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|x| named(&png, e(x)))?;
        fig.draw(&root).map_err(|x| named(&png, x))?;
        root.present().map_err(|x| named(&png, e(x)))?;
    }
    let bytes = encode_png(&rgb, w, h).map_err(|source| FigureError::Png {
        file: png.clone(),
        source,
    })?;
    write_atomic(&png, &bytes)?;
    Ok(vec![svg, png])
}

/// An RGB8 image as PNG bytes.
fn encode_png(rgb: &[u8], w: u32, h: u32) -> Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::with_capacity(rgb.len() / 4);
    let mut enc = png::Encoder::new(&mut out, w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()?;
    Ok(out)
}

/// A line of a 2-D chart.
pub struct Line {
    pub label: String,
    pub points: Vec<(Real, Real)>,
    pub color: RGBColor,
    pub dashed: bool,
}

/// A horizontal or vertical reference line (a limit).
pub struct Rule {
    pub label: String,
    pub at: Real,
    pub vertical: bool,
    pub color: RGBColor,
}

/// One 2-D panel: title, axis descriptions with units, lines and limits.
pub struct Panel {
    pub title: String,
    pub x_desc: String,
    pub y_desc: String,
    pub lines: Vec<Line>,
    pub rules: Vec<Rule>,
    pub log_y: bool,
    pub legend: SeriesLabelPosition,
}

/// The axis range covering lines and rules, padded by 5 %.
fn range(values: impl Iterator<Item = Real>, log: bool) -> (Real, Real) {
    let (mut lo, mut hi) = (Real::INFINITY, Real::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite() && (!log || *v > 0.0)) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if log {
        return (lo / 1.5, hi * 1.5);
    }
    let pad = ((hi - lo) * 0.05).max(1e-6 * hi.abs().max(1.0));
    (lo - pad, hi + pad)
}

impl Panel {
    fn x_range(&self) -> (Real, Real) {
        let xs = self.lines.iter().flat_map(|l| l.points.iter().map(|p| p.0));
        let rs = self.rules.iter().filter(|r| r.vertical).map(|r| r.at);
        let (lo, hi) = range(xs.chain(rs), false);
        // Time axes start where the data starts: no padding on the left of t = 0.
        (lo, hi)
    }

    fn y_range(&self) -> (Real, Real) {
        let ys = self.lines.iter().flat_map(|l| l.points.iter().map(|p| p.1));
        let rs = self.rules.iter().filter(|r| !r.vertical).map(|r| r.at);
        range(ys.chain(rs), self.log_y)
    }

    /// Draw the panel on an area.
    pub fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<(), DrawError> {
        let (x0, x1) = self.x_range();
        let (y0, y1) = self.y_range();
        let mut builder = ChartBuilder::on(area);
        builder
            .caption(&self.title, (FAMILY, 20))
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(78);
        // The same axes for a linear and a logarithmic y (two coordinate types in plotters).
        macro_rules! axes_then_series {
            ($chart:expr) => {{
                let mut chart = $chart.map_err(e)?;
                chart
                    .configure_mesh()
                    .x_desc(&self.x_desc)
                    .y_desc(&self.y_desc)
                    .label_style((FAMILY, 14))
                    .axis_desc_style((FAMILY, 16))
                    .light_line_style(WHITE.mix(0.0))
                    .draw()
                    .map_err(e)?;
                self.series(&mut chart, x0..x1, y0..y1)
            }};
        }
        if self.log_y {
            axes_then_series!(builder.build_cartesian_2d(x0..x1, (y0..y1).log_scale()))
        } else {
            axes_then_series!(builder.build_cartesian_2d(x0..x1, y0..y1))
        }
    }

    fn series<'a, DB, X, Y>(
        &self,
        chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
        x: std::ops::Range<Real>,
        y: std::ops::Range<Real>,
    ) -> Result<(), DrawError>
    where
        DB: DrawingBackend + 'a,
        X: Ranged<ValueType = Real>,
        Y: Ranged<ValueType = Real>,
    {
        for l in &self.lines {
            let style = l.color.stroke_width(2);
            let pts: Vec<(Real, Real)> = l
                .points
                .iter()
                .copied()
                .filter(|p| p.0.is_finite() && p.1.is_finite() && (!self.log_y || p.1 > 0.0))
                .collect();
            let color = l.color;
            if l.dashed {
                chart
                    .draw_series(DashedLineSeries::new(pts, 8, 5, style))
                    .map_err(e)?
                    .label(&l.label)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 10, y)], color.stroke_width(2))
                    });
            } else {
                chart
                    .draw_series(LineSeries::new(pts, style))
                    .map_err(e)?
                    .label(&l.label)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                    });
            }
        }
        for r in &self.rules {
            let pts = if r.vertical {
                vec![(r.at, y.start), (r.at, y.end)]
            } else {
                vec![(x.start, r.at), (x.end, r.at)]
            };
            let color = r.color;
            chart
                .draw_series(DashedLineSeries::new(pts, 6, 6, color.stroke_width(2)))
                .map_err(e)?
                .label(&r.label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 6, y)], color.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .position(self.legend.clone())
            .label_font((FAMILY, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(e)
    }
}

/// Stacked panels (one above the other) as one figure.
pub struct Stack {
    pub width: u32,
    pub panel_height: u32,
    pub panels: Vec<Panel>,
}

impl Figure for Stack {
    fn size(&self) -> (u32, u32) {
        (self.width, self.panel_height * self.panels.len() as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError> {
        let areas = root.split_evenly((self.panels.len(), 1));
        for (p, a) in self.panels.iter().zip(&areas) {
            p.draw(a)?;
        }
        Ok(())
    }
}

/// Keep at most about `max` points: every k-th sample plus the last.
pub fn thin<T: Copy>(v: &[T], max: usize) -> Vec<T> {
    let k = v.len().div_ceil(max.max(1)).max(1);
    let mut out: Vec<T> = v.iter().step_by(k).copied().collect();
    if let Some(&l) = v.last() {
        if !(v.len() - 1).is_multiple_of(k) {
            out.push(l);
        }
    }
    out
}

/// Keep at most about `max` points, each the minimum (in y) of its bucket, so that minima
/// (the quantity a safety figure is about) survive decimation.
pub fn thin_min(v: &[(Real, Real)], max: usize) -> Vec<(Real, Real)> {
    let k = v.len().div_ceil(max.max(1)).max(1);
    v.chunks(k)
        .filter_map(|c| c.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1)))
        .collect()
}
