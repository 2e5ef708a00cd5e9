//! The plugin in headless Apps (`MinimalPlugins`, one fixed step of 1/64 s per update): it
//! steps exactly as the core driver, holds and moves pins, collides, survives despawns, keeps
//! meshes equal to particles, and leaves bodies with bad input out with a message naming the
//! culprit.
#![cfg(feature = "plugin")]
// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

mod common;
use bevy::prelude::*;
use bevy_soft_body::core::build;
use bevy_soft_body::core::driver::{DriverConfig, Simulation, StepPolicy};
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::core::motion::Motion;
use bevy_soft_body::core::scene::Scene;
use bevy_soft_body::ecs::*;
use bevy_soft_body::math::VectorExt;
use bevy_soft_body::render::SoftBodySurface;
use common::spawn;

/// 1/64 s: exactly representable, so the plugin's frame (from `Time<Fixed>`'s `Duration`) and
/// the core driver's are the same number.
const FRAME: f64 = 1.0 / 64.0;

fn app() -> App {
    common::headless_app(FRAME)
}

fn frames(app: &App, body: Entity) -> u64 {
    app.world()
        .get::<BodySim>(body)
        .and_then(|b| b.simulation())
        .map_or(0, |s| s.frame)
}

fn status(app: &App, body: Entity) -> SoftBodyStatus {
    app.world().get::<SoftBodyStatus>(body).unwrap().clone()
}

fn particles_of(app: &App, body: Entity) -> Vec<Vec3> {
    let w = app.world();
    w.get::<BodyParticles>(body)
        .unwrap()
        .entities()
        .iter()
        .map(|e| w.get::<Particle>(*e).unwrap().position)
        .collect()
}

/// The default pendulum chain with dyadic parameters (mass 1/8 kg, k = 256 N/m, drag 1/64,
/// g = 9.8125), so the plugin's f32 components carry them exactly in either precision.
fn chain_scene() -> Scene {
    let mut s = build::chain(&build::ChainParams {
        particles: 5,
        mass: 0.125,
        stiffness: 256.0,
        drag: 0.015625,
        ..Default::default()
    })
    .unwrap();
    s.gravity = [0.0, -9.8125, 0.0];
    s
}

use bevy::ecs::system::RunSystemOnce;

#[test]
fn plugin_steps_a_pendulum_bitwise_like_the_core_driver() {
    let scene = chain_scene();
    let h = 1.0 / 512.0;
    let body = SoftBody {
        integrator: IntegratorKind::Rk4,
        step: StepPolicy::Fixed { h },
        ..Default::default()
    };
    let mut app = app();
    let e = spawn(&mut app, &scene, body);
    for _ in 0..128 {
        app.update();
    }
    assert_eq!(frames(&app, e), 128, "one fixed step per update");
    let (model, state) = scene.build().unwrap();
    let mut core = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: IntegratorKind::Rk4,
            policy: StepPolicy::Fixed { h },
            frame_dt: FRAME,
            ..Default::default()
        },
    );
    core.run(128, |_, _| {}).unwrap();
    let bs = app.world().get::<BodySim>(e).unwrap();
    let ecs = bs.simulation().unwrap();
    assert_eq!(ecs.time, core.time);
    assert_eq!(ecs.state.x, core.state.x, "positions differ");
    assert_eq!(ecs.state.v, core.state.v, "velocities differ");
    let expected: Vec<Vec3> = core.state.x.iter().map(|x| x.to_f32()).collect();
    assert_eq!(
        particles_of(&app, e),
        expected,
        "components differ from the state"
    );
    assert!(
        expected[4].y < -0.3,
        "the chain swung down: {:?}",
        expected[4]
    );
}

/// `IntegratorKind::Auto` through the plugin: the body steps bitwise like the core driver's
/// Auto, the status names the method in use and the reason, and editing `AutoSettings`
/// makes it decide again (a tolerance on the chain's energy error asks for more).
#[test]
fn auto_through_the_plugin_steps_like_the_core_and_reports_its_choice() {
    let scene = chain_scene();
    let body = SoftBody {
        integrator: IntegratorKind::Auto,
        ..Default::default()
    };
    let mut app = app();
    let e = spawn(&mut app, &scene, body);
    for _ in 0..64 {
        app.update();
    }
    let (model, state) = scene.build().unwrap();
    let mut core = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: IntegratorKind::Auto,
            frame_dt: FRAME,
            ..Default::default()
        },
    );
    core.run(64, |_, _| {}).unwrap();
    let st = status(&app, e);
    let choice = core.auto_choice().unwrap();
    assert_eq!(st.method, choice.kind);
    assert_eq!(st.auto_reason, choice.reason);
    assert_eq!(st.substeps, choice.substeps);
    assert!(st.auto_reason.contains("substep"), "{}", st.auto_reason);
    let bs = app.world().get::<BodySim>(e).unwrap();
    assert_eq!(bs.simulation().unwrap().state.x, core.state.x);
    let loose = st.substeps;
    app.world_mut()
        .entity_mut(e)
        .insert(AutoSettings(AutoConfig {
            tolerance: Some(1e-3),
            max_substeps: 64,
        }));
    app.update();
    let st = status(&app, e);
    println!(
        "{loose} substeps, then with a tolerance: {}",
        st.auto_reason
    );
    assert!(
        st.auto_reason.contains("energy error"),
        "{}",
        st.auto_reason
    );
    assert!(st.substeps > loose || st.method != IntegratorKind::SymplecticEuler);
}

