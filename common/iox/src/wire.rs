//! The runtime's wire messages as iceoryx2 payloads. cdm-runtime keeps [`StateMsg`] and
//! [`ClockMsg`] plain `#[repr(C)]` types that do not name iceoryx2; the orphan rule forbids
//! implementing iceoryx2's trait on them here, so each travels in a `#[repr(transparent)]`
//! [`Wire`] (same layout, same bytes) that carries `ZeroCopySend` and a stable type name.
//!
//! The type names are part of the wire contract: iceoryx2 refuses to connect ports whose payload
//! names differ, and programs in other languages open these services by these names.
//!
//! A state service carries a [`StateBatch`]: up to [`STATES_PER_SAMPLE`] consecutive states of
//! one member per iceoryx2 sample. A member runs several ticks per wake-up and wakes its readers
//! only before it sleeps, so the states of one run travel together; iceoryx2's cost is per
//! sample (about 0.25 us per publish or receive on the development VM, as much as one member's
//! arithmetic of a tick), so a batch pays it once for up to four ticks.

use iceoryx2::prelude::ZeroCopySend;

use crate::messages::{ClockMsg, StateMsg};

/// iceoryx2's type name of [`StateMsg`] on `cdm/<team>/state/<id>`.
pub const STATE_TYPE_NAME: &str = "cdm::State";
/// iceoryx2's type name of [`StateBatch`] on `cdm/<team>/state/<id>`.
pub const STATE_BATCH_TYPE_NAME: &str = "cdm::StateBatch";
/// iceoryx2's type name of [`ClockMsg`] on `cdm/<team>/clock`.
pub const CLOCK_TYPE_NAME: &str = "cdm::Clock";

/// A wire message in shared memory: the runtime's type with the layout unchanged.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(transparent)]
pub struct Wire<T>(pub T);

/// One [`StateMsg`] as a payload of its own (`cdm-bench barrier`'s bare services).
pub type StateWire = Wire<StateMsg>;
/// The payload of a team's state service (`cdm/<team>/state/<id>`).
pub type StateBatchWire = Wire<StateBatch>;
/// The payload of the clock service.
pub type ClockWire = Wire<ClockMsg>;

/// The most states one sample of a state service carries. Every sample is this large (iceoryx2
/// slots have one size), so the state services' shared memory, and the memory a process touches
/// reading them, grows with it. Measured at N = 40 (CPU per tick) and N = 250 (peak memory)
/// against one state per sample: 4 saves 28-30 % of the team's CPU per tick, 8 saved only 17 %
/// (larger chunks stay out of the cache). Since the state services keep no history
/// (`resend.rs`), 4 costs the largest member at N = 250 about 0.2 MiB, which the 8 MiB budget
/// just allows. BENCHMARKS.md, "Several ticks per sample, session 7".
pub const STATES_PER_SAMPLE: usize = 4;

/// Consecutive states of one member, oldest first: `states[..len]` (the rest is unused). The
/// reader takes them in order, so a batch is exactly the samples it replaces, sent at once.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct StateBatch {
    /// How many of `states` are used (1 to [`STATES_PER_SAMPLE`] in a sent sample).
    pub len: u32,
    /// [`StateBatch::RESENT`] for states sent again at a repair's hand-over (`resend.rs`), else 0.
    pub flags: u32,
    /// The states, oldest first.
    pub states: [StateMsg; STATES_PER_SAMPLE],
}

impl StateBatch {
    /// [`Self::flags`] of a batch of states sent again at a hand-over: a new reader takes them
    /// before the states it received since it subscribed (`resend.rs`).
    pub const RESENT: u32 = 1;

    /// A batch with no state.
    pub const EMPTY: StateBatch = StateBatch {
        len: 0,
        flags: 0,
        states: [StateMsg {
            tick: 0,
            scenario_hash: 0,
            id: 0,
            status: 0,
            fault_code: 0,
            fault_peer: 0,
            state: [0.0; 12],
        }; STATES_PER_SAMPLE],
    };

    /// Appends `msg`; true when the batch is now full (send it before the next push).
    pub fn push(&mut self, msg: StateMsg) -> bool {
        let at = self.states().len();
        if let Some(slot) = self.states.get_mut(at) {
            *slot = msg;
            self.len = at as u32 + 1;
        }
        self.is_full()
    }

    /// The states carried, oldest first. A `len` beyond the array (a corrupt or foreign sample)
    /// reads as the whole array, never past it.
    pub fn states(&self) -> &[StateMsg] {
        let len = (self.len as usize).min(STATES_PER_SAMPLE);
        &self.states[..len]
    }

    /// True when no state is carried.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// True when no further state fits.
    pub fn is_full(&self) -> bool {
        self.len as usize >= STATES_PER_SAMPLE
    }

