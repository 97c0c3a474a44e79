//! A daemon's side of a repair across hosts: the clock messages it publishes announce losses;
//! before its members hear one, the relays standing in for other hosts' members wake their new
//! readers here; the new links whose reader runs here are watched until connected and reported
//! to the orchestrator (its team core announces the next loss, and has history handed over,
//! only then); once they are, the relays hand their history to new readers, as members do.

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use cdm_iox::{MemberPorts, OrchestratorPorts, TeamName, TeamProcess};
use cdm_runtime::messages::ClockMsg;

use crate::handover::{self, warn_hand_over, PendingHandOver, HAND_OVER_WAIT};
use crate::repairs::CrossRepairs;
use cdm_runtime::notices::NoticeGap;

/// How often the links awaited are looked up in the registry.
const CHECK_EVERY: Duration = Duration::from_millis(20);

/// The repairs as this host follows them.
pub struct DaemonRepairs {
    team: TeamName,
    host_of: BTreeMap<u32, u32>,
    mine: BTreeSet<u32>,
    repairs: CrossRepairs,
    /// Links (reader, writer) with the reader here, not seen connected yet.
    pending: BTreeSet<(u32, u32)>,
    last_check: Instant,
    /// Relays still to hand their history over (`handover.rs`).
    handing: Option<PendingHandOver>,
}

impl DaemonRepairs {
    pub fn new(
        team: TeamName,
        host_of: BTreeMap<u32, u32>,
        mine: BTreeSet<u32>,
        repairs: CrossRepairs,
        now: Instant,
    ) -> Self {
        Self {
            team,
            host_of,
            mine,
            repairs,
            pending: BTreeSet::new(),
            last_check: now,
            handing: None,
        }
    }

    /// A clock message about to be published on this host at `now`.
    pub fn on_clock(
        &mut self,
        c: &ClockMsg,
        relays: &mut BTreeMap<u32, MemberPorts>,
        now: Instant,
    ) -> Result<(), NoticeGap> {
        let step = self.repairs.on_notice(c.loss())?;
        for &(reader, writer) in &step.new_links {
            if !self.mine.contains(&reader) {
                continue;
            }
            self.pending.insert((reader, writer));
            if self.mine.contains(&writer) {
                continue;
            }
            match relays.get_mut(&writer) {
                Some(relay) => {
                    if let Err(e) = relay.connect(&[], &[reader]) {
                        tracing::warn!(
                            "the relay of agent {writer} cannot wake agent {reader}: {e}"
                        );
                    }
                }
                None => tracing::warn!(
                    "no relay of agent {writer} on this host for its new reader {reader}: \
                     the repair of several losses needs a link no single loss does"
                ),
            }
        }
        if step.hand_over {
            let from = step.needs_from;
            handover::start(&mut self.handing, from, relays, now, warn_hand_over);
        }
        Ok(())
    }

    /// Hands over the relays whose history now reaches the connected repair's tick.
    pub fn hand_over_ready(&mut self, relays: &mut BTreeMap<u32, MemberPorts>, now: Instant) {
        let wait = HAND_OVER_WAIT;
        handover::poll(&mut self.handing, relays, wait, now, warn_hand_over);
    }

    /// The awaited links connected since the last call (looked up every [`CHECK_EVERY`]): the
    /// reader subscribes to the writer's state and the writer (a member here, or the relay of
    /// one elsewhere) notifies the reader's wake event.
    pub fn connected(&mut self, ports: &OrchestratorPorts, now: Instant) -> Vec<(u32, u32)> {
        let since = now.saturating_duration_since(self.last_check);
        if self.pending.is_empty() || since < CHECK_EVERY {
            return Vec::new();
        }
        self.last_check = now;
        let done: Vec<(u32, u32)> = self
            .pending
            .iter()
            .copied()
            .filter(|&(r, w)| self.is_linked(ports, r, w))
            .collect();
        for l in &done {
            self.pending.remove(l);
        }
        done
    }

    fn is_linked(&self, ports: &OrchestratorPorts, reader: u32, writer: u32) -> bool {
        let writer_node = match self.host_of.get(&writer) {
            Some(&h) if !self.mine.contains(&writer) => self.team.relay_node_name(h, writer),
            _ => self.team.node_name(TeamProcess::Agent(writer)),
        };
        let reader_node = self.team.node_name(TeamProcess::Agent(reader));
        ports
            .subscriber_nodes(writer)
            .is_ok_and(|n| n.contains(&reader_node))
            && ports
                .notifier_nodes(reader)
                .is_ok_and(|n| n.contains(&writer_node))
    }
}
