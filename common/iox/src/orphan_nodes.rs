//! Dead iceoryx2 nodes of this user that name no team: only their monitor files are left
//! (`<prefix><id>.node_monitor`, `..._owner_lock`, `..._context` in `<root>/nodes`), no details.
//!
//! iceoryx2 0.10 writes a node's details before its monitor and removes them before the monitor
//! when the node is dropped or cleaned, so a process killed (SIGKILL, `timeout`) between the two
//! steps of a drop or of a cleanup leaves exactly this. iceoryx2 cannot remove such a node
//! itself: without details it cleans with its default configuration (another root), and the
//! scan of teams skips it (no name, no team). They pile up (seen: ~770 such nodes, ~2,300 files,
//! on a CI machine). A node is removed only when its files are in this user's root (checked by
//! the caller: `ownership::check_root`), iceoryx2 reads no details for it, its directory holds
//! no service or port tag (a node with ports is left to iceoryx2), and the process that created
//! it no longer exists (its pid is in its id). A live node, even one being created (its details
//! come first), is never touched.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use super::creator::creator_is_dead;
use super::{iox2_location, iox2_root};

/// The suffix iceoryx2 0.10 gives a node's monitor files (`global.node.monitor_suffix`).
const MONITOR_SUFFIX: &str = ".node_monitor";

/// Removes the monitor files (and the empty details directory) of every dead node of this user
/// that iceoryx2 reads no details for. `described` holds the ids of the nodes iceoryx2 listed
/// with details, or as alive; they are never touched. Returns how many nodes were removed.
pub(super) fn remove(described: &BTreeSet<u128>) -> usize {
    let nodes = Path::new(iox2_root()).join("nodes");
    let mut removed = 0;
    for (id, files) in monitor_files(&nodes) {
        if described.contains(&id) || !creator_is_dead(&id.to_string()) {
            continue;
        }
        let dir = nodes.join(id.to_string());
        let entries: Vec<_> = std::fs::read_dir(&dir)
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.path())
            .collect();
        if entries.iter().any(|p| is_tag(p)) {
            tracing::warn!(node = id, dir = %dir.display(),
                "a dead node without details still has service or port tags; left alone");
            continue;
        }
        let mut gone = 0;
        for path in files.iter().chain(&entries) {
            gone += usize::from(std::fs::remove_file(path).is_ok());
        }
        let _ = std::fs::remove_dir(&dir);
        if gone > 0 {
            removed += 1;
            tracing::info!(
                node = id,
                files = gone,
                "removed the monitor files of a dead iceoryx2 node of no known team"
            );
        }
    }
    removed
}

/// The monitor files under `nodes`, by node id (sorted).
fn monitor_files(nodes: &Path) -> BTreeMap<u128, Vec<std::path::PathBuf>> {
    let prefix = iox2_location().prefix.as_str();
    let mut out: BTreeMap<u128, Vec<std::path::PathBuf>> = BTreeMap::new();
    for entry in std::fs::read_dir(nodes).into_iter().flatten().flatten() {
        let name = entry.file_name();
        let Some(id) = name.to_str().and_then(|n| monitor_id(n, prefix)) else {
            continue;
        };
        if entry.file_type().is_ok_and(|t| t.is_file()) {
            out.entry(id).or_default().push(entry.path());
        }
    }
    out
}

/// The node id in a monitor file's name: `<prefix><decimal id>.node_monitor[_owner_lock|_context]`.
fn monitor_id(name: &str, prefix: &str) -> Option<u128> {
    let (id, kind) = name.strip_prefix(prefix)?.split_once(MONITOR_SUFFIX)?;
    let known = ["", "_owner_lock", "_context"].contains(&kind);
    (known && !id.is_empty() && id.bytes().all(|b| b.is_ascii_digit()))
        .then(|| id.parse().ok())
        .flatten()
}

/// A service or port tag iceoryx2 keeps in a node's directory.
fn is_tag(path: &Path) -> bool {
    path.file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.ends_with(".service_tag") || n.ends_with(".port_tag"))
}

#[cfg(test)]
mod tests {
    use super::monitor_id;

    #[test]
    fn monitor_file_names_give_their_node_id() {
        let p = "cdm0_";
        assert_eq!(monitor_id("cdm0_1234.node_monitor", p), Some(1234));
        assert_eq!(
            monitor_id("cdm0_1234.node_monitor_owner_lock", p),
            Some(1234)
        );
        assert_eq!(monitor_id("cdm0_1234.node_monitor_context", p), Some(1234));
        for other in [
            "cdm0_1234.details",
            "cdm0_12a4.node_monitor",
            "cdm1_1234.node_monitor",
            "cdm0_.node_monitor",
            "cdm0_1234.node_monitor_x",
            "1234",
        ] {
            assert_eq!(monitor_id(other, p), None, "{other}");
        }
    }
}
