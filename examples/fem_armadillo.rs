//! The small, stiff armadillo (496 vertices, 1466 tets; 0.98 m tall, E = 1 MPa, ν = 0.45,
//! ρ = 1000 kg/m³) hung by the top 5 % of its vertices and set swinging, with the
//! 26 002-vertex armadillo surface skinned onto it. Newton backward Euler (sparse Cholesky),
//! one step per 60 Hz frame. Press N to switch to linearly implicit Euler and pull hard with
//! the mouse: its single linearized step overshoots, the body's energy explodes, the
//! divergence is detected and reported in the panel, and the body is held at its last good
//! state (never drawn as NaN). Y yanks it the same way every time (40 m/s sideways per metre
//! of height, as `tests/fem_plugin.rs` does): linearly implicit Euler diverges within two
//! frames, backward Euler rides it out. Press N again (or B) to go back to backward Euler; R resets.
//!
//! Keys: Y yank, N (running) linearly implicit ↔ backward Euler, S skinned ↔ simulation mesh,
//! Space pause, N (paused) step, R reset, G wireframe, E/T/M/K/A/I/D/B integrator;
//! left drag pulls the nearest vertex with a spring, right drag or arrows orbit, wheel zoom.

#[path = "common/mod.rs"]
mod common;
#[path = "common/fem.rs"]
mod fem;

use bevy::prelude::*;
use bevy_soft_body::prelude::*;

fn main() {
    let args = common::args("fem_armadillo");
    let body = args.body(IntegratorKind::BackwardEuler, 1.0 / 60.0);
    let mut app = common::app("fem_armadillo", &args);
    app.add_systems(Startup, move |mut c: Commands, server: Res<AssetServer>| {
        c.insert_resource(fem::FemSpec {
            mesh: server.load("meshes/armadillo_coarse.mesh"),
            material: NeoHookean {
                young: 1e6,
                poisson: 0.45,
                density: 1000.0,
            },
            body: body.clone(),
            scale: 1.0,
            offset: [0.0, 0.3, 0.0],
            display: Some("meshes/armadillo_hires.obj"),
            pin_above: Some(0.95),
            kick: 3.0,
            color: Color::srgb(0.55, 0.6, 0.75),
        });
        common::stage(&mut c, Vec3::new(0.0, 0.8, 0.0), 2.8);
    })
    .add_systems(Update, (fem::spawn_when_loaded, yank));
    app.run();
}

/// Y: every free particle gets 40 m/s sideways per metre above the body's lowest point.
fn yank(
    input: Res<ButtonInput<KeyCode>>,
    bodies: Query<&SoftBodyInitial>,
    mut particles: Query<&mut Particle, Without<Pinned>>,
) {
    if !input.just_pressed(KeyCode::KeyY) {
        return;
    }
    for init in &bodies {
        let bottom = init
            .particles
            .iter()
            .map(|p| p.1.y)
            .fold(f32::MAX, f32::min);
        for (e, _, _) in &init.particles {
            if let Ok(mut p) = particles.get_mut(*e) {
                p.velocity.x += 40.0 * (p.position.y - bottom);
            }
        }
    }
}
