//! Micro-benchmarks of the hot math: one agent's tick (controller + RK4), Q/d and lambda(U_D),
//! and one audit of a whole team. Run: `cargo bench -p cdm-engine --bench hot_math`.

use std::hint::black_box;

use cdm_engine::engine::quad_engine;
use cdm_model::dynamics::QuadState;
use cdm_model::frame::deformation_eigenvalues;
use cdm_model::step::{law_for, step};
use cdm_records::audit::Auditor;
use cdm_scenario::Scenario;
use criterion::{criterion_group, criterion_main, Criterion};

fn hot_math(c: &mut Criterion) {
    let s = Scenario::builtin("paper40").expect("paper40");
    let cfg = s.step_config();
    // A follower mid-plan: advance the engine a while so states are non-trivial.
    let mut e = quad_engine(&s);
    for _ in 0..5000 {
        e.advance().expect("engine");
    }
    let k = s
        .formation
        .members
        .iter()
        .position(|m| m.link.is_some())
        .expect("a follower");
    let (law, ids) = law_for(&s.formation.members[k]);
    let nb = ids.map(|id| e.states()[s.formation.index_of(id).expect("id")].flat());
    let own: QuadState = e.states()[k];
    c.bench_function("one follower tick (FL controller + RK4, 1 substep)", |b| {
        b.iter(|| {
            step(
                &cfg,
                &s.plan,
                &law,
                black_box(5000),
                black_box(&own),
                &nb,
                &ids,
            )
        })
    });
    c.bench_function("Q, d and lambda(U_D) at one instant", |b| {
        b.iter(|| {
            let (q, _) = s.plan.q_d_at_s(black_box(0.4)).expect("q");
            deformation_eigenvalues(&q)
        })
    });
    let pos: Vec<_> = e.states().iter().map(|q| q.position()).collect();
    let mut ht = Vec::new();
    s.desired_positions(50.0, &mut ht);
    let mut audit = Auditor::new(&s);
    c.bench_function("audit of one tick, 40 agents", |b| {
        b.iter(|| audit.observe(black_box(5000), 50.0, &pos, &ht))
    });
    c.bench_function("engine tick, 40 agents", |b| {
        b.iter(|| {
            let mut e2 = quad_engine(&s);
            e2.advance().expect("engine");
            black_box(e2.tick())
        })
    });
}

criterion_group!(benches, hot_math);
criterion_main!(benches);
