//! Crazyswarm2 files: `<id>.csv` per quadcopter in the format of Crazyswarm2's
//! `uav_trajectory.py` (`loadcsv`, read by `uploadTrajectory`): the header
//! `duration,x^0,...,x^7,y^0,...,y^7,z^0,...,z^7,yaw^0,...,yaw^7`, one row per piece,
//! coefficients in increasing powers of the time local to the piece (ours stop at degree 5,
//! yaw is 0); a `crazyflies.yaml` fragment; `fly.py`; and `README.txt`. A mission's file holds
//! every phase and the hovers between them; with `[takeoff]` it starts on the ground.

use std::fmt::Write as _;
use std::path::Path;

use cdm_math::Real;
use cdm_model::airspace::Shape;
use cdm_records::rundir::write_atomic;
use cdm_scenario::{has_airspace, ScenarioFile};
use cdm_trajectory::{pieces, CrazyflieSplit, PolyPiece};

use super::Scaled;
use crate::ExportError;

/// Coefficients per axis in the file (Crazyflie pieces are degree-7 polynomials).
const COEFFS: usize = 8;

fn header() -> String {
    let mut h = String::from("duration");
    for axis in ["x", "y", "z", "yaw"] {
        for k in 0..COEFFS {
            let _ = write!(h, ",{axis}^{k}");
        }
    }
    h
}

/// One row: the duration, then x, y, z and yaw coefficients, 8 each.
fn row(p: &PolyPiece) -> String {
    let mut r = format!("{}", p.duration_s);
    for axis in 0..3 {
        for k in 0..COEFFS {
            let c = p.coeffs.get(k).map_or(0.0, |c| c[axis]);
            let _ = write!(r, ",{c}");
        }
    }
    for _ in 0..COEFFS {
        r.push_str(",0");
    }
    r
}

fn put(dir: &Path, name: &str, text: &str) -> Result<(), ExportError> {
    Ok(write_atomic(&dir.join(name), text.as_bytes())?)
}

pub fn write(dir: &Path, sc: &Scaled, split: &CrazyflieSplit) -> Result<(), ExportError> {
    let head = header();
    for t in &sc.trajs {
        let mut text = head.clone();
        text.push('\n');
        for p in pieces(t, split.cut) {
            text.push_str(&row(&p));
            text.push('\n');
        }
        put(dir, &format!("{}.csv", t.id), &text)?;
    }
    put(dir, "crazyflies.yaml", &yaml(sc))?;
    put(dir, "fly.py", &fly_py(sc))?;
    if let Some(text) = airspace_yaml(&sc.scenario.file) {
        put(dir, AIRSPACE_FILE, &text)?;
    }
    put(dir, "README.txt", &readme(sc, split))
}

/// Where the scenario's fence and obstacles go: Crazyswarm2 has no airspace file of
/// its own, so this one is ours, explained in README.txt and the project README.
const AIRSPACE_FILE: &str = "airspace.yaml";

/// A number as YAML reads it back: Rust's `Display` never writes an exponent, which YAML 1.1
/// readers (PyYAML) would take for a string (`1e-5`).
fn num(v: Real) -> String {
    format!("{v}")
}

fn nums(v: &[Real]) -> String {
    let cells: Vec<String> = v.iter().map(|c| num(*c)).collect();
    format!("[{}]", cells.join(", "))
}

