//! The team protocol without a transport: the `#[repr(C)]` wire messages (plain types; the
//! iceoryx2 backend gives them their shared-memory trait), the seams (transport, clocks,
//! vehicle), the member's protocol core (no I/O) with its two timings (lockstep and real time)
//! and the one generic loop around it, and the team's cores. No iceoryx2 here, and no OS
//! process concerns (signals, scheduling, fault injection: cdm-process): the compiler holds
//! that rule.

mod inbox;
pub mod member_core;
pub mod member_lockstep;
pub mod member_loop;
pub mod member_loss;
mod member_protocol;
pub mod member_steer;
mod member_watch;
pub mod messages;
pub mod notices;
pub mod process_exit;
pub mod realtime;
pub mod realtime_journal;
pub mod realtime_links;
pub mod realtime_loop;
pub mod realtime_monitor;
pub mod realtime_replay;
pub mod seams;
pub mod stall;
pub mod team_core;
pub mod team_fault;
pub mod team_loss;
pub mod team_slots;
