//! The scenarios of the airspace and vehicle tests (`geofence.rs`, `vehicle.rs`,
//! `mavlink_global.rs`), built in one place: four members of the paper's kind (generated(4)),
//! the fence they fly in, and `plan` with its certificate read back.

use std::path::Path;
use std::process::{Command, Output};

use crate::{bin, run};
use cdm_scenario::{generated, GeofenceSpec, ScenarioFile};

/// generated(4) (primary 1 from (360, 0, 900) to (224, 434, 560)) flying its plan in
/// `t_total_s`.
pub fn four_members(t_total_s: f64) -> ScenarioFile {
    let mut f = generated(4).expect("four agents generate");
    f.t_total_s = t_total_s;
    f
}

/// A fence around generated(4)'s whole flight: x -100..500 m, y -200..600 m, up to 1,200 m.
pub fn fence() -> GeofenceSpec {
    GeofenceSpec {
        polygon: vec![
            [-100.0, -200.0],
            [500.0, -200.0],
            [500.0, 600.0],
            [-100.0, 600.0],
        ],
        min_z_m: 0.0,
        max_z_m: 1200.0,
    }
}

/// `plan --scenario PATH --json DIR/cert.json --suggest`, and the certificate read back.
pub fn plan(dir: &Path, scenario: &Path) -> (Output, serde_json::Value) {
    let json = dir.join("cert.json");
    let (s, j) = (scenario.to_str().unwrap(), json.to_str().unwrap());
    let out = run(
        Command::new(bin("orchestrator")).args(["plan", "--scenario", s, "--json", j, "--suggest"]),
        crate::deadline::FLIGHT,
    );
    let cert = super::read_json(&json);
    (out, cert)
}
