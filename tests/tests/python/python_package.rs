//! The `cdm` Python package (python/: PyO3 and maturin) against the orchestrator CLI. The
//! package is installed with pip from the source tree into the test venv of
//! scripts/test-deps.sh (`pip install ./python`, maturin pinned in
//! python/requirements-test.txt, no download), then:
//!
//! - `cdm.plan` and `cdm.simulate` give the CLI's certificate (`plan --json`, byte for byte, and
//!   every typed field equal to it), audit.json as a dict, and telemetry.csv as NumPy columns,
//!   value for value, for paper40, its mission and a fenced paper40
//!   (tests/python/check_cdm_package.py);
//! - `cdm.export` writes the very files of `orchestrator export crazyswarm2` and `export
//!   skybrush`;
//! - bad input raises `cdm.BadInput` with the very message the CLI prints after `error: `;
//! - python/examples/design_sweep.py designs a formation, certifies it and sweeps its travel
//!   time: its deviations and T_threshold are the CLI's `plan --sweep` and `plan --json`
//!   numbers for the scenario it wrote.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;
use std::time::Duration;

use integration_tests::{
    bin, describe, fenced_paper40, python_script, run, venv_python, without_test_variables,
    write_scenario, write_text, TempDir,
};

/// pip building the extension (cargo, incremental over the workspace's build) and installing.
const INSTALL_DEADLINE: Duration = integration_tests::deadline::LONG;
/// A full paper40 flight in one process, from the CLI or Python, and the comparison.
const RUN_DEADLINE: Duration = integration_tests::deadline::FLIGHT;
/// A refusal.
const REFUSE_DEADLINE: Duration = integration_tests::deadline::REFUSE;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The venv's Python with the package installed from this tree, once per test process.
fn python_with_cdm() -> PathBuf {
    static INSTALLED: OnceLock<Result<(), String>> = OnceLock::new();
    let python = venv_python();
    let outcome = INSTALLED.get_or_init(|| {
        // As an activated venv has it: maturin's build hook runs the venv's `maturin`.
        let bin_dir = python.parent().map(Path::to_path_buf).unwrap_or_default();
        let path = std::env::var_os("PATH").unwrap_or_default();
        let path =
            std::env::join_paths(std::iter::once(bin_dir).chain(std::env::split_paths(&path)))
                .unwrap_or(path);
        let mut pip = Command::new(&python);
        // maturin runs cargo on the workspace's build directory, where the module shares the
        // workspace's units: with the test's own CARGO_* variables, build scripts that watch them
        // (ring's) would run again, and the next test's `cargo build` would rebuild what is above.
        without_test_variables(&mut pip);
        let out = run(
            pip.env("PATH", path)
                .args([
                    "-m",
                    "pip",
                    "install",
                    "--quiet",
                    "--disable-pip-version-check",
                    "--no-build-isolation",
                    "--no-deps",
                    "--force-reinstall",
                ])
                .arg(repo().join("python")),
            INSTALL_DEADLINE,
        );
        if out.status.success() {
            Ok(())
        } else {
            Err(describe(&out))
        }
    });
    if let Err(e) = outcome {
        panic!("pip install ./python failed:\n{e}");
    }
    python
}

/// Python in `cwd` (not the source tree: `import cdm` is the installed package).
fn python(cwd: &Path, args: &[&str]) -> Command {
    let mut c = Command::new(python_with_cdm());
    c.current_dir(cwd)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .args(args);
    c
}

fn orchestrator(cwd: &Path, args: &[&str]) -> Output {
    run(
        Command::new(bin("orchestrator"))
            .current_dir(cwd)
            .args(args),
        RUN_DEADLINE,
    )
}

/// `--builtin NAME` or `--scenario FILE` for the CLI, from what the Python side is given.
fn source_args(source: &str) -> [&str; 2] {
    if source.ends_with(".toml") {
        ["--scenario", source]
    } else {
        ["--builtin", source]
    }
}

