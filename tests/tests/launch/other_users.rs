//! Other local users, and teams that died, with the real binaries.
//!
//! - Users: two users created for the test (`useradd`; removed with their files at the end) run
//!   the binaries, copied into a directory they can read, with `setpriv`. Needs root (CI runs as
//!   root); skipped with a note elsewhere.
//! - Dead teams: `launch --n 200` killed (SIGKILL) 50 ms after its start, in a private mount
//!   namespace with a /dev/shm of its own so that other tests on the machine do not disturb the
//!   comparison of /dev/shm before and after; skipped where `unshare -m` is not allowed.

use integration_tests::support;

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use integration_tests::{bin, describe, run, spawn, unique_team, TempDir};
use support::users::{binaries_for_everyone, TestUser};
use support::*;

/// A small team's launch and stop take a few seconds; the rest is slack for a loaded machine.
const DEADLINE: Duration = integration_tests::deadline::FLIGHT;

/// A run directory writable by `user` only.
fn out_dir_of(user: &TestUser, dir: &Path, name: &str) -> PathBuf {
    let d = dir.join(name);
    std::fs::create_dir(&d).expect("create out dir");
    std::os::unix::fs::chown(&d, Some(user.uid), Some(user.gid)).expect("chown out dir");
    d
}

/// `launch --n 4` of a few ticks as `user`.
fn short_launch(user: &TestUser, orch: &Path, team: &str, out: &Path) -> Output {
    let mut c = user.command(orch);
    c.args([
        "launch",
        "--n",
        "4",
        "--max-ticks",
        "20",
        "--no-figures",
        "--force",
    ])
    .args(["--team", team, "--out"])
    .arg(out);
    run(&mut c, DEADLINE)
}

/// Item 1: a user's launch leaves nothing in /dev/shm that another user can write, everything it
/// keeps there directly carries the user's own iceoryx2 prefix `cdm<uid>_`, and another user who
/// writes 16 bytes of garbage into every file of /dev/shm they can cannot stop the next launch.
/// In a private /dev/shm (mount namespace), so that the launch creates what iceoryx2 keeps for
/// good. Before the fix the launch kept `iox2_<hash>_node.0_10_0.global_mgmt` with mode 0666,
/// one file shared by every user, and the garbage made every later launch fail
/// (`UnableToGenerateUniqueNodeId`, exit 2).
#[test]
fn a_launch_leaves_nothing_in_dev_shm_that_another_user_can_write() {
    if !private_mounts_allowed() {
        return;
    }
    let (Some(user), Some(other)) = (TestUser::create("w"), TestUser::create("x")) else {
        return;
    };
    let dir = TempDir::new();
    let orch = binaries_for_everyone(dir.path());
    let out = out_dir_of(&user, dir.path(), "run");
    let script = r#"
set -u
O="$0"; OUT="$1"; U="$2"; G="$3"; XU="$4"; XG="$5"; TEAM="$6"
mount -t tmpfs -o size=512m,mode=1777 tmpfs /dev/shm || exit 90
as_user() { setpriv --reuid="$U" --regid="$G" --clear-groups "$@"; }
fly() { timeout 60 setpriv --reuid="$U" --regid="$G" --clear-groups "$O" launch --n 4   --max-ticks 20 --no-figures --quiet --force --team "$TEAM" --out "$OUT"; echo "launch exit $?"; }
fly
find /dev/shm -mindepth 1 -maxdepth 1 -printf 'entry %u %m %f
'
find /dev/shm -perm -o+w ! -type d -printf 'writable %p
'
for f in $(find /dev/shm -type f); do
  setpriv --reuid="$XU" --regid="$XG" --clear-groups sh -c 'printf 0123456789abcdef > "$1"' sh "$f"     2>/dev/null && echo "overwritten $f"
done
fly
"#;
    let o = run(
        Command::new("unshare")
            .args(["-m", "sh", "-c", script])
            .arg(&orch)
            .arg(&out)
            .args([user.uid, user.gid, other.uid, other.gid].map(|v| v.to_string()))
            .arg(unique_team("users")),
        DEADLINE,
    );
    let said = String::from_utf8_lossy(&o.stdout).into_owned();
    let lines = |tag: &str| -> Vec<String> {
        said.lines()
            .filter_map(|l| l.strip_prefix(tag))
            .map(str::to_owned)
            .collect()
    };
    let all = describe(&o);
    assert_eq!(
        lines("launch exit "),
        ["0", "0"],
        "both launches fly:\n{all}"
    );
    assert_eq!(
        lines("writable "),
        Vec::<String>::new(),
        "find -perm -o+w:\n{all}"
    );
    assert_eq!(
        lines("overwritten "),
        Vec::<String>::new(),
        "another user wrote:\n{all}"
    );
    let prefix = format!("cdm{}_", user.uid);
    let root = format!("cdm-iceoryx2-{}", user.uid);
    let entries = lines("entry ");
    assert!(
        !entries.is_empty(),
        "the launch kept nothing in {SHM}?\n{all}"
    );
    for e in &entries {
        let name = e.rsplit(' ').next().unwrap_or_default();
        assert!(
            name == root || name.starts_with(&prefix),
            "{e}: not the user's root nor under the prefix {prefix}\n{all}"
        );
    }
}

