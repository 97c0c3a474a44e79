//! The team core's side of losing members (`--on-loss repair`, issue 16): a scripted loss's
//! member is killed once it has published its tick (grants stop there meanwhile), a member
//! found dead or silent is lost, and after one more drain of its states its loss is announced
//! with the tick after its last state; the next is announced once the repair's new links are
//! connected. With `--on-loss stop` a scripted loss is a fault, as `simulate` records it, and a
//! dead member stays the fault of `team_core.rs`. Decisions only: the loop kills, reaps and asks
//! the transport.

use std::time::Duration;

use cdm_core::audit::FaultRecord;
use cdm_core::outcome::FaultKind;

use super::{first_grant, FaultRank, LossEvents, Stopping, TeamAction, TeamCore, WAIT_SLICE};
use crate::messages::StopReason;
use crate::team_loss::{LossCause, TeamLosses};

impl TeamCore {
    /// The same core handling `book`'s losses. `repairs`: dead or silent members are lost and
    /// repaired around (`--on-loss repair` with spawned members); otherwise only scripted losses
    /// happen, each a fault (`--on-loss stop`).
    pub fn with_losses(mut self, book: TeamLosses, repairs: bool) -> Self {
        self.grant = first_grant(self.window, book.cap(self.cfg.last_tick));
        self.losses = Some(LossEvents {
            book,
            repairs,
            dying: Vec::new(),
            last_link_check: Duration::ZERO,
            republish: false,
        });
        self
    }

    /// The losses so far (the loop's audit records them, telemetry leaves their rows out).
    pub fn losses(&self) -> Option<&TeamLosses> {
        self.losses.as_ref().map(|l| &l.book)
    }

    /// The answer to [`TeamAction::CheckLinks`]: `linked(reader, writer)` tells whether a link
    /// is connected.
    pub fn on_links(&mut self, now: Duration, linked: impl FnMut(u32, u32) -> bool) {
        let timeout = self.cfg.agent_timeout;
        let Some(l) = &mut self.losses else { return };
        match l.book.poll(now, timeout, linked) {
            Ok(changed) => {
                l.republish |= changed;
                if changed {
                    self.last_progress = now;
                }
            }
            Err(e) => {
                let what = format!(
                    "the repair after losing agent {} did not connect within {timeout:?}: links (reader, writer) {:?} missing",
                    e.id, e.missing
                );
                let f = FaultRecord::new(
                    FaultKind::AgentSilent,
                    Some(e.id),
                    None,
                    self.next_tick,
                    what,
                );
                self.interrupt.get_or_insert((f, StopReason::AgentSilent));
            }
        }
    }

    /// How many states complete `tick` (fewer once members are lost).
    pub(super) fn expected(&self, tick: u64) -> usize {
        self.losses
            .as_ref()
            .map_or(self.cfg.ids.len(), |l| l.book.expected(tick))
    }

    /// The highest tick that may be granted.
    pub(super) fn cap(&self) -> u64 {
        let last = self.cfg.last_tick;
        self.losses.as_ref().map_or(last, |l| l.book.cap(last))
    }

    /// True when `id` has no state at `tick` because it was lost.
    pub(super) fn is_lost(&self, id: u32, tick: u64) -> bool {
        self.losses
            .as_ref()
            .is_some_and(|l| l.book.lost_at(id, tick))
    }

    /// Announce the dead, carry out a due scripted loss, republish a changed notice, ask about
    /// awaited links.
    pub(super) fn loss_action(&mut self, now: Duration) -> Option<TeamAction> {
        self.announce_dead(now);
        let l = self.losses.as_mut()?;
        if std::mem::take(&mut l.republish) {
            return Some(TeamAction::Grant(self.grant));
        }
        let book = &l.book;
        if let Some(id) = book.scripted_due(|id| book.seen(id)) {
            if l.dying.iter().all(|d| d.0 != id) {
                l.dying.push((id, LossCause::Scripted, false));
                return Some(TeamAction::Kill(vec![id]));
            }
        }
        if l.book.busy() && now.saturating_sub(l.last_link_check) >= WAIT_SLICE {
            l.last_link_check = now;
            return Some(TeamAction::CheckLinks);
        }
        None
    }

    /// Members killed or found dead whose states were drained since: lost after their last
    /// tick received. With `--on-loss stop` the first is a fault (ticks before it complete).
    fn announce_dead(&mut self, now: Duration) {
        let Some(l) = &mut self.losses else { return };
        let (drained, rest): (Vec<_>, Vec<_>) = l.dying.drain(..).partition(|d| d.2);
        l.dying = rest;
        for (id, cause, _) in drained {
            let from = l.book.lose(id, l.book.seen(id), cause);
            self.last_progress = now;
            if l.repairs {
                continue;
            }
            let what = format!(
                "agent(s) [{id}] lost after tick {} (--on-loss stop)",
                from.saturating_sub(1)
            );
            let rank = FaultRank {
                echo: false,
                tick: from,
                member: usize::MAX,
            };
            if rank.outranks(self.stopping.as_ref().map(|s| &s.rank)) {
                self.stopping = Some(Stopping {
                    record: FaultRecord::new(FaultKind::Lost, Some(id), None, from, what),
                    since: now,
                    rank,
                });
            }
        }
    }

    /// A member process seen exited is lost (`killed` by a signal, else `exited`) when losses
    /// are repaired and the orchestrator did not stall just before (then it is a fault).
    /// `how` is `first_exited`'s wording ("was killed by signal 9", "exited with code 3").
    pub(super) fn lost_on_exit(&mut self, id: u32, how: &str, now: Duration) -> bool {
        let blamed = self.stall.blames(now);
        let Some(l) = self.losses.as_mut().filter(|l| l.repairs && !blamed) else {
            return false;
        };
        if !l.book.is_lost(id) && l.dying.iter().all(|d| d.0 != id) {
            let cause = if how.starts_with("was killed") {
                LossCause::Killed
            } else {
                LossCause::Exited
            };
            l.dying.push((id, cause, false));
        }
        true
    }

    /// Past the silence deadline: the silent members are killed and lost (when losses are
    /// repaired and the orchestrator did not stall just before).
    pub(super) fn kill_silent(&mut self, now: Duration) -> Option<TeamAction> {
        let missing = self.missing();
        let blamed = self.stall.blames(now);
        let l = self.losses.as_mut().filter(|l| l.repairs && !blamed)?;
        if missing.is_empty() {
            return None;
        }
        l.dying
            .extend(missing.iter().map(|&id| (id, LossCause::Silent, false)));
        self.last_progress = now;
        Some(TeamAction::Kill(missing))
    }
}
