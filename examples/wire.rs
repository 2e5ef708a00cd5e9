//! The PhysBAM slides' wire: 11 particles, total mass 1 kg, strain-law springs (E = 10 N)
//! with dampers (b = 10 N·s/m), hanging from an endpoint that moves on a circle of radius
//! 0.5 m (one turn in 5 s) — a prescribed-motion particle following a `ScriptedMotion`
//! target. By default forward Euler with the slides' CFL step (0.5 × min(μ l₀/b, b/k)), as
//! in the slides; `cargo run --release --example wire -- d 0.01` runs the implicit-damping
//! trapezoid at a fixed step 20× larger.
//!
//! Keys: Space pause, N step, R reset, G wireframe, E/S/T/M/K/A/I/D/B/X/P integrator (K = RK4);
//! left drag pulls a particle, right drag or arrows orbit, wheel zoom.

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;
use bevy_soft_body::prelude::*;

fn main() {
    let args = common::args("wire");
    let scene = build::wire(11, 0.05, 100).expect("valid wire");
    let body = match args.h {
        Some(_) => args.body(IntegratorKind::ForwardEuler, 0.0),
        None => SoftBody {
            integrator: args.integrator.unwrap_or(IntegratorKind::ForwardEuler),
            step: StepPolicy::Cfl {
                number: 0.5,
                max: 1.0 / 60.0,
                limit: CflLimit::PhysBam,
            },
            ..Default::default()
        },
    };
    let mut app = common::app("PhysBAM wire", &args);
    app.add_systems(Startup, move |mut c: Commands| {
        c.spawn_soft_body(&scene, body.clone())
            .expect("valid scene");
        common::stage(&mut c, Vec3::new(0.0, -0.4, 0.3), 3.0);
    });
    app.run();
}
