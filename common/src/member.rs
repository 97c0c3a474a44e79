//! One team member as a process: the loop around `step::step` that only does I/O.
//!
//! Protocol (see ARCHITECTURE.md): the orchestrator grants ticks on the clock service; a member
//! publishes its tick-k state once tick k is granted, and computes tick k + 1 once k + 1 is
//! granted and its three in-neighbours' tick-k states are in. Every state carries its tick, so a
//! neighbour that runs ahead is buffered, never confused. Every wait has a deadline.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::dynamics::{Flat, QuadState};
use crate::engine::step_config;
use crate::formation::Role;
use crate::messages::{AgentStatus, ClockCommand, ClockMsg, FaultCode, StateMsg, NO_PEER};
use crate::scenario::{Checks, Scenario, ScenarioError};
use crate::step::{law_for, step, Law, StepFault};
use crate::transport::{MemberPorts, TeamName, TransportError};

/// Which binary is running: leaders fly primary and secondary leaders, agents fly followers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Leader,
    Agent,
}

impl Kind {
    fn accepts(self, role: Role) -> bool {
        match self {
            Kind::Leader => role.is_leader(),
            Kind::Agent => role == Role::Follower,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Kind::Leader => "leader",
            Kind::Agent => "agent",
        }
    }
}

/// Deadlines of a member.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deadlines {
    /// How long to wait for the team to start (first grant) while the orchestrator lives.
    pub join: Duration,
    /// How long without progress (no grant, no neighbour state) before giving up mid-run.
    pub silence: Duration,
}

impl Default for Deadlines {
    fn default() -> Self {
        Deadlines {
            join: Duration::from_secs(300),
            silence: Duration::from_secs(10),
        }
    }
}

/// Why a member stopped without finishing.
#[derive(Debug, thiserror::Error)]
pub enum MemberError {
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    #[error("agent {id} is not in scenario {origin}")]
    NotInScenario { id: u32, origin: String },
    #[error("agent {id} is a {role} in {origin}; the `{binary}` binary flies {flies}")]
    WrongRole {
        id: u32,
        role: &'static str,
        binary: &'static str,
        flies: &'static str,
        origin: String,
    },
    #[error(transparent)]
    Transport(#[from] TransportError),
    #[error("agent {id}: the orchestrator of team {team} is gone (at tick {tick}); stopping")]
    OrchestratorLost { id: u32, team: String, tick: u64 },
    #[error("agent {id}: nothing happened for {waited:?} at tick {tick} (waiting for {waiting_for}); stopping")]
    Silent {
        id: u32,
        tick: u64,
        waited: Duration,
        waiting_for: String,
    },
    #[error("agent {id} at tick {tick}: {fault}")]
    Step {
        id: u32,
        tick: u64,
        fault: StepFault,
    },
    #[error("agent {id} at tick {tick}: in-neighbour {peer} {what}")]
    Neighbor {
        id: u32,
        tick: u64,
        peer: u32,
        what: String,
    },
    #[error("agent {id}: interrupted at tick {tick}")]
    Interrupted { id: u32, tick: u64 },
}

impl MemberError {
    /// Exit code: 2 for bad input (scenario, id, role, mismatch), 3 for runtime faults.
    pub fn exit_code(&self) -> i32 {
        match self {
            MemberError::Scenario(_)
            | MemberError::NotInScenario { .. }
            | MemberError::WrongRole { .. } => 2,
            MemberError::Transport(
                TransportError::ScenarioMismatch { .. }
                | TransportError::NotInTeam { .. }
                | TransportError::TeamNotFound { .. }
                | TransportError::AgentAlreadyRunning { .. }
                | TransportError::InvalidTeamName { .. },
            ) => 2,
            _ => 3,
        }
    }
}

/// How a member ended normally.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Finished {
    /// The last tick published.
    pub tick: u64,
    /// The orchestrator's stop reason code.
    pub reason: u32,
}