/// The scenario's `[geofence]` and `[[obstacle]]`s in the target frame (the scaled scenario has
/// them moved already), or None without either.
fn airspace_yaml(file: &ScenarioFile) -> Option<String> {
    if !has_airspace(file) {
        return None;
    }
    let mut y = String::from(
        "# The airspace of this plan, written by `orchestrator export crazyswarm2`, in the frame of the\n\
         # trajectories (metres, z up). certificate.json proves that every drone's ball (radius eps plus\n\
         # its tracking bound) stays inside the geofence and clear of every obstacle for the whole flight.\n\
         # geofence: a vertical prism over `polygon` (x, y) from min_z_m to max_z_m.\n\
         # obstacles: an axis-aligned `box` (corners min, max) or a vertical `cylinder`.\n",
    );
    if let Some(f) = &file.geofence {
        let polygon: Vec<String> = f.polygon.iter().map(|v| nums(v)).collect();
        let _ = write!(
            y,
            "geofence:
  polygon: [{}]
  min_z_m: {}
  max_z_m: {}
",
            polygon.join(", "),
            num(f.min_z_m),
            num(f.max_z_m)
        );
    }
    y.push_str(if file.obstacles.is_empty() {
        "obstacles: []
"
    } else {
        "obstacles:
"
    });
    for o in &file.obstacles {
        // A JSON string is a YAML double-quoted scalar: any name survives.
        let name = serde_json::to_string(&o.name).unwrap_or_default();
        let shape = match o.shape() {
            Shape::Box { min, max } => format!("box: {{min: {}, max: {}}}", nums(&min), nums(&max)),
            Shape::Cylinder {
                center,
                radius_m,
                min_z_m,
                max_z_m,
            } => format!(
                "cylinder: {{center: {}, radius_m: {}, min_z_m: {}, max_z_m: {}}}",
                nums(&center),
                num(radius_m),
                num(min_z_m),
                num(max_z_m)
            ),
        };
        let _ = writeln!(
            y,
            "  - name: {name}
    {shape}"
        );
    }
    Some(y)
}

/// True when the trajectories start on the ground (a mission's take-off is their first phase).
fn from_the_ground(sc: &Scaled) -> bool {
    sc.scenario.file.takeoff.is_some()
}

/// Each drone on the floor under the start of its trajectory (Crazyswarm2 reads
/// `initial_position` as where the vehicle sits before take-off): z = 0, or the mission's ground
/// where the trajectory starts.
fn yaml(sc: &Scaled) -> String {
    let mut y = String::from(
        "# Fragment of Crazyswarm2's crazyflie/config/crazyflies.yaml, written by `orchestrator export\n\
         # crazyswarm2`: merge these entries under `robots:` and set each uri to that Crazyflie's address.\n\
         # initial_position: on the floor (z = 0) under the start of the drone's trajectory.\n\
         robots:\n",
    );
    let ground = from_the_ground(sc);
    for t in &sc.trajs {
        let p = t.position(0.0);
        let z = if ground { p.z } else { 0.0 };
        let _ = write!(
            y,
            "  cf{id}:\n    enabled: true\n    uri: radio://0/80/2M/E7E7E7E7{id:02X}\n    initial_position: [{x}, {yy}, {z:?}]\n    type: cf21\n",
            id = t.id,
            x = p.x,
            yy = p.y
        );
    }
    y
}