#[test]
fn pinned_particles_hold_and_follow_their_targets_exactly() {
    let mut app = app();
    let scene = chain_scene();
    let e = spawn(&mut app, &scene, SoftBody::default());
    app.update();
    let p0 = particles_of(&app, e)[0];
    // A second chain whose first particle follows a target moving on a circle.
    let target = app
        .world_mut()
        .spawn((
            Transform::default(),
            ScriptedMotion(Motion::Circle {
                center: [0.0, 1.0, 0.0],
                radius: 0.5,
                omega: 3.0,
                phase: 0.0,
                a: [1.0, 0.0, 0.0],
                b: [0.0, 0.0, 1.0],
            }),
        ))
        .id();
    let mut s2 = chain_scene();
    s2.particles[0].pinned = false;
    let e2 = spawn(&mut app, &s2, SoftBody::default());
    let first = app.world().get::<BodyParticles>(e2).unwrap().entities()[0];
    let offset = Vec3::new(0.0, -0.1, 0.0);
    app.world_mut()
        .entity_mut(first)
        .insert(Pinned::to(target, offset));
    for _ in 0..200 {
        app.update();
        assert_eq!(particles_of(&app, e)[0], p0, "a pinned particle moved");
        let gt = app.world().get::<GlobalTransform>(target).unwrap();
        let want = gt.transform_point(offset);
        let got = app.world().get::<Particle>(first).unwrap().position;
        assert_eq!(got, want, "the follower is off its target");
    }
    let xs = particles_of(&app, e2);
    assert!(xs.iter().all(|x| x.is_finite()));
    assert_eq!(status(&app, e2).state, BodyState::Running);
}

#[test]
fn cloth_never_sinks_into_the_swinging_sphere() {
    // The cloth_sphere scene (16×16 here, RK4 at h = 0.0025 as the example): after every fixed
    // step every particle is outside the sphere by at least its contact thickness, less 1 mm.
    let p = build::ClothParams::default();
    let scene = build::cloth_sphere(&p, 0.25, 0.6, 4.0).unwrap();
    let c = &scene.colliders[0];
    let radius = match c.shape {
        bevy_soft_body::core::collide::ShapeDesc::Sphere { radius } => radius as f32,
        _ => unreachable!(),
    };
    let thickness = c.material.thickness as f32;
    let mut app = app();
    let e = spawn(
        &mut app,
        &scene,
        SoftBody {
            integrator: IntegratorKind::Rk4,
            step: StepPolicy::Fixed { h: 0.0025 },
            ..Default::default()
        },
    );
    let mut q = app
        .world_mut()
        .query_filtered::<&GlobalTransform, With<SoftBodyCollider>>();
    let mut closest = f32::INFINITY;
    for _ in 0..(5.0 / FRAME) as usize {
        app.update();
        let center = q.single(app.world()).unwrap().translation();
        for x in particles_of(&app, e) {
            closest = closest.min(x.distance(center) - radius);
        }
    }
    println!(
        "closest approach to the sphere's surface over 5 s: {closest:.4} m (thickness {thickness})"
    );
    assert_eq!(status(&app, e).state, BodyState::Running);
    assert!(closest >= thickness - 1e-3, "{closest}");
}

#[test]
fn cloth_sphere_through_the_plugin_tracks_the_core_driver() {
    // The same scene through both: the only difference is the collider's path, exact in the
    // core (its `Oscillate` motion evaluated at every substep) and linear between fixed steps
    // in the plugin (its velocity from the transform change). Without colliders the two are
    // bitwise equal; with the sphere sweeping through the cloth the contact amplifies the path
    // difference to about 1.5 cm by t = 4.5 s (measured). Bound: 3 cm, and one model build.
    let p = build::ClothParams::default();
    let scene = build::cloth_sphere(&p, 0.25, 0.6, 4.0).unwrap();
    let h = 0.0025;
    let mut app = app();
    let e = spawn(
        &mut app,
        &scene,
        SoftBody {
            integrator: IntegratorKind::Rk4,
            step: StepPolicy::Fixed { h },
            ..Default::default()
        },
    );
    let (model, state) = scene.build().unwrap();
    let mut core = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: IntegratorKind::Rk4,
            policy: StepPolicy::Fixed { h },
            frame_dt: FRAME,
            ..Default::default()
        },
    );
    let mut worst = 0.0f32;
    for _ in 0..(4.5 / FRAME) as usize {
        app.update();
        core.advance_frame().unwrap();
        let xs = particles_of(&app, e);
        let mut w = 0.0f32;
        for (a, b) in xs.iter().zip(&core.state.x) {
            w = w.max(a.distance(b.to_f32()));
        }
        worst = worst.max(w);
    }
    let st = status(&app, e);
    println!(
        "largest distance from the core's cloth over 4.5 s: {worst:.4} m; {} rebuilds",
        st.rebuilds
    );
    assert_eq!(st.rebuilds, 1);
    assert!(worst < 0.03, "{worst}");
}