/// Run one member until the orchestrator stops the team.
pub fn run_member(
    kind: Kind,
    scenario_path: &Path,
    team: &TeamName,
    id: u32,
    deadlines: Deadlines,
    interrupted: &AtomicBool,
) -> Result<Finished, MemberError> {
    let s = Scenario::load(scenario_path, Checks::Member)?;
    let Some(me) = s.formation.member(id).cloned() else {
        return Err(MemberError::NotInScenario {
            id,
            origin: s.origin.clone(),
        });
    };
    if !kind.accepts(me.role) {
        return Err(MemberError::WrongRole {
            id,
            role: me.role.as_str(),
            binary: kind.name(),
            flies: if kind == Kind::Leader {
                "primary and secondary leaders"
            } else {
                "followers"
            },
            origin: s.origin.clone(),
        });
    }
    let (law, neighbor_ids) = law_for(&me);
    let is_follower = matches!(law, Law::Follower { .. });
    let mut ins: Vec<u32> = if is_follower {
        neighbor_ids.to_vec()
    } else {
        Vec::new()
    };
    ins.sort_unstable();
    let outs = s.formation.out_neighbors().remove(&id).unwrap_or_default();
    let hash = s.content_hash();
    let mut ports = MemberPorts::open(team, id, hash, &ins, &outs)?;
    tracing::info!(
        id,
        role = me.role.as_str(),
        team = %team,
        subscribes = ?ins,
        notifies = ?outs,
        "joined: subscribed to state services of {:?}",
        ins
    );

    let cfg = step_config(&s);
    let last = s.last_tick();
    let mut x = QuadState::hover(me.position);
    let mut tick: u64 = 0;
    let mut published: Option<u64> = None;
    let mut grant: Option<u64> = None;
    let mut inbox: [Inbox; 3] = Default::default();
    let mut last_progress = Instant::now();
    let mut last_alive_check = Instant::now();
    let mut unnotified = false;
    let inject = crate::fault_inject::from_env(id);
    let fault_reply =
        |ports: &mut MemberPorts, tick: u64, code: FaultCode, peer: u32, x: &QuadState| {
            let msg = StateMsg::ok(tick, hash, id, x.0).with_status(AgentStatus::Fault {
                code,
                peer: if peer == NO_PEER { None } else { Some(peer) },
            });
            let _ = ports.publish(msg);
            linger(ports, interrupted);
        };

    loop {
        if interrupted.load(Ordering::Relaxed) {
            return Err(MemberError::Interrupted { id, tick });
        }
        let mut progress = false;
        if let Some(c) = ports.latest_clock()? {
            progress |= on_clock(&c, hash, &mut grant, id, team)?;
            if matches!(c.command(), ClockCommand::Stop(_)) {
                return Ok(Finished {
                    tick,
                    reason: c.reason,
                });
            }
        }
        let mut bad: Option<(u32, String)> = None;
        ports.receive_neighbors(|msg| {
            let Some(slot) = neighbor_ids.iter().position(|n| *n == msg.id) else {
                return;
            };
            if msg.status() != AgentStatus::Ok {
                // A neighbour's fault notice is not a state: the orchestrator stops the team once
                // every tick before the fault is complete (as the engine would have flown them).
                tracing::debug!(
                    peer = msg.id,
                    tick = msg.tick,
                    "in-neighbour reported a fault"
                );
                return;
            }
            if msg.scenario_hash != hash && bad.is_none() {
                bad = Some((
                    msg.id,
                    format!("sent a state of another scenario (tick {})", msg.tick),
                ));
            }
            if msg.tick >= tick {
                inbox[slot].insert(msg.tick, QuadState(msg.state).flat());
                progress = true;
            }
        })?;
        if let Some((peer, what)) = bad {
            fault_reply(&mut ports, tick, FaultCode::NeighborFault, peer, &x);
            return Err(MemberError::Neighbor {
                id,
                tick,
                peer,
                what,
            });
        }
        // Advance as far as grants and neighbour data allow (several ticks per wake-up).
        while let Some(g) = grant {
            if published != Some(tick) && g >= tick {
                let mut msg = StateMsg::ok(tick, hash, id, x.0);
                if let Some(i) = &inject {
                    i.apply(tick, &mut msg);
                }
                // Notify on block: readers are woken once, before this member sleeps,
                // instead of after every tick it runs ahead.
                ports.publish_quietly(msg)?;
                unnotified = true;
                published = Some(tick);
                progress = true;
            }
            if published != Some(tick) || tick >= last || g < tick + 1 {
                break;
            }
            let mut flats = [Flat::rest(me.position); 3];
            if is_follower {
                let mut ready = true;
                for (slot, f) in flats.iter_mut().enumerate() {
                    match inbox[slot].get(tick) {
                        Some(v) => *f = *v,
                        None => {
                            // A later tick without this one: a sample was lost.
                            if let Some(later) = inbox[slot].first_tick() {
                                if later > tick {
                                    let peer = neighbor_ids[slot];
                                    fault_reply(&mut ports, tick, FaultCode::TickGap, peer, &x);
                                    return Err(MemberError::Neighbor {
                                        id,
                                        tick,
                                        peer,
                                        what: format!("skipped from tick {tick} to {later}"),
                                    });
                                }
                            }
                            ready = false;
                        }
                    }
                }
                if !ready {
                    break;
                }
            }
            match step(&cfg, &s.plan, &law, tick, &x, &flats, &neighbor_ids) {
                Ok(next) => x = next,
                Err(fault) => {
                    let (code, peer) = match fault {
                        StepFault::NeighborNonFinite { peer } => (FaultCode::NonFinite, peer),
                        StepFault::Control(_) => (FaultCode::Control, NO_PEER),
                    };
                    fault_reply(&mut ports, tick, code, peer, &x);
                    return Err(MemberError::Step { id, tick, fault });
                }
            }
            tick += 1;
            for b in inbox.iter_mut() {
                b.drop_before(tick);
            }
            progress = true;
        }
        if progress {
            last_progress = Instant::now();
            continue;
        }
        let idle = last_progress.elapsed();
        if last_alive_check.elapsed() >= Duration::from_millis(500) {
            last_alive_check = Instant::now();
            if !ports.orchestrator_alive() {
                return Err(MemberError::OrchestratorLost {
                    id,
                    team: team.to_string(),
                    tick,
                });
            }
        }
        let limit = if grant.is_none() {
            deadlines.join
        } else {
            deadlines.silence
        };
        if idle >= limit {
            let waiting_for = if grant.is_none() {
                "the team to start".to_string()
            } else if grant.is_some_and(|g| g < tick + 1) || published != Some(tick) {
                format!("a grant of tick {}", tick + 1)
            } else {
                let missing: Vec<u32> = (0..3)
                    .filter(|&k| inbox[k].get(tick).is_none())
                    .map(|k| neighbor_ids[k])
                    .collect();
                format!("tick-{tick} states of in-neighbours {missing:?}")
            };
            return Err(MemberError::Silent {
                id,
                tick,
                waited: idle,
                waiting_for,
            });
        }
        if unnotified {
            ports.notify_readers()?;
            unnotified = false;
            // Readers may answer at once (a grant or a neighbour's state): look before sleeping.
            continue;
        }
        // Every wake-up that matters is a notification (a grant, a neighbour's state, a stop) or
        // a signal; the slice only bounds how late the deadlines and the orchestrator check run.
        // Short slices cost: 1000 members polling every 50 ms took a tenth of a core at start-up.
        ports.wait(WAIT_SLICE.min(limit - idle))?;
    }
}

