//! Bad input, refused with exit 2 and a message naming what is at fault, never with a panic.
//!
//! - The command line: unknown flags, missing values, team sizes outside 4..=2000, bad numbers,
//!   durations and names, an --out that is not empty or cannot be written, a launch without the
//!   member binaries, `--follow` and `--sweep`. Each is refused before anything is written: no
//!   run directory, no shared memory of the team.
//! - Special files (/dev/zero, a FIFO) where a regular file is read.
//! - Scenario files: `orchestrator plan --scenario FILE` refuses every kind of bad scenario with
//!   an `error:` line that names the file and the agent(s) or field at fault. Each test starts
//!   from the paper's 40-agent scenario (`paper40`: primary leaders 1-3, secondary leaders 4-6,
//!   followers 7-40) and breaks one thing, or writes raw TOML for parse errors. The expected
//!   phrases are those of `cdm_scenario` (`mod.rs`, `validate.rs`) and
//!   `cdm_model::formation`.
//! - A hand-started team that does not assemble: the launch names the members that did not join.
//!
//! (Full disks and closed pipes: `hardening_files.rs`; property tests of the parser:
//! `common/scenario/tests/proptest.rs`.)

use integration_tests::support;

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use cdm_model::formation::Role;
use cdm_scenario::{AgentSpec, ScenarioFile};
use integration_tests::{
    bin, describe, paper40, run, scenario_toml, spawn, unique_team, write_scenario, write_text,
    TempDir,
};
use support::{
    assert_exit, assert_no_team_resources, assert_stderr_has, files_under, launch, member,
    read_json, simulate, toml_value,
};

/// A refusal on the command line happens before any work; the deadline only keeps a hang from
/// stalling CI.
const CLI_DEADLINE: Duration = integration_tests::deadline::REFUSE;
/// A refusal that reads a file first (a scenario, /dev/zero, a FIFO) takes milliseconds, and a
/// 10-agent team with a 30 s plan flies in about a second: the deadline only stops a hang.
const SHORT_DEADLINE: Duration = integration_tests::deadline::SHORT;
/// A valid file is planned in full (a few seconds to tens of seconds in release).
const PLAN_DEADLINE: Duration = integration_tests::deadline::FLIGHT;

fn command(binary: &str, args: &[&str]) -> Command {
    let mut c = Command::new(bin(binary));
    c.args(args);
    c
}

/// Runs `c` within `deadline` and asserts exit 2, no panic, and every needle in stderr.
fn refused_within(c: &mut Command, deadline: Duration, needles: &[&str]) -> Output {
    let what = format!("{c:?}");
    let o = run(c, deadline);
    assert!(
        !String::from_utf8_lossy(&o.stderr).contains("panicked"),
        "{what} panicked:\n{}",
        describe(&o)
    );
    assert_exit(&o, 2, &what);
    assert_stderr_has(&o, &what, needles);
    o
}

/// Runs `binary args` and asserts exit 2 with every needle in stderr and nothing on stdout.
fn refused(binary: &str, args: &[&str], needles: &[&str]) -> Output {
    let o = refused_within(&mut command(binary, args), CLI_DEADLINE, needles);
    let what = format!("{binary} {}", args.join(" "));
    assert!(
        o.stdout.is_empty(),
        "{what}: wrote to stdout\n{}",
        describe(&o)
    );
    o
}

/// Runs `c`, which may read a file first, and asserts exit 2 with every needle in stderr.
fn refused_cmd(c: &mut Command, needles: &[&str]) -> Output {
    refused_within(c, SHORT_DEADLINE, needles)
}

/// Every file under `dir` with its contents.
fn contents(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    files_under(dir)
        .into_iter()
        .filter(|p| p.is_file())
        .map(|p| {
            let bytes = std::fs::read(&p).expect("read");
            (p, bytes)
        })
        .collect()
}

fn fifo(path: &Path) {
    let c = std::ffi::CString::new(path.to_str().expect("UTF-8")).expect("path");
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0, "mkfifo");
}

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn scale(a: V3, k: f64) -> V3 {
    [a[0] * k, a[1] * k, a[2] * k]
}

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn unit(a: V3) -> V3 {
    scale(a, 1.0 / dot(a, a).sqrt())
}

/// The agent with this id.
fn agent(f: &mut ScenarioFile, id: u32) -> &mut AgentSpec {
    f.agents
        .iter_mut()
        .find(|a| a.id == id)
        .unwrap_or_else(|| panic!("scenario `{}` has no agent {id}", f.name))
}

/// Positions of the three primary leaders, in file order.
fn primaries(f: &ScenarioFile) -> [V3; 3] {
    let p: Vec<V3> = f
        .agents
        .iter()
        .filter(|a| a.role == Role::Primary)
        .map(|a| a.position)
        .collect();
    assert_eq!(p.len(), 3, "paper40 must have 3 primary leaders");
    [p[0], p[1], p[2]]
}

/// Unit normal of the primary leaders' plane.
fn plane_normal(f: &ScenarioFile) -> V3 {
    let [r1, r2, r3] = primaries(f);
    unit(cross(sub(r2, r1), sub(r3, r1)))
}

/// Centroid of the primary leaders (on their plane, inside every leader's hull).
fn primary_centroid(f: &ScenarioFile) -> V3 {
    let [r1, r2, r3] = primaries(f);
    scale(add(add(r1, r2), r3), 1.0 / 3.0)
}

/// Barycentric weights of `p` in the triangle `t`, measured in the plane with normal `n`.
fn weights(p: V3, t: [V3; 3], n: V3) -> V3 {
    let area = |a: V3, b: V3, c: V3| dot(cross(sub(b, a), sub(c, a)), n);
    let total = area(t[0], t[1], t[2]);
    [
        area(p, t[1], t[2]) / total,
        area(t[0], p, t[2]) / total,
        area(t[0], t[1], p) / total,
    ]
}

/// `orchestrator plan --scenario path`. `RUST_LOG` is cleared so that the notes the tool logs
/// at its default level (projections) appear whatever the caller's environment says.
fn plan_command(path: &Path) -> Command {
    let mut c = Command::new(bin("orchestrator"));
    c.arg("plan")
        .arg("--scenario")
        .arg(path)
        .env_remove("RUST_LOG");
    c
}