/// The Python bus reader (`python/cdm_bus.py`, here through `examples/watch.py`) run by another
/// user leaves nothing in /dev/shm that anybody else can write: creating its iceoryx2 node makes
/// the user's management segment 0666, and the reader makes it owner-only as the Rust side does.
/// In a private /dev/shm; the reader is the system Python with the venv's iceoryx2 package copied
/// where the test user can read it (the venv's own interpreter may live under /root). Before the
/// fix the segment stayed `666`.
#[test]
fn a_python_reader_of_another_user_leaves_nothing_writable_in_dev_shm() {
    let system_python = Path::new("/usr/bin/python3");
    if !private_mounts_allowed() || !system_python.is_file() {
        eprintln!("skipped: needs `unshare -m` and /usr/bin/python3");
        return;
    }
    let Some(user) = TestUser::create("p") else {
        return;
    };
    let dir = TempDir::new();
    let py = python_for_everyone(dir.path());
    let script = r#"
set -u
PY="$0"; U="$1"; G="$2"
mount -t tmpfs -o size=64m,mode=1777 tmpfs /dev/shm || exit 90
PYTHONPATH="$PY/site" timeout 60 setpriv --reuid="$U" --regid="$G" --clear-groups /usr/bin/python3 "$PY/python/examples/watch.py" --team absent --join 1
echo "watch exit $?"
find /dev/shm -mindepth 1 -maxdepth 1 -printf 'entry %u %m %f
'
find /dev/shm -perm -o+w ! -type d -printf 'writable %p
'
"#;
    let o = run(
        Command::new("unshare")
            .args(["-m", "sh", "-c", script])
            .arg(&py)
            .args([user.uid, user.gid].map(|v| v.to_string())),
        DEADLINE,
    );
    let said = String::from_utf8_lossy(&o.stdout).into_owned();
    let all = describe(&o);
    let lines = |tag: &str| -> Vec<String> {
        said.lines()
            .filter_map(|l| l.strip_prefix(tag))
            .map(str::to_owned)
            .collect()
    };
    assert_eq!(lines("watch exit "), ["2"], "no such team: exit 2\n{all}");
    assert_eq!(
        lines("writable "),
        Vec::<String>::new(),
        "find -perm -o+w:\n{all}"
    );
    let prefix = format!("cdm{}_", user.uid);
    let segment = lines("entry ")
        .into_iter()
        .find(|e| e.contains(&prefix) && e.ends_with(".global_mgmt"));
    let segment = segment.unwrap_or_else(|| panic!("the reader created no segment?\n{all}"));
    assert!(
        segment.starts_with(&format!("{} 600 ", user.name)),
        "{segment}\n{all}"
    );
}

/// `python/` and the venv's iceoryx2 package (with its one dependency) copied into `dir/py`,
/// readable by every user.
fn python_for_everyone(dir: &Path) -> PathBuf {
    let py = dir.join("py");
    let site = py.join("site");
    std::fs::create_dir_all(&site).expect("create py dir");
    let venv_lib = integration_tests::venv_python()
        .parent()
        .and_then(Path::parent)
        .map(|v| v.join("lib"))
        .expect("the venv's lib");
    let packages = std::fs::read_dir(&venv_lib)
        .expect("read the venv's lib")
        .flatten()
        .map(|e| e.path().join("site-packages"))
        .find(|p| p.is_dir())
        .expect("the venv's site-packages");
    let repo_python = Path::new(env!("CARGO_MANIFEST_DIR")).join("../python");
    for (from, to) in [
        (packages.join("iceoryx2"), site.clone()),
        (packages.join("flatbuffers"), site.clone()),
        (repo_python, py.clone()),
    ] {
        let o = run(Command::new("cp").arg("-r").arg(&from).arg(&to), DEADLINE);
        assert!(
            o.status.success(),
            "cp {}: {}",
            from.display(),
            describe(&o)
        );
    }
    let o = run(
        Command::new("chmod").args(["-R", "a+rX"]).arg(dir),
        DEADLINE,
    );
    assert!(o.status.success(), "chmod: {}", describe(&o));
    py
}

