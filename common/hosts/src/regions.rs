//! Which member runs on which host: contiguous regions of the formation, so that few
//! communication edges cross hosts (pure; no I/O).
//!
//! The synthesised graph links each follower to a triangle of nearby members
//! (`common/model/src/graph.rs`), so cutting the formation into slabs along one in-plane axis keeps
//! most edges inside a slab. Both in-plane axes are tried and the one with fewer crossing edges
//! kept; slabs hold `n / K` members each (the first ones one more when K does not divide n).

use std::collections::BTreeMap;

/// One member as the split sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct Placed {
    pub id: u32,
    /// In-plane coordinates at t0 (eq. 12).
    pub planar: [f64; 2],
    /// The members whose states it reads.
    pub in_neighbors: Vec<u32>,
}

/// Members assigned to hosts 0..K (host 0 is the orchestrator's).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Regions {
    host_of: BTreeMap<u32, u32>,
    hosts: u32,
}

impl Regions {
    /// Splits `members` over `hosts` hosts (1 <= hosts <= members.len(), checked by the caller).
    pub fn split(members: &[Placed], hosts: u32) -> Self {
        let best = [0, 1]
            .into_iter()
            .map(|axis| Self::along(members, hosts, axis))
            .min_by_key(|r| r.crossing(members).len());
        best.unwrap_or_else(|| Self::along(members, hosts, 0))
    }

    /// Slabs along one in-plane axis (ties by id, so the split is deterministic).
    fn along(members: &[Placed], hosts: u32, axis: usize) -> Self {
        let mut order: Vec<&Placed> = members.iter().collect();
        order.sort_by(|a, b| {
            a.planar[axis]
                .total_cmp(&b.planar[axis])
                .then(a.id.cmp(&b.id))
        });
        let n = order.len();
        let k = hosts.max(1) as usize;
        let mut host_of = BTreeMap::new();
        let mut start = 0;
        for h in 0..k {
            let size = n / k + usize::from(h < n % k);
            for m in &order[start..start + size] {
                host_of.insert(m.id, h as u32);
            }
            start += size;
        }
        Self {
            host_of,
            hosts: hosts.max(1),
        }
    }

    /// From an explicit map (a daemon rebuilds the orchestrator's split from its assignment).
    pub fn from_map(host_of: BTreeMap<u32, u32>, hosts: u32) -> Self {
        Self { host_of, hosts }
    }

    /// How many hosts.
    pub fn hosts(&self) -> u32 {
        self.hosts
    }

    /// The host of `id` (host 0 for an unknown id).
    pub fn host_of(&self, id: u32) -> u32 {
        self.host_of.get(&id).copied().unwrap_or(0)
    }

    /// Every (id, host), by id.
    pub fn pairs(&self) -> Vec<(u32, u32)> {
        self.host_of.iter().map(|(&i, &h)| (i, h)).collect()
    }

    /// The members of `host`, by id.
    pub fn members(&self, host: u32) -> Vec<u32> {
        let on = self.host_of.iter().filter(|(_, &h)| h == host);
        on.map(|(&i, _)| i).collect()
    }

    /// Edges `(source, reader)` whose ends run on different hosts, sorted.
    pub fn crossing(&self, members: &[Placed]) -> Vec<(u32, u32)> {
        let mut out = vec![];
        for m in members {
            for &j in &m.in_neighbors {
                if self.host_of(j) != self.host_of(m.id) {
                    out.push((j, m.id));
                }
            }
        }
        out.sort_unstable();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 x 5 grid, each member reading its left and lower neighbours.
    fn grid() -> Vec<Placed> {
        let mut v = vec![];
        for x in 0..4u32 {
            for y in 0..5u32 {
                let id = x * 5 + y;
                let mut ins = vec![];
                if x > 0 {
                    ins.push(id - 5);
                }
                if y > 0 {
                    ins.push(id - 1);
                }
                v.push(Placed {
                    id,
                    planar: [f64::from(x), f64::from(y)],
                    in_neighbors: ins,
                });
            }
        }
        v
    }

    #[test]
    fn regions_are_contiguous_balanced_and_cut_few_edges() {
        let g = grid();
        let r = Regions::split(&g, 2);
        assert_eq!(r.members(0).len(), 10);
        assert_eq!(r.members(1).len(), 10);
        // Cutting the 4-wide axis in half crosses 5 edges; the 5-long axis would cross 4 x 1
        // ... either way far fewer than the 31 edges of the grid; the best of both is kept.
        let crossing = r.crossing(&g);
        assert_eq!(crossing.len(), 5, "{crossing:?}");
        for (s, t) in crossing {
            assert_ne!(r.host_of(s), r.host_of(t));
        }
    }

    #[test]
    fn uneven_splits_give_the_first_hosts_one_more() {
        let g = grid();
        let r = Regions::split(&g, 3);
        let sizes: Vec<usize> = (0..3).map(|h| r.members(h).len()).collect();
        assert_eq!(sizes, vec![7, 7, 6]);
        assert_eq!(Regions::split(&g, 1).crossing(&g), vec![]);
    }
}
