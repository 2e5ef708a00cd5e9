//! Force fields: the built-ins' Jacobians against central differences, and a jelly raft
//! floating in a buoyancy field at the depth Archimedes gives, with an explicit and an implicit
//! method, in the core and through the plugin.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

mod common;
use bevy_soft_body::core::build;
use bevy_soft_body::core::driver::{DriverConfig, Simulation, StepPolicy};
use bevy_soft_body::core::forces::{Buoyancy, ForceField, RadialBlast};
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::math::{Scalar, Vector};
use std::sync::Arc;

const F64: bool = cfg!(feature = "f64");

/// `∂f/∂x` and `∂f/∂v` by central differences (step `e`), row by row.
fn differences(
    field: &dyn ForceField,
    t: Scalar,
    x: Vector,
    v: Vector,
    m: Scalar,
    e: Scalar,
) -> ([Vector; 3], [Vector; 3]) {
    let mut dx = [Vector::ZERO; 3];
    let mut dv = [Vector::ZERO; 3];
    for c in 0..3 {
        let mut d = Vector::ZERO;
        d[c] = e;
        let fx = (field.force(t, x + d, v, m) - field.force(t, x - d, v, m)) / (2.0 * e);
        let fv = (field.force(t, x, v + d, m) - field.force(t, x, v - d, m)) / (2.0 * e);
        for r in 0..3 {
            dx[r][c] = fx[r];
            dv[r][c] = fv[r];
        }
    }
    (dx, dv)
}

fn check(field: &dyn ForceField, t: Scalar, x: Vector, v: Vector, m: Scalar) -> Scalar {
    let j = field
        .jacobian(t, x, v, m)
        .expect("the built-ins give their Jacobian");
    let e = if F64 { 1e-6 } else { 1e-3 };
    let (dx, dv) = differences(field, t, x, v, m, e);
    let mut scale: Scalar = 1e-30;
    let mut err: Scalar = 0.0;
    for r in 0..3 {
        scale = scale
            .max(dx[r].abs().max_element())
            .max(dv[r].abs().max_element());
        err = err
            .max((j.dx[r] - dx[r]).abs().max_element())
            .max((j.dv[r] - dv[r]).abs().max_element());
    }
    err / scale
}

#[test]
fn the_built_in_fields_jacobians_match_differences() {
    // Central differences: truncation O(e²) (exact here for the piecewise-linear buoyancy),
    // round-off about u·|f|/e: 1e-4 in f32 (u = 6e-8, e = 1e-3), 1e-10 in f64.
    let tol = if F64 { 1e-6 } else { 3e-3 };
    let buoy = Buoyancy {
        level: 0.3,
        layer: 0.1,
        drag: 3.0,
        ..Default::default()
    };
    // In the band where the particle goes under, fully under, and moving.
    for (y, v) in [
        (0.31, Vector::new(0.2, -0.5, 0.1)),
        (0.27, Vector::new(-1.0, 0.3, 0.0)),
        (0.1, Vector::new(0.4, 0.4, -0.2)),
    ] {
        let x = Vector::new(0.2, y, -0.1);
        let r = check(&buoy, 0.0, x, v, 0.7);
        println!("buoyancy at y = {y}: relative error {r:e}");
        assert!(r < tol, "buoyancy at y = {y}: {r}");
    }
    let blast = RadialBlast {
        center: [0.1, 0.2, 0.0],
        strength: 150.0,
        radius: 0.4,
        start: 0.0,
        duration: 1.0,
    };
    for x in [
        Vector::new(0.3, 0.1, 0.2),
        Vector::new(-0.2, 0.6, 0.1),
        Vector::new(0.12, 0.21, -0.05),
    ] {
        let r = check(&blast, 0.5, x, Vector::ZERO, 0.3);
        println!("blast at {x}: relative error {r:e}");
        assert!(r < tol, "blast at {x}: {r}");
    }
    // Before it starts, nothing.
    assert_eq!(
        blast.force(-0.1, Vector::X, Vector::ZERO, 1.0),
        Vector::ZERO
    );
}

