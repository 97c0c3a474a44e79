//! The crate layering of ARCHITECTURE.md, held by the manifests and checked here from
//! `cargo metadata`: only `cdm-iox` depends on iceoryx2, only `cdm-math` on nalgebra,
//! only `cdm-zenoh` on zenoh, only `cdm-rosbag` and `cdm-recording` on mcap, only `cdm-ros2`
//! on ros2-client; the core crates' whole dependency trees have no iceoryx2, zenoh,
//! ros2-client, arrow, clap or tracing-subscriber (they are usable as libraries on their own),
//! the pure model's not even libc or sha2, and each core crate depends only on the core crates
//! below it.

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
    // MCAP is two files' format: a run as a ROS 2 bag, and a real-time member's recording.
    for (lib, owners) in [
        ("iceoryx2", &["cdm-iox"][..]),
        ("nalgebra", &["cdm-math"]),
        ("zenoh", &["cdm-zenoh"]),
        ("mcap", &["cdm-recording", "cdm-rosbag"]),
        ("ros2-client", &["cdm-ros2"]),
    ] {
        let direct: Vec<&String> = members
            .iter()
            .filter(|m| deps.get(*m).is_some_and(|d| d.contains(lib)))
            .collect();
        assert_eq!(
            direct,
            owners.to_vec(),
            "workspace crates depending on {lib} directly"
        );
    }
    for core in CORE_LAYERS.iter().flat_map(|layer| layer.iter()) {
        let tree = closure(&deps, core);
        for banned in [
            "iceoryx2",
            "zenoh",
            "ros2-client",
            "arrow-array",
            "parquet",
            "clap",
            "tracing-subscriber",
        ] {
            assert!(!tree.contains(banned), "{core}'s tree has {banned}");
        }
    }
    let model = closure(&deps, "cdm-model");
    for banned in ["libc", "sha2", "toml", "serde_json", "tracing"] {
        assert!(!model.contains(banned), "cdm-model's tree has {banned}");
    }
    assert!(
        model.contains("nalgebra"),
        "the check sees the model's tree: {model:?}"
    );
}

/// The core crates, bottom to top: a crate depends only on crates of the layers below its own.
const CORE_LAYERS: &[&[&str]] = &[
    &["cdm-math", "cdm-files"],
    &["cdm-model"],
    &["cdm-scenario"],
    &["cdm-trajectory", "cdm-records"],
    &["cdm-engine"],
    &["cdm-certificates"],
    &["cdm-simulate"],
];

#[test]
fn each_core_crate_depends_only_on_core_crates_below_it() {
    let (deps, members) = graph();
    for (k, layer) in CORE_LAYERS.iter().enumerate() {
        let below: BTreeSet<&str> = CORE_LAYERS[..k]
            .iter()
            .flat_map(|l| l.iter().copied())
            .collect();
        for core in *layer {
            assert!(members.contains(*core), "{core} is a workspace member");
            let ours: Vec<&String> = (deps[*core].iter())
                .filter(|d| members.contains(*d) && !below.contains(d.as_str()))
                .collect();
            assert!(ours.is_empty(), "{core} depends on {ours:?}, not below it");
        }
    }
}