/// One way to spoil a user's iceoryx2 root: its name, how to do it, what the refusal must say.
type Case<'a> = (&'a str, Box<dyn Fn() + 'a>, &'a [&'a str]);

/// Item 2: the user's iceoryx2 root `/dev/shm/cdm-iceoryx2-<uid>` created beforehand by another
/// user, or writable by group or others, or a link: the launch refuses, exit 2, naming the path,
/// the owner and the mode and saying what to do; it writes no run directory. Before the fix the
/// launch used such a root as it was (another user could then delete the team's event sockets).
#[test]
fn a_squatted_or_open_iceoryx2_root_is_refused_naming_owner_and_mode() {
    let Some(user) = TestUser::create("v") else {
        return;
    };
    let Some(squatter) = TestUser::create("s") else {
        return;
    };
    let dir = TempDir::new();
    let orch = binaries_for_everyone(dir.path());
    let root = user.iox2_root();
    let root_text = root.display().to_string();
    let target = dir.path().join("elsewhere");
    std::fs::create_dir(&target).expect("mkdir");
    let cases: [Case; 3] = [
        (
            "owned by another user",
            Box::new(|| {
                let mut c = squatter.command(Path::new("/bin/mkdir"));
                c.args(["-m", "0777"]).arg(&root);
                assert_exit(&run(&mut c, DEADLINE), 0, "mkdir as the squatter");
            }),
            &[
                "owned by another user",
                &format!("owner uid {}", squatter.uid),
                "mode 0777",
            ],
        ),
        (
            "writable by others",
            Box::new(|| {
                std::fs::create_dir(&root).expect("mkdir root");
                std::os::unix::fs::chown(&root, Some(user.uid), Some(user.gid)).expect("chown");
                std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o777))
                    .expect("chmod");
            }),
            &[
                "writable by group or others",
                &format!("owner uid {}", user.uid),
                "mode 0777",
            ],
        ),
        (
            "a link",
            Box::new(|| std::os::unix::fs::symlink(&target, &root).expect("symlink")),
            &["not a directory (a link or a file)"],
        ),
    ];
    for (what, prepare, needles) in cases {
        let _ = std::fs::remove_file(&root);
        let _ = std::fs::remove_dir_all(&root);
        prepare();
        let out = out_dir_of(&user, dir.path(), &what.replace(' ', "-"));
        let run_dir = out.join("run");
        let o = short_launch(&user, &orch, &unique_team("squat"), &run_dir);
        let case = format!("launch with an iceoryx2 root {what}");
        assert_exit(&o, 2, &case);
        let mut all = vec![root_text.as_str(), "remove it", "and launch again"];
        all.extend_from_slice(needles);
        assert_stderr_has(&o, &case, &all);
        assert!(
            !run_dir.exists(),
            "{case}: {} was written",
            run_dir.display()
        );
    }
    let _ = std::fs::remove_file(&root);
    let _ = std::fs::remove_dir_all(&root);
}