fn ground(app: &mut App, friction: f32, restitution: f32) {
    app.world_mut()
        .spawn(SoftBodyCollider::ground().with_material(friction, restitution, 0.0));
}

fn lone_particle(app: &mut App, position: Vec3, velocity: Vec3, h: f64) -> Entity {
    let body = app
        .world_mut()
        .spawn(SoftBody {
            integrator: IntegratorKind::SymplecticEuler,
            step: StepPolicy::Fixed { h },
            ..Default::default()
        })
        .id();
    app.world_mut().spawn((
        Particle {
            position,
            velocity,
            mass: 0.1,
        },
        ParticleOf(body),
    ));
    body
}

#[test]
fn a_dropped_particle_rebounds_to_e_squared_times_its_height() {
    // Dropped from h₀ = 1 m on a plane with restitution e = 0.5: it leaves the plane with e
    // times its impact speed, so it climbs to e² h₀ = 0.25 m. Error sources: the impact speed
    // is read up to one substep (h = 1/1024 s) late, g h / v ≈ 0.2 %; the apex is sampled
    // once per frame, ½ g (Δt/2)² ≈ 0.3 mm.
    let mut app = app();
    ground(&mut app, 0.0, 0.5);
    let body = lone_particle(&mut app, Vec3::Y, Vec3::ZERO, 1.0 / 1024.0);
    let (mut bounced, mut apex) = (false, 0.0f32);
    for _ in 0..128 {
        app.update();
        let p = app
            .world()
            .get::<BodySim>(body)
            .unwrap()
            .simulation()
            .unwrap()
            .state
            .v[0];
        let y = particles_of(&app, body)[0].y;
        if p.y > 0.0 {
            bounced = true;
        }
        if bounced {
            apex = apex.max(y);
        }
    }
    println!("apex after the bounce: {apex:.4} m (e² h₀ = 0.25 m)");
    assert!(bounced);
    assert!((apex - 0.25).abs() <= 0.02 * 0.25, "{apex}");
}

#[test]
fn a_sliding_particle_stops_where_coulomb_friction_says() {
    // Sliding at v₀ = 2 m/s on a plane with μ = 0.3: deceleration μ g, stopping distance
    // v₀² / (2 μ g) = 0.6796 m.
    let mut app = app();
    ground(&mut app, 0.3, 0.0);
    let body = lone_particle(&mut app, Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0), 1.0 / 1024.0);
    for _ in 0..128 {
        app.update();
    }
    let x = particles_of(&app, body)[0];
    let expected = 4.0 / (2.0 * 0.3 * 9.81);
    println!(
        "stopped at x = {:.4} m (Coulomb: {expected:.4} m), y = {:.2e}",
        x.x, x.y
    );
    assert!((x.x - expected).abs() <= 0.05 * expected, "{x}");
}

#[test]
fn despawning_springs_and_particles_mid_run_keeps_the_body_stepping() {
    let mut app = app();
    let e = spawn(&mut app, &chain_scene(), SoftBody::default());
    for _ in 0..30 {
        app.update();
    }
    let spring = app.world().get::<BodySprings>(e).unwrap().entities()[3];
    app.world_mut().despawn(spring);
    for _ in 0..30 {
        app.update();
    }
    assert_eq!(status(&app, e).springs, 3, "the cut spring is gone");
    // A particle two springs refer to: they are left out with a warning.
    let middle = app.world().get::<BodyParticles>(e).unwrap().entities()[2];
    app.world_mut().despawn(middle);
    for _ in 0..30 {
        app.update();
    }
    let st = status(&app, e);
    assert_eq!(st.state, BodyState::Running);
    assert_eq!(st.particles, 4);
    assert_eq!(
        st.springs, 1,
        "only the spring between particles 0 and 1 is left"
    );
    assert_eq!(frames(&app, e), 30, "30 frames since the rebuild");
    assert!(particles_of(&app, e).iter().all(|x| x.is_finite()));
}

