//! The team's processes: check the member binaries, spawn one per quadcopter, notice one that
//! exits early, and stop them all (stop message, SIGTERM, SIGKILL, then clean their resources).

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use cdm_iox::{remove_dead_nodes, OrchestratorPorts, TeamName};
use cdm_model::formation::Role;
use cdm_model::outcome::FaultKind;
use cdm_records::audit::FaultRecord;
use cdm_runtime::messages::{ClockMsg, StopReason};
use cdm_scenario::Scenario;

/// A spawned member process.
pub struct Spawned {
    pub id: u32,
    pub child: MemberProcess,
}

/// A member's process: started from its binary, or forked by the member template and adopted
/// (`template.rs`); watched and stopped the same way.
#[derive(Debug)]
pub enum MemberProcess {
    Started(Child),
    Forked(cdm_process::fork::Adopted),
}

impl From<Child> for MemberProcess {
    fn from(c: Child) -> Self {
        MemberProcess::Started(c)
    }
}

impl MemberProcess {
    /// Its process id.
    pub fn id(&self) -> u32 {
        match self {
            MemberProcess::Started(c) => c.id(),
            MemberProcess::Forked(a) => a.id(),
        }
    }

    /// How it ended, if it has, without waiting.
    pub fn try_wait(&mut self) -> std::io::Result<Option<std::process::ExitStatus>> {
        match self {
            MemberProcess::Started(c) => c.try_wait(),
            MemberProcess::Forked(a) => a.try_wait(),
        }
    }

    /// Waits until it ends.
    pub fn wait(&mut self) -> std::io::Result<std::process::ExitStatus> {
        match self {
            MemberProcess::Started(c) => c.wait(),
            MemberProcess::Forked(a) => a.wait(),
        }
    }

    /// SIGKILL (nothing once it was reaped).
    pub fn kill(&mut self) -> std::io::Result<()> {
        match self {
            MemberProcess::Started(c) => c.kill(),
            MemberProcess::Forked(a) => a.kill(),
        }
    }
}

pub use cdm_runtime::process_exit::ProcessExit;
pub use cdm_runtime::team_core::{exited_fault, Stop};

/// A fault record.
pub fn fault(
    kind: FaultKind,
    agent: Option<u32>,
    peer: Option<u32>,
    tick: u64,
    message: String,
) -> FaultRecord {
    FaultRecord::new(kind, agent, peer, tick, message)
}

/// The `leader` and `agent` binaries must sit next to this one (`cargo build --release` builds
/// them; `cargo run --bin orchestrator` alone does not). Checked before anything is created.
pub fn member_binaries_present() -> Result<(), MemberBinaryError> {
    let exe = std::env::current_exe().map_err(MemberBinaryError::Locate)?;
    for name in ["leader", "agent"] {
        let path = exe.with_file_name(name);
        if !path.is_file() {
            return Err(MemberBinaryError::Missing { name, path });
        }
    }
    Ok(())
}

/// Why the member binaries cannot be started.
#[derive(Debug, thiserror::Error)]
pub enum MemberBinaryError {
    /// The running executable could not be found (the member binaries sit beside it): a fault.
    #[error("cannot locate the orchestrator binary: {0}")]
    Locate(#[source] std::io::Error),
    /// A member binary is not built: the operator's to fix (bad input).
    #[error(
        "the `{name}` binary is missing ({}): build every binary with `cargo build --release` \
         (`cargo run --bin orchestrator` builds only the orchestrator)",
        path.display()
    )]
    Missing {
        name: &'static str,
        path: std::path::PathBuf,
    },
}

/// Starts member `id`'s binary; `flags` are passed on (`--realtime`, ...).
pub fn spawn_member(
    scenario: &Path,
    team: &TeamName,
    id: u32,
    role: Role,
    flags: &[String],
) -> std::io::Result<Child> {
    member_command(scenario, team, id, role, flags)?.spawn()
}

/// The command [`spawn_member`] runs (to change before it is spawned).
pub fn member_command(
    scenario: &Path,
    team: &TeamName,
    id: u32,
    role: Role,
    flags: &[String],
) -> std::io::Result<Command> {
    let exe = std::env::current_exe()?;
    let bin = exe.with_file_name(if role.is_leader() { "leader" } else { "agent" });
    let mut c = Command::new(bin);
    c.args(member_args(scenario, team, id, flags))
        .stdin(Stdio::null())
        .stdout(Stdio::null());
    Ok(c)
}

