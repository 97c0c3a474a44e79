//! A paper40 team held in flight for live commands: launched in lockstep, one follower stopped
//! (SIGSTOP: the grants wait for it, so commands surely arrive while the team is airborne).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use integration_tests::{spawn, unique_team, Running, TempDir};

use super::{launch, member_pid, signal, Stopped};

/// How long a command's answer and the stopped team's first ticks may take.
const SHORT: Duration = integration_tests::deadline::REFUSE;

/// The follower stopped while the commands are given.
pub const STOPPED: u32 = 9;

/// paper40 launched in lockstep (a long agent timeout: one member is stopped for a while).
pub fn launched(team: &str, out: &Path) -> Running {
    let source = [
        "--builtin",
        "paper40",
        "--no-figures",
        "--agent-timeout",
        "120",
    ];
    spawn(&mut launch(team, out, &source))
}

/// Waits until telemetry.csv holds a row of tick `tick` or later.
pub fn wait_for_tick(orch: &mut Running, telemetry: &Path, tick: u64) {
    let until = Instant::now() + integration_tests::deadline::scaled(SHORT);
    loop {
        let text = std::fs::read_to_string(telemetry).unwrap_or_default();
        let last = (text.lines().rev())
            .filter_map(|l| l.split(',').next()?.parse::<u64>().ok())
            .next();
        if last.is_some_and(|t| t >= tick) {
            return;
        }
        assert!(!orch.has_exited(), "the launch ended before tick {tick}");
        assert!(
            Instant::now() < until,
            "no tick {tick} in {}",
            telemetry.display()
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Stops follower `STOPPED` once the team flew past `tick`: the grants then wait for it.
pub fn stop_a_follower(orch: &mut Running, team: &str, out: &Path, tick: u64) -> Stopped {
    wait_for_tick(orch, &out.join("telemetry.csv"), tick);
    let pid = member_pid(team, STOPPED).expect("the follower runs");
    signal(pid, libc::SIGSTOP);
    Stopped(pid)
}

/// Lets the stopped follower go on (the guard would kill it).
pub fn resume(stopped: Stopped) {
    signal(stopped.0, libc::SIGCONT);
    std::mem::forget(stopped);
}

/// A paper40 team launched under a unique name from `tag`, in flight with a follower stopped:
/// its temporary directory, name, run directory, launch and stopped follower.
pub fn stopped_team(tag: &str) -> (TempDir, String, PathBuf, Running, Stopped) {
    let tmp = TempDir::new();
    let team = unique_team(tag);
    let out = tmp.path().join("launch");
    let mut orch = launched(&team, &out);
    let stopped = stop_a_follower(&mut orch, &team, &out, 500);
    (tmp, team, out, orch, stopped)
}
