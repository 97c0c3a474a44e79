//! `orchestrator replay` of lockstep and real-time runs.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod replay;
mod replay_realtime;
