//! The plugin as a Bevy citizen (headless `MinimalPlugins`, 1/64 s fixed steps): its
//! measurements reach Bevy's `DiagnosticsStore` with the values the bodies' own counters give;
//! invalid bodies are announced to observers on them; and soft bodies survive a save and load
//! through Bevy's reflected world serialization (RON), entities remapped, still stepping.
#![cfg(feature = "plugin")]
#![allow(clippy::unnecessary_cast)]

mod common;

use common::latest;

use bevy::asset::{AssetPath, LoadFromPath, UntypedHandle};
use bevy::ecs::entity::EntityHashMap;
use bevy::ecs::system::RunSystemOnce;
use bevy::prelude::*;
use bevy::world_serialization::serde::WorldDeserializer;
use bevy::world_serialization::{DynamicWorld, DynamicWorldBuilder};
use bevy_soft_body::core::build;
use bevy_soft_body::core::driver::StepPolicy;
use bevy_soft_body::core::fem::NeoHookean;
use bevy_soft_body::core::fem::mesh::TetMesh;
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::ecs::*;
use serde::de::DeserializeSeed;
use std::any::TypeId;

const FRAME: f64 = 1.0 / 64.0;

fn app() -> App {
    common::headless_app(FRAME)
}

fn cloth() -> bevy_soft_body::core::scene::Scene {
    build::cloth(&build::ClothParams::default().resized(8, 8)).unwrap()
}

const MAT: NeoHookean = NeoHookean {
    young: 2e5,
    poisson: 0.4,
    density: 1000.0,
};

fn tet_block() -> TetMesh {
    TetMesh::tet_box([0.3, 0.2, 0.2], [3, 2, 2])
        .unwrap()
        .transformed(1.0, [2.0, 1.0, 0.0])
}

fn spawn_both(app: &mut App, cloth_body: SoftBody, tet_body: SoftBody) -> (Entity, Entity) {
    let scene = cloth();
    app.world_mut()
        .run_system_once(move |mut c: Commands| {
            let a = c.spawn_soft_body(&scene, cloth_body.clone()).unwrap();
            let b = c
                .spawn_tet_body(&tet_block(), MAT, tet_body.clone(), None)
                .unwrap();
            (a, b)
        })
        .unwrap()
}

fn status(app: &App, e: Entity) -> SoftBodyStatus {
    app.world().get::<SoftBodyStatus>(e).unwrap().clone()
}

#[test]
fn diagnostics_reach_the_store_with_the_bodies_counts() {
    // A cloth in symplectic Euler at h = 1/64 / 8 (eight substeps a frame, by construction)
    // and a tet block in backward Euler (one step a frame, Newton iterations, direct solves:
    // no CG iterations), then the same block in linearly implicit Euler with CG.
    let mut app = app();
    let (c, t) = spawn_both(
        &mut app,
        SoftBody {
            integrator: IntegratorKind::SymplecticEuler,
            step: StepPolicy::Fixed {
                h: (FRAME / 8.0) as _,
            },
            ..Default::default()
        },
        SoftBody {
            integrator: IntegratorKind::BackwardEuler,
            step: StepPolicy::Fixed { h: FRAME as _ },
            ..Default::default()
        },
    );
    for _ in 0..5 {
        app.update();
    }
    let (sc, st) = (status(&app, c), status(&app, t));
    assert_eq!(sc.substeps, 8);
    assert_eq!(st.substeps, 1);
    assert!(st.newton_iterations >= 1, "{st:?}");
    assert_eq!(sc.newton_iterations, 0);
    assert_eq!(latest(&app, &SoftBodyDiagnostics::BODIES), 2.0);
    assert_eq!(
        latest(&app, &SoftBodyDiagnostics::PARTICLES),
        (sc.particles + st.particles) as f64
    );
    assert_eq!(latest(&app, &SoftBodyDiagnostics::SUBSTEPS), 9.0);
    assert_eq!(
        latest(&app, &SoftBodyDiagnostics::NEWTON_ITERATIONS),
        st.newton_iterations as f64
    );
    let ms = latest(&app, &SoftBodyDiagnostics::STEP_TIME);
    assert!(ms > 0.0 && ms.is_finite(), "{ms}");
    // The step set's wall time covers both bodies (stepped in parallel: at least the slower).
    assert!(
        ms >= sc.step_ms.max(st.step_ms) as f64 * 0.999,
        "{ms} {sc:?} {st:?}"
    );

    // Linearly implicit Euler with the conjugate-gradient solver: its iterations are counted.
    app.world_mut().entity_mut(t).insert(LinearSolverChoice(
        bevy_soft_body::core::integrate::SolverChoice::Pcg,
    ));
    app.world_mut().get_mut::<SoftBody>(t).unwrap().integrator =
        IntegratorKind::LinearlyImplicitEuler;
    for _ in 0..3 {
        app.update();
    }
    let st = status(&app, t);
    assert!(st.linear_iterations > 0, "{st:?}");
    assert_eq!(st.newton_iterations, 0);
    assert_eq!(
        latest(&app, &SoftBodyDiagnostics::LINEAR_ITERATIONS),
        st.linear_iterations as f64
    );
}

