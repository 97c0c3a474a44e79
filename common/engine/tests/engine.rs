//! The in-process engine: the nonlinear team equals the linear model (feedback linearisation,
//! eqs. 43-46), determinism, and the error of exchanging states once per tick.

use cdm_engine::engine::{chain_engine, max_follower_deviation, quad_engine, AgentFault};
use cdm_math::{Real, Vec3};
use cdm_model::dynamics::{Flat, Plant};
use cdm_model::plan::Piece;
use cdm_model::step::{law_for, Law, NeighborModel};
use cdm_scenario::{Checks, Scenario};

fn paper40_with(t_total_s: f64) -> Scenario {
    let mut f = cdm_scenario::paper40();
    f.t_total_s = t_total_s;
    Scenario::from_file(f, "paper40", Checks::Member).unwrap()
}

#[test]
fn nonlinear_team_matches_linear_model_over_a_whole_plan() {
    let s = paper40_with(200.0);
    let mut quad = quad_engine(&s);
    let mut chain = chain_engine(&s);
    let mut worst: f64 = 0.0;
    while quad.tick() < s.last_tick() {
        quad.advance().unwrap();
        chain.advance().unwrap();
        for (q, c) in quad.states().iter().zip(chain.states()) {
            worst = worst.max((q.position() - c.flat().r).norm());
        }
    }
    println!("nonlinear vs linear team, paper40 T=200 s: max |dr| = {worst:.3e} m");
    assert!(worst < 1e-6, "{worst}");
}

#[test]
fn engine_is_deterministic() {
    let s = paper40_with(20.0);
    let run = || {
        let mut e = quad_engine(&s);
        while e.tick() < s.last_tick() {
            e.advance().unwrap();
        }
        e.states().iter().map(|q| q.0).collect::<Vec<_>>()
    };
    let (a, b) = (run(), run());
    assert!(a
        .iter()
        .zip(&b)
        .all(|(x, y)| x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits())));
}

#[test]
fn exchange_error_is_small_and_taylor_beats_hold() {
    let s = paper40_with(100.0);
    let taylor = exchange_error(&s, NeighborModel::Taylor).unwrap();
    let hold = exchange_error(&s, NeighborModel::Hold).unwrap();
    println!("exchange error vs continuous eqs. 24-25, paper40 T=100 s, dt=10 ms: taylor {taylor:.3e} m, hold {hold:.3e} m");
    assert!(taylor < hold, "taylor {taylor} hold {hold}");
    assert!(taylor < 1e-3, "{taylor}");
}

#[test]
fn deviation_falls_as_travel_time_grows() {
    let mut last = f64::INFINITY;
    for t in [50.0, 100.0, 200.0] {
        let t0 = std::time::Instant::now();
        let d = max_follower_deviation(&paper40_with(t)).unwrap();
        println!(
            "T_total = {t} s: max follower deviation {d:.4} m ({:?})",
            t0.elapsed()
        );
        assert!(d < last);
        last = d;
    }
}

/// The continuously coupled linear team of eqs. 24-25: one RK4 over all agents at once, every
/// stage seeing every neighbour's current state (no exchange, no extrapolation). Returns the
/// largest position difference against the engine's linear team with the given neighbour model,
/// i.e. the error that exchanging states once per tick adds.
fn exchange_error(s: &Scenario, model: NeighborModel) -> Result<Real, AgentFault> {
    let mut e = chain_engine(s).with_neighbor_model(model);
    let n = s.formation.members.len();
    let mut x: Vec<Flat> = s
        .formation
        .members
        .iter()
        .map(|m| Flat::rest(m.position))
        .collect();
    let f = &s.formation;
    let laws: Vec<Law> = f.members.iter().map(|m| law_for(m).0).collect();
    let nbr: Vec<[usize; 3]> = (f.members.iter().enumerate())
        .map(|(k, m)| law_for(m).1.map(|id| f.index_of(id).unwrap_or(k)))
        .collect();
    let [k1, k2, k3, k4] = s.file.gains;
    let plan = &s.plan;
    let deriv = |t: Real, seg: Piece, x: &[Flat]| -> Vec<Flat> {
        (0..n)
            .map(|k| {
                let f = &x[k];
                let snap = match &laws[k] {
                    Law::Leader { alpha } => {
                        let d = plan.agent_derivs(alpha, t, seg);
                        d[4] + (d[3] - f.j) * k1
                            + (d[2] - f.a) * k2
                            + (d[1] - f.v) * k3
                            + (d[0] - f.r) * k4
                    }
                    Law::Follower { weights } => {
                        let mut rd = Vec3::zeros();
                        let mut vd = Vec3::zeros();
                        for (j, w) in nbr[k].iter().zip(weights) {
                            rd += x[*j].r * *w;
                            vd += x[*j].v * *w;
                        }
                        (rd - f.r) * k4 + (vd - f.v) * k3 - f.a * k2 - f.j * k1
                    }
                };
                Flat {
                    r: f.v,
                    v: f.a,
                    a: f.j,
                    j: snap,
                }
            })
            .collect()
    };
    let axpy = |x: &[Flat], d: &[Flat], h: Real| -> Vec<Flat> {
        x.iter()
            .zip(d)
            .map(|(a, b)| Flat {
                r: a.r + b.r * h,
                v: a.v + b.v * h,
                a: a.a + b.a * h,
                j: a.j + b.j * h,
            })
            .collect()
    };
    let dt = s.dt_s();
    let sub = s.substeps();
    let mut worst: Real = 0.0;
    for tick in 0..s.last_tick() {
        for i in 0..sub {
            let ts = (tick as Real + i as Real / sub as Real) * dt;
            let te = (tick as Real + (i + 1) as Real / sub as Real) * dt;
            let pieces: Vec<(Real, Real, Piece)> = match plan.break_inside(ts, te) {
                None => vec![(ts, te, plan.piece_of(ts, te))],
                Some(tt) => vec![
                    (ts, tt, plan.piece_of(ts, tt)),
                    (tt, te, plan.piece_of(tt, te)),
                ],
            };
            for (a, b, seg) in pieces {
                let h = b - a;
                let d1 = deriv(a, seg, &x);
                let d2 = deriv(a + h / 2.0, seg, &axpy(&x, &d1, h / 2.0));
                let d3 = deriv(a + h / 2.0, seg, &axpy(&x, &d2, h / 2.0));
                let d4 = deriv(b, seg, &axpy(&x, &d3, h));
                for k in 0..n {
                    let c = |f: fn(&Flat) -> Vec3| {
                        (f(&d1[k]) + f(&d2[k]) * 2.0 + f(&d3[k]) * 2.0 + f(&d4[k])) * (h / 6.0)
                    };
                    x[k] = Flat {
                        r: x[k].r + c(|f| f.r),
                        v: x[k].v + c(|f| f.v),
                        a: x[k].a + c(|f| f.a),
                        j: x[k].j + c(|f| f.j),
                    };
                }
            }
        }
        e.advance()?;
        for (st, xk) in e.states().iter().zip(&x) {
            worst = worst.max((st.0.r - xk.r).norm());
        }
    }
    Ok(worst)
}
