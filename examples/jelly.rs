//! A jelly block: a 6×6×6 lattice (10 g particles, structural, shear and flex springs with
//! dampers) dropped from 0.8 m, bouncing on the ground (restitution 0.5, friction 0.5), drawn
//! as a deforming mesh of its boundary with smooth normals. Symplectic Euler at h = 0.001 by
//! default; `cargo run --release --example jelly -- b 0.0167` uses Newton backward Euler,
//! one step per frame.
//!
//! Keys: Space pause, N step, R reset, W wind, G wireframe, E/S/T/M/K/A/I/D/B/X/P integrator
//! (K = RK4); left drag pulls the jelly, right drag or arrows orbit, wheel zoom.

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;
use bevy_soft_body::prelude::*;

fn main() {
    let args = common::args("jelly");
    let scene = build::jelly(&build::JellyParams::default()).expect("valid jelly");
    let body = args.body(IntegratorKind::SymplecticEuler, 1e-3);
    let mut app = common::app("jelly", &args);
    app.add_systems(Startup, move |mut c: Commands| {
        let e = c
            .spawn_soft_body(&scene, body.clone())
            .expect("valid scene");
        c.entity(e).insert(SoftBodySurface {
            color: Color::srgb(0.35, 0.8, 0.4),
            ..scene_surface(&scene)
        });
        common::stage(&mut c, Vec3::new(0.0, 0.4, 0.0), 2.2);
    });
    app.run();
}

fn scene_surface(scene: &Scene) -> SoftBodySurface {
    let s = scene.surface.clone().unwrap_or_default();
    SoftBodySurface {
        triangles: s.triangles,
        uvs: s.uvs,
        ..Default::default()
    }
}
