//! What a real-time member's flight depended on that the wall clock decided, as it flies: for
//! each tick, which state of each in-neighbour it flew on (the newest its links had delivered
//! by then) or that it had none. Everything else a tick computes is a pure function of the
//! scenario, the phase seed and the tick (`step::step_at` at the member's own time
//! `tick * dt + phi_i`, neighbours brought to it by `step::extrapolate_flat`), so these choices
//! are what a replay needs to fly the team again bit for bit (`realtime_replay.rs`).
//!
//! The core hands each flown tick to a [`Journal`]; where it goes (a file, memory) is the
//! caller's: the core does no I/O.

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

/// Where a real-time member's flown ticks go.
pub trait Journal: std::fmt::Debug + Send {
    /// Tick `f.tick` was flown, on the states `f.used`.
    fn flown(&mut self, f: &Flown);

    /// A command to the team became final for this member: from tick `n.tick` on it flies the
    /// commanded plan (`cdm_model::steer`, made from the notice alone, as the orchestrator
    /// made it). The default keeps nothing: a journal that does not record commands cannot
    /// replay a commanded flight.
    fn steered(&mut self, n: &crate::messages::SteerNotice) {
        let _ = n;
    }
}