/// The body's mesh: positions, normals, texture coordinates and triangles.
type MeshData = (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<[f32; 2]>, Vec<u32>);

fn mesh_of(app: &App, body: Entity) -> MeshData {
    use bevy::mesh::{Indices, VertexAttributeValues as V};
    let handle = &app.world().get::<Mesh3d>(body).expect("a mesh").0;
    let mesh = app.world().resource::<Assets<Mesh>>().get(handle).unwrap();
    let f3 = |a| match mesh.attribute(a) {
        Some(V::Float32x3(v)) => v.clone(),
        _ => vec![],
    };
    let uv = match mesh.attribute(Mesh::ATTRIBUTE_UV_0) {
        Some(V::Float32x2(v)) => v.clone(),
        _ => vec![],
    };
    let idx = match mesh.indices() {
        Some(Indices::U32(i)) => i.clone(),
        _ => vec![],
    };
    (
        f3(Mesh::ATTRIBUTE_POSITION),
        f3(Mesh::ATTRIBUTE_NORMAL),
        uv,
        idx,
    )
}

#[test]
fn a_surface_detail_draws_a_finer_mesh_that_the_particles_carry() {
    use bevy_soft_body::core::detail::{Rounding, Tessellation};
    use bevy_soft_body::render::SurfaceDetail;
    let mut app = app();
    app.add_plugins(bevy::asset::AssetPlugin::default())
        .init_asset::<Mesh>();
    // A lying cloth held at its four corners sags into a bowl (a hanging one would stay in
    // its plane, where rounding has nothing to do).
    let scene = build::cloth(&build::ClothParams {
        pins: build::ClothPins::FourCorners,
        hanging: false,
        ..Default::default()
    })
    .unwrap();
    let surface = scene.surface.clone().unwrap();
    let n = scene.particles.len();
    let e = spawn(&mut app, &scene, SoftBody::default());
    app.world_mut()
        .entity_mut(e)
        .insert(SurfaceDetail::level(3));
    // The mesh the core's tessellation makes of the particles where they are (the plugin
    // draws the last step exactly: interpolation is off).
    let expected = |app: &App, level: u32| {
        let xs = particles_of(app, e);
        let fine = Tessellation::new(&surface.triangles, n, level).unwrap();
        let mut y = vec![[0.0; 3]; fine.len()];
        fine.apply(&xs, Rounding::default(), &mut y);
        (y, fine)
    };
    for frames in [60, 5] {
        for _ in 0..frames {
            app.update();
        }
        let (pos, nrm, uv, idx) = mesh_of(&app, e);
        let (y, fine) = expected(&app, 3);
        // 16² cloth, level 3: a 46² grid (3 · 15 + 1 a side).
        assert_eq!(pos.len(), 46 * 46);
        assert_eq!(
            pos, y,
            "the mesh follows the particles through the tessellation"
        );
        for (p, x) in pos.iter().zip(particles_of(&app, e)) {
            assert_eq!(Vec3::from_array(*p), x, "coarse vertices are the particles");
        }
        assert_eq!(uv, fine.interpolate(&surface.uvs));
        assert_eq!(
            idx,
            fine.triangles()
                .iter()
                .flatten()
                .copied()
                .collect::<Vec<_>>()
        );
        let mut shade = vec![[0.0; 3]; fine.len()];
        fine.shade(&fine.coarse_normals(&particles_of(&app, e)), &mut shade);
        assert_eq!(nrm, shade);
        assert!(
            nrm.iter()
                .all(|n| (Vec3::from_array(*n).length() - 1.0).abs() < 1e-5)
        );
        // The display does leave the flat triangles.
        let flat = fine.skin().zip(&pos).map(|((c, w), p)| {
            let x = particles_of(&app, e);
            let q = x[c[0] as usize] * w[0] + x[c[1] as usize] * w[1] + x[c[2] as usize] * w[2];
            q.distance(Vec3::from_array(*p))
        });
        let lift = flat.fold(0.0, f32::max);
        assert!(lift > 1e-4, "{lift}");
    }
    // Another level remakes the mesh; removing the detail draws the particles again.
    app.world_mut()
        .entity_mut(e)
        .insert(SurfaceDetail::level(2));
    app.update();
    assert_eq!(mesh_of(&app, e).0, expected(&app, 2).0);
    app.world_mut().entity_mut(e).remove::<SurfaceDetail>();
    app.update();
    let plain: Vec<[f32; 3]> = particles_of(&app, e).iter().map(|p| p.to_array()).collect();
    assert_eq!(mesh_of(&app, e).0, plain);
    // Settings that cannot be used: drawn as simulated (and a warning names the body).
    app.world_mut().entity_mut(e).insert(SurfaceDetail {
        roundness: f32::NAN,
        ..Default::default()
    });
    app.update();
    assert_eq!(mesh_of(&app, e).0.len(), n);
    // Beyond `far` from the camera: drawn as simulated; back within 0.9 × far: fine again.
    app.world_mut().entity_mut(e).insert(SurfaceDetail {
        far: Some(5.0),
        ..SurfaceDetail::level(3)
    });
    let cam = app
        .world_mut()
        .spawn((Camera3d::default(), Transform::from_xyz(0.0, 0.5, 3.0)))
        .id();
    app.update();
    assert_eq!(mesh_of(&app, e).0.len(), 46 * 46, "near: fine");
    app.world_mut()
        .entity_mut(cam)
        .insert(Transform::from_xyz(0.0, 0.5, 20.0));
    app.update();
    app.update();
    assert_eq!(mesh_of(&app, e).0.len(), n, "far: as simulated");
    // Just inside `far` is not enough to switch back (hysteresis), well inside is.
    let d = |app: &App| {
        let x = particles_of(app, e);
        let (lo, hi) = x
            .iter()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), p| {
                (l.min(*p), h.max(*p))
            });
        ((lo + hi) * 0.5, (hi - lo).length() * 0.5)
    };
    let (c, r) = d(&app);
    app.world_mut()
        .entity_mut(cam)
        .insert(Transform::from_translation(c + Vec3::Z * (r + 4.8)));
    app.update();
    app.update();
    assert_eq!(
        mesh_of(&app, e).0.len(),
        n,
        "within the hysteresis band: unchanged"
    );
    app.world_mut()
        .entity_mut(cam)
        .insert(Transform::from_translation(c + Vec3::Z * (r + 4.0)));
    app.update();
    app.update();
    assert_eq!(mesh_of(&app, e).0.len(), 46 * 46, "near again: fine");
}

