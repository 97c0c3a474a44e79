//! Process limits that iceoryx2 runs into with large teams, reported as such: when a port or
//! node cannot be created while this process's file-descriptor table is (nearly) full, the error
//! says which limit was hit and how to raise it, instead of iceoryx2's bare `InternalFailure`.

/// Descriptors this close to the soft limit count as "the limit was hit": iceoryx2 releases
/// what a failed port had opened before it reports the failure.
const FD_MARGIN: u64 = 16;

/// This process's open-file numbers at the moment of a failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FdUsage {
    /// Descriptors open now (entries of `/proc/self/fd`).
    pub open: u64,
    /// The soft `RLIMIT_NOFILE`.
    pub soft: u64,
    /// The hard `RLIMIT_NOFILE`.
    pub hard: u64,
}

/// This process's (soft, hard) limit of `resource` (`libc::RLIMIT_*`).
fn limit(resource: libc::__rlimit_resource_t) -> std::io::Result<(u64, u64)> {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `lim` is a valid, writable rlimit for the duration of the call.
    if unsafe { libc::getrlimit(resource, &mut lim) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    #[allow(clippy::unnecessary_cast)] // rlim_t is u64 on Linux, not everywhere
    Ok((lim.rlim_cur as u64, lim.rlim_max as u64))
}

/// Raises this process's soft `RLIMIT_NOFILE` to the hard limit and returns the new soft limit.
/// The orchestrator holds 6 to 11 descriptors per member, so a large team passes 1024 quickly.
pub fn raise_fd_limit() -> std::io::Result<u64> {
    let (soft, hard) = limit(libc::RLIMIT_NOFILE)?;
    if soft < hard {
        let lim = libc::rlimit {
            rlim_cur: hard as libc::rlim_t,
            rlim_max: hard as libc::rlim_t,
        };
        // SAFETY: `lim` is a valid rlimit; only the soft limit changed, within the hard limit.
        if unsafe { libc::setrlimit(libc::RLIMIT_NOFILE, &lim) } != 0 {
            return Err(std::io::Error::last_os_error());
        }
    }
    Ok(hard)
}

/// `Some` when the open-file limit is (nearly) exhausted; `None` when it is not or cannot be read.
pub fn fd_exhausted() -> Option<FdUsage> {
    let (soft, hard) = limit(libc::RLIMIT_NOFILE).ok()?;
    let open = match std::fs::read_dir("/proc/self/fd") {
        Ok(d) => d.count() as u64,
        // Listing the table needs a descriptor of its own: failing for lack of one is the answer.
        Err(e) if matches!(e.raw_os_error(), Some(libc::EMFILE | libc::ENFILE)) => soft,
        Err(_) => return None,
    };
    (open + FD_MARGIN >= soft).then_some(FdUsage { open, soft, hard })
}

/// Descriptors the orchestrator holds for a team of `agents`, measured with iceoryx2 0.10 on a
/// flying team. When it wakes every member itself (`launch --n 100` held 1,119): per member 11,
/// the dynamic segment and static file of its state and wake services, a port tag for the
/// subscriber and the notifier, a connection segment each way (its state, the clock), the wake
/// event's management segment and socket and its publisher's data segment; estimated at 12 per
/// member (N = 2000: 24,064, above this machine's hard limit of 20,000). With relayed wake-ups
/// (`TeamLayout::with_relayed_wakes`) the wake event's five are gone once the team flies (its
/// static file and segment are held only while the team gathers, when no connection is open
/// yet): 6 per member, estimated at 7. Both with 64 for the run directory, the children's pipes
/// and the logging.
pub fn orchestrator_fd_need(agents: usize, relayed_wakes: bool) -> u64 {
    let per_agent = if relayed_wakes { 7 } else { 12 };
    64 + per_agent * agents as u64
}

/// The orchestrator's open-file limit against what a team needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FdShortfall {
    /// What the team needs ([`orchestrator_fd_need`]).
    pub need: u64,
    /// The soft `RLIMIT_NOFILE`.
    pub soft: u64,
    /// The hard `RLIMIT_NOFILE`.
    pub hard: u64,
}

