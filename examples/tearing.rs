//! A curtain that tears: a 32 × 32 cloth held along its top edge by two hands that draw
//! apart and back; springs stretched past 30 % break, and the cloth rips from the top down
//! between the hands (`Tearable`, vertices split along the cut, texture coordinates kept).
//! Pull it apart yourself with the mouse: a hard drag tears it where you pull.
//!
//! ```text
//! cargo run --release --example tearing
//! cargo run --release --example tearing -- --bench     # headless: what a tear costs
//! cargo run --release --example tearing -- --detail 3  # drawn 3× finer (SurfaceDetail)
//! ```
//!
//! Keys: Space pause, N step, R reset (mend and start again), G wireframe; left drag pulls the
//! cloth (and tears it), right drag or arrows orbit, wheel zoom. `--screenshot FILE
//! [--frames N]` renders N frames (default 150: torn halfway down at 2.5 s), saves a PNG
//! and exits. Every tear is logged (`SoftBodyTorn`).

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::build::{ClothParams, ClothPins, cloth};
use bevy_soft_body::core::scene::MotionDesc;
use bevy_soft_body::core::tear::{TearParams, tear_scene};
use bevy_soft_body::prelude::*;
use std::time::Instant;

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;

const N: usize = 32;

/// The curtain: 1 m square, 2 kg, stretch springs 500 N/m (the cloth pile's cloth, hanging),
/// its top row following two hands that draw apart by 0.4 m and back over 7.9 s
/// (`Oscillate`, ω = 0.8 rad/s); tearing at a strain of 0.3.
fn curtain() -> Scene {
    let p = ClothParams {
        rows: N,
        cols: N,
        width: 1.0,
        height: 1.0,
        mass: 2.0 / (N * N) as f64,
        k_structural: 500.0,
        k_shear: 200.0,
        k_flex: 5.0,
        damping: 0.02,
        drag: 0.002,
        pins: ClothPins::None,
        hanging: true,
        origin: [0.0, 1.6, 0.0],
    };
    let mut s = cloth(&p).expect("valid cloth");
    s.name = "tearing".into();
    for j in 0..N {
        let k = p.index_of(0, j);
        let side = if j < N / 2 { -1.0 } else { 1.0 };
        let [x, y, z] = s.particles[k].position;
        s.motions.push(MotionDesc {
            particle: k,
            // p(t) = c + a·sin(ωt − π/2): starts where the particle is, draws 0.2 m outwards
            // by t = π/ω ≈ 3.9 s, and comes back.
            motion: Motion::Oscillate {
                center: [x + side * 0.1, y, z],
                amplitude: [side * 0.1, 0.0, 0.0],
                omega: 0.8,
                phase: -std::f64::consts::FRAC_PI_2,
            },
        });
    }
    s.tearing = Some(TearParams { max_strain: 0.3 });
    s
}

/// Symplectic Euler, stable for these springs (the cloth pile's `stable_step`, 1/1200 s).
const H: f64 = 1.0 / 1200.0;

fn main() {
    let argv: Vec<String> = std::env::args().collect();
    if argv.iter().any(|a| a == "--bench") {
        bench();
        return;
    }
    let args = common::args("tearing");
    let scene = curtain();
    let body = args.body(IntegratorKind::SymplecticEuler, H);
    let detail = args.detail.map(SurfaceDetail::level);
    let mut app = common::app("tearing", &args);
    app.add_systems(Startup, move |mut commands: Commands| {
        let e = commands
            .spawn_soft_body(&scene, body.clone())
            .expect("built-in scene is valid");
        let s = scene.surface.clone().unwrap_or_default();
        commands.entity(e).insert(SoftBodySurface {
            triangles: s.triangles,
            uvs: s.uvs,
            color: Color::srgb(0.80, 0.30, 0.25),
            ..Default::default()
        });
        if let Some(d) = detail {
            commands.entity(e).insert(d);
        }
        common::stage_with(
            &mut commands,
            common::OrbitCamera {
                target: Vec3::new(0.0, 1.1, 0.0),
                yaw: 0.35,
                pitch: 0.15,
                distance: 2.2,
            },
        );
    })
    .add_systems(Update, log_tears);
    app.run();
}

fn log_tears(mut torn: MessageReader<SoftBodyTorn>) {
    for t in torn.read() {
        info!(
            "soft body {}: {} springs broke, {} particles split",
            t.body,
            t.springs.len(),
            t.split.len()
        );
    }
}

/// Headless: the curtain for 4 s, with and without tearing, and what the tears cost.
fn bench() {
    println!(
        "tearing curtain, {N}² cloth, symplectic Euler h = 1/1200 s, 240 frames (4 s), {PRECISION}, one thread"
    );
    println!(
        "| tearing | µs per step (stepping) | tear checks µs per frame | frames with a tear | µs per tear (split + rebuild) | springs broken | particles added |"
    );
    println!("| --- | ---: | ---: | ---: | ---: | ---: | ---: |");
    for on in [false, true] {
        let mut scene = curtain();
        if !on {
            scene.tearing = None;
        }
        let (model, state) = scene.build().expect("valid scene");
        let mut sim = Simulation::new(
            model,
            state,
            DriverConfig {
                integrator: IntegratorKind::SymplecticEuler,
                policy: StepPolicy::Fixed { h: H },
                frame_dt: 1.0 / 60.0,
                ..Default::default()
            },
        );
        let (n0, s0) = (scene.particles.len(), scene.springs.len());
        let (mut step, mut check, mut tear) = (0.0, 0.0, 0.0);
        let (mut steps, mut tears) = (0u64, 0u32);
        for _ in 0..240 {
            let t = Instant::now();
            steps += sim.advance_frame().expect("stable").substeps as u64;
            step += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let torn = tear_scene(&mut scene, &mut sim).expect("valid");
            let dt = t.elapsed().as_secs_f64();
            if torn.is_empty() {
                check += dt;
            } else {
                tear += dt;
                tears += 1;
            }
        }
        println!(
            "| {} | {:.0} | {:.1} | {tears} | {:.0} | {} | {} |",
            if on { "on" } else { "off" },
            step * 1e6 / steps as f64,
            check * 1e6 / (240 - tears) as f64,
            if tears > 0 {
                tear * 1e6 / tears as f64
            } else {
                0.0
            },
            s0 - scene.springs.len(),
            scene.particles.len() - n0
        );
    }
}
