//! Determinism (in the style of avian's determinism test): the same scene, the same build,
//! the same inputs give bit-identical states after 1000 steps — for every integrator, with
//! Bevy's multi-threaded task pool (bodies stepped in parallel) and with a single thread.
#![cfg(feature = "plugin")]
// Casts to f64 are no-ops in the f64 build.
#![allow(clippy::unnecessary_cast)]

use bevy::app::{TaskPoolOptions, TaskPoolPlugin};
use bevy::ecs::system::RunSystemOnce;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_soft_body::core::build;
use bevy_soft_body::core::driver::StepPolicy;
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::ecs::*;

/// Runs four bodies (a chain, a 6×6 cloth with the swinging sphere, a 3×3×3 jelly and a
/// 48-tet neo-Hookean box on the ground) with `kind` at h = 1/256 s for 250 fixed frames of 1/64 s — 1000 steps — and
/// hashes every particle's position and velocity bits (FNV-1a), body by body.
fn run(kind: IntegratorKind, threads: Option<usize>) -> u64 {
    let mut app = App::new();
    let pool = match threads {
        Some(n) => TaskPoolPlugin {
            task_pool_options: TaskPoolOptions::with_num_threads(n),
        },
        None => TaskPoolPlugin::default(),
    };
    app.add_plugins((
        MinimalPlugins.set(pool),
        TransformPlugin,
        SoftBodyPlugin::default(),
    ))
    .insert_resource(Time::<Fixed>::from_seconds(1.0 / 64.0))
    .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
    app.update();
    let scenes = [
        build::chain(&build::ChainParams::default()).unwrap(),
        build::cloth_sphere(&build::ClothParams::default().resized(6, 6), 0.25, 0.6, 4.0).unwrap(),
        build::jelly(&build::JellyParams {
            size: [3, 3, 3],
            drop_height: 0.3,
            ..Default::default()
        })
        .unwrap(),
        // A soft neo-Hookean box (48 tets) dropped on the ground: element forces, contacts
        // held inside implicit steps, the sparse Cholesky.
        {
            let mut s = bevy_soft_body::core::fem::mesh::TetMesh::tet_box([0.2; 3], [2, 2, 2])
                .unwrap()
                .transformed(1.0, [2.0, 0.1, 0.0])
                .to_scene(
                    "box",
                    bevy_soft_body::core::fem::NeoHookean {
                        young: 1e4,
                        ..Default::default()
                    },
                );
            s.colliders.push(build::ground(0.0, 0.0, 0.5));
            s
        },
    ];
    let body = SoftBody {
        integrator: kind,
        step: StepPolicy::Fixed { h: 1.0 / 256.0 },
        energy_guard: None,
        ..Default::default()
    };
    let roots: Vec<Entity> = app
        .world_mut()
        .run_system_once(move |mut c: Commands| {
            scenes
                .iter()
                .map(|s| c.spawn_soft_body(s, body.clone()).unwrap())
                .collect::<Vec<_>>()
        })
        .unwrap();
    for _ in 0..250 {
        app.update();
    }
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let w = app.world();
    for r in roots {
        for e in w.get::<BodyParticles>(r).unwrap().entities() {
            let p = w.get::<Particle>(*e).unwrap();
            for v in p
                .position
                .to_array()
                .into_iter()
                .chain(p.velocity.to_array())
            {
                for b in v.to_bits().to_le_bytes() {
                    h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
                }
            }
        }
        let st = w.get::<SoftBodyStatus>(r).unwrap();
        assert!(
            // Bodies that came to rest sleep (and must do so on the same frame every run).
            matches!(
                st.state,
                BodyState::Running | BodyState::Sleeping | BodyState::Diverged(_)
            ),
            "{kind}: {:?}",
            st.state
        );
    }
    h
}

#[test]
fn every_integrator_is_bitwise_deterministic_single_and_multi_threaded() {
    for kind in IntegratorKind::ALL {
        let a = run(kind, None);
        let b = run(kind, None);
        let c = run(kind, Some(1));
        println!("{:<34} {a:016x}", kind.label());
        assert_eq!(a, b, "{kind}: two multi-threaded runs differ");
        assert_eq!(a, c, "{kind}: single-threaded run differs");
    }
}

/// One large body whose forces are cut into chunks (a 48×48 cloth: three chunks of springs;
/// a 1536-tet box: six chunks of elements) stepped with its kernels on one thread and on two
/// (`SoftBodyPlugin::with_kernel_threads`): 200 fixed frames of symplectic Euler and RK4 end
/// in the same bits.
#[test]
fn a_large_body_is_bitwise_the_same_on_one_and_two_kernel_threads() {
    let run = |kind: IntegratorKind, threads: usize| -> Vec<u64> {
        let mut app = App::new();
        app.add_plugins((
            MinimalPlugins,
            TransformPlugin,
            SoftBodyPlugin::default().with_kernel_threads(threads),
        ))
        .insert_resource(Time::<Fixed>::from_seconds(1.0 / 64.0))
        .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
        app.update();
        // Without the `parallel` feature every body runs on one thread, whatever is asked.
        let expect = if cfg!(feature = "parallel") {
            threads
        } else {
            1
        };
        assert_eq!(
            app.world().resource::<SoftBodyKernelPool>().threads(),
            expect
        );
        let cloth = build::cloth(&build::ClothParams::default().resized(48, 48)).unwrap();
        let block = bevy_soft_body::core::fem::mesh::TetMesh::tet_box([0.4; 3], [8, 8, 4])
            .unwrap()
            .transformed(1.0, [2.0, 0.1, 0.0])
            .to_scene(
                "box",
                bevy_soft_body::core::fem::NeoHookean {
                    young: 2e3,
                    ..Default::default()
                },
            );
        let mut block = block;
        block.colliders.push(build::ground(0.0, 0.0, 0.5));
        let body = SoftBody {
            integrator: kind,
            step: StepPolicy::Fixed { h: 1.0 / 512.0 },
            energy_guard: None,
            ..Default::default()
        };
        let roots: Vec<Entity> = app
            .world_mut()
            .run_system_once(move |mut c: Commands| {
                [&cloth, &block]
                    .iter()
                    .map(|s| c.spawn_soft_body(s, body.clone()).unwrap())
                    .collect::<Vec<_>>()
            })
            .unwrap();
        for _ in 0..200 {
            app.update();
        }
        let w = app.world();
        let mut bits = vec![];
        for r in roots {
            let sim = w.get::<BodySim>(r).unwrap().simulation().unwrap();
            assert!(sim.system.is_chunked());
            let state = &w.get::<SoftBodyStatus>(r).unwrap().state;
            assert!(matches!(state, BodyState::Running), "{kind}: {state:?}");
            for x in sim.state.x.iter().chain(&sim.state.v) {
                bits.extend(x.to_array().map(|c| (c as f64).to_bits()));
            }
        }
        bits
    };
    for kind in [IntegratorKind::SymplecticEuler, IntegratorKind::Rk4] {
        assert!(
            run(kind, 1) == run(kind, 2),
            "{kind}: 1 and 2 threads differ"
        );
    }
}
