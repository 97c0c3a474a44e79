//! The replay's side of the switches a member applied in flight and of the losses the monitor
//! applied: which repaired link each member flew from which tick (checked against the repair of
//! the run's losses, `LossLog::epochs`, as every member computed it from the notices), that each
//! command was taken before its switch, and from which audit instant a lost member's body is out.

use cdm_model::dynamics::Flat;
use cdm_model::formation::Member;
use cdm_model::repair::Repair;
use cdm_model::step::{law_for, Law};
use cdm_records::audit::Auditor;
use cdm_records::loss_log::LossLog;
use cdm_scenario::Scenario;

use super::{Flier, Recorded, ReplayInputError, ReplayLoss};
use crate::realtime_journal::Switched;
use crate::seams::Vehicle;

/// The graph's changes of the run's losses: each tick at which it changes, with the repair in
/// force from it (the members' `MemberLosses` compute the same from the same notices).
pub(super) fn epochs(s: &Scenario, losses: &[ReplayLoss]) -> Vec<(u64, Repair)> {
    let mut log = LossLog::new(s);
    for l in losses {
        log.add(l.id, l.repair_tick);
    }
    log.epochs()
}

/// Member `id`'s repaired links as it flew them, each from its tick, checked against the run's
/// losses (`epochs`) and commands (`commands`: their switch ticks, notice 1 first).
pub(super) fn relinks(
    id: u32,
    rec: &Recorded,
    epochs: &[(u64, Repair)],
    commands: &[u64],
) -> Result<Vec<(u64, Member)>, ReplayInputError> {
    let mut out = Vec::new();
    let (mut taken, mut last_seq) = (0u32, 0u32);
    for sw in &rec.switches {
        let bad = |why: String| ReplayInputError::Switch {
            id,
            tick: sw.tick,
            why,
        };
        match sw.what {
            Switched::Repair { at, in_neighbors } => {
                let member = (epochs.iter())
                    .find(|(t, _)| *t == at)
                    .and_then(|(_, r)| r.formation.member(id));
                let Some(member) = member else {
                    return Err(bad(format!(
                        "flew the repaired link of tick {at}, but the run's losses change no link then"
                    )));
                };
                let given = member.link.map(|l| l.in_neighbors);
                if given != in_neighbors {
                    return Err(bad(format!(
                        "flew in-neighbours {in_neighbors:?} from the repair of tick {at}, but the run's losses give {given:?}"
                    )));
                }
                out.push((sw.tick, member.clone()));
            }
            Switched::Command { seq, at } => {
                // Notice numbers grow with every proposal, withdrawn ones too (real time), so
                // the k-th command taken is the run's k-th, whatever its number.
                taken += 1;
                let given = commands.get(taken as usize - 1);
                let in_order = seq > last_seq;
                last_seq = seq;
                if !in_order || given != Some(&at) || sw.tick > at {
                    return Err(bad(format!(
                        "took command {seq} switching at tick {at}, but the run's command {taken} switches at {given:?}"
                    )));
                }
            }
        }
    }
    Ok(out)
}

/// Member `k` applies the repaired link it flew from its next tick, if any, as the member did
/// (`realtime/repair.rs`): the in-neighbours it keeps stay where they were heard from; each new
/// one starts at rest where it started.
pub(super) fn relink_if_due(s: &Scenario, fliers: &mut [Flier], k: usize) {
    let index_of = |id: u32| s.formation.members.iter().position(|m| m.id == id);
    let f = &mut fliers[k];
    let next = f.next();
    while let Some((_, member)) = f.relinks.0.get(f.relinks.1).filter(|(t, _)| *t <= next) {
        let member = member.clone();
        f.relinks.1 += 1;
        // A model vehicle always switches.
        let _ = f.vehicle.relink(&member);
        let (law, ids) = law_for(&member);
        let (old_ids, old_initial) = (f.neighbor_ids, f.initial);
        for (slot, &j) in ids.iter().enumerate() {
            f.initial[slot] = match old_ids.iter().position(|&o| o == j) {
                Some(kept) => old_initial[kept],
                None => (s.formation.member(j)).map_or(old_initial[slot], |m| Flat::rest(m.start)),
            };
        }
        f.neighbor_ids = ids;
        let follower = matches!(law, Law::Follower { .. });
        f.neighbors = follower.then(|| ids.map(|j| index_of(j).unwrap_or(usize::MAX)));
    }
}

/// The lost members' bodies out of the audit, each from the instant the run's monitor took it
/// out, with its records, in the order found.
pub(super) struct Out<'a> {
    losses: &'a [ReplayLoss],
    /// The members' ids in formation order.
    ids: Vec<u32>,
    handed: Vec<bool>,
    out: Vec<bool>,
}

impl<'a> Out<'a> {
    pub(super) fn new(s: &Scenario, losses: &'a [ReplayLoss]) -> Self {
        let ids: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
        Out {
            losses,
            out: vec![false; ids.len()],
            ids,
            handed: vec![false; losses.len()],
        }
    }

