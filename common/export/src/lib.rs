//! The plan and the runs in the formats other tools load, as functions that write files and
//! return what they wrote (the orchestrator prints it; the Python package returns it).
//!
//! [`export_plan`], `orchestrator export crazyswarm2|skybrush`: the plan in the formats real
//! fleets load, in the target frame (p -> S p + origin), with the certificate issued again at
//! that scale and the target vehicles' radius. A mission is exported whole, from the ground to
//! the ground: every phase's quintic and the hovers between them. Steps: load and scale, cut the
//! exact quintics into pieces (a plan the target cannot hold is an error), certify (UNSAFE: the
//! trajectory files are written only with `force`), write.
//!
//! [`export_bag`] (`rosbag2.rs`): a finished run as a ROS 2 bag. [`export_geojson`] and
//! [`export_qgc_plan`] (`map.rs`, `geojson_map.rs`, `qgc_plan.rs`): the airspace and the
//! leaders' paths on the Earth, for map tools and QGroundControl.

mod crazyswarm2;
mod error;
mod geojson_map;
mod map;
mod qgc_plan;
mod rosbag2;
mod skybrush;
mod source;

use std::path::{Path, PathBuf};

use serde::Serialize;

use cdm_certificates::certificate::Certificate;
use cdm_certificates::certify::certify;
use cdm_math::{Real, Vec3};
use cdm_model::formation::Role;
use cdm_model::outcome::Verdict;
use cdm_records::rundir::write_atomic;
use cdm_report::{top_view, TopPath};
use cdm_scenario::{Checks, Scenario};
use cdm_trajectory::{
    crazyflie_split, float32, pieces, team_trajectories, AgentTrajectory, Cut, TargetFrame,
    DEFAULT_TOLERANCE_M, SKYBRUSH_MAX_SEGMENT_S,
};

pub use error::ExportError;
pub use geojson_map::{export_geojson, GeoJsonExport};
pub use map::MapSource;
pub use qgc_plan::{export_qgc_plan, QgcPlanExport};
pub use rosbag2::{export_bag, BagExport};
pub use skybrush::ShowFrame;
pub use source::{load, ScenarioSource};

/// Where an exported plan flies: p -> scale p + origin, and the target vehicles' radius.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportFrame {
    /// Every position and goal times this (a mission's segment goals and ground heights too).
    pub scale: Real,
    /// Then plus this, "X,Y,Z" metres (none: 0,0,0).
    pub origin: Option<String>,
    /// The radius of the target vehicles' ball, metres.
    pub eps_m: Real,
    /// Write the trajectory files even when the certificate is UNSAFE, and over an existing
    /// `out`.
    pub force: bool,
}

/// Which fleet format [`export_plan`] writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlanTarget {
    /// A directory: one <id>.csv of polynomial pieces per quadcopter, crazyflies.yaml, ...
    Crazyswarm2,
    /// A .skyc show file, with <stem>.certificate.json and <stem>.scenario.toml beside it.
    Skybrush,
}

impl PlanTarget {
    pub fn name(self) -> &'static str {
        match self {
            PlanTarget::Crazyswarm2 => "crazyswarm2",
            PlanTarget::Skybrush => "skybrush",
        }
    }
}

/// How a Crazyflie holds the plan: its pieces and the float32 error against the limit.
#[derive(Debug, Clone, PartialEq)]
pub struct CrazyflieFit {
    pub pieces: usize,
    pub piece_duration_s: Real,
    pub bytes: usize,
    pub memory_bytes: usize,
    pub f32_bound_m: Real,
    pub tolerance_m: Real,
}

/// What [`export_plan`] did.
#[derive(Debug)]
pub struct PlanExport {
    pub target: PlanTarget,
    pub out: PathBuf,
    pub quadcopters: usize,
    pub scale: Real,
    pub origin_m: [Real; 3],
    pub eps_m: Real,
    pub pieces_per_agent: usize,
    pub piece_duration_s: Real,
    /// The certificate at the target scale (also written beside the export).
    pub certificate: Certificate,
    /// Crazyswarm2 only.
    pub crazyflie: Option<CrazyflieFit>,
    /// Skybrush only: where the show sits on the Earth and the limits it is validated against.
    pub show: Option<ShowFrame>,
    /// Whether the trajectory files were written: an UNSAFE certificate writes them only with
    /// `force` (the certificate and the scaled scenario are written either way).
    pub written: bool,
    /// The top view drawn beside a written export, or why it was not.
    pub top_view: Option<Result<PathBuf, TopViewError>>,
}

