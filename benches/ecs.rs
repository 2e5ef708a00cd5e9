//! What the ECS layer costs over the core driver: the same 64×64 cloth advanced one 1/60 s
//! frame at a time by `Simulation::advance_frame` directly and by a headless Bevy App
//! (`MinimalPlugins` + `SoftBodyPlugin`, one fixed step per `update`), which adds the change
//! scan of every particle and spring (prepare), the collider pass and the writeback into
//! 4,096 `Particle` components. Two loads: RK4 at h = 1/960 (16 substeps per frame) and
//! linearly implicit Euler at h = 1/60 (one step per frame, the cheapest frame).
//!
//! `cargo bench --bench ecs`. Target: at most 10 % over the core driver. Both run the force
//! kernels on one thread. A second group measures the broad phase: the same cloth among 200
//! colliders that never touch it, against the cloth alone (target: at most 10 % more). These
//! two run with sleeping off, so that a cloth coming to rest during the measurement does not
//! stop stepping. A third measures sleeping: 50 flags of which 40 hang at rest and 10 flap
//! in a gusting breeze, against the same 50 with sleeping off (target: at most 25 %).

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_soft_body::core::build;
use bevy_soft_body::core::driver::{DriverConfig, Simulation, StepPolicy};
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::ecs::{SoftBody, SoftBodyPlugin, SpawnSoftBody};
use criterion::{Criterion, criterion_group, criterion_main};
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let frame = Duration::from_secs_f64(1.0 / 60.0);
    let scene = build::cloth(&build::ClothParams::default().resized(64, 64)).unwrap();
    let mut g = c.benchmark_group("ecs_overhead_64x64");
    g.sample_size(20);
    for (kind, h) in [
        (IntegratorKind::Rk4, 1.0 / 960.0),
        (IntegratorKind::LinearlyImplicitEuler, 1.0 / 60.0),
    ] {
        let (model, state) = scene.build().unwrap();
        let mut core = Simulation::new(
            model,
            state,
            DriverConfig {
                integrator: kind,
                policy: StepPolicy::Fixed { h },
                frame_dt: frame.as_secs_f64(),
                ..Default::default()
            },
        );
        for _ in 0..30 {
            core.advance_frame().unwrap();
        }
        g.bench_function(format!("{}/core", kind.name()), |b| {
            b.iter(|| core.advance_frame().unwrap())
        });

        // One kernel thread, as the core driver above runs (outside any thread pool).
        let mut app = one_thread_app(frame, false);
        let sc = scene.clone();
        let body = SoftBody {
            integrator: kind,
            step: StepPolicy::Fixed { h },
            ..Default::default()
        };
        app.world_mut()
            .run_system_once(move |mut cmd: Commands| {
                cmd.spawn_soft_body(&sc, body.clone()).unwrap();
            })
            .unwrap();
        for _ in 0..31 {
            app.update();
        }
        g.bench_function(format!("{}/ecs", kind.name()), |b| b.iter(|| app.update()));
    }
    // The App's own cost per update with no body (schedules, time, empty queries).
    let mut empty = App::new();
    empty
        .add_plugins((MinimalPlugins, TransformPlugin, SoftBodyPlugin::default()))
        .insert_resource(Time::<Fixed>::from_duration(frame))
        .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
    empty.update();
    g.bench_function("no_body/ecs", |b| b.iter(|| empty.update()));
    let mut bare = App::new();
    bare.add_plugins((MinimalPlugins, TransformPlugin))
        .insert_resource(Time::<Fixed>::from_duration(frame))
        .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
    bare.update();
    g.bench_function("no_plugin/bevy", |b| b.iter(|| bare.update()));
    g.finish();
}