/// `Some` when this process's soft open-file limit is below what a team of `agents` needs, so
/// the launch can refuse before it creates anything (instead of failing half-way, at whichever
/// iceoryx2 call happens to take the last descriptor). A limit below the need is first raised
/// as far as this process may ([`raise_fd_limit_to`]).
pub fn fd_short(agents: usize, relayed_wakes: bool) -> Option<FdShortfall> {
    let need = orchestrator_fd_need(agents, relayed_wakes);
    raise_fd_limit_to(need);
    let (soft, hard) = limit(libc::RLIMIT_NOFILE).ok()?;
    (soft < need).then_some(FdShortfall { need, soft, hard })
}

/// Raises the soft `RLIMIT_NOFILE` to `need` when the hard limit allows it, and otherwise the hard
/// limit too, up to the kernel's `fs.nr_open`, which only a privileged process may do (root:
/// `CAP_SYS_RESOURCE`). Best effort: what it cannot raise, [`fd_short`] reports.
pub fn raise_fd_limit_to(need: u64) {
    let Ok((soft, hard)) = limit(libc::RLIMIT_NOFILE) else {
        return;
    };
    if soft >= need {
        return;
    }
    let nr_open = std::fs::read_to_string("/proc/sys/fs/nr_open")
        .ok()
        .and_then(|t| t.trim().parse::<u64>().ok())
        .unwrap_or(hard);
    let target = need.min(nr_open.max(hard));
    let lim = libc::rlimit {
        rlim_cur: target as libc::rlim_t,
        rlim_max: target.max(hard) as libc::rlim_t,
    };
    // SAFETY: `lim` is a valid rlimit; the kernel refuses (EPERM) a hard limit above the current
    // one for an unprivileged process, which leaves the limits as they were.
    if unsafe { libc::setrlimit(libc::RLIMIT_NOFILE, &lim) } != 0 {
        tracing::debug!(
            need,
            soft,
            hard,
            error = %std::io::Error::last_os_error(),
            "cannot raise the open-file limit"
        );
    }
}

/// Where iceoryx2 (0.10, Linux) keeps its shared-memory segments.
pub const SHM_DIR: &str = "/dev/shm";

/// Shared memory a team takes with a window of `window` ticks, measured with iceoryx2 0.10 at
/// N = 100 as the space the tmpfs reports used (segments and iceoryx2's root files), when a
/// state sample was one 128-byte state: about 54 KiB per member at window 4, and the state
/// segments grew by about 0.8 KiB per member per tick of window (window 256: 207 KiB, 1024:
/// 789 KiB per member). They grow with the sample's size ([`StateBatch`](crate::StateBatch), up
/// to [`STATES_PER_SAMPLE`](crate::STATES_PER_SAMPLE) states): asked for at 1 KiB per 128 bytes
/// of sample, with a margin.
pub fn shm_need_bytes(agents: usize, window: u32) -> u64 {
    let per_tick_kib = (std::mem::size_of::<crate::StateBatch>() as u64).div_ceil(128);
    (agents as u64 + 4) * (64 + u64::from(window) * per_tick_kib) * 1024
}

/// The smallest window [`lockstep_window`] falls back to when shared memory is short.
pub const MIN_AUTO_WINDOW: u32 = 16;