#[test]
fn mesh_vertices_are_the_particles_and_normals_are_unit() {
    let mut app = app();
    app.add_plugins(bevy::asset::AssetPlugin::default())
        .init_asset::<Mesh>();
    let scene = build::cloth(&build::ClothParams::default()).unwrap();
    let e = spawn(&mut app, &scene, SoftBody::default());
    for _ in 0..20 {
        app.update();
    }
    let xs = particles_of(&app, e);
    let handle = app
        .world()
        .get::<Mesh3d>(e)
        .expect("a mesh was made")
        .0
        .clone();
    let meshes = app.world().resource::<Assets<Mesh>>();
    let mesh = meshes.get(&handle).unwrap();
    let pos = mesh
        .attribute(Mesh::ATTRIBUTE_POSITION)
        .unwrap()
        .as_float3()
        .unwrap()
        .to_vec();
    let nrm = match mesh.attribute(Mesh::ATTRIBUTE_NORMAL).unwrap() {
        bevy::mesh::VertexAttributeValues::Float32x3(n) => n.clone(),
        _ => panic!("normals"),
    };
    assert_eq!(pos.len(), xs.len());
    for (p, x) in pos.iter().zip(&xs) {
        assert_eq!(Vec3::from_array(*p), *x);
    }
    for n in nrm {
        assert!((Vec3::from_array(n).length() - 1.0).abs() < 1e-5);
    }
    assert!(app.world().get::<SoftBodySurface>(e).is_some());

    // A particle added to the body (as the mouse grab does) must not freeze or shift the
    // surface: its vertices stay tied to their particles.
    let corner = app.world().get::<BodyParticles>(e).unwrap().entities()[0];
    let extra = app
        .world_mut()
        .spawn((
            Particle::at(Vec3::new(0.0, 2.0, 0.0), 1.0),
            ParticleOf(e),
            Pinned::here(),
        ))
        .id();
    app.world_mut().spawn((
        Spring {
            a: corner,
            b: extra,
            rest_length: 0.5,
            stiffness: 10.0,
            damping: 0.0,
            law: Default::default(),
        },
        SpringOf(e),
    ));
    for _ in 0..5 {
        app.update();
    }
    let xs = particles_of(&app, e);
    assert_eq!(xs.len(), pos.len() + 1);
    let meshes = app.world().resource::<Assets<Mesh>>();
    let now = meshes
        .get(&handle)
        .unwrap()
        .attribute(Mesh::ATTRIBUTE_POSITION)
        .unwrap()
        .as_float3()
        .unwrap();
    for (p, x) in now.iter().zip(&xs) {
        assert_eq!(
            Vec3::from_array(*p),
            *x,
            "the surface stopped following its particles"
        );
    }

    // Interpolated drawing: between the last two fixed steps by the fixed clock's overstep,
    // which is exactly zero when every update runs one whole fixed step — so the mesh shows
    // the positions before the last step, while the components hold the last step.
    app.world_mut()
        .resource_mut::<bevy_soft_body::render::SoftBodyDebug>()
        .interpolate = true;
    app.update();
    let prev = app
        .world()
        .get::<bevy_soft_body::render::PreviousPositions>(e)
        .unwrap()
        .positions()
        .to_vec();
    let xs = particles_of(&app, e);
    assert_eq!(prev.len(), xs.len());
    assert_ne!(prev, xs, "the cloth moved in the last step");
    let meshes = app.world().resource::<Assets<Mesh>>();
    let pos = meshes
        .get(&handle)
        .unwrap()
        .attribute(Mesh::ATTRIBUTE_POSITION)
        .unwrap()
        .as_float3()
        .unwrap();
    for (p, q) in pos.iter().zip(&prev) {
        assert_eq!(Vec3::from_array(*p), *q);
    }
}

