//! Headless finite-element measurements, printed as tables (no window, no keys):
//!
//! - `cantilever`: tip deflection of a clamped beam under gravity against Euler–Bernoulli
//!   `w L⁴ / (8 E I)` as the tet mesh is refined (linear tets lock in bending);
//! - `armadillo [E,E,… [KICK,KICK,…]]`: linearly implicit vs backward Euler at h = 1/60 on the
//!   armadillo hung by its top 5 % and yanked sideways (KICK m/s per metre of height), 5 s;
//! - `bunny`: energy, inverted tets and ground contacts per frame of the bunny dropped on the
//!   ground (env: YOUNG, DROP, BE=1 for backward Euler, SE=1 with H for symplectic Euler,
//!   PINBOTTOM=1 to pin its feet instead).
//!
//! `cargo run --release --no-default-features --example fem_study -- cantilever`
//! (costs per step and per Newton iteration are in `cargo bench --bench fem`).

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::driver::{DriverConfig, Simulation, StepPolicy};
use bevy_soft_body::core::fem::NeoHookean;
use bevy_soft_body::core::fem::mesh::TetMesh;
use bevy_soft_body::core::integrate::IntegratorKind;

/// The armadillo hung by the particles of its top 5 %, with a sideways kick of `kick` m/s on
/// the rest, stepped at h = 1/60 with `kind` for `seconds`: (frames run, first divergence).
pub fn armadillo(
    kind: IntegratorKind,
    mat: NeoHookean,
    kick: f64,
    seconds: f64,
) -> (u64, Option<String>, f64) {
    let text = std::fs::read_to_string("assets/meshes/armadillo_coarse.mesh").unwrap();
    let mesh = TetMesh::from_medit("armadillo_coarse.mesh", &text).unwrap();
    let (model, state) = bevy_soft_body::core::build::hung_tet_body(&mesh, mat, kick)
        .build()
        .unwrap();
    let mut sim = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: kind,
            policy: StepPolicy::Fixed { h: 1.0 / 60.0 },
            frame_dt: 1.0 / 60.0,
            ..Default::default()
        },
    );
    let frames = (seconds * 60.0).round() as u64;
    let mut emax: f64 = 0.0;
    for _ in 0..frames {
        if let Err(d) = sim.advance_frame() {
            return (sim.frame, Some(d.to_string()), emax);
        }
        emax = emax.max(sim.system.elastic_energy(&sim.state.x) as f64);
        if std::env::var("TRACE").is_ok() {
            use bevy_soft_body::core::ode::OdeSystem;
            let e = sim.system.energy(sim.time, &sim.state).unwrap();
            let st = sim.stats();
            println!(
                "frame {} E {:.1} K {:.1} inverted {} newton {} residual {:.2e}",
                sim.frame,
                e.total(),
                e.kinetic,
                sim.system.tets.inverted(&sim.state.x),
                st.newton_iterations,
                st.newton_residual
            );
        }
    }
    (sim.frame, None, emax)
}

/// The bunny on the ground (LIE or BE) with or without the ground: energy and inverted
/// elements per frame (diagnostics).
fn bunny_trace(kind: IntegratorKind, ground: bool, kick: f64) {
    let text = std::fs::read_to_string("assets/meshes/bunny_coarse.mesh").unwrap();
    let mesh = TetMesh::from_medit("bunny_coarse.mesh", &text)
        .unwrap()
        .transformed(
            1.0,
            [
                0.0,
                std::env::var("DROP").map_or(0.002, |s| s.parse().unwrap()),
                0.0,
            ],
        );
    let young: f64 = std::env::var("YOUNG").map_or(2e5, |s| s.parse().unwrap());
    let mat = NeoHookean {
        young,
        poisson: 0.4,
        density: 1000.0,
    };
    let mut scene = mesh.to_scene("bunny", mat);
    if !ground {
        scene.gravity = [0.0; 3];
    } else if std::env::var("PINBOTTOM").is_ok() {
        for p in &mut scene.particles {
            if p.position[1] < 0.03 {
                p.pinned = true;
            }
        }
    } else {
        scene
            .colliders
            .push(bevy_soft_body::core::build::ground(0.0, 0.0, 0.6));
    }
    for p in &mut scene.particles {
        p.velocity = [kick * p.position[1], 0.0, 0.0];
    }
    let (model, state) = scene.build().unwrap();
    let hh: f64 = std::env::var("H").map_or(1.0 / 60.0, |s| s.parse().unwrap());
    let kind = if std::env::var("SE").is_ok() {
        IntegratorKind::SymplecticEuler
    } else {
        kind
    };
    let mut sim = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: kind,
            policy: StepPolicy::Fixed { h: hh as _ },
            frame_dt: 1.0 / 60.0,
            ..Default::default()
        },
    );
    use bevy_soft_body::core::ode::OdeSystem;
    for _ in 0..60 {
        if let Err(d) = sim.advance_frame() {
            println!("{d}");
            break;
        }
        let e = sim.system.energy(sim.time, &sim.state).unwrap();
        if sim.frame <= 10 || sim.frame % 3 == 0 {
            println!(
                "frame {} E {:.1} K {:.1} elastic {:.1} inverted {} ymin {:.4} on ground {}",
                sim.frame,
                e.total(),
                e.kinetic,
                sim.system.tets.energy(&sim.state.x),
                sim.system.tets.inverted(&sim.state.x),
                sim.state
                    .x
                    .iter()
                    .map(|x| x.y as f64)
                    .fold(f64::MAX, f64::min),
                sim.state.x.iter().filter(|x| (x.y as f64) <= 1e-6).count()
            );
        }
    }
}

