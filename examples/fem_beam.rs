//! A cantilever: a 1 m beam of square 0.1 m section (40×4×4 cells, 3840 linear tets;
//! E = 30 MPa, ν = 0, ρ = 1000 kg/m³) clamped at x = 0, sagging under gravity next to
//! Euler–Bernoulli's small-strain tip deflection `w L⁴ / (8 E I)` (the yellow marker). The
//! readout compares the measured tip with it: linear tets are too stiff in bending (shear
//! locking), so this mesh reaches about 83 % of it and finer meshes approach it
//! (`cargo run --release --no-default-features --example fem_study -- cantilever` prints the
//! convergence table). Newton backward Euler, one step per 60 Hz frame, light drag so it
//! settles.
//!
//! Keys: Space pause, N (paused) step, N (running) linearly implicit ↔ backward Euler,
//! R reset, G wireframe, E/T/M/K/A/I/D/B integrator; left drag pulls the nearest vertex,
//! right drag or arrows orbit, wheel zoom.

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;
use bevy_soft_body::prelude::*;

const LENGTH: f64 = 1.0;
const SIDE: f64 = 0.1;
const HEIGHT: f64 = 1.0;
const MATERIAL: NeoHookean = NeoHookean {
    young: 3e7,
    poisson: 0.0,
    density: 1000.0,
};

/// Euler–Bernoulli: w = ρ g A per length, I = a⁴/12, tip deflection w L⁴ / (8 E I).
fn analytic_tip() -> f64 {
    let w = MATERIAL.density * 9.81 * SIDE * SIDE;
    let i = SIDE.powi(4) / 12.0;
    w * LENGTH.powi(4) / (8.0 * MATERIAL.young * i)
}

#[derive(Resource)]
struct Beam {
    root: Entity,
    tip: Vec<Entity>,
}

fn main() {
    let args = common::args("fem_beam");
    let body = SoftBody {
        drag: 0.02,
        ..args.body(IntegratorKind::BackwardEuler, 1.0 / 60.0)
    };
    let mut app = common::app("fem_beam", &args);
    app.add_systems(Startup, move |mut c: Commands| {
        let mesh = TetMesh::beam(LENGTH, SIDE, 40, 4)
            .unwrap()
            .transformed(1.0, [-0.5, HEIGHT, 0.0]);
        let root = c
            .spawn_tet_body(&mesh, MATERIAL, body.clone(), None)
            .expect("a valid beam");
        c.entity(root).insert(SoftBodySurface {
            triangles: mesh.boundary(),
            color: Color::srgb(0.4, 0.65, 0.85),
            ..default()
        });
        c.insert_resource(Beam { root, tip: vec![] });
        common::stage(&mut c, Vec3::new(0.0, HEIGHT as f32 - 0.05, 0.0), 1.8);
    })
    .add_systems(Update, (clamp_and_find_tip, marker))
    .add_systems(bevy_egui::EguiPrimaryContextPass, readout);
    app.run();
}

/// Once spawned: pin the x = 0 end, remember the free end's particles.
fn clamp_and_find_tip(
    mut commands: Commands,
    mut beam: ResMut<Beam>,
    init: Query<&SoftBodyInitial>,
    mut done: Local<bool>,
) {
    if *done {
        return;
    }
    let Ok(init) = init.get(beam.root) else {
        return;
    };
    for (e, x, _) in &init.particles {
        if (x.x + 0.5).abs() < 1e-4 {
            commands.entity(*e).insert(Pinned::here());
        } else if (x.x - 0.5).abs() < 1e-4 {
            beam.tip.push(*e);
        }
    }
    *done = true;
}

/// Mean downward displacement of the free end (m).
fn tip_deflection(beam: &Beam, particles: &Query<&Particle>, init: &SoftBodyInitial) -> f32 {
    let rest: std::collections::HashMap<Entity, Vec3> =
        init.particles.iter().map(|(e, x, _)| (*e, *x)).collect();
    let n = beam.tip.len().max(1) as f32;
    beam.tip
        .iter()
        .filter_map(|e| Some(rest[e].y - particles.get(*e).ok()?.position.y))
        .sum::<f32>()
        / n
}

/// The analytic tip as a yellow marker.
fn marker(mut gizmos: Gizmos) {
    let eb = analytic_tip() as f32;
    let m = Vec3::new(0.5, HEIGHT as f32 + SIDE as f32 / 2.0 - eb, 0.0);
    let c = Color::srgb(1.0, 0.85, 0.2);
    gizmos.line(m - Vec3::Z * 0.12, m + Vec3::Z * 0.12, c);
    gizmos.sphere(Isometry3d::from_translation(m), 0.01, c);
}

fn readout(
    beam: Res<Beam>,
    particles: Query<&Particle>,
    init: Query<&SoftBodyInitial>,
    mut contexts: bevy_egui::EguiContexts,
) -> Result {
    let Ok(init) = init.get(beam.root) else {
        return Ok(());
    };
    let w = tip_deflection(&beam, &particles, init);
    let eb = analytic_tip() as f32;
    bevy_egui::egui::Window::new("cantilever")
        .anchor(bevy_egui::egui::Align2::RIGHT_BOTTOM, [-8.0, -8.0])
        .show(contexts.ctx_mut()?, |ui| {
            ui.label(format!("tip deflection {:.2} mm", 1e3 * w));
            ui.label(format!("Euler–Bernoulli {:.2} mm (yellow)", 1e3 * eb));
            ui.label(format!("ratio {:.3}", w / eb));
        });
    Ok(())
}