#[test]
fn particles_land_on_cuboids_and_trimeshes() {
    // Any parry shape works through the general projection path: a particle dropped on a
    // 1 m cuboid (top face at y = 0.5) and one on a two-triangle trimesh floor at y = 0.25
    // come to rest on the surface plus the contact thickness (1 cm).
    use parry3d::math::Vector as PVec;
    use parry3d::shape::SharedShape;
    let mut app = app();
    app.world_mut().spawn((
        SoftBodyCollider::new(SharedShape::cuboid(0.5, 0.5, 0.5)).with_material(0.5, 0.0, 0.01),
        Transform::from_xyz(0.0, 0.0, 0.0),
    ));
    let floor = SharedShape::trimesh(
        vec![
            PVec::new(2.0, 0.25, -1.0),
            PVec::new(4.0, 0.25, -1.0),
            PVec::new(4.0, 0.25, 1.0),
            PVec::new(2.0, 0.25, 1.0),
        ],
        vec![[0, 2, 1], [0, 3, 2]],
    )
    .unwrap();
    app.world_mut()
        .spawn(SoftBodyCollider::new(floor).with_material(0.5, 0.0, 0.01));
    let on_cube = lone_particle(&mut app, Vec3::new(0.1, 1.0, 0.1), Vec3::ZERO, 1.0 / 1024.0);
    let on_mesh = lone_particle(&mut app, Vec3::new(3.0, 1.0, 0.0), Vec3::ZERO, 1.0 / 1024.0);
    for _ in 0..192 {
        app.update();
    }
    let (a, b) = (
        particles_of(&app, on_cube)[0],
        particles_of(&app, on_mesh)[0],
    );
    println!(
        "resting on the cuboid at y = {:.4}, on the trimesh at y = {:.4}",
        a.y, b.y
    );
    assert!((a.y - 0.51).abs() < 2e-3, "{a}");
    assert!((b.y - 0.26).abs() < 2e-3, "{b}");
}

