//! Whether the process that minted an iceoryx2 name is gone: read by the sweep of dead teams
//! and by the removal of orphan nodes.

/// True when every 128-bit id in `name` was minted by a process that no longer exists (and
/// there is at least one).
pub(super) fn creator_is_dead(name: &str) -> bool {
    let mut pids = crate::ids::ids_in(name)
        .map(|id| crate::ids::id_pid(id) as libc::pid_t)
        .peekable();
    pids.peek().is_some()
        && pids.all(|pid| {
            // SAFETY: kill(2) with signal 0 only asks whether the process exists.
            pid > 0
                && unsafe { libc::kill(pid, 0) } != 0
                && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH)
        })
}