fn plan(path: &Path, deadline: Duration) -> Output {
    run(&mut plan_command(path), deadline)
}

/// `orchestrator plan` must refuse `path` with exit code 2, no panic, and an `error:` line
/// naming the file; that line (with any continuation lines, as a TOML parse error has) must
/// contain every phrase in `expected`.
fn assert_refused(path: &Path, expected: &[&str]) {
    let out = refused_within(&mut plan_command(path), SHORT_DEADLINE, &[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let origin = format!("{}: ", path.display());
    let start = stderr
        .lines()
        .position(|l| l.starts_with("error:") && l.contains(&origin))
        .unwrap_or_else(|| {
            panic!(
                "no stderr line starts with `error:` and names {:?}:\n{}",
                origin,
                describe(&out)
            )
        });
    let message: Vec<&str> = stderr.lines().skip(start).collect();
    let message = message.join("\n");
    for phrase in expected {
        assert!(
            message.contains(phrase),
            "the error for {} does not contain {phrase:?}:\n{}",
            path.display(),
            describe(&out)
        );
    }
}

/// Write `file` as `name` in a fresh directory and assert `plan` refuses it with `expected`.
fn assert_scenario_refused(name: &str, file: &ScenarioFile, expected: &[&str]) {
    let dir = TempDir::new();
    let path = write_scenario(dir.path(), name, file);
    assert_refused(&path, expected);
}

/// The 1-based number of the first line of `text` that starts with `prefix`.
fn line_of(text: &str, prefix: &str) -> usize {
    text.lines()
        .position(|l| l.starts_with(prefix))
        .map(|k| k + 1)
        .unwrap_or_else(|| panic!("no line starts with {prefix:?}:\n{text}"))
}

/// paper40's TOML as a table, for edits the typed file cannot express (unknown keys).
fn paper40_table() -> toml::Table {
    toml::from_str(&scenario_toml(&paper40()))
        .unwrap_or_else(|e| panic!("paper40 does not round-trip through TOML: {e}"))
}

// ---- the command line ------------------------------------------------------------------------

/// Unknown flags, missing values and values of the wrong type, for the orchestrator and the
/// member binaries: exit 2 naming the argument.
#[test]
fn unknown_flags_and_missing_or_malformed_values_are_refused() {
    let cases: &[(&str, &[&str], &[&str])] = &[
        ("orchestrator", &["launch", "--bogus"], &["'--bogus'"]),
        ("orchestrator", &["fly"], &["'fly'"]),
        ("orchestrator", &["launch", "--n"], &["'--n <N>'"]),
        (
            "orchestrator",
            &["launch", "--n", "ten"],
            &["'ten'", "'--n <N>'"],
        ),
        ("orchestrator", &["launch", "--out"], &["'--out <DIR>'"]),
        (
            "orchestrator",
            &["launch", "--scenario", "a.toml", "--n", "10"],
            &["'--scenario <FILE>'", "'--n <N>'"],
        ),
        ("orchestrator", &["plan", "--window", "2"], &["'--window'"]),
        ("agent", &["--bogus"], &["'--bogus'"]),
        (
            "agent",
            &["--team", "t"],
            &["--scenario <FILE>", "--id <ID>"],
        ),
        (
            "leader",
            &["--scenario", "s.toml", "--team", "t", "--id", "one"],
            &["'one'", "'--id <ID>'"],
        ),
    ];
    for (binary, args, needles) in cases {
        refused(binary, args, needles);
    }
}

/// Generated teams must have 4 to 2000 agents, in every command that takes `--n`.
#[test]
fn team_sizes_outside_4_to_2000_are_refused() {
    let dir = TempDir::new();
    for n in ["0", "3", "2001", "1000000"] {
        let out = dir.path().join(format!("out{n}"));
        let out = out.to_str().expect("UTF-8 path");
        let needle = if n == "2001" || n == "1000000" {
            format!("field `--n` must be at most 2000, got {n}")
        } else {
            format!("field `--n` must be at least 4 (3 primary leaders and a follower), got {n}")
        };
        for args in [
            vec!["plan", "--n", n],
            vec!["simulate", "--n", n, "--out", out],
            vec!["launch", "--n", n, "--out", out],
            vec!["scenario", "export", "--n", n],
        ] {
            refused("orchestrator", &args, &[&needle]);
            assert!(!Path::new(out).exists(), "{args:?} wrote {out}");
        }
    }
    refused("orchestrator", &["launch", "--n", "-4"], &["'-4'"]);
    // The bounds themselves are accepted: a 4- and a 2000-agent team are generated (acyclic
    // graph, spectrum of L by components: well under a second each).
    for n in ["4", "2000"] {
        let file = dir.path().join(format!("team{n}.toml"));
        let mut cmd = Command::new(bin("orchestrator"));
        cmd.args(["scenario", "export", "--n", n, "--out"])
            .arg(&file);
        let o = run(&mut cmd, integration_tests::deadline::SHORT);
        assert_eq!(o.status.code(), Some(0), "export --n {n}\n{}", describe(&o));
        let text = std::fs::read_to_string(&file).expect("exported file");
        let agents = text.matches("[[agents]]").count();
        assert_eq!(
            agents.to_string(),
            n,
            "export --n {n} wrote {agents} agents"
        );
    }
}

/// Numbers and names the types accept but the tool does not: exit 2 naming the option.
#[test]
fn bad_numbers_and_names_are_refused_naming_the_option() {
    let dir = TempDir::new();
    let out = dir.path().join("run");
    let out = out.to_str().expect("UTF-8 path");
    let team = unique_team("badnum");
    let long = "x".repeat(49);
    let cases: &[(&[&str], &str)] = &[
        (
            &["--agent-timeout", "-1"],
            "--agent-timeout must be a number of seconds in (0, 86400], got -1",
        ),
        (
            &["--agent-timeout", "0"],
            "--agent-timeout must be a number of seconds in (0, 86400], got 0",
        ),
        (
            &["--agent-timeout", "nan"],
            "--agent-timeout must be a number of seconds in (0, 86400], got NaN",
        ),
        (
            &["--join-timeout", "inf"],
            "--join-timeout must be a number of seconds in (0, 86400], got inf",
        ),
        (
            &["--window", "0"],
            "'--window <WINDOW>': 0 is not in 1..=4096",
        ),
        (
            &["--window", "4097"],
            "'--window <WINDOW>': 4097 is not in 1..=4096",
        ),
        (&["--every", "0"], "'--every <K>': 0 is not in 1.."),
        (
            &["--t-total", "-5"],
            "field `t_total_s` must be > 0, got -5",
        ),
        (&["--t-total", "nan"], "field `t_total_s`"),
        (
            &["--team", "a/b"],
            "--team: invalid team name \"a/b\": only A-Z",
        ),
        (
            &["--team", ""],
            "--team: invalid team name \"\": it is empty",
        ),
        (&["--team", &long], "it is longer than 48 characters"),
    ];
    for (extra, needle) in cases {
        let mut args = vec!["launch", "--n", "10", "--out", out];
        if !extra.contains(&"--team") {
            args.extend(["--team", &team]);
        }
        args.extend(extra.iter());
        refused("orchestrator", &args, &[needle]);
        assert!(!Path::new(out).exists(), "{args:?} wrote {out}");
    }
    assert_no_team_resources(&team);
    for (flag, v) in [("--silence-timeout", "-2"), ("--join-timeout", "0")] {
        let args = ["--scenario", "s.toml", "--team", "t", "--id", "1", flag, v];
        refused(
            "agent",
            &args,
            &[&format!(
                "{flag} must be a number of seconds in (0, 86400], got {v}"
            )],
        );
    }
}

/// `launch --out` naming a directory that exists and is not empty: refused (exit 2) and left
/// byte for byte as it was, without any shared memory of the team; with --force it flies.
#[test]
fn launch_refuses_a_non_empty_out_unless_forced() {
    let dir = TempDir::new();
    let team = unique_team("nonempty");
    let out = dir.path().join("run");
    std::fs::create_dir_all(out.join("sub")).expect("mkdir");
    std::fs::write(out.join("notes.txt"), "keep me\n").expect("write");
    std::fs::write(out.join("telemetry.csv"), "not ours\n").expect("write");
    let before = contents(&out);
    let out_s = out.to_str().expect("UTF-8 path");
    let args = [
        "launch",
        "--n",
        "10",
        "--t-total",
        "30",
        "--team",
        &team,
        "--out",
        out_s,
    ];
    refused(
        "orchestrator",
        &args,
        &[&format!(
            "--out {out_s}: exists and is not empty (use --force to overwrite)"
        )],
    );
    assert_eq!(contents(&out), before, "the refused launch changed {out_s}");
    assert_no_team_resources(&team);

    let mut forced = args.to_vec();
    forced.extend(["--force", "--quiet"]);
    let o = run(&mut command("orchestrator", &forced), SHORT_DEADLINE);
    assert_exit(&o, 0, "launch --force");
    assert_eq!(
        std::fs::read(out.join("notes.txt")).expect("notes.txt"),
        b"keep me\n",
        "--force removed a file that is not the tool's"
    );
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["complete"], true, "{audit:#}");
    assert_no_team_resources(&team);
}

/// An export never overwrites: a file at a Skybrush export's --out, or a non-empty directory at
/// a Crazyswarm2 export's, is refused with exit 2 and left as it was, unless --force; an empty
/// directory is used.
#[test]
fn export_refuses_an_existing_out_unless_forced() {
    let dir = TempDir::new();
    let show = dir.path().join("show.skyc");
    std::fs::write(&show, "an unrelated file\n").expect("write");
    let show_s = show.to_str().expect("UTF-8 path");
    let sky = [
        "export", "skybrush", "--n", "10", "--scale", "0.05", "--out", show_s,
    ];
    refused_cmd(
        &mut command("orchestrator", &sky),
        &[&format!(
            "--out {show_s}: exists (use --force to overwrite)"
        )],
    );
    assert_eq!(std::fs::read(&show).expect("show"), b"an unrelated file\n");
    let cs = dir.path().join("cs");
    std::fs::create_dir(&cs).expect("mkdir");
    std::fs::write(cs.join("notes.txt"), "keep me\n").expect("write");
    let before = contents(&cs);
    let cs_s = cs.to_str().expect("UTF-8 path");
    let crazy = [
        "export",
        "crazyswarm2",
        "--n",
        "10",
        "--scale",
        "0.05",
        "--out",
        cs_s,
    ];
    refused_cmd(
        &mut command("orchestrator", &crazy),
        &[&format!(
            "--out {cs_s}: exists and is not empty (use --force to overwrite)"
        )],
    );
    assert_eq!(contents(&cs), before, "the refused export changed {cs_s}");
    let mut forced = sky.to_vec();
    forced.extend(["--force", "--quiet"]);
    let o = run(&mut command("orchestrator", &forced), PLAN_DEADLINE);
    assert_exit(&o, 0, "export skybrush --force");
    let zip = std::fs::read(&show).expect("the forced show");
    assert!(zip.starts_with(b"PK"), "--force wrote a .skyc (a ZIP)");
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).expect("mkdir");
    let into_empty = [
        "export",
        "crazyswarm2",
        "--n",
        "10",
        "--scale",
        "0.05",
        "--quiet",
        "--out",
    ];
    let o = run(
        command("orchestrator", &into_empty).arg(&empty),
        PLAN_DEADLINE,
    );
    assert_exit(&o, 0, "export crazyswarm2 into an empty directory");
}

