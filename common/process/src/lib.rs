//! The OS side of a team's processes (members, the orchestrator, the host daemons), kept out
//! of the protocol crate (cdm-runtime): stopping signals turned into a flag, Linux real-time
//! scheduling for `--rt-priority`, the test-only fault injection a member reads from its
//! environment and hands to the member loop as its before-publish hook, and members forked
//! from a template process (`fork.rs`).

pub mod fault_inject;
pub mod fork;
pub mod sched;
pub mod signals;
