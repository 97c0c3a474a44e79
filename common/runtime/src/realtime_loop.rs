//! The loop around a [`RealtimeCore`]: it moves messages between the core and a transport, reads
//! the clocks and sleeps; every decision is the core's. States are published without waking
//! anyone: a real-time reader reads at its own tick, never because a neighbour published.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::member_core::{Action, Finished};
use crate::member_loop::{failed, linger, LoopError};
use crate::realtime::RealtimeCore;
use crate::seams::{Clock, MemberTransport, Vehicle};

/// The system clock (CLOCK_REALTIME) in nanoseconds since the Unix epoch: read once, when the
/// start arrives, to place the announced start instant on the member's monotonic clock.
pub fn unix_now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// Flies `core` in real time over `transport` until the orchestrator stops the team, a fault,
/// or a signal. At the stop it publishes its pacing figures and waits (at most
/// [`crate::member_loop::LINGER`]) for the orchestrator's second stop or its end, which come once
/// the orchestrator has read them. After a reported fault the member holds (flies no further tick) and keeps its
/// ports open until the stop, as in lockstep.
pub fn fly_realtime<T, V, K>(
    core: &mut RealtimeCore<V>,
    transport: &mut T,
    clock: &K,
    interrupted: &AtomicBool,
) -> Result<Finished, LoopError<T::Error>>
where
    T: MemberTransport,
    V: Vehicle,
    K: Clock,
{
    loop {
        if interrupted.load(Ordering::Relaxed) {
            return Err(LoopError::Interrupted { tick: core.tick() });
        }
        if let Some(c) = transport.latest_clock().map_err(LoopError::Transport)? {
            let started = core.on_clock(&c, clock.now(), unix_now_ns());
            if let Some(done) = started.map_err(LoopError::Fault)? {
                // The final pacing figures; kept readable until the orchestrator's second stop
                // (a publisher's unread samples die with its process).
                let _ = transport.publish(core.pacing().to_msg(core.id(), core.hash()));
                linger(transport, clock, interrupted);
                return Ok(done);
            }
        }
        transport
            .receive_neighbors(|m| core.on_neighbor(&m))
            .map_err(LoopError::Transport)?;
        loop {
            match core.poll(clock.now()) {
                Action::Publish(msg) => {
                    transport
                        .publish_quietly(msg)
                        .map_err(LoopError::Transport)?;
                    // Readers poll by the clock, not by wake-ups: the state must be out now.
                    transport.flush().map_err(LoopError::Transport)?;
                }
                Action::CheckOrchestrator => {
                    core.on_orchestrator_alive(transport.orchestrator_alive());
                }
                // Flew a tick: read the clock and the neighbours again before the next one.
                // The real-time core never asks for a repair: losses are repaired in lockstep only
                // (a real-time team stops on a lost member).
                Action::Poll | Action::NotifyReaders | Action::Repair(_) => break,
                Action::Wait(d) => {
                    pause(transport, d).map_err(LoopError::Transport)?;
                    break;
                }
                Action::Fail { report, fault } => {
                    return Err(failed(transport, clock, interrupted, report, fault));
                }
            }
        }
    }
}

/// Below this a wait is a plain sleep, not the transport's: the transport's timed wait is only
/// as fine as the kernel's socket timeouts (a few ms) and treats a zero timeout as "forever",
/// while a tick's instant must be met to a fraction of a period. Longer waits go through the
/// transport, so the orchestrator's stop wakes the member at once.
pub const FINE_WAIT: std::time::Duration = std::time::Duration::from_millis(20);

/// Sleeps for `d`: through the transport (woken early by the stop) down to [`FINE_WAIT`], then
/// precisely.
fn pause<T: MemberTransport>(transport: &mut T, d: std::time::Duration) -> Result<(), T::Error> {
    if d > FINE_WAIT {
        transport.wait(d - FINE_WAIT)?;
    } else if !d.is_zero() {
        std::thread::sleep(d);
    }
    Ok(())
}
