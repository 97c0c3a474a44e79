//! A real-time member's side of a team-mate's loss: the notices (the same [`MemberLosses`] as
//! lockstep: the run's `LossLog`, the repair of `simulate`, the ports to open, the hand-over),
//! the states of future in-neighbours, and the switch to the repaired link.
//!
//! When. The notice's tick T lies a lead ahead of the instant the orchestrator found the loss
//! (`team_realtime/losses.rs`); a reader of the lost member flies its repaired link (new
//! triangle, eq. 18 weights; or its own plan when none is left) from its own tick T, once every
//! loss it knows is linked (`MemberLosses::due`) and it has a usable state of each new
//! in-neighbour. Until then it flies the link it has, the lost neighbour brought forward from
//! its last state by the cubic model of a tick. A notice that comes after T (a starved machine)
//! is followed as if at T, and the link switches at the next tick it flies: later, logged, the
//! same link.

use cdm_model::dynamics::{Flat, QuadState};
use cdm_model::formation::Member;
use cdm_model::step::{law_for, Law};

use super::{hear, phase_offset_s, stamp_s, Realtime};
use crate::member_core::{Action, MemberFault, Shared};
use crate::messages::{AgentStatus, LossNotice, StateMsg};
use crate::realtime_journal::{Switch, Switched};
use crate::seams::Vehicle;

impl Realtime {
    /// A clock message's loss notice (a repeat changes nothing).
    pub(super) fn on_notice<V: Vehicle>(&mut self, m: &mut Shared<V>, n: LossNotice) {
        // Flown past the notice's tick already: followed as if this member were at it, so the
        // repair is the one everyone computes; it applies at the next tick (`relink_if_due`).
        let at = m.tick.min(n.tick);
        let taken = match self.losses.as_mut() {
            Some(l) => l.on_notice(n, at).map_err(MemberFault::Loss),
            None => Err(MemberFault::RepairUnsupported { tick: m.tick }),
        };
        if let Err(fault) = taken {
            m.watch.defer(Action::Fail {
                report: None,
                fault,
            });
        }
    }

    /// A state of a member that is not an in-neighbour: kept when a repair makes it one (its
    /// last ticks within the stale bound: the links may hold the newest back).
    pub(super) fn keep_future_neighbor<V: Vehicle>(&mut self, m: &Shared<V>, msg: &StateMsg) {
        let Some(l) = self
            .losses
            .as_mut()
            .filter(|l| l.is_future_neighbor(msg.id, m.tick))
        else {
            return;
        };
        if msg.status() == AgentStatus::Ok && msg.scenario_hash == m.hash {
            let count = (self.stale_after.as_secs_f64() / self.dt_s).ceil() as u64 + 8;
            l.keep_last(msg.id, (msg.tick, QuadState(msg.state).flat()), count);
        }
    }

