//! `orchestrator export rosbag2` and `--telemetry mcap` (issue 29): the bag of a run, read by
//! code nobody here wrote. `rosbags` opens the rosbag2 directory and decodes every message with
//! its ROS 2 Humble typestore (one PoseStamped topic per member with one message per telemetry
//! row, the last pose equal to telemetry to 1e-6 m; /tf, the MarkerArray, the margins), Foxglove's
//! `mcap` reads the summary, the schemas (equal to the ROS 2 definitions) and the channels; a
//! fenced paper40's geofence and obstacles are markers where its scenario.toml puts them. The
//! bag written during a run (`simulate` and `launch --telemetry mcap`) equals, message for
//! message, the export of that run. A bad RUN_DIR or an existing --out exits 2 naming it.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{
    bin, describe, fenced_paper40, launch, python_script, run, simulate, unique_team, venv_python,
    write_scenario, TempDir,
};

const DEADLINE: Duration = integration_tests::deadline::FLIGHT;
/// A small team over a short plan; member 9 (a follower) is lost at 2 s, so ticks after it have
/// fewer rows, frames and spheres.
const TEAM: [&str; 5] = ["--n", "10", "--t-total", "5", "--no-figures"];
const LOSS: [&str; 2] = ["--lose", "9@2"];

fn orchestrator(args: &[&str]) -> Output {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    run(&mut c, DEADLINE)
}

fn export(run_dir: &Path, out: &Path, extra: &[&str]) -> Output {
    let (r, o) = (run_dir.to_str().unwrap(), out.to_str().unwrap());
    orchestrator(&[&["export", "rosbag2", r, "--out", o][..], extra].concat())
}

/// Fly the team; at --t-total 5 the followers lag behind their plan (UNSAFE, exit 1): the bag
/// shows a run whatever its verdict.
fn fly(out: &Path, extra: &[&str]) {
    let o = run(&mut simulate(out, &[&TEAM[..], extra].concat()), DEADLINE);
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", describe(&o));
}

/// Run the checker; its output names what failed.
fn check(mode: &str, a: &Path, b: &Path) {
    let mut c = Command::new(venv_python());
    c.arg(python_script("check_rosbag2.py"))
        .args([mode.as_ref(), a.as_os_str(), b.as_os_str()])
        .env("PYTHONDONTWRITEBYTECODE", "1");
    let out = run(&mut c, DEADLINE);
    assert!(out.status.success(), "{}", describe(&out));
}

#[test]
fn export_of_a_csv_run_is_read_by_rosbags_and_mcap() {
    let tmp = TempDir::new();
    let (run_dir, bag) = (tmp.path().join("run"), tmp.path().join("bag"));
    fly(&run_dir, &LOSS);
    let out = export(&run_dir, &bag, &[]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    assert!(bag.join("metadata.yaml").is_file() && bag.join("bag_0.mcap").is_file());
    check("check", &bag, &run_dir);
}

/// paper40 in its airspace (issue 27): the fence and the obstacles are markers too.
#[test]
fn export_of_a_parquet_run_with_every_is_read_by_rosbags_and_mcap() {
    let tmp = TempDir::new();
    let (run_dir, bag) = (tmp.path().join("run"), tmp.path().join("bag"));
    let fenced = write_scenario(tmp.path(), "fenced.toml", &fenced_paper40());
    let source = ["--scenario", fenced.to_str().unwrap(), "--max-ticks", "300"];
    let flags = ["--no-figures", "--telemetry", "parquet", "--every", "3"];
    let o = run(
        &mut simulate(&run_dir, &[&source[..], &flags[..]].concat()),
        DEADLINE,
    );
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let out = export(&run_dir, &bag, &["--quiet"]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    check("check", &bag, &run_dir);
}

#[test]
fn simulate_telemetry_mcap_equals_the_export_of_the_run() {
    let tmp = TempDir::new();
    let (run_dir, bag) = (tmp.path().join("run"), tmp.path().join("exported"));
    fly(
        &run_dir,
        &[&LOSS[..], &["--telemetry", "mcap", "--every", "2"]].concat(),
    );
    let live = run_dir.join("rosbag2");
    check("check", &live, &run_dir);
    let out = export(&run_dir, &bag, &["--quiet"]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    check("equal", &live, &bag);
    // A run reusing the directory in another format leaves no bag of the earlier run behind.
    fly(&run_dir, &["--force"]);
    assert!(!live.exists(), "{} left by the earlier run", live.display());
}

#[test]
fn launch_telemetry_mcap_equals_the_export_of_the_run() {
    let tmp = TempDir::new();
    let (run_dir, bag) = (tmp.path().join("run"), tmp.path().join("exported"));
    let team = unique_team("rosbag");
    let args = [&TEAM[..], &["--telemetry", "mcap"]].concat();
    let o = run(&mut launch(&team, &run_dir, &args), DEADLINE);
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", describe(&o));
    let live = run_dir.join("rosbag2");
    check("check", &live, &run_dir);
    let out = export(&run_dir, &bag, &["--quiet"]);
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    check("equal", &live, &bag);
}

fn refused(out: &Output, names: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{}", describe(out));
    assert!(err.contains(names), "stderr should name {names}: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_run_dirs_and_an_existing_out_exit_2_naming_them() {
    let tmp = TempDir::new();
    let (run_dir, bag) = (tmp.path().join("run"), tmp.path().join("bag"));
    refused(&export(&tmp.path().join("nowhere"), &bag, &[]), "nowhere");
    fly(&run_dir, &[]);
    // An existing, non-empty --out is not overwritten without --force.
    std::fs::create_dir_all(&bag).unwrap();
    std::fs::write(bag.join("mine.txt"), "keep").unwrap();
    refused(&export(&run_dir, &bag, &[]), "--out");
    let forced = export(&run_dir, &bag, &["--force", "--quiet"]);
    assert_eq!(forced.status.code(), Some(0), "{}", describe(&forced));
    assert!(bag.join("mine.txt").is_file() && bag.join("metadata.yaml").is_file());
    // Broken files of the run: each named, and no partial bag left.
    let csv = run_dir.join("telemetry.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    std::fs::write(&csv, text.replacen(",follower,", ",follower,oops", 1)).unwrap();
    let partial = tmp.path().join("partial");
    refused(&export(&run_dir, &partial, &[]), "telemetry.csv");
    assert!(!partial.exists(), "a partial bag was left");
    std::fs::write(run_dir.join("audit.json"), "{").unwrap();
    refused(&export(&run_dir, &partial, &[]), "audit.json");
    std::fs::write(run_dir.join("scenario.toml"), "n = ").unwrap();
    refused(&export(&run_dir, &partial, &[]), "scenario.toml");
}