/// One in-neighbour's states not yet used, by tick (ascending). A neighbour publishes its ticks
/// in order, so states are appended and taken from the front: no allocation per tick (a
/// `BTreeMap` here took a sixth of a member's time at N = 40).
#[derive(Debug, Default)]
struct Inbox(std::collections::VecDeque<(u64, Flat)>);

impl Inbox {
    /// Stores `tick`'s state; a repeated tick replaces the earlier one.
    fn insert(&mut self, tick: u64, f: Flat) {
        match self.0.back() {
            Some(&(last, _)) if last >= tick => match self.0.binary_search_by_key(&tick, |e| e.0) {
                Ok(k) => self.0[k].1 = f,
                Err(k) => self.0.insert(k, (tick, f)),
            },
            _ => self.0.push_back((tick, f)),
        }
    }

    fn get(&self, tick: u64) -> Option<&Flat> {
        // Used ticks are dropped, so the wanted one is (nearly always) at the front.
        self.0
            .iter()
            .find(|e| e.0 >= tick)
            .filter(|e| e.0 == tick)
            .map(|e| &e.1)
    }

    fn first_tick(&self) -> Option<u64> {
        self.0.front().map(|e| e.0)
    }

    fn drop_before(&mut self, tick: u64) {
        while self.0.front().is_some_and(|e| e.0 < tick) {
            self.0.pop_front();
        }
    }
}

/// How long a member that reported a fault keeps its ports open for the orchestrator's stop.
const LINGER: Duration = Duration::from_secs(5);

/// After a fault report: keep the process (and so its published states) alive until the
/// orchestrator stops the team, it is gone, or [`LINGER`] passes. iceoryx2 drops the samples a
/// subscriber has not yet taken when their publisher's process exits, so a member that ran ahead
/// (a large window) and exited at once could take its fault report, and the states before it,
/// with it; the orchestrator would then see only an exited process.
fn linger(ports: &mut MemberPorts, interrupted: &AtomicBool) {
    let start = Instant::now();
    let mut last_alive_check = Instant::now();
    while start.elapsed() < LINGER && !interrupted.load(Ordering::Relaxed) {
        match ports.latest_clock() {
            Ok(Some(c)) if matches!(c.command(), ClockCommand::Stop(_)) => return,
            Ok(_) => {}
            Err(_) => return,
        }
        if last_alive_check.elapsed() >= Duration::from_millis(500) {
            last_alive_check = Instant::now();
            if !ports.orchestrator_alive() {
                return;
            }
        }
        if ports.wait(Duration::from_millis(100)).is_err() {
            return;
        }
    }
}

/// The longest single wait of a member.
const WAIT_SLICE: Duration = Duration::from_millis(250);

fn on_clock(
    c: &ClockMsg,
    hash: u64,
    grant: &mut Option<u64>,
    id: u32,
    team: &TeamName,
) -> Result<bool, MemberError> {
    if c.scenario_hash != hash {
        return Err(MemberError::Transport(TransportError::ScenarioMismatch {
            team: team.clone(),
            id,
            mine: hash,
            team_hash: crate::transport::scenario_hash_value(c.scenario_hash),
        }));
    }
    if c.command() == ClockCommand::Run && grant.is_none_or(|g| c.grant_tick > g) {
        *grant = Some(c.grant_tick);
        return Ok(true);
    }
    Ok(false)
}
