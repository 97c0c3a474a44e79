//! The loop around a [`MemberCore`]: it only moves messages between the core and a transport,
//! reads the clock, and sleeps. Generic over the transport, the vehicle and both clocks, so the
//! hot path has no dynamic dispatch.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::fault_inject::Injection;
use crate::member_core::{Action, Finished, MemberCore, MemberFault, ALIVE_CHECK};
use crate::member_loss::LossWork;
use crate::messages::{ClockCommand, StateMsg};
use crate::seams::{Clock, MemberTransport, TickClock, Vehicle};

/// Why the loop stopped without the orchestrator's stop.
#[derive(Debug)]
pub enum LoopError<E> {
    /// The transport failed.
    Transport(E),
    /// The protocol found a fault (already reported to the team when it has a report).
    Fault(MemberFault),
    /// SIGINT or SIGTERM at this tick.
    Interrupted { tick: u64 },
}

/// Flies `core` over `transport` until the orchestrator stops the team, a fault, or a signal.
/// `inject` (tests only) alters a state just before it is published.
pub fn fly<T, V, C, K>(
    core: &mut MemberCore<V, C>,
    transport: &mut T,
    clock: &K,
    interrupted: &AtomicBool,
    inject: Option<&Injection>,
) -> Result<Finished, LoopError<T::Error>>
where
    T: MemberTransport,
    V: Vehicle,
    C: TickClock,
    K: Clock,
{
    loop {
        if interrupted.load(Ordering::Relaxed) {
            return Err(LoopError::Interrupted { tick: core.tick() });
        }
        let mut outcome = Ok(None);
        transport
            .receive_clock(|c| {
                if matches!(outcome, Ok(None)) {
                    outcome = core.on_clock(&c);
                }
            })
            .map_err(LoopError::Transport)?;
        if let Some(done) = outcome.map_err(LoopError::Fault)? {
            // The stop reaches readers the orchestrator does not wake itself through us.
            let _ = transport.notify_readers();
            return Ok(done);
        }
        transport
            .receive_neighbors(|m| core.on_neighbor(&m))
            .map_err(LoopError::Transport)?;
        loop {
            match core.poll(clock.now()) {
                Action::Publish(mut msg) => {
                    if let Some(i) = inject {
                        // An injected crash or hang happens "instead of publishing this tick":
                        // every earlier state must be out, as if each were its own sample.
                        transport.flush().map_err(LoopError::Transport)?;
                        i.apply(msg.tick, &mut msg);
                    }
                    transport
                        .publish_quietly(msg)
                        .map_err(LoopError::Transport)?;
                }
                Action::CheckOrchestrator => {
                    core.on_orchestrator_alive(transport.orchestrator_alive());
                }
                Action::NotifyReaders => {
                    transport.notify_readers().map_err(LoopError::Transport)?;
                    break;
                }
                Action::Repair(work) => {
                    let done = match work {
                        LossWork::Connect { subscribe, notify } => {
                            transport.connect(&subscribe, &notify)
                        }
                        LossWork::HandOver => transport.hand_over(),
                    };
                    if !done.map_err(LoopError::Transport)? {
                        let tick = core.tick();
                        return Err(LoopError::Fault(MemberFault::RepairUnsupported { tick }));
                    }
                }
                Action::Poll => break,
                Action::Wait(d) => {
                    transport.wait(d).map_err(LoopError::Transport)?;
                    break;
                }
                Action::Fail { report, fault } => {
                    return Err(failed(transport, clock, interrupted, report, fault));
                }
            }
        }
    }
}

/// [`Action::Fail`] in either loop (lockstep or real time): publish the fault's report, if
/// any, and [`linger`] for the orchestrator's stop so the team reads it; the loop then ends.
pub(crate) fn failed<T: MemberTransport, K: Clock>(
    transport: &mut T,
    clock: &K,
    interrupted: &AtomicBool,
    report: Option<StateMsg>,
    fault: MemberFault,
) -> LoopError<T::Error> {
    if let Some(r) = report {
        let _ = transport.publish(r);
        linger(transport, clock, interrupted);
    }
    LoopError::Fault(fault)
}

/// How long a member that reported a fault keeps its ports open for the orchestrator's stop.
pub const LINGER: Duration = Duration::from_secs(5);

/// After a fault report: keep the process (and so its published states) alive until the
/// orchestrator stops the team, it is gone, or [`LINGER`] passes. iceoryx2 drops the samples a
/// subscriber has not yet taken when their publisher's process exits, so a member that ran ahead
/// (a large window) and exited at once could take its fault report, and the states before it,
/// with it; the orchestrator would then see only an exited process.
pub fn linger<T: MemberTransport, K: Clock>(
    transport: &mut T,
    clock: &K,
    interrupted: &AtomicBool,
) {
    let start = clock.now();
    let mut last_alive_check = start;
    while clock.now().saturating_sub(start) < LINGER && !interrupted.load(Ordering::Relaxed) {
        match transport.latest_clock() {
            Ok(Some(c)) if matches!(c.command(), ClockCommand::Stop(_)) => {
                // Passed on, as in `fly`: readers may be woken only through us.
                let _ = transport.notify_readers();
                return;
            }
            Ok(_) => {}
            Err(_) => return,
        }
        if clock.now().saturating_sub(last_alive_check) >= ALIVE_CHECK {
            last_alive_check = clock.now();
            if !transport.orchestrator_alive() {
                return;
            }
        }
        if transport.wait(Duration::from_millis(100)).is_err() {
            return;
        }
    }
}
