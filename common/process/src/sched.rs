//! Real-time scheduling for `--realtime --rt-priority P`: the calling thread (and the threads
//! and processes it creates afterwards) runs under Linux's `SCHED_FIFO` at priority P.
//!
//! Why: in real time each member must wake at its own instant every period (1/comm_hz). Under
//! the default CFS policy a wake-up waits behind whatever else is runnable, so with hundreds of
//! members (or a compiler) on 2 cores single wake-ups queue for more than a period and the tick
//! is late (BENCHMARKS.md, "Real time"). A `SCHED_FIFO` thread that becomes runnable preempts
//! every CFS thread at once; the members' own work per tick is tens of microseconds, so they
//! barely queue behind each other. The kernel's RT throttling (`sched_rt_runtime_us`, 95 % by
//! default) keeps the rest of the machine alive if a team asks for more than the CPUs have.

/// `SCHED_FIFO` could not be set: the process lacks the right (root, `CAP_SYS_NICE`, or an
/// `RLIMIT_RTPRIO` of at least the priority, `ulimit -r`).
#[derive(Debug, thiserror::Error)]
#[error(
    "--rt-priority {priority}: this process may not use SCHED_FIFO at priority {priority} \
     (it needs root, CAP_SYS_NICE or `ulimit -r` of at least {priority})"
)]
pub struct SchedError {
    pub priority: u8,
    #[source]
    pub source: std::io::Error,
}

/// The lowest and highest `SCHED_FIFO` priorities Linux accepts.
pub const RT_PRIORITIES: std::ops::RangeInclusive<i64> = 1..=99;

/// Puts the calling thread under `SCHED_FIFO` at `priority`. Threads and child processes
/// created afterwards inherit it, so call it before spawning.
pub fn fifo(priority: u8) -> Result<(), SchedError> {
    let param = libc::sched_param {
        sched_priority: i32::from(priority),
    };
    // SAFETY: `param` is a valid sched_param for the whole call; pid 0 is the calling thread.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    if rc == 0 {
        tracing::debug!(priority, "running under SCHED_FIFO");
        Ok(())
    } else {
        Err(SchedError {
            priority,
            source: std::io::Error::last_os_error(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Priority 0 is not a SCHED_FIFO priority: the kernel refuses it (EINVAL) whoever asks, so
    /// the error path is exercised on any machine; its message names the flag.
    #[test]
    fn an_invalid_priority_is_refused_naming_the_flag() {
        let e = fifo(0).unwrap_err();
        assert_eq!(e.source.raw_os_error(), Some(libc::EINVAL));
        assert!(e.to_string().starts_with("--rt-priority 0:"), "{e}");
    }
}
