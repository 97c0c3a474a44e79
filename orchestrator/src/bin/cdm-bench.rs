//! Benchmark baselines for BENCHMARKS.md (`scripts/bench.sh` runs them beside `launch`):
//!
//! - `cdm-bench engine --n N --ticks K`: the in-process engine alone (controller, RK4 substeps,
//!   neighbour exchange for all N members; no audit, no telemetry): the floor the arithmetic sets.
//! - `cdm-bench barrier --n N --ticks K`: a bare iceoryx2 central barrier with N processes and no
//!   math: per tick the coordinator wakes every process, each reads its 3 neighbours' samples,
//!   publishes one 128-byte sample and acknowledges; the coordinator waits for all N samples.
//!   This is what a naive one-process-per-member runtime pays per tick.
//!
//! - `cdm-bench command --n N`: the certificate of one `hold` (at 30 % of the flight, moving)
//!   and of one `goto` (every leader 20 m along x from where it holds, default travel time) on
//!   the generated team of N members: what a command costs between its request and its switch.
//!
//! The first two print one line `<what>: N agents, K ticks in S s (R ticks/s)`, `command` one
//! line per command. Every wait has a deadline.

use std::process::ExitCode;
use std::time::Instant;

use cdm_engine::engine::quad_engine;
use cdm_iox::bench_barrier::{barrier, barrier_member};
use cdm_scenario::Scenario;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(about = "Baselines for BENCHMARKS.md: the engine alone and a bare iceoryx2 barrier")]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Tick rate of the in-process engine (arithmetic only) on the generated team of N members.
    Engine {
        #[arg(long)]
        n: usize,
        #[arg(long, default_value_t = 5000)]
        ticks: u64,
    },
    /// Tick rate of a bare iceoryx2 central barrier with N member processes.
    Barrier {
        #[arg(long)]
        n: usize,
        #[arg(long, default_value_t = 5000)]
        ticks: u64,
    },
    /// Certification time of one hold and one goto on the generated team of N members.
    Command {
        #[arg(long)]
        n: usize,
    },
    /// One member of `barrier` (started by it).
    #[command(hide = true)]
    BarrierMember {
        #[arg(long)]
        run: String,
        #[arg(long)]
        n: usize,
        #[arg(long)]
        id: usize,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r: Result<(), String> = match cli.command {
        Cmd::Engine { n, ticks } => engine(n, ticks),
        Cmd::Barrier { n, ticks } => barrier(n, ticks)
            .map(|b| {
                println!(
                    "barrier: {} agents, {} ticks in {:.3} s ({:.0} ticks/s), start-up {:.2} s",
                    b.n,
                    b.ticks,
                    b.secs,
                    b.ticks as f64 / b.secs,
                    b.startup_s
                );
            })
            .map_err(|e| e.to_string()),
        Cmd::Command { n } => command(n),
        Cmd::BarrierMember { run, n, id } => barrier_member(&run, n, id).map_err(|e| e.to_string()),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

fn engine(n: usize, ticks: u64) -> Result<(), String> {
    let s = Scenario::generated(n).map_err(|e| format!("generated --n {n}: {e}"))?;
    let ticks = ticks.min(s.last_tick());
    let mut e = quad_engine(&s);
    let start = Instant::now();
    for _ in 0..ticks {
        e.advance().map_err(|f| format!("engine: {f:?}"))?;
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "engine: {n} agents, {ticks} ticks in {secs:.3} s ({:.0} ticks/s)",
        ticks as f64 / secs
    );
    Ok(())
}

fn command(n: usize) -> Result<(), String> {
    use cdm_certificates::command_certificate::{steer, CommandOutcome};
    use cdm_model::steer::TeamCommand;
    use cdm_records::audit::SafetyNumbers;
    let s = Scenario::generated(n).map_err(|e| format!("generated --n {n}: {e}"))?;
    let numbers = SafetyNumbers::of(&s);
    let mut steering = s.steering();
    let dt = s.dt_s();
    let t_hold = (0.3 * s.plan.flight_end_s() / dt).round() * dt;
    let one = |steering: &mut cdm_model::steer::Steering,
               name: &str,
               c: &TeamCommand,
               t: f64|
     -> Result<(), String> {
        let start = Instant::now();
        let outcome = steer(steering, &s, &numbers, c, t);
        let secs = start.elapsed().as_secs_f64();
        let (verdict, e) = match &outcome {
            CommandOutcome::Accepted(c) => ("accepted", c.max_follower_deviation_m),
            CommandOutcome::Refused(c) => ("refused", c.max_follower_deviation_m),
            CommandOutcome::NotApplicable(why) => return Err(format!("{name}: {why}")),
        };
        println!(
            "command {name}: {n} agents, certified in {secs:.3} s ({verdict}, max follower deviation {e:.4} m)"
        );
        Ok(())
    };
    one(&mut steering, "hold", &TeamCommand::Hold, t_hold)?;
    let plan = steering.plan().clone();
    let t = plan.end_s();
    let here = plan.primary_derivs(t, plan.piece_at(t)).map(|d| d[0]);
    let goals = here.map(|p| p + cdm_math::Vec3::new(20.0, 0.0, 0.0));
    let t_goto = ((t + 1.0) / dt).ceil() * dt;
    one(
        &mut steering,
        "goto",
        &TeamCommand::Goto {
            goals,
            travel_s: None,
        },
        t_goto,
    )
}
