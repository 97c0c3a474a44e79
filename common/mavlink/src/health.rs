//! Losing a vehicle, as pure logic over a clock the caller drives: no HEARTBEAT for
//! [`LinkTimeouts::heartbeat`] or no position ([`PositionStream`]: LOCAL_POSITION_NED indoors,
//! GLOBAL_POSITION_INT with an `[origin]`) for [`LinkTimeouts::position`] is a fault naming the
//! member and the message it waited for. Times are durations since the link started, read from the caller's
//! clock.
//!
//! Why these defaults. A HEARTBEAT comes once a second from PX4 and ArduPilot, so a limit of one
//! period declares a healthy vehicle lost on the first late packet. The MAVLink heartbeat
//! microservice (mavlink.io, "Heartbeat/Connection Protocol") leaves the number of missed
//! heartbeats to the channel and notes that components on telemetry links usually beat at 1 Hz
//! and treat four or five missed ones as a disconnection; ground stations and SDKs wait about
//! 3 to 5 s, and PX4's own data-link-loss failsafe waits `COM_DL_LOSS_T`, 10 s by default
//! (PX4 commander parameters). A member flies its vehicle in a formation, so it gives up sooner
//! than the autopilot: 3 s, three missed heartbeats. The position stream is what the member
//! flies on, so it is held to a few stream periods instead: PX4's onboard link streams
//! LOCAL_POSITION_NED at 30 Hz (PX4 `mavlink_main.cpp`, onboard mode), and 0.5 s is 15 of its
//! periods.

use std::time::Duration;

use crate::flight_mode::FlightMode;

/// `--heartbeat-timeout`'s default: three missed 1 Hz HEARTBEATs.
pub const DEFAULT_HEARTBEAT_TIMEOUT: Duration = Duration::from_secs(3);
/// `--position-timeout`'s default: 15 periods of PX4's 30 Hz LOCAL_POSITION_NED stream.
pub const DEFAULT_POSITION_TIMEOUT: Duration = Duration::from_millis(500);

/// The message a member flies on: what it waits for, and what a fault names.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum PositionStream {
    /// LOCAL_POSITION_NED: local NED about the vehicle's origin.
    #[default]
    LocalNed,
    /// GLOBAL_POSITION_INT: latitude, longitude and altitude through the scenario's `[origin]`.
    GlobalInt,
}

impl std::fmt::Display for PositionStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            PositionStream::LocalNed => "LOCAL_POSITION_NED",
            PositionStream::GlobalInt => "GLOBAL_POSITION_INT",
        })
    }
}

/// How long each of the vehicle's streams may be silent before the vehicle is lost.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkTimeouts {
    /// No HEARTBEAT for longer than this: lost (a multiple of the vehicle's 1 Hz beat).
    pub heartbeat: Duration,
    /// No position for longer than this: lost (a multiple of its stream period).
    pub position: Duration,
}

impl Default for LinkTimeouts {
    fn default() -> Self {
        LinkTimeouts {
            heartbeat: DEFAULT_HEARTBEAT_TIMEOUT,
            position: DEFAULT_POSITION_TIMEOUT,
        }
    }
}

/// Why a member's vehicle link failed. Every variant names the member (by id).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LinkFault {
    /// Nothing usable (a HEARTBEAT and a position) arrived before the connect deadline.
    #[error("agent {agent}: no vehicle heard within {:.1} s (needs a HEARTBEAT and a {stream})", waited.as_secs_f64())]
    NeverHeard {
        agent: u32,
        waited: Duration,
        stream: PositionStream,
    },
    /// The vehicle's HEARTBEAT stopped for longer than `limit` (`--heartbeat-timeout`).
    #[error("agent {agent}: vehicle lost: no HEARTBEAT for {:.3} s (limit {} s, --heartbeat-timeout)", silent.as_secs_f64(), limit.as_secs_f64())]
    HeartbeatLost {
        agent: u32,
        silent: Duration,
        limit: Duration,
    },
    /// The vehicle's position stream stopped for longer than `limit` (`--position-timeout`).
    #[error("agent {agent}: vehicle lost: no {stream} for {:.3} s (limit {} s, --position-timeout)", silent.as_secs_f64(), limit.as_secs_f64())]
    PositionLost {
        agent: u32,
        silent: Duration,
        limit: Duration,
        stream: PositionStream,
    },
    /// The vehicle's SYS_STATUS fell below `--min-battery` (`battery.rs`).
    #[error("agent {agent}: vehicle lost: battery at {pct} % (below --min-battery {min} %)")]
    BatteryLow { agent: u32, pct: u8, min: u8 },
    /// The autopilot's HEARTBEAT reports its own failsafe or worse (`battery.rs`).
    #[error("agent {agent}: vehicle lost: its autopilot reports {state}")]
    Failsafe { agent: u32, state: &'static str },
    /// After it was seen guided and armed, the vehicle's HEARTBEAT shows another mode: a pilot,
    /// a mode switch or the autopilot's failsafe took it (`takeover.rs`).
    #[error("agent {agent}: vehicle lost: it left {left}: now {now} (a pilot, a mode switch or its autopilot took it over); no more setpoints are sent to it")]
    LeftMode {
        agent: u32,
        /// "OFFBOARD" (PX4) or "GUIDED" (ArduPilot).
        left: &'static str,
        now: FlightMode,
    },
    /// After it was seen guided and armed, the vehicle's HEARTBEAT shows it disarmed
    /// (`takeover.rs`).
    #[error("agent {agent}: vehicle lost: disarmed in flight (in {mode}); no more setpoints are sent to it")]
    Disarmed { agent: u32, mode: FlightMode },
}

