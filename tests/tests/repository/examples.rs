//! The examples run as their docs say: `two_members` of cdm-iox started as two processes (the
//! leader side first, as Terminal 1, then the follower, as Terminal 2) over real iceoryx2 shared
//! memory, each under a watchdog deadline; both exit 0 having exchanged every tick's state, and
//! the team leaves nothing behind. The example scenarios under `examples/` are certified SAFE
//! by `orchestrator plan`, with the margins the README quotes.

use std::process::Command;
use std::time::Duration;

use integration_tests::{bin, describe, example, run, spawn, unique_team};

use integration_tests::support;
use support::TeamFootprint;

/// Generous: the machine is shared; the exchange itself takes milliseconds.
const DEADLINE: Duration = integration_tests::deadline::SHORT;
const TICKS: u64 = 5;

fn side(role: &str, team: &str) -> Command {
    let mut c = Command::new(example("cdm-iox", "two_members"));
    c.args([role, "--team", team, "--ticks", &TICKS.to_string()]);
    c
}

#[test]
fn two_members_exchange_every_tick_and_leave_nothing() {
    let team = unique_team("two_members");
    let mut leader = spawn(&mut side("leader", &team));
    leader.wait_for_output("waiting for member 1", DEADLINE);
    let mut footprint = TeamFootprint::record(&team, [leader.id()]);
    let mut follower = spawn(&mut side("follower", &team));
    footprint.absorb(TeamFootprint::record(&team, [follower.id()]));
    let (l, f) = (leader.finish(DEADLINE), follower.finish(DEADLINE));
    assert!(l.status.success(), "leader side:\n{}", describe(&l));
    assert!(f.status.success(), "follower side:\n{}", describe(&f));
    let (l_out, f_out) = (
        String::from_utf8_lossy(&l.stdout),
        String::from_utf8_lossy(&f.stdout),
    );
    // The leader side read both members' states of every tick; the follower heard the leader's
    // state of every tick before its last and flew on it (its gap to the leader shrinks).
    for k in 0..=TICKS {
        let x0 = format!(
            "tick {k}: member 0 x = {:.3} m, member 1 x = ",
            0.1 * k as f64
        );
        assert!(l_out.contains(&x0), "no `{x0}` in:\n{}", describe(&l));
    }
    for k in 1..=TICKS {
        let heard = format!(
            "tick {k}: heard member 0 at x = {:.3} m (tick {})",
            0.1 * (k - 1) as f64,
            k - 1
        );
        assert!(f_out.contains(&heard), "no `{heard}` in:\n{}", describe(&f));
    }
    let gaps: Vec<f64> = l_out
        .lines()
        .filter_map(|line| line.split("gap ").nth(1)?.strip_suffix(" m")?.parse().ok())
        .collect();
    assert_eq!(gaps.len() as u64, TICKS + 1, "{}", describe(&l));
    assert!(gaps.windows(2).all(|w| w[1] < w[0]), "gaps {gaps:?}");
    assert!(
        f_out.contains(&format!(
            "stopped by the team (Finished) after tick {TICKS}"
        )),
        "{}",
        describe(&f)
    );
    footprint.assert_nothing_left();
}

/// `examples/airspace10.toml` (README "Geofences and obstacles"): SAFE, with the fence's and
/// each obstacle's smallest margin printed.
#[test]
fn the_airspace_example_is_certified_safe_with_its_margins() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/airspace10.toml");
    let out = run(
        Command::new(bin("orchestrator")).args(["plan", "--scenario", path]),
        integration_tests::deadline::FLIGHT,
    );
    assert_eq!(out.status.code(), Some(0), "{}", describe(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for line in [
        "    fence (edge 1)             59.343 m  member 3 at t = 0.00 s (segment 1)",
        "    obstacle \"tower\"           41.014 m  member 9 at t = 60.00 s (segment 1)",
        "    obstacle \"mast\"           194.797 m  member 2 at t = 60.00 s (segment 1)",
    ] {
        assert!(
            stdout.lines().any(|l| l == line),
            "no line `{line}` in:\n{}",
            describe(&out)
        );
    }
}
