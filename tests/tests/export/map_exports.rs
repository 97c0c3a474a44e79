//! The exports that carry the scenario's place on the Earth: `export geojson` and `export
//! qgc-plan` of examples/field10.toml (a fence, a box and a cylinder, ten members from the ground
//! and back, an [origin] and a [vehicle]) read back by code nobody here wrote (the `geojson`
//! package, `shapely`, `pymap3d`: every vertex back in scenario metres within 1e-6 m; the plan
//! against QGroundControl's documented structure), the Skybrush show's location and validation
//! limits as Skybrush reads them, a run directory as the source, and a scenario without
//! [origin] refused with exit 2 naming the table.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{bin, describe, run, venv_python, TempDir};

const DEADLINE: Duration = integration_tests::deadline::LONG;

fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("examples")
        .join(name)
}

fn orchestrator(args: &[&std::ffi::OsStr]) -> Output {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    run(&mut c, DEADLINE)
}

fn check(mode: &str, file: &Path, scenario: &Path) -> String {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("python");
    let mut c = Command::new(venv_python());
    c.arg(dir.join("check_map_exports.py"))
        .arg(mode)
        .arg(file)
        .arg(scenario)
        .current_dir(&dir)
        .env("PYTHONDONTWRITEBYTECODE", "1");
    let out = run(&mut c, DEADLINE);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn export(kind: &str, source: &Path, out: &Path) -> Output {
    orchestrator(&[
        "export".as_ref(),
        kind.as_ref(),
        source.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ])
}

#[test]
fn the_map_and_the_plan_are_the_scenario_on_the_earth() {
    let tmp = TempDir::new();
    let field = example("field10.toml");
    let map = tmp.path().join("field10.geojson");
    let out = export("geojson", &field, &map);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.contains("1 geofence, 2 obstacle(s), 6 leader path(s), 20 ground spot(s)"),
        "{said}"
    );
    let read = check("geojson", &map, &field);
    assert!(read.starts_with("geojson ok: 29 features"), "{read}");

    let plan = tmp.path().join("field10.plan");
    let out = export("qgc-plan", &field, &plan);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    let read = check("qgc-plan", &plan, &field);
    assert!(
        read.starts_with(
            "qgc-plan ok: 1 inclusion, 1 exclusion polygon(s), 1 circle(s), 10 rally point(s)"
        ),
        "{read}"
    );
    // Not over what is there.
    let again = export("qgc-plan", &field, &plan);
    assert_eq!(again.status.code(), Some(2), "{}", describe(&again));
    assert!(String::from_utf8_lossy(&again.stderr).contains("--force"));
}

#[test]
fn the_skybrush_show_carries_its_location_and_the_vehicles_limits() {
    let tmp = TempDir::new();
    let field = example("field10.toml");
    let show = tmp.path().join("field10.skyc");
    let out = orchestrator(&[
        "export".as_ref(),
        "skybrush".as_ref(),
        "--scenario".as_ref(),
        field.as_os_str(),
        "--eps".as_ref(),
        "1.5".as_ref(),
        "--out".as_ref(),
        show.as_os_str(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.contains("show location: lat 47.3977420 deg, lon 8.5455940 deg, 488.000 m AMSL, +x at 30 deg from north"),
        "{said}"
    );
    let read = check("skyc", &show, &field);
    assert!(read.starts_with("skyc frame ok"), "{read}");
}

#[test]
fn a_run_directory_is_mapped_as_it_flew() {
    let tmp = TempDir::new();
    let run_dir = tmp.path().join("run");
    let scenario = example("outdoor5km.toml");
    let out = orchestrator(&[
        "simulate".as_ref(),
        "--scenario".as_ref(),
        scenario.as_os_str(),
        "--out".as_ref(),
        run_dir.as_os_str(),
        "--every".as_ref(),
        "100".as_ref(),
        "--no-figures".as_ref(),
        "--quiet".as_ref(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    let map = tmp.path().join("run.geojson");
    let out = export("geojson", &run_dir, &map);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    let read = check("geojson", &map, &run_dir.join("scenario.toml"));
    assert!(read.starts_with("geojson ok: 3 features"), "{read}");
}

#[test]
fn a_map_needs_an_origin() {
    let tmp = TempDir::new();
    let indoor = example("airspace10.toml");
    for kind in ["geojson", "qgc-plan"] {
        let out = export(kind, &indoor, &tmp.path().join("x"));
        assert_eq!(out.status.code(), Some(2), "{}", describe(&out));
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(&format!("export {kind}:"))
                && err.contains("airspace10.toml has no [origin] table"),
            "{err}"
        );
        assert!(!tmp.path().join("x").exists());
    }
}
