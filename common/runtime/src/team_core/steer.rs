//! The team core's side of the commands to a team in flight: each accepted command is announced
//! on the clock channel before any member may step into its switch tick, as a loss notice is
//! (`losses.rs`). In lockstep the grants stop at the tick before the next command's switch
//! until its notice is out: a member steps from tick k only with tick k + 1 granted, so no
//! member flies past the switch on the old plan. Every later clock message repeats the latest
//! notice; members read every clock message, and a jump in the sequence is their fault.

use std::collections::VecDeque;

use super::{Pacing, TeamAction, TeamCore, TeamState};
use crate::messages::SteerNotice;

/// The commands of a run as the team core handles them.
#[derive(Debug, Default)]
pub(super) struct SteerEvents {
    /// Accepted commands not announced yet, in switch order.
    pending: VecDeque<SteerNotice>,
    /// The latest announced.
    latest: Option<SteerNotice>,
}

impl SteerEvents {
    /// The highest tick that may be granted before the next notice is out (`last` without one).
    pub(super) fn cap(&self, last: u64) -> u64 {
        self.pending
            .front()
            .map_or(last, |n| n.tick.saturating_sub(1).min(last))
    }
}

impl TeamCore {
    /// The same core announcing these accepted commands (ascending switch ticks, numbered from
    /// 1 in order) ahead of their switch.
    pub fn with_commands(mut self, notices: Vec<SteerNotice>) -> Self {
        self.t.steer.pending = notices.into();
        if let Pacing::Lockstep(g) = &mut self.pacing {
            let cap = self.t.steer.cap(u64::MAX);
            g.cap_first_grant_at(cap);
        }
        self
    }

    /// Announce `notice` too: an accepted command (its sequence number the next, its switch
    /// after every tick granted so far) and the flight's new last tick.
    pub fn command(&mut self, notice: SteerNotice, last_tick: u64) {
        self.t.steer.pending.push_back(notice);
        if let Pacing::Lockstep(g) = &mut self.pacing {
            g.set_last_tick(last_tick);
        }
    }

    /// The latest command announced (every clock message repeats it).
    pub fn steer_notice(&self) -> Option<SteerNotice> {
        self.t.steer.latest
    }

    /// True while a command is accepted but not announced yet.
    pub fn announcing(&self) -> bool {
        !self.t.steer.pending.is_empty()
    }
}

impl TeamState {
    /// The next notice to announce, once the grants reached the tick before its switch.
    pub(super) fn steer_action(&mut self, granted: u64) -> Option<TeamAction> {
        let s = &mut self.steer;
        if s.cap(u64::MAX) > granted {
            return None;
        }
        let n = s.pending.pop_front()?;
        s.latest = Some(n);
        Some(TeamAction::Steer(n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::StateMsg;
    use crate::team_core::TeamConfig;
    use cdm_model::steer::TeamCommand;
    use std::time::Duration;

    fn ms(t: u64) -> Duration {
        Duration::from_millis(t)
    }

    fn notice(seq: u32, tick: u64) -> SteerNotice {
        SteerNotice {
            seq,
            tick,
            command: Some(TeamCommand::Hold),
        }
    }

    /// The actions of one turn at `now`, up to a wait or a poll.
    fn turn(c: &mut TeamCore, now: Duration) -> Vec<TeamAction> {
        c.on_turn(now);
        let mut out = Vec::new();
        loop {
            let a = c.next_action(now);
            if let TeamAction::Complete { states, .. } = &a {
                c.recycle(states.clone());
            }
            let end = matches!(
                a,
                TeamAction::Wait(_) | TeamAction::Poll | TeamAction::Finished
            );
            out.push(a);
            if end {
                return out;
            }
        }
    }

    fn send(c: &mut TeamCore, ids: &[u32], ticks: std::ops::RangeInclusive<u64>) {
        for tick in ticks {
            for &id in ids {
                c.on_state(&StateMsg::ok(tick, 7, id, [0.0; 12]), ms(0));
            }
        }
    }

    #[test]
    fn grants_stop_before_a_switch_until_its_notice_is_out_and_then_go_on() {
        let ids = [1, 2, 3];
        let cfg = TeamConfig {
            ids: ids.to_vec(),
            window: 8,
            last_tick: 40,
            agent_timeout: Duration::from_secs(10),
        };
        let mut c = TeamCore::lockstep(cfg, ms(0)).with_commands(vec![notice(1, 5), notice(2, 6)]);
        let a = turn(&mut c, ms(1));
        // The first grant stops at tick 4; notice 1 goes out at once, then the grants go on
        // up to the tick before notice 2's switch, and it goes out: each notice in a message
        // of its own, before any grant past the tick before its switch.
        assert_eq!(a[0], TeamAction::Grant(4));
        assert_eq!(a[1], TeamAction::Steer(notice(1, 5)));
        assert_eq!(a[2], TeamAction::Grant(5));
        assert_eq!(a[3], TeamAction::Steer(notice(2, 6)));
        assert_eq!(c.steer_notice(), Some(notice(2, 6)));
        send(&mut c, &ids, 0..=4);
        let a = turn(&mut c, ms(2));
        assert!(a.contains(&TeamAction::Grant(12)), "{a:?}");
        // A live command: announced once the grants reach the tick before it.
        c.command(notice(3, 20), 30);
        send(&mut c, &ids, 5..=12);
        let a = turn(&mut c, ms(3));
        let grants: Vec<&TeamAction> = a
            .iter()
            .filter(|x| matches!(x, TeamAction::Grant(_) | TeamAction::Steer(_)))
            .collect();
        assert_eq!(
            grants,
            [&TeamAction::Grant(19), &TeamAction::Steer(notice(3, 20))]
        );
        // The new last tick ends the flight there.
        let mut a = Vec::new();
        for (k, ticks) in [13..=19, 20..=27, 28..=30].into_iter().enumerate() {
            send(&mut c, &ids, ticks);
            a = turn(&mut c, ms(4 + k as u64));
        }
        assert_eq!(a.last(), Some(&TeamAction::Finished), "{a:?}");
    }
}
