//! The core alone, no processes and no shared memory: certify the paper's 40-quadcopter
//! scenario, then fly it with the whole-team engine and audit every tick.
//!
//! How to run: `cargo run --release -p cdm-simulate --example fly_paper40`

use cdm_certificates::certify::certify;
use cdm_model::outcome::Verdict;
use cdm_records::rundir::RunDir;
use cdm_scenario::{Checks, Scenario};
use cdm_simulate::{simulate, SimulateOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let s = Scenario::from_file(cdm_scenario::paper40(), "paper40", Checks::Full)?;
    let c = certify(&s);
    println!(
        "certificate: {} (delta {:.3} m)",
        c.verdict, c.numbers.delta_m
    );
    let out = std::env::temp_dir().join(format!("cdm-example-{}", std::process::id()));
    let dir = RunDir::create(&out, true)?;
    let opts = SimulateOptions {
        every: 1,
        stop_on_violation: false,
        max_ticks: None,
        ..SimulateOptions::default()
    };
    let mut tel = dir.telemetry(opts.every)?;
    let report = simulate(&s, &dir, opts, &mut tel, |_, _| {})?;
    println!(
        "flown: {} ticks, verdict {}, max deviation {:.4} m, min separation {:.3} m ({})",
        report.ticks,
        report.verdict,
        report.max_deviation_m,
        report.min_separation_m,
        out.display()
    );
    std::process::exit(if report.verdict == Verdict::Safe {
        0
    } else {
        1
    })
}