/// The window a lockstep team of `agents` flies with when none is asked for, with link delays
/// of up to `delay` ticks (the buffers hold `window + delay` ticks) and `free` bytes free in
/// [`SHM_DIR`] (`None`: not known).
///
/// Wider windows let a member fly more ticks per wake-up (docs/src/benchmarks/scale.md: 1024
/// against 256 flew N = 250 1.6x, N = 40 1.15x and N = 1000 1.41x faster) but cost about
/// 0.8 KiB of shared memory per member per tick of window, and a member touches more of it: at
/// N = 1000 the largest member's peak RSS was 11.8 MiB at 1024 against 9.8 at 256. So 1024 for
/// teams of up to 250, 512 up to 500, 256 above; then halved (down to [`MIN_AUTO_WINDOW`])
/// while the team's segments would take more than half of what is free, leaving the rest to
/// other teams. When even the smallest does not fit, the smallest is returned and the
/// orchestrator's check refuses the team with the space it needs.
pub fn lockstep_window(agents: usize, delay: u32, free: Option<u64>) -> u32 {
    let mut window: u32 = match agents {
        0..=250 => 1024,
        251..=500 => 512,
        _ => 256,
    };
    let Some(free) = free else {
        return window;
    };
    while window > MIN_AUTO_WINDOW
        && shm_need_bytes(agents, window.saturating_add(delay)) > free / 2
    {
        window /= 2;
    }
    window
}

/// Free bytes for unprivileged writers in `dir`, if it can be asked.
pub fn free_bytes(dir: &str) -> Option<u64> {
    let path = std::ffi::CString::new(dir).ok()?;
    // SAFETY: `st` is zero-initialised plain data that statvfs fills; `path` is NUL-terminated.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: both pointers are valid for the duration of the call.
    if unsafe { libc::statvfs(path.as_ptr(), &mut st) } != 0 {
        return None;
    }
    #[allow(clippy::unnecessary_cast)] // the field types differ between platforms
    Some(st.f_bavail as u64 * st.f_frsize as u64)
}

/// Free bytes in [`SHM_DIR`], where the team's segments go, if it can be asked.
pub fn shm_free_bytes() -> Option<u64> {
    free_bytes(SHM_DIR)
}

/// `e`, the error of starting a process, with the limit behind it when it is the process limit
/// (`EAGAIN` from fork: `RLIMIT_NPROC`, which root is exempt from, or a cgroup's `pids.max`).
pub fn describe_spawn_error(e: &std::io::Error) -> String {
    if e.raw_os_error() != Some(libc::EAGAIN) {
        return e.to_string();
    }
    let show = |v: u64| {
        #[allow(clippy::unnecessary_cast)] // rlim_t is u64 on Linux, not everywhere
        if v == libc::RLIM_INFINITY as u64 {
            "unlimited".to_string()
        } else {
            v.to_string()
        }
    };
    let nproc = limit(libc::RLIMIT_NPROC).map_or_else(
        |_| "unknown".to_string(),
        |(soft, hard)| format!("soft {}, hard {}", show(soft), show(hard)),
    );
    format!(
        "{e}: the process limit was hit (RLIMIT_NPROC {nproc}, or the pids.max of this \
         process's cgroup); raise it (`ulimit -u`, or the cgroup's pids.max) or fly a smaller team"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_window_narrows_with_the_team() {
        assert_eq!(lockstep_window(40, 0, None), 1024);
        assert_eq!(lockstep_window(250, 0, None), 1024);
        assert_eq!(lockstep_window(400, 0, None), 512);
        assert_eq!(lockstep_window(1000, 0, None), 256);
    }

    #[test]
    fn the_window_halves_until_the_team_takes_at_most_half_the_free_memory() {
        let plenty = 1 << 40;
        assert_eq!(lockstep_window(40, 0, Some(plenty)), 1024);
        // Room for exactly window 128 in half the free space.
        let free = 2 * shm_need_bytes(1000, 128);
        assert_eq!(lockstep_window(1000, 0, Some(free)), 128);
        assert_eq!(lockstep_window(1000, 0, Some(free - 1)), 64);
        // Link delays count: the buffers hold window + delay ticks.
        assert_eq!(lockstep_window(1000, 64, Some(free)), 64);
    }

    #[test]
    fn a_full_file_system_gets_the_smallest_window_for_the_check_to_refuse() {
        assert_eq!(lockstep_window(1000, 0, Some(0)), MIN_AUTO_WINDOW);
        assert!(shm_need_bytes(1000, MIN_AUTO_WINDOW) > 0);
    }
}