fn main() {
    if std::env::args().nth(1).as_deref() == Some("bunny") {
        let ground = std::env::args().nth(2).as_deref() != Some("noground");
        let kick: f64 = std::env::args().nth(3).map_or(1.0, |s| s.parse().unwrap());
        bunny_trace(
            if std::env::var("BE").is_ok() {
                IntegratorKind::BackwardEuler
            } else {
                IntegratorKind::LinearlyImplicitEuler
            },
            ground,
            kick,
        );
        return;
    }
    if let Some(a) = std::env::args().nth(1).filter(|a| a == "armadillo") {
        let _ = a;
        let young_list: Vec<f64> = std::env::args()
            .nth(2)
            .map_or(vec![1e5, 1e6, 1e7, 1e8], |s| {
                s.split(',').map(|x| x.parse().unwrap()).collect()
            });
        let kicks: Vec<f64> = std::env::args().nth(3).map_or(vec![0.0, 2.0, 10.0], |s| {
            s.split(',').map(|x| x.parse().unwrap()).collect()
        });
        for &young in &young_list {
            for &kick in &kicks {
                let mat = NeoHookean {
                    young,
                    poisson: 0.45,
                    density: 1000.0,
                };
                for kind in [
                    IntegratorKind::LinearlyImplicitEuler,
                    IntegratorKind::BackwardEuler,
                ] {
                    let t0 = std::time::Instant::now();
                    let (f, d, e) = armadillo(kind, mat, kick, 5.0);
                    println!(
                        "E {young:e} kick {kick} {kind}: {f} frames, max elastic {e:.3e} J, {:?}, {:.2} s",
                        d,
                        t0.elapsed().as_secs_f64()
                    );
                }
            }
        }
    }
    let what = std::env::args().nth(1).unwrap_or_else(|| "all".into());
    if what == "cantilever" || what == "all" {
        let (length, side): (f64, f64) = (1.0, 0.1);
        let mat = NeoHookean {
            young: 1.5e8,
            poisson: 0.0,
            density: 1000.0,
        };
        let w = mat.density * 9.81 * side * side;
        let i = side.powi(4) / 12.0;
        let eb = w * length.powi(4) / (8.0 * mat.young * i);
        println!("Euler–Bernoulli tip deflection {eb:.5} m");
        println!("| cells (length × side²) | tets | tip (m) | ratio to EB |");
        for (n, m) in [(10, 1), (20, 2), (40, 4), (60, 6), (80, 8)] {
            let t0 = std::time::Instant::now();
            let c = bevy_soft_body::core::study::cantilever_tip(length, side, n, m, mat).unwrap();
            eprintln!(
                "{n}x{m}: {} frames, {} Newton iterations, {:.2} s",
                c.frames,
                c.newton_iterations,
                t0.elapsed().as_secs_f64()
            );
            println!(
                "| {n} × {m}² | {} | {:.5} | {:.4} |",
                c.tets,
                c.tip,
                c.tip / eb
            );
        }
    }
}
