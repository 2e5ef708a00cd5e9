//! The team of threads and the kernels that write through raw pointers, small enough for Miri:
//! the fused symplectic Euler step (a force chunk's phase and the gathers' phase of one pass,
//! on a banded cloth, a tet box and both in one model), the spring rows on a random network, a
//! linearly implicit Euler step (the matrix product and the solve on the team), and a
//! self-colliding cloth's first passes (the cone bits and the colliders in chunks). Each
//! compares one thread with two and three, bit for bit. Under Miri the library cuts its passes
//! into smaller chunks (`cfg(miri)`) and the bodies here are smaller, so every body still makes
//! several chunks; outside Miri they are sized for the chunks of a normal build.
//!
//! Miri gives the float functions whose precision Rust leaves unspecified (`powf`, `sin`,
//! `cos`, …) results that vary by a few units of round-off from call to call, so each test
//! makes its scene and step once and hands the same values to every thread count (a pile's
//! scene and step, made in each run, made one and two threads differ in the f64 build).
use bevy_soft_body::core::build::{ClothPileParams, cloth_pile};
use bevy_soft_body::core::fem::NeoHookean;
use bevy_soft_body::core::fem::mesh::TetMesh;
use bevy_soft_body::core::forces::{SpringLaw, Springs};
use bevy_soft_body::core::integrate::{Integrator, LinearlyImplicitEuler};
use bevy_soft_body::core::kernels::{self, springs, tets};
use bevy_soft_body::core::ode::{OdeSystem, ParticleState};
use bevy_soft_body::core::scene::Scene;
use bevy_soft_body::math::{Scalar, Vector, VectorExt};
use bevy_soft_body::prelude::*;

/// Chooses the size for Miri or for a normal build.
fn sized(miri: usize, native: usize) -> usize {
    if cfg!(miri) { miri } else { native }
}

/// xorshift 13/7/17, as the main tests' generator.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn below(&mut self, n: usize) -> usize {
        (self.unit() * n as f64) as usize % n
    }
    fn vector(&mut self) -> Vector {
        Vector::new(
            self.unit() as Scalar,
            self.unit() as Scalar,
            self.unit() as Scalar,
        )
    }
}

fn bits(s: &ParticleState) -> Vec<[f64; 3]> {
    s.x.iter().chain(&s.v).map(|v| v.to_f64()).collect()
}

/// A cloth of `n × n` particles: two or three chunks of the springs' kernel.
fn cloth(n: usize) -> Scene {
    let scene = build::cloth(&build::ClothParams::default().resized(n, n)).unwrap();
    assert!(n * n > springs::CHUNK_PARTICLES, "one chunk only");
    assert!(
        n * n <= 3 * springs::CHUNK_PARTICLES,
        "larger than it needs to be"
    );
    scene
}

/// A tet box of `cells³` cells standing on its pinned `x = 0` face.
fn tet_box(cells: usize) -> Scene {
    let mesh = TetMesh::tet_box([0.1, 0.1, 0.1], [cells, cells, cells]).unwrap();
    assert!(
        mesh.vertices.len() > 2 * tets::CHUNK_PARTICLES,
        "too few chunks"
    );
    let mut block = mesh.to_scene("box", NeoHookean::default());
    block.gravity = [0.0, 0.0, -9.81];
    for p in block.particles.iter_mut() {
        p.pinned = p.position[0] == 0.0;
    }
    block
}

/// `n` fused symplectic Euler steps of `scene` on `threads` threads.
fn fused_steps(scene: &Scene, threads: usize, n: usize) -> Vec<[f64; 3]> {
    let (model, state) = scene.build().unwrap();
    let (mut a, mut scratch) = (state.clone(), state);
    let h = 1e-4 as Scalar;
    kernels::with_threads(threads, || {
        for k in 0..n {
            let t = k as Scalar * h;
            model.apply_constraints(t, &mut a);
            assert!(model.symplectic_euler(t, h, &mut a, &mut scratch));
        }
    });
    bits(&a)
}

