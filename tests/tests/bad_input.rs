//! Bad input on the command line: unknown flags, missing values, team sizes outside
//! 4..=2000, bad numbers and names, an --out that is not empty or cannot be written. Each is
//! refused with exit 2 and a message naming the argument, before anything is written: no run
//! directory, no shared memory of the team.
//!
//! (Scenario files: `validation.rs`; property tests of the parser: `common/core/tests/proptest.rs`.)

mod support;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{bin, describe, run, unique_team, TempDir};
use support::*;

/// Every refusal here happens before any work; the deadline only keeps a hang from stalling CI.
const DEADLINE: Duration = integration_tests::deadline::REFUSE;
/// A 10-agent team with a 30 s plan flies in about a second.
const FLY_DEADLINE: Duration = integration_tests::deadline::SHORT;

fn command(binary: &str, args: &[&str]) -> Command {
    let mut c = Command::new(bin(binary));
    c.args(args);
    c
}

/// Runs `binary args` and asserts exit 2 with every needle in stderr and nothing on stdout.
fn refused(binary: &str, args: &[&str], needles: &[&str]) -> Output {
    let o = run(&mut command(binary, args), DEADLINE);
    let what = format!("{binary} {}", args.join(" "));
    assert_exit(&o, 2, &what);
    assert_stderr_has(&o, &what, needles);
    assert!(
        o.stdout.is_empty(),
        "{what}: wrote to stdout\n{}",
        describe(&o)
    );
    o
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
    let o = run(&mut command("orchestrator", &forced), FLY_DEADLINE);
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

/// `cargo run --bin orchestrator` builds only the orchestrator: a launch without the member
/// binaries beside it is refused before anything is created, saying how to build them.
#[test]
fn a_launch_without_the_member_binaries_says_how_to_build_them() {
    let dir = TempDir::new();
    let lonely = dir.path().join("orchestrator");
    std::fs::copy(bin("orchestrator"), &lonely).expect("copy the orchestrator binary");
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
