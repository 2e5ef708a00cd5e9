//! A curtain that tears: a 32 × 32 cloth held along its top edge by two hands that draw
//! apart and back; springs stretched past 30 % break, and the cloth rips from the top down
//! between the hands (`Tearable`, vertices split along the cut, texture coordinates kept).
//! Pull it apart yourself with the mouse: a hard drag tears it where you pull. With `--tets`,
//! a hanging slab of foam (1536 tets) held the same way cracks from the top down instead
//! (tets past a principal stretch of 1.3 split off at a corner; the crack's faces are drawn).
//!
//! ```text
//! cargo run --release --example tearing
//! cargo run --release --example tearing -- --bench     # headless: what a tear costs
//! cargo run --release --example tearing -- --detail 3  # drawn 3× finer (SurfaceDetail)
//! cargo run --release --example tearing -- --tets      # a slab of tets cracks instead
//! ```
//!
//! Keys: Space pause, N step, R reset (mend and start again), G wireframe; left drag pulls the
//! cloth (and tears it), right drag or arrows orbit, wheel zoom. `--screenshot FILE
//! [--frames N]` renders N frames (default 150: torn halfway down at 2.5 s), saves a PNG
//! and exits. Every tear is logged (`SoftBodyTorn`).

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::build::{ClothParams, ClothPins, cloth};
use bevy_soft_body::core::fem::mesh::TetMesh;
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
            motion: hand([x, y, z], side),
        });
    }
    s.tearing = Some(TearParams { max_strain: 0.3 });
    s
}

/// The path of a particle held by the left (`side` −1) or right (+1) hand:
/// p(t) = c + a·sin(ωt − π/2), which starts where the particle is, draws 0.2 m outwards by
/// t = π/ω ≈ 3.9 s, and comes back.
fn hand([x, y, z]: [f64; 3], side: f64) -> Motion {
    Motion::Oscillate {
        center: [x + side * 0.1, y, z],
        amplitude: [side * 0.1, 0.0, 0.0],
        omega: 0.8,
        phase: -std::f64::consts::FRAC_PI_2,
    }
}

/// The slab (`--tets`): a block of foam 0.8 m × 0.4 m × 8 cm hanging from its top face,
/// 16 × 8 × 2 cubes of six tets (1536 tets), E = 50 kPa, ν = 0.3, 300 kg/m³; the top face's
/// left and right halves follow the curtain's hands; tets break past a largest principal
/// stretch of 1.3.
fn slab() -> Scene {
    let mesh = TetMesh::tet_box([0.8, 0.4, 0.08], [16, 8, 2])
        .expect("valid box")
        .transformed(1.0, [-0.4, 1.2, -0.04]);
    let mut s = mesh.to_scene(
        "tearing slab",
        NeoHookean {
            young: 5e4,
            poisson: 0.3,
            density: 300.0,
        },
    );
    let top = 1.6 - 1e-9;
    for k in 0..s.particles.len() {
        let [x, y, z] = s.particles[k].position;
        if y < top {
            continue;
        }
        let side = if x <= 1e-9 { -1.0 } else { 1.0 };
        s.motions.push(MotionDesc {
            particle: k,
            motion: hand([x, y, z], side),
        });
    }
    s.tearing = Some(TearParams { max_strain: 0.3 });
    s
}

/// Symplectic Euler, stable for these springs (the cloth pile's `stable_step`, 1/1200 s) and
/// for the slab's tets (its P-wave speed 15 m/s across 5 cm cubes allows about 1/500 s).
const H: f64 = 1.0 / 1200.0;

fn main() {
    let argv: Vec<String> = std::env::args().collect();
    if argv.iter().any(|a| a == "--bench") {
        bench();
        return;
    }
    let args = common::args_with("tearing", &["--tets"]);
    let tets = argv.iter().any(|a| a == "--tets");
    let scene = if tets { slab() } else { curtain() };
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
            color: if tets {
                Color::srgb(0.85, 0.70, 0.30)
            } else {
                Color::srgb(0.80, 0.30, 0.25)
            },
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
            "soft body {}: {} springs and {} tets broke, {} particles split",
            t.body,
            t.springs.len(),
            t.tets.len(),
            t.split.len()
        );
    }
}

/// Headless: the curtain for 4 s, with and without tearing, and what the tears cost.
fn bench() {
    println!(
        "tearing curtain ({N}² cloth) and slab (1536 tets, `--tets`), symplectic Euler h = 1/1200 s, 240 frames (4 s), {PRECISION}, one thread"
    );
    println!(
        "| body | tearing | µs per step (stepping) | tear checks µs per frame | frames with a tear | µs per tear (split + rebuild) | springs broken | tets broken | particles added |"
    );
    println!("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    for (tets, on) in [(false, false), (false, true), (true, false), (true, true)] {
        let mut scene = if tets { slab() } else { curtain() };
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
        let (mut steps, mut tears, mut tets_over) = (0u64, 0u32, 0usize);
        let mut frames = 0;
        for _ in 0..240 {
            let t = Instant::now();
            match sim.advance_frame() {
                Ok(r) => steps += r.substeps as u64,
                Err(e) => {
                    println!(
                        "({} {}: {e})",
                        if tets { "slab" } else { "curtain" },
                        if on { "on" } else { "off" }
                    );
                    break;
                }
            }
            frames += 1;
            step += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let torn = tear_scene(&mut scene, &mut sim).expect("valid");
            let dt = t.elapsed().as_secs_f64();
            if torn.is_empty() {
                check += dt;
            } else {
                tear += dt;
                tears += 1;
                tets_over += torn.tets_over.len();
            }
        }
        println!(
            "| {} | {} | {:.0} | {:.1} | {tears} | {:.0} | {} | {tets_over} | {} |",
            if tets { "slab" } else { "curtain" },
            if on { "on" } else { "off" },
            step * 1e6 / steps as f64,
            check * 1e6 / (frames - tears).max(1) as f64,
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
