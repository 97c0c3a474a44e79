//! Who minted an iceoryx2 file, and when: the sweep of dead teams (`creator.rs`) and the
//! "nothing of the team is left" checks of the tests use it to attribute files to a process.
//!
//! iceoryx2 0.10 names its files (node, port, service and event ids) with 128-bit ids laid out
//! as `UniqueSystemId { seconds, nanoseconds, pid, counter }` (u32 each, little end first): the
//! creator's process id in bits 64..96 and the CLOCK_MONOTONIC second of the id's creation in
//! bits 0..32. Process ids wrap (32,768 by default), so a pid alone blames a live team for the
//! files of an old dead process that had the same pid; a file is the team's only when its id
//! was also minted after the process holding that pid now was born.

/// The process id in an iceoryx2 id (bits 64..96).
pub fn id_pid(id: u128) -> u32 {
    (id >> 64) as u32
}

/// The CLOCK_MONOTONIC second at which an iceoryx2 id was minted (bits 0..32).
pub fn id_seconds(id: u128) -> u32 {
    id as u32
}

/// The iceoryx2 ids in a file name: runs of at least 20 digits (a 128-bit id with a pid in it
/// has at least 20 decimal digits).
pub fn ids_in(name: &str) -> impl Iterator<Item = u128> + '_ {
    name.split(|c: char| !c.is_ascii_digit())
        .filter(|run| run.len() >= 20)
        .filter_map(|run| run.parse::<u128>().ok())
}

fn clock_s(clock: libc::clockid_t) -> f64 {
    // SAFETY: an all-zero timespec is a valid value for clock_gettime(2) to overwrite.
    let mut ts: libc::timespec = unsafe { std::mem::zeroed() };
    // SAFETY: clock_gettime(2) writes into a timespec we own.
    let rc = unsafe { libc::clock_gettime(clock, &mut ts) };
    // The clocks asked for exist on every Linux since 2.6.39: a failure leaves zero.
    if rc != 0 {
        return 0.0;
    }
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// Now, in the seconds of iceoryx2's ids (CLOCK_MONOTONIC).
pub fn monotonic_s() -> u32 {
    clock_s(libc::CLOCK_MONOTONIC) as u32
}

/// The CLOCK_MONOTONIC second at which process `pid` started, rounded down and less one second
/// of slack (`/proc/<pid>/stat` counts in clock ticks since boot); `None` once it is gone.
pub fn born_s(pid: u32) -> Option<u32> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Field 22 (starttime) counts from the field after the command name, which may hold spaces.
    let (_, rest) = stat.rsplit_once(')')?;
    let ticks: f64 = rest.split_whitespace().nth(19)?.parse().ok()?;
    // SAFETY: sysconf(3) takes no pointers.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    // starttime is on the boot-time clock; the age carries over to the monotonic clock.
    let age = clock_s(libc::CLOCK_BOOTTIME) - ticks / hz;
    let born = (clock_s(libc::CLOCK_MONOTONIC) - age).max(0.0) as u32;
    Some(born.saturating_sub(1))
}
