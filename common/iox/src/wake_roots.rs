//! Which members the orchestrator wakes itself when clock messages are relayed
//! (`TeamLayout::with_relayed_wakes`): pure graph code, no iceoryx2.

use std::collections::BTreeSet;

/// The members from which every member of `ids` is reached along `out` (who a member wakes):
/// every member nobody reads from (in-degree 0: the leaders of a synthesised graph), then, in id
/// order, any member still unreached (a cycle with no way in, possible in scenario files).
/// Sorted; deterministic.
pub fn roots<'a>(ids: &[u32], out: impl Fn(u32) -> &'a [u32]) -> Vec<u32> {
    let mut has_reader: BTreeSet<u32> = BTreeSet::new();
    for &id in ids {
        has_reader.extend(out(id).iter().copied());
    }
    let mut roots: Vec<u32> = ids
        .iter()
        .copied()
        .filter(|id| !has_reader.contains(id))
        .collect();
    let mut reached = BTreeSet::new();
    let mut stack = roots.clone();
    let flood = |stack: &mut Vec<u32>, reached: &mut BTreeSet<u32>| {
        while let Some(id) = stack.pop() {
            if reached.insert(id) {
                stack.extend(out(id).iter().copied().filter(|j| !reached.contains(j)));
            }
        }
    };
    flood(&mut stack, &mut reached);
    for &id in ids {
        if !reached.contains(&id) {
            roots.push(id);
            stack.push(id);
            flood(&mut stack, &mut reached);
        }
    }
    roots.sort_unstable();
    roots
}

#[cfg(test)]
mod tests {
    use super::roots;
    use std::collections::BTreeMap;

    fn outs(edges: &[(u32, u32)]) -> BTreeMap<u32, Vec<u32>> {
        let mut m: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
        for &(from, to) in edges {
            m.entry(from).or_default().push(to);
        }
        m
    }

    fn roots_of(ids: &[u32], edges: &[(u32, u32)]) -> Vec<u32> {
        let m = outs(edges);
        roots(ids, |id| m.get(&id).map_or(&[], Vec::as_slice))
    }

    #[test]
    fn the_leaders_of_an_acyclic_graph_reach_everyone() {
        // 0 and 1 lead; 2 reads both, 3 reads 1 and 2.
        let r = roots_of(&[0, 1, 2, 3], &[(0, 2), (1, 2), (1, 3), (2, 3)]);
        assert_eq!(r, vec![0, 1]);
    }

    #[test]
    fn a_cycle_nobody_enters_gets_one_root() {
        // 0 leads 1; 2 and 3 read each other only.
        let r = roots_of(&[0, 1, 2, 3], &[(0, 1), (2, 3), (3, 2)]);
        assert_eq!(r, vec![0, 2]);
    }

    #[test]
    fn a_cycle_entered_from_a_leader_needs_no_root() {
        let r = roots_of(&[0, 1, 2], &[(0, 1), (1, 2), (2, 1)]);
        assert_eq!(r, vec![0]);
    }

    #[test]
    fn members_without_edges_are_all_roots() {
        assert_eq!(roots_of(&[4, 7, 9], &[]), vec![4, 7, 9]);
    }
}
