//! Finite elements at h = 1/60 (one step per 60 Hz frame) on the coarse bunny (407 vertices,
//! 1616 tets) and the coarse armadillo (496 vertices, 1466 tets), E = 1 MPa, ν = 0.45, hung by
//! their top 5 % and swinging (2 m/s per m of height): time per step of backward Euler
//! (sparse Cholesky with and without reusing a factorization across Newton iterations — the
//! former is the FEM default — and PCG) and linearly implicit Euler, and the parts of
//! one Newton iteration — the Hessian's assembly (element stiffness, PSD projection, scatter),
//! the gradient (forces and the objective), and the linear solve. The state is advanced 30
//! steps first, so the elements are deformed.
//!
//! `cargo bench --no-default-features --bench fem`. Target: the armadillo at
//! ≤ 5 ms per step with backward Euler on one core.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::fem::NeoHookean;
use bevy_soft_body::core::fem::mesh::TetMesh;
use bevy_soft_body::core::integrate::{BackwardEuler, Integrator, LinearlyImplicitEuler};
use bevy_soft_body::core::jacobian::Linearization;
use bevy_soft_body::core::solve::LinearSolver;
use bevy_soft_body::prelude::*;
use criterion::{Criterion, criterion_group, criterion_main};

fn body(name: &str) -> (ParticleModel, ParticleState) {
    let path = format!(
        "{}/assets/meshes/{name}_coarse.mesh",
        env!("CARGO_MANIFEST_DIR")
    );
    let mesh = TetMesh::from_medit(&path, &std::fs::read_to_string(&path).unwrap()).unwrap();
    let mat = NeoHookean {
        young: 1e6,
        poisson: 0.45,
        density: 1000.0,
    };
    build::hung_tet_body(&mesh, mat, 2.0).build().unwrap()
}

type Boxed = Box<dyn Integrator<ParticleState, ParticleModel>>;

fn method(name: &str) -> Boxed {
    match name {
        "newton_cholesky" => Box::new(BackwardEuler::new(LinearSolver::cholesky(), 5)),
        "modified_newton_cholesky" => {
            let mut be = BackwardEuler::new(LinearSolver::cholesky(), 5);
            be.reuse_factorization = true;
            Box::new(be)
        }
        "newton_pcg" => Box::new(BackwardEuler::default()),
        "lie_cholesky" => Box::new(LinearlyImplicitEuler::with_solver(LinearSolver::cholesky())),
        _ => unreachable!(),
    }
}

fn bench(c: &mut Criterion) {
    let prec = bevy_soft_body::math::PRECISION;
    let mut g = c.benchmark_group(format!("fem_{prec}"));
    g.sample_size(10);
    let h: Scalar = 1.0 / 60.0;
    for mesh in ["bunny", "armadillo"] {
        for name in [
            "modified_newton_cholesky",
            "newton_cholesky",
            "newton_pcg",
            "lie_cholesky",
        ] {
            let (model, mut state) = body(mesh);
            let mut integ = method(name);
            let mut t = 0.0;
            for _ in 0..30 {
                t += integ.step(&model, t, h, &mut state).unwrap();
            }
            integ.reset();
            g.bench_function(format!("{mesh}/{name}"), |b| {
                b.iter(|| {
                    t += integ.step(&model, t, h, &mut state).unwrap();
                })
            });
            let st = integ.stats();
            let per = |x: u64| x as f64 / st.steps.max(1) as f64;
            println!(
                "{mesh} {name}: per step {:.2} Newton iterations, {:.2} linear solves, {:.1} CG iterations, residual {:.1e} m/s ({} steps)",
                per(st.newton_iterations),
                per(st.linear_solves),
                per(st.linear_iterations),
                st.newton_residual,
                st.steps
            );
        }
        // The parts of one Newton iteration at a deformed state.
        let (model, mut state) = body(mesh);
        let mut be = method("newton_cholesky");
        let mut t = 0.0;
        for _ in 0..30 {
            t += be.step(&model, t, h, &mut state).unwrap();
        }
        let n = model.len();
        let x0 = state.x.clone();
        let v0 = state.v.clone();
        let mut x = vec![Vector::ZERO; n];
        let mut grad = vec![Vector::ZERO; n];
        let mut a = model.new_matrix();
        let mut mask = vec![0.0; n];
        model.free_mask(&mut mask);
        g.bench_function(format!("{mesh}/assemble_hessian"), |b| {
            b.iter(|| {
                model.incremental_potential(t + h, h, &x0, &v0, &v0, &mut x, None);
                model.assemble_incremental_hessian(
                    h,
                    &x0,
                    &x,
                    std::env::var("NOPROJ").is_err(),
                    &mut a,
                );
            })
        });
        g.bench_function(format!("{mesh}/gradient"), |b| {
            b.iter(|| model.incremental_potential(t + h, h, &x0, &v0, &v0, &mut x, Some(&mut grad)))
        });
        let mut chol = LinearSolver::cholesky();
        let mut d = vec![Vector::ZERO; n];
        g.bench_function(format!("{mesh}/cholesky_solve"), |b| {
            b.iter(|| {
                d.fill(Vector::ZERO);
                chol.solve(&a, &grad, &mut d, &mask)
            })
        });
        let mut pcg = LinearSolver::default();
        g.bench_function(format!("{mesh}/pcg_solve"), |b| {
            b.iter(|| {
                d.fill(Vector::ZERO);
                pcg.solve(&a, &grad, &mut d, &mask)
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