/// The flight script: upload every trajectory, take off, go to the starts, fly, land. A mission
/// with `[takeoff]` starts its trajectories on the ground: they take off themselves.
fn fly_py(sc: &Scaled) -> String {
    let t_total = sc.duration_s;
    let climb = if from_the_ground(sc) {
        "    # The trajectories start on the ground: their first phase is the take-off.\n"
    } else {
        concat!(
            "    cfs.takeoff(targetHeight=TAKEOFF_HEIGHT_M, duration=3.0)\n",
            "    clock.sleep(3.5)\n",
            "    for ident, start in START.items():\n",
            "        cfs.crazyfliesByName[f\"cf{ident}\"].goTo(start, 0.0, 5.0)\n",
            "    clock.sleep(5.5)\n"
        )
    };
    let lowest = sc
        .trajs
        .iter()
        .map(|t| t.position(0.0).z)
        .fold(Real::INFINITY, Real::min);
    let mut starts = String::new();
    for t in &sc.trajs {
        let p = t.position(0.0);
        let _ = writeln!(starts, "    {}: [{}, {}, {}],", t.id, p.x, p.y, p.z);
    }
    format!(
        r#"#!/usr/bin/env python3
"""Fly the exported continuum-deformation plan with Crazyswarm2 (written by `orchestrator export
crazyswarm2`). Start the server first: ros2 launch crazyflie launch.py (with crazyflies.yaml)."""
from pathlib import Path

from crazyflie_py import Crazyswarm
from crazyflie_py.uav_trajectory import Trajectory

HERE = Path(__file__).resolve().parent
T_TOTAL_S = {t_total}
TAKEOFF_HEIGHT_M = {takeoff}
START = {{
{starts}}}


def main():
    swarm = Crazyswarm()
    clock, cfs = swarm.timeHelper, swarm.allcfs
    for ident in START:
        traj = Trajectory()
        traj.loadcsv(str(HERE / f"{{ident}}.csv"))
        cfs.crazyfliesByName[f"cf{{ident}}"].uploadTrajectory(0, 0, traj)
{climb}    cfs.startTrajectory(0, timescale=1.0, relative=False)
    clock.sleep(T_TOTAL_S + 1.0)
    cfs.land(targetHeight=0.03, duration=4.0)
    clock.sleep(4.5)


if __name__ == "__main__":
    main()
"#,
        takeoff = lowest.max(0.3)
    )
}

fn readme(sc: &Scaled, split: &CrazyflieSplit) -> String {
    let flight = if sc.scenario.plan.is_mission() {
        let names: Vec<String> = (sc.scenario.plan.phases().iter())
            .map(|p| p.kind.name())
            .collect();
        format!(
            "a mission of {} phases ({}) lasting {} s",
            names.len(),
            names.join(", "),
            sc.duration_s
        )
    } else {
        format!("travel time {} s", sc.scenario.file.t_total_s)
    };
    let steps = if from_the_ground(sc) {
        "startTrajectory(0,\n   relative=False) from the ground: the trajectory takes off itself, lands"
    } else {
        "takes off, goes to\n   the starts, startTrajectory(0, relative=False), lands"
    };
    let mut r = format!(
        "Continuum-deformation plan `{name}` for Crazyswarm2, written by `orchestrator export crazyswarm2`.\n\
         Scale {scale}, origin {origin:?} m, vehicle radius eps = {eps} m, {flight}.\n\
         Each <id>.csv holds {n} polynomial piece(s) of {d:.3} s ({bytes} of 4096 bytes of trajectory\n\
         memory); float32 evaluation stays within {bound:.3e} m of the exact plan (limit 1 mm).\n\
         certificate.json is the certificate at this scale; scenario.toml the scaled scenario\n\
         (`orchestrator simulate --scenario scenario.toml` flies it).\n\n\
         Upload and start:\n\
         1. Merge crazyflies.yaml into crazyflie/config/crazyflies.yaml (set each uri).\n\
         2. ros2 launch crazyflie launch.py\n\
         3. python3 fly.py   (uploads every trajectory with uploadTrajectory, {steps})\n\n\
         agent  role       file     Crazyswarm2 name\n",
        name = sc.scenario.file.name,
        scale = sc.frame.scale,
        origin = [sc.frame.origin.x, sc.frame.origin.y, sc.frame.origin.z],
        eps = sc.scenario.file.eps_m,
        n = split.pieces,
        d = split.piece_duration_s,
        bytes = split.bytes,
        bound = split.f32_bound_m,
    );
    for (t, role) in sc.trajs.iter().zip(&sc.roles) {
        let _ = writeln!(
            r,
            "{:<6} {:<10} {:<8} cf{}",
            t.id,
            role.as_str(),
            format!("{}.csv", t.id),
            t.id
        );
    }
    if has_airspace(&sc.scenario.file) {
        let _ = write!(
            r,
            "\n{AIRSPACE_FILE}: the scenario's geofence and obstacles at this scale, which the certificate\n\
             checked. Crazyswarm2 reads no such file: set your arena's limits and obstacles from it.\n"
        );
    }
    r
}
