//! The crate layering of ARCHITECTURE.md, held by the manifests and checked here from
//! `cargo metadata`: only `cdm-iox` depends on iceoryx2, only `cdm-math` on nalgebra,
//! only `cdm-zenoh` on zenoh, only `cdm-rosbag` on mcap, only `cdm-ros2` on ros2-client, and the
//! core crate's whole dependency tree has no iceoryx2, zenoh, ros2-client, clap or
//! tracing-subscriber (it is usable as a library on its own).

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

use serde_json::Value;

/// Every package of the build graph: name -> names of its normal (non-dev, non-build) deps.
fn graph() -> (BTreeMap<String, BTreeSet<String>>, BTreeSet<String>) {
    // The host's packages only: the lock file also names other platforms' crates, which a
    // machine that never built for them has not downloaded.
    let rustc = Command::new("rustc")
        .arg("-vV")
        .output()
        .expect("rustc -vV runs");
    let host = String::from_utf8_lossy(&rustc.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("host: ").map(str::to_owned))
        .expect("rustc -vV names the host");
    let out = Command::new(env!("CARGO"))
        .args(["metadata", "--format-version", "1", "--offline"])
        .args(["--filter-platform", &host])
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .output()
        .expect("cargo metadata runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: Value = serde_json::from_slice(&out.stdout).expect("cargo metadata is JSON");
    let name_of: BTreeMap<&str, &str> = meta["packages"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|p| Some((p["id"].as_str()?, p["name"].as_str()?)))
        .collect();
    let members: BTreeSet<String> = meta["workspace_members"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|id| name_of.get(id.as_str()?).map(|n| n.to_string()))
        .collect();
    let mut deps = BTreeMap::new();
    for node in meta["resolve"]["nodes"].as_array().into_iter().flatten() {
        let Some(name) = node["id"].as_str().and_then(|id| name_of.get(id)) else {
            continue;
        };
        let normal: BTreeSet<String> = node["deps"]
            .as_array()
            .into_iter()
            .flatten()
            .filter(|d| {
                d["dep_kinds"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .any(|k| k["kind"].is_null())
            })
            .filter_map(|d| d["pkg"].as_str().and_then(|id| name_of.get(id)))
            .map(|n| n.to_string())
            .collect();
        deps.entry(name.to_string())
            .or_insert_with(BTreeSet::new)
            .extend(normal);
    }
    (deps, members)
}

/// Every package reachable from `root` through normal dependencies.
fn closure(deps: &BTreeMap<String, BTreeSet<String>>, root: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut todo = vec![root.to_string()];
    while let Some(p) = todo.pop() {
        for d in deps.get(&p).into_iter().flatten() {
            if seen.insert(d.clone()) {
                todo.push(d.clone());
            }
        }
    }
    seen
}

#[test]
fn only_the_backends_name_their_libraries_and_the_core_stands_alone() {
    let (deps, members) = graph();
    for (lib, owner) in [
        ("iceoryx2", "cdm-iox"),
        ("nalgebra", "cdm-math"),
        ("zenoh", "cdm-zenoh"),
        ("mcap", "cdm-rosbag"),
        ("ros2-client", "cdm-ros2"),
    ] {
        let direct: Vec<&String> = members
            .iter()
            .filter(|m| deps.get(*m).is_some_and(|d| d.contains(lib)))
            .collect();
        assert_eq!(
            direct,
            vec![owner],
            "workspace crates depending on {lib} directly"
        );
    }
    let core = closure(&deps, "cdm-core");
    for banned in [
        "iceoryx2",
        "zenoh",
        "ros2-client",
        "clap",
        "tracing-subscriber",
    ] {
        assert!(!core.contains(banned), "cdm-core's tree has {banned}");
    }
    assert!(
        core.contains("nalgebra"),
        "the check sees the core's tree: {core:?}"
    );
}