/// The CLI's plan and flight of `source`, then the package's, compared by the check script.
fn same_as_cli(source: &str, tmp: &TempDir) -> String {
    let dir = tmp.path();
    let src = source_args(source);
    let plan = orchestrator(
        dir,
        &["--quiet", "plan", src[0], src[1], "--json", "plan.json"],
    );
    assert!(
        plan.status.code().is_some_and(|c| c <= 1),
        "{}",
        describe(&plan)
    );
    let sim = orchestrator(
        dir,
        &[
            "--quiet",
            "simulate",
            src[0],
            src[1],
            "--out",
            "cli-run",
            "--no-figures",
        ],
    );
    assert!(
        sim.status.code().is_some_and(|c| c <= 1),
        "{}",
        describe(&sim)
    );
    let check = python_script("check_cdm_package.py");
    let out = run(
        &mut python(
            dir,
            &[
                check.to_str().unwrap_or_default(),
                "same",
                source,
                "cli-run",
                "plan.json",
            ],
        ),
        RUN_DEADLINE,
    );
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn plan_and_simulate_equal_the_cli_for_paper40() {
    let tmp = TempDir::new();
    let line = same_as_cli("paper40", &tmp);
    assert!(
        line.starts_with(
            "same paper40: verdict SAFE, certificate SAFE with 0 phase(s), 800040 telemetry rows"
        ),
        "{line}"
    );
}

#[test]
fn plan_and_simulate_equal_the_cli_for_a_mission() {
    let tmp = TempDir::new();
    let line = same_as_cli("paper40-mission", &tmp);
    // Take-off, the paper's descent, the turn and landing, each certified.
    assert!(
        line.contains("certificate SAFE with 4 phase(s), 2900040 telemetry rows"),
        "{line}"
    );
}

#[test]
fn plan_and_simulate_equal_the_cli_with_a_geofence_and_obstacles() {
    let tmp = TempDir::new();
    write_scenario(tmp.path(), "fenced.toml", &fenced_paper40());
    let line = same_as_cli("fenced.toml", &tmp);
    assert!(line.contains("certificate SAFE"), "{line}");
}

#[test]
fn export_writes_the_files_of_the_cli() {
    let tmp = TempDir::new();
    let dir = tmp.path();
    let check = python_script("check_cdm_package.py");
    let check = check.to_str().unwrap_or_default();
    for (target, cli_out, py_out) in [
        ("crazyswarm2", "cli-cf", "py-cf"),
        ("skybrush", "cli/show.skyc", "py/show.skyc"),
    ] {
        let cli = orchestrator(
            dir,
            &[
                "--quiet",
                "export",
                target,
                "--builtin",
                "paper40",
                "--scale",
                "0.01",
                "--out",
                cli_out,
            ],
        );
        assert_eq!(cli.status.code(), Some(0), "{}", describe(&cli));
        let py = run(
            &mut python(dir, &[check, "export", "paper40", target, py_out, "0.01"]),
            RUN_DEADLINE,
        );
        assert_eq!(py.status.code(), Some(0), "{}", describe(&py));
        // cdm.export prints nothing: the script's own line is all of standard output.
        let text = String::from_utf8_lossy(&py.stdout);
        assert_eq!(text, "export SAFE True\n", "{text}");
    }
    // Crazyswarm2: every file the CLI wrote, byte for byte.
    let names = |d: &str| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir.join(d))
            .expect("export directory")
            .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
            .collect();
        v.sort();
        v
    };
    let files = names("cli-cf");
    assert_eq!(files, names("py-cf"));
    assert!(files.len() > 40, "{files:?}");
    for f in &files {
        let a = std::fs::read(dir.join("cli-cf").join(f)).expect("read");
        let b = std::fs::read(dir.join("py-cf").join(f)).expect("read");
        assert!(
            a == b,
            "{f} differs between the CLI's export and cdm.export"
        );
    }
    // Skybrush: the show and the certificate beside it.
    for f in ["show.skyc", "show.certificate.json", "show.scenario.toml"] {
        let read = |d: &str| std::fs::read(dir.join(d).join(f)).expect("read");
        assert!(read("cli") == read("py"), "{f} differs");
    }
}

/// The CLI's refusal (exit 2, `error: MESSAGE`) and the package's (`BadInput: MESSAGE`).
fn refusals(dir: &Path, cli: &[&str], call: &[&str]) -> (String, String) {
    let out = run(
        Command::new(bin("orchestrator")).current_dir(dir).args(cli),
        REFUSE_DEADLINE,
    );
    assert_eq!(out.status.code(), Some(2), "{}", describe(&out));
    // The message may span lines (a TOML parse error shows the line at fault).
    let err = String::from_utf8_lossy(&out.stderr);
    let cli_message = err
        .find("error: ")
        .map(|at| err[at + "error: ".len()..].trim_end().to_string())
        .unwrap_or_else(|| panic!("no `error: ` line\n{}", describe(&out)));
    let check = python_script("check_cdm_package.py");
    let mut args = vec![check.to_str().unwrap_or_default(), "refuse"];
    args.extend_from_slice(call);
    let py = run(&mut python(dir, &args), REFUSE_DEADLINE);
    assert_eq!(py.status.code(), Some(0), "{}", describe(&py));
    let py_message = String::from_utf8_lossy(&py.stdout).trim_end().to_string();
    (format!("BadInput: {cli_message}"), py_message)
}

