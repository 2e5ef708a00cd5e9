//! Cloth from the game's own meshes through the plugin (headless, 1/64 s fixed steps): the
//! cape of `assets/models/cape.gltf` (modelled with a UV seam down its middle and a red
//! pinned rim; see `make_cape.py` there) loaded by Bevy's glTF loader and spawned by
//! `SoftBodyGltf`; after 2 s of wind the deformed mesh has no crack at the seam and one normal
//! per seam position, the rim has not moved, and the rest has. A mesh made in code with pins
//! following an entity, and meshes the builder must refuse.
#![cfg(feature = "plugin")]
#![allow(clippy::unnecessary_cast)]

mod common;

use bevy::asset::AssetPlugin;
use bevy::ecs::system::RunSystemOnce;
use bevy::gltf::{Gltf, GltfPlugin};
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_soft_body::assets::{SoftBodySceneAsset, SoftBodySceneRoot, SoftBodySceneSpawned};
use bevy_soft_body::core::build::SurfaceParams;
use bevy_soft_body::core::forces::Wind;
use bevy_soft_body::ecs::*;

const FRAME: f64 = 1.0 / 64.0;

fn app() -> App {
    app_at(concat!(env!("CARGO_MANIFEST_DIR"), "/assets"))
}

fn app_at(assets: &str) -> App {
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        TransformPlugin,
        AssetPlugin {
            file_path: assets.into(),
            ..default()
        },
    ))
    .init_asset::<Mesh>()
    .init_asset::<Image>()
    .init_asset::<bevy::world_serialization::WorldAsset>()
    .add_plugins((GltfPlugin::default(), common::headless_plugins()))
    .insert_resource(Time::<Fixed>::from_seconds(FRAME))
    .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
    // What `App::run` does first: plugins finish (the glTF loader and the soft-body glTF
    // system are registered there).
    app.finish();
    app.cleanup();
    app.update();
    app
}

fn positions(mesh: &Mesh, attr: bevy::mesh::MeshVertexAttribute) -> Vec<[f32; 3]> {
    match mesh.attribute(attr) {
        Some(VertexAttributeValues::Float32x3(p)) => p.clone(),
        _ => panic!("no {attr:?}"),
    }
}

