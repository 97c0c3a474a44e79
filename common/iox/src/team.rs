//! Team names (the prefix of every service and node of a team) and team layouts (who reads
//! whom: the orchestrator sizes every service from it).

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;

use super::{TeamProcess, TransportError, TEAM_NAME_MAX_LEN};

/// A validated team name (`[A-Za-z0-9_-]`, 1 to [`TEAM_NAME_MAX_LEN`] characters). It prefixes
/// every service and node name of the team, so two teams never see each other.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TeamName(String);

impl TeamName {
    /// Validates `name`.
    pub fn new(name: &str) -> Result<Self, TransportError> {
        let invalid = |reason| TransportError::InvalidTeamName {
            name: name.to_owned(),
            reason,
        };
        if name.is_empty() {
            return Err(invalid("it is empty"));
        }
        if name.len() > TEAM_NAME_MAX_LEN {
            return Err(invalid("it is longer than 48 characters"));
        }
        if !name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
        {
            return Err(invalid("only A-Z, a-z, 0-9, '_' and '-' are allowed"));
        }
        Ok(Self(name.to_owned()))
    }

    /// The name itself.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// `cdm/<team>/state/<id>`: member `id`'s states.
    pub fn state_service(&self, id: u32) -> String {
        format!("cdm/{}/state/{id}", self.0)
    }

    /// `cdm/<team>/clock`: the orchestrator's grants.
    pub fn clock_service(&self) -> String {
        format!("cdm/{}/clock", self.0)
    }

    /// `cdm/<team>/wake/<id>`: wakes member `id`.
    pub fn wake_service(&self, id: u32) -> String {
        format!("cdm/{}/wake/{id}", self.0)
    }

    /// `cdm/<team>/wake/orch`: wakes the orchestrator.
    pub fn orchestrator_wake_service(&self) -> String {
        format!("cdm/{}/wake/orch", self.0)
    }

    /// The node name of a process of this team: `cdm/<team>/agent/<id>` or
    /// `cdm/<team>/orchestrator`.
    pub fn node_name(&self, who: TeamProcess) -> String {
        match who {
            TeamProcess::Orchestrator => format!("cdm/{}/orchestrator", self.0),
            TeamProcess::Agent(id) => format!("cdm/{}/agent/{id}", self.0),
        }
    }

    /// `cdm/<team>/host/<host>/agent/<id>`: the node through which host `host`'s bridge stands
    /// in for member `id`, which runs on another host.
    pub fn relay_node_name(&self, host: u32, id: u32) -> String {
        format!("cdm/{}/host/{host}/agent/{id}", self.0)
    }

    /// True when `node_name` belongs to a process of this team.
    pub fn owns_node(&self, node_name: &str) -> bool {
        node_name
            .strip_prefix("cdm/")
            .and_then(|rest| rest.strip_prefix(self.0.as_str()))
            .is_some_and(|rest| rest.starts_with('/'))
    }
}

impl fmt::Display for TeamName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::str::FromStr for TeamName {
    type Err = TransportError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::new(s)
    }
}

/// Who talks to whom in a team, validated: the orchestrator sizes every service from it.
/// `in_neighbors[i]` are the members whose states member `i` reads; out-neighbours are derived.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TeamLayout {
    ids: Vec<u32>,
    in_neighbors: BTreeMap<u32, Vec<u32>>,
    out_neighbors: BTreeMap<u32, Vec<u32>>,
    window: u32,
    scenario_hash: u64,
    repair: Option<RepairRoom>,
    /// Edges `(source, reader)` that this host's shared memory never carries (both ends run on
    /// one other host: that host's daemon connects them). Readiness does not wait for them.
    hidden: BTreeSet<(u32, u32)>,
    /// Clock messages reach most members through their in-neighbours (see
    /// [`TeamLayout::with_relayed_wakes`]); `false`: the orchestrator wakes every member itself.
    relayed_wakes: bool,
}

/// Room the services keep for repairs after losses: readers a member may gain, and how many
/// states a new reader receives again from its new in-neighbour (`resend.rs`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RepairRoom {
    /// Extra subscribers (and nodes) on `state/<id>`, by id; ids not listed get none.
    pub readers: BTreeMap<u32, usize>,
    /// Extra notifiers (and nodes) on every `wake/<id>`: the new in-neighbours of a follower.
    pub writers: usize,
    /// States every member sends again for a late subscriber at a hand-over.
    pub history: usize,
}

/// The clock service's attribute that carries the team's scenario hash.
pub const SCENARIO_HASH_KEY: &str = "cdm.scenario_hash";

/// The attribute value of a scenario hash.
pub fn scenario_hash_value(hash: u64) -> String {
    format!("{hash:016x}")
}

