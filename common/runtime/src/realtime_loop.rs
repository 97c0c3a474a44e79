//! The wall clock's side of the member loop ([`crate::member_loop::fly`]) in real time: the
//! system clock read once at the start, and waits that meet a tick's instant.

use std::time::Duration;

use crate::seams::MemberTransport;

/// The system clock (CLOCK_REALTIME) in nanoseconds since the Unix epoch: read once, when the
/// start arrives, to place the announced start instant on the member's monotonic clock.
pub fn unix_now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// Below this a wait is a plain sleep, not the transport's: the transport's timed wait is only
/// as fine as the kernel's socket timeouts (a few ms) and treats a zero timeout as "forever",
/// while a tick's instant must be met to a fraction of a period. Longer waits go through the
/// transport, so the orchestrator's stop wakes the member at once.
pub const FINE_WAIT: Duration = Duration::from_millis(20);

/// Sleeps for `d`: through the transport (woken early by the stop) down to [`FINE_WAIT`], then
/// precisely.
pub(crate) fn pause<T: MemberTransport>(transport: &mut T, d: Duration) -> Result<(), T::Error> {
    if d > FINE_WAIT {
        transport.wait(d - FINE_WAIT)?;
    } else if !d.is_zero() {
        std::thread::sleep(d);
    }
    Ok(())
}
