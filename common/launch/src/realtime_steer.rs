//! Commands to a real-time team (`orchestrator command` while `launch --realtime` flies). Nobody
//! waits for a grant in real time, so a command cannot switch at "the first tick not granted":
//! its switch tick is chosen ahead of the flight from measured quantities
//! (`TeamCore::realtime_switch`: the certificate's own time, measured on the previous command,
//! twice the largest delay measured from a leader's state stamp to its arrival at the monitor,
//! and a margin of ticks), the command is certified there with the code lockstep uses
//! (`LiveSteer`, on a copy), proposed to every member on the clock channel as the loss repair
//! announces its switch tick, and becomes final once every leader acknowledged it; a leader
//! that did not by the tick before the switch withdraws it and nothing changes (exit 3).
//!
//! A command file's commands (`launch --realtime --commands FILE`) go the same way, one after
//! the other from the start of the flight: each is certified at its own switch tick (as
//! `simulate --commands` certifies it) and proposed at once, long before that tick; the
//! commanded plan is the old one before the switch, so a plan made final early flies the same
//! ticks until then. Commands given live come after them.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Duration;

use cdm_model::outcome::FaultKind;
use cdm_records::audit::Auditor;
use cdm_runtime::messages::SteerNotice;
use cdm_runtime::seams::{Clock, MonotonicClock};
use cdm_runtime::team_core::{Pacing, SteerOutcome, TeamCore};
use cdm_scenario::{Scenario, TimedCommand};
use cdm_team::notices::{NoticeSink, TickProgress};
use cdm_team::team::{fault, Stop};

use crate::channel::{Answered, CommandAnswer, PendingAnswer};
use crate::feeds::Feeds;
use crate::steer::{FlightAt, LiveDecision, LiveSteer, Steer};

/// Who asked for a command, and hears what became of it.
enum AnswerTo {
    /// `orchestrator command`.
    Operator(PendingAnswer),
    /// An interrupt under `--on-interrupt land` (the log hears).
    Interrupt,
    /// The command file's command of this index (`--commands`; the launch's output hears).
    File(usize),
}

/// A command proposed to the team and not decided yet.
struct Proposed {
    to: AnswerTo,
    /// `hold`, `land`, ...
    command: String,
    decision: LiveDecision,
    next: LiveSteer,
    /// The plan flown once it is final, and its last tick.
    flown: Arc<Scenario>,
    last: u64,
}

/// The commands of a real-time flight.
pub(crate) struct RealtimeSteer<'a> {
    steer: Steer<'a>,
    clock: MonotonicClock,
    proposed: Option<Proposed>,
    /// How long the latest certificate took: the next switch tick leaves it room.
    certify: Duration,
    /// The plan flown, as commanded so far.
    flown: Arc<Scenario>,
    /// Its last tick (`--max-ticks` applied).
    last: u64,
    max_ticks: Option<u64>,
    /// `--on-interrupt land`, and the signal that asked for the landing once one did.
    land_on_interrupt: bool,
    interrupted: Option<&'static str>,
    notices: Arc<dyn NoticeSink>,
    /// The command file's commands not proposed yet (`--commands`), with their index.
    file: VecDeque<(usize, TimedCommand)>,
}

/// Where a decision goes: the operator's `command`, the log of an interrupt, or the launch's
/// output for a file's command.
fn answer(notices: &dyn NoticeSink, to: AnswerTo, a: CommandAnswer) {
    match to {
        AnswerTo::Operator(to) => to.answer(a),
        AnswerTo::Interrupt => tracing::warn!(answer = ?a.answer, "{}", a.text),
        AnswerTo::File(k) => notices.notice(&format_args!("  commands[{k}]: {}", a.text)),
    }
}

/// Where the flight is, in ticks, once `audits` instants `period_s` apart were audited.
fn complete_tick(audits: u64, period_s: f64, dt_s: f64) -> u64 {
    (audits.saturating_sub(1) as f64 * period_s / dt_s).floor() as u64
}

