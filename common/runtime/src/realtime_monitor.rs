//! The orchestrator's side of a real-time flight as a plain type with no I/O: it keeps the
//! newest states of every member, brings them to the monitor's audit instants, finds a member
//! whose newest state is too old, and sums the members' pacing reports. The loop around it (the
//! orchestrator's `realtime.rs`) owns the ports, the processes and the files.

use std::collections::VecDeque;

use cdm_math::Vec3;
use cdm_model::dynamics::{Flat, QuadState};
use cdm_model::step::{extrapolate_flat, NeighborModel};
use cdm_records::audit::{RealtimeFigures, SlowMember, Unheard};

use crate::messages::{AgentStatus, FaultCode, StateMsg};
use crate::realtime::{phase_offset_s, stamp_s, MemberPacing, PacingFigures};
use crate::team_slots::IdIndex;

/// States kept per member beyond the history the monitor is asked to cover: an audit instant
/// waits for the slowest member (up to the stale bound), so the fastest members' states back to
/// that instant must still be kept.
const RING_SLACK: usize = 8;

/// What a message told the monitor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MonitorEvent {
    /// A state, a pacing report, or nothing of interest.
    Nothing,
    /// A member reported a fault at its tick `tick` (`peer`: the member it is about).
    Fault {
        id: u32,
        tick: u64,
        code: FaultCode,
        peer: Option<u32>,
    },
    /// A member published a non-finite state (never audited).
    NonFinite { id: u32, tick: u64 },
}

/// One member as the monitor sees it.
#[derive(Debug, Clone)]
struct Seen {
    id: u32,
    follower: bool,
    phase_s: f64,
    at_rest: Flat,
    states: VecDeque<(u64, [f64; 12])>,
    pacing: Option<PacingFigures>,
    /// A pacing report arrived after the stop (its final figures).
    final_report: bool,
    /// Lost in flight (`--on-loss repair`): no longer waited for, judged stale or audited.
    lost: bool,
}

/// The monitor's state.
#[derive(Debug, Clone)]
pub struct MonitorCore {
    hash: u64,
    dt_s: f64,
    members: Vec<Seen>,
    index: IdIndex,
    stopped: bool,
    /// States kept per member.
    ring: usize,
    /// The states never received, in the order their gaps were found.
    unheard: Vec<Unheard>,
}

impl MonitorCore {
    /// `members` in formation order: (id, initial position, is a follower). `history_s`: how far
    /// back an audit instant may lie behind the newest states (the stale bound).
    pub fn new(
        members: &[(u32, Vec3, bool)],
        hash: u64,
        (dt_s, history_s): (f64, f64),
        phase_seed: u32,
    ) -> Self {
        let ring = (history_s / dt_s).ceil().clamp(0.0, 1e5) as usize + RING_SLACK;
        let members: Vec<Seen> = members
            .iter()
            .map(|&(id, p, follower)| Seen {
                id,
                follower,
                phase_s: phase_offset_s(phase_seed, id, dt_s),
                at_rest: Flat::rest(p),
                states: VecDeque::with_capacity(ring),
                pacing: None,
                final_report: false,
                lost: false,
            })
            .collect();
        let ids: Vec<u32> = members.iter().map(|m| m.id).collect();
        let index = IdIndex::new(&ids);
        Self {
            hash,
            dt_s,
            members,
            index,
            stopped: false,
            ring,
            unheard: Vec::new(),
        }
    }

    /// A message from a member's state service.
    pub fn on_state(&mut self, msg: &StateMsg) -> MonitorEvent {
        let Some(k) = self.index.get(msg.id) else {
            return MonitorEvent::Nothing;
        };
        if msg.scenario_hash != self.hash {
            return MonitorEvent::Nothing;
        }
        let stopped = self.stopped;
        let m = &mut self.members[k];
        if let Some(p) = MemberPacing::from_msg(msg) {
            m.pacing = Some(p);
            m.final_report |= stopped;
            return MonitorEvent::Nothing;
        }
        if let AgentStatus::Fault { code, peer } = msg.status() {
            return MonitorEvent::Fault {
                id: msg.id,
                tick: msg.tick,
                code,
                peer,
            };
        }
        if msg.state.iter().any(|v| !v.is_finite()) {
            return MonitorEvent::NonFinite {
                id: msg.id,
                tick: msg.tick,
            };
        }
        if m.states.back().is_none_or(|(t, _)| msg.tick > *t) {
            // The states between the newest kept and this one never arrived (the subscriber's
            // buffer overflowed): the audit goes around them, and a replay must too.
            let from = m.states.back().map_or(0, |(t, _)| t + 1);
            if msg.tick > from {
                self.unheard.push(Unheard {
                    id: m.id,
                    from,
                    to: msg.tick - 1,
                });
            }
            if m.states.len() == self.ring {
                m.states.pop_front();
            }
            m.states.push_back((msg.tick, msg.state));
        }
        MonitorEvent::Nothing
    }