#[test]
fn scene_files_spawn_and_bad_files_name_themselves() {
    let dir = std::env::temp_dir().join(format!("bsb_plugin_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = dir.join("chain.json");
    std::fs::write(&good, chain_scene().to_json()).unwrap();
    let bad = dir.join("bad.json");
    std::fs::write(&bad, "{ \"particles\": [ { \"mass\": -1 } ] }").unwrap();
    let mut app = app();
    let (g, b) = (good.clone(), bad.clone());
    let (ok, err) = app
        .world_mut()
        .run_system_once(move |mut c: Commands| {
            (
                c.spawn_soft_body_file(&g, SoftBody::default()),
                c.spawn_soft_body_file(&b, SoftBody::default()),
            )
        })
        .unwrap();
    let e = ok.unwrap();
    let err = err.unwrap_err().to_string();
    println!("{err}");
    assert!(err.contains("bad.json"), "{err}");
    for _ in 0..10 {
        app.update();
    }
    assert_eq!(status(&app, e).particles, 5);
    assert_eq!(frames(&app, e), 10);
}

#[test]
fn bad_input_leaves_the_body_out_with_a_message_naming_the_culprit() {
    let mut app = app();
    let good = spawn(&mut app, &chain_scene(), SoftBody::default());
    let mk = |app: &mut App, body: SoftBody, mass: f32, pos: Vec3| {
        let b = app.world_mut().spawn(body).id();
        let p = app
            .world_mut()
            .spawn((
                Particle {
                    position: pos,
                    velocity: Vec3::ZERO,
                    mass,
                },
                ParticleOf(b),
            ))
            .id();
        (b, p)
    };
    let (massless, mp) = mk(&mut app, SoftBody::default(), 0.0, Vec3::ZERO);
    let (nan, np) = mk(&mut app, SoftBody::default(), 1.0, Vec3::NAN);
    let bad_h = SoftBody {
        step: StepPolicy::Fixed { h: 0.0 },
        ..Default::default()
    };
    let (zero_h, _) = mk(&mut app, bad_h, 1.0, Vec3::ZERO);
    // A spring to an entity that is no particle: left out, the body runs.
    let (lonely, lp) = mk(&mut app, SoftBody::default(), 1.0, Vec3::ZERO);
    let stranger = app.world_mut().spawn_empty().id();
    app.world_mut().spawn((
        Spring {
            a: lp,
            b: stranger,
            rest_length: 1.0,
            stiffness: 10.0,
            damping: 0.0,
            law: Default::default(),
        },
        SpringOf(lonely),
    ));
    for _ in 0..10 {
        app.update();
    }
    let invalid = |e: Entity| match status(&app, e).state {
        BodyState::Invalid(m) => m,
        other => panic!("{e}: {other:?}"),
    };
    let m = invalid(massless);
    println!("{m}");
    assert!(m.contains(&mp.to_string()) && m.contains("mass"), "{m}");
    let m = invalid(nan);
    println!("{m}");
    assert!(
        m.contains(&np.to_string()) && m.contains("position must be finite"),
        "{m}"
    );
    let m = invalid(zero_h);
    println!("{m}");
    assert!(m.contains("h = 0"), "{m}");
    assert_eq!(status(&app, lonely).state, BodyState::Running);
    assert_eq!(status(&app, lonely).springs, 0);
    // The good body kept stepping, finite; nothing was written into the bad ones.
    assert_eq!(frames(&app, good), 10);
    assert!(particles_of(&app, good).iter().all(|x| x.is_finite()));
    assert!(
        app.world()
            .get::<BodySim>(nan)
            .unwrap()
            .simulation()
            .is_none()
    );
}

#[test]
fn a_diverging_body_stops_alone_with_a_message_and_no_nan() {
    // Forward Euler on the stiff pendulum at h = 1/64 (one step per frame; ω = √(k/μ) ≈ 64
    // rad/s, h ω ≈ 1, and forward Euler has no stable step without damping): it must blow up,
    // be stopped by the guard with its last good state, send `SoftBodyDiverged`, and leave
    // the RK4 body beside it stepping.
    let mut app = app();
    let bad = spawn(
        &mut app,
        &chain_scene(),
        SoftBody {
            integrator: IntegratorKind::ForwardEuler,
            step: StepPolicy::Fixed { h: FRAME },
            ..Default::default()
        },
    );
    let good = spawn(&mut app, &chain_scene(), SoftBody::default());
    // The same news as an entity event, caught by an observer on the body itself.
    #[derive(Resource, Default)]
    struct Caught(Vec<(Entity, String)>);
    app.init_resource::<Caught>();
    app.world_mut().entity_mut(bad).observe(
        |d: On<SoftBodyDiverged>, mut caught: ResMut<Caught>| {
            caught.0.push((d.event_target(), d.message.clone()));
        },
    );
    let mut sent = vec![];
    for _ in 0..400 {
        app.update();
        // Messages live for two updates: collect them as they come.
        let messages = app.world().resource::<Messages<SoftBodyDiverged>>();
        sent.extend(messages.iter_current_update_messages().map(|m| m.body));
    }
    let msg = match status(&app, bad).state {
        BodyState::Diverged(m) => m,
        other => panic!("expected a divergence, got {other:?}"),
    };
    println!("{msg}");
    assert!(msg.contains("forward Euler"), "{msg}");
    assert_eq!(sent, vec![bad], "one SoftBodyDiverged, for that body");
    let caught = &app.world().resource::<Caught>().0;
    assert_eq!(caught.len(), 1, "the observer on the body saw it once");
    assert_eq!(caught[0].0, bad);
    assert!(caught[0].1.contains("forward Euler"), "{}", caught[0].1);
    assert!(particles_of(&app, bad).iter().all(|x| x.is_finite()));
    assert_eq!(status(&app, good).state, BodyState::Running);
    assert_eq!(frames(&app, good), 400);
}

#[test]
fn runtime_edits_teleport_and_retune_on_the_next_step() {
    let mut app = app();
    let e = spawn(&mut app, &chain_scene(), SoftBody::default());
    for _ in 0..10 {
        app.update();
    }
    // Teleport the last particle: the next step starts from there (one step of 1/64 s moves
    // it by about |v| / 64, far less than the 5 m jump).
    let last = *app
        .world()
        .get::<BodyParticles>(e)
        .unwrap()
        .entities()
        .last()
        .unwrap();
    let target = Vec3::new(5.0, 5.0, 0.0);
    app.world_mut().get_mut::<Particle>(last).unwrap().position = target;
    app.update();
    let at = app.world().get::<Particle>(last).unwrap().position;
    assert!(at.distance(target) < 0.5, "teleport ignored: {at}");
    assert_eq!(status(&app, e).rebuilds, 1, "a teleport needs no rebuild");
    // Retune a spring: the model is rebuilt with the new stiffness.
    let spring = app.world().get::<BodySprings>(e).unwrap().entities()[0];
    app.world_mut().get_mut::<Spring>(spring).unwrap().stiffness = 1000.0;
    app.update();
    let st = status(&app, e);
    assert_eq!(st.rebuilds, 2);
    let k = app
        .world()
        .get::<BodySim>(e)
        .unwrap()
        .simulation()
        .unwrap()
        .system
        .springs
        .as_slice()[0]
        .k;
    assert_eq!(k as f32, 1000.0);
}

#[test]
fn the_plugin_runs_in_another_schedule() {
    // `SoftBodyPlugin::new(Update)`: one step per app update, the frame still Time<Fixed>'s.
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, TransformPlugin, SoftBodyPlugin::new(Update)))
        .insert_resource(Time::<Fixed>::from_seconds(FRAME));
    let e = spawn(&mut app, &chain_scene(), SoftBody::default());
    for _ in 0..7 {
        app.update();
    }
    assert_eq!(frames(&app, e), 7);
}

