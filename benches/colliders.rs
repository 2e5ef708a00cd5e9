//! A cloth on a collider of each kind: the cloth pile's 64×64 cloth (self-collision off)
//! dropped onto its sphere on the ground, the sphere given as parry's ball, as the convex hull
//! of an icosphere (162 vertices) and as that icosphere's triangle mesh (320 triangles), at the
//! pile's radius (0.3 m: the cloth drapes over it) and at 0.1 m (a small prop: most of the
//! cloth falls past it). Balls have their own exact queries; a hull answers by its own
//! triangles' planes, and a cloth's triangle they do not settle by exact pairs with the hull's
//! triangles near it (parry's contact query, on the hull's support points, for one crossing
//! it); a mesh by parry's point projection and exact triangle pairs; both are skipped for
//! particles outside the shape's box or bounding sphere grown by the thickness and their
//! path. Time per frame of 1/60 s, symplectic Euler at the pile's stable step and linearly
//! implicit Euler at one step a frame. The cost of a frame depends on how far the cloth has draped, so the timed frames are
//! always frames 30 to 59 of the same run (the cloth reaching the sphere and draping on it),
//! taken in turn: after the 60th the state of frame 30 is put back, untimed. Criterion's
//! figure is then their mean whatever the number of frames it asks for (a run that went on
//! instead would time later frames on a faster machine, where warm-up takes more of them).
//!
//! `cargo bench --bench colliders`; `THREADS=N` as in the other benches.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::collide::{Collider, SharedShape};
use bevy_soft_body::core::detail;
use bevy_soft_body::prelude::*;
use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;

mod common;
use common::timed_in_turn;

/// How many frames from frame 30 are timed, in turn.
const WINDOW: u64 = 30;

fn bench(c: &mut Criterion) {
    let prec = bevy_soft_body::math::PRECISION;
    let mut g = c.benchmark_group(format!("colliders_{prec}"));
    g.sample_size(10);
    let (unit, triangles) = detail::icosphere(2);
    for radius in [0.3, 0.1] {
        let v: Vec<Vec3> = unit.iter().map(|p| *p * radius as f32).collect();
        for shape in ["ball", "hull", "trimesh"] {
            for method in ["symplectic_euler", "linearly_implicit_euler"] {
                let p = build::ClothPileParams {
                    cloths: 1,
                    self_collision: None,
                    radius,
                    ..Default::default()
                }
                .with_resolution(64);
                let (mut model, state) = build::cloth_pile(&p).unwrap().build().unwrap();
                let s = &model.colliders[1];
                let replaced = match shape {
                    "ball" => SharedShape::ball(radius as f32),
                    "hull" => SharedShape::convex_hull(&v).expect("an icosphere's hull"),
                    _ => SharedShape::trimesh(v.clone(), triangles.clone())
                        .expect("an icosphere's triangles"),
                };
                model.colliders[1] = Collider::new(replaced, s.motion, s.rotation, s.material);
                let (integrator, h) = match method {
                    "symplectic_euler" => (IntegratorKind::SymplecticEuler, p.stable_step()),
                    _ => (IntegratorKind::LinearlyImplicitEuler, 1.0 / 60.0),
                };
                let mut sim = Simulation::new(
                    model,
                    state,
                    DriverConfig {
                        integrator,
                        policy: StepPolicy::Fixed { h },
                        frame_dt: 1.0 / 60.0,
                        ..Default::default()
                    },
                );
                sim.run(30, |_, _| {}).unwrap();
                let at_30 = sim.state.clone();
                let mut done = 0u64;
                g.bench_function(format!("{method}/{shape}/r{radius}"), |b| {
                    b.iter_custom(|iters| {
                        timed_in_turn(
                            iters,
                            (WINDOW, &mut done),
                            &mut sim,
                            |sim| sim.state = at_30.clone(),
                            |sim| {
                                sim.advance_frame().unwrap();
                            },
                        )
                    })
                });
            }
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
