//! The team protocol's parts that need no transport: the `#[repr(C)]` wire messages (plain
//! types; the iceoryx2 backend gives them their shared-memory trait), the signal flags and the
//! test-only fault injection. No iceoryx2 here: the compiler holds that rule.

pub mod fault_inject;
pub mod messages;
pub mod signals;
