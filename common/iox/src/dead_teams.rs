//! Finding and removing what teams of this user left behind when all their processes died
//! (SIGKILL, a crash, a power-off of the terminal): a launch does it for every such team, and
//! `orchestrator clean` on demand. A team with any live process is never touched: its dead
//! members are evidence of a fault its orchestrator is still examining.

use std::collections::{BTreeMap, BTreeSet};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;

use super::creator::creator_is_dead;
use super::{init_logging, iox2_root, process_config, remove_stale, TeamName, TransportError};

/// What a scan of this user's iceoryx2 registry found of one team.
#[derive(Default)]
pub(super) struct TeamScan {
    /// Names of live nodes of the team, sorted.
    pub alive: Vec<String>,
    /// Dead nodes of the team, to be cleaned.
    pub dead: Vec<iceoryx2::node::DeadNodeView<ipc::Service>>,
}

/// A team whose processes were all dead, and what was removed of it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RemovedTeam {
    /// The team.
    pub team: TeamName,
    /// Its dead processes (iceoryx2 nodes) found.
    pub dead_nodes: usize,
    /// How many of them this call cleaned (the others were cleaned meanwhile by someone else).
    pub removed: usize,
}

/// The team a node name (`cdm/<team>/...`) belongs to; `None` for nodes of other tools.
fn team_of(node_name: &str) -> Option<TeamName> {
    let rest = node_name.strip_prefix("cdm/")?;
    let (team, _) = rest.split_once('/')?;
    TeamName::new(team).ok()
}

/// What a scan of this user's iceoryx2 registry found.
#[derive(Default)]
pub(super) struct Registry {
    /// Every team with a node, live or dead.
    pub teams: BTreeMap<TeamName, TeamScan>,
    /// Ids of the nodes iceoryx2 listed alive or with details: the only nodes that
    /// `orphan_nodes` leaves alone without looking further.
    pub described: BTreeSet<u128>,
}

/// What [`remove_dead_teams`] removed.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Cleaned {
    /// The teams whose processes were all dead.
    pub teams: Vec<RemovedTeam>,
    /// Dead nodes of no known team (a process killed while its node was being dropped or
    /// cleaned left only the node's monitor files: see `orphan_nodes`).
    pub unknown_nodes: usize,
}

/// Every team of this user in iceoryx2's registry, with its live and dead nodes (a node whose
/// details are unreadable is skipped), and the ids of every node with details or alive.
pub(super) fn scan_teams(cfg: &Config) -> Result<Registry, TransportError> {
    let mut reg = Registry::default();
    let team_of_view = |v: &dyn NodeView| {
        v.details()
            .as_ref()
            .map(|d| d.name().to_string())
            .and_then(|n| team_of(&n).map(|t| (t, n)))
    };
    Node::<ipc::Service>::list(cfg, |state| {
        match state {
            NodeState::Alive(v) => {
                reg.described.insert(v.id().value());
                if let Some((t, n)) = team_of_view(&v) {
                    reg.teams.entry(t).or_default().alive.push(n);
                }
            }
            NodeState::Dead(v) => {
                if v.details().is_some() {
                    reg.described.insert(v.id().value());
                }
                if let Some((t, _)) = team_of_view(&v) {
                    reg.teams.entry(t).or_default().dead.push(v);
                }
            }
            NodeState::Inaccessible(_) | NodeState::Undefined(_) => {}
        }
        CallbackProgression::Continue
    })
    .map_err(|e| TransportError::NodeRegistry {
        root: iox2_root().to_owned(),
        detail: format!("{e:?}"),
    })?;
    for scan in reg.teams.values_mut() {
        scan.alive.sort();
    }
    Ok(reg)
}

/// Removes the resources of every team in `reg` none of whose processes is alive, and the
/// dead nodes of no known team.
pub(super) fn remove_dead(reg: Registry) -> Cleaned {
    if reg.teams.values().any(|s| !s.dead.is_empty()) {
        remove_unfinished_segments();
    }
    let teams = reg
        .teams
        .into_iter()
        .filter(|(_, scan)| scan.alive.is_empty() && !scan.dead.is_empty())
        .map(|(team, scan)| {
            let dead_nodes = scan.dead.len();
            let leftovers: Vec<NodeFiles> = scan.dead.iter().filter_map(NodeFiles::of).collect();
            let removed = remove_stale(&team, scan.dead);
            for node in &leftovers {
                node.sweep(&team);
            }
            RemovedTeam {
                team,
                dead_nodes,
                removed,
            }
        })
        .collect();
    Cleaned {
        teams,
        unknown_nodes: super::orphan_nodes::remove(&reg.described),
    }
}

/// Removes the resources of every team of this user whose processes are all dead, and the dead
/// nodes of no known team, and says what it removed. Live teams, and the dead members of live
/// teams, are left alone.
pub fn remove_dead_teams() -> Result<Cleaned, TransportError> {
    init_logging();
    // Never read another user's files as if they were ours.
    super::ownership::check_root(super::iox2_location())?;
    Ok(remove_dead(scan_teams(process_config())?))
}

