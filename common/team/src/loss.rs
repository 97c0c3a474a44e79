//! `launch` losing members: the I/O pieces around the team core's loss decisions
//! (`cdm_runtime::team_core`, `team_core/loss_events.rs`): the scripted kills of `--lose`, killing and
//! reaping a member, and the room the services keep for repairs.

use std::collections::{BTreeMap, BTreeSet};

use cdm_engine::loss::LossSchedule;
use cdm_iox::RepairRoom;
use cdm_model::repair::{synthesis_order, SingleLosses};
use cdm_records::loss_log::LossLog;
use cdm_scenario::Scenario;

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

/// SIGTERM member `id`, then SIGKILL it if it has not exited within `grace`, and reap it. A
/// member stopped by SIGTERM stops flying at once and closes its recording (`recording/<id>.mcap`
/// then holds every tick it flew, so `replay` flies the run through its loss); a killed one
/// leaves its recording cut short.
pub fn stop_and_reap(children: &mut [Spawned], id: u32, grace: std::time::Duration) {
    let Some(c) = children.iter_mut().find(|c| c.id == id) else {
        return;
    };
    if matches!(c.child.try_wait(), Ok(None)) {
        // SAFETY: plain kill(2) on our own child's pid, not reaped yet.
        unsafe {
            libc::kill(c.child.id() as libc::pid_t, libc::SIGTERM);
        }
        let until = std::time::Instant::now() + grace;
        while matches!(c.child.try_wait(), Ok(None)) && std::time::Instant::now() < until {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
    }
    let _ = c.child.kill();
    let _ = c.child.wait();
}

/// Room for repairs: every member may gain, as a new in-neighbour, as many readers as the loss
/// of any single member gives it, plus two for further losses; every follower may gain three
/// new in-neighbours' wake-ups plus two. History: a window of states plus one (a new reader may
/// need every state its new in-neighbour published since the lost member's last one; members
/// run at most a window ahead of the last complete tick).
///
/// N single-loss repairs: the synthesis order they share is computed once (it was an O(N^2) scan
/// per repair, 2 s of the start-up at N = 1000), each repairs only the lost member's readers on
/// a shared working copy (`SingleLosses`), and the members are split over the cores.
pub fn repair_room(s: &Scenario, window: u32) -> RepairRoom {
    let floor = s
        .file
        .weight_floor
        .unwrap_or(cdm_model::graph::DEFAULT_WEIGHT_FLOOR);
    let order = synthesis_order(&s.formation);
    // A member nobody reads changes no link when it is lost: only the others need a repair
    // (three quarters of them at N = 1000).
    let ids: Vec<u32> = s
        .formation
        .out_neighbors()
        .into_iter()
        .filter(|(_, readers)| !readers.is_empty())
        .map(|(id, _)| id)
        .collect();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let chunk = ids.len().div_ceil(threads).max(1);
    let most = std::thread::scope(|scope| {
        let parts: Vec<_> = ids
            .chunks(chunk)
            .map(|part| scope.spawn(|| most_gained(s, floor, &order, part)))
            .collect();
        let mut most: BTreeMap<u32, usize> = BTreeMap::new();
        for part in parts {
            // A panic in a repair is a bug; sizing without its part would only risk a refused
            // port later, so the part is skipped rather than the launch stopped.
            for (j, g) in part.join().unwrap_or_default() {
                let e = most.entry(j).or_default();
                *e = (*e).max(g);
            }
        }
        most
    });
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

/// Widens `room` for the loss of each group of `groups` at once: a killed daemon loses every
/// member of its host (`launch --hosts`, lockstep, `--on-loss repair`), each after its own last
/// tick. Losses apply in tick order, one epoch per tick (`LossLog::epochs`), and the ticks are
/// not known in advance: the group is repaired all at one tick, one by one in ascending and in
/// descending id order, and (groups of up to [`SHUFFLED_UP_TO`]) in [`SHUFFLES`] seeded shuffles
/// whose ticks tie at random, and the repairs of every first few of the group at one tick
/// (members open ports for each notice); every state service gets room for the most new
/// readers any of these gives it, plus two, and every wake event for twice the most new
/// in-neighbours, plus two.
/// Orders other than these may still need more (then the link is refused, by name). One by one
/// costs a repair per member (0.23 s for 125 of N = 250, 3.3 s for 500 of N = 1000): groups
/// larger than [`ONE_BY_ONE_UP_TO`] are sized for the loss at one tick only.
pub fn with_group_losses(mut room: RepairRoom, s: &Scenario, groups: &[Vec<u32>]) -> RepairRoom {
    for group in groups.iter().filter(|g| !g.is_empty()) {
        let mut sets: Vec<BTreeSet<(u32, u32)>> = loss_orders(group)
            .into_iter()
            .map(|ticks| {
                let mut log = LossLog::new(s);
                for (id, tick) in ticks {
                    log.add(id, tick);
                }
                log.new_links()
            })
            .collect();
        // Members open ports as each notice comes, and the losses of one tick are announced one
        // at a time (a lost host hands them over in ascending id): the repairs of the first
        // few of them are opened too.
        if group.len() <= ONE_BY_ONE_UP_TO {
            let mut ascending = group.clone();
            ascending.sort_unstable();
            let mut log = LossLog::new(s);
            let mut all = BTreeSet::new();
            for id in ascending {
                log.add(id, 1);
                all.extend(log.new_links());
            }
            sets.push(all);
        }
        for links in sets {
            let mut readers: BTreeMap<u32, usize> = BTreeMap::new();
            let mut writers: BTreeMap<u32, usize> = BTreeMap::new();
            for (reader, writer) in links {
                *readers.entry(writer).or_default() += 1;
                *writers.entry(reader).or_default() += 1;
            }
            for (j, gain) in readers {
                let e = room.readers.entry(j).or_default();
                *e = (*e).max(gain + 2);
            }
            // Twice: a member also opens a notifier for the repairs of the first few losses of
            // a tick, announced one at a time, which these sets do not count (at N = 40, one
            // lost host needed 15 on one wake event where the sets counted 12); a notifier
            // slot costs a few bytes of the event service's dynamic config.
            let most_writers = writers.values().copied().max().unwrap_or(0);
            room.writers = room.writers.max(2 * most_writers + 2);
        }
    }
    room
}

/// The largest group sized for losses one by one (see [`with_group_losses`]).
pub const ONE_BY_ONE_UP_TO: usize = 256;
/// The largest group also sized for shuffled orders.
pub const SHUFFLED_UP_TO: usize = 64;
/// How many shuffled orders.
pub const SHUFFLES: u64 = 6;

/// The (id, loss tick) assignments a group is sized for (see [`with_group_losses`]).
fn loss_orders(group: &[u32]) -> Vec<Vec<(u32, u64)>> {
    let mut ascending = group.to_vec();
    ascending.sort_unstable();
    let ranked =
        |ids: &[u32]| -> Vec<(u32, u64)> { ids.iter().zip(1..).map(|(&id, k)| (id, k)).collect() };
    let mut out = vec![ascending.iter().map(|&id| (id, 1)).collect()];
    if group.len() > ONE_BY_ONE_UP_TO {
        return out;
    }
    out.push(ranked(&ascending));
    let descending: Vec<u32> = ascending.iter().rev().copied().collect();
    out.push(ranked(&descending));
    if group.len() > SHUFFLED_UP_TO {
        return out;
    }
    for seed in 0..SHUFFLES {
        let mut ids = ascending.clone();
        let draw = |k: u64| cdm_model::link::splitmix64(seed.wrapping_mul(1 << 32) ^ k);
        // Fisher-Yates, then ticks that stay put or step by one at random (ties: one epoch).
        for k in (1..ids.len()).rev() {
            ids.swap(k, (draw(k as u64) % (k as u64 + 1)) as usize);
        }
        let mut tick = 1;
        let mut order = Vec::with_capacity(ids.len());
        for (k, id) in ids.into_iter().enumerate() {
            tick += draw(1 << 20 | k as u64) & 1;
            order.push((id, tick));
        }
        out.push(order);
    }
    out
}

/// For the loss of each member of `lost_one_by_one` alone: the most new readers any survivor
/// gains, by survivor id.
fn most_gained(
    s: &Scenario,
    floor: f64,
    order: &[(u32, cdm_math::Vec2)],
    lost_one_by_one: &[u32],
) -> BTreeMap<u32, usize> {
    let mut most: BTreeMap<u32, usize> = BTreeMap::new();
    let mut singles = SingleLosses::new(&s.formation, floor, order);
    for &id in lost_one_by_one {
        let mut gain: BTreeMap<u32, usize> = BTreeMap::new();
        for x in &singles.retriangulated(id) {
            for j in x.new.iter().filter(|j| !x.old.contains(j)) {
                *gain.entry(*j).or_default() += 1;
            }
        }
        for (j, g) in gain {
            let e = most.entry(j).or_default();
            *e = (*e).max(g);
        }
    }
    most
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lost_host_gets_room_for_every_order_it_was_sized_for() {
        let s = Scenario::generated(40).unwrap();
        let single = repair_room(&s, 8);
        let group: Vec<u32> = s
            .formation
            .members
            .iter()
            .map(|m| m.id)
            .filter(|&i| i > 20)
            .collect();
        let room = with_group_losses(single.clone(), &s, std::slice::from_ref(&group));
        // Losing the group one by one, its new links all fit.
        let mut log = LossLog::new(&s);
        for (k, &id) in group.iter().rev().enumerate() {
            log.add(id, k as u64 + 1);
        }
        let mut readers: BTreeMap<u32, usize> = BTreeMap::new();
        let mut writers: BTreeMap<u32, usize> = BTreeMap::new();
        for (r, w) in log.new_links() {
            *readers.entry(w).or_default() += 1;
            *writers.entry(r).or_default() += 1;
        }
        for (j, n) in &readers {
            assert!(room.readers[j] >= n + 2, "state/{j}: {n} new readers");
        }
        assert!(writers.values().all(|&n| room.writers >= n + 2));
        // Single losses alone would not have been enough (else this sizing proves nothing).
        let short = readers.iter().any(|(j, &n)| single.readers[j] < n)
            || writers.values().any(|&n| single.writers < n);
        assert!(short, "{readers:?} {writers:?}");
    }

    #[test]
    fn members_nobody_reads_need_no_repair() {
        let s = Scenario::generated(80).unwrap();
        let floor = cdm_model::graph::DEFAULT_WEIGHT_FLOOR;
        let order = synthesis_order(&s.formation);
        let all: Vec<u32> = s.formation.members.iter().map(|m| m.id).collect();
        let most = most_gained(&s, floor, &order, &all);
        let room = repair_room(&s, 8);
        for m in &s.formation.members {
            let expected = most.get(&m.id).copied().unwrap_or(0) + 2;
            assert_eq!(room.readers[&m.id], expected, "member {}", m.id);
        }
        assert!(most.values().any(|&g| g > 0));
    }
}
