//! A commanded run's commands seen in every output of it, read from its commands.json
//! (`simulate --commands`): paper40 held, refused a goto far too quick for its followers
//! (T_threshold, eq. 34), then landed:
//!
//! - `report` marks each switch on the figures, accepted and refused apart;
//! - replay.html's scene lists the commands for the timeline (the page's counts are checked in
//!   a browser by `viewer.rs`; the bag's `/cdm/commands` by `rosbag.rs`).
//!
//! How to run: `cargo test --release -p integration-tests --test steering -- commands_seen::`.

use std::process::Command;

use integration_tests::{bin, describe, run, simulate, TempDir};

const DEADLINE: std::time::Duration = integration_tests::deadline::FLIGHT;

/// Hold at 30 s, a goto of 1 s at 40 s (refused: eq. 34), land at 50 s.
const HELD_REFUSED_LANDED: &str = r#"[
  {"at_s": 30, "command": "hold"},
  {"at_s": 40, "command": "goto", "goals": [[300, 500, 600], [300, 300, 600], [400, 300, 600]],
   "travel_s": 1},
  {"at_s": 50, "command": "land"}
]"#;

fn orchestrator(args: &[&str]) -> std::process::Output {
    let mut c = Command::new(bin("orchestrator"));
    c.args(args);
    run(&mut c, DEADLINE)
}

#[test]
fn a_commanded_runs_figures_and_replay_show_its_commands() {
    let tmp = TempDir::new();
    let file = tmp.path().join("commands.json");
    std::fs::write(&file, HELD_REFUSED_LANDED).unwrap();
    let run_dir = tmp.path().join("run");
    let source = [
        "--builtin",
        "paper40",
        "--commands",
        file.to_str().unwrap(),
        "--no-figures",
    ];
    let o = run(&mut simulate(&run_dir, &source), DEADLINE);
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let commands: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("commands.json")).unwrap())
            .unwrap();
    let accepted: Vec<bool> = (commands.as_array().unwrap().iter())
        .map(|c| c["accepted"].as_bool().unwrap())
        .collect();
    assert_eq!(accepted, [true, false, true]);

    // The figures: a line at each switch, named accepted or refused.
    let o = orchestrator(&["report", run_dir.to_str().unwrap(), "--quiet"]);
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let svg = std::fs::read_to_string(run_dir.join("fig_separation.svg")).unwrap();
    for label in [
        "hold accepted, t = 30.00 s",
        "goto refused, t = 40.00 s",
        "land accepted, t = 50.00 s",
    ] {
        assert!(svg.contains(label), "fig_separation.svg has no `{label}`");
    }

    // The replay's scene: the commands for the timeline and the status.
    let o = orchestrator(&["view", run_dir.to_str().unwrap(), "--quiet"]);
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let page = std::fs::read_to_string(run_dir.join("replay.html")).unwrap();
    let start = page
        .find(r#"id="cdm-scene""#)
        .expect("the scene's script element");
    let json_start = start + page[start..].find('>').unwrap() + 1;
    let json_end = json_start + page[json_start..].find("</script>").unwrap();
    let scene: serde_json::Value = serde_json::from_str(&page[json_start..json_end]).unwrap();
    let marks: Vec<(String, u64, bool)> = (scene["commands"].as_array().unwrap().iter())
        .map(|c| {
            (
                c["command"].as_str().unwrap().to_owned(),
                c["tick"].as_u64().unwrap(),
                c["accepted"].as_bool().unwrap(),
            )
        })
        .collect();
    let want = [
        ("hold", 3000, true),
        ("goto", 4000, false),
        ("land", 5000, true),
    ]
    .map(|(c, t, a)| (c.to_owned(), t, a));
    assert_eq!(marks, want);
    assert!(scene["commands"][1]["why"]
        .as_str()
        .unwrap()
        .contains("eq. 34"));
}
