//! Resource safety: what a team's shared memory lets other users do, and running out
//! of file descriptors.
//!
//! - Every file a team creates in /dev/shm and /dev/shm/cdm-iceoryx2-<uid> is readable and writable by its
//!   owner only (iceoryx2 creates them 0600 or 0400; its directories are 0750 at most).
//! - An orchestrator that runs out of file descriptors says so, with the limit and how to raise
//!   it, exits 2, and leaves no run directory and no shared memory behind; so does one whose
//!   /dev/shm has no room for the team, or that hits the process limit; a process that gets
//!   SIGBUS (shared memory full under a running team) says so.

use integration_tests::support;

use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use integration_tests::{bin, describe, run, spawn, unique_team, TempDir};
use support::*;

/// A hand-started team waits for its members; this bounds the wait (it is killed sooner).
const DEADLINE: Duration = integration_tests::deadline::SHORT;

/// The mode bits of `path` (0 when it is gone).
fn mode(path: &Path) -> u32 {
    std::fs::symlink_metadata(path)
        .map(|m| m.permissions().mode() & 0o7777)
        .unwrap_or(0)
}

/// A team's files give group and others no access (directories: no write, no access for
/// others), checked on the live team, orchestrator and members alike.
#[test]
fn a_teams_shared_memory_files_are_owner_only() {
    let dir = TempDir::new();
    let team = unique_team("modes");
    let out = dir.path().join("run");
    let mut orch = spawn(&mut launch(&team, &out, &["--n", "10", "--t-total", "600"]));
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), 100);
    let procs = team_processes(&team);
    assert_eq!(procs.len(), 11, "{procs:#?}");
    let fp = TeamFootprint::record(&team, procs.keys().copied());
    fp.assert_visible(11);
    let files: Vec<String> = fp
        .leftovers()
        .into_iter()
        .filter(|l| l.starts_with(SHM) || l.starts_with(iox2_root()))
        .collect();
    let mut wrong = vec![];
    for f in &files {
        let p = Path::new(f);
        let m = mode(p);
        let ok = if p.is_dir() {
            m & 0o027 == 0
        } else {
            m & 0o077 == 0
        };
        if !ok && p.exists() {
            wrong.push(format!("{f}: {m:o}"));
        }
    }
    // The roots themselves: /dev/shm/cdm-iceoryx2-<uid> is not writable by group or others.
    let root = mode(Path::new(iox2_root()));
    assert_eq!(root & 0o022, 0, "{} is {root:o}", iox2_root());
    assert!(
        wrong.is_empty(),
        "{} of {} team files are open to others: {wrong:#?}",
        wrong.len(),
        files.len()
    );
    // Stop the team the ordinary way; it leaves nothing behind.
    signal(orch.id(), libc::SIGINT);
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 3, "launch after SIGINT");
    assert_no_process_of(&team);
    fp.assert_nothing_left();
}

/// Linux's `CAP_SYS_RESOURCE` (linux/capability.h): lets a process raise its hard limits.
const CAP_SYS_RESOURCE: libc::c_ulong = 24;

