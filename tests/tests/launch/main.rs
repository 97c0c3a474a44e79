//! `orchestrator launch` with the real binaries over real iceoryx2 shared memory: the team end to end, the live audit, faults, losses, resources, other users, dead nodes.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod audit;
mod faults;
mod launch;
mod loss_launch;
mod other_users;
mod resources;
mod unknown_nodes;