/// Scales that no vehicle flies (and that lose the digits the certificate needs) are refused
/// naming the range, not blamed on the formation.
#[test]
fn export_scales_out_of_range_are_refused_naming_the_limit() {
    let dir = TempDir::new();
    for scale in ["1e300", "1e-9"] {
        let out = dir.path().join(format!("s{scale}.skyc"));
        let o = refused_cmd(
            command(
                "orchestrator",
                &["export", "skybrush", "--n", "10", "--scale", scale],
            )
            .arg("--out")
            .arg(&out),
            &["is out of range", "[1e-4, 1e4]"],
        );
        assert!(
            !String::from_utf8_lossy(&o.stderr).contains("collinear"),
            "{}",
            describe(&o)
        );
        assert!(!out.exists(), "a refused export wrote {}", out.display());
    }
}

/// Scripted losses the runtime cannot fly as asked are refused up front, the same in every
/// mode: losing every member (nobody left to fly; simulate called it SAFE while the processes
/// stopped on "no state"), and --lose in real time over several hosts (real time repairs a
/// loss on one host only).
#[test]
fn scripted_losses_that_cannot_be_flown_are_refused() {
    let dir = TempDir::new();
    let every: Vec<String> = (1..=10).map(|id| format!("{id}@10")).collect();
    for cmd in ["simulate", "launch"] {
        let out = dir.path().join(format!("{cmd}-all"));
        let mut args = vec![cmd, "--n", "10", "--t-total", "30", "--quiet", "--out"];
        args.push(out.to_str().expect("UTF-8 path"));
        for l in &every {
            args.extend(["--lose", l]);
        }
        refused(
            "orchestrator",
            &args,
            &["--lose names all 10 agents of the team: nobody would be left to fly the plan"],
        );
        assert!(!out.join("audit.json").exists(), "{cmd} wrote an audit");
    }
    let team = unique_team("rtlose");
    let out = dir.path().join("rt");
    let o = refused_cmd(
        integration_tests::launch(&team, &out, &["--n", "10"]).args([
            "--realtime",
            "--hosts",
            "2",
            "--lose",
            "8@5",
        ]),
        &["--lose with --realtime needs one host"],
    );
    assert!(o.stdout.is_empty(), "{}", describe(&o));
    assert_no_team_resources(&team);
}

