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
        assert_eq!(state(&app, all_pinned), BodyState::Running, "{kind}");
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
        (nanv, pv[0], "not finite"),
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
