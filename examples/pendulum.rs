//! A pendulum chain: eight 0.1 kg particles on 200 N/m springs, the first pinned, released
//! horizontally; drawn as spheres and lines (gizmos). Symplectic Euler at h = 0.001 by
//! default: `cargo run --release --example pendulum -- r 0.004` takes the sample solution's
//! letter and step.
//!
//! Keys: Space pause, N step, R reset, W wind, G wireframe, E/S/T/M/K/A/I/D/B/X/P integrator
//! (K = RK4); left drag pulls a particle, right drag or arrows orbit, wheel zoom.

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;
use bevy_soft_body::prelude::*;

fn main() {
    let args = common::args("pendulum");
    let scene = build::chain(&build::ChainParams {
        particles: 8,
        ..Default::default()
    })
    .expect("valid chain");
    let body = args.body(IntegratorKind::SymplecticEuler, 1e-3);
    let mut app = common::app("pendulum chain", &args);
    app.add_systems(Startup, move |mut c: Commands| {
        c.spawn_soft_body(&scene, body.clone())
            .expect("valid scene");
        common::stage(&mut c, Vec3::new(0.8, -0.8, 0.0), 4.5);
    });
    app.run();
}
