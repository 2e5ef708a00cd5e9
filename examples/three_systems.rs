//! The sample solution's three systems side by side: the circle system (left, gizmos: the
//! exact circle in grey, the computed path in blue), the pendulum chain (middle) and the cloth
//! with a swinging sphere (right). The chain and cloth are plugin bodies; the circle is a
//! first-order system stepped by the core directly (it has no particles). One integrator
//! letter and step size for all: `cargo run --release --example three_systems -- r 0.0025`.
//!
//! Keys: Space pause, N step, R reset, W wind, G wireframe, E/S/T/M/K/A/I/D/B/X/P integrator for
//! the bodies, E/S/T/M/K/A for the circle (K = RK4); left drag pulls a particle, right drag
//! or arrows orbit, wheel zoom.

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;
use bevy_soft_body::prelude::*;

fn main() {
    let args = common::args("three_systems");
    let kind = args.integrator.unwrap_or(IntegratorKind::Rk4);
    let chain = build::chain(&build::ChainParams::default())
        .expect("valid chain")
        .translated([-0.4, 1.0, 0.0]);
    let cloth = build::cloth_sphere(
        &common::stiff_cloth(args.size.unwrap_or(24)),
        0.25,
        0.6,
        4.0,
    )
    .expect("valid cloth")
    .translated([1.8, 0.0, 0.0]);
    let body = args.body(IntegratorKind::Rk4, 0.0025);
    let mut app = common::app("three systems", &args);
    let circle_kind = if kind.is_implicit() {
        IntegratorKind::Rk4
    } else {
        kind
    };
    common::circle::add(
        &mut app,
        circle_kind,
        args.h.unwrap_or(1.0 / 60.0),
        Vec3::new(-1.8, 0.5, 0.0),
        0.5,
    );
    app.add_systems(Startup, move |mut c: Commands| {
        c.spawn_soft_body(&chain, body.clone())
            .expect("valid chain");
        let cloth_body = SoftBody {
            energy_guard: Some(10.0),
            ..body.clone()
        };
        c.spawn_soft_body(&cloth, cloth_body).expect("valid cloth");
        common::stage(&mut c, Vec3::new(0.0, 0.5, 0.0), 5.0);
    });
    app.run();
}
