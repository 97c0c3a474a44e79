//! A team's keys on disk, as `launch --keys` and `host --keys` take them (real binaries, real
//! files, a second local user): a key directory or key file that anyone but its owner can write
//! or read, or that another user owns, is refused before any socket is opened, with exit 2 and a
//! message naming it and its mode or owner. Otherwise a user who can write into the directory
//! puts their own authority's certificate and key there, and their daemon joins the team.
//!
//! The second user is created for the test (`useradd`; needs root, as CI runs; that part is
//! skipped with a note elsewhere).

use integration_tests::support;

use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{bin, describe, run, unique_team, TempDir};
use support::netns::{arg, new_keys};
use support::users::{binaries_for_everyone, TestUser};
use support::{assert_exit, assert_stderr_has};

/// A refusal happens before any socket is opened; the deadline only stops a hang (an accepted
/// directory would have the orchestrator wait for its daemon).
const DEADLINE: Duration = integration_tests::deadline::REFUSE;

fn chmod(p: &Path, mode: u32) {
    std::fs::set_permissions(p, std::fs::Permissions::from_mode(mode))
        .unwrap_or_else(|e| panic!("chmod {mode:o} {}: {e}", p.display()));
}

/// `launch --hosts 2 --listen tls/... --keys KEYS` of a small team.
fn launch_with(keys: &Path, out: &Path) -> Output {
    let team = unique_team("keymode");
    run(
        Command::new(bin("orchestrator"))
            .args(["launch", "--n", "10", "--team", &team, "--hosts", "2"])
            .args(["--listen", "tls/127.0.0.1:7447", "--keys", &arg(keys)])
            .args(["--no-figures", "--out", &arg(out)]),
        DEADLINE,
    )
}

/// `host --connect tls/... --keys KEYS`.
fn host_with(keys: &Path) -> Output {
    run(
        Command::new(bin("orchestrator"))
            .args(["host", "--join-timeout", "1"])
            .args(["--connect", "tls/127.0.0.1:7447", "--keys", &arg(keys)]),
        DEADLINE,
    )
}

fn refused(o: &Output, what: &str, needles: &[&str]) {
    assert_exit(o, 2, what);
    assert_stderr_has(o, what, needles);
    assert!(
        !String::from_utf8_lossy(&o.stderr).contains("panicked"),
        "{what}\n{}",
        describe(o)
    );
}

/// Directory modes 0703, 0730 (others or the group can write: replace the keys) and 0755
/// (others can read), a ca.pem others can write or read: refused by `launch` and by `host`,
/// naming the directory or file, its mode, whether others can write or read it, and the chmod
/// that fixes it. Before the fix every directory mode was accepted, and ca.pem's message said
/// "read" when others could write it.
#[test]
fn key_directories_and_files_others_can_write_or_read_are_refused() {
    let tmp = TempDir::new();
    let keys = tmp.path().join("keys");
    new_keys(&keys, 1);
    let out = tmp.path().join("run");
    let (orch, host) = (keys.join("orchestrator"), keys.join("host-1"));
    for (mode, says) in [(0o703, "write"), (0o730, "write"), (0o755, "read")] {
        chmod(&orch, mode);
        let o = launch_with(&orch, &out);
        let said = format!("{}: mode {mode:04o} lets others {says} it", arg(&orch));
        refused(&o, &format!("launch, keys {mode:o}"), &[&said, "chmod 700"]);
        assert!(!out.exists(), "a refused launch wrote {}", out.display());
        chmod(&host, mode);
        let o = host_with(&host);
        let said = format!("{}: mode {mode:04o} lets others {says} it", arg(&host));
        refused(&o, &format!("host, keys {mode:o}"), &[&said, "chmod 700"]);
    }
    chmod(&orch, 0o700);
    let ca = orch.join("ca.pem");
    for (mode, says) in [(0o646, "write"), (0o620, "write"), (0o604, "read")] {
        chmod(&ca, mode);
        let o = launch_with(&orch, &out);
        let said = format!("{}: mode {mode:04o} lets others {says} it", arg(&ca));
        refused(
            &o,
            &format!("launch, ca.pem {mode:o}"),
            &[&said, "chmod 600"],
        );
    }
}

/// The attack itself: the orchestrator's key directory is 0703; another local user makes a team
/// of their own and puts their orchestrator's ca.pem, cert.pem and key.pem in it. `launch` is
/// refused for the directory's mode; once the directory is 0700 again, for the files another
/// user owns (naming the owner). Before the fix the launch accepted them and the other user's
/// daemon, with their own authority's keys, joined the team and flew its members.
#[test]
fn keys_another_user_put_in_a_writable_key_directory_are_refused() {
    let Some(intruder) = TestUser::create("k") else {
        return;
    };
    let tmp = TempDir::new();
    let orchestrator = binaries_for_everyone(tmp.path());
    let keys = tmp.path().join("keys");
    new_keys(&keys, 1);
    let orch = keys.join("orchestrator");
    // The orchestrator's directory may be anywhere others can reach (here: in the team's).
    chmod(&keys, 0o711);
    chmod(&orch, 0o703);
    // The intruder's own team, in a directory of theirs.
    let theirs = tmp.path().join("intruder");
    std::fs::create_dir(&theirs).expect("mkdir");
    std::os::unix::fs::chown(&theirs, Some(intruder.uid), Some(intruder.gid)).expect("chown");
    let made = run(
        intruder
            .command(&orchestrator)
            .args(["keys", "new", &arg(&theirs.join("team"))]),
        DEADLINE,
    );
    assert_exit(&made, 0, "the intruder's keys new");
    let swap = "for f in ca.pem cert.pem key.pem; do rm -f \"$2/$f\" && cp \"$1/$f\" \"$2/$f\" || exit 1; done";
    let swapped = run(
        intruder
            .command(Path::new("/bin/sh"))
            .args(["-c", swap, "sh"])
            .arg(theirs.join("team/orchestrator"))
            .arg(&orch),
        DEADLINE,
    );
    assert_exit(
        &swapped,
        0,
        "the intruder replaces the keys in a 0703 directory",
    );
    let out = tmp.path().join("run");
    let o = launch_with(&orch, &out);
    let said = format!("{}: mode 0703 lets others write it", arg(&orch));
    refused(&o, "launch, keys replaced in a 0703 directory", &[&said]);
    chmod(&orch, 0o700);
    let o = launch_with(&orch, &out);
    let owner = format!("owned by user {}", intruder.uid);
    refused(
        &o,
        "launch, keys owned by another user",
        &[&owner, "ca.pem"],
    );
    assert!(!out.exists(), "a refused launch wrote {}", out.display());
}
