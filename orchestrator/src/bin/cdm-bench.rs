//! Benchmark baselines for BENCHMARKS.md (`scripts/bench.sh` runs them beside `launch`):
//!
//! - `cdm-bench engine --n N --ticks K`: the in-process engine alone (controller, RK4 substeps,
//!   neighbour exchange for all N members; no audit, no telemetry): the floor the arithmetic sets.
//! - `cdm-bench barrier --n N --ticks K`: a bare iceoryx2 central barrier with N processes and no
//!   math: per tick the coordinator wakes every process, each reads its 3 neighbours' samples,
//!   publishes one 128-byte sample and acknowledges; the coordinator waits for all N samples.
//!   This is what a naive one-process-per-member runtime pays per tick.
//!
//! Both print one line `<what>: N agents, K ticks in S s (R ticks/s)`. Every wait has a deadline.

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
