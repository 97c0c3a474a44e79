//! `--vehicles mavlink`: the vehicle link and MAVLink teams against pymavlink.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod mavlink_global;
mod mavlink_plant;
mod mavlink_team;
