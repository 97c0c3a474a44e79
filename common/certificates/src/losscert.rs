//! The loss certificate of `plan --losses`: for every member, fly the plan with that member lost
//! at the worst moment, and say whether the team stays safe.
//!
//! The worst moment: after a switch, a repaired follower's reference jumps by
//! sum_new w_j e_j - sum_old w_j e_j, e_j = r_j - r_j,HT the neighbours' tracking errors (the
//! r_HT terms cancel: both triangles satisfy eq. 18). Every r_HT is affine in the same s(t)
//! (eq. 13), so the tracking errors of the whole team rise and fall together and the kick is
//! largest when they peak: each member is lost right after publishing the tick at which the
//! nominal flight's follower deviation (eq. 34) peaks.
//!
//! Shared work: the nominal flight is flown once up to that tick, then each of `threads` workers
//! flies the nominal remainder once and, beside it, one branch per member it certifies. A
//! branch steps only the members whose flight differs from the nominal (the repaired followers
//! and everyone downstream of them in the repaired graph), reading everyone else's nominal
//! state: the others are bit-identical to the nominal flight by construction. Tracking (eq. 34)
//! and containment (Theorem 3) are checked exactly for the branch's members; collisions with
//! the bound sep >= sep_nominal - 2 max ||r_branch - r_nominal|| (sound, not tight).

use std::collections::BTreeSet;

use serde::Serialize;

use cdm_engine::engine::{quad_engine, Engine};
use cdm_math::{Real, Vec3};
use cdm_model::dynamics::{Flat, QuadState};
use cdm_model::formation::{Formation, Role};
use cdm_model::graph::DEFAULT_WEIGHT_FLOOR;
use cdm_model::outcome::Verdict;
use cdm_model::repair::{repair, Repair, Retriangulation};
use cdm_model::safety::Prism;
use cdm_model::step::{law_for, step, tick_time, Law, StepConfig};
use cdm_records::audit::Auditor;
use cdm_scenario::Scenario;

/// One member's loss, certified.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MemberLoss {
    pub id: u32,
    /// Its role (serialised lowercase, as in the scenario).
    pub role: Role,
    /// Safe or Unsafe.
    pub verdict: Verdict,
    pub reasons: Vec<String>,
    pub retriangulated: Vec<Retriangulation>,
    /// Followers left with no triangle, flying their own plan.
    pub degraded: Vec<u32>,
    /// Members whose flight differs from the nominal one.
    pub affected: usize,
    /// Largest ||r_i - r_i,HT||_2 of a re-triangulated or degraded follower after the loss.
    pub max_repaired_deviation_m: Real,
    /// Largest ||r_i - r_i,nominal|| of an affected member after the loss.
    pub max_shift_m: Real,
    /// When the largest repaired deviation happened, and whose.
    pub worst_id: Option<u32>,
    pub worst_t_s: Real,
}

/// `plan --losses`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LossCertificate {
    /// "survives the loss of any single member", or the members it cannot lose.
    pub verdict: String,
    pub survives_any_single_loss: bool,
    pub cannot_lose: Vec<u32>,
    pub scenario: String,
    pub agents: usize,
    /// Every member is lost right after publishing this tick (the nominal peak deviation).
    pub loss_last_tick: u64,
    pub loss_t_s: Real,
    pub nominal_verdict: Verdict,
    pub nominal_max_follower_deviation_m: Real,
    pub nominal_min_separation_m: Real,
    pub delta_m: Real,
    pub eps_m: Real,
    pub threads: usize,
    pub members: Vec<MemberLoss>,
}