    /// Forgets every state (after sending them).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Writes the length, `flags` and `states` (at most [`STATES_PER_SAMPLE`]) into the batch at `dst`
    /// without touching its unused slots: a sample's cost stays with the states it carries
    /// (a sample is 520 bytes; a run of one state writes 136 of them).
    ///
    /// # Safety
    /// `dst` must be valid for writes of a `StateBatch`, aligned, and its bytes initialized
    /// memory (a chunk of a shared-memory segment: the kernel zero-fills it and earlier samples
    /// only ever wrote whole values into it), so the unused slots hold plain old bytes.
    pub(crate) unsafe fn write_prefix(dst: *mut StateBatch, states: &[StateMsg], flags: u32) {
        let len = states.len().min(STATES_PER_SAMPLE);
        // SAFETY: in bounds of `*dst` by the caller's contract; `len` fits the array.
        unsafe {
            core::ptr::addr_of_mut!((*dst).len).write(len as u32);
            core::ptr::addr_of_mut!((*dst).flags).write(flags);
            let slots = core::ptr::addr_of_mut!((*dst).states).cast::<StateMsg>();
            core::ptr::copy_nonoverlapping(states.as_ptr(), slots, len);
        }
    }
}

// The sizes other languages mirror; a field added to a message must fail here first.
const _: () = assert!(core::mem::size_of::<StateMsg>() == 128);
const _: () = assert!(core::mem::size_of::<StateBatch>() == 8 + 128 * STATES_PER_SAMPLE);
const _: () = assert!(core::mem::size_of::<ClockMsg>() == 144);

// SAFETY: `StateMsg` is `#[repr(C)]` with only `u64`, `u32` and `[f64; 12]` fields (no pointers,
// no references, no heap), so its bytes mean the same in every process that maps them; `Wire` is
// `#[repr(transparent)]` over it.
unsafe impl ZeroCopySend for Wire<StateMsg> {
    unsafe fn type_name() -> &'static str {
        STATE_TYPE_NAME
    }
}

// SAFETY: `StateBatch` is `#[repr(C)]` with only `u32` fields and an array of `StateMsg` (see
// above); as above.
unsafe impl ZeroCopySend for Wire<StateBatch> {
    unsafe fn type_name() -> &'static str {
        STATE_BATCH_TYPE_NAME
    }
}

// SAFETY: `ClockMsg` is `#[repr(C)]` with only `u64`, `u32`, `f64` and `[f64; 9]` fields; as above.
unsafe impl ZeroCopySend for Wire<ClockMsg> {
    unsafe fn type_name() -> &'static str {
        CLOCK_TYPE_NAME
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn type_names_are_stable() {
        // SAFETY: reading a name has no precondition; the trait marks it unsafe for implementers.
        unsafe {
            assert_eq!(<StateWire as ZeroCopySend>::type_name(), "cdm::State");
            assert_eq!(<ClockWire as ZeroCopySend>::type_name(), "cdm::Clock");
            assert_eq!(
                <StateBatchWire as ZeroCopySend>::type_name(),
                "cdm::StateBatch"
            );
        }
    }

    #[test]
    fn a_batch_keeps_its_states_in_order_up_to_its_size() {
        let mut b = StateBatch::EMPTY;
        assert!(b.is_empty() && b.states().is_empty());
        for tick in 0..STATES_PER_SAMPLE as u64 {
            let full = b.push(StateMsg::ok(tick, 1, 7, [tick as f64; 12]));
            assert_eq!(full, tick + 1 == STATES_PER_SAMPLE as u64);
        }
        let ticks: Vec<u64> = b.states().iter().map(|m| m.tick).collect();
        assert_eq!(ticks, (0..STATES_PER_SAMPLE as u64).collect::<Vec<_>>());
        // A push into a full batch is refused, not written past the array.
        assert!(b.push(StateMsg::ok(99, 1, 7, [0.0; 12])));
        assert_eq!(b.states().len(), STATES_PER_SAMPLE);
        assert_eq!(
            b.states()[STATES_PER_SAMPLE - 1].tick,
            STATES_PER_SAMPLE as u64 - 1
        );
        b.clear();
        assert!(b.is_empty());
        // A corrupt length reads as the whole array, never past it.
        let odd = StateBatch {
            len: 1000,
            ..StateBatch::EMPTY
        };
        assert_eq!(odd.states().len(), STATES_PER_SAMPLE);
    }

    #[test]
    fn writing_a_prefix_leaves_the_unused_slots_alone() {
        let old = StateMsg::ok(1, 2, 3, [4.0; 12]);
        let mut b = StateBatch {
            len: 5,
            flags: 9,
            states: [old; STATES_PER_SAMPLE],
        };
        let new = [
            StateMsg::ok(7, 2, 3, [8.0; 12]),
            StateMsg::ok(8, 2, 3, [9.0; 12]),
        ];
        // SAFETY: `b` is a whole, initialized batch.
        unsafe { StateBatch::write_prefix(&mut b, &new, StateBatch::RESENT) };
        assert_eq!((b.len, b.flags), (2, StateBatch::RESENT));
        assert_eq!(b.states(), &new);
        assert!(b.states[2..].iter().all(|m| *m == old));
    }
}