#[test]
fn fused_steps_are_the_same_bits_on_one_two_and_three_threads() {
    // A banded cloth (Miri 12²: three chunks of springs; otherwise 36²: two), a tet box (4³
    // cells: four chunks; 7³: four), and both in one model (two kernels, one pass each).
    let (cloth, block) = (cloth(sized(12, 36)), tet_box(sized(4, 7)));
    let both = block.clone().append(cloth.clone());
    for scene in [cloth, block, both] {
        let one = fused_steps(&scene, 1, 2);
        for threads in [2, 3] {
            assert!(
                one == fused_steps(&scene, threads, 2),
                "{}, {threads} threads",
                scene.name
            );
        }
    }
}

#[test]
fn spring_rows_and_tets_are_the_same_bits_on_one_and_two_threads() {
    // A random network (springs in rows, not bands), most springs between near indices and
    // one in ten between any two, as in the main tests.
    let mut r = Rng(7);
    let n = sized(300, 2500);
    let x: Vec<Vector> = (0..n).map(|_| r.vector()).collect();
    let v: Vec<Vector> = (0..n).map(|_| r.vector()).collect();
    let mut s = Springs::new();
    for k in 0..2 * n {
        let i = r.below(n);
        let j = if k % 10 == 0 {
            r.below(n)
        } else {
            (i + 1 + r.below(40)).min(n - 1)
        };
        let law = if k % 3 == 0 {
            SpringLaw::Strain
        } else {
            SpringLaw::Hooke
        };
        s.push(i, j, 0.1, 100.0, 0.3, law);
    }
    let (model, state) = tet_box(sized(4, 7)).build().unwrap();
    let tets = &model.tets;
    let run = |threads| {
        kernels::with_threads(threads, || {
            let mut f = vec![Vector::ZERO; n];
            s.accumulate(&x, &v, &mut f);
            let mut g = vec![Vector::ZERO; state.x.len()];
            tets.accumulate(&state.x, &mut g);
            let e = (
                s.energy_fast(&x).to_bits(),
                tets.energy_fast(&state.x).to_bits(),
            );
            let as_bits = |a: &[Vector]| a.iter().map(|v| v.to_f64()).collect::<Vec<_>>();
            (as_bits(&f), as_bits(&g), e)
        })
    };
    assert!(run(1) == run(2));
}

#[test]
fn an_implicit_step_is_the_same_bits_on_one_and_two_threads() {
    let scene = cloth(sized(12, 36));
    let run = |threads| {
        kernels::with_threads(threads, || {
            let (model, mut st) = scene.build().unwrap();
            let mut integ = LinearlyImplicitEuler::default();
            integ.step(&model, 0.0, 1.0 / 60.0, &mut st).unwrap();
            bits(&st)
        })
    };
    assert!(run(1) == run(2));
}

#[test]
fn a_self_colliding_cloth_is_the_same_bits_on_one_and_two_threads() {
    // One cloth falling onto the sphere (Miri 12²: 242 triangles, four chunks of cone bits,
    // and three chunks of collider responses; otherwise 32²: two and two), a few steps with a
    // pass at each.
    let p = ClothPileParams::default().with_resolution(sized(12, 32));
    let (scene, h) = (cloth_pile(&p).unwrap(), p.stable_step());
    let run = |threads| {
        let (model, state) = scene.build().unwrap();
        let config = DriverConfig {
            integrator: IntegratorKind::SymplecticEuler,
            policy: StepPolicy::Fixed { h },
            frame_dt: h,
            ..Default::default()
        };
        let mut sim = Simulation::new(model, state, config);
        kernels::with_threads(threads, || sim.run(3, |_, _| {})).unwrap();
        assert!(sim.system.self_contact.as_ref().unwrap().total.passes_run >= 3);
        bits(&sim.state)
    };
    assert!(run(1) == run(2));
}
