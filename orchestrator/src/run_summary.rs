//! The paragraph printed after a flight (`simulate`, `launch`, `replay`): verdict, margins, the
//! first violation, the airspace and the losses.

use std::path::Path;
use std::time::Instant;

use cdm_exit::Exit;
use cdm_model::outcome::Verdict;
use cdm_records::audit::AuditReport;

/// One-paragraph summary of a run.
pub fn summary(what: &str, r: &AuditReport, started: Instant, dir: &Path, quiet: bool) {
    let wall = started.elapsed().as_secs_f64();
    if quiet {
        out!("{}", r.verdict);
        return;
    }
    // No rate for a run that flew no tick (it would read "inf" or "NaN").
    let rate = if r.ticks > 0 {
        format!(" ({:.0} ticks/s)", r.ticks as f64 / wall.max(1e-9))
    } else {
        String::new()
    };
    out!(
        "{what}: {} agents, {} ticks in {:.2} s{rate}, verdict {}",
        r.agents,
        r.ticks,
        wall,
        r.verdict
    );
    // A run that flew no tick has no margins (they would read "inf").
    if r.ticks > 0 {
        out!(
            "  max deviation {:.4} m (delta {:.4} m), min separation {:.4} m (2 eps {} m), min boundary distance {:.4} m, lambda_1 min {:.4} (lambda_CD,min {:.4})",
            r.max_deviation_m, r.numbers.delta_m, r.min_separation_m, 2.0 * r.numbers.eps_m, r.min_boundary_distance_m, r.lambda1_min_run, r.numbers.lambda_cd_min
        );
    }
    if !r.violations.is_empty() {
        let v = &r.violations[0];
        out!(
            "  {} violation(s), first: {} at tick {} (t = {:.2} s), agents {:?}, value {:.4} against the limit {:.4}",
            r.violations.len(),
            v.label(),
            v.tick,
            v.t_s,
            v.agents,
            v.value,
            v.limit
        );
    }
    airspace_summary(r);
    if let Some(f) = &r.fault {
        out!("  fault: {}", f.message);
    }
    if !r.losses.is_empty() {
        let ids: Vec<String> = r
            .losses
            .iter()
            .map(|l| format!("{} from tick {}", l.id, l.tick))
            .collect();
        let switched: usize = r.losses.iter().map(|l| l.retriangulated.len()).sum();
        let degraded: usize = r.losses.iter().map(|l| l.degraded.len()).sum();
        out!(
            "  lost {} member(s) ({}): {switched} follower(s) re-triangulated, {degraded} degraded to the plan",
            r.losses.len(),
            ids.join(", ")
        );
    }
    out!("  run directory: {}", dir.display());
}

/// The airspace's smallest margins and its breaches by name: the first breach of
/// each fence side and obstacle; nothing without a fence or obstacles.
fn airspace_summary(r: &AuditReport) {
    let margins: Vec<String> = [
        ("fence", r.min_fence_margin_m),
        ("obstacle", r.min_obstacle_margin_m),
    ]
    .into_iter()
    .filter_map(|(what, m)| m.map(|m| format!("{what} margin {m:.4} m")))
    .collect();
    if r.ticks > 0 && !margins.is_empty() {
        out!("  airspace (balls of eps): {}", margins.join(", "));
    }
    let mut named = std::collections::BTreeSet::new();
    for v in r.violations.iter().filter(|v| v.name.is_some()) {
        if named.insert(v.label()) {
            out!(
                "  {}: agent {:?} from t = {:.2} s",
                v.label(),
                v.agents,
                v.t_s
            );
        }
    }
}

/// Exit code of a finished run.
pub fn exit_of(r: &AuditReport) -> Exit {
    match r.verdict {
        Verdict::Safe => Exit::Safe,
        Verdict::Unsafe => Exit::Unsafe,
        Verdict::Fault => Exit::Fault,
    }
}
