//! The pre-flight certificate as `plan`, `simulate` and `export` print it.

use cdm_certificates::airspace_certificate::{AirspaceCertificate, ClearanceKind};
use cdm_certificates::certificate::{Certificate, PhaseCertificate};

pub fn print_certificate(c: &Certificate) {
    out!(
        "pre-flight certificate: {} ({} agents)",
        c.scenario,
        c.agents
    );
    out!(
        "  lambda_1(U_D) min       {:.4} at t = {:.2} s",
        c.numbers.lambda1_min,
        c.numbers.t_lambda1_min_s
    );
    out!("  lambda_CD,min           {:.4}", c.numbers.lambda_cd_min);
    out!(
        "  D_B, D_S                {:.4} m, {:.4} m",
        c.numbers.d_b_m,
        c.numbers.d_s_m
    );
    out!("  eps                     {} m", c.numbers.eps_m);
    out!("  delta_max (eq. 35)      {:.4} m", c.numbers.delta_max_m);
    out!("  delta (eq. 38)          {:.4} m", c.numbers.delta_m);
    out!(
        "  gains stability margin  {:.4} (eq. 26)",
        c.gains_stability_margin
    );
    out!(
        "  t_total_s               {} s (max follower deviation {:.4} m)",
        c.t_total_s,
        c.max_follower_deviation_m
    );
    out!("  T_threshold             {:.2} s", c.t_threshold_s);
    match (c.max_link_delay_ms, c.max_link_delay_at_least) {
        (Some(ms), false) => {
            out!("  max link delay          {ms} ms (E_max <= delta, every state that late)")
        }
        (Some(ms), true) => out!(
            "  max link delay          at least {ms} ms (E_max <= delta at every delay searched)"
        ),
        (None, _) => out!("  max link delay          none (E_max > delta even without delay)"),
    }
    if let Some(rows) = &c.segments {
        print_phases(rows);
    }
    if let Some(a) = &c.airspace {
        print_airspace(a);
    }
    out!("verdict: {}", c.verdict);
    for r in &c.reasons {
        out!("  - {r}");
    }
}

/// A mission's phases, one line each.
fn print_phases(rows: &[PhaseCertificate]) {
    out!("  mission phases:");
    out!(
        "    phase        from (s)  to (s)   lambda_1 min (t s)    E_max (m)  T_threshold  verdict"
    );
    for r in rows {
        out!(
            "    {:<11} {:>8.1}  {:>7.1}  {:>7.4} ({:>7.1})  {:>10.4}  {:>9.2} s  {}",
            r.name,
            r.t_start_s,
            r.t_end_s,
            r.lambda1_min,
            r.t_lambda1_min_s,
            r.max_follower_deviation_m,
            r.t_threshold_s,
            r.verdict
        );
        if let Some(d) = r.min_ground_separation_m {
            out!("      ground spots at least {d:.3} m apart (needs 2 (eps + delta))");
        }
    }
}

/// The airspace's smallest margins: the fence's worst side, then every obstacle.
fn print_airspace(a: &AirspaceCertificate) {
    out!(
        "  airspace: smallest margins of the balls of eps + delta = {:.4} m (negative: breached)",
        a.radius_m
    );
    let rows = a.fence().into_iter().chain(
        a.clearances
            .iter()
            .filter(|c| c.kind == ClearanceKind::Obstacle),
    );
    for c in rows {
        let what = if c.kind == ClearanceKind::Fence {
            format!("fence ({})", c.name)
        } else {
            c.label()
        };
        out!(
            "    {what:<22} {:>10.3} m  member {} at t = {:.2} s ({})",
            c.margin_m,
            c.agent,
            c.t_s,
            c.phase
        );
    }
    if let Some(s) = &a.suggestion {
        print_suggestion(s);
    }
}

/// `plan --suggest`: the offsets that clear each breach, and why no time scaling does.
fn print_suggestion(s: &cdm_certificates::airspace_certificate::Suggestion) {
    if s.offsets.is_empty() {
        out!("  suggest: nothing to clear (no margin is negative)");
        return;
    }
    out!("  suggest (every height above the ground moved; ground spots kept):");
    let offset = |v: Option<f64>, verb: &str| {
        v.map_or(format!("no {verb} clears it"), |d| {
            format!("{verb} by {d:.3} m")
        })
    };
    for o in &s.offsets {
        out!(
            "    {:<22} {}; {}",
            o.what,
            offset(o.raise_m, "raise"),
            offset(o.lower_m, "lower")
        );
    }
    out!("    time: {}", s.time_scaling_note);
    for n in &s.notes {
        out!("    - {n}");
    }
}
