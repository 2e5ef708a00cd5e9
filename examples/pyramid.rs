//! The particle-system assignment's pyramid: four layers of particles joined by springs along every row, column
//! and diagonal and to the layer below, dropped from 0.5 m onto a ground plane with
//! restitution 0.8 and friction 0.3. Symplectic Euler at h = 0.0005 by default;
//! `cargo run --release --example pyramid -- i 0.0167` drops it with linearly implicit Euler,
//! one step per frame.
//!
//! Keys: Space pause, N step, R reset, G wireframe, E/S/T/M/K/A/I/D/B/X/P integrator (K = RK4);
//! left drag pulls a particle, right drag or arrows orbit, wheel zoom.

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;
use bevy_soft_body::prelude::*;

fn main() {
    let args = common::args("pyramid");
    let scene = build::pyramid(4, 0.2, 0.05, 500.0, 0.5, 0.5).expect("valid pyramid");
    let body = args.body(IntegratorKind::SymplecticEuler, 5e-4);
    let mut app = common::app("pyramid", &args);
    app.add_systems(Startup, move |mut c: Commands| {
        c.spawn_soft_body(&scene, body.clone())
            .expect("valid scene");
        common::stage(&mut c, Vec3::new(0.0, 0.3, 0.0), 2.5);
    });
    app.run();
}
