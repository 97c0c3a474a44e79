//! Python on a team's live bus (`python/cdm_bus.py`, the PyPI `iceoryx2` 0.10 package in the test
//! venv of scripts/test-deps.sh): the Python wire types and iceoryx2 paths are the Rust ones, and
//! `python/examples/watch.py` reads a running team and prints, per tick, the same smallest
//! separation as the audit's function computes from the same states (telemetry.csv).

mod support;

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use cdm_math::{vec3, Vec3};
use integration_tests::{describe, run, spawn, unique_team, TempDir};
use support::python::{python, python_dir};
use support::read_json;
use support::steering::{resume, stopped_team};

/// A Python start-up and one query.
const PYTHON_DEADLINE: Duration = integration_tests::deadline::SHORT;
/// paper40 for 100,001 ticks as processes: ~10 s on two idle cores.
const TEAM_DEADLINE: Duration = integration_tests::deadline::LONG;
/// watch.py's lines: enough ticks to compare. Python drains 40 subscribers more slowly than a
/// fast team publishes, so it completes the ticks it can (the team never waits for it); the
/// buffered last ticks of a finished team complete in any case.
const WATCHED_TICKS: usize = 50;

#[test]
fn python_wire_types_and_paths_are_the_rust_ones() {
    let out = run(
        &mut python(&[
            "-c",
            "import ctypes, cdm_bus as b; r, p = b.bus_paths(); \
             print(r); print(p); \
             print(b.StateMsg.type_name(), ctypes.sizeof(b.StateMsg)); \
             print(b.StateBatch.type_name(), ctypes.sizeof(b.StateBatch), b.STATES_PER_SAMPLE); \
             print(b.ClockMsg.type_name(), ctypes.sizeof(b.ClockMsg))",
        ]),
        PYTHON_DEADLINE,
    );
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = text.lines().collect();
    let cfg = cdm_iox::iceoryx2_config();
    let want = [
        cfg.global.root_path().to_string(),
        cfg.global.prefix.to_string(),
        format!(
            "{} {}",
            cdm_iox::STATE_TYPE_NAME,
            std::mem::size_of::<cdm_runtime::messages::StateMsg>()
        ),
        format!(
            "{} {} {}",
            cdm_iox::STATE_BATCH_TYPE_NAME,
            std::mem::size_of::<cdm_iox::StateBatch>(),
            cdm_iox::STATES_PER_SAMPLE
        ),
        format!(
            "{} {}",
            cdm_iox::CLOCK_TYPE_NAME,
            std::mem::size_of::<cdm_runtime::messages::ClockMsg>()
        ),
    ];
    assert_eq!(
        lines, want,
        "python/cdm_bus.py disagrees with the Rust side"
    );
}

/// Per-tick positions of telemetry.csv, for the ticks asked.
fn positions(path: &Path, ticks: &BTreeMap<u64, f64>) -> BTreeMap<u64, Vec<Vec3>> {
    use std::io::BufRead;
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let last = ticks.keys().next_back().copied().unwrap_or(0);
    let mut out: BTreeMap<u64, Vec<Vec3>> = BTreeMap::new();
    for line in std::io::BufReader::new(file).lines().skip(1) {
        let line = line.unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let f: Vec<&str> = line.split(',').collect();
        let tick: u64 = f[0].parse().unwrap_or(u64::MAX);
        if tick > last {
            break;
        }
        if ticks.contains_key(&tick) {
            let num = |i: usize| f[i].parse::<f64>().unwrap_or(f64::NAN);
            out.entry(tick)
                .or_default()
                .push(vec3([num(4), num(5), num(6)]));
        }
    }
    out
}