#[test]
fn observers_on_a_body_hear_that_it_is_invalid() {
    #[derive(Resource, Default)]
    struct Caught(Vec<(Entity, String)>);
    let mut app = app();
    app.init_resource::<Caught>();
    let body = app.world_mut().spawn(SoftBody::default()).id();
    app.world_mut().entity_mut(body).observe(
        |i: On<SoftBodyInvalid>, mut caught: ResMut<Caught>| {
            caught.0.push((i.event_target(), i.message.clone()));
        },
    );
    let p = app
        .world_mut()
        .spawn((
            Particle {
                position: Vec3::ZERO,
                velocity: Vec3::ZERO,
                mass: -1.0,
            },
            ParticleOf(body),
        ))
        .id();
    app.update();
    let caught = &app.world().resource::<Caught>().0;
    assert_eq!(caught.len(), 1, "{caught:?}");
    assert_eq!(caught[0].0, body);
    assert!(
        caught[0].1.contains(&format!("{p}")),
        "names the particle: {}",
        caught[0].1
    );
}

/// Asset handles in the saved world (none here: headless bodies have no meshes).
struct NoAssets;

impl LoadFromPath for NoAssets {
    fn load_from_path_erased(&mut self, _: TypeId, path: AssetPath<'static>) -> UntypedHandle {
        panic!("the saved bodies refer to no asset, yet {path} was asked for")
    }
}

/// Every entity of the soft bodies: roots, particles, springs, tets.
fn body_entities(app: &App, roots: &[Entity]) -> Vec<Entity> {
    let w = app.world();
    let mut out = vec![];
    for &r in roots {
        out.push(r);
        if let Some(p) = w.get::<BodyParticles>(r) {
            out.extend(p.entities());
        }
        if let Some(s) = w.get::<BodySprings>(r) {
            out.extend(s.entities());
        }
        if let Some(t) = w.get::<BodyTets>(r) {
            out.extend(t.entities());
        }
    }
    out
}

fn positions(app: &App, root: Entity) -> Vec<Vec3> {
    let w = app.world();
    w.get::<BodyParticles>(root)
        .unwrap()
        .entities()
        .iter()
        .map(|e| w.get::<Particle>(*e).unwrap().position)
        .collect()
}

