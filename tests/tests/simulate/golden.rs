//! Golden pin (rapier's golden-hash tests are the model): the telemetry of the built-in paper40
//! flight (`orchestrator simulate`, default options, every tick written) is pinned bit for bit by
//! its SHA-256. Any change to the math, the engine, the step order or the CSV writer that moves a
//! single digit fails here. If a change is meant to alter the flight, update the value in the same commit and
//! say why there.
//!
//! How to run: `cargo test --release -p integration-tests --test simulate -- golden::`.

use integration_tests::support;

use std::time::Duration;

use integration_tests::TempDir;
use sha2::{Digest, Sha256};
use support::{assert_exit, simulate};

/// SHA-256 of telemetry.csv of `orchestrator simulate --out DIR --no-figures --every 1` (paper40,
/// measured on main at 1536876 before the crate split; unchanged since).
const PAPER40_TELEMETRY_SHA256: &str =
    "12e97df9ea3eff93f3ab34acb80ba385102effe70453ebc3127a0dade75f8d59";

/// A paper40 flight takes about a second in release; the rest is slack for a loaded machine.
const DEADLINE: Duration = integration_tests::deadline::FLIGHT;

fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

#[test]
fn paper40_simulate_telemetry_is_pinned() {
    let dir = TempDir::new();
    let out = dir.path().join("sim");
    let o = integration_tests::run(
        &mut simulate(&out, &["--no-figures", "--every", "1"]),
        DEADLINE,
    );
    assert_exit(&o, 0, "simulate paper40");
    let csv = std::fs::read(out.join("telemetry.csv")).expect("telemetry.csv written");
    assert_eq!(sha256_hex(&csv), PAPER40_TELEMETRY_SHA256);
}
