//! Losing a vehicle, as pure logic over a clock the caller drives: no HEARTBEAT for
//! [`HEARTBEAT_TIMEOUT`] or no LOCAL_POSITION_NED for [`POSITION_TIMEOUT`] is a fault naming the
//! member. Times are durations since the link started, read from the caller's clock.

use std::time::Duration;

/// No HEARTBEAT for this long: the vehicle is lost.
pub const HEARTBEAT_TIMEOUT: Duration = Duration::from_secs(1);
/// No LOCAL_POSITION_NED for this long: the member flies blind.
pub const POSITION_TIMEOUT: Duration = Duration::from_millis(500);

/// Why a member's vehicle link failed. Every variant names the member (by id).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LinkFault {
    /// Nothing usable (a HEARTBEAT and a position) arrived before the connect deadline.
    #[error("agent {agent}: no vehicle heard within {:.1} s (needs a HEARTBEAT and a LOCAL_POSITION_NED)", waited.as_secs_f64())]
    NeverHeard { agent: u32, waited: Duration },
    /// The vehicle's HEARTBEAT stopped.
    #[error(
        "agent {agent}: vehicle lost: no HEARTBEAT for {silent:?} (limit {HEARTBEAT_TIMEOUT:?})"
    )]
    HeartbeatLost { agent: u32, silent: Duration },
    /// The vehicle's LOCAL_POSITION_NED stopped.
    #[error("agent {agent}: vehicle lost: no LOCAL_POSITION_NED for {:.3} s (limit {:.1} s)", silent.as_secs_f64(), POSITION_TIMEOUT.as_secs_f64())]
    PositionLost { agent: u32, silent: Duration },
}

/// When the vehicle's HEARTBEAT and position were last heard, and the verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkHealth {
    agent: u32,
    connect_deadline: Duration,
    last_heartbeat: Option<Duration>,
    last_position: Option<Duration>,
}

impl LinkHealth {
    /// A link of member `agent` that must hear its vehicle (both a HEARTBEAT and a position)
    /// within `connect_deadline` of the clock's zero.
    pub fn new(agent: u32, connect_deadline: Duration) -> Self {
        LinkHealth {
            agent,
            connect_deadline,
            last_heartbeat: None,
            last_position: None,
        }
    }

    /// A HEARTBEAT arrived at `now`.
    pub fn on_heartbeat(&mut self, now: Duration) {
        self.last_heartbeat = Some(now);
    }

    /// A LOCAL_POSITION_NED arrived at `now`.
    pub fn on_position(&mut self, now: Duration) {
        self.last_position = Some(now);
    }

    /// Both a HEARTBEAT and a position have been heard.
    pub fn connected(&self) -> bool {
        self.last_heartbeat.is_some() && self.last_position.is_some()
    }

    /// The verdict at `now`: `Ok` while the link is healthy (or still within the connect
    /// deadline), the first fault otherwise. A timeout is exceeded strictly (`silent > limit`),
    /// so a vehicle exactly on its deadline is still alive.
    pub fn check(&self, now: Duration) -> Result<(), LinkFault> {
        let agent = self.agent;
        let (Some(hb), Some(pos)) = (self.last_heartbeat, self.last_position) else {
            return if now > self.connect_deadline {
                Err(LinkFault::NeverHeard {
                    agent,
                    waited: self.connect_deadline,
                })
            } else {
                Ok(())
            };
        };
        let hb_silent = now.saturating_sub(hb);
        let pos_silent = now.saturating_sub(pos);
        if hb_silent > HEARTBEAT_TIMEOUT {
            return Err(LinkFault::HeartbeatLost {
                agent,
                silent: hb_silent,
            });
        }
        if pos_silent > POSITION_TIMEOUT {
            return Err(LinkFault::PositionLost {
                agent,
                silent: pos_silent,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn heard_at(t: Duration) -> LinkHealth {
        let mut h = LinkHealth::new(7, ms(3000));
        h.on_heartbeat(t);
        h.on_position(t);
        h
    }

    #[test]
    fn waits_for_the_vehicle_until_the_connect_deadline() {
        let h = LinkHealth::new(7, ms(3000));
        assert_eq!(h.check(ms(3000)), Ok(()));
        assert_eq!(
            h.check(ms(3001)),
            Err(LinkFault::NeverHeard {
                agent: 7,
                waited: ms(3000)
            })
        );
    }

    #[test]
    fn a_heartbeat_alone_is_not_a_connection() {
        let mut h = LinkHealth::new(7, ms(100));
        h.on_heartbeat(ms(50));
        assert!(!h.connected());
        assert!(matches!(
            h.check(ms(101)),
            Err(LinkFault::NeverHeard { .. })
        ));
    }

    #[test]
    fn position_silence_is_named_after_half_a_second() {
        let mut h = heard_at(ms(1000));
        h.on_heartbeat(ms(1400));
        assert_eq!(h.check(ms(1500)), Ok(()));
        assert_eq!(
            h.check(ms(1501)),
            Err(LinkFault::PositionLost {
                agent: 7,
                silent: ms(501)
            })
        );
    }

    #[test]
    fn heartbeat_silence_is_named_after_one_second() {
        let mut h = heard_at(ms(1000));
        for t in (1020..=2020).step_by(20) {
            h.on_position(ms(t));
        }
        assert_eq!(h.check(ms(2000)), Ok(()));
        let fault = h.check(ms(2001)).unwrap_err();
        assert_eq!(
            fault,
            LinkFault::HeartbeatLost {
                agent: 7,
                silent: ms(1001)
            }
        );
        assert!(fault.to_string().starts_with("agent 7: vehicle lost"));
    }

    #[test]
    fn fresh_messages_keep_the_link_alive() {
        let mut h = heard_at(ms(0));
        for t in (0..10_000).step_by(100) {
            h.on_heartbeat(ms(t));
            h.on_position(ms(t));
            assert_eq!(h.check(ms(t + 99)), Ok(()));
        }
    }
}