/// An --out that cannot be created (under a regular file; in /proc) or written (a file in
/// /proc's read-only tree): refused with exit 2 naming --out, nothing written, no shared memory
/// left. (Tests run as root, where permission bits do not stop writes: these paths fail for
/// everyone.)
#[test]
fn an_unwritable_out_is_refused_and_nothing_is_written() {
    let dir = TempDir::new();
    let file = dir.path().join("a-file");
    std::fs::write(&file, "x\n").expect("write");
    let under_file = file.join("run");
    let under_file = under_file.to_str().expect("UTF-8 path");
    let in_proc = format!("/proc/cdm-test-{}", std::process::id());
    let team = unique_team("unwritable");
    for (out, why) in [
        (
            under_file,
            "cannot create the run directory: Not a directory",
        ),
        (in_proc.as_str(), "cannot create the run directory"),
        ("/proc/sys", "cannot write into the run directory"),
    ] {
        let force = if out == "/proc/sys" {
            "--force"
        } else {
            "--quiet"
        };
        for cmd in ["launch", "simulate"] {
            let mut args = vec![cmd, "--n", "10", "--t-total", "30", "--out", out, force];
            if cmd == "launch" {
                args.extend(["--team", &team]);
            }
            refused("orchestrator", &args, &[&format!("--out {out}: {why}")]);
        }
        assert!(
            out == "/proc/sys" || !Path::new(out).exists(),
            "{out} was created"
        );
    }
    assert_eq!(std::fs::read(&file).expect("read"), b"x\n");
    assert_no_team_resources(&team);
}

/// Waits until a just copied executable can run: another test's thread that forked while the
/// copy was open for writing holds it until its child execs (ETXTBSY), for a moment.
fn wait_until_runnable(exe: &Path) {
    let deadline = std::time::Instant::now() + integration_tests::deadline::REFUSE;
    loop {
        match Command::new(exe).arg("--version").output() {
            Err(e)
                if e.kind() == std::io::ErrorKind::ExecutableFileBusy
                    && std::time::Instant::now() < deadline =>
            {
                std::thread::sleep(Duration::from_millis(20))
            }
            Err(e) => panic!("{}: {e}", exe.display()),
            Ok(_) => return,
        }
    }
}

/// `cargo run --bin orchestrator` builds only the orchestrator: a launch without the member
/// binaries beside it is refused before anything is created, saying how to build them.
#[test]
fn a_launch_without_the_member_binaries_says_how_to_build_them() {
    let dir = TempDir::new();
    let lonely = dir.path().join("orchestrator");
    std::fs::copy(bin("orchestrator"), &lonely).expect("copy the orchestrator binary");
    wait_until_runnable(&lonely);
    let out_dir = dir.path().join("run");
    let team = unique_team("lonely");
    let out = run(
        Command::new(&lonely)
            .args([
                "launch",
                "--n",
                "4",
                "--max-ticks",
                "5",
                "--team",
                &team,
                "--out",
            ])
            .arg(&out_dir),
        integration_tests::deadline::REFUSE,
    );
    assert_eq!(out.status.code(), Some(2), "{}", describe(&out));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("binary is missing") && err.contains("cargo build --release"),
        "{}",
        describe(&out)
    );
    assert!(
        !out_dir.exists(),
        "nothing may be written: {}",
        out_dir.display()
    );
    assert_no_team_resources(&team);
}

/// Every duration option has a range; 1e308 is refused by name, not a panic.
#[test]
fn huge_durations_are_refused_naming_the_option() {
    let tmp = TempDir::new();
    for flag in ["--agent-timeout", "--join-timeout"] {
        let out = tmp.path().join("run");
        let team = unique_team("dur");
        refused_cmd(
            launch(&team, &out, &["--n", "4"]).args([flag, "1e308"]),
            &[&format!(
                "{flag} must be a number of seconds in (0, 86400], got 1e308"
            )],
        );
        assert!(!out.exists());
    }
    for flag in ["--silence-timeout", "--join-timeout"] {
        let mut c = member("agent", Path::new("s.toml"), "t", 4);
        refused_cmd(
            c.args([flag, "1e308"]),
            &[&format!("{flag} must be a number of seconds in (0, 86400]")],
        );
    }
}

/// `--follow` is checked before the flight; `--sweep` like `--t-total`.
#[test]
fn follow_and_sweep_are_checked_up_front() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let team = unique_team("follow");
    refused_cmd(
        &mut simulate(&out, &["--follow", "999"]),
        &["--follow 999", "no agent with this id"],
    );
    assert!(!out.exists(), "simulate flew before refusing --follow");
    refused_cmd(
        &mut launch(&team, &out, &["--n", "4", "--follow", "999"]),
        &["--follow 999", "no agent with this id"],
    );
    assert!(!out.exists(), "launch flew before refusing --follow");
    assert_no_team_resources(&team);
    let sweep = tmp.path().join("sweep");
    refused_cmd(
        command("orchestrator", &["plan", "--sweep", "30:1e9:1e8", "--out"]).arg(&sweep),
        &["--sweep travel time", "field `t_total_s`", "at most 1e8"],
    );
    assert!(!sweep.exists());
}

