//! The loop around a [`MemberCore`], in lockstep and in real time: it only moves messages
//! between the core and a transport, reads the clocks, and sleeps; every decision is the
//! core's, and how messages move is what the core's [`Timing`] says
//! ([`Wiring`](crate::member_core::Wiring)). Generic over the transport, the vehicle, the
//! timing and the clock, so the hot path has no dynamic dispatch.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::member_core::{Action, Finished, MemberCore, MemberFault, Timing, ALIVE_CHECK};
use crate::member_loss::LossWork;
use crate::messages::{ClockCommand, StateMsg};
use crate::realtime_loop::{pause, unix_now_ns};
use crate::seams::{Clock, MemberTransport, Vehicle};

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

/// Alters a state just before it is published: the hook through which tests inject faults
/// (`cdm_process::fault_inject`; a crash or a hang "instead of publishing this tick").
pub type BeforePublish<'a> = &'a dyn Fn(&mut StateMsg);

/// Flies `core` over `transport` until the orchestrator stops the team, a fault, or a signal.
/// `inject` (tests only) alters a state just before it is published. At the stop a member with
/// a final report (real time: its pacing figures) publishes it and waits (at most [`LINGER`])
/// for the orchestrator's second stop or its end, which come once the orchestrator has read
/// it. After a reported fault the member holds (flies no further tick) and keeps its ports
/// open until the stop.
pub fn fly<T, V, P, K>(
    core: &mut MemberCore<V, P>,
    transport: &mut T,
    clock: &K,
    interrupted: &AtomicBool,
    inject: Option<BeforePublish>,
) -> Result<Finished, LoopError<T::Error>>
where
    T: MemberTransport,
    V: Vehicle,
    P: Timing<V>,
    K: Clock,
{
    loop {
        if interrupted.load(Ordering::Relaxed) {
            return Err(LoopError::Interrupted { tick: core.tick() });
        }
        if let Some(done) = read_clock(core, transport, clock)? {
            match core.final_report() {
                // Kept readable until the orchestrator's second stop (a publisher's unread
                // samples die with its process).
                Some(report) => {
                    let _ = transport.publish(report);
                    linger(transport, clock, interrupted);
                }
                // The stop reaches readers the orchestrator does not wake itself through us.
                None => {
                    let _ = transport.notify_readers();
                }
            }
            return Ok(done);
        }
        transport
            .receive_neighbors(|m| core.on_neighbor(&m))
            .map_err(LoopError::Transport)?;
        loop {
            match core.poll(clock.now()) {
                Action::Publish(msg) => {
                    publish(transport, msg, inject, P::WIRING.flush_each_publish)?;
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
                // Progressed (in real time: flew a tick): read the inputs again first.
                Action::Poll => break,
                Action::Wait(d) => {
                    if P::WIRING.fine_waits {
                        pause(transport, d)
                    } else {
                        transport.wait(d).map(|_| ())
                    }
                    .map_err(LoopError::Transport)?;
                    break;
                }
                Action::Fail { report, fault } => {
                    return Err(failed(transport, clock, interrupted, report, fault));
                }
            }
        }
    }
}

/// Hands the core the clock messages that arrived (with `Wiring::every_clock_message` every
/// one, oldest first, until one ends the flight; else the newest): `Some` when the team
/// stopped.
fn read_clock<T, V, P, K>(
    core: &mut MemberCore<V, P>,
    transport: &mut T,
    clock: &K,
) -> Result<Option<Finished>, LoopError<T::Error>>
where
    T: MemberTransport,
    V: Vehicle,
    P: Timing<V>,
    K: Clock,
{
    if !P::WIRING.every_clock_message {
        let Some(c) = transport.latest_clock().map_err(LoopError::Transport)? else {
            return Ok(None);
        };
        return core
            .on_clock(&c, clock.now(), unix_now_ns())
            .map_err(LoopError::Fault);
    }
    let mut outcome = Ok(None);
    transport
        .receive_clock(|c| {
            if matches!(outcome, Ok(None)) {
                outcome = core.on_clock(&c, clock.now(), unix_now_ns());
            }
        })
        .map_err(LoopError::Transport)?;
    outcome.map_err(LoopError::Fault)
}

/// Publishes `msg`, after `inject` (tests only) altered it; `flush`: sent at once.
fn publish<T: MemberTransport>(
    transport: &mut T,
    mut msg: StateMsg,
    inject: Option<BeforePublish>,
    flush: bool,
) -> Result<(), LoopError<T::Error>> {
    if let Some(i) = inject {
        // An injected crash or hang happens "instead of publishing this tick": every earlier
        // state must be out, as if each were its own sample.
        transport.flush().map_err(LoopError::Transport)?;
        i(&mut msg);
    }
    transport
        .publish_quietly(msg)
        .map_err(LoopError::Transport)?;
    if flush {
        // Readers poll by the clock, not by wake-ups: the state must be out now.
        transport.flush().map_err(LoopError::Transport)?;
    }
    Ok(())
}

/// [`Action::Fail`], in lockstep and in real time alike: publish the fault's report, if
/// any, and [`linger`] for the orchestrator's stop so the team reads it; the loop then ends.
fn failed<T: MemberTransport, K: Clock>(
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
