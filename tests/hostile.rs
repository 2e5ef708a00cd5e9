//! Hostile input through the plugin: each case ends in a clear warning or a body left out with
//! a message naming the culprit, never a panic, and never a non-finite value written into the
//! world; the other bodies keep stepping.
#![cfg(feature = "plugin")]

use bevy::ecs::system::RunSystemOnce;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_soft_body::core::build;
use bevy_soft_body::core::driver::StepPolicy;
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::ecs::*;

fn app() -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, TransformPlugin, SoftBodyPlugin::default()))
        .insert_resource(Time::<Fixed>::from_seconds(1.0 / 64.0))
        .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
    app.update();
    app
}

fn state(app: &App, body: Entity) -> BodyState {
    app.world()
        .get::<SoftBodyStatus>(body)
        .unwrap()
        .state
        .clone()
}

fn positions(app: &App, body: Entity) -> Vec<Vec3> {
    let w = app.world();
    w.get::<BodyParticles>(body)
        .map(|p| p.entities().to_vec())
        .unwrap_or_default()
        .iter()
        .map(|e| w.get::<Particle>(*e).unwrap().position)
        .collect()
}

fn body_with(
    app: &mut App,
    body: SoftBody,
    particles: &[(Vec3, f32, bool)],
) -> (Entity, Vec<Entity>) {
    let b = app.world_mut().spawn(body).id();
    let ps = particles
        .iter()
        .map(|(x, m, pinned)| {
            let mut e = app.world_mut().spawn((Particle::at(*x, *m), ParticleOf(b)));
            if *pinned {
                e.insert(Pinned::here());
            }
            e.id()
        })
        .collect();
    (b, ps)
}

fn spring(app: &mut App, body: Entity, a: Entity, b: Entity, k: f32) -> Entity {
    app.world_mut()
        .spawn((
            Spring {
                a,
                b,
                rest_length: 0.5,
                stiffness: k,
                damping: 0.0,
                law: Default::default(),
            },
            SpringOf(body),
        ))
        .id()
}

#[test]
fn degenerate_springs_pins_and_steps_are_survived() {
    for kind in IntegratorKind::ALL {
        let mut app = app();
        let body = SoftBody {
            integrator: kind,
            // Larger than the 1/64 s frame: the driver takes the frame in one step.
            step: StepPolicy::Fixed { h: 1.0 },
            ..Default::default()
        };
        // Duplicate springs, a self spring and a zero-length spring (two particles at one
        // point) on a free pair hanging from a pin.
        let (b, p) = body_with(
            &mut app,
            body.clone(),
            &[
                (Vec3::ZERO, 1.0, true),
                (Vec3::new(0.0, -0.5, 0.0), 0.1, false),
                (Vec3::new(0.0, -0.5, 0.0), 0.1, false),
            ],
        );
        spring(&mut app, b, p[0], p[1], 50.0);
        spring(&mut app, b, p[0], p[1], 50.0);
        spring(&mut app, b, p[1], p[1], 50.0);
        spring(&mut app, b, p[1], p[2], 50.0);
        // Every particle pinned.
        let (all_pinned, q) = body_with(
            &mut app,
            body.clone(),
            &[(Vec3::X, 1.0, true), (Vec3::Y, 1.0, true)],
        );
        spring(&mut app, all_pinned, q[0], q[1], 10.0);
        for _ in 0..64 {
            app.update();
        }
        let xs = positions(&app, b);
        assert!(xs.iter().all(|x| x.is_finite()), "{kind}: {xs:?}");
        assert!(
            matches!(state(&app, b), BodyState::Running | BodyState::Diverged(_)),
            "{kind}: {:?}",
            state(&app, b)
        );
        // Accepted; with nothing free to move it is at rest from the start, and sleeps.
        assert!(
            matches!(
                state(&app, all_pinned),
                BodyState::Running | BodyState::Sleeping
            ),
            "{kind}: {:?}",
            state(&app, all_pinned)
        );
        assert_eq!(
            positions(&app, all_pinned),
            vec![Vec3::X, Vec3::Y],
            "{kind}"
        );
    }
}

