//! The runtime's wire messages as iceoryx2 payloads. cdm-runtime keeps [`StateMsg`] and
//! [`ClockMsg`] plain `#[repr(C)]` types that do not name iceoryx2; the orphan rule forbids
//! implementing iceoryx2's trait on them here, so each travels in a `#[repr(transparent)]`
//! [`Wire`] (same layout, same bytes) that carries `ZeroCopySend` and a stable type name.
//!
//! The type names are part of the wire contract: iceoryx2 refuses to connect ports whose payload
//! names differ, and programs in other languages open these services by these names.

use iceoryx2::prelude::ZeroCopySend;

use crate::messages::{ClockMsg, StateMsg};

/// iceoryx2's type name of [`StateMsg`] on `cdm/<team>/state/<id>`.
pub const STATE_TYPE_NAME: &str = "cdm::State";
/// iceoryx2's type name of [`ClockMsg`] on `cdm/<team>/clock`.
pub const CLOCK_TYPE_NAME: &str = "cdm::Clock";

/// A wire message in shared memory: the runtime's type with the layout unchanged.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(transparent)]
pub struct Wire<T>(pub T);

/// The payload of a state service.
pub type StateWire = Wire<StateMsg>;
/// The payload of the clock service.
pub type ClockWire = Wire<ClockMsg>;

// The sizes other languages mirror; a field added to a message must fail here first.
const _: () = assert!(core::mem::size_of::<StateMsg>() == 128);
const _: () = assert!(core::mem::size_of::<ClockMsg>() == 48);

// SAFETY: `StateMsg` is `#[repr(C)]` with only `u64`, `u32` and `[f64; 12]` fields (no pointers,
// no references, no heap), so its bytes mean the same in every process that maps them; `Wire` is
// `#[repr(transparent)]` over it.
unsafe impl ZeroCopySend for Wire<StateMsg> {
    unsafe fn type_name() -> &'static str {
        STATE_TYPE_NAME
    }
}

// SAFETY: `ClockMsg` is `#[repr(C)]` with only `u64` and `u32` fields; as above.
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
        }
    }
}