/// Removes the shared-memory segments under this user's prefix that a process killed while
/// creating them left empty: size 0, not yet readable (iceoryx2 makes a segment readable once
/// it is initialised), and created by a process that no longer exists (the process id is in
/// bits 64..96 of the 128-bit id that names the segment). iceoryx2 0.10 waits without a deadline
/// for such a segment to be sized when it removes a dead node (`MappingSizeIsZero` in its
/// `open`), so the cleanup of the dead team would hang; nothing else can ever use them.
fn remove_unfinished_segments() {
    const SHM: &str = "/dev/shm";
    let prefix = &super::iox2_location().prefix;
    let Ok(entries) = std::fs::read_dir(SHM) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(name) = name.to_str().filter(|n| n.starts_with(prefix.as_str())) else {
            continue;
        };
        let Ok(meta) = entry.metadata() else { continue };
        let unfinished =
            meta.is_file() && meta.len() == 0 && meta.permissions().mode() & 0o400 == 0;
        if unfinished && creator_is_dead(name) {
            let path = entry.path();
            match std::fs::remove_file(&path) {
                Ok(()) => tracing::info!(file = %path.display(),
                    "removed a shared-memory segment its killed creator left unfinished"),
                Err(e) => tracing::warn!(file = %path.display(), error = %e,
                    "cannot remove an unfinished shared-memory segment"),
            }
        }
    }
}

/// Whether a service's static config file is one whose writer was killed before finishing it:
/// empty, or still writable. iceoryx2 0.10 (`iceoryx2-cal` `static_storage::file`) creates it
/// owner read-write, writes it, and only then sets it owner read-only; until then it calls the
/// service "non-existing" and its own cleanup leaves the file.
fn unfinished_static_config(m: &std::fs::Metadata) -> bool {
    m.is_file() && (m.len() == 0 || m.permissions().mode() & 0o200 != 0)
}

/// The files iceoryx2 keeps for one dead node in this user's root, read before iceoryx2's own
/// cleanup: the node's directory of tags, its monitor files, and the static configs of the
/// services it had tagged. A node killed while it created a service or a port defeats
/// iceoryx2 0.10's cleanup (the node stays, `InternalError`; or an unfinished static config
/// stays, "non-existing service"), and no later process can remove what is left; only this user's
/// teams with every process dead are swept, and only these names.
struct NodeFiles {
    /// The node id as iceoryx2 writes it in file names (decimal).
    id: String,
    /// Hashes of the services the node had tagged.
    services: Vec<String>,
}

impl NodeFiles {
    fn of(node: &iceoryx2::node::DeadNodeView<ipc::Service>) -> Option<Self> {
        let id = u128::from_str_radix(&node.id().to_string(), 16)
            .ok()?
            .to_string();
        let prefix = &super::iox2_location().prefix;
        let dir = Path::new(iox2_root()).join("nodes").join(&id);
        let services = std::fs::read_dir(dir)
            .into_iter()
            .flatten()
            .flatten()
            .filter_map(|e| {
                let name = e.file_name().into_string().ok()?;
                let hash = name
                    .strip_prefix(prefix.as_str())?
                    .strip_suffix(".service_tag")?;
                Some(hash.to_owned())
            })
            .collect();
        Some(Self { id, services })
    }

    /// Removes what iceoryx2's cleanup left of the node: unfinished static configs of its
    /// services (a service whose creation was cut short), its directory and its monitor files.
    fn sweep(&self, team: &TeamName) {
        let root = Path::new(iox2_root());
        let prefix = &super::iox2_location().prefix;
        let mut gone: Vec<PathBuf> = vec![];
        for hash in &self.services {
            let path = root
                .join("services")
                .join(format!("{prefix}{hash}.service"));
            if std::fs::symlink_metadata(&path).is_ok_and(|m| unfinished_static_config(&m)) {
                gone.push(path);
            }
        }
        let nodes = root.join("nodes");
        let own = format!("{prefix}{}.", self.id);
        for entry in std::fs::read_dir(&nodes).into_iter().flatten().flatten() {
            if entry
                .file_name()
                .to_str()
                .is_some_and(|n| n.starts_with(&own))
            {
                gone.push(entry.path());
            }
        }
        let dir = nodes.join(&self.id);
        for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            gone.push(entry.path());
        }
        let mut removed = 0;
        for path in &gone {
            removed += usize::from(std::fs::remove_file(path).is_ok());
        }
        removed += usize::from(std::fs::remove_dir(&dir).is_ok());
        if removed > 0 {
            tracing::info!(team = %team, node = %self.id, files = removed,
                "removed what iceoryx2's cleanup left of a node killed mid-creation");
        }
    }
}