    /// The states never received so far (ranges of ticks per member, in the order found).
    pub fn unheard(&self) -> &[Unheard] {
        &self.unheard
    }

    /// The members' ids in formation order.
    pub fn ids(&self) -> Vec<u32> {
        self.members.iter().map(|m| m.id).collect()
    }

    /// Member `id`'s index in the formation.
    pub fn index_of(&self, id: u32) -> Option<usize> {
        self.index.get(id)
    }

    /// Member `k` (formation order) is lost: from now on no audit instant waits for it, it is
    /// never stale, and it is out of the audit ([`Self::is_lost`]). Its states are still kept.
    pub fn lose(&mut self, k: usize) {
        if let Some(m) = self.members.get_mut(k) {
            m.lost = true;
        }
    }

    /// True once member `k` (formation order) is lost.
    pub fn is_lost(&self, k: usize) -> bool {
        self.members.get(k).is_some_and(|m| m.lost)
    }

    /// The stamp of member `k`'s newest state (formation order), if any arrived.
    pub fn newest_stamp_of(&self, k: usize) -> Option<f64> {
        let m = self.members.get(k)?;
        m.states
            .back()
            .map(|(t, _)| stamp_s(*t, m.phase_s, self.dt_s))
    }

    /// The stamp of `msg` when it is a leader's healthy state of this flight (`None` for a
    /// follower's, a report, or another scenario's).
    pub fn leader_stamp(&self, msg: &StateMsg) -> Option<f64> {
        let m = &self.members[self.index.get(msg.id)?];
        let state = msg.status() == AgentStatus::Ok && msg.scenario_hash == self.hash;
        (state && !m.follower).then(|| stamp_s(msg.tick, m.phase_s, self.dt_s))
    }

    /// The leaders still flying (not lost), in formation order.
    pub fn leaders(&self) -> Vec<u32> {
        (self.members.iter())
            .filter(|m| !m.follower && !m.lost)
            .map(|m| m.id)
            .collect()
    }

    /// The tick of member `id`'s newest state, if any arrived.
    pub fn newest_tick(&self, id: u32) -> Option<u64> {
        let k = self.index.get(id)?;
        self.members[k].states.back().map(|(t, _)| *t)
    }

    /// The team was told to stop: pacing reports from now on are final.
    pub fn stopping(&mut self) {
        self.stopped = true;
    }

    /// True when every member in `alive` (formation order) sent its final pacing report.
    pub fn final_reports_in(&self, alive: impl Fn(u32) -> bool) -> bool {
        // A lost member that still runs (its vehicle lost) reports nothing more.
        self.members
            .iter()
            .all(|m| m.final_report || m.lost || !alive(m.id))
    }

    /// The stamp of member `k`'s newest state (0, the start, before its first).
    fn newest_stamp(&self, k: usize) -> f64 {
        let m = &self.members[k];
        m.states
            .back()
            .map_or(0.0, |(t, _)| stamp_s(*t, m.phase_s, self.dt_s))
    }

