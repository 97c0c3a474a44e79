//! `view RUN_DIR --foxglove`: a finished run played to Foxglove at its own pace (simulation
//! time on the wall clock), through the same server and topics as a live launch. The run is
//! read back by cdm-report's reader (scenario.toml, audit.json, telemetry), one tick at a time.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use cdm_model::outcome::Verdict;
use cdm_report::data::{read_audit, stream_ticks};
use cdm_scenario::{Checks, Scenario};

use crate::{FoxgloveError, FoxgloveLive, FoxgloveOptions, FoxgloveSummary};

/// Plays the run in `dir` once a client is connected, then returns (or as soon as `stop` is
/// set). `on_listening` is told the server's address once it listens.
pub fn replay(
    dir: &Path,
    o: &FoxgloveOptions,
    stop: &AtomicBool,
    on_listening: impl FnOnce(std::net::SocketAddr),
) -> Result<FoxgloveSummary, FoxgloveError> {
    let run = |e: String| FoxgloveError::Run(e);
    let scenario = Scenario::load(&dir.join("scenario.toml"), Checks::Member)
        .map_err(|e| run(e.to_string()))?;
    let audit = read_audit(&dir.join("audit.json")).map_err(|e| run(e.to_string()))?;
    let mut live = FoxgloveLive::start(o, &scenario)?;
    on_listening(live.addr());
    while live.clients() == 0 && !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(50));
    }
    // The verdict as it stood at each tick: UNSAFE from the first violation on.
    let unsafe_from = audit.first_violation.map(|(_, t)| t);
    let verdict_at = |t_s: f64| match unsafe_from {
        Some(at) if t_s >= at => Verdict::Unsafe,
        _ => Verdict::Safe,
    };
    let started = Instant::now();
    stream_ticks(dir, &scenario, &audit.losses, |tp| {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        let due = started + Duration::from_secs_f64(tp.t_s.max(0.0));
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        live.tick(
            tp.tick,
            tp.t_s,
            (tp.pos, tp.ht),
            |k| tp.alive[k],
            verdict_at(tp.t_s),
        );
    })
    .map_err(|e| run(e.to_string()))?;
    Ok(live.finish(final_verdict(dir)?))
}

/// audit.json's verdict (SAFE, UNSAFE or FAULT).
fn final_verdict(dir: &Path) -> Result<Verdict, FoxgloveError> {
    let path = dir.join("audit.json");
    let text = cdm_files::read_input(&path, cdm_files::MAX_INPUT_BYTES)
        .map_err(|e| FoxgloveError::Run(e.to_string()))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| FoxgloveError::Run(format!("{}: {e}", path.display())))?;
    let text = v["verdict"].as_str().unwrap_or_default();
    [Verdict::Safe, Verdict::Unsafe, Verdict::Fault]
        .into_iter()
        .find(|k| k.as_str() == text)
        .ok_or_else(|| {
            FoxgloveError::Run(format!(
                "{}: verdict {text:?}: expected SAFE, UNSAFE or FAULT",
                path.display()
            ))
        })
}
