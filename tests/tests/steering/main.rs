//! Steering a team in flight: `--commands` files and `orchestrator command`.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod commands_seen;
mod steering;
mod steering_launch;
mod steering_live;
mod steering_realtime;
mod steering_realtime_file;
