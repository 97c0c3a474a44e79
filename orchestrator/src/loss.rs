//! `launch` losing members: the I/O pieces around the team core's loss decisions
//! (`common::team_core`, `team_core_loss.rs`): the scripted kills of `--lose`, killing and
//! reaping a member, and the room the services keep for repairs.

use std::collections::BTreeMap;

use common::loss::LossSchedule;
use common::repair::repair;
use common::scenario::Scenario;
use common::transport::RepairRoom;

use crate::team::Spawned;

/// `--lose` as (id, last tick it publishes) for the team core.
pub fn scripted_kills(schedule: &LossSchedule) -> Vec<(u32, u64)> {
    schedule
        .events
        .iter()
        .flat_map(|(from, ids)| ids.iter().map(move |&id| (id, from - 1)))
        .collect()
}

/// SIGKILL member `id` and reap it: once `wait` returns it publishes nothing more, and what it
/// published stays readable (a killed publisher's samples remain until its node is cleaned,
/// which happens only when the team stops).
pub fn kill_and_reap(children: &mut [Spawned], id: u32) {
    if let Some(c) = children.iter_mut().find(|c| c.id == id) {
        let _ = c.child.kill();
        let _ = c.child.wait();
    }
}

/// Room for repairs: every member may gain, as a new in-neighbour, as many readers as the loss
/// of any single member gives it, plus two for further losses; every follower may gain three
/// new in-neighbours' wake-ups plus two. History: a window of states plus one (a new reader may
/// need every state its new in-neighbour published since the lost member's last one; members
/// run at most a window ahead of the last complete tick).
pub fn repair_room(s: &Scenario, window: u32) -> RepairRoom {
    let floor = s
        .file
        .weight_floor
        .unwrap_or(common::graph::DEFAULT_WEIGHT_FLOOR);
    let mut most: BTreeMap<u32, usize> = BTreeMap::new();
    for m in &s.formation.members {
        let r = repair(&s.formation, floor, &[m.id].into());
        let mut gain: BTreeMap<u32, usize> = BTreeMap::new();
        for x in &r.retriangulated {
            for j in x.new.iter().filter(|j| !x.old.contains(j)) {
                *gain.entry(*j).or_default() += 1;
            }
        }
        for (j, g) in gain {
            let e = most.entry(j).or_default();
            *e = (*e).max(g);
        }
    }
    let readers = s
        .formation
        .members
        .iter()
        .map(|m| (m.id, most.get(&m.id).copied().unwrap_or(0) + 2))
        .collect();
    RepairRoom {
        readers,
        writers: 5,
        history: window as usize + 1,
    }
}