/// `cmd` runs with RLIMIT_NOFILE at 64 (soft and hard); with `privileged` false also without
/// `CAP_SYS_RESOURCE` (dropped from the bounding set, so even root cannot raise the hard limit
/// after exec; without root there is nothing to drop).
fn with_64_fds(cmd: &mut Command, privileged: bool) {
    // SAFETY: setrlimit and prctl are async-signal-safe; the closure touches nothing but its
    // own stack.
    unsafe {
        cmd.pre_exec(move || {
            let lim = libc::rlimit {
                rlim_cur: 64,
                rlim_max: 64,
            };
            if libc::setrlimit(libc::RLIMIT_NOFILE, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            if !privileged && libc::geteuid() == 0 {
                let zero: libc::c_ulong = 0;
                if libc::prctl(libc::PR_CAPBSET_DROP, CAP_SYS_RESOURCE, zero, zero, zero) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
            }
            Ok(())
        });
    }
}

/// `launch --n 40` with RLIMIT_NOFILE at 64 (soft and hard) and no right to raise it: exit 2, "a
/// team of 40 agents needs about 344 file descriptors ... out of file descriptors (limit
/// RLIMIT_NOFILE soft 64, hard 64); raise it, e.g. `ulimit -n 344`", no run directory, nothing
/// of the team left. The check comes before anything is created, so the message does not depend
/// on which iceoryx2 call would have taken the last descriptor (CI once saw
/// `UnableToCreateServiceTag` there instead).
#[test]
fn running_out_of_file_descriptors_is_reported_with_the_limit() {
    let dir = TempDir::new();
    let team = unique_team("nofile");
    let out = dir.path().join("run");
    let mut cmd = launch(&team, &out, &["--n", "40"]);
    with_64_fds(&mut cmd, false);
    let o = run(&mut cmd, DEADLINE);
    let what = "launch --n 40 with 64 file descriptors";
    assert_exit(&o, 2, what);
    assert_stderr_has(
        &o,
        what,
        &[
            "out of file descriptors",
            "a team of 40 agents needs about 344 file descriptors",
            "limit RLIMIT_NOFILE soft 64, hard 64",
            "ulimit -n",
        ],
    );
    assert!(!out.exists(), "{} was written", out.display());
    assert_no_team_resources(&team);
}

/// An orchestrator allowed to raise its hard limit (root: `CAP_SYS_RESOURCE`) raises it to what
/// the team needs: `launch --n 40` with RLIMIT_NOFILE at 64 (soft and hard) flies. Skipped
/// (with a note) without `CAP_SYS_RESOURCE` (not root, or a sandbox that withholds it).
#[test]
fn a_privileged_launch_raises_a_low_hard_file_limit() {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let effective = (status.lines())
        .find_map(|l| l.strip_prefix("CapEff:"))
        .and_then(|v| u64::from_str_radix(v.trim(), 16).ok())
        .unwrap_or(0);
    if effective & (1 << CAP_SYS_RESOURCE) == 0 {
        eprintln!("skipped: without CAP_SYS_RESOURCE no process may raise its hard RLIMIT_NOFILE");
        return;
    }
    let dir = TempDir::new();
    let team = unique_team("nofileup");
    let out = dir.path().join("run");
    let mut cmd = launch(
        &team,
        &out,
        &["--n", "40", "--max-ticks", "20", "--no-figures"],
    );
    with_64_fds(&mut cmd, true);
    let o = run(&mut cmd, DEADLINE);
    assert_exit(&o, 0, "launch --n 40 with 64 file descriptors, as root");
    let rows = std::fs::read_to_string(out.join("telemetry.csv")).unwrap_or_default();
    assert_eq!(
        rows.lines().count(),
        1 + 21 * 40,
        "telemetry rows of 21 ticks"
    );
    assert_no_team_resources(&team);
}

/// `launch --n 40` with a 256 KiB /dev/shm (a private tmpfs in a private mount namespace, so
/// nothing else on the machine sees it): exit 2, "/dev/shm has 256 KiB free, a team of 40 agents
/// needs about ... KiB; ... enlarge it", no run directory. Without the check iceoryx2 dies of
/// SIGBUS writing past the full file system. Skipped (with a note) where `unshare -m` is not
/// allowed.
#[test]
fn a_full_dev_shm_is_reported_with_the_space_and_how_to_enlarge_it() {
    if !private_mounts_allowed() {
        return;
    }
    let dir = TempDir::new();
    let team = unique_team("shmfull");
    let out = dir.path().join("run");
    let root = iox2_root();
    // The root's own tmpfs is 0700: a root writable by others (a tmpfs is 1777) is refused
    // first, before any space is counted.
    let script = format!(
        "mount -t tmpfs -o size=256k tmpfs /dev/shm && mkdir -p {root} && \
         mount -t tmpfs -o mode=0700 tmpfs {root} && exec \"$0\" launch --n 40 --team {team} --out \"$1\" --quiet"
    );
    let o = run(
        Command::new("unshare")
            .args(["-m", "sh", "-c", &script])
            .arg(bin("orchestrator"))
            .arg(&out),
        DEADLINE,
    );
    let what = "launch --n 40 with a 256 KiB /dev/shm";
    assert_exit(&o, 2, what);
    assert_stderr_has(
        &o,
        what,
        &[
            "/dev/shm has 256 KiB free, a team of 40 agents needs about",
            "enlarge it (e.g. `mount -o remount,size=",
        ],
    );
    assert!(!out.exists(), "{} was written", out.display());
}

/// A cgroup (v1 `pids` controller) for one test, removed on drop after killing what is left in
/// it.
struct PidsCgroup(std::path::PathBuf);

impl PidsCgroup {
    /// A fresh cgroup with `pids.max = max`; `None` where cgroups cannot be made (not root, no
    /// v1 pids controller).
    fn new(max: u32) -> Option<Self> {
        let root = Path::new("/sys/fs/cgroup/pids");
        let dir = root.join(format!("cdm-test-{}-{max}", std::process::id()));
        std::fs::create_dir(&dir).ok()?;
        let g = PidsCgroup(dir);
        std::fs::write(g.0.join("pids.max"), max.to_string()).ok()?;
        Some(g)
    }
}

impl Drop for PidsCgroup {
    fn drop(&mut self) {
        let tasks = std::fs::read_to_string(self.0.join("tasks")).unwrap_or_default();
        for pid in tasks
            .lines()
            .filter_map(|l| l.trim().parse::<libc::pid_t>().ok())
        {
            // SAFETY: kill(2) takes no pointers; these are the test's own children.
            unsafe {
                libc::kill(pid, libc::SIGKILL);
            }
        }
        for _ in 0..100 {
            if std::fs::remove_dir(&self.0).is_ok() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// `launch --n 10` in a cgroup that allows 5 processes (root is exempt from RLIMIT_NPROC, a
/// cgroup is not): an agent cannot be started (which one depends on how many processes the
/// orchestrator and its member template use); exit 3 naming the agent and the process limit
/// with how to raise it; audit.json says `spawn-failed` for that agent; the started members are
/// stopped and nothing of the team is left. Skipped (with a note) where no pids cgroup can be
/// made.
#[test]
fn hitting_the_process_limit_is_reported_with_the_limit() {
    let Some(cgroup) = PidsCgroup::new(5) else {
        eprintln!(
            "skipped: cannot create a cgroup under /sys/fs/cgroup/pids (needs root, cgroup v1)"
        );
        return;
    };
    let dir = TempDir::new();
    let team = unique_team("nproc");
    let out = dir.path().join("run");
    let procs = cgroup.0.join("cgroup.procs");
    let o = run(
        Command::new("sh")
            .arg("-c")
            .arg("echo $$ > \"$0\" && exec \"$1\" launch --n 10 --team \"$2\" --out \"$3\" --quiet")
            .arg(&procs)
            .arg(bin("orchestrator"))
            .arg(&team)
            .arg(&out),
        DEADLINE,
    );
    let what = "launch --n 10 with 5 processes allowed";
    assert_exit(&o, 3, what);
    assert_stderr_has(
        &o,
        what,
        &[
            "error: cannot start agent ",
            "the process limit was hit (RLIMIT_NPROC ",
            "or the pids.max of this process's cgroup); raise it",
        ],
    );
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["fault"]["kind"], "spawn-failed", "{audit:#}");
    let agent = audit["fault"]["agent"]
        .as_u64()
        .expect("the agent that failed");
    assert!(agent <= 5, "{audit:#}");
    assert_stderr_has(&o, what, &[&format!("error: cannot start agent {agent}: ")]);
    assert_no_process_of(&team);
    assert_no_team_resources(&team);
}

/// SIGBUS, which iceoryx2 gets when /dev/shm fills up under a running team (another program
/// filling it): the process says "/dev/shm is probably full" and exits 3 instead of dumping
/// core silently; the orchestrator names it and stops the team, leaving nothing behind.
#[test]
fn a_bus_error_in_a_member_is_reported_as_shared_memory_full() {
    let dir = TempDir::new();
    let team = unique_team("sigbus");
    let out = dir.path().join("run");
    // `--on-loss stop`: the fault is the subject here (with repair the team flies on).
    let args = ["--n", "10", "--t-total", "600", "--on-loss", "stop"];
    let mut orch = spawn(&mut launch(&team, &out, &args));
    wait_for_rows(&mut orch, &out.join("telemetry.csv"), 100);
    let procs = team_processes(&team);
    assert_eq!(procs.len(), 11, "{procs:#?}");
    let fp = TeamFootprint::record(&team, procs.keys().copied());
    let pid = member_pid(&team, 9).expect("agent 9 runs");
    signal(pid, libc::SIGBUS);
    let o = orch.finish(DEADLINE);
    assert_exit(&o, 3, "launch after SIGBUS in agent 9");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("bus error (SIGBUS) touching shared memory: /dev/shm is probably full"),
        "{}",
        describe(&o)
    );
    let audit = read_json(&out.join("audit.json"));
    assert_eq!(audit["fault"]["kind"], "agent-exited", "{audit:#}");
    assert_eq!(audit["fault"]["agent"], 9, "{audit:#}");
    assert!(
        audit["fault"]["message"]
            .as_str()
            .is_some_and(|m| m.contains("agent 9 exited with code 3")),
        "{audit:#}"
    );
    assert_no_process_of(&team);
    fp.assert_nothing_left();
}