impl<'a> RealtimeSteer<'a> {
    /// The commands of `s`'s flight on `clock`: `--max-ticks`, `--on-interrupt land`, the
    /// command file's commands (`--commands`), and where notices go.
    pub(crate) fn new(
        (steer, clock): (Steer<'a>, MonotonicClock),
        s: &Scenario,
        (max_ticks, land_on_interrupt, file): (Option<u64>, bool, &[TimedCommand]),
        notices: Arc<dyn NoticeSink>,
    ) -> Self {
        let last = max_ticks.map_or(s.last_tick(), |k| k.min(s.last_tick()));
        RealtimeSteer {
            flown: Arc::clone(steer.live.flown()),
            steer,
            clock,
            proposed: None,
            certify: Duration::ZERO,
            last,
            max_ticks,
            land_on_interrupt,
            interrupted: None,
            notices,
            file: file.iter().cloned().enumerate().collect(),
        }
    }

    /// The plan flown, as commanded so far.
    pub(crate) fn flown(&self) -> &Arc<Scenario> {
        &self.flown
    }

    /// Takes the command waiting on the channel, if any and none is being decided: certified
    /// at a switch tick ahead, then proposed to the team (or answered at once when its
    /// certificate refuses it, or it does not apply).
    pub(crate) fn serve(
        &mut self,
        core: &mut TeamCore,
        (live, progress): (&mut Feeds, &mut dyn TickProgress),
    ) -> Result<(), Stop> {
        if self.proposed.is_some() || core.announcing() {
            return Ok(());
        }
        if let Some(entry) = self.file.pop_front() {
            return self.propose_file(core, entry, (live, progress));
        }
        let Some(channel) = self.steer.channel else {
            return Ok(());
        };
        let Some((to, request)) = channel.take_one() else {
            return Ok(());
        };
        let request = match request {
            Ok(r) => r,
            Err(why) => {
                to.answer(CommandAnswer::without_switch(
                    Answered::BadInput,
                    why.to_string(),
                ));
                return Ok(());
            }
        };
        self.decide(core, request, AnswerTo::Operator(to), (live, progress))
            .map(drop)
    }

    /// The command file's command `c` (index `k`): certified at its own switch tick and
    /// proposed now, or refused by its certificate (recorded, as `simulate` records it), or
    /// said on the output when its switch is too close to propose it (nothing changes).
    fn propose_file(
        &mut self,
        core: &mut TeamCore,
        (k, c): (usize, TimedCommand),
        (live, progress): (&mut Feeds, &mut dyn TickProgress),
    ) -> Result<(), Stop> {
        let Pacing::Realtime(w) = core.pacing() else {
            return Ok(());
        };
        let leaders = w.book().leaders();
        let (decision, next) = self.steer.live.tentatively_timed(&c);
        let Some((notice, flown, last)) = decision.accepted.clone() else {
            let recorded = decision.recorded;
            answer(&*self.notices, AnswerTo::File(k), decision.answer);
            if recorded {
                self.steer.live.adopt(next);
                self.record(core, live, progress)?;
            }
            return Ok(());
        };
        if !core.realtime_in_time(self.clock.now(), notice.tick) {
            let text = format!(
                "{} not proposed: the flight is too close to its switch at tick {} (t = {:.2} s) for the leaders to acknowledge it; nothing changed",
                c.spec.command, notice.tick, c.spec.at_s
            );
            let a = CommandAnswer::without_switch(Answered::Unavailable, text);
            answer(&*self.notices, AnswerTo::File(k), a);
            return Ok(());
        }
        core.propose(notice, leaders);
        self.proposed = Some(Proposed {
            to: AnswerTo::File(k),
            command: c.spec.command.clone(),
            decision,
            next,
            flown,
            last: self.max_ticks.map_or(last, |m| m.min(last)),
        });
        Ok(())
    }

    /// `--on-interrupt land`: the first interrupt lands the team, decided as an operator's
    /// `land` is. True when the landing is proposed (or the team lands already): the flight
    /// goes on; false: stop now.
    pub(crate) fn land_on_interrupt(
        &mut self,
        core: &mut TeamCore,
        signal: &'static str,
        feeds: (&mut Feeds, &mut dyn TickProgress),
    ) -> bool {
        if !self.land_on_interrupt || self.interrupted.is_some() {
            return false;
        }
        self.interrupted = Some(signal);
        if self.proposed.is_some() || core.announcing() {
            self.notices.notice(&format_args!(
                "{signal}: a command is being decided; stopping the team now"
            ));
            return false;
        }
        let land = crate::channel::CommandRequest::land();
        match self.decide(core, land, AnswerTo::Interrupt, feeds) {
            Ok(true) => {
                self.notices.notice(&format_args!(
                    "{signal}: landing the team (--on-interrupt land); a second signal stops it at once"
                ));
                true
            }
            _ if self.landing_now(core) => {
                self.notices.notice(&format_args!(
                    "{signal}: the team is landing already; a second signal stops it at once"
                ));
                true
            }
            _ => false,
        }
    }

    /// True when the flight is in its plan's landing already.
    fn landing_now(&self, core: &TeamCore) -> bool {
        let Pacing::Realtime(w) = core.pacing() else {
            return false;
        };
        let t_s = w.audits() as f64 * w.plan().period_s;
        (self.flown.plan.phases().last())
            .is_some_and(|p| p.kind == cdm_model::plan::PhaseKind::Landing && p.t_start_s <= t_s)
    }

    /// Certifies `request` at a switch tick ahead and proposes it to the team (true), or
    /// answers it at once: refused by its certificate, not applicable, or no time left.
    fn decide(
        &mut self,
        core: &mut TeamCore,
        request: crate::channel::CommandRequest,
        to: AnswerTo,
        (live, progress): (&mut Feeds, &mut dyn TickProgress),
    ) -> Result<bool, Stop> {
        let Pacing::Realtime(w) = core.pacing() else {
            return Ok(false);
        };
        let (period_s, dt_s) = (w.plan().period_s, w.plan().dt_s);
        let leaders = w.book().leaders();
        let complete = complete_tick(w.audits(), period_s, dt_s);
        // Twice at most: a certificate slower than the last one measured may leave its switch
        // too close; the second try leaves twice the time it took.
        let mut certify = self.certify;
        for _ in 0..2 {
            let Some((tick, _)) = core.realtime_switch(self.clock.now(), certify) else {
                break;
            };
            let at = FlightAt {
                first_free: tick,
                complete: complete.min(tick),
                last: self.last,
            };
            let started = std::time::Instant::now();
            let (decision, next) = self.steer.live.tentatively(request.clone(), at);
            self.certify = started.elapsed();
            tracing::info!(
                certify_ms = self.certify.as_secs_f64() * 1e3,
                switch_tick = tick,
                "a real-time command certified"
            );
            let Some((notice, flown, last)) = decision.accepted.clone() else {
                // Refused by its certificate, or it does not apply: decided now.
                let recorded = decision.recorded;
                answer(&*self.notices, to, decision.answer);
                if recorded {
                    self.steer.live.adopt(next);
                    self.record(core, live, progress)?;
                }
                return Ok(false);
            };
            if core.realtime_in_time(self.clock.now(), notice.tick) {
                core.propose(notice, leaders);
                let last = self.max_ticks.map_or(last, |k| k.min(last));
                self.proposed = Some(Proposed {
                    to,
                    command: request.command.clone(),
                    decision,
                    next,
                    flown,
                    last,
                });
                return Ok(true);
            }
            certify = self.certify * 2;
        }
        answer(
            &*self.notices,
            to,
            CommandAnswer::without_switch(
                Answered::Unavailable,
                format!(
                    "the certificate took {:.1} ms: the flight reached the switch tick before it could be announced; nothing changed",
                    self.certify.as_secs_f64() * 1e3
                ),
            ),
        );
        Ok(false)
    }

    /// A command notice went out: when it decided the proposal, answer it and (final) fly the
    /// commanded plan from now on: the audit, the last tick and the files follow it.
    pub(crate) fn on_notice(
        &mut self,
        core: &mut TeamCore,
        n: SteerNotice,
        (audit, live, progress): (&mut Auditor, &mut Feeds, &mut dyn TickProgress),
    ) -> Result<(), Stop> {
        let Some(outcome) = core.take_steer_outcome() else {
            tracing::info!(seq = n.seq, switch_tick = n.tick, "a command proposed");
            return Ok(());
        };
        let Some(p) = self.proposed.take() else {
            return Ok(());
        };
        match outcome {
            SteerOutcome::Final(n) => {
                // How far ahead of the switch the decision went out (the bench's "answer to
                // switch"): the switch's instant on the common time line minus now.
                let ahead_ms = match core.pacing() {
                    Pacing::Realtime(w) => {
                        let now_s = self.clock.now().as_secs_f64() - w.plan().start.as_secs_f64();
                        (n.tick as f64 * w.plan().dt_s - now_s) * 1e3
                    }
                    Pacing::Lockstep(_) => 0.0,
                };
                tracing::info!(
                    seq = n.seq,
                    switch_tick = n.tick,
                    ahead_ms,
                    "every leader acknowledged the command: final"
                );
                answer(&*self.notices, p.to, p.decision.answer);
                self.steer.live.adopt(p.next);
                audit.replan(&p.flown);
                self.flown = p.flown;
                self.last = p.last;
                core.set_last_tick(p.last);
                if let Pacing::Realtime(w) = core.pacing() {
                    progress.set_last_tick(w.plan().last_audit);
                }
                self.record(core, live, progress)
            }
            SteerOutcome::Withdrawn { notice, missing } => {
                self.steer.live.spend_notice();
                let text = format!(
                    "{} refused: leader(s) {missing:?} did not acknowledge it before its switch at tick {} (t = {:.2} s); withdrawn, nothing changed",
                    p.command,
                    notice.tick,
                    notice.tick as f64 * self.flown.dt_s()
                );
                answer(
                    &*self.notices,
                    p.to,
                    CommandAnswer::without_switch(Answered::Unavailable, text),
                );
                // An interrupt's landing that cannot be: the team stops now.
                if let Some(signal) = self.interrupted {
                    core.on_interrupt(signal);
                }
                Ok(())
            }
        }
    }

    /// The flight ended: a command still waiting for its acknowledgements is refused.
    pub(crate) fn end(&mut self) {
        if let Some(p) = self.proposed.take() {
            answer(&*self.notices, p.to, CommandAnswer::without_switch(
                Answered::Unavailable,
                "the flight ended before every leader acknowledged the command; nothing changed"
                    .into(),
            ));
        }
        for (k, c) in std::mem::take(&mut self.file) {
            let text = format!("{} not proposed: the flight ended first", c.spec.command);
            let a = CommandAnswer::without_switch(Answered::Unavailable, text);
            answer(&*self.notices, AnswerTo::File(k), a);
        }
    }

    /// A command recorded: the live view, the progress line and commands.json.
    fn record(
        &mut self,
        core: &TeamCore,
        live: &mut Feeds,
        progress: &mut dyn TickProgress,
    ) -> Result<(), Stop> {
        let steer = &mut self.steer;
        if let Some(r) = steer.live.records().last() {
            live.command(&r.summary());
        }
        let (accepted, refused) = steer.live.counts();
        progress.set_commands(accepted, refused);
        crate::steer::write_commands(steer.dir, steer.live.records()).map_err(|e| {
            (
                fault(FaultKind::Io, None, None, core.position(), e.to_string()),
                cdm_runtime::messages::StopReason::AgentFault,
            )
        })
    }
}