    /// Before flying tick `m.tick` (own time `t_own`): switches to the repaired link due at or
    /// before it, once every loss is linked and each new in-neighbour has a state this member's
    /// links deliver by `t_own`. A vehicle that cannot switch is a fault.
    pub(super) fn relink_if_due<V: Vehicle>(
        &mut self,
        m: &mut Shared<V>,
        t_own: f64,
    ) -> Option<Action> {
        let l = self.losses.as_deref()?;
        let (at, next) = l.upcoming()?;
        if at > m.tick {
            return None;
        }
        let start = self.start?;
        let (law, ids) = law_for(next);
        let heard = |j: u32| {
            let phase = phase_offset_s(start.seed, j, self.dt_s);
            l.kept_states(j).any(|(tick, _)| {
                let stamp = stamp_s(tick, phase, self.dt_s);
                self.links.delivered_by(j, tick, stamp, t_own)
            })
        };
        let follower = matches!(law, Law::Follower { .. });
        let unheard: Vec<u32> = (ids.iter().copied())
            .filter(|&j| follower && !m.neighbor_ids.contains(&j) && !heard(j))
            .collect();
        // A new in-neighbour lost since is never heard: a real-time repair applies a lead after
        // its loss was found, so a member lost just after (two lost at once) may be a new
        // in-neighbour of the repair before its own. Its own repair, scheduled next, replaces
        // this link, which is never flown.
        let reads_lost = unheard.iter().any(|&j| l.is_lost(j));
        let waits = l.waits_at(m.tick) || !unheard.is_empty();
        if reads_lost && self.losses.as_mut().is_some_and(|l| l.skip_upcoming()) {
            tracing::info!(id = m.id, tick = m.tick, at, lost = ?unheard, "a repaired link reads a member lost since: the next one replaces it");
            return self.relink_if_due(m, t_own);
        }
        if waits {
            if self.waited_at != Some(at) {
                self.waited_at = Some(at);
                tracing::debug!(id = m.id, tick = m.tick, at, "the repaired link waits");
            }
            return None;
        }
        let member = self.losses.as_mut()?.due(at)?;
        if m.vehicle.relink(&member).is_err() {
            let fault = MemberFault::RepairUnsupported { tick: m.tick };
            return Some(Action::Fail {
                report: None,
                fault,
            });
        }
        self.relink(m, &member);
        if let Some(j) = self.journal.as_mut() {
            let in_neighbors = member.link.map(|l| l.in_neighbors);
            j.switched(&Switch {
                tick: m.tick,
                what: Switched::Repair { at, in_neighbors },
            });
        }
        if at < m.tick {
            tracing::warn!(
                id = m.id,
                due = at,
                tick = m.tick,
                in_neighbors = ?m.neighbor_ids,
                "flying the repaired link late"
            );
        } else {
            tracing::info!(id = m.id, tick = m.tick, in_neighbors = ?m.neighbor_ids, "flying the repaired link");
        }
        None
    }

