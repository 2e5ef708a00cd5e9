//! Spring force kernel on a 64×64 cloth (structural + shear + flex = 24,060 springs): time per
//! spring for the row kernel (undamped, damped), the one-loop reference kernel it replaced,
//! and a whole derivative evaluation.
//!
//! `cargo bench --bench springs` (f32) and `cargo bench --bench springs --features f64`;
//! `THREADS=1 cargo bench --bench springs` runs the kernels on one thread (default: all
//! cores). Criterion reports throughput in elements (springs) per second; ns per spring =
//! 1e9 / that.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::ode::OdeSystem;
use bevy_soft_body::prelude::*;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

mod common;
use common::timed;
use std::hint::black_box;

fn cloth(damping: f64) -> (ParticleModel, ParticleState) {
    let p = build::ClothParams {
        rows: 64,
        cols: 64,
        damping,
        ..Default::default()
    };
    let (model, mut state) = build::cloth(&p).unwrap().build().unwrap();
    // A deformed, moving state so no spring is at rest.
    for (i, (x, v)) in state.x.iter_mut().zip(state.v.iter_mut()).enumerate() {
        let s = (i as Scalar * 0.37).sin();
        *x += Vector::new(0.01 * s, 0.02 * s * s, 0.015 * (i as Scalar * 0.11).cos());
        *v = Vector::new(s, -s, 0.5 * s);
    }
    (model, state)
}

fn bench(c: &mut Criterion) {
    let prec = bevy_soft_body::math::PRECISION;
    let mut g = c.benchmark_group(format!("spring_kernel_64x64_{prec}"));
    for (name, damping) in [("undamped", 0.0), ("damped", 0.05)] {
        let (model, state) = cloth(damping);
        let n = model.springs.len();
        let mut f = vec![Vector::ZERO; state.len()];
        g.throughput(Throughput::Elements(n as u64));
        g.bench_function(name, |b| {
            b.iter_custom(|iters| {
                timed(iters, || {
                    f.fill(Vector::ZERO);
                    model
                        .springs
                        .accumulate(black_box(&state.x), black_box(&state.v), &mut f);
                    black_box(&f);
                })
            })
        });
    }
    let (model, state) = cloth(0.05);
    let mut f = vec![Vector::ZERO; state.len()];
    g.throughput(Throughput::Elements(model.springs.len() as u64));
    g.bench_function("damped_reference", |b| {
        b.iter(|| {
            f.fill(Vector::ZERO);
            model
                .springs
                .accumulate_reference(black_box(&state.x), black_box(&state.v), &mut f);
            black_box(&f);
        })
    });
    let mut d = state.clone();
    g.throughput(Throughput::Elements(model.springs.len() as u64));
    g.bench_function("derivative", |b| {
        b.iter_custom(|iters| {
            timed(iters, || {
                model.derivative(0.0, black_box(&state), &mut d);
                black_box(&d);
            })
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