#[test]
fn bad_parameters_name_their_entity() {
    let mut app = app();
    let good = app
        .world_mut()
        .run_system_once(|mut c: Commands| {
            c.spawn_soft_body(
                &build::chain(&build::ChainParams::default()).unwrap(),
                SoftBody::default(),
            )
            .unwrap()
        })
        .unwrap();
    // No particles at all.
    let empty = app.world_mut().spawn(SoftBody::default()).id();
    // A negative mass, a non-finite velocity, a NaN stiffness, a negative stiffness.
    let (neg, pn) = body_with(&mut app, SoftBody::default(), &[(Vec3::ZERO, -1.0, false)]);
    let (nanv, pv) = body_with(&mut app, SoftBody::default(), &[(Vec3::ZERO, 1.0, false)]);
    app.world_mut().get_mut::<Particle>(pv[0]).unwrap().velocity =
        Vec3::new(0.0, f32::INFINITY, 0.0);
    let (nank, pk) = body_with(
        &mut app,
        SoftBody::default(),
        &[(Vec3::ZERO, 1.0, true), (Vec3::X, 1.0, false)],
    );
    let sk = spring(&mut app, nank, pk[0], pk[1], f32::NAN);
    let (negk, pg) = body_with(
        &mut app,
        SoftBody::default(),
        &[(Vec3::ZERO, 1.0, true), (Vec3::X, 1.0, false)],
    );
    let sg = spring(&mut app, negk, pg[0], pg[1], -5.0);
    // A CFL policy with a zero number.
    let cfl = SoftBody {
        step: StepPolicy::Cfl {
            number: 0.0,
            max: 0.01,
            limit: Default::default(),
        },
        ..Default::default()
    };
    let (zero_cfl, _) = body_with(&mut app, cfl, &[(Vec3::ZERO, 1.0, false)]);
    for _ in 0..5 {
        app.update();
    }
    let invalid = |e: Entity| match state(&app, e) {
        BodyState::Invalid(m) => m,
        other => panic!("{e}: expected Invalid, got {other:?}"),
    };
    for (body, culprit, word) in [
        (empty, empty, "no particles"),
        (neg, pn[0], "mass"),
        (nanv, pv[0], "velocity must be finite"),
        (nank, sk, "spring"),
        (negk, sg, "spring"),
        (zero_cfl, zero_cfl, "CFL"),
    ] {
        let m = invalid(body);
        println!("{m}");
        assert!(m.contains(&culprit.to_string()) && m.contains(word), "{m}");
    }
    assert_eq!(state(&app, good), BodyState::Running);
    assert!(positions(&app, good).iter().all(|x| x.is_finite()));
}

