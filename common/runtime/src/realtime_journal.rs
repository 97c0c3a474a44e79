//! What a real-time member's flight depended on that the wall clock decided, as it flies: for
//! each tick, which state of each in-neighbour it flew on (the newest its links had delivered
//! by then) or that it had none; and the tick from which it flew each switch it applied (a
//! repaired link after a loss, a commanded plan). Everything else a tick computes is a pure
//! function of the scenario, the phase seed, the tick and the run's notices (`step::step_at` at
//! the member's own time `tick * dt + phi_i`, neighbours brought to it by
//! `step::extrapolate_flat`; the repair `cdm_model::repair` of the notices' losses), so these
//! choices are what a replay needs to fly the team again bit for bit (`realtime_replay.rs`).
//!
//! The core hands each flown tick and each switch to a [`Journal`]; where they go (a file,
//! memory) is the caller's: the core does no I/O.

/// One tick flown in real time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Flown {
    /// The tick flown.
    pub tick: u64,
    /// For each in-neighbour slot (the order of the law's weights), the tick of the state it
    /// flew on; `None`: none had arrived, it flew on the neighbour at rest where it starts.
    /// All `None` for a leader.
    pub used: [Option<u64>; 3],
}

/// A switch a real-time member applied in flight, from its tick `tick` on (before flying it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Switch {
    /// The first tick flown after the switch.
    pub tick: u64,
    pub what: Switched,
}

/// What a member switched to. A repair and a command take the same path: a notice on the clock
/// channel names the tick it applies from, and the member records the tick it applied it at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Switched {
    /// The repaired link the loss notices give from their tick `at` (the repair of every loss
    /// up to it): these in-neighbours in the order of the law (`None`: no triangle is left,
    /// the member flies its own plan). Applied at `at`, or later when the member was late.
    Repair {
        at: u64,
        in_neighbors: Option<[u32; 3]>,
    },
    /// Command notice `seq` taken: the commanded plan, which switches at the team's tick `at`
    /// (the same plan as the old one before it).
    Command { seq: u32, at: u64 },
}

/// Where a real-time member's flown ticks and switches go.
pub trait Journal: std::fmt::Debug + Send {
    /// Tick `f.tick` was flown, on the states `f.used`.
    fn flown(&mut self, f: &Flown);

    /// A switch, applied before tick `s.tick` is flown.
    fn switched(&mut self, s: &Switch);
}

#[cfg(test)]
impl Switch {
    /// The repaired link of tick `at` with in-neighbours `ins`, flown from `tick` (tests).
    pub(crate) fn repaired(tick: u64, at: u64, ins: [u32; 3]) -> Self {
        Switch {
            tick,
            what: Switched::Repair {
                at,
                in_neighbors: Some(ins),
            },
        }
    }
}