/// Certify the loss of every member, on `threads` workers.
pub fn certify_losses(s: &Scenario, threads: usize) -> LossCertificate {
    let (snapshot, nominal) = nominal_flight(s);
    let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
    let threads = threads.clamp(1, ids.len().max(1));
    let mut members: Vec<MemberLoss> = std::thread::scope(|sc| {
        let workers: Vec<_> = (0..threads)
            .map(|w| {
                let mine: Vec<u32> = ids.iter().copied().skip(w).step_by(threads).collect();
                let snap = snapshot.clone();
                sc.spawn(move || fly_branches(s, snap, &mine, &nominal))
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_default())
            .collect()
    });
    members.sort_by_key(|m| s.formation.index_of(m.id));
    // A member without a SAFE branch (also: none flown, when the nominal flight faulted).
    let cannot_lose: Vec<u32> = s
        .formation
        .members
        .iter()
        .map(|m| m.id)
        .filter(|id| {
            !members
                .iter()
                .any(|b| b.id == *id && b.verdict == Verdict::Safe)
        })
        .collect();
    let survives = cannot_lose.is_empty();
    LossCertificate {
        verdict: if survives {
            "survives the loss of any single member".into()
        } else {
            format!("cannot lose {cannot_lose:?}")
        },
        survives_any_single_loss: survives,
        cannot_lose,
        scenario: s.file.name.clone(),
        agents: ids.len(),
        loss_last_tick: nominal.peak_tick,
        loss_t_s: tick_time(nominal.peak_tick, s.dt_s()),
        nominal_verdict: nominal.verdict,
        nominal_max_follower_deviation_m: nominal.max_follower_deviation_m,
        nominal_min_separation_m: nominal.min_separation_m,
        delta_m: nominal.delta_m,
        eps_m: s.file.eps_m,
        threads,
        members,
    }
}

/// What the branches need from the nominal flight.
#[derive(Debug, Clone, Copy)]
struct Nominal {
    peak_tick: u64,
    verdict: Verdict,
    max_follower_deviation_m: Real,
    min_separation_m: Real,
    delta_m: Real,
}

/// Fly the nominal plan with the full audit; return the engine at the tick of the largest
/// follower deviation (before its step) and the nominal numbers.
fn nominal_flight(s: &Scenario) -> (Engine<QuadState>, Nominal) {
    let mut e = quad_engine(s);
    let mut audit = Auditor::new(s);
    let (mut ht, mut pos) = (Vec::new(), Vec::new());
    let mut snapshot = e.clone();
    let mut peak = (Real::NEG_INFINITY, 0);
    let last = s.last_tick();
    let complete = loop {
        let tick = e.tick();
        let t = tick_time(tick, s.dt_s());
        s.desired_positions(t, &mut ht);
        pos.clear();
        pos.extend(e.states().iter().map(|q| q.position()));
        audit.observe(tick, t, &pos, &ht);
        let dev = audit.report().max_follower_deviation_m;
        // The loss must leave a tick to fly after it.
        if dev > peak.0 && tick < last {
            peak = (dev, tick);
            snapshot = e.clone();
        }
        if tick >= last {
            break true;
        }
        if e.advance().is_err() {
            break false;
        }
    };
    let r = audit.finish(complete);
    let nominal = Nominal {
        peak_tick: peak.1,
        verdict: r.verdict,
        max_follower_deviation_m: r.max_follower_deviation_m,
        min_separation_m: r.min_separation_m,
        delta_m: r.numbers.delta_m,
    };
    (snapshot, nominal)
}

/// One member's loss flown beside the nominal flight.
struct Branch {
    id: u32,
    repair: Repair,
    /// Member indices of the affected members, and each member's slot among them.
    idx: Vec<usize>,
    slot: Vec<Option<usize>>,
    laws: Vec<Law>,
    nb: Vec<[usize; 3]>,
    nb_ids: Vec<[u32; 3]>,
    /// Slot is a re-triangulated or degraded follower.
    repaired: Vec<bool>,
    states: Vec<QuadState>,
    flats: Vec<Flat>,
    out: MemberLoss,
}

impl Branch {
    /// The branch of losing `id` after the nominal `e`'s current tick (states at tick L + 1).
    fn new(s: &Scenario, e: &Engine<QuadState>, (id, role): (u32, Role), floor: Real) -> Self {
        let r = repair(&s.formation, floor, &BTreeSet::from([id]));
        let changed: BTreeSet<u32> = r
            .retriangulated
            .iter()
            .map(|x| x.id)
            .chain(r.degraded.iter().copied())
            .collect();
        let f = &r.formation;
        let idx = downstream(f, &changed, &r.lost);
        let mut slot = vec![None; f.members.len()];
        for (i, &k) in idx.iter().enumerate() {
            slot[k] = Some(i);
        }
        let (mut laws, mut nb, mut nb_ids) = (Vec::new(), Vec::new(), Vec::new());
        for &k in &idx {
            let (law, ids) = law_for(&f.members[k]);
            laws.push(law);
            nb.push(ids.map(|j| f.index_of(j).unwrap_or(k)));
            nb_ids.push(ids);
        }
        let states: Vec<QuadState> = idx.iter().map(|&k| e.states()[k]).collect();
        let out = MemberLoss {
            id,
            role,
            verdict: Verdict::Safe,
            reasons: Vec::new(),
            retriangulated: r.retriangulated.clone(),
            degraded: r.degraded.clone(),
            affected: idx.len(),
            max_repaired_deviation_m: 0.0,
            max_shift_m: 0.0,
            worst_id: None,
            worst_t_s: 0.0,
        };
        Branch {
            id,
            repaired: idx
                .iter()
                .map(|&k| changed.contains(&f.members[k].id))
                .collect(),
            flats: states.iter().map(|q| q.flat()).collect(),
            repair: r,
            idx,
            slot,
            laws,
            nb,
            nb_ids,
            states,
            out,
        }
    }

    /// Audit the branch's members at this tick against the nominal positions.
    fn observe(
        &mut self,
        at: (u64, Real),
        ht: &[Vec3],
        nominal: &[Vec3],
        prism: &Prism,
        delta: Real,
    ) {
        for (i, &k) in self.idx.iter().enumerate() {
            let p = self.states[i].position();
            let dev = (p - ht[k]).norm();
            self.out.max_shift_m = self.out.max_shift_m.max((p - nominal[k]).norm());
            if self.repaired[i] && dev > self.out.max_repaired_deviation_m {
                self.out.max_repaired_deviation_m = dev;
                self.out.worst_id = Some(self.repair.formation.members[k].id);
                self.out.worst_t_s = at.1;
            }
            let id = self.repair.formation.members[k].id;
            if dev > delta {
                fail(
                    &mut self.out,
                    format!(
                        "tracking: agent {id} at t = {:.2} s deviates {dev:.4} m > delta (eq. 34)",
                        at.1
                    ),
                );
            }
            let follower = self.repair.formation.members[k].role == Role::Follower;
            let outside =
                prism.side_distance(&p) < 0.0 || prism.height(&p).abs() > prism.half_height_m;
            if follower && outside {
                fail(
                    &mut self.out,
                    format!(
                        "containment: agent {id} leaves the prism at t = {:.2} s (Theorem 3)",
                        at.1
                    ),
                );
            }
        }
    }

    /// Step the branch's members from `tick` to `tick + 1`, reading the others' nominal states.
    fn advance(&mut self, cfg: &StepConfig, s: &Scenario, tick: u64, nominal: &[Flat]) {
        for (f, q) in self.flats.iter_mut().zip(&self.states) {
            *f = q.flat();
        }
        for i in 0..self.idx.len() {
            let nbf = self.nb[i].map(|j| self.slot[j].map_or(nominal[j], |sl| self.flats[sl]));
            match step(
                cfg,
                &s.plan,
                &self.laws[i],
                tick,
                &self.states[i],
                &nbf,
                &self.nb_ids[i],
            ) {
                Ok(next) => self.states[i] = next,
                Err(fault) => fail(
                    &mut self.out,
                    format!("agent {} faulted at tick {tick}: {fault}", self.id),
                ),
            }
        }
    }
}

/// Mark a branch UNSAFE, keeping the first few reasons.
fn fail(out: &mut MemberLoss, reason: String) {
    out.verdict = Verdict::Unsafe;
    if out.reasons.len() < 4 {
        out.reasons.push(reason);
    }
}

/// Members whose flight differs from the nominal one: the changed followers and every survivor
/// that reads them, directly or through others (member indices, sorted).
fn downstream(f: &Formation, changed: &BTreeSet<u32>, lost: &BTreeSet<u32>) -> Vec<usize> {
    let out = f.out_neighbors();
    let mut seen: BTreeSet<u32> = changed.clone();
    let mut stack: Vec<u32> = changed.iter().copied().collect();
    while let Some(j) = stack.pop() {
        for &k in out.get(&j).into_iter().flatten() {
            if !lost.contains(&k) && seen.insert(k) {
                stack.push(k);
            }
        }
    }
    let mut idx: Vec<usize> = seen.iter().filter_map(|id| f.index_of(*id)).collect();
    idx.sort_unstable();
    idx
}

/// Fly the nominal flight from `e` (at the peak tick L) to the end, with one branch per id
/// lost after tick L; return their certificates.
fn fly_branches(
    s: &Scenario,
    mut e: Engine<QuadState>,
    ids: &[u32],
    nominal: &Nominal,
) -> Vec<MemberLoss> {
    let cfg = s.step_config();
    let floor = s.file.weight_floor.unwrap_or(DEFAULT_WEIGHT_FLOOR);
    let last = s.last_tick();
    if e.advance().is_err() {
        return Vec::new();
    }
    let mut branches: Vec<Branch> = ids
        .iter()
        // Ids outside the team have no branch (the callers pass the formation's own).
        .filter_map(|&id| s.role_of(id).map(|role| (id, role)))
        .map(|member| Branch::new(s, &e, member, floor))
        .collect();
    let (mut ht, mut pos, mut flats) = (Vec::new(), Vec::new(), Vec::new());
    let half = nominal.delta_m + s.file.eps_m;
    loop {
        let tick = e.tick();
        let t = tick_time(tick, s.dt_s());
        s.desired_positions(t, &mut ht);
        pos.clear();
        pos.extend(e.states().iter().map(|q| q.position()));
        let prism = prism_at(&s.formation, &ht, half);
        for b in &mut branches {
            b.observe((tick, t), &ht, &pos, &prism, nominal.delta_m);
        }
        if tick >= last {
            break;
        }
        flats.clear();
        flats.extend(e.states().iter().map(|q| q.flat()));
        for b in &mut branches {
            b.advance(&cfg, s, tick, &flats);
        }
        if e.advance().is_err() {
            break;
        }
    }
    branches
        .into_iter()
        .map(|b| verdict(b.out, nominal, s.file.eps_m))
        .collect()
}

/// Theorem 3's prism over the leaders' desired polygon, as the audit builds it.
fn prism_at(f: &Formation, ht: &[Vec3], half_height_m: Real) -> Prism {
    let verts: Vec<Vec3> = f.polygon.iter().map(|&k| ht[k]).collect();
    let normal = (verts[1] - verts[0])
        .cross(&(verts[2] - verts[0]))
        .normalize();
    Prism::new(verts, normal, half_height_m)
}

/// The branch's verdict: the nominal flight was safe, the branch's members stayed within
/// tracking and containment, and the separation bound holds.
fn verdict(mut out: MemberLoss, nominal: &Nominal, eps_m: Real) -> MemberLoss {
    if nominal.verdict != Verdict::Safe {
        out.verdict = Verdict::Unsafe;
        out.reasons
            .push(format!("the nominal flight is {}", nominal.verdict));
    }
    let bound = nominal.min_separation_m - 2.0 * out.max_shift_m;
    if bound < 2.0 * eps_m {
        out.verdict = Verdict::Unsafe;
        out.reasons.push(format!(
            "separation not certified: nominal {:.4} m - 2 x shift {:.4} m < 2 eps = {} m",
            nominal.min_separation_m,
            out.max_shift_m,
            2.0 * eps_m
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_engine::loss::{LossSchedule, LossState};
    use cdm_scenario::Checks;

    /// A shorter paper40 flight (60 s) so the reference flights are quick.
    fn short_paper40() -> Scenario {
        let s = Scenario::builtin("paper40").unwrap();
        let mut f = s.file.clone();
        f.t_total_s = 60.0;
        Scenario::from_file(f, "paper40 at 60 s", Checks::Member).unwrap()
    }

    /// The whole team flown with the loss (as `simulate --lose` does): the repaired followers'
    /// largest deviation and the largest shift from the nominal flight.
    fn full_flight(s: &Scenario, id: u32, last_tick: u64) -> (Real, Real) {
        let mut nominal = quad_engine(s);
        let mut e = quad_engine(s);
        let mut audit = Auditor::new(s);
        let mut losses = LossState::new(s, LossSchedule::single(id, last_tick));
        let mut ht = Vec::new();
        let (mut dev, mut shift) = (0.0 as Real, 0.0 as Real);
        let mut changed = BTreeSet::new();
        loop {
            let tick = e.tick();
            if let Some(ids) = losses.due(tick) {
                let r = losses.apply(s, tick, &ids, &mut e, &mut audit);
                changed.extend(r.retriangulated.iter().map(|x| x.id));
                changed.extend(r.degraded.iter().copied());
            }
            s.desired_positions(tick_time(tick, s.dt_s()), &mut ht);
            if tick > last_tick {
                for (k, m) in s.formation.members.iter().enumerate() {
                    if m.id == id {
                        continue;
                    }
                    let p = e.states()[k].position();
                    shift = shift.max((p - nominal.states()[k].position()).norm());
                    if changed.contains(&m.id) {
                        dev = dev.max((p - ht[k]).norm());
                    }
                }
            }
            if tick >= s.last_tick() {
                return (dev, shift);
            }
            e.advance().unwrap();
            nominal.advance().unwrap();
        }
    }

    #[test]
    fn branches_match_full_flights_with_the_loss() {
        let s = short_paper40();
        let c = certify_losses(&s, 2);
        assert_eq!(c.members.len(), 40);
        assert_eq!(c.threads, 2);
        // A primary leader, a secondary leader and a follower that others read.
        let out = s.formation.out_neighbors();
        let follower = s
            .formation
            .members
            .iter()
            .find(|m| m.role == Role::Follower && !out[&m.id].is_empty())
            .unwrap()
            .id;
        let secondary = s
            .formation
            .members
            .iter()
            .find(|m| m.role == Role::Secondary)
            .unwrap()
            .id;
        for id in [s.formation.members[0].id, secondary, follower] {
            let m = c.members.iter().find(|m| m.id == id).unwrap();
            assert!(m.affected > 0, "{m:?}");
            let (dev, shift) = full_flight(&s, id, c.loss_last_tick);
            assert!(
                (dev - m.max_repaired_deviation_m).abs() < 1e-12,
                "{id}: {dev} vs {m:?}"
            );
            assert!(
                (shift - m.max_shift_m).abs() < 1e-12,
                "{id}: {shift} vs {m:?}"
            );
        }
    }

    #[test]
    fn an_unsafe_nominal_flight_certifies_no_loss() {
        let s = short_paper40();
        let mut f = s.file.clone();
        f.t_total_s = 2.0;
        let fast = Scenario::from_file(f, "paper40 at 2 s", Checks::Member).unwrap();
        let c = certify_losses(&fast, 2);
        assert_ne!(c.nominal_verdict, Verdict::Safe);
        assert!(!c.survives_any_single_loss);
        assert_eq!(c.cannot_lose.len(), 40);
    }
}
