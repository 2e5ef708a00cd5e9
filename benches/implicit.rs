//! Implicit methods on 64×64 and 128×128 cloths at h = 1/60 (one step per frame): time per
//! step, and per step the CG iterations, linear solves and Newton iterations. Linearly implicit
//! Euler with PCG (the default) and with the sparse Cholesky; Newton backward Euler (at most 5
//! iterations) with each. The clock starts after 30 warm-up steps, once the cloth is falling
//! and the springs are stretched; the state is not reset between samples, so every sample is a
//! step of the same ongoing simulation.
//!
//! `cargo bench --bench implicit` (`--no-default-features --features parallel` builds the
//! library without its Bevy layer, though Bevy is still built as a dev-dependency of the
//! examples and tests; the numbers are the core's either way); `THREADS=N` runs the solves on
//! a team of `N` threads (default: all cores; `THREADS=1` for one). Target: linearly implicit Euler on 128×128 at
//! ≤ 16.7 ms per step.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::integrate::{BackwardEuler, Integrator, LinearlyImplicitEuler};
use bevy_soft_body::core::solve::LinearSolver;
use bevy_soft_body::prelude::*;
use criterion::{Criterion, criterion_group, criterion_main};

mod common;
use common::timed;

type Boxed = Box<dyn Integrator<ParticleState, ParticleModel>>;

fn method(name: &str) -> Boxed {
    let chol = LinearSolver::cholesky;
    match name {
        "lie_pcg" => Box::new(LinearlyImplicitEuler::default()),
        "lie_cholesky" => Box::new(LinearlyImplicitEuler::with_solver(chol())),
        "newton_pcg" => Box::new(BackwardEuler::default()),
        "newton_cholesky" => Box::new(BackwardEuler::new(chol(), 5)),
        _ => unreachable!(),
    }
}

fn bench(c: &mut Criterion) {
    let prec = bevy_soft_body::math::PRECISION;
    let mut g = c.benchmark_group(format!("implicit_{prec}"));
    g.sample_size(10);
    for name in ["lie_pcg", "lie_cholesky", "newton_pcg", "newton_cholesky"] {
        for n in [64, 128] {
            let p = build::ClothParams::default().resized(n, n);
            let (model, mut state) = build::cloth(&p).unwrap().build().unwrap();
            let mut integ = method(name);
            let h = 1.0 / 60.0;
            let mut t = 0.0;
            for _ in 0..30 {
                t += integ.step(&model, t, h, &mut state).unwrap();
            }
            integ.reset();
            g.bench_function(format!("{name}/{n}x{n}"), |b| {
                b.iter_custom(|iters| {
                    timed(iters, || {
                        t += integ.step(&model, t, h, &mut state).unwrap();
                    })
                })
            });
            let st = integ.stats();
            let per = |x: u64| x as f64 / st.steps.max(1) as f64;
            println!(
                "{name} {n}x{n}: {} particles, {} springs; per step {:.1} CG iterations, {:.2} linear solves, {:.2} Newton iterations ({} steps)",
                model.len(),
                model.springs.len(),
                per(st.linear_iterations),
                per(st.linear_solves),
                per(st.newton_iterations),
                st.steps
            );
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
