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
//! - `cdm-bench sleepers --n N --secs S`: the machine's own floor for real time. N processes that
//!   only sleep to the same 10 ms instants a real-time member keeps (absolute deadlines from one
//!   shared start, the member's `thread::sleep` wait), no exchange and no maths; a wake-up more
//!   than one period after its instant counts as late, as a member's tick does. What launch
//!   --realtime loses beyond this is ours; what this loses is the machine's.
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
    /// The machine's real-time floor: N processes that only sleep to 10 ms instants.
    Sleepers {
        #[arg(long)]
        n: usize,
        #[arg(long, default_value_t = 10.0)]
        secs: f64,
        #[arg(long, default_value_t = 100.0)]
        hz: f64,
    },
    /// One process of `sleepers` (started by it): sleeps to its instants, prints its figures.
    #[command(hide = true)]
    Sleeper {
        /// The shared first instant, nanoseconds since the Unix epoch.
        #[arg(long)]
        start_ns: u128,
        #[arg(long)]
        ticks: u64,
        #[arg(long)]
        hz: f64,
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
        Cmd::Sleepers { n, secs, hz } => sleepers::sleepers(n, secs, hz),
        Cmd::Sleeper {
            start_ns,
            ticks,
            hz,
        } => sleepers::sleeper(start_ns, ticks, hz),
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

mod sleepers {
    use std::io::Read;
    use std::process::{Child, Command, Stdio};
    use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

    /// One sleeper's figures, as it prints them: `ticks late max_late_ms`.
    struct Figures {
        ticks: u64,
        late: u64,
        max_late_ms: f64,
    }

    pub fn sleepers(n: usize, secs: f64, hz: f64) -> Result<(), String> {
        let positive = |x: f64| x.is_finite() && x > 0.0;
        if n == 0 || !positive(secs) || !positive(hz) {
            return Err(format!(
                "sleepers: --n, --secs and --hz must be positive (got {n}, {secs}, {hz})"
            ));
        }
        let ticks = (secs * hz).round() as u64;
        let me = std::env::current_exe().map_err(|e| format!("sleepers: own path: {e}"))?;
        // Every process is started before the first instant (about 2 ms of spawning each), so
        // none begins late because its siblings were still being created.
        let lead = Duration::from_millis(500 + 3 * n as u64);
        let start = SystemTime::now() + lead;
        let start_ns = start
            .duration_since(UNIX_EPOCH)
            .map_err(|e| format!("sleepers: clock: {e}"))?
            .as_nanos();
        let mut children: Vec<Child> = Vec::with_capacity(n);
        for i in 0..n {
            let child = Command::new(&me)
                .args(["sleeper", "--start-ns", &start_ns.to_string()])
                .args(["--ticks", &ticks.to_string(), "--hz", &hz.to_string()])
                .stdout(Stdio::piped())
                .spawn()
                .map_err(|e| format!("sleepers: spawn sleeper {i}: {e}"));
            match child {
                Ok(c) => children.push(c),
                Err(e) => {
                    children.iter_mut().for_each(|c| drop(c.kill()));
                    return Err(e);
                }
            }
        }
        let deadline = Instant::now() + lead + Duration::from_secs_f64(secs * 2.0 + 10.0);
        let figures = collect(children, deadline)?;
        let ticks: u64 = figures.iter().map(|f| f.ticks).sum();
        let late: u64 = figures.iter().map(|f| f.late).sum();
        let max = figures.iter().map(|f| f.max_late_ms).fold(0.0, f64::max);
        println!(
            "sleepers: {n} processes at {hz} Hz for {secs} s: {late} of {ticks} wake-ups late ({:.3} %), latest {max:.1} ms after its instant",
            100.0 * late as f64 / ticks.max(1) as f64
        );
        Ok(())
    }

    /// Waits for every sleeper until `deadline` (then kills the rest) and reads its line.
    fn collect(children: Vec<Child>, deadline: Instant) -> Result<Vec<Figures>, String> {
        let mut out = Vec::with_capacity(children.len());
        let mut failed = None;
        for (i, mut c) in children.into_iter().enumerate() {
            loop {
                match c.try_wait() {
                    Ok(Some(_)) => break,
                    Ok(None) if Instant::now() < deadline => {
                        std::thread::sleep(Duration::from_millis(20))
                    }
                    _ => {
                        let _ = c.kill();
                        let _ = c.wait();
                        failed.get_or_insert(format!("sleeper {i} did not finish in time"));
                        break;
                    }
                }
            }
            let mut line = String::new();
            if let Some(mut so) = c.stdout.take() {
                let _ = so.read_to_string(&mut line);
            }
            let v: Vec<&str> = line.split_whitespace().collect();
            match (v.first(), v.get(1), v.get(2)) {
                (Some(t), Some(l), Some(m)) => out.push(Figures {
                    ticks: t.parse().unwrap_or(0),
                    late: l.parse().unwrap_or(0),
                    max_late_ms: m.parse().unwrap_or(0.0),
                }),
                _ => {
                    failed.get_or_insert(format!("sleeper {i} printed no figures"));
                }
            }
        }
        match failed {
            Some(e) => Err(format!("sleepers: {e}")),
            None => Ok(out),
        }
    }

    pub fn sleeper(start_ns: u128, ticks: u64, hz: f64) -> Result<(), String> {
        let period = Duration::from_secs_f64(1.0 / hz);
        let start = UNIX_EPOCH + Duration::from_nanos(start_ns as u64);
        let (mut late, mut max_late) = (0u64, Duration::ZERO);
        for k in 0..ticks {
            let instant = start + period * k as u32;
            // Already past its instant: no sleep, and the lateness below counts it.
            if let Ok(wait) = instant.duration_since(SystemTime::now()) {
                std::thread::sleep(wait);
            }
            let lateness = SystemTime::now()
                .duration_since(instant)
                .unwrap_or(Duration::ZERO);
            if lateness > period {
                late += 1;
            }
            max_late = max_late.max(lateness);
        }
        println!("{ticks} {late} {:.3}", max_late.as_secs_f64() * 1e3);
        Ok(())
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
