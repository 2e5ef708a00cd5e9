//! Linearly implicit Euler on 64×64 and 128×128 cloths at h = 1/60 (one step per frame): time
//! per step and CG iterations per step. The clock starts after 30 warm-up steps, once the cloth
//! is falling and the springs are stretched; the state is not reset between samples, so every
//! sample is a step of the same ongoing simulation.
//!
//! `cargo bench --bench implicit`. Target (issue 4): 128×128 at ≤ 16.7 ms per step on one core.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::integrate::{AdaptiveConfig, Integrator};
use bevy_soft_body::prelude::*;
use criterion::{Criterion, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let prec = bevy_soft_body::math::PRECISION;
    let mut g = c.benchmark_group(format!("linearly_implicit_euler_{prec}"));
    g.sample_size(20);
    for n in [64, 128] {
        let p = build::ClothParams::default().resized(n, n);
        let (model, mut state) = build::cloth(&p).unwrap().build().unwrap();
        let mut integ: Box<dyn Integrator<ParticleState, ParticleModel>> =
            IntegratorKind::LinearlyImplicitEuler.build(AdaptiveConfig::default());
        let h = 1.0 / 60.0;
        let mut t = 0.0;
        for _ in 0..30 {
            t += integ.step(&model, t, h, &mut state).unwrap();
        }
        integ.reset();
        g.bench_function(format!("{n}x{n}_step"), |b| {
            b.iter(|| {
                t += integ.step(&model, t, h, &mut state).unwrap();
            })
        });
        let st = integ.stats();
        println!(
            "{n}x{n}: {} particles, {} springs, {:.1} CG iterations per step over {} steps",
            model.len(),
            model.springs.len(),
            st.linear_iterations as f64 / st.steps.max(1) as f64,
            st.steps
        );
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
