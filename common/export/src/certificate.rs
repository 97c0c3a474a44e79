//! The pre-flight certificate as `plan`, `simulate` and `export` print it.

use cdm_core::mission_certificate::PhaseCertificate;
use cdm_core::simulate::Certificate;
use cdm_team::out;

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
    out!("verdict: {}", c.verdict);
    for r in &c.reasons {
        out!("  - {r}");
    }
}

/// A mission's phases, one line each (issue 26).
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