impl TeamLayout {
    /// Checks that ids are unique and non-empty, every neighbour is a team member, nobody is its
    /// own neighbour, and `window >= 1` (how many ticks a member may run ahead of the slowest).
    /// Ids missing from `in_neighbors` read nobody. Neighbour lists are sorted and deduplicated.
    pub fn new(
        ids: Vec<u32>,
        in_neighbors: BTreeMap<u32, Vec<u32>>,
        window: u32,
    ) -> Result<Self, TransportError> {
        let invalid = |reason: String| TransportError::InvalidLayout { reason };
        let members: BTreeSet<u32> = ids.iter().copied().collect();
        if members.is_empty() {
            return Err(invalid("the team has no agents".into()));
        }
        if members.len() != ids.len() {
            return Err(invalid(format!("duplicate agent ids in {ids:?}")));
        }
        if window == 0 {
            return Err(invalid("window must be at least 1 tick".into()));
        }
        let mut ins = BTreeMap::new();
        let mut outs: BTreeMap<u32, Vec<u32>> = members.iter().map(|&i| (i, vec![])).collect();
        for &id in &members {
            let mut list: Vec<u32> = in_neighbors.get(&id).cloned().unwrap_or_default();
            list.sort_unstable();
            list.dedup();
            for &j in &list {
                if j == id {
                    return Err(invalid(format!("agent {id} lists itself as a neighbour")));
                }
                let Some(out) = outs.get_mut(&j) else {
                    return Err(invalid(format!(
                        "agent {id} reads agent {j}, which is not in the team"
                    )));
                };
                out.push(id);
            }
            ins.insert(id, list);
        }
        if let Some(stray) = in_neighbors.keys().find(|k| !members.contains(k)) {
            return Err(invalid(format!(
                "neighbours are given for agent {stray}, which is not in the team"
            )));
        }
        Ok(Self {
            ids: members.into_iter().collect(),
            in_neighbors: ins,
            out_neighbors: outs,
            window,
            scenario_hash: 0,
            repair: None,
            hidden: BTreeSet::new(),
            relayed_wakes: false,
        })
    }

    /// The same layout carrying the team's scenario hash (published as an attribute of the clock
    /// service; a member whose scenario differs is refused before it opens any other port).
    pub fn with_scenario_hash(mut self, hash: u64) -> Self {
        self.scenario_hash = hash;
        self
    }

    /// The same layout with room for repairs after losses (`launch --on-loss repair`).
    pub fn with_repair_room(mut self, room: RepairRoom) -> Self {
        self.repair = Some(room);
        self
    }

    /// Extra (subscribers on `state/<id>`, notifiers on `wake/<id>`) for repairs.
    pub fn repair_slots(&self, id: u32) -> (usize, usize) {
        self.repair.as_ref().map_or((0, 0), |r| {
            (r.readers.get(&id).copied().unwrap_or(0), r.writers)
        })
    }

    /// States a member sends again for late subscribers at a hand-over (0 without repairs).
    pub fn history(&self) -> usize {
        self.repair.as_ref().map_or(0, |r| r.history)
    }

    /// The same layout, where the orchestrator wakes only the [`wake_roots`](Self::wake_roots)
    /// after a clock message and every member passes each clock message it reads on to its
    /// out-neighbours (it notifies them before it sleeps or exits). The orchestrator then holds
    /// no port on the other members' wake events, which were 5 of its 11 file descriptors per
    /// member (N = 2000 needed 24,064, above this machine's hard limit of 20,000). Lockstep
    /// teams on one host only: real-time members do not relay (they never notify readers), and
    /// across hosts a member's in-neighbours may live elsewhere.
    pub fn with_relayed_wakes(mut self) -> Self {
        self.relayed_wakes = true;
        self
    }

    /// True when clock messages are relayed ([`Self::with_relayed_wakes`]).
    pub fn relays_wakes(&self) -> bool {
        self.relayed_wakes
    }

    /// The members the orchestrator wakes itself: every member when wake-ups are not relayed;
    /// otherwise the fewest members from which the wake-up reaches everyone along the
    /// out-neighbour edges ([`crate::wake_roots::roots`]): the leaders of a synthesised graph.
    pub fn wake_roots(&self) -> Vec<u32> {
        if self.relayed_wakes {
            crate::wake_roots::roots(&self.ids, |id| self.out_neighbors(id))
        } else {
            self.ids.clone()
        }
    }

    /// The same layout with edges `(source, reader)` that run on another host entirely (issue
    /// 12): services stay sized for the whole team, readiness expects none of their ports here.
    pub fn with_hidden_edges(mut self, hidden: BTreeSet<(u32, u32)>) -> Self {
        self.hidden = hidden;
        self
    }

    /// How many readers of `id`'s states take a port on this host.
    pub fn visible_out_degree(&self, id: u32) -> usize {
        let outs = self.out_neighbors(id);
        outs.iter()
            .filter(|&&r| !self.hidden.contains(&(id, r)))
            .count()
    }

    /// How many of `id`'s in-neighbours notify it on this host.
    pub fn visible_in_degree(&self, id: u32) -> usize {
        let ins = self.in_neighbors(id);
        ins.iter()
            .filter(|&&s| !self.hidden.contains(&(s, id)))
            .count()
    }

    /// The team's scenario hash.
    pub fn scenario_hash(&self) -> u64 {
        self.scenario_hash
    }

    /// The member ids, sorted.
    pub fn ids(&self) -> &[u32] {
        &self.ids
    }

    /// The members whose states `id` reads (sorted; empty for an unknown id).
    pub fn in_neighbors(&self, id: u32) -> &[u32] {
        self.in_neighbors.get(&id).map_or(&[], Vec::as_slice)
    }

    /// The members that read `id`'s states (sorted; empty for an unknown id).
    pub fn out_neighbors(&self, id: u32) -> &[u32] {
        self.out_neighbors.get(&id).map_or(&[], Vec::as_slice)
    }

    /// How many ticks a member may run ahead of the slowest one.
    pub fn window(&self) -> u32 {
        self.window
    }
}