/// A 7×3×7 jelly raft of slabs 0.1 m thick standing for 500 kg/m³, in water (1000 kg/m³)
/// whose surface is at y = 0.3: Archimedes says it floats with half its 0.3 m height under the
/// surface, 0.15 m. Let go from above the water, it settles there (within 3 %) with symplectic
/// Euler and with linearly implicit Euler (which takes the field's stiffness implicitly).
/// (A raft, not a cube: a cube of half the water's density floats tilted — its metacentre is
/// below its centre of mass upright — and a wide raft's is well above.)
#[test]
fn a_jelly_floats_at_the_depth_archimedes_gives() {
    let spacing = 0.1;
    let rho_b = 500.0;
    let mut scene = build::jelly(&build::JellyParams {
        size: [7, 3, 7],
        spacing,
        mass: rho_b * spacing * spacing * spacing,
        stiffness: [20000.0, 10000.0, 5000.0],
        damping: 2.0,
        drop_height: 0.5,
        ..Default::default()
    })
    .unwrap();
    scene.colliders.clear();
    let level = 0.3;
    let field = Buoyancy {
        level,
        fluid_density: 1000.0,
        body_density: rho_b,
        gravity: 9.81,
        layer: spacing,
        drag: 3.0,
        region: None,
    };
    let expect = rho_b / 1000.0 * 3.0 * spacing;
    for (kind, h) in [
        (IntegratorKind::SymplecticEuler, 1.0 / 2400.0),
        (IntegratorKind::LinearlyImplicitEuler, 1.0 / 120.0),
    ] {
        let (mut model, state) = scene.build().unwrap();
        model.fields.push(Arc::new(field));
        let mut sim = Simulation::new(
            model,
            state,
            DriverConfig {
                integrator: kind,
                policy: StepPolicy::Fixed { h },
                frame_dt: 1.0 / 60.0,
                ..Default::default()
            },
        );
        for _ in 0..(8 * 60) {
            sim.advance_frame().unwrap();
        }
        let bottom = sim
            .state
            .x
            .iter()
            .map(|x| x.y as f64)
            .fold(f64::INFINITY, f64::min);
        let speed = sim
            .state
            .v
            .iter()
            .map(|v| v.length() as f64)
            .fold(0.0, f64::max);
        // The bottom slab's lower face is half a layer under the bottom particles.
        let depth = level - (bottom - spacing / 2.0);
        println!(
            "{}: depth {depth:.4} m (Archimedes {expect:.4} m), fastest particle {speed:e} m/s",
            kind.name()
        );
        assert!(
            (depth - expect).abs() < 0.03 * expect,
            "{}: depth {depth} vs {expect}",
            kind.name()
        );
        assert!(speed < 0.01, "{}: still moving at {speed}", kind.name());
    }
}

/// Through the plugin: the same raft floats at the same depth with the field given to every
/// body (`GlobalForceFields`) or to this body alone (`SoftBodyForceFields`).
#[cfg(feature = "plugin")]
#[test]
fn the_plugin_applies_world_and_body_fields() {
    use bevy::ecs::system::RunSystemOnce;
    use bevy::prelude::Commands;
    use bevy_soft_body::ecs::{
        BodyParticles, GlobalForceFields, Particle, SoftBody, SoftBodyForceFields, SpawnSoftBody,
    };
    let spacing = 0.1;
    let mut scene = build::jelly(&build::JellyParams {
        size: [5, 2, 5],
        spacing,
        mass: 500.0 * spacing * spacing * spacing,
        stiffness: [20000.0, 10000.0, 5000.0],
        damping: 2.0,
        drop_height: 0.4,
        ..Default::default()
    })
    .unwrap();
    scene.colliders.clear();
    let field: bevy_soft_body::core::forces::SharedField = Arc::new(Buoyancy {
        level: 0.3,
        layer: spacing,
        drag: 3.0,
        ..Default::default()
    });
    for global in [true, false] {
        let mut app = common::headless_app(1.0 / 64.0);
        if global {
            app.insert_resource(GlobalForceFields(vec![field.clone()]));
        }
        let (sc, f) = (scene.clone(), field.clone());
        let body = app
            .world_mut()
            .run_system_once(move |mut c: Commands| {
                let e = c
                    .spawn_soft_body(
                        &sc,
                        SoftBody {
                            integrator: IntegratorKind::LinearlyImplicitEuler,
                            step: StepPolicy::Fixed { h: 1.0 / 128.0 },
                            ..Default::default()
                        },
                    )
                    .unwrap();
                if !global {
                    c.entity(e).insert(SoftBodyForceFields(vec![f.clone()]));
                }
                e
            })
            .unwrap();
        for _ in 0..(8 * 64) {
            app.update();
        }
        let w = app.world_mut();
        let ps = w.get::<BodyParticles>(body).unwrap().entities().to_vec();
        let bottom = ps
            .iter()
            .map(|e| w.get::<Particle>(*e).unwrap().position.y as f64)
            .fold(f64::INFINITY, f64::min);
        let depth = 0.3 - (bottom - spacing / 2.0);
        // Half of 0.2 m under the surface.
        println!("global {global}: depth {depth:.4} m (Archimedes 0.1 m)");
        assert!((depth - 0.1).abs() < 0.003, "global {global}: {depth}");
    }
}
