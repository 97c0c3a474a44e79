//! `orchestrator export rosbag2` (`rosbag2.rs`): a finished run as a ROS 2 bag.
//!
//! `orchestrator export crazyswarm2|skybrush`: the plan in the formats real fleets load, in the
//! target frame (p -> S p + origin), with the certificate issued again at that scale and the
//! target vehicles' radius. A mission is exported whole, from the ground to the ground: every
//! phase's quintic and the hovers between them. Steps: load and scale (bad input: exit 2), cut
//! the exact quintics into pieces (a plan the target cannot hold: exit 2), certify (UNSAFE: exit
//! 1, and the trajectory files are written only with --force), write.

pub mod certificate;
pub mod cli;
mod crazyswarm2;
pub mod geographic;
mod rosbag2;
mod skybrush;

use std::path::{Path, PathBuf};

use serde::Serialize;

use cdm_certificates::certificate::Certificate;
use cdm_certificates::certify::certify;
use cdm_math::{Real, Vec3};
use cdm_model::formation::Role;
use cdm_model::outcome::Verdict;
use cdm_records::rundir::write_atomic;
use cdm_scenario::{Checks, Scenario};
use cdm_team::out;
use cdm_trajectory::{
    crazyflie_split, float32, pieces, team_trajectories, AgentTrajectory, Cut, TargetFrame,
    DEFAULT_TOLERANCE_M, SKYBRUSH_MAX_SEGMENT_S,
};

use crate::certificate::print_certificate;
use crate::cli::{load, ExportFrame, ExportTarget, Source};
use cdm_report::{top_view, TopPath};
use cdm_team::errors::CommandError;
use cdm_team::progress::Spinner;
use cdm_team::{Exit, Failure};

