//! The one loop around the team core (`cdm_runtime::team_core`), lockstep or real time: I/O
//! only. The core decides what to grant, record, kill and announce, and when to stop; this loop
//! reads the clock and the signal flag, and hands every action to the pacing's I/O
//! ([`TeamIo`]: the ports, the processes, the files).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use cdm_runtime::messages::{LossNotice, SteerNotice};
use cdm_runtime::seams::{Clock, MonotonicClock};
use cdm_runtime::team_core::{LostMember, TeamAction, TeamCore, TickStates};
use cdm_team::team::Stop;

/// What the loop does with the team core's actions, for one pacing. An action a pacing never
/// gets has the default: nothing to do.
pub(crate) trait TeamIo {
    /// Takes every state and report that arrived (the core's turn began at `now`).
    fn receive(&mut self, core: &mut TeamCore, now: Duration) -> Result<(), Stop>;

    /// Lockstep: publishes a grant up to tick `g`.
    fn grant(&mut self, core: &TeamCore, g: u64) -> Result<(), Stop> {
        let _ = (core, g);
        Ok(())
    }

    /// Publishes the clock message again with the loss notice `n`.
    fn announce(&mut self, core: &TeamCore, n: LossNotice) -> Result<(), Stop>;

    /// Publishes the clock message again with the command notice `n` (real time: then takes
    /// what became of a proposed command from the core).
    fn steer(&mut self, core: &mut TeamCore, n: SteerNotice) -> Result<(), Stop> {
        let _ = (core, n);
        Ok(())
    }

    /// Lockstep: records complete tick `tick` and hands its states back to the core. `Some`
    /// ends the run here (its first violation, `--stop-on-violation`): whether the whole plan
    /// was flown.
    fn complete(
        &mut self,
        core: &mut TeamCore,
        tick: u64,
        states: TickStates,
    ) -> Result<Option<bool>, Stop> {
        core.recycle(states);
        let _ = tick;
        Ok(None)
    }

    /// `--on-interrupt land`: the first interrupt (`signal`) lands the team, certified as a
    /// command; true when the landing was taken (or is being decided). The default: no.
    fn land_on_interrupt(&mut self, core: &mut TeamCore, signal: &'static str) -> bool {
        let _ = (core, signal);
        false
    }

    /// Real time: audits and writes instant `index` at `t_s`.
    fn audit(&mut self, core: &TeamCore, index: u64, t_s: f64) -> Result<(), Stop> {
        let _ = (core, index, t_s);
        Ok(())
    }

    /// Real time: a member lost, for the audit.
    fn lost(&mut self, lost: LostMember) {
        let _ = lost;
    }

    /// Looks for exited members and tells the core (at `now`).
    fn check_exited(&mut self, core: &mut TeamCore, now: Duration) -> Result<(), Stop>;

    /// SIGKILLs member `id` and reaps it.
    fn kill(&mut self, id: u32);

    /// True when the link (reader, writer) a repair opened is connected.
    fn linked(&self, reader: u32, writer: u32) -> bool;

    /// Flushes the telemetry (`at`: the core's position, for a fault).
    fn flush(&mut self, at: u64) -> Result<(), Stop>;

    /// Waits at most `d` before the next turn.
    fn wait(&mut self, core: &TeamCore, d: Duration);

    /// The run ends: the whole plan flown (`finished`), or stopped.
    fn end(&mut self, core: &TeamCore, finished: bool) -> Result<(), Stop>;
}

/// Flies the team to the end of the plan or its stop; true when every tick (lockstep) or
/// instant (real time) of the plan was recorded.
pub(crate) fn fly(
    core: &mut TeamCore,
    io: &mut impl TeamIo,
    clock: &MonotonicClock,
    interrupted: &AtomicBool,
) -> Result<bool, Stop> {
    loop {
        let now = clock.now();
        if interrupted.load(Ordering::Relaxed) {
            let signal = cdm_process::signals::received();
            // `--on-interrupt land`: the first signal lands the team (the flag is cleared, so
            // a second one stops it at once); otherwise the team stops now.
            if io.land_on_interrupt(core, signal) {
                interrupted.store(false, Ordering::Relaxed);
            } else {
                core.on_interrupt(signal);
            }
        }
        core.on_turn(now);
        io.receive(core, now)?;
        loop {
            match core.next_action(clock.now()) {
                TeamAction::Grant(g) => io.grant(core, g)?,
                TeamAction::Announce(n) => io.announce(core, n)?,
                TeamAction::Steer(n) => io.steer(core, n)?,
                TeamAction::Complete { tick, states } => {
                    if let Some(all) = io.complete(core, tick, states)? {
                        return Ok(all);
                    }
                }
                TeamAction::Audit { index, t_s } => io.audit(core, index, t_s)?,
                TeamAction::Lost(lost) => io.lost(lost),
                TeamAction::CheckExited => io.check_exited(core, clock.now())?,
                TeamAction::CheckLinks => {
                    core.on_links(clock.now(), |r, w| io.linked(r, w));
                }
                TeamAction::Kill(ids) => {
                    for id in ids {
                        io.kill(id);
                    }
                    // Their last states are drained before they are lost.
                    break;
                }
                TeamAction::Flush => io.flush(core.position())?,
                TeamAction::Poll => break,
                TeamAction::Wait(d) => {
                    io.wait(core, d);
                    break;
                }
                TeamAction::Finished => {
                    io.end(core, true)?;
                    return Ok(true);
                }
                TeamAction::Stop(f, reason) => {
                    let _ = io.end(core, false);
                    return Err((f, reason));
                }
            }
        }
    }
}
