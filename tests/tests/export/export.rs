//! `orchestrator export crazyswarm2|skybrush`: the exported pieces are the plan's r_HT, checked
//! by code nobody here wrote (cflib packs them within a Crazyflie's 4 KiB; numpy evaluates them
//! at 1,000 instants against `simulate`'s telemetry of the scaled scenario), the .skyc is a ZIP
//! of Skybrush's show.json whose Bézier curves are r_HT too, and the export refuses what the
//! target cannot fly: single precision too coarse (exit 2), UNSAFE at the target scale (exit 1
//! unless --force), bad flags (exit 2, naming the flag).

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{bin, describe, fenced_paper40, run, venv_python, write_scenario, TempDir};

const DEADLINE: Duration = integration_tests::deadline::LONG;
/// paper40 in a 9 m x 9 m arena: 300 m -> 4.5 m, the descent ends 0.5 m above the floor.
const LAB: [&str; 4] = ["--scale", "0.015", "--origin=-1.2,-2.7,-7.9", "--quiet"];

fn orchestrator(args: &[&str]) -> Output {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    run(&mut c, DEADLINE)
}

fn code(out: &Output) -> Option<i32> {
    out.status.code()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Fly the scaled scenario the export wrote with `simulate` (every 20th tick: 1,001 instants
/// over 200 s) and return its telemetry.csv.
fn reference(scenario: &Path, tmp: &Path) -> std::path::PathBuf {
    let run_dir = tmp.join("reference");
    let out = orchestrator(&[
        "simulate",
        "--scenario",
        scenario.to_str().unwrap(),
        "--out",
        run_dir.to_str().unwrap(),
        "--every",
        "20",
        "--no-figures",
        "--quiet",
    ]);
    assert_eq!(code(&out), Some(0), "{}", describe(&out));
    run_dir.join("telemetry.csv")
}

fn python(script: &str, args: &[&Path]) -> Output {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("python");
    let mut c = Command::new(venv_python());
    c.arg(dir.join(script))
        .args(args)
        .current_dir(&dir)
        .env("PYTHONDONTWRITEBYTECODE", "1");
    run(&mut c, DEADLINE)
}

#[test]
fn crazyswarm2_pieces_are_the_plan_in_cflib_and_numpy() {
    let tmp = TempDir::new();
    let dir = tmp.path().join("cf");
    let ds = dir.to_str().unwrap();
    let out = orchestrator(&[&["export", "crazyswarm2", "--out", ds][..], &LAB[..]].concat());
    assert_eq!(code(&out), Some(0), "{}", describe(&out));
    for f in [
        "1.csv",
        "40.csv",
        "crazyflies.yaml",
        "README.txt",
        "fly.py",
        "certificate.json",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    let readme = std::fs::read_to_string(dir.join("README.txt")).unwrap();
    assert!(
        readme.contains("40     follower   40.csv   cf40"),
        "{readme}"
    );
    assert!(
        readme.contains("ros2 launch crazyflie launch.py"),
        "{readme}"
    );
    let cert: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("certificate.json")).unwrap()).unwrap();
    assert_eq!(cert["certificate"]["verdict"], "SAFE", "{cert}");
    assert!(cert["certificate"]["t_threshold_s"].as_f64().unwrap() < 200.0);
    assert_eq!(cert["certificate"]["eps_m"], 0.1);

    let telemetry = reference(&dir.join("scenario.toml"), tmp.path());
    let check = python("check_crazyswarm2.py", &[&dir, &telemetry]);
    assert_eq!(code(&check), Some(0), "{}", describe(&check));
    assert!(String::from_utf8_lossy(&check.stdout).contains("crazyswarm2 ok"));

    // The check can fail: one coefficient off by 1e-5 m is caught.
    let p = dir.join("7.csv");
    let text = std::fs::read_to_string(&p).unwrap();
    let (head, body) = text.split_once('\n').unwrap();
    let mut cells: Vec<String> = body
        .lines()
        .next()
        .unwrap()
        .split(',')
        .map(String::from)
        .collect();
    cells[1] = (cells[1].parse::<f64>().unwrap() + 1e-5).to_string();
    let rest: Vec<&str> = body.lines().skip(1).collect();
    let tampered = format!("{head}\n{}\n{}", cells.join(","), rest.join("\n"));
    std::fs::write(&p, tampered).unwrap();
    let check = python("check_crazyswarm2.py", &[&dir, &telemetry]);
    assert_eq!(code(&check), Some(1), "{}", describe(&check));
}

#[test]
fn skybrush_show_is_the_plan_as_bezier_curves() {
    let tmp = TempDir::new();
    let skyc = tmp.path().join("show.skyc");
    let out = orchestrator(&[
        "export",
        "skybrush",
        "--out",
        skyc.to_str().unwrap(),
        "--scale",
        "0.1",
        "--origin=0,0,-50",
        "--eps",
        "0.5",
        "--quiet",
    ]);
    assert_eq!(code(&out), Some(0), "{}", describe(&out));
    let cert = tmp.path().join("show.certificate.json");
    let telemetry = reference(&tmp.path().join("show.scenario.toml"), tmp.path());
    let check = python("check_skyc.py", &[&skyc, &telemetry, &cert]);
    assert_eq!(code(&check), Some(0), "{}", describe(&check));
    assert!(String::from_utf8_lossy(&check.stdout).contains("skyc ok: 40 drones, 4 segments"));
}

/// A mission is exported whole for both targets: take-off, both segments, the hovers
/// and the landing, read back by cflib and numpy (Crazyswarm2) and the skyc reader against
/// `simulate`'s r_HT of the scaled mission, on the ground (z = 0 scaled stays 0) at the first
/// and the last point, lasting the mission's 200 + 5 + 200 + 5 + 150 + 5 + 150 = 715 s.
#[test]
fn a_mission_is_exported_from_the_ground_to_the_ground() {
    const MISSION_S: f64 = 715.0;
    let tmp = TempDir::new();
    let dir = tmp.path().join("cf");
    let skyc = tmp.path().join("mission.skyc");
    // eps 0.05 m: with a Crazyflie's 0.1 m the take-off at this scale needs 201.48 s > 200 s.
    let source = [
        "--builtin",
        "paper40-mission",
        "--scale",
        "0.01",
        "--eps",
        "0.05",
        "--quiet",
    ];
    let out = orchestrator(
        &[
            &["export", "crazyswarm2", "--out", dir.to_str().unwrap()][..],
            &source[..],
        ]
        .concat(),
    );
    assert_eq!(code(&out), Some(0), "{}", describe(&out));
    let out = orchestrator(
        &[
            &["export", "skybrush", "--out", skyc.to_str().unwrap()][..],
            &source[..],
        ]
        .concat(),
    );
    assert_eq!(code(&out), Some(0), "{}", describe(&out));
    let sky_cert = tmp.path().join("mission.certificate.json");
    for cert in [dir.join("certificate.json"), sky_cert.clone()] {
        let c: serde_json::Value = serde_json::from_slice(&std::fs::read(&cert).unwrap()).unwrap();
        assert_eq!(c["duration_s"].as_f64(), Some(MISSION_S), "{c}");
        assert_eq!(c["certificate"]["verdict"], "SAFE", "{c}");
    }
    let fly = std::fs::read_to_string(dir.join("fly.py")).unwrap();
    assert!(
        fly.contains("T_TOTAL_S = 715") && !fly.contains("goTo"),
        "{fly}"
    );
    // Both exports wrote the same scaled scenario: one reference flight serves both.
    let scenario = std::fs::read(dir.join("scenario.toml")).unwrap();
    assert_eq!(
        scenario,
        std::fs::read(tmp.path().join("mission.scenario.toml")).unwrap()
    );
    let telemetry = reference(&dir.join("scenario.toml"), tmp.path());
    let ground = Path::new("0");
    let check = python("check_crazyswarm2.py", &[&dir, &telemetry, ground]);
    assert_eq!(code(&check), Some(0), "{}", describe(&check));
    let said = String::from_utf8_lossy(&check.stdout).into_owned();
    assert!(
        said.contains("crazyswarm2 ok") && said.contains("715.0 s, from and to the ground"),
        "{said}"
    );
    let check = python("check_skyc.py", &[&skyc, &telemetry, &sky_cert, ground]);
    assert_eq!(code(&check), Some(0), "{}", describe(&check));
    let said = String::from_utf8_lossy(&check.stdout).into_owned();
    assert!(
        said.contains("skyc ok: 40 drones") && said.contains("715.0 s, from and to the ground"),
        "{said}"
    );
}

#[test]
fn single_precision_too_coarse_is_refused_with_both_numbers() {
    // The paper's frame: coordinates near 1 km, where f32 alone is ~1e-4 m and the bound > 1 mm.
    let tmp = TempDir::new();
    let dir = tmp.path().join("native");
    let out = orchestrator(&["export", "crazyswarm2", "--out", dir.to_str().unwrap()]);
    assert_eq!(code(&out), Some(2), "{}", describe(&out));
    let err = stderr(&out);
    assert!(
        err.contains("float32 evaluation cannot stay within 0.001 m"),
        "{err}"
    );
    assert!(
        err.contains("4096 bytes") && err.contains("pieces"),
        "{err}"
    );
    assert!(!dir.join("1.csv").exists());
}

#[test]
fn unsafe_at_the_target_scale_is_refused_unless_forced() {
    // Scale 0.005: D_B = 0.19 m < 2 eps = 0.2 m, so delta <= 0 (eq. 38).
    let tmp = TempDir::new();
    let dir = tmp.path().join("tiny");
    let ds = dir.to_str().unwrap();
    let args = [
        "export",
        "crazyswarm2",
        "--out",
        ds,
        "--scale",
        "0.005",
        "--origin=0,0,-4",
    ];
    let out = orchestrator(&args);
    assert_eq!(code(&out), Some(1), "{}", describe(&out));
    assert!(stderr(&out).contains("UNSAFE"), "{}", describe(&out));
    let cert = std::fs::read_to_string(dir.join("certificate.json")).unwrap();
    assert!(cert.contains("\"verdict\": \"UNSAFE\""), "{cert}");
    assert!(
        !dir.join("1.csv").exists(),
        "files written for an UNSAFE plan"
    );
    let out = orchestrator(&[&args[..], &["--force"]].concat());
    assert_eq!(code(&out), Some(1), "{}", describe(&out));
    assert!(dir.join("1.csv").is_file() && dir.join("crazyflies.yaml").is_file());
}

#[test]
fn bad_flags_are_named() {
    let tmp = TempDir::new();
    let d = tmp.path().join("x");
    let ds = d.to_str().unwrap();
    for (flags, needle) in [
        (&["--scale", "0"][..], "--scale"),
        (&["--scale=-2"][..], "--scale"),
        (&["--origin", "1,2"][..], "--origin"),
        (&["--origin", "1,a,3"][..], "--origin"),
        (&["--eps", "0"][..], "--eps"),
    ] {
        let out = orchestrator(&[&["export", "skybrush", "--out", ds][..], flags].concat());
        assert_eq!(code(&out), Some(2), "{flags:?}: {}", describe(&out));
        assert!(
            stderr(&out).contains(needle),
            "{flags:?}: {}",
            describe(&out)
        );
    }
    let out = orchestrator(&["export", "skybrush", "--out", ds, "--n", "3"]);
    assert_eq!(code(&out), Some(2), "{}", describe(&out));
    assert!(!d.exists(), "nothing written on bad input");
}

/// The fence and the obstacles go with the plan into the target frame: Crazyswarm2's
/// airspace.yaml (PyYAML), the Skybrush show's geofence (as skybrush-server reads it) and the
/// scaled scenario.toml (tomllib) all equal the file's tables mapped by p -> S p + origin.
#[test]
fn the_airspace_goes_with_the_exports_at_their_scale() {
    let tmp = TempDir::new();
    let scenario = write_scenario(tmp.path(), "fenced.toml", &fenced_paper40());
    let (cf, skyc) = (tmp.path().join("cf"), tmp.path().join("show.skyc"));
    for (target, dest) in [("crazyswarm2", &cf), ("skybrush", &skyc)] {
        let args = ["export", target, "--scenario", scenario.to_str().unwrap()];
        let out = orchestrator(&[&args[..], &["--out", dest.to_str().unwrap()], &LAB[..]].concat());
        assert_eq!(code(&out), Some(0), "{target}: {}", describe(&out));
    }
    let readme = std::fs::read_to_string(cf.join("README.txt")).unwrap();
    assert!(readme.contains("airspace.yaml:"), "{readme}");
    let check = |cf: &Path| {
        let args = [&scenario, cf, &skyc].map(|p| p.as_os_str().to_owned());
        let frame = ["0.015", "-1.2", "-2.7", "-7.9"].map(std::ffi::OsString::from);
        let all: Vec<&Path> = args.iter().chain(&frame).map(Path::new).collect();
        python("check_airspace.py", &all)
    };
    let ok = check(&cf);
    assert_eq!(code(&ok), Some(0), "{}", describe(&ok));
    assert!(
        String::from_utf8_lossy(&ok.stdout).contains("airspace ok: 2 obstacles"),
        "{}",
        describe(&ok)
    );
    // The check can fail: a ceiling 1 mm off is caught.
    let yaml = cf.join("airspace.yaml");
    let text = std::fs::read_to_string(&yaml).unwrap();
    let line = text.lines().find(|l| l.starts_with("  max_z_m:")).unwrap();
    let z: f64 = line.split(':').nth(1).unwrap().trim().parse().unwrap();
    let tampered = text.replacen(line, &format!("  max_z_m: {}", z + 1e-3), 1);
    std::fs::write(&yaml, tampered).unwrap();
    let bad = check(&cf);
    assert_eq!(code(&bad), Some(1), "{}", describe(&bad));
}
