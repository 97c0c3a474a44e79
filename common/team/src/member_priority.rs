//! How the orchestrator starts lockstep members: at a lower CPU priority than itself, and with a
//! silence timeout that follows `--agent-timeout`.
//!
//! Why: in lockstep the orchestrator is one process on the team's critical path (it grants, and
//! audits and writes every tick), while its members may have a window of ticks of work each. At
//! N = 2000 on 2 cores about 800 members were runnable at once, the scheduler gave the
//! orchestrator its fair 1/800 share, it did not run for 11.3 s, and the members' silence
//! timeout stopped the team. A nice value of [`MEMBER_NICE`] above the orchestrator's weighs a
//! member about a tenth of it (Linux CFS weights 1024 at nice 0, 110 at nice 10), so it is not
//! starved while the members have work. Results do not depend on scheduling (lockstep), and
//! raising a child's nice value needs no privilege. Real-time members keep their priority (the
//! real-time options decide it).

use std::process::Child;

/// How far above the orchestrator's nice value a lockstep member runs (clamped to 19).
pub const MEMBER_NICE: i32 = 10;

/// Lowers `child`'s priority to the orchestrator's nice value + [`MEMBER_NICE`]. Best effort:
/// a member that keeps its priority still flies, only the orchestrator may then be starved on a
/// crowded machine, so a failure is logged.
pub fn lower(child: &Child) {
    // SAFETY: getpriority/setpriority take plain integers and touch no memory of ours; errno is
    // cleared first because -1 is also a valid nice value.
    let own = unsafe {
        *libc::__errno_location() = 0;
        libc::getpriority(libc::PRIO_PROCESS, 0)
    };
    let nice = (own + MEMBER_NICE).min(19);
    // SAFETY: as above; `child.id()` is our own child's pid, not yet reaped.
    if unsafe { libc::setpriority(libc::PRIO_PROCESS, child.id(), nice) } != 0 {
        tracing::debug!(pid = child.id(), nice, error = %std::io::Error::last_os_error(),
            "cannot lower a member's priority");
    }
}

/// Flags for a spawned lockstep member: `--silence-timeout` at twice `--agent-timeout` when that
/// exceeds the members' default (10 s), nothing otherwise (the default run is unchanged). Why:
/// a team so large that one half-window takes longer than 10 s on a crowded machine (N = 2000
/// on 2 cores at load average 300+) saw its leaders, which wait for nothing but grants, stop by
/// themselves; a user who gives the orchestrator more patience gives it to the members too,
/// and the orchestrator still notices a silent member first.
pub fn lockstep_flags(agent_timeout: std::time::Duration) -> Vec<String> {
    let silence_s = 2.0 * agent_timeout.as_secs_f64();
    if silence_s > cdm_member::member::DEFAULT_SILENCE_TIMEOUT_S {
        vec!["--silence-timeout".into(), silence_s.to_string()]
    } else {
        Vec::new()
    }
}

#[cfg(test)]
mod tests {
    use super::lockstep_flags;
    use std::time::Duration;

    #[test]
    fn the_default_agent_timeout_keeps_the_members_default() {
        assert!(lockstep_flags(Duration::from_secs(5)).is_empty());
    }

    #[test]
    fn a_longer_agent_timeout_doubles_into_the_members_silence_timeout() {
        assert_eq!(
            lockstep_flags(Duration::from_secs(60)),
            vec!["--silence-timeout".to_string(), "120".to_string()]
        );
    }
}
