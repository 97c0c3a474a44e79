//! The deterministic in-process engine: the whole team in one process, running the same
//! per-member `step` the member processes run, in member order. It is the reference the
//! multi-process runtime must match bit for bit.

use cdm_math::{Real, Vec3};
use cdm_model::dynamics::{Chain, Flat, Plant, QuadState};
use cdm_model::formation::Role;
use cdm_model::link::{Heard, LinkModel};
use cdm_model::repair::Repair;
use cdm_model::step::{law_for, step, tick_time, Law, NeighborModel, StepConfig, StepFault};
use cdm_scenario::Scenario;

/// A member failed to complete a tick.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("agent {id} at tick {tick}: {fault}")]
pub struct AgentFault {
    pub id: u32,
    pub tick: u64,
    pub fault: StepFault,
}

/// The whole team in one process (cloned to fly variants of one flight from a shared prefix).
#[derive(Clone)]
pub struct Engine<P: Plant> {
    cfg: StepConfig,
    scenario: Scenario,
    laws: Vec<Law>,
    neighbor_idx: Vec<[usize; 3]>,
    neighbor_ids: Vec<[u32; 3]>,
    states: Vec<P>,
    flats: Vec<Flat>,
    /// Member order: false once a member is lost (it no longer steps).
    alive: Vec<bool>,
    tick: u64,
    links: Links,
}

/// What the engine keeps for imperfect links (`link.rs`): the newest state each follower has
/// heard of each in-neighbour, and every member's recent states, from tick `history_from` on
/// (the candidates still in flight).
#[derive(Clone)]
struct Links {
    model: LinkModel,
    held: Vec<[Heard; 3]>,
    history: std::collections::VecDeque<Vec<Flat>>,
    history_from: u64,
}

impl Links {
    /// Before anything arrives a follower knows where its neighbours start (link.rs).
    fn new(model: LinkModel, neighbor_idx: &[[usize; 3]], flats: &[Flat]) -> Self {
        let held = neighbor_idx
            .iter()
            .map(|idx| {
                idx.map(|j| Heard {
                    tick: 0,
                    flat: flats[j],
                })
            })
            .collect();
        Links {
            model,
            held,
            history: Default::default(),
            history_from: 0,
        }
    }
}

impl<P: Plant> Engine<P> {
    /// A team at rest at its initial positions (`init` makes a plant at rest at a point).
    pub fn new(scenario: &Scenario, init: impl Fn(Vec3) -> P) -> Self {
        let f = &scenario.formation;
        let mut laws = Vec::with_capacity(f.members.len());
        let mut neighbor_idx = Vec::with_capacity(f.members.len());
        let mut neighbor_ids = Vec::with_capacity(f.members.len());
        for (k, m) in f.members.iter().enumerate() {
            let (law, ids) = law_for(m);
            laws.push(law);
            neighbor_idx.push(ids.map(|id| f.index_of(id).unwrap_or(k)));
            neighbor_ids.push(ids);
        }
        let states: Vec<P> = f.members.iter().map(|m| init(m.start)).collect();
        let flats: Vec<Flat> = states.iter().map(|p| p.flat()).collect();
        let links = Links::new(scenario.link_model(), &neighbor_idx, &flats);
        Engine {
            cfg: scenario.step_config(),
            scenario: scenario.clone(),
            laws,
            neighbor_idx,
            neighbor_ids,
            states,
            flats,
            alive: vec![true; f.members.len()],
            tick: 0,
            links,
        }
    }

    /// From the next `advance` on, fly the survivors of `repair`: lost members stop stepping
    /// (their state is frozen and must not be read), every survivor takes the law of its
    /// repaired link (a degraded follower tracks its own r_HT, like a leader).
    pub fn apply_repair(&mut self, repair: &Repair) {
        let f = &repair.formation;
        for (k, m) in f.members.iter().enumerate() {
            if repair.lost.contains(&m.id) {
                self.alive[k] = false;
                continue;
            }
            let (law, ids) = law_for(m);
            self.laws[k] = law;
            let idx = ids.map(|id| f.index_of(id).unwrap_or(k));
            // A new in-neighbour over imperfect links: known, until its states arrive, where
            // it started (as at tick 0).
            for (slot, &j) in idx.iter().enumerate() {
                if idx[slot] != self.neighbor_idx[k][slot] {
                    let flat = Flat::rest(self.scenario.formation.members[j].start);
                    self.links.held[k][slot] = Heard { tick: 0, flat };
                }
            }
            self.neighbor_idx[k] = idx;
            self.neighbor_ids[k] = ids;
        }
    }

    /// The same team with followers extrapolating their neighbours by `model` inside a tick
    /// (the product flies the default; the exchange-error test compares models).
    pub fn with_neighbor_model(mut self, model: NeighborModel) -> Self {
        self.cfg.neighbor_model = model;
        self
    }

