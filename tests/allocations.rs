//! "Integrators own their scratch: a step allocates nothing" — checked with a counting global
//! allocator. After one warm-up frame (scratch states are created on the first step), whole
//! frames of every integrator on a cloth with wind, dampers, drag, pins and a collider make no
//! heap allocation at all; nor do the implicit methods' frames on a tet body resting on the
//! ground, nor the constrained solve of triangles held at their contact points.
//!
//! Without the test harness (`harness = false`): the harness's own thread allocates when it
//! first waits for a test's result, and under load that can fall inside a counted window.
//! Here the only threads are this one and the kernels' team.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

mod common;

use bevy_soft_body::core::collide::{FaceHold, NormalHolds};
use bevy_soft_body::core::fem::NeoHookean;
use bevy_soft_body::core::fem::mesh::TetMesh;
use bevy_soft_body::core::jacobian::Linearization;
use bevy_soft_body::core::solve::{Pcg, Preconditioner};
use bevy_soft_body::prelude::*;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn main() {
    frames_allocate_nothing_after_the_first();
    println!(
        "allocations: every integrator's frames (Auto's after its decision), the chunked kernels, the implicit solve on the team, tets resting on the ground, triangles held at points and self-collision allocate nothing"
    );
}

/// Heap allocations (any thread's) while `sim` advances `frames` frames.
fn allocations_in<S: OdeState, Sys: OdeSystem<S>>(
    sim: &mut Simulation<S, Sys>,
    frames: usize,
) -> usize {
    let before = ALLOCS.load(Ordering::Relaxed);
    for _ in 0..frames {
        sim.advance_frame().unwrap();
    }
    ALLOCS.load(Ordering::Relaxed) - before
}