#[test]
fn bodies_survive_a_save_and_load_round_trip() {
    // A pinned cloth and a tet block (its x = 2 face pinned) in symplectic Euler, 20 frames.
    let body = SoftBody {
        integrator: IntegratorKind::SymplecticEuler,
        step: StepPolicy::Fixed {
            h: (FRAME / 16.0) as _,
        },
        ..Default::default()
    };
    let mut a = app();
    let (c, t) = spawn_both(&mut a, body.clone(), body.clone());
    a.update();
    let tet_parts = a
        .world()
        .get::<BodyParticles>(t)
        .unwrap()
        .entities()
        .to_vec();
    for p in tet_parts {
        if (a.world().get::<Particle>(p).unwrap().position.x - 2.0).abs() < 1e-4 {
            a.world_mut().entity_mut(p).insert(Pinned::here());
        }
    }
    for _ in 0..20 {
        a.update();
    }
    let roots = [c, t];
    let saved_x: Vec<Vec<Vec3>> = roots.iter().map(|r| positions(&a, *r)).collect();

    // Save: the bodies' entities with their reflected components, as RON text.
    let registry = a.world().resource::<AppTypeRegistry>().clone();
    let text = {
        let reg = registry.read();
        let dw = DynamicWorldBuilder::from_world(a.world(), &reg)
            .extract_entities(body_entities(&a, &roots).into_iter())
            .build();
        dw.serialize(&reg).expect("soft bodies serialize")
    };
    if let Ok(path) = std::env::var("DUMP_SAVED_WORLD") {
        std::fs::write(path, &text).unwrap();
    }
    assert!(text.contains("bevy_soft_body::ecs::components::Spring"));
    assert!(text.contains("bevy_soft_body::ecs::components::Tet"));

    // Load into a fresh app, whose entity ids differ (a few entities spawned first).
    let mut b = app();
    for _ in 0..7 {
        b.world_mut().spawn_empty();
    }
    let loaded: DynamicWorld = {
        let reg = b.world().resource::<AppTypeRegistry>().clone();
        let reg = reg.read();
        let mut de = ron::de::Deserializer::from_str(&text).unwrap();
        WorldDeserializer {
            type_registry: &reg,
            load_from_path: &mut NoAssets,
        }
        .deserialize(&mut de)
        .map_err(|e| de.span_error(e))
        .unwrap_or_else(|e| panic!("soft bodies deserialize: {e}"))
    };
    let mut map = EntityHashMap::default();
    loaded
        .write_to_world(b.world_mut(), &mut map)
        .expect("soft bodies load");
    let (c2, t2) = (map[&c], map[&t]);
    assert!(c2 != c || t2 != t, "fresh ids");

    // Same particles, same positions, every reference remapped into the new world.
    for (r, x) in [c2, t2].iter().zip(&saved_x) {
        assert_eq!(&positions(&b, *r), x);
    }
    let w = b.world();
    let parts: std::collections::HashSet<Entity> = [c2, t2]
        .iter()
        .flat_map(|r| w.get::<BodyParticles>(*r).unwrap().entities().to_vec())
        .collect();
    for s in w.get::<BodySprings>(c2).unwrap().entities() {
        let s = w.get::<Spring>(*s).unwrap();
        assert!(
            parts.contains(&s.a) && parts.contains(&s.b),
            "spring remapped"
        );
    }
    for te in w.get::<BodyTets>(t2).unwrap().entities() {
        let tet = w.get::<Tet>(*te).unwrap();
        assert!(
            tet.particles.iter().all(|p| parts.contains(p)),
            "tet remapped"
        );
    }
    let init = w.get::<SoftBodyInitial>(c2).unwrap();
    assert!(init.particles.iter().all(|(p, _, _)| parts.contains(p)));

    // Both worlds step on from there identically (same components → same model → same bits).
    // The saved world is rebuilt from its components too: they hold f32 (Bevy's precision),
    // so in the f64 build its running state carries digits the file does not.
    for r in roots {
        a.world_mut().get_mut::<SoftBody>(r).unwrap().set_changed();
    }
    for _ in 0..10 {
        a.update();
        b.update();
    }
    for (r1, r2) in roots.iter().zip([c2, t2]) {
        let (x1, x2) = (positions(&a, *r1), positions(&b, r2));
        assert_eq!(x1, x2, "the loaded body steps as the saved one");
        assert_eq!(status(&b, r2).state, BodyState::Running);
    }
    assert_ne!(positions(&b, c2), saved_x[0], "the loaded cloth moved");
}