/// The broad phase: the same cloth among 200 plain colliders (balls on a ring 10 m away)
/// that never touch it, against the cloth alone. Target: at most 10 % more per frame.
fn broad_phase(c: &mut Criterion) {
    let frame = Duration::from_secs_f64(1.0 / 60.0);
    let scene = build::cloth(&build::ClothParams::default().resized(64, 64)).unwrap();
    let mut g = c.benchmark_group("broad_phase_64x64");
    g.sample_size(20);
    for colliders in [0usize, 200] {
        let mut app = one_thread_app(frame, false);
        let sc = scene.clone();
        app.world_mut()
            .run_system_once(move |mut cmd: Commands| {
                let body = SoftBody {
                    integrator: IntegratorKind::SymplecticEuler,
                    step: StepPolicy::Fixed { h: 1.0 / 960.0 },
                    ..Default::default()
                };
                cmd.spawn_soft_body(&sc, body).unwrap();
                for k in 0..colliders {
                    let a = k as f32 / colliders as f32 * std::f32::consts::TAU;
                    cmd.spawn((
                        bevy_soft_body::ecs::SoftBodyCollider::ball(0.2),
                        Transform::from_xyz(10.0 * a.cos(), 0.5, 10.0 * a.sin()),
                    ));
                }
            })
            .unwrap();
        for _ in 0..31 {
            app.update();
        }
        g.bench_function(format!("symplectic_euler/{colliders}_far_colliders"), |b| {
            b.iter(|| app.update())
        });
    }
    g.finish();
}

/// A headless App stepping one fixed frame of `frame` per `update`, the force kernels on one
/// thread, with sleeping on or off (off: every body steps, so a cloth coming to rest during a
/// measurement does not stop).
fn one_thread_app(frame: Duration, sleeping: bool) -> App {
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        TransformPlugin,
        SoftBodyPlugin::default().with_kernel_threads(1),
    ))
    .insert_resource(Time::<Fixed>::from_duration(frame))
    .insert_resource(TimeUpdateStrategy::FixedTimesteps(1))
    .insert_resource(SoftBodySleep {
        enabled: sleeping,
        ..Default::default()
    });
    app
}

/// 50 hanging 10×10 flags (the sleeping tests' flag: 0.5 m, top edge pinned, symplectic Euler
/// at 1/1024 s), 10 of them in a gusting breeze; after 3 s the other 40 hang at rest. One
/// frame of the whole app with sleeping on, against sleeping off. Target: at most 25 %.
fn sleeping(c: &mut Criterion) {
    use bevy_soft_body::core::build::{ClothParams, ClothPins, cloth};
    let frame = Duration::from_secs_f64(1.0 / 64.0);
    let mut g = c.benchmark_group("sleeping_50_flags");
    g.sample_size(20);
    for on in [false, true] {
        let mut app = one_thread_app(frame, on);
        app.world_mut()
            .run_system_once(move |mut cmd: Commands| {
                for k in 0..50 {
                    let scene = cloth(&ClothParams {
                        rows: 10,
                        cols: 10,
                        width: 0.5,
                        height: 0.5,
                        mass: 0.005,
                        k_structural: 50.0,
                        k_shear: 20.0,
                        k_flex: 2.0,
                        damping: 0.02,
                        drag: 0.05,
                        pins: ClothPins::TopEdge,
                        hanging: true,
                        origin: [(k % 10) as f64 * 0.7, 1.0 + (k / 10) as f64 * 0.7, 0.0],
                    })
                    .unwrap();
                    let body = SoftBody {
                        integrator: IntegratorKind::SymplecticEuler,
                        step: StepPolicy::Fixed { h: 1.0 / 1024.0 },
                        ..Default::default()
                    };
                    let e = cmd.spawn_soft_body(&scene, body).unwrap();
                    if k < 10 {
                        cmd.entity(e).insert(SoftBodyWind {
                            velocity: Vec3::new(0.0, 0.0, 0.5),
                            gust: 0.5,
                            frequency: 0.5,
                            coefficient: 0.005,
                            seed: k as u64,
                            enabled: true,
                        });
                    }
                }
            })
            .unwrap();
        for _ in 0..193 {
            app.update();
        }
        let name = if on { "40_asleep" } else { "sleeping_off" };
        g.bench_function(name, |b| b.iter(|| app.update()));
    }
    g.finish();
}

use bevy::ecs::system::RunSystemOnce;
use bevy_soft_body::ecs::{SoftBodySleep, SoftBodyWind};

criterion_group!(benches, bench, broad_phase, sleeping);
criterion_main!(benches);
