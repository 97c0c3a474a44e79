//! The clock loop of one team: `launch` creates the team, spawns its members (here and, through
//! cdm-hosts, on other hosts) and grants ticks in lockstep; `realtime` paces the same team by
//! the wall clock. Both audit every tick and write the run directory.

pub mod channel;
pub mod feeds;
pub mod flight;
mod fly;
pub mod launch;
pub mod launch_error;
pub mod notice;
pub mod realtime;
pub mod steer;
pub mod team_arm;
pub mod vehicle_reports;
