//! fig_formation (the paper's Figs. 2 and 7): the team at the first and the last tick projected
//! on the primary leaders' plane, and a 3-D view, with the communication graph's edges
//! (in-neighbour to follower, eq. 18) and the leaders marked.

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use cdm_math::{Real, Vec3};
use cdm_model::formation::Role;

use super::data::RunData;
use super::plot::{e, DrawError, Figure, FAMILY, GREY, PALETTE};

/// Drawn data: members' roles, edges as member-index pairs, positions at both ends.
pub struct FormationFigure {
    roles: Vec<Role>,
    edges: Vec<(usize, usize)>,
    polygon: Vec<usize>,
    first: Vec<Vec3>,
    last: Vec<Vec3>,
    t_first_s: Real,
    t_last_s: Real,
    primary_paths: [Vec<Vec3>; 3],
}

impl FormationFigure {
    pub fn new(d: &RunData) -> Self {
        let members = &d.scenario.formation.members;
        let index = |id: u32| members.iter().position(|m| m.id == id);
        let mut edges = Vec::new();
        for (k, m) in members.iter().enumerate() {
            if let Some(l) = m.link {
                for j in l.in_neighbors {
                    if let Some(jk) = index(j) {
                        edges.push((jk, k));
                    }
                }
            }
        }
        FormationFigure {
            roles: members.iter().map(|m| m.role).collect(),
            edges,
            polygon: d.scenario.formation.polygon.clone(),
            first: d.first.clone(),
            last: d.last.clone(),
            t_first_s: d.samples.first().map_or(0.0, |s| s.t_s),
            t_last_s: d.samples.last().map_or(0.0, |s| s.t_s),
            primary_paths: d.primary_paths.clone(),
        }
    }
}

/// In-plane coordinates on the primary leaders' plane (eq. 12): origin at leader 1,
/// first axis towards leader 2, second axis in the plane, normal by the right-hand rule.
fn project(pos: &[Vec3]) -> Vec<(Real, Real)> {
    if pos.len() < 3 {
        return pos.iter().map(|p| (p.x, p.y)).collect();
    }
    let o = pos[0];
    let e1 = (pos[1] - o).normalize();
    let n = (pos[1] - o).cross(&(pos[2] - o)).normalize();
    let e2 = n.cross(&e1);
    pos.iter()
        .map(|p| ((p - o).dot(&e1), (p - o).dot(&e2)))
        .collect()
}

fn style_of(role: Role) -> (RGBColor, u32) {
    match role {
        Role::Primary => (PALETTE[3], 7),
        Role::Secondary => (PALETTE[1], 6),
        Role::Follower => (PALETTE[0], 4),
    }
}

const ROLE_NAMES: [(Role, &str); 3] = [
    (Role::Primary, "primary leader"),
    (Role::Secondary, "secondary leader"),
    (Role::Follower, "follower"),
];

