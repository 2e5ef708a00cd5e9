//! Cloths dropped on a sphere and the ground: they drape, fold onto themselves and onto each
//! other, and pile up — with self-collision (Bridson, Fedkiw and Anderson 2002) they never
//! pass through themselves or each other.
//!
//! ```text
//! cargo run --release --example cloth_pile
//! cargo run --release --example cloth_pile -- --bench     # headless: cost of a step, table
//! cargo run --release --example cloth_pile -- --bodies    # the pile as three bodies only
//! cargo run --release --example cloth_pile -- --bench --only 64   # the 64² rows only (or 32)
//! cargo run --release --example cloth_pile -- --bench --threads 2 # kernels on 2 threads (default 1)
//! cargo run --release --example cloth_pile -- --faces     # colliders against triangles: cost
//! cargo run --release --example cloth_pile -- --detail 3  # drawn 3× finer (SurfaceDetail)
//! ```
//!
//! The three cloths are one body (`Scene::append`), so their surfaces collide with each other
//! as well as with themselves. (Separate bodies that each have `SelfCollision` collide with
//! each other too, resolved once a frame after they have stepped; `--bench` compares the
//! two.) Keys: Space pause, N step, R reset (drop again), G wireframe;
//! left drag pulls a cloth, right drag or arrows orbit, wheel zoom. `--screenshot FILE
//! [--frames N]` renders N frames (default 150: piled at 2.5 s), saves a PNG and exits.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::build::{ClothPileParams, cloth_pile};
use bevy_soft_body::core::self_contact::SelfContactReport;
use bevy_soft_body::prelude::*;
use std::time::{Duration, Instant};

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;

fn main() {
    let argv: Vec<String> = std::env::args().collect();
    if argv.iter().any(|a| a == "--bodies") {
        // The separate-bodies row alone (`PER_FRAME=1`: each group pass's cost on stderr).
        bench_bodies(180);
        return;
    }
    if argv.iter().any(|a| a == "--faces") {
        bench_faces();
        return;
    }
    if argv.iter().any(|a| a == "--bench") {
        let only = argv
            .iter()
            .position(|a| a == "--only")
            .and_then(|k| argv.get(k + 1))
            .and_then(|n| n.parse().ok());
        // One thread unless asked: self-collision's share of a step is stated for one.
        let threads = argv
            .iter()
            .position(|a| a == "--threads")
            .and_then(|k| argv.get(k + 1))
            .and_then(|n| n.parse().ok())
            .unwrap_or(1);
        bench(argv.iter().any(|a| a == "--quick"), only, threads);
        return;
    }
    let args = common::args("cloth_pile");
    let p = ClothPileParams::default();
    let scene = cloth_pile(&p).expect("valid pile");
    let body = args.body(IntegratorKind::SymplecticEuler, p.stable_step());
    let detail = args.detail.map(SurfaceDetail::level);
    let mut app = common::app("cloth pile", &args);
    app.add_systems(Startup, move |mut commands: Commands| {
        let e = commands
            .spawn_soft_body(&scene, body.clone())
            .expect("built-in scene is valid");
        commands.entity(e).insert(SoftBodySurface {
            color: Color::srgb(0.25, 0.45, 0.85),
            ..surface(&scene)
        });
        if let Some(d) = detail {
            commands.entity(e).insert(d);
        }
        common::stage_with(
            &mut commands,
            common::OrbitCamera {
                target: Vec3::new(0.0, 0.3, 0.0),
                yaw: 0.6,
                pitch: 0.45,
                distance: 2.6,
            },
        );
    });
    app.run();
}

fn surface(scene: &Scene) -> SoftBodySurface {
    let s = scene.surface.clone().unwrap_or_default();
    SoftBodySurface {
        triangles: s.triangles,
        uvs: s.uvs,
        ..Default::default()
    }
}

