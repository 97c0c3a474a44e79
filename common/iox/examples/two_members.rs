//! Two members exchanging states over the iceoryx2 transport, in lockstep: the team protocol's
//! ports without the flight. Terminal 1 creates the team (the orchestrator's part: every
//! service, the clock) and is member 0, a leader flying a straight line at 1 m/s; Terminal 2 is
//! member 1, a follower that reads member 0's state of tick k and publishes its own state of
//! tick k + 1, closing the gap to a point 2 m behind the leader. Terminal 1 grants one tick at a
//! time, reads both members' states of that tick, and stops the team after the last tick.
//!
//! How to run (either terminal may start first; each waits up to 60 s for the other):
//!   Terminal 1: cargo run --release -p cdm-iox --example two_members -- leader
//!   Terminal 2: cargo run --release -p cdm-iox --example two_members -- follower
//! Options (both sides alike): `--team NAME` (default `two-members`), `--ticks K` (default 10:
//! ticks 0..=K). Exit codes: 0 the exchange finished, 2 bad arguments, 3 a transport error or a
//! deadline (the message says which).
//!
//! Output of one run with `--ticks 5` (Terminal 1, then Terminal 2):
//! ```text
//! team two-members created; waiting for member 1 (Terminal 2)
//! tick 0: member 0 x = 0.000 m, member 1 x = -3.000 m, gap 3.000 m
//! tick 1: member 0 x = 0.100 m, member 1 x = -2.850 m, gap 2.950 m
//! tick 2: member 0 x = 0.200 m, member 1 x = -2.703 m, gap 2.903 m
//! tick 3: member 0 x = 0.300 m, member 1 x = -2.557 m, gap 2.857 m
//! tick 4: member 0 x = 0.400 m, member 1 x = -2.415 m, gap 2.815 m
//! tick 5: member 0 x = 0.500 m, member 1 x = -2.274 m, gap 2.774 m
//! stopped the team after tick 5; member 1 left
//! ```
//! ```text
//! joined team two-members as member 1, reading member 0
//! tick 0: published x = -3.000 m
//! tick 1: heard member 0 at x = 0.000 m (tick 0), published x = -2.850 m
//! tick 2: heard member 0 at x = 0.100 m (tick 1), published x = -2.703 m
//! tick 3: heard member 0 at x = 0.200 m (tick 2), published x = -2.557 m
//! tick 4: heard member 0 at x = 0.300 m (tick 3), published x = -2.415 m
//! tick 5: heard member 0 at x = 0.400 m (tick 4), published x = -2.274 m
//! stopped by the team (Finished) after tick 5
//! ```

use std::collections::BTreeMap;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use cdm_iox::{MemberPorts, OrchestratorPorts, TeamLayout, TeamName, TransportError};
use cdm_runtime::messages::{ClockCommand, ClockMsg, StateMsg, StopReason};

/// Both sides must agree on it: a member whose scenario hash differs is refused.
const SCENARIO_HASH: u64 = 0x2_6d65_6d62;
const LEADER: u32 = 0;
const FOLLOWER: u32 = 1;
/// Simulation time of one tick (s): time is tick x dt, never the wall clock.
const DT_S: f64 = 0.1;
/// The leader's speed along x (m/s).
const SPEED_MPS: f64 = 1.0;
/// Where the follower starts and the distance it keeps behind the leader (m).
const FOLLOWER_START_X_M: f64 = -3.0;
const FOLLOWER_GAP_M: f64 = 2.0;
/// The follower's gain towards its place behind the leader (1/s).
const GAIN_PER_S: f64 = 0.5;
/// How long either side waits for the other, and for each tick.
const DEADLINE: Duration = Duration::from_secs(60);
const POLL: Duration = Duration::from_millis(50);

/// The two members' states: position in `state[0..3]`, velocity in `state[3..6]` (the 12-state
/// model's order); the rest stays zero.
fn state_at_x(x_m: f64, vx_mps: f64) -> [f64; 12] {
    let mut s = [0.0; 12];
    s[0] = x_m;
    s[3] = vx_mps;
    s
}

#[derive(Debug)]
struct Args {
    leader: bool,
    team: TeamName,
    ticks: u64,
}