/// A member's arguments after the program's name: `--scenario FILE --team T --id ID FLAGS`.
pub fn member_args(
    scenario: &Path,
    team: &TeamName,
    id: u32,
    flags: &[String],
) -> Vec<std::ffi::OsString> {
    let mut args: Vec<std::ffi::OsString> = vec![
        "--scenario".into(),
        scenario.into(),
        "--team".into(),
        team.as_str().into(),
        "--id".into(),
        id.to_string().into(),
    ];
    args.extend(flags.iter().map(Into::into));
    args
}

/// The first spawned member that has exited: its id and how.
pub fn first_exited(children: &mut [Spawned]) -> Option<(u32, ProcessExit)> {
    first_exited_but(children, |_| false)
}

/// [`first_exited`] among the members `known` does not hold (lost members already reaped).
pub fn first_exited_but(
    children: &mut [Spawned],
    known: impl Fn(u32) -> bool,
) -> Option<(u32, ProcessExit)> {
    children.iter_mut().filter(|c| !known(c.id)).find_map(|c| {
        let status = c.child.try_wait().ok()??;
        Some((c.id, ProcessExit::of(status)))
    })
}

/// A spawned member that exited before the end is a fault, named with its id and the tick.
pub fn check_children(children: &mut [Spawned], tick: u64) -> Result<(), Stop> {
    match first_exited(children) {
        Some((id, how)) => Err(exited_fault(id, how, tick)),
        None => Ok(()),
    }
}

/// Stop message, then SIGTERM, then SIGKILL for a process that does not stop; then remove the
/// dead nodes' resources. Bounded: about 3.6 s after a finished run (3 s to stop on its own),
/// 0.9 s otherwise.
pub fn stop_team(
    ports: &mut OrchestratorPorts,
    children: &mut [Spawned],
    s: &Scenario,
    reason: StopReason,
) {
    let _ = ports.publish_clock(ClockMsg::stop(s.last_tick(), s.content_hash(), reason));
    let wait_all = |children: &mut [Spawned], d: Duration| {
        let until = Instant::now() + d;
        loop {
            let alive = children
                .iter_mut()
                .map(|c| matches!(c.child.try_wait(), Ok(None)))
                .filter(|a| *a)
                .count();
            if alive == 0 || Instant::now() >= until {
                return alive;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    let graceful = if reason == StopReason::Finished {
        Duration::from_secs(3)
    } else {
        Duration::from_millis(300)
    };
    if wait_all(children, graceful) > 0 {
        for c in children.iter_mut() {
            if matches!(c.child.try_wait(), Ok(None)) {
                // SAFETY: plain kill(2) on our own child's pid, not reaped yet.
                unsafe {
                    libc::kill(c.child.id() as libc::pid_t, libc::SIGTERM);
                }
            }
        }
        if wait_all(children, Duration::from_millis(300)) > 0 {
            for c in children.iter_mut() {
                let _ = c.child.kill();
            }
            wait_all(children, Duration::from_millis(300));
        }
    }
    match remove_dead_nodes(ports.team()) {
        Ok(0) => {}
        Ok(k) => tracing::info!(removed = k, "removed resources of stopped processes"),
        Err(e) => tracing::warn!("{e}"),
    }
}

/// Peak resident memory (`VmHWM`) of a team's members, read from `/proc` before the team is
/// stopped (spawned teams only).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MembersPeak {
    /// The member with the largest peak, and that peak in KiB.
    pub largest: (u32, u64),
    /// The sum over every member read, in KiB. An upper bound of what the team takes: each
    /// member counts the pages it shares with the others (the binary's text, shared memory).
    pub total_kib: u64,
    /// How many members were read.
    pub members: usize,
}

/// The peak resident memory of the running `children`; `None` when none can be read.
pub fn members_peak_rss(children: &[Spawned]) -> Option<MembersPeak> {
    let peaks: Vec<(u32, u64)> = children
        .iter()
        .filter_map(|c| {
            let status = std::fs::read_to_string(format!("/proc/{}/status", c.child.id())).ok()?;
            Some((c.id, vm_hwm_kib(&status)?))
        })
        .collect();
    let largest = peaks
        .iter()
        .copied()
        .max_by_key(|&(id, kib)| (kib, std::cmp::Reverse(id)))?;
    Some(MembersPeak {
        largest,
        total_kib: peaks.iter().map(|p| p.1).sum(),
        members: peaks.len(),
    })
}

/// This process's peak resident memory in KiB.
pub fn own_peak_rss() -> Option<u64> {
    vm_hwm_kib(&std::fs::read_to_string("/proc/self/status").ok()?)
}

/// The `VmHWM:` line of a `/proc/<pid>/status` text, in KiB.
fn vm_hwm_kib(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}
