//! `plan`, `simulate` and the scenario features they certify and fly in one process: the paper's figures' numbers, the golden pin, missions, the airspace, the Earth, the vehicles' limits, imperfect links, losses.
//!
//! One test binary (each file a module): the files share one link of the harness.

mod cli;
mod geofence;
mod golden;
mod links;
mod loss;
mod mission;
mod origin;
mod vehicle;
