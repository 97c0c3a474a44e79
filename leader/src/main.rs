//! `leader`: one quadcopter of a team as its own process, a primary or secondary leader: tracks r_HT = Q r_0 + d from its plan (eqs. 5, 13-15).
//!
//! It joins a team created by `orchestrator launch` (or `orchestrator launch --no-spawn`),
//! subscribes only to its in-neighbours' state services, and publishes its own state every tick.
//! Arguments: see `cdm_member_cli::MemberArgs` (`leader --help`).

fn main() {
    cdm_member_cli::main(cdm_member::member::Binary::Leader)
}