#[test]
fn watch_py_reads_a_live_team_like_the_audit() {
    let tmp = TempDir::new();
    let out = tmp.path().join("run");
    let team = unique_team("watch");
    let orch = spawn(integration_tests::launch_loud(&team, &out, &[]).args([
        "--no-figures",
        "--t-total",
        "1000",
    ]));
    let script = python_dir().join("examples").join("watch.py");
    let watched = run(
        &mut python(&[
            script.to_str().unwrap_or_default(),
            "--team",
            &team,
            "--ticks",
            &WATCHED_TICKS.to_string(),
            "--silence",
            "30",
        ]),
        PYTHON_DEADLINE,
    );
    assert_eq!(watched.status.code(), Some(0), "{}", describe(&watched));
    let done = orch.finish(TEAM_DEADLINE);
    assert_eq!(done.status.code(), Some(0), "{}", describe(&done));

    // `tick <k> t <s> min_separation <m> agents <i> <j>`
    let mut seen = BTreeMap::new();
    for line in String::from_utf8_lossy(&watched.stdout).lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        assert!(
            f.len() == 9 && f[0] == "tick" && f[4] == "min_separation",
            "{line}"
        );
        let tick: u64 = f[1].parse().unwrap_or_else(|e| panic!("{line}: {e}"));
        let sep: f64 = f[5].parse().unwrap_or_else(|e| panic!("{line}: {e}"));
        assert!(
            seen.keys().next_back().is_none_or(|&last| tick > last),
            "ticks must come out strictly increasing: {tick} after {:?}",
            seen.keys().next_back()
        );
        seen.insert(tick, sep);
    }
    assert_eq!(
        seen.len(),
        WATCHED_TICKS,
        "one line per tick, no tick twice"
    );
    let states = positions(&out.join("telemetry.csv"), &seen);
    for (tick, sep) in &seen {
        let pos = states
            .get(tick)
            .unwrap_or_else(|| panic!("tick {tick} is not in telemetry.csv"));
        assert_eq!(pos.len(), 40, "tick {tick}");
        // The audit's own function over the same states.
        let (audit_sep, _, _) = cdm_model::safety::min_separation(pos);
        assert!(
            (sep - audit_sep).abs() <= 1e-9,
            "tick {tick}: watch.py {sep} m, audit {audit_sep} m"
        );
    }
}

/// The Python bus steers a live team as `orchestrator command` does (`cdm_bus.command`): a hold
/// is accepted with a switch tick, a goto with two goals is refused in Python before the team is
/// asked, a squeezed goto is UNSAFE, a land is accepted; the run's commands.json lists exactly
/// those three with the switch ticks and verdicts Python got, the team lands and ends, and a
/// command after the end raises NoTeam.
#[test]
fn the_python_bus_steers_a_live_team_like_orchestrator_command() {
    let (_tmp, team, out, orch, stopped) = stopped_team("py_steer");
    let script = format!(
        r#"
import cdm_bus as b
team = "{team}"
def show(what, a):
    print(what, a["answer"], a["switch_tick"], b.ANSWER_EXIT[a["answer"]])
show("hold", b.command(team, "hold"))
try:
    b.command(team, "goto", goals=[[1, 2, 3], [4, 5, 6]])
    print("goto-two-goals sent")
except ValueError as e:
    print("goto-two-goals refused", e)
show("goto", b.command(team, "goto", goals=[[224, 434, 600], [220, 224, 600], [228, 224, 600]]))
show("land", b.command(team, "land"))
"#
    );
    let o = run(&mut python(&["-c", &script]), PYTHON_DEADLINE);
    resume(stopped);
    assert_eq!(o.status.code(), Some(0), "{}", describe(&o));
    let done = orch.finish(TEAM_DEADLINE);
    assert_eq!(done.status.code(), Some(0), "{}", describe(&done));

    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let lines: Vec<Vec<&str>> = text.lines().map(|l| l.split(' ').collect()).collect();
    assert_eq!(lines.len(), 4, "{text}");
    assert_eq!(&lines[1][..2], ["goto-two-goals", "refused"], "{text}");
    let said: Vec<(&str, &str, u64, &str)> = [&lines[0], &lines[2], &lines[3]]
        .iter()
        .map(|f| {
            assert_eq!(f.len(), 4, "{text}");
            (f[0], f[1], f[2].parse().unwrap_or(u64::MAX), f[3])
        })
        .collect();
    assert_eq!(
        said.iter().map(|s| (s.0, s.1, s.3)).collect::<Vec<_>>(),
        [
            ("hold", "accepted", "0"),
            ("goto", "unsafe", "1"),
            ("land", "accepted", "0")
        ],
        "{text}"
    );
    let list = read_json(&out.join("commands.json"));
    let recorded: Vec<(&str, bool, u64)> = (list.as_array().expect("a list").iter())
        .map(|c| {
            (
                c["command"].as_str().unwrap_or_default(),
                c["accepted"].as_bool().unwrap_or_default(),
                c["switch_tick"].as_u64().unwrap_or(u64::MAX),
            )
        })
        .collect();
    let expected: Vec<(&str, bool, u64)> = (said.iter())
        .map(|s| (s.0, s.1 == "accepted", s.2))
        .collect();
    assert_eq!(recorded, expected, "{list:#}");

    let after = run(
        &mut python(&[
            "-c",
            &format!(
                "import cdm_bus as b\ntry:\n    b.command('{team}', 'hold')\nexcept b.NoTeam as e:\n    print('no team', e)"
            ),
        ]),
        PYTHON_DEADLINE,
    );
    assert_eq!(after.status.code(), Some(0), "{}", describe(&after));
    assert!(
        String::from_utf8_lossy(&after.stdout).starts_with("no team"),
        "{}",
        describe(&after)
    );
}