    /// The losses out at or before instant `index`, not handed yet, to the audit (as the run's
    /// monitor did before auditing it).
    pub(super) fn hand(&mut self, index: u64, audit: &mut Auditor) {
        for (k, l) in self.losses.iter().enumerate() {
            if self.handed[k] || l.out_from > index {
                continue;
            }
            self.handed[k] = true;
            for r in &l.records {
                if let Some(m) = self.ids.iter().position(|&id| id == r.id) {
                    self.out[m] = true;
                }
                audit.lose(r.clone());
            }
        }
    }

    /// True once member `k` (formation order) is out of the audit.
    pub(super) fn is_out(&self, k: usize) -> bool {
        self.out.get(k).copied().unwrap_or(false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::realtime_journal::Switch;

    /// generated10 losing 6 from tick 20: follower 9 reads [1, 6, 8], then [1, 3, 8].
    fn lose_six() -> (Scenario, Vec<ReplayLoss>) {
        let s = Scenario::generated(10).expect("generated10");
        let loss = ReplayLoss {
            id: 6,
            repair_tick: 20,
            out_from: 3,
            records: Vec::new(),
        };
        (s, vec![loss])
    }

    fn recorded(switches: Vec<Switch>) -> Recorded {
        Recorded {
            used: Vec::new(),
            switches,
            whole: true,
        }
    }

    #[test]
    fn a_repaired_link_is_the_run_s_repair_and_a_command_was_taken_before_its_switch() {
        let (s, losses) = lose_six();
        let e = epochs(&s, &losses);
        // Flown late (from 23), the repair of tick 20: the member with that link.
        let r = relinks(
            9,
            &recorded(vec![Switch::repaired(23, 20, [1, 3, 8])]),
            &e,
            &[],
        )
        .expect("ok");
        assert_eq!(r.len(), 1);
        assert_eq!(r[0].0, 23);
        assert_eq!(r[0].1.link.map(|l| l.in_neighbors), Some([1, 3, 8]));
        // Other in-neighbours, or a repair at a tick the losses do not give: refused, named.
        let bad = relinks(
            9,
            &recorded(vec![Switch::repaired(23, 20, [1, 2, 8])]),
            &e,
            &[],
        );
        let why = bad.unwrap_err().to_string();
        assert!(
            why.starts_with("agent 9 tick 23: flew in-neighbours Some([1, 2, 8])"),
            "{why}"
        );
        let bad = relinks(
            9,
            &recorded(vec![Switch::repaired(23, 21, [1, 3, 8])]),
            &e,
            &[],
        );
        assert!(bad.unwrap_err().to_string().contains("change no link then"));
        // Commands: taken in order, each before its switch, at the run's switch ticks.
        let command = |tick, seq, at| Switch {
            tick,
            what: Switched::Command { seq, at },
        };
        let ok = recorded(vec![command(10, 1, 50), command(60, 2, 90)]);
        assert_eq!(relinks(9, &ok, &e, &[50, 90]).expect("ok"), []);
        // A withdrawn proposal took number 2: the run's second command is number 3.
        let ok = recorded(vec![command(10, 1, 50), command(60, 3, 90)]);
        assert_eq!(relinks(9, &ok, &e, &[50, 90]).expect("ok"), []);
        for (sw, commands) in [
            (vec![command(10, 1, 50)], vec![60]),
            (vec![command(10, 2, 50), command(60, 2, 90)], vec![50, 90]),
            (vec![command(51, 1, 50)], vec![50]),
            (vec![command(10, 1, 50)], vec![]),
        ] {
            let why = relinks(9, &recorded(sw), &e, &commands).unwrap_err();
            assert!(why.to_string().contains("took command"), "{why}");
        }
    }

    #[test]
    fn a_lost_body_leaves_the_audit_at_its_instant_with_its_records() {
        let (s, mut losses) = lose_six();
        let mut audit = Auditor::new(&s);
        losses[0].records = record_of_six(&s);
        let mut out = Out::new(&s, &losses);
        out.hand(2, &mut audit);
        let six = s.formation.members.iter().position(|m| m.id == 6);
        let six = six.expect("member 6");
        assert!(!out.is_out(six));
        out.hand(3, &mut audit);
        assert!(out.is_out(six));
        assert_eq!(audit.report().losses.len(), 1);
        // Handed once.
        out.hand(u64::MAX, &mut audit);
        assert_eq!(audit.report().losses.len(), 1);
    }

    /// A loss record of member 6 as the audit takes it.
    fn record_of_six(s: &Scenario) -> Vec<cdm_records::audit::LossRecord> {
        let role = s.formation.member(6).map(|m| m.role);
        vec![cdm_records::audit::LossRecord {
            id: 6,
            role,
            cause: cdm_model::outcome::LossCause::Scripted,
            last_tick: 10,
            tick: 3,
            t_s: 0.3,
            repair_tick: Some(20),
            retriangulated: Vec::new(),
            degraded: Vec::new(),
            host: None,
        }]
    }
}
