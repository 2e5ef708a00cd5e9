//! A cape modelled as a glTF file (`assets/models/cape.gltf`, written by `make_cape.py`
//! beside it: a curved 16 × 22-quad sheet with a UV seam down its middle and its top rim
//! painted red) becomes a cloth with `SoftBodyGltf`: seam welded, rim pinned by its vertex
//! colour to a banner pole that sways from side to side, in a breeze. The mesh is drawn as the
//! file made it (its material, vertex colours and UVs), deformed; pulled hard (past 50 %
//! strain) it tears, and the file's mesh opens along the cut. Linearly implicit Euler at
//! one step per 1/60 s frame by default (`-- LETTER H` picks another).
//!
//! Keys: Space pause, N step, R reset, W wind, G wireframe, E/S/T/M/K/A/I/D/B/X/P integrator;
//! left drag pulls the cape, right drag or arrows orbit, wheel zoom.

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;
use bevy_soft_body::core::motion::Motion;
use bevy_soft_body::prelude::*;

fn main() {
    let args = common::args("gltf_cape");
    let body = args.body(IntegratorKind::LinearlyImplicitEuler, 1.0 / 60.0);
    let mut app = common::app("glTF cape", &args);
    app.add_systems(
        Startup,
        move |mut c: Commands,
              server: Res<AssetServer>,
              mut meshes: ResMut<Assets<Mesh>>,
              mut materials: ResMut<Assets<StandardMaterial>>| {
            // The banner pole: a crossbar at 1.9 m on a post, swaying ±0.35 m along x.
            let metal = materials.add(StandardMaterial {
                base_color: Color::srgb(0.55, 0.56, 0.6),
                metallic: 0.6,
                perceptual_roughness: 0.4,
                ..default()
            });
            let sway = Motion::Oscillate {
                center: [0.0, 1.9, 0.0],
                amplitude: [0.35, 0.0, 0.0],
                omega: 1.3,
                phase: 0.0,
            };
            let pole = c
                .spawn((
                    Name::new("banner pole"),
                    ScriptedMotion(sway),
                    Transform::from_xyz(0.0, 1.9, 0.0),
                    Mesh3d(meshes.add(Cylinder::new(0.025, 1.0))),
                    MeshMaterial3d(metal.clone()),
                ))
                .with_children(|p| {
                    // The crossbar along x, the post down to the ground.
                    p.spawn((
                        Transform::from_rotation(Quat::from_rotation_z(
                            std::f32::consts::FRAC_PI_2,
                        )),
                        Mesh3d(meshes.add(Cylinder::new(0.02, 1.0))),
                        MeshMaterial3d(metal.clone()),
                    ));
                    p.spawn((
                        Transform::from_xyz(0.0, -0.95, -0.05),
                        Mesh3d(meshes.add(Cylinder::new(0.03, 1.9))),
                        MeshMaterial3d(metal),
                    ));
                })
                .id();
            // The cape hangs from the crossbar, pinned where the file painted it red.
            c.spawn((
                Name::new("cape from glTF"),
                Transform::from_xyz(0.0, 1.9, 0.02),
                SoftBodyGltf {
                    gltf: server.load("models/cape.gltf"),
                    mesh: "cape".into(),
                    params: MeshBody {
                        cloth: SurfaceParams {
                            areal_density: 0.25,
                            stretch: SurfaceStiffness::PerArea(400.0),
                            bend: Some(SurfaceStiffness::PerArea(1.0)),
                            damping: 0.002,
                            ..Default::default()
                        },
                        pins: MeshPins::VertexColor {
                            color: LinearRgba::RED,
                            tolerance: 0.01,
                        },
                        wind: Some(Wind {
                            velocity: [0.4, 0.0, 1.6],
                            gust: 0.8,
                            frequency: 0.4,
                            // Per particle (N·s/m), for 0.6 g particles.
                            coefficient: 1.2e-3,
                            ..Default::default()
                        }),
                        // A hard pull tears it: the file's mesh opens along the cut.
                        tearing: Some(Tearable { max_strain: 0.5 }),
                        ..Default::default()
                    },
                    pin_nodes: vec![],
                    attach: Some(pole),
                    body: body.clone(),
                },
            ));
            c.spawn_collider(&build::ground(0.0, 0.0, 0.5));
            common::stage_with(
                &mut c,
                common::OrbitCamera {
                    target: Vec3::new(0.0, 1.3, 0.0),
                    yaw: 0.55,
                    pitch: 0.12,
                    distance: 3.0,
                },
            );
        },
    );
    app.run();
}