/// Runs the pile headless and prints the cost of a step with and without self-collision,
/// with the broad/narrow split.
/// The table; `only`: just the rows of that resolution (64 or 32); the bodies' kernels,
/// self-contact and colliders on `threads` threads (`core::kernels::with_threads`).
///
/// The 64² cloth is run with symplectic Euler at its stable step and with linearly implicit
/// Euler at 1/60 s, each over the fall and the start of the drape (a sixth of the run) and
/// over the drape and the fold onto itself (two thirds): where it lies folded, every pass
/// tests the layers' pairs, and symplectic Euler takes 59 passes' worth of steps a frame. The
/// 3 × 32² pile with both too.
fn bench(quick: bool, only: Option<usize>, threads: usize) {
    let frames = if quick { 60 } else { 180 };
    println!(
        "cloth pile, symplectic Euler at `ClothPileParams::stable_step` (1/1200 s for 32², 1/3500 s for 64²) or linearly implicit Euler at 1/60 s, {}, {threads} thread(s)",
        PRECISION
    );
    println!(
        "| scene | method | frames | self-collision | µs per step | broad µs per step | narrow µs per step | passes per frame | searches per frame | searches around vertices per frame | triangle pairs per search | candidates (end) | near pairs per pass | CCD collisions | zones | passes due by budget / tube / horizon / frame end | particle making most passes due (passes) |"
    );
    println!(
        "| --- | --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | --- |"
    );
    let se = IntegratorKind::SymplecticEuler;
    let lie = IntegratorKind::LinearlyImplicitEuler;
    let rows = [
        (1, 64, se, frames / 6),
        (1, 64, se, frames * 2 / 3),
        (1, 64, lie, frames / 6),
        (1, 64, lie, frames * 2 / 3),
        (3, 32, se, frames),
        (3, 32, lie, frames),
    ];
    for (cloths, n, method, frames) in rows {
        if only.is_some_and(|o| o != n) {
            continue;
        }
        for on in [false, true] {
            let mut p = ClothPileParams {
                cloths,
                ..Default::default()
            }
            .with_resolution(n);
            if !on {
                p.self_collision = None;
            }
            let scene = cloth_pile(&p).expect("valid pile");
            let (model, state) = scene.build().expect("valid scene");
            let (sim, wall, steps) = timed(model, state, method, &p, frames, threads);
            let sc = sim.system.self_contact.as_ref();
            let r = sc.map_or(SelfContactReport::default(), |c| c.total);
            // What made the passes due, and the particle that made most of them due.
            let busiest = sc
                .and_then(|c| {
                    let counts = c.due_counts().iter().enumerate().filter(|&(_, &n)| n > 0);
                    counts.max_by_key(|&(i, &n)| (n, std::cmp::Reverse(i)))
                })
                .map_or("–".to_string(), |(i, n)| format!("{i} ({n})"));
            let frame_end = r.passes_run - r.due_budget - r.due_tube - r.due_horizon;
            let per = |d: Duration| d.as_secs_f64() * 1e6 / steps as f64;
            let pf = |k: u32| k as f64 / frames as f64;
            println!(
                "| {cloths} × {n}² | {} | {frames} | {} | {:.0} | {:.0} | {:.0} | {:.1} | {:.2} | {:.2} | {:.0} | {} | {:.0} | {} | {} | {} / {} / {} / {frame_end} | {busiest} |",
                method.label(),
                if on { "on" } else { "off" },
                per(wall),
                per(r.broad),
                per(r.narrow),
                pf(r.passes_run),
                pf(r.searches),
                pf(r.searched_around),
                r.tested as f64 / r.searches.max(1) as f64,
                r.candidates,
                r.proximity as f64 / r.passes_run.max(1) as f64,
                r.collisions,
                r.zones,
                r.due_budget,
                r.due_tube,
                r.due_horizon
            );
        }
    }
    if only.is_none() {
        bench_bodies(frames as u32);
    }
}

/// What the colliders' test of the surface's triangles costs (`Collider::resolve_faces`):
/// the pile's cloths without self-collision, over its 0.3 m sphere and over a box of the same
/// size in its place, with the triangles tested (as built) and with the particles alone
/// (`ParticleModel::contact_faces` emptied), one thread, 30 frames (64², the fall onto the
/// collider) or 60 (3 × 32²).
fn bench_faces() {
    println!("colliders against triangles, {PRECISION}, one thread");
    println!(
        "| collider | scene | method | frames | triangles tested: µs per step | particles alone: µs per step |"
    );
    println!("| --- | --- | --- | ---: | ---: | ---: |");
    let se = IntegratorKind::SymplecticEuler;
    let lie = IntegratorKind::LinearlyImplicitEuler;
    for boxed in [false, true] {
        for (cloths, n, method, frames) in [(1, 64, se, 30), (3, 32, se, 60), (1, 64, lie, 30)] {
            let mut cells = vec![];
            for faces in [true, false] {
                let mut p = ClothPileParams {
                    cloths,
                    ..Default::default()
                }
                .with_resolution(n);
                p.self_collision = None;
                let mut scene = cloth_pile(&p).expect("valid pile");
                if boxed {
                    let r = p.radius;
                    scene.colliders[1].shape = ShapeDesc::Cuboid {
                        half_extents: [r, r, r],
                    };
                }
                let (mut model, state) = scene.build().expect("valid scene");
                if !faces {
                    model.contact_faces.clear();
                }
                let (_, wall, steps) = timed(model, state, method, &p, frames, 1);
                cells.push(wall.as_secs_f64() * 1e6 / steps as f64);
            }
            println!(
                "| {} | {cloths} × {n}² | {} | {frames} | {:.0} | {:.0} |",
                if boxed { "box" } else { "sphere" },
                method.label(),
                cells[0],
                cells[1]
            );
        }
    }
}