#[test]
fn bad_input_raises_with_the_cli_message() {
    let tmp = TempDir::new();
    let dir = tmp.path();
    let mut broken = fenced_paper40();
    broken.eps_m = -1.0;
    write_scenario(dir, "negative_eps.toml", &broken);
    write_text(dir, "not_toml.toml", "name = \"x\"\nagents = [[[\n");
    std::fs::create_dir_all(dir.join("taken")).expect("mkdir");
    write_text(&dir.join("taken"), "keep.txt", "not a run\n");
    let cases: [(&[&str], &[&str]); 6] = [
        (
            &["plan", "--scenario", "missing.toml"],
            &["load", "missing.toml"],
        ),
        (
            &["plan", "--scenario", "negative_eps.toml"],
            &["plan", "negative_eps.toml"],
        ),
        (
            &["plan", "--scenario", "not_toml.toml"],
            &["load", "not_toml.toml"],
        ),
        (&["plan", "--builtin", "paper41"], &["load", "paper41"]),
        (&["plan", "--n", "3"], &["generated", "3"]),
        (
            &["simulate", "--builtin", "paper40", "--out", "taken"],
            &["simulate", "paper40", "taken"],
        ),
    ];
    for (cli, call) in cases {
        let (want, got) = refusals(dir, cli, call);
        assert_eq!(got, want, "orchestrator {cli:?} and cdm {call:?}");
    }
    // Nothing was written into the refused run directory.
    let names: Vec<_> = std::fs::read_dir(dir.join("taken"))
        .expect("read taken")
        .filter_map(|e| e.ok().map(|e| e.file_name()))
        .collect();
    assert_eq!(names, ["keep.txt"]);
}

/// `KEY value...` lines of the example's output.
fn lines_of<'a>(text: &'a str, key: &str) -> Vec<&'a str> {
    text.lines()
        .filter_map(|l| l.strip_prefix(key).and_then(|r| r.strip_prefix(' ')))
        .collect()
}

#[test]
fn the_example_designs_certifies_and_sweeps_as_the_cli_does() {
    let tmp = TempDir::new();
    let dir = tmp.path();
    let example = repo()
        .join("python")
        .join("examples")
        .join("design_sweep.py");
    let out = run(
        &mut python(
            dir,
            &[
                example.to_str().unwrap_or_default(),
                "--out",
                "design",
                "--sweep",
                "4:40:4",
            ],
        ),
        RUN_DEADLINE,
    );
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        lines_of(&text, "verdict")
            .first()
            .is_some_and(|l| l.starts_with("SAFE ")),
        "{text}"
    );
    // The CLI on the scenario the example designed and saved.
    let plan = orchestrator(
        dir,
        &[
            "--quiet",
            "plan",
            "--scenario",
            "design/design.toml",
            "--json",
            "plan.json",
            "--sweep",
            "4:40:4",
            "--out",
            "cli-sweep",
        ],
    );
    assert_eq!(plan.status.code(), Some(0), "{}", describe(&plan));
    let csv = std::fs::read_to_string(dir.join("cli-sweep").join("fig_deviation_sweep.csv"))
        .expect("the CLI's sweep data");
    let cli: Vec<(f64, f64)> = csv.lines().skip(1).map(pair).collect();
    let py: Vec<(f64, f64)> = lines_of(&text, "T")
        .into_iter()
        .map(|l| pair(&l.replace(" deviation ", ",")))
        .collect();
    assert_eq!(cli.len(), 10, "{csv}");
    assert_eq!(
        bits(&py),
        bits(&cli),
        "the example's sweep differs from `plan --sweep`\n{text}\n{csv}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("plan.json")).expect("plan.json"))
            .expect("plan.json is JSON");
    let threshold: f64 = lines_of(&text, "T_threshold")[0]
        .parse()
        .expect("T_threshold");
    assert_eq!(
        Some(threshold.to_bits()),
        json["t_threshold_s"].as_f64().map(f64::to_bits),
        "{text}"
    );
    // Its flight: SAFE, the audit's largest follower deviation seen in its telemetry too.
    let flight = lines_of(&text, "flight");
    let words: Vec<&str> = flight.first().map_or(vec![], |l| l.split(' ').collect());
    assert!(
        words.len() == 7 && words[0] == "SAFE" && words[4] == words[6],
        "{text}"
    );
    // The figure only when matplotlib is there; the data always.
    assert!(dir.join("design").join("sweep.csv").is_file());
    let plotted = dir.join("design").join("sweep.png").is_file();
    assert!(
        plotted != text.contains("plot skipped: matplotlib is not installed"),
        "{text}"
    );
}

fn pair(line: &str) -> (f64, f64) {
    let (a, b) = line
        .split_once(',')
        .unwrap_or_else(|| panic!("no pair in {line:?}"));
    (
        a.trim().parse().unwrap_or_else(|_| panic!("{line:?}")),
        b.trim().parse().unwrap_or_else(|_| panic!("{line:?}")),
    )
}

fn bits(points: &[(f64, f64)]) -> Vec<(u64, u64)> {
    points
        .iter()
        .map(|(a, b)| (a.to_bits(), b.to_bits()))
        .collect()
}