/// Why the top view beside an export was not drawn (the export stands without it).
#[derive(Debug, thiserror::Error)]
pub enum TopViewError {
    #[error(transparent)]
    Figure(#[from] cdm_report::FigureError),
    #[error("no figure written")]
    NoFigure,
}

/// The scaled scenario and everything derived from it.
pub(crate) struct Scaled {
    pub scenario: Scenario,
    pub frame: TargetFrame,
    /// r_HT of every member, in id order.
    pub trajs: Vec<AgentTrajectory>,
    pub roles: Vec<Role>,
    /// The end of the trajectories: T_total, or a mission's last phase's end.
    pub duration_s: Real,
}

/// What certificate.json holds: the target, the cut, and the certificate at the target scale.
#[derive(Serialize)]
struct Record<'a> {
    target: &'static str,
    scale: Real,
    origin_m: [Real; 3],
    pieces_per_agent: usize,
    piece_duration_s: Real,
    /// A mission: how long the trajectories last, take-off to landing (absent otherwise, where
    /// it is the certificate's t_total_s).
    #[serde(skip_serializing_if = "Option::is_none")]
    duration_s: Option<Real>,
    #[serde(skip_serializing_if = "Option::is_none")]
    f32_bound_m: Option<Real>,
    #[serde(skip_serializing_if = "Option::is_none")]
    f32_tolerance_m: Option<Real>,
    #[serde(skip_serializing_if = "Option::is_none")]
    trajectory_bytes: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    trajectory_memory_bytes: Option<usize>,
    certificate: &'a Certificate,
}

/// Export the plan of `source` to `target` at `out` in `frame`.
pub fn export_plan(
    target: PlanTarget,
    source: &ScenarioSource,
    out: &Path,
    frame: &ExportFrame,
) -> Result<PlanExport, ExportError> {
    refuse_existing(out, frame.force)?;
    let sc = scaled(source, frame)?;
    match target {
        PlanTarget::Crazyswarm2 => to_crazyswarm2(sc, out, frame.force),
        PlanTarget::Skybrush => to_skybrush(sc, out, frame.force),
    }
}

fn to_crazyswarm2(sc: Scaled, out: &Path, force: bool) -> Result<PlanExport, ExportError> {
    let split = crazyflie_split(&sc.trajs, DEFAULT_TOLERANCE_M).map_err(ExportError::Split)?;
    let cert = certify(&sc.scenario);
    create_dir(out)?;
    let record = Record {
        target: "crazyswarm2",
        scale: sc.frame.scale,
        origin_m: sc.frame.origin.into(),
        pieces_per_agent: split.pieces,
        piece_duration_s: split.piece_duration_s,
        duration_s: mission_duration(&sc),
        f32_bound_m: Some(split.f32_bound_m),
        f32_tolerance_m: Some(DEFAULT_TOLERANCE_M),
        trajectory_bytes: Some(split.bytes),
        trajectory_memory_bytes: Some(float32::TRAJECTORY_MEMORY_BYTES),
        certificate: &cert,
    };
    write_record(out, "", &record, &sc.scenario)?;
    let mut done = outcome(PlanTarget::Crazyswarm2, out, &sc, &record);
    done.crazyflie = Some(CrazyflieFit {
        pieces: split.pieces,
        piece_duration_s: split.piece_duration_s,
        bytes: split.bytes,
        memory_bytes: float32::TRAJECTORY_MEMORY_BYTES,
        f32_bound_m: split.f32_bound_m,
        tolerance_m: DEFAULT_TOLERANCE_M,
    });
    if !writes(&cert, force, out) {
        return Ok(done);
    }
    crazyswarm2::write(out, &sc, &split)?;
    done.written = true;
    done.top_view = Some(draw(out, "top_view", &sc));
    Ok(done)
}

fn to_skybrush(sc: Scaled, out: &Path, force: bool) -> Result<PlanExport, ExportError> {
    let cut = Cut::MaxDuration(SKYBRUSH_MAX_SEGMENT_S);
    let cut_pieces = sc.trajs.first().map(|t| pieces(t, cut)).unwrap_or_default();
    let longest_s = cut_pieces.iter().map(|p| p.duration_s).fold(0.0, Real::max);
    let cert = certify(&sc.scenario);
    let (dir, stem) = beside(out)?;
    let record = Record {
        target: "skybrush",
        scale: sc.frame.scale,
        origin_m: sc.frame.origin.into(),
        pieces_per_agent: cut_pieces.len(),
        piece_duration_s: longest_s,
        duration_s: mission_duration(&sc),
        f32_bound_m: None,
        f32_tolerance_m: None,
        trajectory_bytes: None,
        trajectory_memory_bytes: None,
        certificate: &cert,
    };
    write_record(&dir, &format!("{stem}."), &record, &sc.scenario)?;
    let mut done = outcome(PlanTarget::Skybrush, out, &sc, &record);
    done.show = Some(skybrush::frame(&sc, &cert));
    if !writes(&cert, force, out) {
        return Ok(done);
    }
    skybrush::write(out, &sc, cut, &cert)?;
    done.written = true;
    done.top_view = Some(draw(&dir, &format!("{stem}.top_view"), &sc));
    Ok(done)
}

fn outcome(target: PlanTarget, out: &Path, sc: &Scaled, record: &Record<'_>) -> PlanExport {
    PlanExport {
        target,
        out: out.to_path_buf(),
        quadcopters: sc.trajs.len(),
        scale: sc.frame.scale,
        origin_m: record.origin_m,
        eps_m: sc.scenario.file.eps_m,
        pieces_per_agent: record.pieces_per_agent,
        piece_duration_s: record.piece_duration_s,
        certificate: record.certificate.clone(),
        crazyflie: None,
        show: None,
        written: false,
        top_view: None,
    }
}