    /// The member whose newest state is the oldest, if older than `bound_s` at time `now_s` of
    /// the common time line: its id, its newest tick and that age (s). Lost members are not.
    pub fn stale(&self, now_s: f64, bound_s: f64) -> Option<(u32, u64, f64)> {
        (0..self.members.len())
            .filter(|&k| !self.members[k].lost)
            .map(|k| (k, now_s - self.newest_stamp(k)))
            .filter(|(_, age)| *age > bound_s)
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(k, age)| {
                let m = &self.members[k];
                (m.id, m.states.back().map_or(0, |(t, _)| *t), age)
            })
    }

    /// The instant up to which every member has been heard: the oldest of the members' newest
    /// stamps (0, the start, while one has sent nothing), lost members left out. An audit instant at or before it is
    /// audited from states that bracket it, not extrapolated from a late one.
    pub fn heard_until(&self) -> f64 {
        (0..self.members.len())
            .filter(|&k| !self.members[k].lost)
            .map(|k| self.newest_stamp(k))
            .fold(f64::INFINITY, f64::min)
    }

    /// Position and velocity of member `k` (formation order) at time `t_s`: its newest state
    /// stamped at or before `t_s`, moved to `t_s` on the cubic Taylor model of a tick. When
    /// every kept state is newer (the monitor fell behind its ring), the oldest kept one is
    /// moved back to `t_s`; only a member never heard is taken at rest, where it starts.
    pub fn state_at(&self, k: usize, t_s: f64) -> (Vec3, Vec3) {
        let m = &self.members[k];
        let stamped = |(t, x): &(u64, [f64; 12])| (stamp_s(*t, m.phase_s, self.dt_s), *x);
        let (stamp, flat) = m
            .states
            .iter()
            .rev()
            .map(stamped)
            .find(|(stamp, _)| *stamp <= t_s)
            .or_else(|| m.states.front().map(stamped))
            .map_or((0.0, m.at_rest), |(stamp, x)| (stamp, QuadState(x).flat()));
        let f = extrapolate_flat(&flat, t_s - stamp, NeighborModel::Taylor);
        (f.r, f.v)
    }

    /// The team's pacing figures from the members' reports; `audits`, `audit_hz`, `phase_seed`,
    /// `stale_after_s` and `wall_s` are the monitor's own.
    pub fn figures(&self, run: RunFigures) -> RealtimeFigures {
        let reports: Vec<&PacingFigures> = self
            .members
            .iter()
            .filter_map(|m| m.pacing.as_ref())
            .collect();
        let ticks: u64 = reports.iter().map(|p| p.ticks).sum();
        let late_ticks: u64 = reports.iter().map(|p| p.late_ticks).sum();
        let followers: Vec<&PacingFigures> = self
            .members
            .iter()
            .filter(|m| m.follower)
            .filter_map(|m| m.pacing.as_ref())
            .filter(|p| p.age_samples > 0)
            .collect();
        let mut p50s: Vec<f64> = followers.iter().map(|p| p.age_p50_ms).collect();
        p50s.sort_by(f64::total_cmp);
        let max = |f: fn(&PacingFigures) -> f64| followers.iter().map(|p| f(p)).fold(0.0, f64::max);
        let slowest = reports
            .iter()
            .max_by(|a, b| {
                (a.late_ticks, a.max_late_ms)
                    .partial_cmp(&(b.late_ticks, b.max_late_ms))
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
            .map(|p| SlowMember {
                id: p.id,
                late_ticks: p.late_ticks,
                max_late_ms: p.max_late_ms,
            });
        RealtimeFigures {
            ticks,
            late_ticks,
            late_ticks_pct: if ticks == 0 {
                0.0
            } else {
                100.0 * late_ticks as f64 / ticks as f64
            },
            neighbor_age_ms_p50: p50s.get(p50s.len() / 2).copied().unwrap_or(0.0),
            neighbor_age_ms_p99: max(|p| p.age_p99_ms),
            neighbor_age_ms_max: max(|p| p.age_max_ms),
            link_states_received: reports.iter().map(|p| p.link_states.0).sum(),
            link_states_lost: reports.iter().map(|p| p.link_states.1).sum(),
            slowest_member: slowest,
            members_reported: reports.len(),
            unheard: self.unheard().to_vec(),
            audits: run.audits,
            audit_hz: run.audit_hz,
            phase_seed: run.phase_seed,
            stale_after_s: run.stale_after_s,
            wall_s: run.wall_s,
            team_cpu_cores: run.team_cpu_cores,
        }
    }
}

/// The monitor's own figures of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunFigures {
    pub audits: u64,
    pub audit_hz: f64,
    pub phase_seed: u32,
    pub stale_after_s: f64,
    pub wall_s: f64,
    pub team_cpu_cores: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_never_received_are_listed_and_an_old_one_changes_nothing() {
        let members = [
            (1, Vec3::zeros(), false),
            (2, Vec3::new(1.0, 0.0, 0.0), true),
        ];
        let mut m = MonitorCore::new(&members, 7, (0.01, 0.5), 0);
        for tick in [0, 1, 2, 6, 7, 5, 8] {
            m.on_state(&StateMsg::ok(tick, 7, 1, [0.0; 12]));
        }
        for tick in [3, 4] {
            m.on_state(&StateMsg::ok(tick, 7, 2, [0.0; 12]));
        }
        let gap = |id, from, to| Unheard { id, from, to };
        assert_eq!(m.unheard(), [gap(1, 3, 5), gap(2, 0, 2)]);
        assert_eq!(m.newest_tick(1), Some(8));
    }
}