/// A plain collider takes its transform's scale: a ball of radius 0.1 scaled by 2 holds a
/// particle dropped on it at 0.2 m (plus the contact thickness) above its centre.
#[test]
fn a_scaled_collider_is_as_large_as_it_looks() {
    let mut app = app();
    app.world_mut().spawn((
        SoftBodyCollider::ball(0.1),
        Transform::from_xyz(0.0, 0.0, 0.0).with_scale(Vec3::splat(2.0)),
    ));
    let scene = Scene {
        gravity: [0.0, -9.8125, 0.0],
        particles: vec![bevy_soft_body::core::scene::ParticleDesc {
            position: [0.0, 0.5, 0.0],
            velocity: [0.0; 3],
            mass: 0.125,
            pinned: false,
        }],
        ..Default::default()
    };
    let body = spawn(
        &mut app,
        &scene,
        SoftBody {
            integrator: IntegratorKind::SymplecticEuler,
            step: StepPolicy::Fixed { h: 1.0 / 512.0 },
            ..Default::default()
        },
    );
    for _ in 0..64 {
        app.update();
    }
    let y = particles_of(&app, body)[0].y;
    assert!((y - 0.21).abs() < 1e-4, "rests at {y}, expected 0.2 + 0.01");
}

/// `SoftBody::hold_faces` reaches the body's model, and it is what keeps a cloth on a rod as
/// wide as its cells from wedging through the plugin: the pile's 32² cloth over 0.6 m (cells
/// of 1.94 cm) dropped from 0.75 m onto a capsule of 1 cm radius at 0.3 m, linearly implicit
/// Euler in steps of a frame (1/64 s), for 3 s. With the triangles held inside the solve (the
/// default) it hangs on the rod at rest, its springs stretched by its weight alone (3 %: see
/// `tests/collider_faces.rs`, which asks for less than 15 %); without, each step's springs
/// pull the triangles round the rod, the contact after the step pushes them back out, and the
/// cloth stays wedged, stretched several times (4.9 in the core at 1/60 s), unless the energy
/// guard stops it first.
#[test]
fn holding_the_triangles_keeps_a_cloth_on_a_thin_rod_from_wedging() {
    let scene = common::cloth_on_a_rod(0.01, 0.3);
    let (n, edge) = (32, (0.6 / 31.0) as f32);
    let mut results = vec![];
    for hold_faces in [true, false] {
        let mut app = app();
        let body = SoftBody {
            integrator: IntegratorKind::LinearlyImplicitEuler,
            step: StepPolicy::Fixed { h: FRAME },
            hold_faces,
            ..Default::default()
        };
        let e = spawn(&mut app, &scene, body);
        for _ in 0..192 {
            app.update();
        }
        let sim = app.world().get::<BodySim>(e).unwrap().simulation().unwrap();
        assert_eq!(sim.system.hold_faces, hold_faces, "the model's switch");
        let x = particles_of(&app, e);
        let mut strain: f32 = 0.0;
        for row in 0..n {
            for c in 0..n {
                let i = row * n + c;
                if c + 1 < n {
                    strain = strain.max(x[i].distance(x[i + 1]) / edge);
                }
                if row + 1 < n {
                    strain = strain.max(x[i].distance(x[i + n]) / edge);
                }
            }
        }
        let state = status(&app, e).state;
        println!("hold_faces {hold_faces}: {state:?}, largest strain {strain:.3} at 3 s");
        results.push((state, strain));
    }
    let [held, loose]: [(BodyState, f32); 2] = results.try_into().unwrap();
    assert!(
        held.0 == BodyState::Running && held.1 < 1.15,
        "held: {held:?}"
    );
    assert!(
        loose.0 != BodyState::Running || loose.1 > 1.5,
        "without the holds the cloth did not wedge: {loose:?}"
    );
}