/// The scaled scenario and everything derived from it.
pub struct Scaled {
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

pub fn run(target: ExportTarget, quiet: bool) -> Result<Exit, Failure> {
    match target {
        ExportTarget::Crazyswarm2 { source, out, frame } => {
            to_crazyswarm2(&source, &out, &frame, quiet)
        }
        ExportTarget::Skybrush { source, out, frame } => to_skybrush(&source, &out, &frame, quiet),
        ExportTarget::Rosbag2 { run, out, force } => {
            refuse_existing(&out, force)?;
            rosbag2::export(&run, &out, quiet)
        }
    }
}

fn to_crazyswarm2(
    source: &Source,
    out: &Path,
    frame: &ExportFrame,
    quiet: bool,
) -> Result<Exit, Failure> {
    refuse_existing(out, frame.force)?;
    let sc = scaled(source, frame)?;
    let split = crazyflie_split(&sc.trajs, DEFAULT_TOLERANCE_M)
        .map_err(|e| Failure::bad_input(CommandError::Split(e)))?;
    let cert = certify_quietly(&sc.scenario, quiet);
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
    report(&sc, &record, quiet);
    if !quiet {
        out!(
            "  crazyflie: {} piece(s) of {:.3} s per quadcopter, {} of {} bytes; float32 error bound {:.3e} m (limit {} m)",
            split.pieces,
            split.piece_duration_s,
            split.bytes,
            float32::TRAJECTORY_MEMORY_BYTES,
            split.f32_bound_m,
            DEFAULT_TOLERANCE_M
        );
    }
    if refused(&cert, frame.force, out) {
        return Ok(Exit::Unsafe);
    }
    crazyswarm2::write(out, &sc, &split)?;
    draw(out, "top_view", &sc, quiet);
    done(out, &cert, quiet)
}

fn to_skybrush(
    source: &Source,
    out: &Path,
    frame: &ExportFrame,
    quiet: bool,
) -> Result<Exit, Failure> {
    refuse_existing(out, frame.force)?;
    let sc = scaled(source, frame)?;
    let cut = Cut::MaxDuration(SKYBRUSH_MAX_SEGMENT_S);
    let cut_pieces = sc.trajs.first().map(|t| pieces(t, cut)).unwrap_or_default();
    let longest_s = cut_pieces.iter().map(|p| p.duration_s).fold(0.0, Real::max);
    let cert = certify_quietly(&sc.scenario, quiet);
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
    report(&sc, &record, quiet);
    if refused(&cert, frame.force, out) {
        return Ok(Exit::Unsafe);
    }
    skybrush::write(out, &sc, cut, &cert)?;
    draw(&dir, &format!("{stem}.top_view"), &sc, quiet);
    done(out, &cert, quiet)
}

/// Load the scenario, map it into the target frame with the target radius and validate it
/// again (`Checks::Full`: the gains' stability is part of the certificate).
fn scaled(source: &Source, frame: &ExportFrame) -> Result<Scaled, Failure> {
    let base = load(source)?;
    let origin = match &frame.origin {
        Some(text) => TargetFrame::parse_origin(text).map_err(Failure::bad_input)?,
        None => Vec3::zeros(),
    };
    let tf = TargetFrame::new(frame.scale, origin).map_err(Failure::bad_input)?;
    let file = tf
        .apply(&base.file, frame.eps)
        .map_err(Failure::bad_input)?;
    let what = format!("{} at scale {} + origin {origin:?}", base.origin, tf.scale);
    let scenario = Scenario::from_file(file, &what, Checks::Full).map_err(Failure::bad_input)?;
    let trajs = team_trajectories(&scenario);
    let roles = scenario
        .id_order()
        .into_iter()
        .map(|k| scenario.formation.members[k].role)
        .collect();
    Ok(Scaled {
        duration_s: scenario.plan.end_s(),
        scenario,
        frame: tf,
        trajs,
        roles,
    })
}

/// certificate.json's `duration_s`: written for a mission only, so the files of a scenario
/// without mission tables stay as they were.
fn mission_duration(sc: &Scaled) -> Option<Real> {
    sc.scenario.plan.is_mission().then_some(sc.duration_s)
}

fn certify_quietly(s: &Scenario, quiet: bool) -> Certificate {
    let spinner = Spinner::new(
        "certifying at the target scale: flying the plan at several travel times",
        quiet,
    );
    let c = certify(s);
    spinner.finish();
    c
}

fn create_dir(dir: &Path) -> Result<(), Failure> {
    std::fs::create_dir_all(dir).map_err(|source| {
        Failure::bad_input(CommandError::CreateDir {
            dir: dir.to_path_buf(),
            source,
        })
    })
}

/// The directory and the file stem of `--out FILE`, the directory created.
fn beside(out: &Path) -> Result<(PathBuf, String), Failure> {
    let stem = out
        .file_stem()
        .and_then(|s| s.to_str())
        .filter(|s| !s.is_empty())
        .ok_or_else(|| Failure::bad_input(format!("--out {}: not a file name", out.display())))?
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
) -> Result<(), Failure> {
    let text = serde_json::to_string_pretty(record).map_err(Failure::fault)?;
    write_atomic(
        &dir.join(format!("{prefix}certificate.json")),
        text.as_bytes(),
    )
    .map_err(Failure::bad_input)?;
    write_atomic(
        &dir.join(format!("{prefix}scenario.toml")),
        s.to_toml().as_bytes(),
    )
    .map_err(Failure::bad_input)
}

fn report(sc: &Scaled, record: &Record<'_>, quiet: bool) {
    if quiet {
        return;
    }
    out!(
        "export {}: {} quadcopters, scale {}, origin {:?} m, eps {} m, {} piece(s) of {:.3} s each",
        record.target,
        sc.trajs.len(),
        sc.frame.scale,
        record.origin_m,
        sc.scenario.file.eps_m,
        record.pieces_per_agent,
        record.piece_duration_s
    );
    print_certificate(record.certificate);
    if record.certificate.t_threshold_s.is_finite() {
        out!(
            "  the show is SAFE at this scale when it lasts at least T_threshold = {:.2} s (--t-total)",
            record.certificate.t_threshold_s
        );
    }
}

/// An export never overwrites what is at `out` (a file, or a directory with anything in it: an
/// unrelated file named like the show, an earlier export) unless `force`; an empty directory is
/// used. Checked before the certificate is flown, so the refusal is immediate.
fn refuse_existing(out: &Path, force: bool) -> Result<(), Failure> {
    if force {
        return Ok(());
    }
    let taken = match std::fs::read_dir(out) {
        Ok(mut entries) => entries.next().map(|_| true),
        Err(_) => out.symlink_metadata().is_ok().then_some(false),
    };
    match taken {
        Some(dir) => Err(Failure::bad_input(CommandError::OutExists {
            out: out.to_path_buf(),
            dir,
        })),
        None => Ok(()),
    }
}

/// An UNSAFE certificate refuses the export unless `force`.
fn refused(cert: &Certificate, force: bool, out: &Path) -> bool {
    if cert.verdict == Verdict::Safe {
        return false;
    }
    if force {
        tracing::warn!(
            "the certificate at the target scale is UNSAFE; writing {} anyway (--force)",
            out.display()
        );
        return false;
    }
    eprintln!(
        "error: the certificate at the target scale is UNSAFE: {} not written (the certificate is beside it; --force writes it anyway)",
        out.display()
    );
    true
}

fn draw(dir: &Path, stem: &str, sc: &Scaled, quiet: bool) {
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
    match top_view(dir, stem, &title, paths) {
        Ok(files) if !quiet => out!("  top view: {}", files[files.len() - 1].display()),
        Ok(_) => {}
        Err(e) => tracing::error!("top view not drawn: {e}"),
    }
}

fn done(out: &Path, cert: &Certificate, quiet: bool) -> Result<Exit, Failure> {
    if quiet {
        out!("{}", cert.verdict);
    } else {
        out!("  written: {}", out.display());
    }
    Ok(if cert.verdict == Verdict::Safe {
        Exit::Safe
    } else {
        Exit::Unsafe
    })
}