// ---- special files ---------------------------------------------------------------------------

/// /dev/zero, /dev/urandom or a FIFO as --scenario, and a FIFO as a run's
/// telemetry.csv for `report`: refused at once (regular files only), exit 2.
#[test]
fn special_files_are_refused_as_inputs() {
    let tmp = TempDir::new();
    let pipe = tmp.path().join("scenario.toml");
    fifo(&pipe);
    for source in ["/dev/zero", "/dev/urandom", pipe.to_str().expect("UTF-8")] {
        refused_cmd(
            &mut command("orchestrator", &["plan", "--scenario", source]),
            &[source, "not a regular file"],
        );
    }
    let out = tmp.path().join("run");
    let o = run(
        &mut simulate(&out, &["--max-ticks", "3", "--no-figures"]),
        SHORT_DEADLINE,
    );
    assert_exit(&o, 0, "simulate");
    let tel = out.join("telemetry.csv");
    fs::remove_file(&tel).expect("rm");
    fifo(&tel);
    refused_cmd(
        command("orchestrator", &["report"]).arg(&out),
        &["telemetry.csv", "not a regular file"],
    );
}

// ---- scenario files: the file itself ---------------------------------------------------------

#[test]
fn nonexistent_file_is_refused() {
    let dir = TempDir::new();
    let path = dir.path().join("does-not-exist.toml");
    assert_refused(&path, &["cannot read the file"]);
}

#[test]
fn directory_instead_of_file_is_refused() {
    let dir = TempDir::new();
    assert_refused(dir.path(), &["cannot read the file"]);
}

#[test]
fn malformed_toml_is_refused() {
    let dir = TempDir::new();
    let path = write_text(
        dir.path(),
        "malformed.toml",
        "name = \"broken\"\nt_total_s = 200.0\neps_m = [1.5\n",
    );
    assert_refused(&path, &["malformed scenario", "line 3"]);
}

#[test]
fn unknown_top_level_key_is_refused() {
    let mut table = paper40_table();
    table.insert("colour".into(), toml::Value::String("red".into()));
    let dir = TempDir::new();
    let text = toml::to_string(&table).unwrap_or_else(|e| panic!("serialising: {e}"));
    let path = write_text(dir.path(), "unknown-top.toml", &text);
    let at = format!("line {},", line_of(&text, "colour ="));
    assert_refused(
        &path,
        &["malformed scenario", &at, "unknown field `colour`"],
    );
}

#[test]
fn unknown_key_in_agent_is_refused() {
    let mut table = paper40_table();
    let agents = table
        .get_mut("agents")
        .and_then(toml::Value::as_array_mut)
        .unwrap_or_else(|| panic!("paper40's TOML has no [[agents]] array"));
    let seventh = agents
        .get_mut(6)
        .and_then(toml::Value::as_table_mut)
        .unwrap_or_else(|| panic!("paper40's 7th agent is not a table"));
    seventh.insert("speed_mps".into(), toml::Value::Float(3.0));
    let dir = TempDir::new();
    let text = toml::to_string(&table).unwrap_or_else(|e| panic!("serialising: {e}"));
    let path = write_text(dir.path(), "unknown-agent.toml", &text);
    // The parse error locates the key by line: the line inside agent 7's table.
    let line = line_of(&text, "speed_mps =");
    let table_id = text
        .lines()
        .take(line)
        .filter(|l| l.starts_with("id = "))
        .last()
        .unwrap_or_else(|| panic!("no `id = ` line before the unknown key:\n{text}"));
    assert_eq!(
        table_id, "id = 7",
        "the unknown key must be in agent 7's table"
    );
    let at = format!("line {line},");
    assert_refused(
        &path,
        &["malformed scenario", &at, "unknown field `speed_mps`"],
    );
}

/// A named change to one agent's section of a file, and what the error must say.
type Edit = (&'static str, fn(&str) -> String, &'static str);

/// In a 1000-agent file, an unknown key on an agent, an unknown role and a position
/// with two components are reported with the agent's id.
#[test]
fn malformed_agents_are_named_by_id() {
    let tmp = TempDir::new();
    let o = run(
        &mut command("orchestrator", &["scenario", "export", "--n", "1000"]),
        SHORT_DEADLINE,
    );
    assert_exit(&o, 0, "scenario export --n 1000");
    let text = String::from_utf8(o.stdout).expect("UTF-8");
    let sections: Vec<&str> = text.split("[[agents]]").collect();
    // Section 701 is the 700th agent (index 699).
    let k = 700;
    let id = toml_value(sections[k], "id").expect("id");
    let edits: [Edit; 3] = [
        (
            "unknown key",
            |s| s.replacen("role =", "colour = 1\nrole =", 1),
            "unknown field `colour`",
        ),
        (
            "unknown role",
            |s| s.replacen("\"follower\"", "\"boss\"", 1),
            "unknown variant `boss`",
        ),
        (
            "two components",
            |s| {
                let start = s.find("position = [").expect("position") + 12;
                let end = start + s[start..].find(']').expect("]");
                let mut parts: Vec<&str> = s[start..end].split(',').collect();
                parts.pop();
                format!("{}{}{}", &s[..start], parts.join(","), &s[end..])
            },
            "invalid length 2",
        ),
    ];
    for (what, edit, needle) in edits {
        let mut parts: Vec<String> = sections.iter().map(|s| s.to_string()).collect();
        parts[k] = edit(&parts[k]);
        let p = tmp.path().join(format!("{}.toml", what.replace(' ', "_")));
        fs::write(&p, parts.join("[[agents]]")).expect("write");
        refused_cmd(
            &mut command(
                "orchestrator",
                &["plan", "--scenario", p.to_str().expect("UTF-8")],
            ),
            &[&format!("agent {id} (agents[{}])", k - 1), needle],
        );
    }
}

