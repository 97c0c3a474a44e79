//! `orchestrator export ...`: calls cdm-export and prints what it wrote. Exit 0 SAFE (or a
//! written bag or map), 1 UNSAFE at the target scale, 2 bad input, 3 a fault.

use std::path::Path;

use crate::progress::Spinner;
use cdm_exit::{Exit, Failure};
use cdm_export::{
    export_bag, export_geojson, export_plan, export_qgc_plan, MapSource, PlanExport, PlanTarget,
    ShowFrame,
};
use cdm_model::outcome::Verdict;

use crate::export_args::{failure, ExportTarget, FrameArgs, SourceArgs};
use crate::print_certificate::print_certificate;

pub fn run(target: ExportTarget, quiet: bool) -> Result<Exit, Failure> {
    match target {
        ExportTarget::Crazyswarm2 { source, out, frame } => {
            plan(PlanTarget::Crazyswarm2, &source, &out, &frame, quiet)
        }
        ExportTarget::Skybrush { source, out, frame } => {
            plan(PlanTarget::Skybrush, &source, &out, &frame, quiet)
        }
        ExportTarget::Rosbag2 { run, out, force } => {
            let bag = export_bag(&run, &out, force).map_err(failure)?;
            if !quiet {
                let total: u64 = bag.counts.iter().map(|c| c.1).sum();
                out!(
                    "export rosbag2: {total} messages on {} topics -> {}",
                    bag.counts.len(),
                    bag.out.display()
                );
                for (name, n) in bag.counts.iter().rev().take(3).rev() {
                    out!("  {name}: {n}");
                }
            }
            Ok(Exit::Safe)
        }
        ExportTarget::Geojson { source, out, force } => {
            let g = export_geojson(&MapSource { path: source }, &out, force).map_err(failure)?;
            if !quiet {
                out!(
                    "export geojson: {} -> {} ({} bytes): {} geofence, {} obstacle(s), {} leader path(s), {} ground spot(s) (WGS-84, [lon, lat, alt AMSL])",
                    g.file.display(),
                    g.out.display(),
                    g.bytes,
                    g.fences,
                    g.obstacles,
                    g.leader_paths,
                    g.ground_spots
                );
            }
            Ok(Exit::Safe)
        }
        ExportTarget::QgcPlan { source, out, force } => {
            let p = export_qgc_plan(&MapSource { path: source }, &out, force).map_err(failure)?;
            if !quiet {
                out!(
                    "export qgc-plan: {} -> {} ({} bytes): {} fence polygon(s), {} fence circle(s), {} rally point(s)",
                    p.file.display(),
                    p.out.display(),
                    p.bytes,
                    p.polygons,
                    p.circles,
                    p.rally_points
                );
            }
            Ok(Exit::Safe)
        }
    }
}

/// `export crazyswarm2|skybrush`: exit 0 SAFE, 1 UNSAFE (the files written only with --force).
fn plan(
    target: PlanTarget,
    source: &SourceArgs,
    out: &Path,
    frame: &FrameArgs,
    quiet: bool,
) -> Result<Exit, Failure> {
    let spinner = Spinner::new(
        "certifying at the target scale: flying the plan at several travel times",
        quiet,
    );
    let done = export_plan(target, &source.plain(), out, &frame.plain());
    spinner.finish();
    let done = done.map_err(failure)?;
    report(&done, quiet);
    if !done.written {
        eprintln!(
            "error: the certificate at the target scale is UNSAFE: {} not written (the certificate is beside it; --force writes it anyway)",
            done.out.display()
        );
        return Ok(Exit::Unsafe);
    }
    match &done.top_view {
        Some(Ok(file)) if !quiet => out!("  top view: {}", file.display()),
        Some(Err(e)) => tracing::error!("top view not drawn: {e}"),
        _ => {}
    }
    if quiet {
        out!("{}", done.certificate.verdict);
    } else {
        out!("  written: {}", done.out.display());
    }
    Ok(if done.certificate.verdict == Verdict::Safe {
        Exit::Safe
    } else {
        Exit::Unsafe
    })
}

fn report(d: &PlanExport, quiet: bool) {
    if quiet {
        return;
    }
    out!(
        "export {}: {} quadcopters, scale {}, origin {:?} m, eps {} m, {} piece(s) of {:.3} s each",
        d.target.name(),
        d.quadcopters,
        d.scale,
        d.origin_m,
        d.eps_m,
        d.pieces_per_agent,
        d.piece_duration_s
    );
    print_certificate(&d.certificate);
    if d.certificate.t_threshold_s.is_finite() {
        out!(
            "  the show is SAFE at this scale when it lasts at least T_threshold = {:.2} s (--t-total)",
            d.certificate.t_threshold_s
        );
    }
    if let Some(c) = &d.crazyflie {
        out!(
            "  crazyflie: {} piece(s) of {:.3} s per quadcopter, {} of {} bytes; float32 error bound {:.3e} m (limit {} m)",
            c.pieces,
            c.piece_duration_s,
            c.bytes,
            c.memory_bytes,
            c.f32_bound_m,
            c.tolerance_m
        );
    }
    if let Some(show) = &d.show {
        print_show_frame(show);
    }
}

/// The show's place on the Earth and its validation limits, as show.json carries them.
fn print_show_frame(f: &ShowFrame) {
    if let Some(o) = &f.location {
        out!(
            "  show location: lat {:.7} deg, lon {:.7} deg, {:.3} m AMSL, +x at {} deg from north",
            o.lat_deg,
            o.lon_deg,
            o.alt_m,
            o.heading_deg
        );
    }
    let v = &f.validation;
    let z = match v.max_velocity_z_up {
        Some(up) => format!("up {up:.3} m/s, down {:.3} m/s", v.max_velocity_z),
        None => format!("z {:.3} m/s", v.max_velocity_z),
    };
    let mut line = format!(
        "  show validation: min distance {} m, max speed xy {:.3} m/s, {z}",
        v.min_distance, v.max_velocity_xy
    );
    if let Some(a) = v.max_acceleration_xy {
        line.push_str(&format!(", accel xy {a} m/s^2"));
    }
    if let Some(a) = v.max_acceleration_z {
        line.push_str(&format!(", accel z {a} m/s^2"));
    }
    out!("{line}, max altitude {:.3} m", v.max_altitude);
}
