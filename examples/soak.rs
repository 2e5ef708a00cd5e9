//! Soak: long headless runs that must neither diverge, drift nor grow. No window, no keys.
//!
//! - the cloth_sphere scene (32×32 cloth, swinging sphere) with linearly implicit Euler at one
//!   step per 1/60 s frame, `--steps` steps;
//! - the undamped pendulum chain (no drag) with symplectic Euler at h = 1 ms, 10 × `--steps`
//!   steps: its energy error must stay within the band it shows in its first 10 000 steps
//!   (symplectic Euler's error oscillates, bounded, with no secular drift), times 2.
//!
//! Resident memory is read from `/proc/self/statm` after a tenth of the run and at the end;
//! the run fails (exit status 1) on a divergence, on energy leaving its band, or on resident
//! memory growing by more than 1 MiB after warm-up.
//!
//! ```text
//! cargo run --release --no-default-features --example soak -- --steps 1000000   # the full soak
//! cargo run --no-default-features --example soak -- --steps 1500                 # CI's short form
//! ```

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::build;
use bevy_soft_body::core::driver::{DriverConfig, Simulation, StepPolicy};
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::core::ode::OdeSystem;
use std::time::Instant;

/// Resident set size in bytes (Linux), or 0 where unknown.
fn rss() -> u64 {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<u64>().ok())
        .map_or(0, |pages| pages * 4096)
}

fn main() {
    let mut steps: u64 = 1_000_000;
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "--steps" => {
                steps = it.next().and_then(|s| s.parse().ok()).unwrap_or_else(|| {
                    eprintln!("--steps needs a count");
                    std::process::exit(1)
                })
            }
            other => {
                eprintln!("unknown option '{other}'\nusage: soak [--steps N]");
                std::process::exit(1);
            }
        }
    }
    let mut failed = false;

    // 1. cloth and sphere, linearly implicit Euler, one step per frame.
    let scene = build::cloth_sphere(
        &build::ClothParams::default().resized(32, 32),
        0.25,
        0.6,
        4.0,
    )
    .expect("built-in scene");
    let (model, state) = scene.build().expect("valid");
    let mut sim = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: IntegratorKind::LinearlyImplicitEuler,
            policy: StepPolicy::Fixed { h: 1.0 / 60.0 },
            frame_dt: 1.0 / 60.0,
            ..Default::default()
        },
    );
    let start = Instant::now();
    let (mut mem_warm, mut e_max) = (0, f64::MIN);
    for k in 0..steps {
        if let Err(d) = sim.advance_frame() {
            println!("cloth_sphere: {d}");
            failed = true;
            break;
        }
        if k == steps / 10 {
            mem_warm = rss();
        }
        let e = sim.system.energy(sim.time, &sim.state).unwrap().total() as f64;
        e_max = e_max.max(e);
    }
    let mem_end = rss();
    let grew = mem_end.saturating_sub(mem_warm);
    println!(
        "cloth_sphere, linearly implicit Euler: {} steps ({:.0} simulated s) in {:.1} s; highest total energy {e_max:.3} J; resident memory {:.1} MiB after warm-up, {:.1} MiB at the end",
        sim.stats().steps,
        sim.time,
        start.elapsed().as_secs_f64(),
        mem_warm as f64 / 1048576.0,
        mem_end as f64 / 1048576.0
    );
    if grew > 1 << 20 {
        println!("FAIL: memory grew by {grew} bytes after warm-up");
        failed = true;
    }

    // 2. undamped pendulum, symplectic Euler.
    let (model, state) = build::chain(&build::ChainParams {
        drag: 0.0,
        ..Default::default()
    })
    .unwrap()
    .build()
    .unwrap();
    let e0 = model.energy(0.0, &state).unwrap().total() as f64;
    let mut sim = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: IntegratorKind::SymplecticEuler,
            policy: StepPolicy::Fixed { h: 1e-3 },
            frame_dt: 1e-3,
            ..Default::default()
        },
    );
    let n = steps * 10;
    let (mut band, mut worst) = (0.0f64, 0.0f64);
    let start = Instant::now();
    for k in 0..n {
        if let Err(d) = sim.advance_frame() {
            println!("pendulum: {d}");
            failed = true;
            break;
        }
        let err = (sim.system.energy(sim.time, &sim.state).unwrap().total() as f64 - e0).abs();
        if k < 10_000 {
            band = band.max(err);
        } else {
            worst = worst.max(err);
        }
    }
    println!(
        "pendulum, symplectic Euler h = 1 ms: {n} steps ({:.0} simulated s) in {:.1} s; energy error band of the first 10 000 steps {band:.3e} J, largest after {worst:.3e} J",
        sim.time,
        start.elapsed().as_secs_f64()
    );
    if n > 10_000 && worst > 2.0 * band {
        println!("FAIL: the energy error left its band (symplectic Euler keeps it bounded)");
        failed = true;
    }
    std::process::exit(if failed { 1 } else { 0 });
}