impl FormationFigure {
    fn planar<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        pos: &[Vec3],
        title: &str,
        legend: bool,
    ) -> Result<(), DrawError> {
        let p = project(pos);
        let Some((xs, ys)) = square_view(&p) else {
            return Ok(());
        };
        let mut chart = ChartBuilder::on(area)
            .caption(title, (FAMILY, 18))
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(xs, ys)
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("in-plane x (m, leader 1 → 2)")
            .y_desc("in-plane y (m)")
            .label_style((FAMILY, 13))
            .axis_desc_style((FAMILY, 15))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(e)?;
        let edge_style = GREY.mix(0.6).stroke_width(1);
        let series = chart
            .draw_series(
                self.edges
                    .iter()
                    .map(|&(a, b)| PathElement::new(vec![p[a], p[b]], edge_style)),
            )
            .map_err(e)?;
        if legend {
            series
                .label("graph edge (in-neighbour → follower)")
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], edge_style));
        }
        let mut poly: Vec<(Real, Real)> = self.polygon.iter().map(|&k| p[k]).collect();
        if let Some(&f) = poly.first() {
            poly.push(f);
        }
        let series = chart
            .draw_series(DashedLineSeries::new(
                poly,
                6,
                4,
                PALETTE[3].mix(0.7).stroke_width(1),
            ))
            .map_err(e)?;
        if legend {
            series.label("leading polygon").legend(|(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], PALETTE[3].stroke_width(1))
            });
        }
        self.role_dots(&mut chart, &p, legend)?;
        if legend {
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::LowerLeft)
                .label_font((FAMILY, 12))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(e)?;
        }
        Ok(())
    }

    /// One dot per member at its in-plane position `p`, styled by role (with a legend entry
    /// per role when `legend`).
    fn role_dots<DB: DrawingBackend>(
        &self,
        chart: &mut ChartContext<'_, DB, Plane>,
        p: &[(Real, Real)],
        legend: bool,
    ) -> Result<(), DrawError> {
        for (role, name) in ROLE_NAMES {
            let (color, size) = style_of(role);
            let pts: Vec<(Real, Real)> = p
                .iter()
                .zip(&self.roles)
                .filter(|(_, r)| **r == role)
                .map(|(q, _)| *q)
                .collect();
            if pts.is_empty() {
                continue;
            }
            let series = chart
                .draw_series(
                    pts.iter()
                        .map(|&q| Circle::new(q, size, color.filled()).into_dyn()),
                )
                .map_err(e)?;
            if legend {
                series
                    .label(name)
                    .legend(move |(x, y)| Circle::new((x + 10, y), size, color.filled()));
            }
        }
        Ok(())
    }

    fn view3d<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<(), DrawError> {
        let all = self
            .first
            .iter()
            .chain(&self.last)
            .chain(self.primary_paths.iter().flatten());
        let mut lo = Vec3::repeat(Real::INFINITY);
        let mut hi = Vec3::repeat(Real::NEG_INFINITY);
        for p in all {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        if !lo.x.is_finite() {
            return Ok(());
        }
        let pad = (hi - lo).amax().max(1.0) * 0.05;
        // plotters' y axis is the vertical one: draw (x, z, y) so altitude z is up.
        let mut chart = ChartBuilder::on(area)
            .caption("3-D view: start, end, leaders' paths", (FAMILY, 18))
            .margin(16)
            .build_cartesian_3d(
                (lo.x - pad)..(hi.x + pad),
                (lo.z - pad)..(hi.z + pad),
                (lo.y - pad)..(hi.y + pad),
            )
            .map_err(e)?;
        chart.with_projection(|mut pb| {
            pb.yaw = 0.6;
            pb.pitch = 0.35;
            pb.scale = 0.78;
            pb.into_matrix()
        });
        chart
            .configure_axes()
            .label_style((FAMILY, 12))
            .max_light_lines(0)
            .draw()
            .map_err(e)?;
        let to3 = |p: &Vec3| (p.x, p.z, p.y);
        let desc = (FAMILY, 15).into_font().color(&BLACK);
        chart
            .draw_series([
                Text::new("x (m)", (hi.x + pad, lo.z - pad, lo.y - pad), desc.clone()),
                Text::new("z (m)", (lo.x - pad, hi.z + pad, lo.y - pad), desc.clone()),
                Text::new("y (m)", (lo.x - pad, lo.z - pad, hi.y + pad), desc),
            ])
            .map_err(e)?;
        for (k, path) in self.primary_paths.iter().enumerate() {
            let s = chart
                .draw_series(LineSeries::new(
                    path.iter().map(to3),
                    PALETTE[3].mix(0.6).stroke_width(1),
                ))
                .map_err(e)?;
            if k == 0 {
                s.label("primary leaders' paths").legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], PALETTE[3].stroke_width(1))
                });
            }
        }
        for pos in [&self.first, &self.last] {
            self.team_3d(&mut chart, pos)?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font((FAMILY, 12))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(e)
    }
}

impl FormationFigure {
    /// The team at `pos` in the 3-D view: its graph's edges, then a dot per member by role.
    fn team_3d<DB: DrawingBackend>(
        &self,
        chart: &mut ChartContext<'_, DB, Space>,
        pos: &[Vec3],
    ) -> Result<(), DrawError> {
        let to3 = |p: &Vec3| (p.x, p.z, p.y);
        let edge_style = GREY.mix(0.5).stroke_width(1);
        chart
            .draw_series(
                self.edges
                    .iter()
                    .map(|&(a, b)| PathElement::new(vec![to3(&pos[a]), to3(&pos[b])], edge_style)),
            )
            .map_err(e)?;
        for role in [Role::Follower, Role::Secondary, Role::Primary] {
            let (color, size) = style_of(role);
            chart
                .draw_series(
                    pos.iter()
                        .zip(&self.roles)
                        .filter(|(_, r)| **r == role)
                        .map(|(q, _)| {
                            Circle::new(to3(q), size.saturating_sub(2).max(2), color.filled())
                        }),
                )
                .map_err(e)?;
        }
        Ok(())
    }
}

/// The planar chart's coordinates (metres on the leaders' plane).
type Plane = Cartesian2d<RangedCoordf64, RangedCoordf64>;
/// The 3-D chart's coordinates (x, z, y: altitude up).
type Space = plotters::coord::ranged3d::Cartesian3d<RangedCoordf64, RangedCoordf64, RangedCoordf64>;

/// A square window around the points `p` (equal scales on both axes, with a margin); `None`
/// when there is no finite point.
fn square_view(p: &[(Real, Real)]) -> Option<(std::ops::Range<Real>, std::ops::Range<Real>)> {
    let (mut x0, mut x1, mut y0, mut y1) = (
        Real::INFINITY,
        Real::NEG_INFINITY,
        Real::INFINITY,
        Real::NEG_INFINITY,
    );
    for &(x, y) in p {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if !x0.is_finite() {
        return None;
    }
    let span = (x1 - x0).max(y1 - y0).max(1.0) * 1.12;
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    Some((
        (cx - span / 2.0)..(cx + span / 2.0),
        (cy - span / 2.0)..(cy + span / 2.0),
    ))
}

impl Figure for FormationFigure {
    fn size(&self) -> (u32, u32) {
        (1560, 540)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError> {
        let areas = root.split_evenly((1, 3));
        self.planar(
            &areas[0],
            &self.first,
            &format!(
                "t = {:.2} s, on the leaders' plane (Fig. 7)",
                self.t_first_s
            ),
            true,
        )?;
        self.planar(
            &areas[1],
            &self.last,
            &format!("t = {:.2} s, on the leaders' plane", self.t_last_s),
            false,
        )?;
        self.view3d(&areas[2])
    }
}