/// `frames` frames of the pile's cloths (`p`, built into `model` and `state`) with `method`
/// at its step (the stable one for symplectic Euler, 1/60 s otherwise) on `threads` threads:
/// the simulation, the wall time of its frames and the steps they took.
fn timed(
    model: ParticleModel,
    state: ParticleState,
    method: IntegratorKind,
    p: &ClothPileParams,
    frames: usize,
    threads: usize,
) -> (Simulation<ParticleState, ParticleModel>, Duration, u64) {
    let h = if method == IntegratorKind::SymplecticEuler {
        p.stable_step()
    } else {
        1.0 / 60.0
    };
    let config = DriverConfig {
        integrator: method,
        policy: StepPolicy::Fixed { h },
        frame_dt: 1.0 / 60.0,
        ..Default::default()
    };
    let mut sim = Simulation::new(model, state, config);
    let (wall, steps) = bevy_soft_body::core::kernels::with_threads(threads, || {
        let (mut wall, mut steps) = (Duration::ZERO, 0u64);
        for _ in 0..frames {
            let t = Instant::now();
            let rep = sim.advance_frame().expect("stable");
            wall += t.elapsed();
            steps += rep.substeps as u64;
        }
        (wall, steps)
    });
    (sim, wall, steps)
}

/// The 3 × 32² pile as three bodies stepped apart (as the plugin steps them), with their
/// contact resolved once a frame (`core::body_contact`, what the plugin runs after its step:
/// passes along the frame when due), against the same pile as one body.
fn bench_bodies(frames: u32) {
    use bevy_soft_body::core::body_contact::{
        ContactGroup, GroupMember, overlapping_groups, swept_box,
    };
    let p = ClothPileParams::default();
    let pile = cloth_pile(&p).expect("valid pile");
    let config = DriverConfig {
        integrator: IntegratorKind::SymplecticEuler,
        policy: StepPolicy::Fixed { h: p.stable_step() },
        frame_dt: 1.0 / 60.0,
        ..Default::default()
    };
    let n = p.resolution;
    let mut sims: Vec<_> = (0..p.cloths)
        .map(|k| {
            let (model, state) = pile
                .part(k * n * n..(k + 1) * n * n)
                .build()
                .expect("valid scene");
            Simulation::new(model, state, config)
        })
        .collect();
    let mut group = ContactGroup::default();
    let (mut steps, mut step_wall, mut group_wall, mut passes) =
        (0u64, Duration::ZERO, Duration::ZERO, 0u32);
    let mut rep = SelfContactReport::default();
    for _ in 0..frames {
        let x0: Vec<Vec<_>> = sims.iter().map(|s| s.state.x.clone()).collect();
        let t = Instant::now();
        for s in &mut sims {
            steps += s.advance_frame().expect("stable").substeps as u64;
        }
        step_wall += t.elapsed();
        let t = Instant::now();
        let boxes: Vec<_> = sims
            .iter()
            .zip(&x0)
            .map(|(s, x0)| {
                let sc = s.system.self_contact.as_ref()?;
                swept_box(&sc.surface, x0, &s.state.x, sc.params.thickness as Scalar)
            })
            .collect();
        for g in overlapping_groups(&boxes) {
            let key: Vec<u64> = g.iter().map(|&k| k as u64).collect();
            let mut members: Vec<GroupMember> = vec![];
            for (k, (s, x0)) in sims.iter_mut().zip(&x0).enumerate() {
                if !g.contains(&k) {
                    continue;
                }
                let (system, state) = (&s.system, &mut s.state);
                let sc = system.self_contact.as_ref().expect("self-colliding");
                members.push(GroupMember {
                    surface: &sc.surface,
                    params: sc.params,
                    x0,
                    x: &mut state.x,
                    v: &mut state.v,
                    inv_mass: system.inv_mass(),
                    support: &[],
                });
            }
            let r = group.resolve(&key, config.frame_dt as Scalar, &mut members);
            if std::env::var("PER_FRAME").is_ok() {
                eprintln!(
                    "group pass: {} candidates, {:.1} ms",
                    r.candidates,
                    (r.broad + r.narrow).as_secs_f64() * 1e3
                );
            }
            rep.add(&r);
            passes += 1;
        }
        group_wall += t.elapsed();
    }
    let per_step = |d: Duration| d.as_secs_f64() * 1e6 / (steps as f64 / p.cloths as f64);
    println!(
        "| {} × {n}² as {} bodies | on (each) + between | {:.0} | {:.0} between | {:.0} | {:.2} group passes per frame | | | | {} | {} |",
        p.cloths,
        p.cloths,
        per_step(step_wall + group_wall),
        per_step(group_wall),
        per_step(rep.narrow),
        passes as f64 / frames as f64,
        rep.collisions,
        rep.zones
    );
}