/// One path from layout to model: the same broken number, written once into a scene and once
/// into the components of the body spawned from the valid scene, is refused by both faces, and
/// both name the same field (the scene by its path, the plugin by the entity and the field).
/// (A non-finite position or velocity written into a running body is a teleport, ignored with
/// a warning; a body built with one is left out, as `bad_parameters_name_their_entity` shows.)
#[test]
fn the_plugin_and_the_scene_refuse_the_same_inputs() {
    use bevy_soft_body::core::forces::{SpringLaw, Wind};
    use bevy_soft_body::core::scene::ForceDesc;
    let base = build::chain(&build::ChainParams {
        particles: 5,
        ..Default::default()
    })
    .unwrap();
    assert!(base.validate().is_ok());
    type SceneEdit = fn(&mut bevy_soft_body::core::scene::Scene);
    type WorldEdit = fn(&mut World, Entity, &[Entity], &[Entity]);
    // (scene path, what the plugin's message must name, the edit in both forms)
    let cases: Vec<(&str, &str, SceneEdit, WorldEdit)> = vec![
        (
            "particles[3].mass",
            "mass",
            |s| s.particles[3].mass = 0.0,
            |w, _, p, _| w.get_mut::<Particle>(p[3]).unwrap().mass = 0.0,
        ),
        (
            "particles[2].position",
            "position",
            |s| s.particles[2].position[1] = f64::NAN,
            |w, _, p, _| w.get_mut::<Particle>(p[2]).unwrap().position.y = f32::NAN,
        ),
        (
            "particles[2].velocity",
            "velocity",
            |s| s.particles[2].velocity[0] = f64::INFINITY,
            |w, _, p, _| w.get_mut::<Particle>(p[2]).unwrap().velocity.x = f32::INFINITY,
        ),
        (
            "springs[1].stiffness",
            "stiffness",
            |s| s.springs[1].stiffness = -1.0,
            |w, _, _, k| w.get_mut::<Spring>(k[1]).unwrap().stiffness = -1.0,
        ),
        (
            "springs[1].damping",
            "damping",
            |s| s.springs[1].damping = f64::NAN,
            |w, _, _, k| w.get_mut::<Spring>(k[1]).unwrap().damping = f32::NAN,
        ),
        (
            "springs[0].rest_length",
            "rest_length",
            |s| {
                s.springs[0].law = SpringLaw::Strain;
                s.springs[0].rest_length = Some(0.0);
            },
            |w, _, _, k| {
                let mut s = w.get_mut::<Spring>(k[0]).unwrap();
                s.law = SpringLaw::Strain;
                s.rest_length = 0.0;
            },
        ),
        (
            "forces[0].force",
            "force",
            |s| {
                s.forces.push(ForceDesc {
                    particle: 4,
                    force: [0.0, f64::NAN, 0.0],
                })
            },
            |w, _, p, _| {
                w.entity_mut(p[4])
                    .insert(ExternalForce(Vec3::new(0.0, f32::NAN, 0.0)));
            },
        ),
        (
            "gravity",
            "gravity",
            |s| s.gravity[0] = f64::NAN,
            |w, b, _, _| w.get_mut::<SoftBody>(b).unwrap().gravity = Some(Vec3::NAN),
        ),
        (
            "drag",
            "drag",
            |s| s.drag = -1.0,
            |w, b, _, _| w.get_mut::<SoftBody>(b).unwrap().drag = -1.0,
        ),
        (
            "wind",
            "wind",
            |s| {
                s.wind = Some(Wind {
                    coefficient: -1.0,
                    ..Default::default()
                })
            },
            |w, b, _, _| {
                w.entity_mut(b).insert(SoftBodyWind {
                    coefficient: -1.0,
                    ..Default::default()
                });
            },
        ),
    ];
    for (path, field, scene_edit, world_edit) in cases {
        let mut scene = base.clone();
        scene_edit(&mut scene);
        let err = scene.validate().expect_err(path);
        assert!(err.has(path), "{path}: scene says {err}");

        let mut app = app();
        let spawned = base.clone();
        let b = app
            .world_mut()
            .run_system_once(move |mut c: Commands| {
                c.spawn_soft_body(&spawned, SoftBody::default()).unwrap()
            })
            .unwrap();
        app.update();
        assert_eq!(state(&app, b), BodyState::Running, "{path}");
        let particles = app
            .world()
            .get::<BodyParticles>(b)
            .unwrap()
            .entities()
            .to_vec();
        let springs = app
            .world()
            .get::<BodySprings>(b)
            .unwrap()
            .entities()
            .to_vec();
        world_edit(app.world_mut(), b, &particles, &springs);
        app.update();
        app.update();
        if field == "position" || field == "velocity" {
            // On a running body, editing a position or velocity is a teleport; a non-finite
            // one is refused by ignoring it (with a warning): the body runs on and the
            // component is written back finite.
            assert_eq!(state(&app, b), BodyState::Running, "{path}");
            let w = app.world();
            assert!(particles.iter().all(|e| {
                let p = w.get::<Particle>(*e).unwrap();
                p.position.is_finite() && p.velocity.is_finite()
            }));
            continue;
        }
        let BodyState::Invalid(msg) = state(&app, b) else {
            panic!("{path}: the plugin accepted what the scene refused");
        };
        assert!(msg.contains(field), "{path}: plugin says {msg}");
        // The culprit entity is named where there is one.
        let culprit = match path.split('[').next().unwrap() {
            "particles" => particles[path[10..11].parse::<usize>().unwrap()],
            "springs" => springs[path[8..9].parse::<usize>().unwrap()],
            "forces" => particles[4],
            _ => b,
        };
        assert!(
            msg.contains(&culprit.to_string()),
            "{path}: {msg} names not {culprit}"
        );
        // Nothing non-finite reached the world.
        assert!(positions(&app, b).iter().all(|x| x.is_finite()));
    }
}
