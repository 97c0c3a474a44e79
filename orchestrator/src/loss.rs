//! `launch` losing members (`--on-loss repair`, the default): the I/O around the pure
//! `team_loss::TeamLosses`. It SIGKILLs a scripted loss's member once it has published its tick,
//! notices members that died (killed from outside, exited) and kills those silent past
//! `--agent-timeout`; after one more drain of their states it knows their last tick, announces
//! the loss on the clock, and waits until the repair's new links are connected. The audit leaves
//! a lost body out from the tick its repair applies, as `simulate` does.
//!
//! With `--on-loss stop` only scripted losses happen here (a fault, as `simulate` records it);
//! a dead or silent member stays a fault of `launch.rs`, exactly as before losses.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use common::audit::Auditor;
use common::loss::{LossSchedule, LossState, OnLoss};
use common::messages::{LossNotice, StopReason};
use common::outcome::FaultKind;
use common::repair::repair;
use common::scenario::Scenario;
use common::team_core::FaultRank;
use common::team_loss::{LossCause, TeamLosses};
use common::transport::{OrchestratorPorts, RepairRoom};

use crate::team::{fault, Spawned, Stop};

/// How often dead members are looked for.
const SCAN_EVERY: Duration = Duration::from_millis(100);

/// A member killed or found dead whose last states are drained before its loss is announced.
struct Dying {
    id: u32,
    cause: LossCause,
}

/// What a turn asks of the loop.
pub enum Turn {
    /// Nothing new.
    Quiet,
    /// The loss notice changed: publish the clock again.
    Publish,
    /// `--on-loss stop`: stop the run with this fault once the ticks before it are complete.
    Stop(Stop, FaultRank),
}

/// The losses of one launch.
pub struct LaunchLosses {
    core: TeamLosses,
    policy: OnLoss,
    index: BTreeMap<u32, usize>,
    /// The highest tick received from each member (member order).
    seen: Vec<Option<u64>>,
    dying: Vec<Dying>,
    audit: LossState,
    started: Instant,
    last_scan: Instant,
}

impl LaunchLosses {
    /// The losses of a launch of `s` with `--lose` (validated) and `--on-loss`.
    pub fn new(s: &Scenario, scripted: &LossSchedule, policy: OnLoss) -> Self {
        let kills: Vec<(u32, u64)> = scripted
            .events
            .iter()
            .flat_map(|(from, ids)| ids.iter().map(move |&id| (id, from - 1)))
            .collect();
        LaunchLosses {
            core: TeamLosses::new(s, &kills),
            policy,
            index: s
                .formation
                .members
                .iter()
                .enumerate()
                .map(|(k, m)| (m.id, k))
                .collect(),
            seen: vec![None; s.formation.members.len()],
            dying: Vec::new(),
            audit: LossState::new(s, LossSchedule::default()),
            started: Instant::now(),
            last_scan: Instant::now(),
        }
    }

    /// True when lost members are repaired around (else a dead member is a fault).
    pub fn repairs(&self) -> bool {
        self.policy == OnLoss::Repair
    }

    /// A state of member index `k` at `tick` arrived.
    pub fn saw(&mut self, k: usize, tick: u64) {
        let s = &mut self.seen[k];
        *s = Some(s.map_or(tick, |t| t.max(tick)));
    }

    /// The highest tick that may be granted (`last` unless a scripted loss is pending).
    pub fn cap(&self, last: u64) -> u64 {
        self.core.cap(last)
    }

    /// How many states complete `tick`.
    pub fn expected(&self, tick: u64) -> usize {
        self.core.expected(tick)
    }

    /// The loss notice the clock carries.
    pub fn notice(&self) -> Option<LossNotice> {
        self.core.notice()
    }

    /// True when member `id` has no row at `tick` (lost).
    pub fn gone(&self, id: u32, tick: u64) -> bool {
        self.core.lost_at(id, tick)
    }

    /// Before the audit observes `tick`: record the losses whose repair applies from it.
    pub fn record(&mut self, s: &Scenario, tick: u64, audit: &mut Auditor) {
        for (cause, ids) in self.core.due_at(tick) {
            self.audit.record(s, tick, &ids, cause.as_str(), audit);
        }
    }

    /// Members missing a tick past `--agent-timeout` are killed and lost (spawned teams with
    /// `--on-loss repair`); false when they are not (then it is a fault).
    pub fn silent(&mut self, missing: &[u32], children: &mut [Spawned]) -> bool {
        let ours = missing
            .iter()
            .all(|id| children.iter().any(|c| c.id == *id));
        if !self.repairs() || missing.is_empty() || !ours {
            return false;
        }
        for &id in missing {
            kill(children, id);
            self.dying.push(Dying {
                id,
                cause: LossCause::Silent,
            });
        }
        true
    }