    /// Whether each member (member order) still flies.
    pub fn alive(&self) -> &[bool] {
        &self.alive
    }

    /// The current tick.
    pub fn tick(&self) -> u64 {
        self.tick
    }

    /// Current plant states in member order.
    pub fn states(&self) -> &[P] {
        &self.states
    }

    /// The scenario flown.
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// Advance every member from tick k to k + 1: everyone reads the tick-k states, then steps.
    pub fn advance(&mut self) -> Result<(), AgentFault> {
        for (f, p) in self.flats.iter_mut().zip(&self.states) {
            *f = p.flat();
        }
        if !self.links.model.is_perfect() {
            return self.advance_over_links();
        }
        for k in 0..self.states.len() {
            if !self.alive[k] {
                continue;
            }
            let nb = self.neighbor_idx[k].map(|j| self.flats[j]);
            let next = step(
                &self.cfg,
                &self.scenario.plan,
                &self.laws[k],
                self.tick,
                &self.states[k],
                &nb,
                &self.neighbor_ids[k],
            )
            .map_err(|fault| AgentFault {
                id: self.scenario.formation.members[k].id,
                tick: self.tick,
                fault,
            })?;
            self.states[k] = next;
        }
        self.tick += 1;
        Ok(())
    }
}

impl<P: Plant> Engine<P> {
    /// `advance` over imperfect links: each follower steps from the newest state it has heard
    /// of each in-neighbour, brought to this tick (`LinkModel::hear`, as the members do).
    fn advance_over_links(&mut self) -> Result<(), AgentFault> {
        let tick = self.tick;
        let l = &mut self.links;
        l.history.push_back(self.flats.clone());
        let members = &self.scenario.formation.members;
        let upto = l.model.needed(tick);
        for (k, member) in members.iter().enumerate() {
            if !self.alive[k] {
                continue;
            }
            let mut nb = self.neighbor_idx[k].map(|j| self.flats[j]);
            if let Law::Follower { .. } = self.laws[k] {
                let (from, hist) = (l.history_from, &l.history);
                let idx = self.neighbor_idx[k];
                let candidates = |slot: usize| {
                    let j = idx[slot];
                    upto.into_iter()
                        .flat_map(move |hi| from..=hi)
                        .map(move |m| Heard {
                            tick: m,
                            flat: hist[(m - from) as usize][j],
                        })
                };
                let ids = &self.neighbor_ids[k];
                let to = member.id;
                let cfg = &self.cfg;
                let held = &mut l.held[k];
                nb = l.model.hear(
                    to,
                    ids,
                    tick,
                    held,
                    candidates,
                    cfg.dt_s,
                    cfg.neighbor_model,
                );
            }
            let next = step(
                &self.cfg,
                &self.scenario.plan,
                &self.laws[k],
                tick,
                &self.states[k],
                &nb,
                &self.neighbor_ids[k],
            )
            .map_err(|fault| AgentFault {
                id: member.id,
                tick,
                fault,
            })?;
            self.states[k] = next;
        }
        self.tick += 1;
        // States older than the oldest candidate of the next tick have been seen for good.
        while l.history_from < l.model.oldest_candidate(self.tick) {
            l.history.pop_front();
            l.history_from += 1;
        }
        Ok(())
    }
}

/// The nonlinear team (the product's plant).
pub fn quad_engine(s: &Scenario) -> Engine<QuadState> {
    Engine::new(s, QuadState::hover)
}

/// The linear 4th-order team (eq. 43a), as a reference.
pub fn chain_engine(s: &Scenario) -> Engine<Chain> {
    Engine::new(s, Chain::rest)
}

/// Largest follower deviation ||r_i - r_i,HT||_2 over the whole plan (eq. 34), flown by the
/// nonlinear engine. Used to find T_threshold.
pub fn max_follower_deviation(s: &Scenario) -> Result<Real, AgentFault> {
    max_follower_deviation_within(s, Real::INFINITY)
}

/// [`max_follower_deviation`], ending the flight as soon as the deviation exceeds `limit_m`
/// (it is a running maximum, so the answer "more than the limit" is then known).
pub fn max_follower_deviation_within(s: &Scenario, limit_m: Real) -> Result<Real, AgentFault> {
    let mut e = quad_engine(s);
    let mut ht = Vec::new();
    let followers: Vec<usize> = s
        .formation
        .members
        .iter()
        .enumerate()
        .filter(|(_, m)| m.role == Role::Follower)
        .map(|(k, _)| k)
        .collect();
    let mut worst: Real = 0.0;
    let last = s.last_tick();
    loop {
        s.desired_positions(tick_time(e.tick(), s.dt_s()), &mut ht);
        for &k in &followers {
            worst = worst.max((e.states()[k].position() - ht[k]).norm());
        }
        if e.tick() >= last || worst > limit_m {
            return Ok(worst);
        }
        e.advance()?;
    }
}