/// A scenario name is at most 256 bytes; a 10 MB one is refused without being printed.
#[test]
fn long_names_are_refused_without_printing_them() {
    let tmp = TempDir::new();
    for len in [257, 10_000_000] {
        let mut f = integration_tests::paper40();
        f.name = "n".repeat(len);
        let p = integration_tests::write_scenario(tmp.path(), "s.toml", &f);
        let o = refused_cmd(
            &mut command(
                "orchestrator",
                &["plan", "--scenario", p.to_str().expect("UTF-8")],
            ),
            &[&format!("field `name` is {len} bytes long; at most 256")],
        );
        assert!(o.stderr.len() < 4096, "{} bytes of error", o.stderr.len());
    }
}

// ---- the airspace -----------------------------------------------------------------

/// `[geofence]` and `[[obstacle]]` tables that cannot be flown: each refused naming the fence or
/// the obstacle (paper40 starts at z 900-1197 m around x -198..360, y -72..117).
#[test]
fn bad_geofences_and_obstacles_are_refused_naming_them() {
    use cdm_model::airspace::Shape;
    use cdm_scenario::{GeofenceSpec, ObstacleSpec};
    let fence = |polygon: Vec<[f64; 2]>, min_z_m, max_z_m| GeofenceSpec {
        polygon,
        min_z_m,
        max_z_m,
    };
    let square = vec![
        [-300.0, -200.0],
        [500.0, -200.0],
        [500.0, 600.0],
        [-300.0, 600.0],
    ];
    let block = |name: &str, min, max| ObstacleSpec {
        name: name.into(),
        shape: Shape::Box { min, max },
    };
    let cylinder = |radius_m| ObstacleSpec {
        name: "mast".into(),
        shape: Shape::Cylinder {
            center: [0.0, 0.0],
            radius_m,
            min_z_m: 0.0,
            max_z_m: 10.0,
        },
    };
    let cases: Vec<(Option<GeofenceSpec>, Vec<ObstacleSpec>, &str)> = vec![
        (
            Some(fence(square[..2].to_vec(), 0.0, 2000.0)),
            vec![],
            "geofence: `polygon` needs at least 3 vertices, got 2",
        ),
        (
            Some(fence(
                vec![square[0], square[2], square[1], square[3]],
                0.0,
                2000.0,
            )),
            vec![],
            "geofence: `polygon` is self-intersecting: edge 1 crosses edge 3",
        ),
        (
            Some(fence(square.clone(), 2000.0, 0.0)),
            vec![],
            "geofence: `min_z_m` = 2000 must be below `max_z_m` = 0",
        ),
        (
            Some(fence(square.clone(), 0.0, f64::INFINITY)),
            vec![],
            "geofence: `max_z_m` must be a finite number, got inf",
        ),
        (
            Some(fence(square.clone(), 0.0, 1000.0)),
            vec![],
            "geofence: agent 2 starts above its ceiling at [72.000, 108.000, 1008.000]",
        ),
        (
            None,
            vec![
                block("tower", [0.0; 3], [1.0; 3]),
                block("tower", [5.0; 3], [6.0; 3]),
            ],
            "obstacle \"tower\": appears more than once",
        ),
        (
            None,
            vec![block("tower", [0.0, 0.0, 5.0], [1.0, 1.0, 1.0])],
            "obstacle \"tower\": `min[2]` = 5 must be below `max[2]` = 1",
        ),
        (
            None,
            vec![cylinder(0.0)],
            "obstacle \"mast\": `radius_m` must be > 0, got 0",
        ),
        (
            None,
            vec![block("tower", [f64::NAN, 0.0, 0.0], [1.0; 3])],
            "obstacle \"tower\": `min[0]` must be a finite number, got NaN",
        ),
        (
            // Agent 1 starts at (360, 0, 900).
            None,
            vec![block("hangar", [350.0, -10.0, 0.0], [370.0, 10.0, 950.0])],
            "obstacle \"hangar\": agent 1 starts inside it at [360.000, 0.000, 900.000]",
        ),
    ];
    for (k, (geofence, obstacles, want)) in cases.into_iter().enumerate() {
        let mut f = paper40();
        f.geofence = geofence;
        f.obstacles = obstacles;
        assert_scenario_refused(&format!("airspace{k}.toml"), &f, &[want]);
    }
    // Both shapes in one table: the parser names the obstacle.
    let dir = TempDir::new();
    let both = "[[obstacle]]\nname = \"tower\"\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nradius_m = 2.0\n";
    let text = format!("{}\n{both}", scenario_toml(&paper40()));
    let path = write_text(dir.path(), "both.toml", &text);
    assert_refused(
        &path,
        &["obstacle \"tower\": give either `min` and `max` (a box) or"],
    );
}

// ---- numbers ---------------------------------------------------------------------------------

#[test]
fn nan_in_a_position_is_refused() {
    let mut f = paper40();
    agent(&mut f, 7).position[2] = f64::NAN;
    let text = scenario_toml(&f);
    assert!(text.contains("nan"), "the file must hold a TOML `nan`");
    assert_scenario_refused(
        "nan-position.toml",
        &f,
        &["field `agents[id=7].position[2]` must be a finite number, got NaN"],
    );
}

#[test]
fn infinite_t_total_is_refused() {
    let mut f = paper40();
    f.t_total_s = f64::INFINITY;
    let text = scenario_toml(&f);
    assert!(text.contains("inf"), "the file must hold a TOML `inf`");
    assert_scenario_refused(
        "inf-t-total.toml",
        &f,
        &["field `t_total_s` must be a finite number, got inf"],
    );
}

#[test]
fn zero_t_total_is_refused() {
    let mut f = paper40();
    f.t_total_s = 0.0;
    assert_scenario_refused(
        "zero-t-total.toml",
        &f,
        &["field `t_total_s` must be > 0, got 0"],
    );
}

#[test]
fn negative_t_total_is_refused() {
    let mut f = paper40();
    f.t_total_s = -5.0;
    assert_scenario_refused(
        "negative-t-total.toml",
        &f,
        &["field `t_total_s` must be > 0, got -5"],
    );
}

#[test]
fn non_positive_comm_hz_is_refused() {
    let mut f = paper40();
    f.comm_hz = -10.0;
    assert_scenario_refused(
        "negative-comm-hz.toml",
        &f,
        &["field `comm_hz` must be > 0, got -10"],
    );
    f.comm_hz = 0.0;
    assert_scenario_refused(
        "zero-comm-hz.toml",
        &f,
        &["field `comm_hz` must be > 0, got 0"],
    );
}

