//! `agent`: one quadcopter of a team as its own process, a follower: tracks the weighted sum of its three in-neighbours (eqs. 6, 44).
//!
//! It joins a team created by `orchestrator launch` (or `orchestrator launch --no-spawn`),
//! subscribes only to its in-neighbours' state services, and publishes its own state every tick.
//! Arguments: see `cdm_member_cli::MemberArgs` (`agent --help`).

fn main() {
    cdm_member_cli::main(cdm_member::member::Binary::Agent)
}