/// Load the scenario, map it into the target frame with the target radius and validate it
/// again (`Checks::Full`: the gains' stability is part of the certificate).
fn scaled(source: &ScenarioSource, frame: &ExportFrame) -> Result<Scaled, ExportError> {
    let base = load(source)?;
    let origin = match &frame.origin {
        Some(text) => TargetFrame::parse_origin(text)?,
        None => Vec3::zeros(),
    };
    let tf = TargetFrame::new(frame.scale, origin)?;
    let file = tf.apply(&base.file, frame.eps_m)?;
    let what = format!("{} at scale {} + origin {origin:?}", base.origin, tf.scale);
    let scenario = Scenario::from_file(file, &what, Checks::Full)?;
    let trajs = team_trajectories(&scenario);
    let roles = roles(&scenario);
    Ok(Scaled {
        duration_s: scenario.plan.end_s(),
        scenario,
        frame: tf,
        trajs,
        roles,
    })
}

/// Every member's role, in id order (the order of [`team_trajectories`]).
pub(crate) fn roles(s: &Scenario) -> Vec<Role> {
    s.id_order()
        .into_iter()
        .map(|k| s.formation.members[k].role)
        .collect()
}

/// certificate.json's `duration_s`: written for a mission only, so the files of a scenario
/// without mission tables stay as they were.
fn mission_duration(sc: &Scaled) -> Option<Real> {
    sc.scenario.plan.is_mission().then_some(sc.duration_s)
}

pub(crate) fn create_dir(dir: &Path) -> Result<(), ExportError> {
    std::fs::create_dir_all(dir).map_err(|source| ExportError::CreateDir {
        dir: dir.to_path_buf(),
        source,
    })
}

/// The directory and the file stem of `--out FILE`, the directory created.
pub(crate) fn beside(out: &Path) -> Result<(PathBuf, String), ExportError> {
    let stem = out
        .file_stem()
        .and_then(|s| s.to_str())
        .filter(|s| !s.is_empty())
        .ok_or_else(|| ExportError::NotAFile {
            out: out.to_path_buf(),
        })?
        .to_string();
    let dir = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    create_dir(&dir)?;
    Ok((dir, stem))
}

/// `<prefix>certificate.json` and `<prefix>scenario.toml` (the scaled scenario: `simulate
/// --scenario` flies it) into `dir`.
fn write_record(
    dir: &Path,
    prefix: &str,
    record: &Record<'_>,
    s: &Scenario,
) -> Result<(), ExportError> {
    let text = serde_json::to_string_pretty(record).map_err(|source| ExportError::Json {
        what: "certificate.json",
        source,
    })?;
    write_atomic(
        &dir.join(format!("{prefix}certificate.json")),
        text.as_bytes(),
    )?;
    Ok(write_atomic(
        &dir.join(format!("{prefix}scenario.toml")),
        s.to_toml().as_bytes(),
    )?)
}

/// An export never overwrites what is at `out` (a file, or a directory with anything in it: an
/// unrelated file named like the show, an earlier export) unless `force`; an empty directory is
/// used. Checked before the certificate is flown, so the refusal is immediate.
pub fn refuse_existing(out: &Path, force: bool) -> Result<(), ExportError> {
    if force {
        return Ok(());
    }
    let taken = match std::fs::read_dir(out) {
        Ok(mut entries) => entries.next().map(|_| true),
        Err(_) => out.symlink_metadata().is_ok().then_some(false),
    };
    match taken {
        Some(dir) => Err(ExportError::OutExists {
            out: out.to_path_buf(),
            dir,
        }),
        None => Ok(()),
    }
}

/// Whether the trajectory files are written: a SAFE certificate, or `force` (logged).
fn writes(cert: &Certificate, force: bool, out: &Path) -> bool {
    if cert.verdict == Verdict::Safe {
        return true;
    }
    if force {
        tracing::warn!(
            "the certificate at the target scale is UNSAFE; writing {} anyway (--force)",
            out.display()
        );
    }
    force
}

fn draw(dir: &Path, stem: &str, sc: &Scaled) -> Result<PathBuf, TopViewError> {
    const SAMPLES: usize = 60;
    let paths = sc
        .trajs
        .iter()
        .zip(&sc.roles)
        .map(|(t, r)| TopPath {
            leader: r.is_leader(),
            points: (0..=SAMPLES)
                .map(|k| t.position(sc.duration_s * k as Real / SAMPLES as Real))
                .collect(),
        })
        .collect();
    let title = format!(
        "{}: {} quadcopters from above, scale {} (start blue, goal red)",
        sc.scenario.file.name,
        sc.trajs.len(),
        sc.frame.scale
    );
    top_view(dir, stem, &title, paths)?
        .pop()
        .ok_or(TopViewError::NoFigure)
}