/// Why the command line is refused (exit 2).
#[derive(Debug, thiserror::Error)]
enum UsageError {
    #[error("expected `leader` or `follower`, got {0:?}")]
    Side(Option<String>),
    #[error("{0} needs a value")]
    NoValue(String),
    #[error("--ticks {value}: {error}")]
    Ticks {
        value: String,
        error: std::num::ParseIntError,
    },
    #[error("unknown option {0}")]
    Unknown(String),
    #[error("{0}")]
    Team(TransportError),
}

fn parse_args() -> Result<Args, UsageError> {
    let mut args = std::env::args().skip(1);
    let leader = match args.next().as_deref() {
        Some("leader") => true,
        Some("follower") => false,
        other => return Err(UsageError::Side(other.map(str::to_owned))),
    };
    let (mut team, mut ticks) = ("two-members".to_owned(), 10);
    while let Some(flag) = args.next() {
        let Some(value) = args.next() else {
            return Err(UsageError::NoValue(flag));
        };
        match flag.as_str() {
            "--team" => team = value,
            "--ticks" => {
                ticks = value
                    .parse()
                    .map_err(|error| UsageError::Ticks { value, error })?
            }
            _ => return Err(UsageError::Unknown(flag)),
        }
    }
    let team = TeamName::new(&team).map_err(UsageError::Team)?;
    Ok(Args {
        leader,
        team,
        ticks,
    })
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!(
                "two_members: {e}\nusage: two_members leader|follower [--team NAME] [--ticks K]"
            );
            return ExitCode::from(2);
        }
    };
    let outcome = if args.leader {
        lead(&args.team, args.ticks)
    } else {
        follow(&args.team)
    };
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("two_members: {e}");
            ExitCode::from(3)
        }
    }
}