fn frames_allocate_nothing_after_the_first() {
    let mut scene = build::cloth_sphere(&build::ClothParams::default(), 0.25, 0.6, 4.0).unwrap();
    scene.wind = Some(Wind::default());
    let (model, state) = scene.build().unwrap();
    // Auto too: it decides (and allocates) in its first frame only.
    for kind in IntegratorKind::ALL
        .into_iter()
        .chain([IntegratorKind::Auto])
    {
        // Inside each method's stability region on this cloth (fastest mode ω ≈ 245 rad/s).
        let h = match kind {
            IntegratorKind::ForwardEuler => 2e-4,
            IntegratorKind::SymplecticEuler => 5e-4,
            _ => 2e-3,
        };
        let cfg = DriverConfig {
            integrator: kind,
            policy: StepPolicy::Fixed { h },
            ..Default::default()
        };
        let mut sim = Simulation::new(model.clone(), state.clone(), cfg);
        sim.advance_frame().unwrap();
        let n = allocations_in(&mut sim, 30);
        assert_eq!(n, 0, "{kind}: {n} allocations in 30 frames");
    }
    // A body large enough for the force kernels to cut into chunks (64×64 cloth: six chunks of
    // springs), on two threads.
    let scene = build::cloth(&build::ClothParams::default().resized(64, 64)).unwrap();
    let (model, state) = scene.build().unwrap();
    assert!(model.springs.rows().chunks() > 1);
    let cfg = DriverConfig {
        integrator: IntegratorKind::SymplecticEuler,
        policy: StepPolicy::Fixed { h: 2e-4 },
        ..Default::default()
    };
    let mut sim = Simulation::new(model, state, cfg);
    let n = bevy_soft_body::core::kernels::with_threads(2, move || {
        sim.advance_frame().unwrap();
        allocations_in(&mut sim, 10)
    });
    assert_eq!(
        n, 0,
        "64×64 cloth, chunked kernels: {n} allocations in 10 frames"
    );
    // The implicit solve on the team: linearly implicit Euler on the 64×64 cloth (the
    // multigrid, the packed product, the solver's passes and sums in chunks) and on a 96×96
    // one (the band product, which takes systems of 8192 particles or more), on two threads.
    for size in [64, 96] {
        let scene = build::cloth(&build::ClothParams::default().resized(size, size)).unwrap();
        let (model, state) = scene.build().unwrap();
        let cfg = DriverConfig {
            integrator: IntegratorKind::LinearlyImplicitEuler,
            policy: StepPolicy::Fixed { h: 1.0 / 60.0 },
            frame_dt: 1.0 / 60.0,
            ..Default::default()
        };
        let mut sim = Simulation::new(model, state, cfg);
        let n = bevy_soft_body::core::kernels::with_threads(2, move || {
            sim.advance_frame().unwrap();
            allocations_in(&mut sim, 5)
        });
        assert_eq!(
            n, 0,
            "{size}×{size} cloth, implicit solve on two threads: {n} allocations in 5 frames"
        );
    }
    // A tet body on the ground under the implicit methods: its particles resting there held
    // along the normal with friction (linearly implicit and backward Euler, either solver),
    // or held still (the trapezoid with implicit damping), from scratch the steps own.
    let mesh = TetMesh::tet_box([0.1, 0.05, 0.1], [4, 2, 4]).unwrap();
    let mut scene = mesh.to_scene("block", NeoHookean::default());
    scene.colliders.push(build::ground(0.0, 0.0, 0.5));
    let (model, state) = scene.build().unwrap();
    for (kind, solver, h) in [
        (
            IntegratorKind::LinearlyImplicitEuler,
            SolverChoice::Pcg,
            1.0 / 60.0,
        ),
        (
            IntegratorKind::LinearlyImplicitEuler,
            SolverChoice::Cholesky,
            1.0 / 60.0,
        ),
        (IntegratorKind::BackwardEuler, SolverChoice::Pcg, 1.0 / 60.0),
        (
            IntegratorKind::BackwardEuler,
            SolverChoice::Cholesky,
            1.0 / 60.0,
        ),
        // Its elastic forces explicit: on a block a hundredth as stiff (below).
        (
            IntegratorKind::ImplicitDampingTrapezoid,
            SolverChoice::Pcg,
            2e-4,
        ),
    ] {
        // The trapezoid with implicit damping has no stable step on an undamped mode (its
        // elastic forces are explicit): the rubber block resting on a plane grows out of
        // round-off within 0.4 s even at 1/20000 s, and one of E = 10 kPa within 0.9 s at
        // 2e-4 s; one of E = 1 kPa rests for the second taken here.
        let (model, state) = if kind == IntegratorKind::ImplicitDampingTrapezoid {
            let mut scene = mesh.to_scene(
                "block",
                NeoHookean {
                    young: 1e3,
                    ..Default::default()
                },
            );
            scene.colliders.push(build::ground(0.0, 0.0, 0.5));
            scene.build().unwrap()
        } else {
            (model.clone(), state.clone())
        };
        let cfg = DriverConfig {
            integrator: kind,
            policy: StepPolicy::Fixed { h },
            frame_dt: 1.0 / 60.0,
            solver,
            ..Default::default()
        };
        let mut sim = Simulation::new(model, state, cfg);
        // Landed and resting by then: its holds have been taken.
        for _ in 0..30 {
            sim.advance_frame().unwrap();
        }
        let n = allocations_in(&mut sim, 30);
        assert_eq!(
            n, 0,
            "{kind} ({solver:?}), tets on the ground: {n} allocations in 30 frames"
        );
    }
    // A cloth hung over a rod thinner than its cells: the triangles spanning the rod held at
    // their contact points, those the trial takes in at their corners (their contact in the
    // rod the crate's own, not parry's penetration query, which allocates). Linearly implicit
    // Euler with PCG, backward Euler with PCG and with the Cholesky (modified Newton: the
    // rows' Schur complement on a reused factor too).
    for (integrator, solver) in [
        (IntegratorKind::LinearlyImplicitEuler, SolverChoice::Pcg),
        (IntegratorKind::BackwardEuler, SolverChoice::Pcg),
        (IntegratorKind::BackwardEuler, SolverChoice::Cholesky),
    ] {
        let (model, state) = common::cloth_on_a_rod(0.01, 0.3).build().unwrap();
        let cfg = DriverConfig {
            integrator,
            policy: StepPolicy::Fixed { h: 1.0 / 60.0 },
            solver,
            ..Default::default()
        };
        let mut sim = Simulation::new(model, state, cfg);
        for _ in 0..90 {
            sim.advance_frame().unwrap();
        }
        let n = allocations_in(&mut sim, 30);
        assert_eq!(
            n, 0,
            "{integrator:?} ({solver:?}), a cloth on a thin rod: {n} allocations in 30 frames"
        );
    }
    // The same cloth dropped on a 2 cm bar (a box), twice: the second drop's impact, where
    // the trial solves take triangles into the bar, allocates nothing (the box's penetration
    // is the crate's own separating-axis answer, not parry's penetration query, which
    // allocated 1,771 times in these 30 frames with linearly implicit Euler). The first drop
    // grows the lists.
    for integrator in [
        IntegratorKind::LinearlyImplicitEuler,
        IntegratorKind::BackwardEuler,
    ] {
        let mut scene = common::cloth_on_a_rod(0.01, 0.3);
        scene.colliders[1].shape = ShapeDesc::Cuboid {
            half_extents: [0.01, 0.01, 0.8],
        };
        scene.colliders[1].rotation = [0.0, 0.0, 0.0, 1.0];
        let (model, state) = scene.build().unwrap();
        let start = state.clone();
        let cfg = DriverConfig {
            integrator,
            policy: StepPolicy::Fixed { h: 1.0 / 60.0 },
            solver: SolverChoice::Pcg,
            ..Default::default()
        };
        let mut sim = Simulation::new(model, state, cfg);
        for _ in 0..60 {
            sim.advance_frame().unwrap();
        }
        sim.state = start;
        for _ in 0..10 {
            sim.advance_frame().unwrap();
        }
        let n = allocations_in(&mut sim, 30);
        assert_eq!(
            n, 0,
            "{integrator:?}, a cloth dropped on a 2 cm bar: {n} allocations in 30 frames"
        );
    }
    // The rows, their factors, the friction's fit of the contact forces and the constrained
    // solve, with either preconditioner, on their own.
    let mut scene = build::cloth(&build::ClothParams {
        rows: 16,
        cols: 16,
        ..Default::default()
    })
    .unwrap();
    scene.gravity = [0.0, -9.81, 0.0];
    let (model, state) = scene.build().unwrap();
    let n = state.len();
    let mut a = model.new_matrix();
    let mut kv = vec![Vector::ZERO; n];
    model.assemble(&state, 1.0 / 60.0, true, &mut a, &mut kv);
    let mut mask = vec![0.0; n];
    model.free_mask(&mut mask);
    let mut f = vec![Vector::ZERO; n];
    model.total_forces(0.0, &state, &mut f);
    let b: Vec<Vector> = f.iter().map(|f| *f * (1.0 / 60.0)).collect();
    let mut holds = NormalHolds::default();
    let up = Vector::new(0.0, 1.0, 0.0);
    for row in 4..12u32 {
        let ids = [16 * row + 7, 16 * row + 8, 16 * (row + 1) + 7];
        holds.faces.push(FaceHold {
            ids,
            weights: [0.3, 0.5, 0.2],
            free: ids.map(|i| mask[i as usize] != 0.0),
            normal: up,
            velocity: Vector::ZERO,
            friction: 0.5,
        });
    }
    holds.raw.push((16 * 5 + 3, up, Vector::ZERO, 0.5));
    for pre in [Preconditioner::BlockJacobi, Preconditioner::Multigrid] {
        let mut pcg = Pcg::new(1e-6, 200).with_preconditioner(pre);
        let mut x = vec![Vector::ZERO; n];
        let mut round = |holds: &mut NormalHolds, x: &mut Vec<Vector>| {
            holds.start_friction(|i| f[i]);
            holds.settle(Some(&state.v), x);
            pcg.solve_constrained(&a, &b, x, &mask, &holds.filters, &mut holds.rows)
        };
        assert!(round(&mut holds, &mut x).converged);
        let before = ALLOCS.load(Ordering::Relaxed);
        for _ in 0..5 {
            assert!(round(&mut holds, &mut x).converged);
        }
        let n = ALLOCS.load(Ordering::Relaxed) - before;
        assert_eq!(
            n, 0,
            "{pre:?}: rows and the constrained solve: {n} allocations"
        );
    }
    // Self-collision: a 16² cloth of the pile, on the sphere and the ground; its passes reuse
    // their buffers once they have held the largest candidate set for 2 s (the cloth slides
    // off the sphere and folds for several seconds, each fold a larger set: by 2.8 s in
    // `f32`, by 5.9 s in `f64`). With short steps, and with frame-long ones (a pass a frame,
    // each with its own search).
    let p = build::ClothPileParams {
        cloths: 1,
        ..Default::default()
    }
    .with_resolution(16);
    for (integrator, h) in [
        (IntegratorKind::SymplecticEuler, p.stable_step()),
        (IntegratorKind::LinearlyImplicitEuler, 1.0 / 60.0),
    ] {
        let (model, state) = build::cloth_pile(&p).unwrap().build().unwrap();
        let cfg = DriverConfig {
            integrator,
            policy: StepPolicy::Fixed { h },
            ..Default::default()
        };
        let mut sim = Simulation::new(model, state, cfg);
        let (mut largest, mut since) = (0, 0);
        for _ in 0..1200 {
            sim.advance_frame().unwrap();
            let c = sim.system.self_contact.as_ref().unwrap().last.candidates;
            (largest, since) = if c > largest {
                (c, 0)
            } else {
                (largest, since + 1)
            };
            if since == 120 {
                break;
            }
        }
        assert_eq!(
            since, 120,
            "{integrator:?}: the pile's candidates still grow after 20 s"
        );
        let n = allocations_in(&mut sim, 30);
        let total = sim.system.self_contact.as_ref().unwrap().total;
        assert!(total.passes_run > 30, "{total:?}");
        assert_eq!(
            n, 0,
            "{integrator:?}: self-collision: {n} allocations in 30 frames"
        );
    }
}