/// Item 4, part 1: `launch --n 200` killed (SIGKILL) mid-way through creating the team's
/// services, then a launch of another team: that launch removes what the dead team left, and
/// /dev/shm returns to its state before the killed launch. The kill comes once a given number
/// of new entries are in /dev/shm (an event, not a delay, so a loaded machine kills at the same
/// stage), at five stages of the hundreds of entries a team creates, each with its own killed
/// team: a kill in the middle of a service's creation, which leaves an unfinished static
/// config, is then all but certain (one stage alone missed it in most runs). In a private
/// /dev/shm (mount namespace), after one warm-up launch that creates what iceoryx2 keeps for
/// good (the user's root directory and management segment). Before the fixes, only a later
/// launch of the same team name removed anything, and iceoryx2 itself could not remove what a
/// kill in the middle of a service's creation left (it even waited forever on an empty
/// segment). `--on-loss stop` because sizing for repairs delays the creation of services past
/// the kill.
#[test]
fn a_team_killed_during_start_up_is_removed_by_the_next_launch_of_another_team() {
    const STAGES: [u32; 5] = [15, 35, 50, 90, 160];
    if !private_mounts_allowed() {
        return;
    }
    let dir = TempDir::new();
    let killed = unique_team("killed");
    let other = unique_team("after");
    let before = dir.path().join("before.txt");
    // One shell in the namespace drives the sequence; each step has its own deadline.
    let script = r#"
set -eu
O="$0"; D="$1"; KILLED="$2"; OTHER="$3"; shift 3
mount -t tmpfs -o size=1g tmpfs /dev/shm
timeout 60 "$O" launch --n 4 --max-ticks 2 --no-figures --quiet --team warmup --out "$D/w" >/dev/null
find /dev/shm | sort > "$D/before.txt"
N0=$(find /dev/shm | wc -l)
for K in "$@"; do
  "$O" launch --n 200 --on-loss stop --quiet --no-figures --team "$KILLED$K" --out "$D/k$K" >/dev/null 2>&1 &
  PID=$!
  i=0
  while [ "$(find /dev/shm | wc -l)" -lt $((N0 + K)) ]; do
    i=$((i+1)); [ "$i" -lt 12000 ] || { echo "the killed team created nothing in 60 s"; exit 1; }
    sleep 0.005
  done
  kill -9 "$PID"
  wait "$PID" || true
  echo "left by the team killed at $K new entries: $(find /dev/shm | wc -l) entries"
  i=0
  while pgrep -f -- "--team $KILLED$K" >/dev/null; do
    i=$((i+1)); [ "$i" -lt 600 ] || { echo "members of $KILLED$K still alive"; exit 1; }
    sleep 0.1
  done
  timeout 60 "$O" launch --n 4 --max-ticks 2 --no-figures --team "$OTHER$K" --out "$D/o$K"
  find /dev/shm | sort > "$D/after$K.txt"
done
"#;
    let stages: Vec<String> = STAGES.iter().map(u32::to_string).collect();
    let o = run(
        Command::new("unshare")
            .args(["-m", "sh", "-c", script])
            .arg(bin("orchestrator"))
            .arg(dir.path())
            .args([&killed, &other])
            .args(&stages),
        DEADLINE,
    );
    assert!(o.status.success(), "{}", describe(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    let before = std::fs::read_to_string(before).expect("before.txt");
    // A kill before the team's first process registered leaves nothing to remove; from the
    // original stage (50 new entries) on there is always something.
    let removed: Vec<&String> = stages
        .iter()
        .filter(|k| err.contains(&format!("team={killed}{k} ")))
        .collect();
    assert!(
        err.contains("removed stale resources") && removed.iter().any(|k| k.as_str() == "50"),
        "the launch after the kill at 50 says it removed the killed team (removed after: {removed:?}):\n{err}"
    );
    for k in &stages {
        let after =
            std::fs::read_to_string(dir.path().join(format!("after{k}.txt"))).expect("after.txt");
        assert_eq!(
            before,
            after,
            "/dev/shm before the launch killed at {k} new entries and after the next one differ\n{}",
            describe(&o)
        );
    }
}

/// Item 4, part 2: `orchestrator clean` while a team flies leaves it alone (the team completes
/// and leaves nothing behind); it says what it did.
#[test]
fn clean_never_touches_a_live_team() {
    let dir = TempDir::new();
    let team = unique_team("cleanlive");
    let out = dir.path().join("run");
    let mut orch = spawn(&mut launch(&team, &out, &["--n", "10", "--t-total", "600"]));
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), 100);
    let procs = team_processes(&team);
    let fp = TeamFootprint::record(&team, procs.keys().copied());
    fp.assert_visible(11);
    let o = run(Command::new(bin("orchestrator")).arg("clean"), DEADLINE);
    assert_exit(&o, 0, "orchestrator clean");
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("nothing to remove") || said.contains("removed team "),
        "{}",
        describe(&o)
    );
    assert!(!said.contains(&team), "clean touched the live team: {said}");
    fp.assert_visible(11);
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 0, "the team after `orchestrator clean`");
    assert_no_process_of(&team);
    fp.assert_nothing_left();
}