    /// One turn, after the loop drained the states: announce the members found dead in the
    /// previous turn, carry out a due scripted loss, look for dead members (unless the
    /// orchestrator `stalled` recently), move the announcements on (new links must connect
    /// within `link_timeout`).
    pub fn turn(
        &mut self,
        ports: &OrchestratorPorts,
        children: &mut [Spawned],
        (link_timeout, stalled): (Duration, bool),
    ) -> Result<Turn, Stop> {
        for d in std::mem::take(&mut self.dying) {
            let last = self.seen[self.index[&d.id]];
            let from = self.core.lose(d.id, last, d.cause);
            tracing::warn!(id = d.id, cause = d.cause.as_str(), from, "member lost");
            if self.policy == OnLoss::Stop {
                let what = format!(
                    "agent(s) [{}] lost after tick {} (--on-loss stop)",
                    d.id,
                    from.saturating_sub(1)
                );
                let f = fault(FaultKind::Lost, Some(d.id), None, from, what);
                let rank = FaultRank {
                    echo: false,
                    tick: from,
                    member: usize::MAX,
                };
                return Ok(Turn::Stop((f, StopReason::AgentFault), rank));
            }
        }
        let seen = |id: u32| self.seen[self.index[&id]];
        if let Some(id) = self.core.scripted_due(seen) {
            kill(children, id);
            self.dying.push(Dying {
                id,
                cause: LossCause::Scripted,
            });
        }
        // After a stall of the orchestrator itself, members that stopped are its consequence
        // (a fault, `stall.rs`), not losses.
        if self.repairs() && !stalled && self.last_scan.elapsed() >= SCAN_EVERY {
            self.last_scan = Instant::now();
            self.find_dead(children);
        }
        let now = self.started.elapsed();
        let changed = self
            .core
            .poll(now, link_timeout, |r, w| ports.linked(r, w).unwrap_or(false))
            .map_err(|e| {
                let what = format!(
                    "the repair after losing agent {} did not connect within {link_timeout:?}: links (reader, writer) {:?} missing",
                    e.id, e.missing
                );
                let f = fault(FaultKind::AgentSilent, Some(e.id), None, 0, what);
                (f, StopReason::AgentSilent)
            })?;
        Ok(if changed { Turn::Publish } else { Turn::Quiet })
    }

    /// Spawned members that died without being told: lost (`killed` by a signal, or `exited`).
    fn find_dead(&mut self, children: &mut [Spawned]) {
        use std::os::unix::process::ExitStatusExt;
        for c in children.iter_mut() {
            let known = self.core.is_lost(c.id) || self.dying.iter().any(|d| d.id == c.id);
            if known {
                continue;
            }
            if let Ok(Some(status)) = c.child.try_wait() {
                let cause = if status.signal().is_some() {
                    LossCause::Killed
                } else {
                    LossCause::Exited
                };
                self.dying.push(Dying { id: c.id, cause });
            }
        }
    }
}

/// SIGKILL member `id` and reap it: once `wait` returns it publishes nothing more, and what it
/// published stays readable (a killed publisher's samples remain until its node is cleaned).
fn kill(children: &mut [Spawned], id: u32) {
    if let Some(c) = children.iter_mut().find(|c| c.id == id) {
        let _ = c.child.kill();
        let _ = c.child.wait();
    }
}

/// Room for repairs: every member may gain, as a new in-neighbour, as many readers as the loss
/// of any single member gives it, plus two for further losses; every follower may gain three
/// new in-neighbours' wake-ups plus two. History: a window of states (a new reader may need
/// every state its new in-neighbour published since the lost member's last one).
pub fn repair_room(s: &Scenario, window: u32) -> RepairRoom {
    let floor = s
        .file
        .weight_floor
        .unwrap_or(common::graph::DEFAULT_WEIGHT_FLOOR);
    let mut most: BTreeMap<u32, usize> = BTreeMap::new();
    for m in &s.formation.members {
        let r = repair(&s.formation, floor, &[m.id].into());
        let mut gain: BTreeMap<u32, usize> = BTreeMap::new();
        for x in &r.retriangulated {
            for j in x.new.iter().filter(|j| !x.old.contains(j)) {
                *gain.entry(*j).or_default() += 1;
            }
        }
        for (j, g) in gain {
            let e = most.entry(j).or_default();
            *e = (*e).max(g);
        }
    }
    let readers = s
        .formation
        .members
        .iter()
        .map(|m| (m.id, most.get(&m.id).copied().unwrap_or(0) + 2))
        .collect();
    RepairRoom {
        readers,
        writers: 5,
        history: window as usize + 1,
    }
}
