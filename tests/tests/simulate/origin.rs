//! `[origin]`: a scenario anchored on the Earth.
//!
//! - `plan` prints each primary leader's start and goal both in scenario metres and as WGS-84
//!   latitude, longitude and altitude; over `examples/outdoor5km.toml`, a team 5 km across, pymap3d (an independent
//!   implementation of the same tangent plane) puts every printed position within 1 mm of its
//!   scenario point (tests/python/check_geodetic.py).
//! - A bad origin (latitude outside [-90, 90], longitude outside [-180, 180], a NaN, a heading
//!   that is not finite) is exit 2 naming the field and the file.
//!
//! How to run: `cargo test --release -p integration-tests --test simulate -- origin::`.

use integration_tests::support;

use std::io::Write;
use std::process::{Command, Output, Stdio};

use integration_tests::{bin, describe, python_script, run, venv_python, TempDir};
use support::assert_exit;

const DEADLINE: std::time::Duration = integration_tests::deadline::FLIGHT;

/// `examples/outdoor5km.toml`: the generated four-member team stretched ten times across (x
/// and y; heights kept), anchored at PX4's SITL home with +x 30 degrees east of north.
fn example() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/outdoor5km.toml")
}

fn plan(scenario: &std::path::Path) -> Output {
    let s = scenario.to_str().expect("utf-8 path");
    run(
        Command::new(bin("orchestrator")).args(["plan", "--scenario", s]),
        DEADLINE,
    )
}

#[test]
fn plan_shows_the_leaders_in_metres_and_in_latitude_and_longitude() {
    let out = plan(&example());
    assert!(
        matches!(out.status.code(), Some(0 | 1)),
        "plan: {}",
        describe(&out)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("geographic origin: lat 47.3977420000 deg, lon 8.5455940000 deg"),
        "{}",
        describe(&out)
    );
    // Three leaders, a start and a goal each.
    assert_eq!(stdout.matches("  leader ").count(), 6, "{stdout}");
    let mut check = Command::new(venv_python())
        .arg(python_script("check_geodetic.py"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the checker");
    check
        .stdin
        .take()
        .expect("stdin")
        .write_all(&out.stdout)
        .expect("write the plan");
    let checked = check.wait_with_output().expect("the checker ends");
    assert_exit(&checked, 0, "check_geodetic.py");
    let report: serde_json::Value = serde_json::from_slice(&checked.stdout).expect("one JSON line");
    assert_eq!(report["points"], 6, "{report}");
    assert!(report["farthest_m"].as_f64().unwrap() > 4000.0, "{report}");
    let err = report["max_error_m"].as_f64().unwrap();
    assert!(err < 1e-3, "{report}");
}

#[test]
fn bad_origins_are_refused_naming_the_field_and_the_file() {
    let dir = TempDir::new();
    let base = std::fs::read_to_string(example()).expect("the example scenario");
    let cases = [
        ("lat_deg = 91.0", "origin.lat_deg", "must be in [-90, 90]"),
        ("lat_deg = nan", "origin.lat_deg", "finite"),
        (
            "lon_deg = -180.5",
            "origin.lon_deg",
            "must be in [-180, 180]",
        ),
        ("heading_deg = inf", "origin.heading_deg", "finite"),
        ("alt_m = nan", "origin.alt_m", "finite"),
    ];
    for (k, (line, field, why)) in cases.iter().enumerate() {
        let key = line.split(' ').next().expect("a key");
        let text = &base;
        // Replace the one key of the [origin] table.
        let start = text.find("[origin]").expect("an [origin] table");
        let at = start + text[start..].find(&format!("{key} = ")).expect("the key");
        let end = at + text[at..].find('\n').expect("a line end");
        let bad = format!("{}{line}{}", &text[..at], &text[end..]);
        let name = format!("bad{k}.toml");
        let path = integration_tests::write_text(dir.path(), &name, &bad);
        let out = plan(&path);
        assert_exit(&out, 2, line);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(&name) && err.contains(field) && err.contains(why),
            "{line}: {err}"
        );
    }
    // An unknown key of the table is named too.
    let text = base.replace("heading_deg", "heading");
    let path = integration_tests::write_text(dir.path(), "typo.toml", &text);
    let out = plan(&path);
    assert_exit(&out, 2, "heading");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("heading"),
        "{}",
        describe(&out)
    );
}