#[test]
fn lambda_cd_min_and_delta_together_are_refused() {
    let mut f = paper40();
    f.lambda_cd_min = Some(0.5);
    f.delta_m = Some(2.0);
    assert_scenario_refused(
        "lambda-and-delta.toml",
        &f,
        &["field `lambda_cd_min`", "`delta_m` are exclusive"],
    );
}

#[test]
fn unstable_gains_are_refused() {
    let mut f = paper40();
    f.gains = [1.0, 1.0, 10.0, 1.0];
    assert_scenario_refused(
        "unstable-gains.toml",
        &f,
        &["gains [1.0, 1.0, 10.0, 1.0] are unstable"],
    );
}

/// Ticks that cannot resolve the motion are bad input with the reason: too few ticks
/// (`--t-total 0.005`), a clock too slow for the gains' fastest pole (`comm_hz = 0.001`), a
/// clock so fast the certificate would fly for hours (`comm_hz = 500000`).
#[test]
fn plans_whose_ticks_cannot_resolve_the_motion_are_refused_cmd() {
    let tmp = TempDir::new();
    let team = unique_team("ticks");
    let out = tmp.path().join("run");
    let needles = ["field `t_total_s`", "ticks over the motion"];
    refused_cmd(
        &mut command("orchestrator", &["plan", "--t-total", "0.005"]),
        &needles,
    );
    refused_cmd(&mut simulate(&out, &["--t-total", "0.005"]), &needles);
    refused_cmd(&mut launch(&team, &out, &["--t-total", "0.005"]), &needles);
    assert!(!out.exists());
    for (hz, needles) in [
        ("0.001", &["field `comm_hz`", "fastest pole"][..]),
        ("500000", &["field `comm_hz`", "at most 10000 Hz"][..]),
    ] {
        let mut f = integration_tests::paper40();
        f.comm_hz = hz.parse().expect("number");
        let p = integration_tests::write_scenario(tmp.path(), "s.toml", &f);
        refused_cmd(
            &mut command(
                "orchestrator",
                &["plan", "--scenario", p.to_str().expect("UTF-8")],
            ),
            needles,
        );
    }
    assert_no_team_resources(&team);
}

// ---- ids and roles ---------------------------------------------------------------------------

#[test]
fn duplicate_id_is_refused() {
    let mut f = paper40();
    agent(&mut f, 12).id = 7;
    assert_scenario_refused(
        "duplicate-id.toml",
        &f,
        &["agent id 7 appears more than once"],
    );
}

#[test]
fn two_primary_leaders_are_refused() {
    let mut f = paper40();
    let a = agent(&mut f, 3);
    a.role = Role::Secondary;
    a.goal = None;
    assert_scenario_refused(
        "two-primaries.toml",
        &f,
        &["exactly 3 primary leaders, found [1, 2]"],
    );
}

#[test]
fn four_primary_leaders_are_refused() {
    let mut f = paper40();
    let a = agent(&mut f, 4);
    a.role = Role::Primary;
    a.goal = Some([0.0, 0.0, 560.0]);
    assert_scenario_refused(
        "four-primaries.toml",
        &f,
        &["exactly 3 primary leaders, found [1, 2, 3, 4]"],
    );
}

#[test]
fn primary_without_goal_is_refused() {
    let mut f = paper40();
    agent(&mut f, 2).goal = None;
    assert_scenario_refused(
        "missing-goal.toml",
        &f,
        &["primary leader 2: `goal` is missing"],
    );
}

#[test]
fn goal_on_secondary_leader_is_refused() {
    let mut f = paper40();
    agent(&mut f, 5).goal = Some([0.0, 0.0, 560.0]);
    assert_scenario_refused(
        "goal-on-secondary.toml",
        &f,
        &["agent 5 (secondary): only primary leaders have a `goal`"],
    );
}

#[test]
fn goal_on_follower_is_refused() {
    let mut f = paper40();
    agent(&mut f, 9).goal = Some([0.0, 0.0, 560.0]);
    assert_scenario_refused(
        "goal-on-follower.toml",
        &f,
        &["agent 9 (follower): only primary leaders have a `goal`"],
    );
}

#[test]
fn in_neighbors_on_primary_leader_are_refused() {
    let mut f = paper40();
    agent(&mut f, 1).in_neighbors = Some(vec![4, 5, 6]);
    assert_scenario_refused(
        "neighbors-on-primary.toml",
        &f,
        &["agent 1 (primary): only followers have `in_neighbors`"],
    );
}

#[test]
fn in_neighbors_on_secondary_leader_are_refused() {
    let mut f = paper40();
    agent(&mut f, 6).in_neighbors = Some(vec![1, 2, 3]);
    assert_scenario_refused(
        "neighbors-on-secondary.toml",
        &f,
        &["agent 6 (secondary): only followers have `in_neighbors`"],
    );
}

// ---- geometry of the leaders -----------------------------------------------------------------

#[test]
fn collinear_primaries_at_t0_are_refused() {
    let mut f = paper40();
    let [r1, r2, _] = primaries(&f);
    // Leader 3 half-way between leaders 1 and 2.
    agent(&mut f, 3).position = scale(add(r1, r2), 0.5);
    assert_scenario_refused(
        "collinear-t0.toml",
        &f,
        &["primary leaders [1, 2, 3] are (nearly) collinear at t0"],
    );
}

#[test]
fn primaries_collinear_during_the_plan_are_refused() {
    let mut f = paper40();
    let [r1, r2, r3] = primaries(&f);
    // The goal triangle is the start triangle mirrored across the line through leaders 1 and 2
    // (in their plane), then translated: both ends are proper triangles, but on the straight
    // path leader 3 crosses that line half-way, so the triangle flips through a segment.
    let u = unit(sub(r2, r1));
    let p = sub(r3, r1);
    let mirrored_r3 = add(r1, sub(scale(u, 2.0 * dot(p, u)), p));
    let shift = [0.0, 0.0, -300.0];
    agent(&mut f, 1).goal = Some(add(r1, shift));
    agent(&mut f, 2).goal = Some(add(r2, shift));
    agent(&mut f, 3).goal = Some(add(mirrored_r3, shift));
    let dir = TempDir::new();
    let path = write_scenario(dir.path(), "collinear-mid-plan.toml", &f);
    assert_refused(
        &path,
        &["primary leaders [1, 2, 3] are (nearly) collinear at t = "],
    );
    // Neither end is the problem.
    let out = plan(&path, SHORT_DEADLINE);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("at t0") && !stderr.contains("at their goals"),
        "the degenerate triangle is mid-plan, not at an end:\n{}",
        describe(&out)
    );
}

