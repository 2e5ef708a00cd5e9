//! Level of detail for cloth: what a frame costs when a 24² cloth is simulated and drawn as a
//! 93² mesh (`core::detail`, the plugin's `SurfaceDetail` level 4), against simulating a 96²
//! cloth and drawing it as it is — the main example's scene (`cloth_sphere`: its stiff cloth,
//! the sphere swinging through it), symplectic Euler at each resolution's CFL step.
//!
//! `cargo bench --no-default-features --bench detail`. Each cloth first runs 90 frames
//! (1.5 s: draped on the sphere), then one frame (1/60 s) is timed, and the drawing work
//! of one frame: vertex normals for a mesh drawn as simulated; coarse normals, Phong
//! tessellation and interpolated normals for the detailed one.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::detail::{Rounding, Tessellation, vertex_normals};
use bevy_soft_body::core::driver::CflLimit;
use bevy_soft_body::math::VectorExt;
use bevy_soft_body::prelude::*;
use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use std::hint::black_box;

const FRAME: f64 = 1.0 / 60.0;

/// The main example's cloth at `n × n` (sheet stiffness kept as it is resized).
fn scene(n: usize) -> Scene {
    let p = build::ClothParams {
        k_structural: 400.0,
        k_shear: 200.0,
        k_flex: 80.0,
        damping: 0.1,
        ..Default::default()
    }
    .resized(n, n);
    build::cloth_sphere(&p, 0.25, 0.6, 4.0).unwrap()
}

fn draped(n: usize) -> (Simulation<ParticleState, ParticleModel>, Vec<[u32; 3]>) {
    let s = scene(n);
    let tris = s.surface.as_ref().unwrap().triangles.clone();
    let (model, state) = s.build().unwrap();
    let mut sim = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: IntegratorKind::SymplecticEuler,
            policy: StepPolicy::Cfl {
                number: 0.5,
                max: FRAME,
                limit: CflLimit::default(),
            },
            frame_dt: FRAME,
            ..Default::default()
        },
    );
    let mut substeps = 0;
    for _ in 0..90 {
        substeps = sim.advance_frame().unwrap().substeps;
    }
    assert!(sim.state.is_finite());
    println!(
        "{n}²: {} particles, h = {:.2e} s, {substeps} substeps per frame",
        n * n,
        sim.step_size()
    );
    (sim, tris)
}

fn detail(c: &mut Criterion) {
    let mut g = c.benchmark_group("cloth_detail");
    g.sample_size(20);
    for n in [24, 96] {
        let (mut sim, tris) = draped(n);
        g.bench_function(format!("simulate a frame, {n}²"), |b| {
            b.iter(|| sim.advance_frame().unwrap())
        });
        let x: Vec<Vec3> = sim.state.x.iter().map(|p| p.to_f32()).collect();
        let mut normals = vec![Vec3::ZERO; x.len()];
        g.bench_function(format!("draw as simulated, {n}² (vertex normals)"), |b| {
            b.iter(|| vertex_normals(black_box(&x), &tris, &mut normals))
        });
        if n == 24 {
            let fine = Tessellation::new(&tris, x.len(), 4).unwrap();
            let (mut p, mut nrm) = (vec![[0.0; 3]; fine.len()], vec![[0.0; 3]; fine.len()]);
            println!("24² at level 4: {} display vertices", fine.len());
            g.bench_function("draw 24² at level 4 (93² display)", |b| {
                b.iter(|| fine.draw(black_box(&x), Rounding::default(), &mut p, &mut nrm))
            });
        }
    }
    g.finish();
}

criterion_group!(benches, detail);
criterion_main!(benches);
