//! The main job: a 32×32 cloth held by its two top corners, and a sphere swinging back and
//! forth through it, smooth shaded — through `SoftBodyPlugin`: the cloth is a body of particle
//! and spring entities spawned from the core's `cloth_sphere` scene, the sphere a
//! `SoftBodyCollider` moved by a `ScriptedMotion`. Like the classic sample solution, the
//! integrator letter and step size come from the command line:
//!
//! ```text
//! cargo run --release --example cloth_sphere              # RK4, h = 0.0025
//! cargo run --release --example cloth_sphere -- r 0.005   # RK4 at twice the step: diverges, and says so
//! cargo run --release --example cloth_sphere -- s 0.001   # symplectic Euler
//! cargo run --release --example cloth_sphere -- i 0.0167  # linearly implicit Euler, one step per frame
//! cargo run --release --example cloth_sphere -- b 0.0167  # Newton backward Euler, one step per frame
//! cargo run --release --example cloth_sphere -- t 0.001 --size 24
//! cargo run --release --example cloth_sphere -- --size 24 --detail 4   # 24² simulated, drawn as ~93²
//! ```
//!
//! `--detail L` draws each simulated triangle as L² (a `SurfaceDetail`: Phong tessellation of
//! the coarse cloth; the simulation is unchanged).
//!
//! Letters: e forward Euler, s symplectic Euler, t trapezoid, m midpoint, r RK4, a RK45,
//! i linearly implicit Euler, d trapezoid with implicit damping, b backward Euler (Newton).
//!
//! Keys (the `SoftBodyUiPlugin` panel shows them too): Space pause/resume, N single step,
//! R reset, W wind, G wireframe, E/S/T/M/K/A/I/D/B/X/P switch integrator (K = RK4). Mouse: left
//! drag pulls the nearest particle, right drag or arrows orbit, wheel or Up/Down zoom.
//!
//! `--screenshot FILE [--frames N]` renders N frames of exactly 1/60 s each (default 150: the
//! sphere, which starts behind the cloth, has pushed it forward and is draped by it at
//! t = 2.5 s), saves a PNG and exits.

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;
use bevy_soft_body::prelude::*;

fn main() {
    let args = common::args("cloth_sphere");
    let params = common::stiff_cloth(args.size.unwrap_or(32));
    let scene = build::cloth_sphere(&params, 0.25, 0.6, 4.0).expect("valid cloth size");
    let body = SoftBody {
        // This scene's internal energy stays far below its energy scale (the cloth swings
        // under gravity, the sphere moves at ~1 m/s), so a guard of 10× stops a diverging
        // method while the last good frame still looks like a cloth.
        energy_guard: Some(10.0),
        ..args.body(IntegratorKind::Rk4, 0.0025)
    };
    let detail = args.detail.map(SurfaceDetail::level);
    let mut app = common::app("cloth and sphere", &args);
    app.add_systems(Startup, move |mut commands: Commands| {
        let e = commands
            .spawn_soft_body(&scene, body.clone())
            .expect("built-in scene is valid");
        if let Some(d) = detail {
            commands.entity(e).insert(d);
        }
        common::stage_with(
            &mut commands,
            common::OrbitCamera {
                target: Vec3::new(0.0, 0.45, 0.0),
                yaw: 0.5,
                pitch: 0.12,
                distance: 2.4,
            },
        );
    });
    app.run();
}