#[test]
fn non_convex_leading_polygon_is_refused() {
    let mut f = paper40();
    // Secondary leader 5 at the primaries' centroid: inside the hull, not a vertex.
    agent(&mut f, 5).position = primary_centroid(&f);
    assert_scenario_refused(
        "non-convex.toml",
        &f,
        &["leader 5: the leading polygon is not strictly convex"],
    );
}

// ---- followers and the plane -----------------------------------------------------------------

#[test]
fn follower_outside_the_leading_polygon_is_refused() {
    let mut f = paper40();
    let c = primary_centroid(&f);
    let [r1, _, _] = primaries(&f);
    // On the plane, beyond leader 1 as seen from the centroid: outside every leader's hull.
    agent(&mut f, 7).position = add(r1, sub(r1, c));
    assert_scenario_refused(
        "outside-polygon.toml",
        &f,
        &["agent 7: outside the leading polygon"],
    );
}

#[test]
fn agent_far_off_the_plane_is_refused() {
    let mut f = paper40();
    let n = plane_normal(&f);
    let a = agent(&mut f, 7);
    a.position = add(a.position, scale(n, 5.0));
    assert_scenario_refused(
        "off-plane.toml",
        &f,
        &["agent 7: 5.000 m off the primary leaders' plane (tolerance 1 m"],
    );
}

#[test]
fn agent_near_the_plane_is_projected() {
    let mut f = paper40();
    let n = plane_normal(&f);
    let a = agent(&mut f, 7);
    a.position = add(a.position, scale(n, 0.5));
    let dir = TempDir::new();
    let path = write_scenario(dir.path(), "near-plane.toml", &f);
    let out = plan(&path, PLAN_DEADLINE);
    let all = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        !all.contains("panicked"),
        "orchestrator panicked:\n{}",
        describe(&out)
    );
    assert!(
        matches!(out.status.code(), Some(0 | 1)),
        "a scenario within the plane tolerance must be planned (exit 0 or 1):\n{}",
        describe(&out)
    );
    assert!(
        all.contains("agent 7: projected 0.500 m"),
        "the output must say agent 7 was projected onto the plane:\n{}",
        describe(&out)
    );
}

// ---- in-neighbours ---------------------------------------------------------------------------

#[test]
fn follower_outside_its_neighbors_triangle_is_refused() {
    let mut f = paper40();
    let n = plane_normal(&f);
    let leaders: Vec<(u32, V3)> = f
        .agents
        .iter()
        .filter(|a| a.role != Role::Follower)
        .map(|a| (a.id, a.position))
        .collect();
    // Follower 7 with three leaders whose triangle clearly leaves it out (the leaders are the
    // vertices of a strictly convex polygon, so any three of them make a proper triangle).
    let p = agent(&mut f, 7).position;
    let mut chosen = None;
    'search: for i in 0..leaders.len() {
        for j in i + 1..leaders.len() {
            for k in j + 1..leaders.len() {
                let t = [leaders[i].1, leaders[j].1, leaders[k].1];
                if weights(p, t, n).iter().any(|w| *w < -0.05) {
                    chosen = Some([leaders[i].0, leaders[j].0, leaders[k].0]);
                    break 'search;
                }
            }
        }
    }
    let chosen = chosen.unwrap_or_else(|| panic!("no leader triangle leaves follower 7 out"));
    agent(&mut f, 7).in_neighbors = Some(chosen.to_vec());
    let expected = format!(
        "agent 7: not strictly inside the triangle of its in-neighbours {:?}",
        chosen
    );
    assert_scenario_refused("outside-triangle.toml", &f, &[&expected]);
}

#[test]
fn unknown_in_neighbor_is_refused() {
    let mut f = paper40();
    agent(&mut f, 7).in_neighbors = Some(vec![1, 2, 999]);
    assert_scenario_refused(
        "unknown-neighbor.toml",
        &f,
        &["agent 7: in-neighbour 999 does not exist"],
    );
}

#[test]
fn follower_listing_itself_is_refused() {
    let mut f = paper40();
    agent(&mut f, 7).in_neighbors = Some(vec![1, 7, 2]);
    assert_scenario_refused(
        "self-neighbor.toml",
        &f,
        &["agent 7: lists itself as an in-neighbour"],
    );
}

#[test]
fn two_in_neighbors_are_refused() {
    let mut f = paper40();
    agent(&mut f, 7).in_neighbors = Some(vec![1, 2]);
    assert_scenario_refused(
        "two-neighbors.toml",
        &f,
        &["agent 7: in-neighbours must be 3 distinct agents, got [1, 2]"],
    );
}

// ---- a hand-started team that does not assemble ----------------------------------------------

/// `--no-spawn` with only leader 1 joining: the message lists the agents that did not
/// join (not leader 1), and leader 1 exits 3 saying its team was stopped before the end.
#[test]
fn a_partial_hand_started_team_names_only_the_missing_agents() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let team = unique_team("partial");
    let orch = spawn(
        launch(&team, &out, &["--n", "4", "--t-total", "30"])
            .args(["--no-spawn", "--join-timeout", "3"])
            .arg("--no-figures"),
    );
    let scenario = out.join("scenario.toml");
    let start = std::time::Instant::now();
    while !scenario.exists() {
        assert!(start.elapsed() < SHORT_DEADLINE, "no scenario.toml");
        std::thread::sleep(Duration::from_millis(20));
    }
    let leader = run(&mut member("leader", &scenario, &team, 1), SHORT_DEADLINE);
    let o = orch.finish(SHORT_DEADLINE);
    assert_exit(&o, 3, "launch with only leader 1");
    assert_stderr_has(&o, "launch", &["agents 2, 3, 4 did not join team"]);
    assert_exit(&leader, 3, "leader 1 of a team that never flew");
    assert_stderr_has(
        &leader,
        "leader 1",
        &["stopped by its orchestrator", "before the end of the plan"],
    );
    assert_no_team_resources(&team);
}