#[test]
fn a_gltf_cape_with_a_uv_seam_has_no_crack_after_two_seconds_of_wind() {
    let mut app = app();
    let gltf: Handle<Gltf> = app
        .world()
        .resource::<AssetServer>()
        .load("models/cape.gltf");
    let holder = app
        .world_mut()
        .spawn((
            Transform::from_xyz(0.0, 1.8, 0.0),
            SoftBodyGltf {
                gltf: gltf.clone(),
                mesh: "cape".into(),
                params: MeshBody {
                    cloth: SurfaceParams::default(),
                    pins: MeshPins::VertexColor {
                        color: LinearRgba::RED,
                        tolerance: 0.01,
                    },
                    wind: Some(Wind {
                        velocity: [0.0, 0.0, 3.0],
                        gust: 1.5,
                        // Per particle (N·s/m): with 0.5 g particles, about 6 m/s² at 3 m/s.
                        coefficient: 1e-3,
                        ..Default::default()
                    }),
                    ..Default::default()
                },
                pin_nodes: vec![],
                attach: None,
                // Stiff cloth at one step per frame: linearly implicit Euler (an explicit
                // method needs h below 2.8/ω, ω ≈ 10³ rad/s for these 5 cm cells).
                body: SoftBody {
                    integrator: bevy_soft_body::IntegratorKind::LinearlyImplicitEuler,
                    step: bevy_soft_body::core::driver::StepPolicy::Fixed { h: FRAME },
                    ..Default::default()
                },
            },
        ))
        .id();
    // Loading runs on the asset server's threads: update until the body exists.
    let mut body = None;
    for _ in 0..2000 {
        app.update();
        if let Some(s) = app.world().get::<SoftBodyGltfSpawned>(holder) {
            body = Some(s.0);
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    let state = app.world().resource::<AssetServer>().load_state(&gltf);
    let body =
        body.unwrap_or_else(|| panic!("the cape was not spawned; glTF load state {state:?}"));
    app.update();
    // The source mesh, as loaded (rest positions, the seam's duplicates).
    let rest = {
        let w = app.world();
        let g = w.resource::<Assets<Gltf>>().get(&gltf).unwrap();
        let gm = w
            .resource::<Assets<bevy::gltf::GltfMesh>>()
            .get(&g.named_meshes["cape"])
            .unwrap();
        let m = w
            .resource::<Assets<Mesh>>()
            .get(&gm.primitives[0].mesh)
            .unwrap();
        positions(m, Mesh::ATTRIBUTE_POSITION)
    };
    // Seam pairs: distinct vertices at the same rest position (the file has 23).
    let mut pairs = vec![];
    for a in 0..rest.len() {
        for b in a + 1..rest.len() {
            if rest[a] == rest[b] {
                pairs.push((a, b));
            }
        }
    }
    assert_eq!(pairs.len(), 23, "the file's seam");
    let status = app.world().get::<SoftBodyStatus>(body).unwrap().clone();
    assert_eq!(status.particles as usize, rest.len() - 23, "seam welded");

    for _ in 0..128 {
        app.update(); // 2 s
    }
    let w = app.world();
    assert_eq!(
        w.get::<SoftBodyStatus>(body).unwrap().state,
        BodyState::Running
    );
    let handle = &w.get::<Mesh3d>(body).expect("the cape's mesh was made").0;
    let mesh = w.resource::<Assets<Mesh>>().get(handle).unwrap();
    let x = positions(mesh, Mesh::ATTRIBUTE_POSITION);
    let n = positions(mesh, Mesh::ATTRIBUTE_NORMAL);
    assert_eq!(
        x.len(),
        rest.len(),
        "the mesh keeps its vertices (UVs split at the seam)"
    );
    let mut crack = 0.0f32;
    for (a, b) in &pairs {
        crack = crack.max(Vec3::from(x[*a]).distance(Vec3::from(x[*b])));
        assert_eq!(n[*a], n[*b], "one normal per seam position");
    }
    println!("seam crack after 2 s of wind: {crack} m");
    assert_eq!(crack, 0.0);
    // The red rim (top row, y = 0 in the file, placed at y = 1.8) holds; the hem moved.
    let mut moved = 0.0f32;
    for (r, p) in rest.iter().zip(&x) {
        let placed = Vec3::from(*r) + Vec3::new(0.0, 1.8, 0.0);
        let d = placed.distance(Vec3::from(*p));
        if r[1] == 0.0 {
            assert!(d < 1e-5, "rim vertex moved {d} m");
        } else {
            moved = moved.max(d);
        }
        assert!(p.iter().all(|c| c.is_finite()));
    }
    println!("largest displacement of the hanging part: {moved} m");
    // Blown by the wind but still hanging: the hem moved, by less than the cape's length.
    assert!(moved > 0.05 && moved < 1.1, "{moved}");
}

/// A 4 × 3-cell sheet in the x–y plane, top row at y = 0, triangles counter-clockwise.
fn sheet() -> Mesh {
    let (nx, ny) = (4u32, 3u32);
    let mut pos = vec![];
    for j in 0..=ny {
        for i in 0..=nx {
            pos.push([i as f32 * 0.1, -(j as f32) * 0.1, 0.0]);
        }
    }
    let mut idx = vec![];
    for j in 0..ny {
        for i in 0..nx {
            let v = |i: u32, j: u32| j * (nx + 1) + i;
            idx.extend([v(i, j), v(i, j + 1), v(i + 1, j + 1)]);
            idx.extend([v(i, j), v(i + 1, j + 1), v(i + 1, j)]);
        }
    }
    let mut m = Mesh::new(PrimitiveTopology::TriangleList, default());
    m.insert_attribute(Mesh::ATTRIBUTE_POSITION, pos);
    m.insert_indices(Indices::U32(idx));
    m
}

#[test]
fn pins_follow_the_entity_they_are_attached_to() {
    let mut app = app();
    let pole = app
        .world_mut()
        .spawn((
            Transform::from_xyz(1.0, 2.0, 0.0),
            GlobalTransform::from_xyz(1.0, 2.0, 0.0),
        ))
        .id();
    let body = app
        .world_mut()
        .run_system_once(move |mut c: Commands| {
            c.spawn_mesh_body(
                &sheet(),
                &MeshBody {
                    pins: MeshPins::Predicate(std::sync::Arc::new(|_, p: Vec3| p.y == 0.0)),
                    transform: Transform::from_xyz(1.0, 2.0, 0.0),
                    attach: Some((pole, GlobalTransform::from_xyz(1.0, 2.0, 0.0))),
                    ..Default::default()
                },
                SoftBody::default(),
            )
            .unwrap()
        })
        .unwrap();
    app.update();
    // Move the pole 0.5 m along x: the top row follows, at its offsets.
    for k in 1..=32 {
        let x = 1.0 + 0.5 * k as f32 / 32.0;
        let mut e = app.world_mut().entity_mut(pole);
        *e.get_mut::<Transform>().unwrap() = Transform::from_xyz(x, 2.0, 0.0);
        app.update();
    }
    // Pin targets are read from `GlobalTransform`, which Bevy propagates in `PostUpdate`: a
    // `Transform` set before an update is followed from the next fixed step on.
    app.update();
    let w = app.world();
    let parts = w.get::<BodyParticles>(body).unwrap().entities().to_vec();
    let mut top = 0;
    for p in parts {
        let pin = w.get::<Pinned>(p);
        let pos = w.get::<Particle>(p).unwrap().position;
        if let Some(pin) = pin {
            top += 1;
            assert_eq!(pin.target, Some(pole));
            let want = Vec3::new(1.5, 2.0, 0.0) + pin.offset;
            assert!(pos.distance(want) < 1e-5, "{pos} vs {want}");
        }
    }
    assert_eq!(top, 5, "the top row of a 4-cell-wide sheet");
}

#[test]
fn meshes_the_builder_cannot_use_are_errors_saying_why() {
    let mut app = app();
    let errors: Vec<String> = app
        .world_mut()
        .run_system_once(|mut c: Commands| {
            let lines = Mesh::new(PrimitiveTopology::LineList, default())
                .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, vec![[0.0f32; 3]; 2]);
            let no_colours = MeshBody {
                pins: MeshPins::VertexColor {
                    color: LinearRgba::RED,
                    tolerance: 0.1,
                },
                ..Default::default()
            };
            let mut bad_index = sheet();
            bad_index.insert_indices(Indices::U32(vec![0, 1, 999]));
            let no_limit = MeshBody {
                tearing: Some(Tearable { max_strain: 0.0 }),
                ..Default::default()
            };
            // Half the sheet's shortest edge (10 cm) is the most a thickness may be.
            let too_thick = MeshBody {
                self_collision: Some(SelfCollision {
                    thickness: 0.06,
                    friction: 0.3,
                }),
                ..Default::default()
            };
            [
                c.spawn_mesh_body(&lines, &MeshBody::default(), SoftBody::default()),
                c.spawn_mesh_body(&sheet(), &no_colours, SoftBody::default()),
                c.spawn_mesh_body(&bad_index, &MeshBody::default(), SoftBody::default()),
                c.spawn_mesh_body(&sheet(), &no_limit, SoftBody::default()),
                c.spawn_mesh_body(&sheet(), &too_thick, SoftBody::default()),
            ]
            .into_iter()
            .map(|r| r.unwrap_err().to_string())
            .collect::<Vec<String>>()
        })
        .unwrap();
    println!("{errors:#?}");
    assert!(errors[0].contains("triangle list"), "{}", errors[0]);
    assert!(errors[1].contains("vertex colours"), "{}", errors[1]);
    assert!(errors[2].contains("999"), "{}", errors[2]);
    assert!(errors[3].contains("tearing.max_strain"), "{}", errors[3]);
    assert!(
        errors[4].contains("self_collision.thickness"),
        "{}",
        errors[4]
    );
}

#[test]
fn scene_files_load_as_assets_and_spawn_bodies() {
    // A chain scene written as a `.softbody.json` file, and a file with a bad spring.
    let dir = std::env::temp_dir().join(format!("soft_body_scene_assets_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let chain = bevy_soft_body::core::build::chain(&Default::default()).unwrap();
    std::fs::write(dir.join("chain.softbody.json"), chain.to_json()).unwrap();
    let mut bad = chain.clone();
    bad.springs[0].b = 99;
    std::fs::write(dir.join("bad.softbody.json"), bad.to_json()).unwrap();
    let mut app = app_at(dir.to_str().unwrap());
    let server = app.world().resource::<AssetServer>().clone();
    let good = app
        .world_mut()
        .spawn(SoftBodySceneRoot {
            scene: server.load("chain.softbody.json"),
            body: SoftBody::default(),
        })
        .id();
    let bad_handle: Handle<SoftBodySceneAsset> = server.load("bad.softbody.json");
    let broken = app
        .world_mut()
        .spawn(SoftBodySceneRoot {
            scene: bad_handle.clone(),
            body: SoftBody::default(),
        })
        .id();
    let mut body = None;
    for _ in 0..2000 {
        app.update();
        body = app.world().get::<SoftBodySceneSpawned>(good).map(|s| s.0);
        if body.is_some() && app.world().get::<SoftBodySceneRoot>(broken).is_none() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    let body = body.expect("the chain was spawned from its file");
    for _ in 0..10 {
        app.update();
    }
    let w = app.world();
    let st = w.get::<SoftBodyStatus>(body).unwrap();
    assert_eq!(st.state, BodyState::Running);
    assert_eq!(st.particles as usize, chain.particles.len());
    // The bad file failed its load (naming the spring) and spawned nothing.
    assert!(w.get::<SoftBodySceneRoot>(broken).is_none());
    assert!(w.get::<SoftBodySceneSpawned>(broken).is_none());
    match server.load_state(&bad_handle) {
        bevy::asset::LoadState::Failed(e) => {
            println!("{e}");
            assert!(e.to_string().contains("springs[0].b"), "{e}");
        }
        other => panic!("expected the bad file to fail, got {other:?}"),
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A game's mesh torn: a 0.8 × 0.4 m sheet with texture coordinates, its top row pinned, the
/// right half of the row pulled away to the right until the sheet tears down its middle. Beside
/// it the same cloth (the same builder's scene) as a body drawn by its own `SoftBodySurface`,
/// torn by the same pull: the game's mesh must draw the same triangles between the same
/// particles (through the particle each of its vertices shows) — drawn whole, as before, its
/// triangles on the far side of the cut would still hold the particles on the near side. Every
/// vertex the tear added must be in the mesh asset, at its particle's position with the texture
/// coordinate of the vertex it split from, and the index buffer must be the torn triangles.
#[test]
fn a_torn_mesh_body_draws_the_cut_its_surface_would_with_split_vertices_that_keep_their_uvs() {
    use bevy_soft_body::core::build::surface_cloth;
    let (nx, ny) = (8u32, 4u32);
    let mut pos = vec![];
    let mut uv = vec![];
    for j in 0..=ny {
        for i in 0..=nx {
            pos.push([i as f32 * 0.1, -(j as f32) * 0.1, 0.0]);
            uv.push([i as f32 / nx as f32, j as f32 / ny as f32]);
        }
    }
    let mut tris = vec![];
    let v = |i: u32, j: u32| j * (nx + 1) + i;
    for j in 0..ny {
        for i in 0..nx {
            tris.push([v(i, j), v(i, j + 1), v(i + 1, j + 1)]);
            tris.push([v(i, j), v(i + 1, j + 1), v(i + 1, j)]);
        }
    }
    let own = pos.len();
    let pinned = |_: usize, p: [f32; 3]| p[1] == 0.0;
    let scene = surface_cloth(&pos, &tris, &SurfaceParams::default(), pinned)
        .unwrap()
        .scene;
    let mut sheet = Mesh::new(PrimitiveTopology::TriangleList, default());
    sheet.insert_attribute(Mesh::ATTRIBUTE_POSITION, pos);
    sheet.insert_attribute(Mesh::ATTRIBUTE_UV_0, uv.clone());
    sheet.insert_indices(Indices::U32(tris.iter().flatten().copied().collect()));
    let mut app = app();
    let pole = app
        .world_mut()
        .spawn((Transform::default(), GlobalTransform::default()))
        .id();
    let (body, twin) = app
        .world_mut()
        .run_system_once(move |mut c: Commands| {
            let body = c
                .spawn_mesh_body(
                    &sheet,
                    &MeshBody {
                        pins: MeshPins::Predicate(std::sync::Arc::new(move |v, p: Vec3| {
                            pinned(v, p.to_array())
                        })),
                        tearing: Some(Tearable { max_strain: 0.3 }),
                        ..Default::default()
                    },
                    SoftBody::default(),
                )
                .unwrap();
            let twin = c.spawn_soft_body(&scene, SoftBody::default()).unwrap();
            (body, twin)
        })
        .unwrap();
    app.world_mut()
        .entity_mut(twin)
        .insert(Tearable { max_strain: 0.3 });
    app.update();
    // The right half of each pinned row follows the pole, at its own positions.
    for b in [body, twin] {
        let parts = app
            .world()
            .get::<BodyParticles>(b)
            .unwrap()
            .entities()
            .to_vec();
        for &p in &parts {
            let x = app.world().get::<Particle>(p).unwrap().position;
            if app.world().get::<Pinned>(p).is_some() && x.x > 0.45 {
                app.world_mut().entity_mut(p).insert(Pinned::to(pole, x));
            }
        }
    }
    for k in 1..=48 {
        let x = 0.6 * k as f32 / 48.0;
        *app.world_mut().get_mut::<Transform>(pole).unwrap() = Transform::from_xyz(x, 0.0, 0.0);
        app.update();
    }
    app.update();
    let mut springs = std::collections::HashSet::new();
    let mut q = app.world_mut().query::<(&Spring, &SpringOf)>();
    for (s, of) in q.iter(app.world()) {
        if of.0 == body {
            springs.insert((s.a.min(s.b), s.a.max(s.b)));
        }
    }
    let w = app.world();
    let surface = w.get::<SoftBodyMeshSurface>(body).unwrap();
    let added = surface.split_from.len();
    assert!(added > 0, "the sheet did not tear");
    assert_eq!(surface.vertices.len(), own + added);
    assert!(!surface.torn, "the mesh asset has not followed the tear");
    // Both bodies' triangles as particle indices (each body's own order), corners sorted.
    let index = |b: Entity| -> std::collections::HashMap<Entity, u32> {
        let parts = w.get::<BodyParticles>(b).unwrap().entities();
        parts
            .iter()
            .enumerate()
            .map(|(i, e)| (*e, i as u32))
            .collect()
    };
    let (ib, it) = (index(body), index(twin));
    let sorted = |mut t: [u32; 3]| {
        t.sort_unstable();
        t
    };
    let mut drawn: Vec<[u32; 3]> = surface
        .triangles
        .iter()
        .map(|t| sorted(t.map(|v| ib[&surface.vertices[v as usize]])))
        .collect();
    let twin_surface = w
        .get::<bevy_soft_body::render::SoftBodySurface>(twin)
        .unwrap();
    let twin_parts = w.get::<BodyParticles>(twin).unwrap().entities().to_vec();
    let mut want: Vec<[u32; 3]> = twin_surface
        .triangles
        .iter()
        .map(|t| sorted(t.map(|i| it[&twin_parts[i as usize]])))
        .collect();
    assert_eq!(ib.len(), it.len(), "the two bodies tore differently");
    drawn.sort_unstable();
    want.sort_unstable();
    println!(
        "{added} vertices added; {} particles; {} triangles drawn",
        ib.len(),
        drawn.len()
    );
    assert_eq!(drawn, want);
    // And every drawn edge is held by a spring of the body: a surface spring that breaks with
    // neither end splittable takes its triangles with it (they were drawn on before, across
    // the opened cut, on a corner no spring held: 0.77 m long here).
    for t in &surface.triangles {
        for c in 0..3 {
            let (a, b) = (
                surface.vertices[t[c] as usize],
                surface.vertices[t[(c + 1) % 3] as usize],
            );
            assert!(
                springs.contains(&(a.min(b), a.max(b))),
                "triangle {t:?}: its edge {a}–{b} is no spring of the body"
            );
        }
    }
    let mesh = w
        .resource::<Assets<Mesh>>()
        .get(&w.get::<Mesh3d>(body).unwrap().0)
        .unwrap();
    assert_eq!(mesh.count_vertices(), surface.vertices.len());
    let uvs = match mesh.attribute(Mesh::ATTRIBUTE_UV_0) {
        Some(VertexAttributeValues::Float32x2(u)) => u.clone(),
        _ => panic!("no UVs"),
    };
    let at = positions(mesh, Mesh::ATTRIBUTE_POSITION);
    for (k, &from) in surface.split_from.iter().enumerate() {
        assert_eq!(uvs[own + k], uv[from as usize], "vertex {}", own + k);
        let p = w
            .get::<Particle>(surface.vertices[own + k])
            .unwrap()
            .position;
        assert!(Vec3::from_array(at[own + k]).distance(p) < 1e-6);
    }
    let indices: Vec<u32> = mesh.indices().unwrap().iter().map(|i| i as u32).collect();
    let want: Vec<u32> = surface.triangles.iter().flatten().copied().collect();
    assert_eq!(indices, want);
}

/// Grids of `n × n` square cells of `cell` metres, lying flat: one per `(height, offset)`,
/// from `(offset, offset)` in x and z, all in one mesh (two triangles a cell).
fn lying_grids(n: u32, cell: f32, grids: &[(f32, f32)]) -> Mesh {
    let (mut pos, mut idx) = (vec![], vec![]);
    for &(y, off) in grids {
        let base = pos.len() as u32;
        for j in 0..=n {
            for i in 0..=n {
                pos.push([off + i as f32 * cell, y, off + j as f32 * cell]);
            }
        }
        let v = |i: u32, j: u32| base + j * (n + 1) + i;
        for j in 0..n {
            for i in 0..n {
                idx.extend([v(i, j), v(i, j + 1), v(i + 1, j + 1)]);
                idx.extend([v(i, j), v(i + 1, j + 1), v(i + 1, j)]);
            }
        }
    }
    let mut m = Mesh::new(PrimitiveTopology::TriangleList, default());
    m.insert_attribute(Mesh::ATTRIBUTE_POSITION, pos);
    m.insert_indices(Indices::U32(idx));
    m
}

/// A mesh body's particles (positions) and its mesh's triangles on them: each vertex of
/// `SoftBodyMeshSurface` shows a particle, looked up in the body's list.
fn mesh_body_surface(app: &App, body: Entity) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let w = app.world();
    let parts = w.get::<BodyParticles>(body).unwrap().entities().to_vec();
    let x = parts
        .iter()
        .map(|p| {
            w.get::<Particle>(*p)
                .unwrap()
                .position
                .as_dvec3()
                .to_array()
        })
        .collect();
    let ms = w.get::<SoftBodyMeshSurface>(body).unwrap();
    let at = |v: u32| {
        parts
            .iter()
            .position(|p| *p == ms.vertices[v as usize])
            .unwrap() as u32
    };
    let tris = ms.triangles.iter().map(|t| t.map(at)).collect();
    (x, tris)
}

fn spawn_mesh(app: &mut App, mesh: Mesh, self_collision: Option<SelfCollision>) -> Entity {
    app.world_mut()
        .run_system_once(move |mut c: Commands| {
            c.spawn_mesh_body(
                &mesh,
                &MeshBody {
                    self_collision,
                    ..Default::default()
                },
                SoftBody::default(),
            )
            .unwrap()
        })
        .unwrap()
}

/// A body made from the game's mesh is met by colliders between its particles: a 9 × 9 mesh
/// of 10 cm cells dropped onto a ball of radius 2 cm under the middle of its middle cell (7 cm
/// from the cell's corners, so no particle ever touches it) rests on the ball over 1 s, every
/// frame's triangles at least half the contact thickness from it (`common::intersect`'s
/// point–triangle distance). With the particles alone the mesh fell past the ball.
#[test]
fn colliders_meet_a_mesh_body_between_its_particles() {
    use bevy_soft_body::core::collide::{ColliderDesc, ShapeDesc};
    let mut app = app();
    let (r, centre) = (0.02, [0.0, 0.3, 0.0]);
    let thickness = SoftBodyCollider::default().thickness as f64;
    app.world_mut()
        .run_system_once(move |mut c: Commands| {
            c.spawn_collider(&ColliderDesc {
                shape: ShapeDesc::Sphere { radius: r },
                motion: bevy_soft_body::core::motion::Motion::Fixed { position: centre },
                rotation: [0.0, 0.0, 0.0, 1.0],
                material: bevy_soft_body::core::collide::ContactMaterial {
                    thickness,
                    friction: 0.5,
                    ..Default::default()
                },
            });
        })
        .unwrap();
    let body = spawn_mesh(&mut app, lying_grids(9, 0.1, &[(0.4, -0.45)]), None);
    let mut nearest = f64::INFINITY;
    for _ in 0..64 {
        app.update();
        let (x, tris) = mesh_body_surface(&app, body);
        for t in &tris {
            let tri = t.map(|i| x[i as usize]);
            nearest = nearest.min(common::intersect::point_triangle_distance(centre, &tri) - r);
        }
    }
    let (x, _) = mesh_body_surface(&app, body);
    let highest = x.iter().map(|p| p[1]).fold(f64::MIN, f64::max);
    println!(
        "nearest {:.2} mm (thickness {:.0} mm); highest particle at {highest:.3} m after 1 s",
        nearest * 1e3,
        thickness * 1e3
    );
    assert!(
        nearest >= 0.5 * thickness,
        "the ball came {nearest} m from the mesh"
    );
    assert!(
        highest > centre[1],
        "the mesh rests on the ball ({highest})"
    );
}

/// Self-collision of a body made from the game's mesh, with its mesh's triangles: two 6 × 6
/// sheets of 10 cm cells in one mesh, the upper dropped from 20 cm onto the lower lying on the
/// ground, its particles over the middles of the lower's cells. With `SelfCollision` (1 cm) it
/// lands on the lower sheet and stays at least half the thickness off its triangles; without,
/// it falls through onto the ground, into the lower sheet's plane.
#[test]
fn a_mesh_body_with_self_collision_keeps_its_layers_apart() {
    use bevy_soft_body::core::build::ground;
    let nearest_layers = |self_collision: Option<SelfCollision>| {
        let mut app = app();
        app.world_mut()
            .run_system_once(|mut c: Commands| {
                c.spawn_collider(&ground(0.0, 0.0, 0.5));
            })
            .unwrap();
        let mesh = lying_grids(6, 0.1, &[(0.011, 0.0), (0.2, 0.05)]);
        let body = spawn_mesh(&mut app, mesh, self_collision);
        let mut nearest = f64::INFINITY;
        for f in 0..64 {
            app.update();
            let status = app.world().get::<SoftBodyStatus>(body).unwrap();
            assert!(
                matches!(status.state, BodyState::Running | BodyState::Sleeping),
                "{:?}",
                status.state
            );
            if f < 32 {
                continue;
            }
            // The upper sheet's particles (the last 49) against the lower's triangles (the
            // first 72).
            let (x, tris) = mesh_body_surface(&app, body);
            let upper = &x[x.len() - 49..];
            for t in &tris[..72] {
                let tri = t.map(|i| x[i as usize]);
                for p in upper {
                    nearest = nearest.min(common::intersect::point_triangle_distance(*p, &tri));
                }
            }
        }
        nearest
    };
    let t = 0.01;
    let with = nearest_layers(Some(SelfCollision {
        thickness: t as f32,
        friction: 0.3,
    }));
    let without = nearest_layers(None);
    println!(
        "over 0.5–1 s the upper sheet's particles came {:.2} mm from the lower's triangles with self-collision ({:.0} mm), {:.2} mm without",
        with * 1e3,
        t * 1e3,
        without * 1e3
    );
    assert!(with >= 0.5 * t, "layers {with} m apart");
    assert!(
        without < 0.5 * t,
        "without self-collision: {without} m apart"
    );
}
