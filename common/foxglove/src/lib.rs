//! FoxgloveLive Foxglove: `launch --foxglove [ADDR]` serves the team, while it flies, over the Foxglove
//! WebSocket protocol with Foxglove's own SDK (the `foxglove` crate), and `view RUN_DIR
//! --foxglove` plays a finished run the same way. The topics carry what the run's ROS 2 bag
//! carries (cdm-rosbag's per-tick content: the formation's markers, the margins), in Foxglove's
//! well-known schemas so its 3-D, Plot and Raw panels need no configuration:
//!
//! - `/cdm/agent_<id>/pose` (`foxglove.PoseInFrame`, frame `world`): each member's position;
//! - `/tf` (`foxglove.FrameTransforms`): a frame `agent_<id>` per member, parent `world`;
//! - `/cdm/formation` (`foxglove.SceneUpdate`): the bag's markers as scene entities (a sphere per
//!   member, the leading polygon, the geofence and the obstacles);
//! - `/cdm/audit` (JSON): the tick's margins, as the bag's `/cdm/audit` holds them;
//! - `/cdm/verdict` (JSON): the run's verdict so far, and the final one;
//! - `/cdm/events` (`foxglove.Log`): a member's loss as it happens.
//!
//! Timestamps are simulation time (tick x dt) and the server advertises it as the clock
//! (the protocol's `time` capability), so Foxglove's timeline is the run's.
//!
//! `scene.rs` turns one tick into those messages (pure); `live.rs` is the rate-limited, dropping
//! publisher on a thread of its own (the launch loop never waits on it); `replay.rs` plays a
//! finished run. The server needs the `live` feature; without it `--foxglove` is refused.

#[cfg(feature = "live")]
mod live;
#[cfg(feature = "live")]
mod replay;
#[cfg(feature = "live")]
pub mod scene;

#[cfg(feature = "live")]
pub use live::FoxgloveLive;
#[cfg(feature = "live")]
pub use replay::replay;

use std::net::SocketAddr;

/// Where `--foxglove` listens when no address is given: Foxglove's default port, loopback only.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";

/// `--foxglove-hz` when not given.
pub const DEFAULT_HZ: f64 = 30.0;

/// `--foxglove` and `--foxglove-hz`, validated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FoxgloveOptions {
    pub addr: SocketAddr,
    /// Ticks published per second of wall time, at most.
    pub hz: f64,
}

impl FoxgloveOptions {
    /// From the flags' text: ADDR is `HOST:PORT` or a bare `PORT` on 127.0.0.1; `hz` in
    /// (0, 1000].
    pub fn parse(addr: &str, hz: Option<f64>) -> Result<Self, FoxgloveError> {
        let addr = match addr.parse::<u16>() {
            Ok(port) => SocketAddr::from(([127, 0, 0, 1], port)),
            Err(_) => addr.parse().map_err(|_| FoxgloveError::Addr {
                text: addr.to_owned(),
            })?,
        };
        let hz = hz.unwrap_or(DEFAULT_HZ);
        if !(hz.is_finite() && hz > 0.0 && hz <= 1000.0) {
            return Err(FoxgloveError::Hz { hz });
        }
        Ok(FoxgloveOptions { addr, hz })
    }
}

/// Why the Foxglove server could not start or play.
#[derive(Debug, thiserror::Error)]
pub enum FoxgloveError {
    /// `--foxglove ADDR` is not an address.
    #[error("--foxglove {text}: expected HOST:PORT (e.g. 127.0.0.1:8765) or a port number")]
    Addr { text: String },
    /// `--foxglove-hz` out of range.
    #[error("--foxglove-hz must be in (0, 1000], got {hz}")]
    Hz { hz: f64 },
    /// The address is taken or not ours to bind.
    #[error("--foxglove {addr}: cannot listen: {source}")]
    Bind {
        addr: SocketAddr,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A topic could not be declared.
    #[error("--foxglove: cannot declare {topic}: {reason}")]
    Channel { topic: String, reason: String },
    /// This build has no server.
    #[error("--foxglove: this orchestrator was built without it (cargo feature foxglove)")]
    NotBuilt,
    /// The publishing thread could not be started.
    #[error("--foxglove: cannot start the publishing thread: {0}")]
    Thread(#[source] std::io::Error),
    /// A finished run could not be read back (`view --foxglove`).
    #[error("{0}")]
    Run(String),
}

/// What the server did over a run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FoxgloveSummary {
    /// Where it listened.
    pub addr: SocketAddr,
    /// Ticks whose messages went out.
    pub ticks: u64,
    /// Ticks the rate let through but the queue had no room for.
    pub dropped: u64,
    /// The thread was still publishing when `finish` stopped waiting.
    pub unfinished: bool,
}

/// Without the server: `--foxglove` is bad input (exit 2), naming the feature.
#[cfg(not(feature = "live"))]
pub struct FoxgloveLive;

#[cfg(not(feature = "live"))]
impl FoxgloveLive {
    pub fn start(_o: &FoxgloveOptions, _s: &cdm_scenario::Scenario) -> Result<Self, FoxgloveError> {
        Err(FoxgloveError::NotBuilt)
    }
    pub fn addr(&self) -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], 0))
    }
    pub fn tick(
        &mut self,
        _tick: u64,
        _t_s: f64,
        _positions: (&[cdm_math::Vec3], &[cdm_math::Vec3]),
        _flying: impl Fn(usize) -> bool,
        _verdict: cdm_model::outcome::Verdict,
    ) {
    }
    pub fn finish(self, _verdict: cdm_model::outcome::Verdict) -> FoxgloveSummary {
        FoxgloveSummary {
            addr: self.addr(),
            ticks: 0,
            dropped: 0,
            unfinished: false,
        }
    }
}

/// Without the server: `view --foxglove` is bad input (exit 2), naming the feature.
#[cfg(not(feature = "live"))]
pub fn replay(
    _dir: &std::path::Path,
    _o: &FoxgloveOptions,
    _stop: &std::sync::atomic::AtomicBool,
    _on_listening: impl FnOnce(SocketAddr),
) -> Result<FoxgloveSummary, FoxgloveError> {
    Err(FoxgloveError::NotBuilt)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_and_rates_are_checked_and_name_their_flag() {
        let o = FoxgloveOptions::parse(DEFAULT_ADDR, None).unwrap();
        assert_eq!((o.addr.port(), o.hz), (8765, DEFAULT_HZ));
        assert!(o.addr.ip().is_loopback());
        let o = FoxgloveOptions::parse("9000", Some(5.0)).unwrap();
        assert_eq!(o.addr, SocketAddr::from(([127, 0, 0, 1], 9000)));
        let e = FoxgloveOptions::parse("localhost", None).unwrap_err();
        assert!(e.to_string().contains("--foxglove localhost"), "{e}");
        for hz in [0.0, -1.0, f64::NAN, 1001.0] {
            let e = FoxgloveOptions::parse("9000", Some(hz)).unwrap_err();
            assert!(e.to_string().contains("--foxglove-hz"), "{e}");
        }
    }
}