/// When the vehicle's HEARTBEAT and position were last heard, and the verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkHealth {
    agent: u32,
    connect_deadline: Duration,
    timeouts: LinkTimeouts,
    stream: PositionStream,
    last_heartbeat: Option<Duration>,
    last_position: Option<Duration>,
}

impl LinkHealth {
    /// A link of member `agent` that must hear its vehicle (both a HEARTBEAT and a position
    /// from `stream`) within `connect_deadline` of the clock's zero, and then keeps hearing it
    /// within `timeouts`.
    pub fn new(
        agent: u32,
        connect_deadline: Duration,
        timeouts: LinkTimeouts,
        stream: PositionStream,
    ) -> Self {
        LinkHealth {
            agent,
            connect_deadline,
            timeouts,
            stream,
            last_heartbeat: None,
            last_position: None,
        }
    }

    /// A HEARTBEAT arrived at `now`.
    pub fn on_heartbeat(&mut self, now: Duration) {
        self.last_heartbeat = Some(now);
    }

    /// A position (of the link's stream) arrived at `now`.
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
                    stream: self.stream,
                })
            } else {
                Ok(())
            };
        };
        let hb_silent = now.saturating_sub(hb);
        let pos_silent = now.saturating_sub(pos);
        let limits = self.timeouts;
        if hb_silent > limits.heartbeat {
            return Err(LinkFault::HeartbeatLost {
                agent,
                silent: hb_silent,
                limit: limits.heartbeat,
            });
        }
        if pos_silent > limits.position {
            return Err(LinkFault::PositionLost {
                agent,
                silent: pos_silent,
                limit: limits.position,
                stream: self.stream,
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

    fn link() -> LinkHealth {
        LinkHealth::new(
            7,
            ms(3000),
            LinkTimeouts::default(),
            PositionStream::LocalNed,
        )
    }

    fn heard_at(t: Duration) -> LinkHealth {
        let mut h = link();
        h.on_heartbeat(t);
        h.on_position(t);
        h
    }

    /// Arrival times (ms) of a stream with `period_ms`, each packet up to `jitter_ms` late, one
    /// in 16 a further `late_ms` late and one in 16 duplicated, from `from_ms` to `until_ms`:
    /// what a vehicle's scheduler and a UDP link do to a nominal rate. Seeded, so reproducible.
    fn stream(
        period_ms: u64,
        jitter_ms: u64,
        late_ms: u64,
        from_ms: u64,
        until_ms: u64,
    ) -> Vec<u64> {
        let mut seed: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut next = || {
            // xorshift64: deterministic and good enough for jitter.
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let mut out = Vec::new();
        for nominal in (from_ms..until_ms).step_by(period_ms as usize) {
            let r = next();
            let mut t = nominal + r % (jitter_ms + 1);
            if (r >> 20) % 16 == 0 {
                t += late_ms;
            }
            out.push(t);
            if (r >> 30) % 16 == 0 {
                out.push(t);
            }
        }
        out.sort_unstable();
        out
    }

    /// Feeds the heartbeat and position arrivals in time order and checks the link every
    /// 10 ms up to `until_ms`; returns the first fault and when it was raised.
    fn replay(
        mut h: LinkHealth,
        beats: &[u64],
        positions: &[u64],
        until_ms: u64,
    ) -> Option<(u64, LinkFault)> {
        let (mut b, mut p) = (0, 0);
        for now in (0..=until_ms).step_by(10) {
            while b < beats.len() && beats[b] <= now {
                h.on_heartbeat(ms(beats[b]));
                b += 1;
            }
            while p < positions.len() && positions[p] <= now {
                h.on_position(ms(positions[p]));
                p += 1;
            }
            if let Err(f) = h.check(ms(now)) {
                return Some((now, f));
            }
        }
        None
    }

    #[test]
    fn waits_for_the_vehicle_until_the_connect_deadline() {
        let h = link();
        assert_eq!(h.check(ms(3000)), Ok(()));
        assert_eq!(
            h.check(ms(3001)),
            Err(LinkFault::NeverHeard {
                agent: 7,
                waited: ms(3000),
                stream: PositionStream::LocalNed
            })
        );
    }

    #[test]
    fn a_heartbeat_alone_is_not_a_connection() {
        let mut h = LinkHealth::new(
            7,
            ms(100),
            LinkTimeouts::default(),
            PositionStream::LocalNed,
        );
        h.on_heartbeat(ms(50));
        assert!(!h.connected());
        assert!(matches!(
            h.check(ms(101)),
            Err(LinkFault::NeverHeard { .. })
        ));
    }

    #[test]
    fn a_1_hz_heartbeat_with_jitter_is_never_lost() {
        // PX4's and ArduPilot's default: HEARTBEAT at 1 Hz, here up to 150 ms late, one in 16
        // a further 800 ms late (1.95 s between two beats), some duplicated; positions at
        // PX4's 30 Hz onboard rate with 10 ms of jitter and an occasional 100 ms hiccup.
        let beats = stream(1000, 150, 800, 0, 120_000);
        let positions = stream(33, 10, 100, 0, 120_000);
        assert!(beats.windows(2).any(|w| w[1] - w[0] > 1500), "{beats:?}");
        assert_eq!(replay(link(), &beats, &positions, 120_000), None);
        // The one-period limit this replaces declared this healthy vehicle lost.
        let strict = LinkTimeouts {
            heartbeat: ms(1000),
            ..LinkTimeouts::default()
        };
        let lost = replay(
            LinkHealth::new(7, ms(3000), strict, PositionStream::LocalNed),
            &beats,
            &positions,
            120_000,
        );
        assert!(
            matches!(lost, Some((_, LinkFault::HeartbeatLost { .. }))),
            "{lost:?}"
        );
    }

    #[test]
    fn three_seconds_without_a_heartbeat_is_a_loss() {
        let beats = stream(1000, 150, 0, 0, 10_000);
        let last = *beats.last().unwrap_or(&0);
        let positions = stream(33, 10, 0, 0, 30_000);
        let (at, fault) = replay(link(), &beats, &positions, 30_000).expect("lost");
        // Named on the first check past the limit (checks every 10 ms).
        assert!(at > last + 3000 && at <= last + 3010, "{at} vs {last}");
        assert_eq!(
            fault,
            LinkFault::HeartbeatLost {
                agent: 7,
                silent: ms(at - last),
                limit: DEFAULT_HEARTBEAT_TIMEOUT
            }
        );
        assert!(fault
            .to_string()
            .starts_with("agent 7: vehicle lost: no HEARTBEAT for 3.0"));
        assert!(
            fault
                .to_string()
                .contains("(limit 3 s, --heartbeat-timeout)"),
            "{fault}"
        );
    }

    #[test]
    fn half_a_second_without_a_position_is_a_loss() {
        let beats = stream(1000, 150, 800, 0, 30_000);
        let positions = stream(33, 10, 100, 0, 5_000);
        let last = *positions.last().unwrap_or(&0);
        let (at, fault) = replay(link(), &beats, &positions, 30_000).expect("lost");
        assert!(at > last + 500 && at <= last + 510, "{at} vs {last}");
        assert_eq!(
            fault,
            LinkFault::PositionLost {
                agent: 7,
                silent: ms(at - last),
                limit: DEFAULT_POSITION_TIMEOUT,
                stream: PositionStream::LocalNed
            }
        );
        assert!(
            fault
                .to_string()
                .contains("(limit 0.5 s, --position-timeout)"),
            "{fault}"
        );
    }

    #[test]
    fn the_limits_are_the_callers_and_exceeded_strictly() {
        let timeouts = LinkTimeouts {
            heartbeat: ms(5000),
            position: ms(250),
        };
        let mut h = LinkHealth::new(7, ms(3000), timeouts, PositionStream::GlobalInt);
        h.on_heartbeat(ms(1000));
        h.on_position(ms(1000));
        assert_eq!(h.check(ms(1250)), Ok(()));
        let lost = h.check(ms(1251));
        assert!(matches!(
            lost,
            Err(LinkFault::PositionLost { limit, .. }) if limit == ms(250)
        ));
        // A vehicle flown in global coordinates is lost for want of the message it sends.
        let said = lost.map_err(|e| e.to_string()).unwrap_err();
        assert!(said.contains("no GLOBAL_POSITION_INT for"), "{said}");
        for t in (1000..=6000).step_by(20) {
            h.on_position(ms(t));
        }
        assert_eq!(h.check(ms(6000)), Ok(()));
        assert_eq!(
            h.check(ms(6001)),
            Err(LinkFault::HeartbeatLost {
                agent: 7,
                silent: ms(5001),
                limit: ms(5000)
            })
        );
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
