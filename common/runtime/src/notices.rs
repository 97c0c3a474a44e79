//! Following the orchestrator's loss notices, with no I/O: the one place that checks their
//! order and keeps the run's [`LossLog`] from them. The member ([`crate::member_loss`]), the
//! orchestrator's bridge and every host daemon follow the same notices through this type, so
//! they agree on the lost set (and so on the repaired graph, eq. 18's weights) and on what a
//! gap in the sequence means.
//!
//! Every clock message repeats the latest notice; the team announces a loss only after the
//! previous ones' links connected, and a relay forwards every clock message whose notice
//! changed. A notice number that jumps means a notice was missed, and the lost set (hence the
//! graph) would silently differ from everyone else's: it is an error, never skipped.

use cdm_records::loss_log::LossLog;

use crate::messages::LossNotice;

/// A notice number jumped: notices `seen + 1 ..= got - 1` were never seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("loss notices jumped from number {seen} to {got}: a notice was missed")]
pub struct NoticeGap {
    /// The last notice followed.
    pub seen: u32,
    /// The notice that arrived.
    pub got: u32,
}

/// What one notice changed.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct NoticeStep {
    /// A loss announced for the first time: (member, tick its repair applies from).
    pub lost: Option<(u32, u64)>,
    /// The count of losses whose links are all connected rose.
    pub linked: bool,
}

/// The losses announced so far, in order.
#[derive(Debug, Clone)]
pub struct Notices {
    log: LossLog,
    seen: u32,
    linked: u32,
}

impl Notices {
    /// No loss yet; `log` is the run's empty loss log.
    pub fn new(log: LossLog) -> Self {
        Self {
            log,
            seen: 0,
            linked: 0,
        }
    }

    /// True when `n` announces the next loss (not a repeat, not past a gap).
    pub fn is_next(&self, n: &LossNotice) -> bool {
        n.seq == self.seen + 1
    }

    /// Follows `n`. A repeat changes nothing; a jump is a [`NoticeGap`] and changes nothing.
    pub fn follow(&mut self, n: LossNotice) -> Result<NoticeStep, NoticeGap> {
        if n.seq > self.seen + 1 {
            return Err(NoticeGap {
                seen: self.seen,
                got: n.seq,
            });
        }
        let mut step = NoticeStep::default();
        if self.is_next(&n) {
            self.seen = n.seq;
            self.log.add(n.id, n.tick);
            step.lost = Some((n.id, n.tick));
        }
        if n.linked > self.linked {
            self.linked = n.linked;
            step.linked = true;
        }
        Ok(step)
    }

    /// True while a loss followed has links not all connected yet.
    pub fn unlinked(&self) -> bool {
        self.linked < self.seen
    }

    /// The run's losses as followed.
    pub fn log(&self) -> &LossLog {
        &self.log
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdm_scenario::Scenario;

    fn notice(seq: u32, id: u32, tick: u64, linked: u32) -> LossNotice {
        LossNotice {
            seq,
            id,
            tick,
            linked,
        }
    }

    fn follower() -> Notices {
        Notices::new(LossLog::new(&Scenario::builtin("paper40").unwrap()))
    }

    #[test]
    fn a_new_notice_is_a_loss_once_and_its_link_count_a_rise_once() {
        let mut f = follower();
        let first = f.follow(notice(1, 20, 30, 0)).unwrap();
        assert_eq!(first.lost, Some((20, 30)));
        assert!(!first.linked && f.unlinked());
        assert_eq!(f.follow(notice(1, 20, 30, 0)), Ok(NoticeStep::default()));
        let linked = f.follow(notice(1, 20, 30, 1)).unwrap();
        assert!(linked.linked && linked.lost.is_none() && !f.unlinked());
        assert_eq!(f.follow(notice(1, 20, 30, 1)), Ok(NoticeStep::default()));
        assert_eq!(f.log().losses(), &[(30, 20)]);
    }

    #[test]
    fn a_jump_in_the_numbers_is_a_gap_and_changes_nothing() {
        let mut f = follower();
        f.follow(notice(1, 20, 30, 1)).unwrap();
        assert_eq!(
            f.follow(notice(3, 22, 40, 1)),
            Err(NoticeGap { seen: 1, got: 3 })
        );
        assert_eq!(f.log().losses(), &[(30, 20)]);
        assert!(f.is_next(&notice(2, 21, 40, 1)));
        assert_eq!(f.follow(notice(2, 21, 40, 1)).unwrap().lost, Some((21, 40)));
    }

    #[test]
    fn several_losses_then_one_rise_links_them_all() {
        let mut f = follower();
        f.follow(notice(1, 20, 30, 0)).unwrap();
        f.follow(notice(2, 21, 30, 0)).unwrap();
        assert!(f.unlinked());
        assert!(f.follow(notice(2, 21, 30, 2)).unwrap().linked);
        assert!(!f.unlinked());
    }
}