    /// Flies `member`'s link from now on: the in-neighbours kept stay with what was heard of
    /// them; each new one starts from the states kept of it, through its link.
    fn relink<V: Vehicle>(&mut self, m: &mut Shared<V>, member: &Member) {
        let (law, ids) = law_for(member);
        m.is_follower = matches!(law, Law::Follower { .. });
        let Some(start) = self.start.as_mut() else {
            return;
        };
        let (old_ids, old_heard, old_initial) = (m.neighbor_ids, self.heard, self.initial);
        let old_phase = start.neighbor_phase_s;
        let mut fresh = Vec::new();
        for (slot, &j) in ids.iter().enumerate() {
            if let Some(k) = old_ids.iter().position(|&o| o == j) {
                self.heard[slot] = old_heard[k];
                self.initial[slot] = old_initial[k];
                start.neighbor_phase_s[slot] = old_phase[k];
                continue;
            }
            let losses = self.losses.as_mut();
            let at_rest = losses.as_ref().and_then(|l| l.start_of(j));
            self.heard[slot] = None;
            self.initial[slot] = at_rest.map_or(old_initial[slot], Flat::rest);
            start.neighbor_phase_s[slot] = phase_offset_s(start.seed, j, self.dt_s);
            fresh.push((slot, losses.map(|l| l.take_kept(j)).unwrap_or_default()));
        }
        self.links.relink(ids);
        for (slot, kept) in fresh {
            for (tick, flat) in kept.upto(u64::MAX) {
                if let Some((tick, flat)) = self.links.receive(slot, tick, flat) {
                    hear(&mut self.heard[slot], tick, flat);
                }
            }
        }
        m.neighbor_ids = ids;
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use cdm_model::link::LinkModel;
    use cdm_model::step::TickAt;
    use cdm_records::loss_log::LossLog;
    use cdm_scenario::Scenario;

    use super::*;
    use crate::member_core::{subscriptions, Deadlines};
    use crate::member_loss::{LossFault, LossWork, MemberLosses};
    use crate::messages::{ClockMsg, PHASES_ALIGNED};
    use crate::realtime::{RealtimeCore, RealtimeSetup, STALE_AFTER};
    use crate::seams::{RelinkUnsupported, VehicleFault};

    const HASH: u64 = 0xfeed;
    const UNIX_START: u64 = 1_000_000_000_000;
    /// generated10: follower 9 reads [1, 6, 8]; losing 6 gives it [1, 3, 8].
    const ME: u32 = 9;

    /// A vehicle that records the ticks it flew and the links it was switched to, with the
    /// tick it flew next.
    #[derive(Debug, Default)]
    struct Relinked {
        flown: u64,
        links: Vec<(u64, Option<[u32; 3]>)>,
    }

    impl Vehicle for Relinked {
        fn state(&self) -> [f64; 12] {
            let mut x = [0.0; 12];
            x[6] = 9.81;
            x
        }

        fn fly_tick(&mut self, _: u64, _: &[Flat; 3]) -> Result<(), VehicleFault> {
            unreachable!("real time flies with fly_tick_at")
        }

        fn fly_tick_at(&mut self, at: TickAt, _: &[Flat; 3]) -> Result<(), VehicleFault> {
            self.flown = at.tick + 1;
            Ok(())
        }

        fn relink(&mut self, m: &Member) -> Result<(), RelinkUnsupported> {
            self.links
                .push((self.flown, m.link.map(|l| l.in_neighbors)));
            Ok(())
        }

        fn replan(&mut self, _: &cdm_model::plan::TeamPlan) -> Result<(), RelinkUnsupported> {
            Ok(())
        }
    }

    fn state(id: u32, tick: u64) -> StateMsg {
        let mut x = [0.0; 12];
        x[6] = 9.81;
        StateMsg::ok(tick, HASH, id, x)
    }

    /// A journal that keeps the switches.
    #[derive(Debug, Default, Clone)]
    struct Kept(std::sync::Arc<std::sync::Mutex<Vec<Switch>>>);

    impl crate::realtime_journal::Journal for Kept {
        fn flown(&mut self, _: &crate::realtime_journal::Flown) {}

        fn switched(&mut self, s: &Switch) {
            self.0.lock().expect("journal").push(*s);
        }
    }

    impl Kept {
        fn switches(&self) -> Vec<Switch> {
            self.0.lock().expect("journal").clone()
        }
    }

    /// Follower 9 of generated10 in real time with losses and steering, started at 1 s, aligned
    /// phases; its journal's switches.
    fn reader(s: &Scenario) -> (RealtimeCore<Relinked>, Kept) {
        let me = s.formation.member(ME).expect("member 9");
        let setup = RealtimeSetup {
            hash: HASH,
            last: 1000,
            dt_s: s.dt_s(),
            stale_after: STALE_AFTER,
            deadlines: Deadlines::default(),
            links: LinkModel::perfect(s.dt_s()),
        };
        let ins = subscriptions(me);
        let outs = s.formation.readers_of(ME);
        let losses = MemberLosses::new(me, LossLog::new(s), &ins, &outs);
        let at_rest = [cdm_math::Vec3::zeros(); 3];
        let kept = Kept::default();
        let steering = crate::member_steer::MemberSteering::new(s.steering(), s.file.comm_hz);
        let mut c = RealtimeCore::realtime(me, at_rest, setup, Relinked::default(), Duration::ZERO)
            .with_losses(losses)
            .with_steering(steering)
            .with_journal(Box::new(kept.clone()));
        let start = ClockMsg::realtime(UNIX_START + 1_000_000_000, HASH, PHASES_ALIGNED);
        assert_eq!(c.on_clock(&start, Duration::ZERO, UNIX_START), Ok(None));
        (c, kept)
    }

    /// The clock message with loss notice (seq, id, tick, linked).
    fn notice(seq: u32, id: u32, tick: u64, linked: u32) -> ClockMsg {
        let n = LossNotice {
            seq,
            id,
            tick,
            linked,
        };
        ClockMsg::realtime(UNIX_START + 1_000_000_000, HASH, PHASES_ALIGNED).with_loss(Some(n))
    }

    /// Hands `c` the clock message `m` (it does not end the flight).
    fn told(c: &mut RealtimeCore<Relinked>, m: ClockMsg) {
        assert_eq!(c.on_clock(&m, Duration::ZERO, 0), Ok(None));
    }

    /// Flies up to tick `to` (exclusive), `senders` publishing every tick; returns the port
    /// work asked for meanwhile.
    fn fly_to(c: &mut RealtimeCore<Relinked>, to: u64, senders: &[u32]) -> Vec<LossWork> {
        let mut work = Vec::new();
        while c.tick() < to {
            let k = c.tick();
            for &id in senders {
                c.on_neighbor(&state(id, k));
            }
            let now = Duration::from_secs_f64(1.0 + k as f64 * 0.01);
            loop {
                match c.poll(now) {
                    Action::Repair(w) => work.push(w),
                    Action::Publish(_) => {}
                    Action::CheckOrchestrator => c.on_orchestrator_alive(true),
                    Action::Poll => break,
                    a => panic!("tick {k}: {a:?}"),
                }
            }
        }
        work
    }

    #[test]
    fn a_reader_switches_at_the_notice_tick_once_its_new_neighbour_is_heard() {
        let s = Scenario::generated(10).expect("generated10");
        let (mut c, kept) = reader(&s);
        fly_to(&mut c, 10, &[1, 6, 8]);
        // Member 6 is lost: the repair applies from tick 20, linked at once.
        told(&mut c, notice(1, 6, 20, 0));
        let work = fly_to(&mut c, 12, &[1, 8]);
        let connect = LossWork::Connect {
            subscribe: vec![3],
            notify: vec![],
        };
        assert_eq!(work, [connect]);
        told(&mut c, notice(1, 6, 20, 1));
        // Its new in-neighbour 3 is heard from tick 15: flown from tick 20 exactly.
        let mut work = fly_to(&mut c, 15, &[1, 8]);
        assert!(c.m.vehicle.links.is_empty());
        work.extend(fly_to(&mut c, 25, &[1, 3, 8]));
        assert_eq!(work, [LossWork::HandOver]);
        assert_eq!(c.m.vehicle.links, [(20, Some([1, 3, 8]))]);
        assert_eq!(c.m.neighbor_ids, [1, 3, 8]);
        // The journal has the switch as applied, for a replay.
        assert_eq!(kept.switches(), [Switch::repaired(20, 20, [1, 3, 8])]);
    }

    #[test]
    fn a_notice_past_its_tick_or_an_unheard_neighbour_switches_at_the_next_tick_heard() {
        let s = Scenario::generated(10).expect("generated10");
        let (mut c, kept) = reader(&s);
        fly_to(&mut c, 30, &[1, 6, 8]);
        // A notice of tick 20 that arrives at 30 (a starved member): followed, not a fault.
        told(&mut c, notice(1, 6, 20, 1));
        // Until 3 is heard the old link flies on (6 brought forward from its last state).
        fly_to(&mut c, 33, &[1, 8]);
        assert!(c.m.vehicle.links.is_empty());
        fly_to(&mut c, 36, &[1, 3, 8]);
        assert_eq!(c.m.vehicle.links, [(33, Some([1, 3, 8]))]);
        assert_eq!(kept.switches(), [Switch::repaired(33, 20, [1, 3, 8])]);
        // A notice naming this member: it was declared lost, it stops.
        told(&mut c, notice(2, ME, 50, 1));
        match c.poll(Duration::from_secs_f64(1.36)) {
            Action::Fail { fault, .. } => {
                assert_eq!(fault, MemberFault::Loss(LossFault::SelfLost { tick: 36 }))
            }
            a => panic!("{a:?}"),
        }
    }

    #[test]
    fn a_command_taken_is_journaled_on_the_path_of_a_repair() {
        let s = Scenario::generated(10).expect("generated10");
        let (mut c, kept) = reader(&s);
        fly_to(&mut c, 12, &[1, 6, 8]);
        let n = crate::messages::SteerNotice::decided(1, 40, cdm_model::steer::TeamCommand::Hold);
        let m = ClockMsg::realtime(UNIX_START + 1_000_000_000, HASH, PHASES_ALIGNED)
            .with_steer(Some(n));
        told(&mut c, m);
        // A repeat of the notice is not taken again.
        told(&mut c, m);
        let taken = Switch {
            tick: 12,
            what: Switched::Command { seq: 1, at: 40 },
        };
        assert_eq!(kept.switches(), [taken]);
    }
}
