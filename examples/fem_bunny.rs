//! The coarse Stanford bunny (407 vertices, 1616 linear tets of neo-Hookean rubber,
//! E = 200 kPa, ν = 0.4, ρ = 1000 kg/m³) dropped from 0.3 m onto the ground, where it
//! squashes and wobbles, with the 28 088-vertex bunny surface skinned onto it
//! (`x_display = W q`). Implicit steps hold the vertices resting on the ground still
//! (sticking contact inside the solve). Drag it with the mouse to squash and stretch it. The tet mesh is loaded
//! through the asset server (`TetMeshAsset`). Linearly implicit Euler, one step per 60 Hz
//! frame, by default; `cargo run --release --example fem_bunny -- b` uses Newton backward
//! Euler.
//!
//! Keys: S skinned ↔ simulation mesh, N (running) linearly implicit ↔ backward Euler,
//! Space pause, N (paused) step, R reset, G wireframe, E/T/M/K/A/I/D/B integrator;
//! left drag pulls the nearest vertex with a spring, right drag or arrows orbit, wheel zoom.

#[path = "common/mod.rs"]
mod common;
#[path = "common/fem.rs"]
mod fem;

use bevy::prelude::*;
use bevy_soft_body::prelude::*;

fn main() {
    let args = common::args("fem_bunny");
    let body = args.body(IntegratorKind::LinearlyImplicitEuler, 1.0 / 60.0);
    let mut app = common::app("fem_bunny", &args);
    app.add_systems(Startup, move |mut c: Commands, server: Res<AssetServer>| {
        c.insert_resource(fem::FemSpec {
            mesh: server.load("meshes/bunny_coarse.mesh"),
            material: NeoHookean {
                young: 2e5,
                poisson: 0.4,
                density: 1000.0,
            },
            body: SoftBody {
                drag: 0.05,
                ..body.clone()
            },
            scale: 1.0,
            offset: [0.0, 0.4, 0.0],
            display: Some("meshes/bunny_hires.obj"),
            pin_above: None,
            kick: 0.0,
            color: Color::srgb(0.85, 0.55, 0.35),
        });
        c.spawn_collider(&build::ground(0.0, 0.0, 0.6));
        common::stage(&mut c, Vec3::new(0.0, 0.5, 0.0), 2.6);
    })
    .add_systems(Update, fem::spawn_when_loaded);
    app.run();
}