/// What went wrong, with the transport error as its source.
#[derive(Debug, thiserror::Error)]
enum ExchangeError {
    #[error("transport: {0}")]
    Transport(#[from] TransportError),
    #[error("gave up after {deadline:?}: {0}", deadline = DEADLINE)]
    Deadline(String),
}

/// Terminal 1: the team's creator and member 0.
fn lead(team: &TeamName, ticks: u64) -> Result<(), ExchangeError> {
    let ins = BTreeMap::from([(FOLLOWER, vec![LEADER])]);
    let layout = TeamLayout::new(vec![LEADER, FOLLOWER], ins, 1)?.with_scenario_hash(SCENARIO_HASH);
    let mut orch = OrchestratorPorts::create(team, &layout)?;
    let mut me = MemberPorts::open(team, LEADER, SCENARIO_HASH, &[], &[FOLLOWER])?;
    println!("team {team} created; waiting for member {FOLLOWER} (Terminal 2)");
    until(|| Ok(orch.readiness().is_complete()), "member 1 to join")?;
    for k in 0..=ticks {
        orch.publish_clock(ClockMsg::run(k, SCENARIO_HASH))?;
        let x = SPEED_MPS * DT_S * k as f64;
        me.publish(StateMsg::ok(
            k,
            SCENARIO_HASH,
            LEADER,
            state_at_x(x, SPEED_MPS),
        ))?;
        // The orchestrator's part: read both members' states of tick k.
        let mut of_tick: BTreeMap<u32, f64> = BTreeMap::new();
        until(
            || {
                orch.receive_states(|s| {
                    if s.tick == k {
                        of_tick.insert(s.id, s.state[0]);
                    }
                })?;
                if of_tick.len() < 2 {
                    orch.wait(POLL)?;
                }
                Ok(of_tick.len() == 2)
            },
            &format!("both states of tick {k}"),
        )?;
        let (x0, x1) = (of_tick[&LEADER], of_tick[&FOLLOWER]);
        println!(
            "tick {k}: member 0 x = {x0:.3} m, member 1 x = {x1:.3} m, gap {:.3} m",
            x0 - x1
        );
    }
    orch.publish_clock(ClockMsg::stop(ticks, SCENARIO_HASH, StopReason::Finished))?;
    // Keep the services until the follower has read the stop and left.
    until(
        || Ok(orch.readiness().not_joined().contains(&FOLLOWER)),
        "member 1 to leave",
    )?;
    println!("stopped the team after tick {ticks}; member {FOLLOWER} left");
    drop(me);
    orch.shutdown()?;
    Ok(())
}

/// Terminal 2: member 1, reading member 0.
fn follow(team: &TeamName) -> Result<(), ExchangeError> {
    let mut me = None;
    until(
        || match MemberPorts::open(team, FOLLOWER, SCENARIO_HASH, &[LEADER], &[]) {
            Ok(ports) => {
                me = Some(ports);
                Ok(true)
            }
            // Terminal 1 has not created the team yet.
            Err(TransportError::TeamNotFound { .. }) => {
                std::thread::sleep(POLL);
                Ok(false)
            }
            Err(e) => Err(e.into()),
        },
        "the team (Terminal 1)",
    )?;
    let Some(mut me) = me else {
        unreachable!("`until` returned Ok only once the ports were open")
    };
    println!("joined team {team} as member {FOLLOWER}, reading member {LEADER}");
    let mut follower = Follower::default();
    let mut last_progress = Instant::now();
    loop {
        let mut stop = None;
        me.receive_clock(|c| match c.command() {
            ClockCommand::Run => follower.granted = Some(c.grant_tick),
            ClockCommand::Stop(reason) => stop = Some(reason),
            // Real-time starts and arm orders are for real-time / MAVLink teams, not this one.
            ClockCommand::Realtime { .. } | ClockCommand::Arm => {}
        })?;
        me.receive_neighbors(|s| {
            follower.heard.insert(s.tick, s.state[0]);
        })?;
        while let Some(msg) = follower.next_state() {
            me.publish(msg)?;
            last_progress = Instant::now();
        }
        if let Some(reason) = stop {
            let last = follower.next_tick.saturating_sub(1);
            println!("stopped by the team ({reason:?}) after tick {last}");
            return Ok(());
        }
        if last_progress.elapsed() > DEADLINE || !me.orchestrator_alive() {
            return Err(ExchangeError::Deadline(format!(
                "no grant or state for tick {} (is Terminal 1 still running?)",
                follower.next_tick
            )));
        }
        me.wait(POLL)?;
    }
}

/// The follower's decisions, apart from its ports: which tick it may publish and its state.
#[derive(Debug)]
struct Follower {
    /// Newest tick the clock allows.
    granted: Option<u64>,
    /// The leader's x by tick, until used.
    heard: BTreeMap<u64, f64>,
    /// The tick of the next state to publish, and the state of the tick before.
    next_tick: u64,
    x_m: f64,
}

impl Default for Follower {
    fn default() -> Self {
        Self {
            granted: None,
            heard: BTreeMap::new(),
            next_tick: 0,
            x_m: FOLLOWER_START_X_M,
        }
    }
}

impl Follower {
    /// The state of the next tick, once it is granted and (after tick 0) the leader's state of
    /// the tick before is in.
    fn next_state(&mut self) -> Option<StateMsg> {
        let k = self.next_tick;
        if self.granted? < k {
            return None;
        }
        let mut vx = 0.0;
        if k > 0 {
            let leader_x = self.heard.remove(&(k - 1))?;
            vx = GAIN_PER_S * (leader_x - FOLLOWER_GAP_M - self.x_m) + SPEED_MPS;
            self.x_m += vx * DT_S;
            println!(
                "tick {k}: heard member 0 at x = {leader_x:.3} m (tick {}), published x = {:.3} m",
                k - 1,
                self.x_m
            );
        } else {
            println!("tick 0: published x = {:.3} m", self.x_m);
        }
        self.next_tick += 1;
        Some(StateMsg::ok(
            k,
            SCENARIO_HASH,
            FOLLOWER,
            state_at_x(self.x_m, vx),
        ))
    }
}

/// Calls `step` until it returns true; fails after [`DEADLINE`] naming `what` it waited for.
fn until(
    mut step: impl FnMut() -> Result<bool, ExchangeError>,
    what: &str,
) -> Result<(), ExchangeError> {
    let start = Instant::now();
    while !step()? {
        if start.elapsed() > DEADLINE {
            return Err(ExchangeError::Deadline(format!("waiting for {what}")));
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    Ok(())
}
