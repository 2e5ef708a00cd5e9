//! The fast force kernels against the simple references they replace, and the same bits on
//! any number of threads.
//!
//! Round-off bounds: a particle's force is a sum of `m` terms, each computed with a few
//! roundings; reordering the sum and the terms' operations changes the result by at most about
//! `c · m · u · S`, with `u` the unit round-off and `S` the sum of the terms' magnitudes. The
//! tests use `64 u S` (springs: terms of 5–10 roundings, each particle in about 13 springs
//! here; tets: about 60 roundings per force, with `F` from edge vectors, which are exact in
//! floating point for nearby particles), plus, for tets, the f64 reference's own round-off.

#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::fem::element::{DVec3, element_forces};
use bevy_soft_body::core::fem::mesh::TetMesh;
use bevy_soft_body::core::fem::{NeoHookean, Tets};
use bevy_soft_body::core::forces::{SpringLaw, Springs};
use bevy_soft_body::math::{EPS, Scalar, ToScalar, Vector, VectorExt};

mod common;
use common::Rng;

/// A vector with entries uniform in [−s, s).
fn random_vec(r: &mut Rng, s: f64) -> Vector {
    Vector::new(
        (s * (2.0 * r.unit() - 1.0)) as Scalar,
        (s * (2.0 * r.unit() - 1.0)) as Scalar,
        (s * (2.0 * r.unit() - 1.0)) as Scalar,
    )
}

/// A random network: `n` particles in a 1 m box moving at up to 1 m/s, `m` springs, most
/// between near indices (as meshes are) and some between any two; duplicates, self springs,
/// zero-length springs (two particles on one spot) and both laws; damped when `damped`.
fn network(seed: u64, n: usize, m: usize, damped: bool) -> (Springs, Vec<Vector>, Vec<Vector>) {
    let mut r = Rng(seed);
    let mut x: Vec<Vector> = (0..n).map(|_| random_vec(&mut r, 1.0)).collect();
    x[1] = x[0];
    let v: Vec<Vector> = (0..n).map(|_| random_vec(&mut r, 1.0)).collect();
    let mut s = Springs::new();
    s.push(0, 1, 0.1, 50.0, 0.2, SpringLaw::Hooke);
    s.push(2, 2, 0.1, 50.0, 0.2, SpringLaw::Hooke);
    for k in 0..m {
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
        let damping = if damped { 0.5 * r.unit() } else { 0.0 };
        let (rest, k) = (
            (0.05 + r.unit()) as Scalar,
            (10.0 + 1000.0 * r.unit()) as Scalar,
        );
        s.push(i, j, rest, k, damping as Scalar, law);
    }
    (s, x, v)
}

/// Per particle, the sum of the magnitudes of the spring forces on it (f64).
fn spring_scale(s: &Springs, x: &[Vector], v: &[Vector]) -> Vec<f64> {
    let mut scale = vec![0.0; x.len()];
    for sp in s.as_slice() {
        let d = DVec3::from_array((x[sp.i as usize] - x[sp.j as usize]).to_f64());
        let w = DVec3::from_array((v[sp.i as usize] - v[sp.j as usize]).to_f64());
        let l = d.length();
        let mag = sp.k as f64 * (l - sp.rest as f64).abs() + sp.damping as f64 * w.length();
        scale[sp.i as usize] += mag;
        scale[sp.j as usize] += mag;
    }
    scale
}

fn worst(a: &[Vector], b: &[Vector], scale: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .zip(scale)
        .map(|((a, b), s)| (*a - *b).length() as f64 / s.max(1e-30))
        .fold(0.0, f64::max)
}

#[test]
fn row_kernel_equals_the_reference_to_round_off() {
    for (seed, damped) in [(1, false), (2, true), (3, true)] {
        // 3000 particles: three chunks of both passes (20,000 springs).
        let (s, x, v) = network(seed, 3000, 20_000, damped);
        assert!(s.rows().chunks() >= 3, "{} chunks", s.rows().chunks());
        forces_match_the_reference(&s, &x, &v, damped);
    }
}

/// The fast kernel's forces (all, and the elastic part alone that implicit methods take)
/// against the one-loop reference, within `64 u S`; returns the forces.
fn forces_match_the_reference(
    s: &Springs,
    x: &[Vector],
    v: &[Vector],
    damped: bool,
) -> Vec<Vector> {
    let mut fast = vec![Vector::ZERO; x.len()];
    let mut reference = fast.clone();
    s.accumulate(x, v, &mut fast);
    s.accumulate_reference(x, v, &mut reference);
    let err = worst(&fast, &reference, &spring_scale(s, x, v));
    println!("damped {damped}: worst |fast − reference| / S = {err:.2e}");
    assert!(err <= 64.0 * EPS as f64, "{err:e}");
    let mut elastic = vec![Vector::ZERO; x.len()];
    s.accumulate_elastic(x, &mut elastic);
    let mut undamped = s.clone();
    for sp in undamped.as_mut_slice() {
        sp.damping = 0.0;
    }
    undamped.refresh();
    let mut reference = vec![Vector::ZERO; x.len()];
    undamped.accumulate_reference(x, v, &mut reference);
    let err = worst(&elastic, &reference, &spring_scale(&undamped, x, v));
    assert!(err <= 64.0 * EPS as f64, "elastic: {err:e}");
    fast
}

/// A structured cloth: a `w × h` grid (2 cm, jittered by up to 5 mm, moving at up to 1 m/s)
/// with its structural (offsets 1 and `w`), shear (`w ± 1`) and bending (2 and `2w`) springs,
/// each pushed in either orientation with its own rest length, stiffness and damping (both
/// laws); one in ten left out (holes the bands pad with springs of zero stiffness), one in
/// fifty pushed twice (the second stays in rows), and a few long springs and a self spring that
/// only rows can take; two particles on one spot (a zero-length spring in a band).
fn grid_network(
    seed: u64,
    w: usize,
    h: usize,
    damped: bool,
) -> (Springs, Vec<Vector>, Vec<Vector>) {
    let mut r = Rng(seed);
    let n = w * h;
    let mut x: Vec<Vector> = (0..n)
        .map(|p| {
            let at = Vector::new((p % w) as Scalar * 0.02, (p / w) as Scalar * 0.02, 0.0);
            at + random_vec(&mut r, 0.005)
        })
        .collect();
    x[w + 1] = x[w];
    let v: Vec<Vector> = (0..n).map(|_| random_vec(&mut r, 1.0)).collect();
    let mut s = Springs::new();
    let add = |r: &mut Rng, s: &mut Springs, i: usize, j: usize| {
        let (i, j) = if r.unit() < 0.5 { (i, j) } else { (j, i) };
        let law = if r.unit() < 0.3 {
            SpringLaw::Strain
        } else {
            SpringLaw::Hooke
        };
        let damping = if damped { 0.5 * r.unit() } else { 0.0 };
        let (rest, k) = (
            (0.01 + 0.03 * r.unit()) as Scalar,
            (10.0 + 1000.0 * r.unit()) as Scalar,
        );
        s.push(i, j, rest, k, damping as Scalar, law);
    };
    for p in 0..n {
        let (c, row) = (p % w, p / w);
        let mut pairs = vec![];
        if c + 1 < w {
            pairs.push(p + 1);
        }
        if c + 2 < w {
            pairs.push(p + 2);
        }
        if row + 1 < h {
            pairs.push(p + w);
            if c + 1 < w {
                pairs.push(p + w + 1);
            }
            if c > 0 {
                pairs.push(p + w - 1);
            }
        }
        if row + 2 < h {
            pairs.push(p + 2 * w);
        }
        for q in pairs {
            if r.unit() < 0.1 {
                continue;
            }
            add(&mut r, &mut s, p, q);
            if r.unit() < 0.02 {
                add(&mut r, &mut s, p, q);
            }
        }
    }
    for _ in 0..100 {
        let (i, j) = (r.below(n), r.below(n));
        add(&mut r, &mut s, i, j);
    }
    s.push(5, 5, 0.1, 50.0, 0.2, SpringLaw::Hooke);
    (s, x, v)
}

/// The band kernel (springs of a structured mesh by offset, in columns) together with the
/// rows it leaves the rest to, against the one-loop reference; its energy against an f64 sum;
/// and the same bits on one, two and three threads.
#[test]
fn band_kernel_equals_the_reference_to_round_off() {
    for (seed, damped) in [(21, false), (22, true)] {
        // 60×60: four chunks of both passes.
        let (s, x, v) = grid_network(seed, 60, 60, damped);
        let (all, banded) = (s.as_slice().len(), s.rows().in_bands());
        println!("{banded} of {all} springs in bands");
        assert!(
            banded > 9 * all / 10 && banded < all,
            "{banded} of {all} in bands"
        );
        assert!(s.rows().chunks() >= 3);
        let fast = forces_match_the_reference(&s, &x, &v, damped);
        // Added into what `f` held, as the other forces are.
        let mut twice = fast.clone();
        s.accumulate(&x, &v, &mut twice);
        let doubled: Vec<Vector> = fast.iter().map(|f| *f * 2.0).collect();
        let err = worst(&twice, &doubled, &spring_scale(&s, &x, &v));
        assert!(err <= 64.0 * EPS as f64, "accumulated: {err:e}");
        // The energy the divergence guard reads, bands included (bound as in the row
        // kernel's energy test).
        let (exact, bound) = spring_energy_f64(&s, &x);
        let energy = s.energy_fast(&x);
        assert!((energy - exact).abs() <= bound, "{energy} against {exact}");
        #[cfg(feature = "parallel")]
        {
            use bevy_soft_body::core::kernels;
            let bits = |a: &[Vector]| a.iter().map(|v| v.to_f64()).collect::<Vec<_>>();
            for threads in [2, 3] {
                let (f, e) = kernels::with_threads(threads, || {
                    let mut f = vec![Vector::ZERO; x.len()];
                    s.accumulate(&x, &v, &mut f);
                    (f, s.energy_fast(&x))
                });
                assert_eq!(bits(&fast), bits(&f), "{threads} threads");
                assert_eq!(energy.to_bits(), e.to_bits(), "{threads} threads");
            }
        }
    }
}

#[test]
fn row_kernel_survives_edits_and_small_bodies() {
    // One spring; then edits after the layout was built must be seen.
    let mut s = Springs::new();
    s.push(1, 0, 1.0, 10.0, 0.0, SpringLaw::Hooke);
    let x = vec![Vector::ZERO, Vector::X * 2.0];
    let v = vec![Vector::ZERO; 2];
    let mut f = vec![Vector::ZERO; 2];
    s.accumulate(&x, &v, &mut f);
    // d = x1 − x0 = (2, 0, 0): f1 = −10 (2 − 1) d/|d| = (−10, 0, 0).
    assert_eq!(f, vec![Vector::X * 10.0, -Vector::X * 10.0]);
    s.as_mut_slice()[0].k = 20.0;
    f.fill(Vector::ZERO);
    s.accumulate(&x, &v, &mut f);
    assert_eq!(f[0], Vector::X * 20.0);
    s.push(0, 1, 3.0, 20.0, 0.0, SpringLaw::Hooke);
    f.fill(Vector::ZERO);
    s.accumulate(&x, &v, &mut f);
    // The second spring is compressed by 1 m: it pushes back with 20 N, cancelling the first.
    assert_eq!(f[0], Vector::ZERO);
}

/// A 10×10×10-cell box (6000 tets) deformed at random, with a few elements pushed flat or
/// inverted, as an explicit step or a drag can leave them.
fn deformed_box(seed: u64) -> (Tets, Vec<Vector>) {
    box_with(seed, 20)
}

/// The box of [`deformed_box`] with `wild` particles moved onto others.
fn box_with(seed: u64, wild: usize) -> (Tets, Vec<Vector>) {
    let mesh = TetMesh::tet_box([0.1, 0.1, 0.1], [10, 10, 10]).unwrap();
    let material = NeoHookean {
        young: 1e5,
        poisson: 0.4,
        density: 1000.0,
    };
    let mut tets = Tets::new();
    for t in &mesh.tets {
        let rest = t.map(|i| DVec3::from_array(mesh.vertices[i as usize]));
        tets.push(t.map(|i| i as usize), rest, &material).unwrap();
    }
    let mut r = Rng(seed);
    let mut x: Vec<Vector> = mesh
        .vertices
        .iter()
        .map(|p| p.to_scalar() + Vector::new(1.0, -2.0, 0.5))
        .collect();
    for xi in x.iter_mut() {
        *xi += random_vec(&mut r, 0.003);
    }
    for k in 0..wild {
        let i = r.below(x.len());
        x[i] = x[(i + 1 + k) % x.len()];
    }
    (tets, x)
}

#[test]
fn tet_kernel_equals_the_f64_reference_to_round_off() {
    let (tets, x) = deformed_box(7);
    let mut fast = vec![Vector::ZERO; x.len()];
    let mut reference = fast.clone();
    tets.accumulate(&x, &mut fast);
    tets.accumulate_f64(&x, &mut reference);
    assert!(
        tets.inverted(&x) > 0,
        "the test must include inverted elements"
    );
    // S per particle: Σ over its elements of |element force on it| (f64), plus the stress
    // scale `2(C + D) |g| V` per element, which bounds the round-off of P near rest.
    let mut scale = vec![0.0; x.len()];
    for t in tets.as_slice() {
        let xs = t.v.map(|i| DVec3::from_array(x[i as usize].to_f64()));
        let fe = element_forces(&t.material, &t.rest, xs);
        let stress = 2.0 * (t.material.c + t.material.d) * t.rest.volume;
        for a in 0..4 {
            scale[t.v[a] as usize] += fe[a].length() + stress * t.rest.grad[a].length();
        }
    }
    let err = worst(&fast, &reference, &scale);
    // The reference forms F from absolute positions (|x| up to 2.3 m, edges of 1 cm): its own
    // round-off is about u_f64 · |x|/ℓ = 230 u_f64 larger, visible in the f64 build only.
    let amplification = 2.3 / 0.01;
    let bound = 64.0 * EPS as f64 + 64.0 * f64::EPSILON * amplification;
    println!("worst |fast − reference| / S = {err:.2e} (bound {bound:.1e})");
    assert!(err <= bound, "{err:e}");
}

/// The tets' energy from the fast kernel's layout (the divergence guard's), against the f64
/// reference: each element's `ψ = C (J^(−2/3) I₁ − 3) + D (J − 1)²` to a few dozen roundings of
/// its terms' magnitudes, `J`'s own round-off being `u |f_a| |f_b| |f_c|` (Hadamard's bound)
/// times `2 D |J − 1|` and the isochoric term's sensitivity to it. On the box deformed by 3 mm
/// per particle that scale is about ten times the energy itself, so an error of the energy's
/// size fails by four orders; with the flattened and inverted elements too it still holds.
#[test]
fn tet_energy_equals_the_f64_reference_to_round_off() {
    for wild in [0, 20] {
        let (tets, x) = box_with(7, wild);
        let mut scale = 0.0;
        for t in tets.as_slice() {
            let xs = t.v.map(|i| DVec3::from_array(x[i as usize].to_f64()));
            let f = t.rest.deformation_gradient(xs);
            let (j, c, d) = (f.determinant(), t.material.c, t.material.d);
            let i1 =
                f.x_axis.length_squared() + f.y_axis.length_squared() + f.z_axis.length_squared();
            let a23 = j.max(0.1).powf(-2.0 / 3.0);
            let hadamard = f.x_axis.length() * f.y_axis.length() * f.z_axis.length();
            let sensitivity = 2.0 * d * (j - 1.0).abs() + c * a23 * i1 / j.max(0.1);
            scale += t.rest.volume
                * (c * (a23 * i1 + 3.0) + d * (j - 1.0).powi(2) + sensitivity * hadamard);
        }
        let (fast, reference) = (tets.energy_fast(&x), tets.energy(&x));
        let err = (fast - reference).abs() / scale;
        let bound = 64.0 * EPS as f64 + 64.0 * f64::EPSILON * 2.3 / 0.01;
        println!(
            "{wild} wild particles: fast {fast:.9e} J, reference {reference:.9e} J, \
             scale {scale:.3e} J, |difference| / scale = {err:.2e} (bound {bound:.1e})"
        );
        assert!(err <= bound, "{err:e}");
        assert!(
            wild > 0 || scale < 20.0 * reference,
            "the scale must stay near the energy"
        );
    }
}

/// The springs' elastic energy summed in f64 from f64 positions, and its round-off bound for
/// the kernel's sum (see [`spring_energy_equals_the_f64_sum_to_round_off`]). A spring from a
/// particle to itself exerts nothing and stores nothing the motion can change: the kernel
/// leaves it out (the reference `energy` counts its constant ½ k L²), and so does this.
fn spring_energy_f64(s: &Springs, x: &[Vector]) -> (f64, f64) {
    let (mut exact, mut bound) = (0.0f64, 0.0f64);
    for sp in s.as_slice().iter().filter(|sp| sp.i != sp.j) {
        let (xi, xj) = (x[sp.i as usize].to_f64(), x[sp.j as usize].to_f64());
        let l = DVec3::from_array(xi).distance(DVec3::from_array(xj));
        let (k, rest) = (sp.k as f64, sp.rest as f64);
        let e = l - rest;
        exact += 0.5 * k * e * e;
        bound += 4.0 * EPS as f64 * (k * e.abs() * (l + rest) + 0.5 * k * e * e);
    }
    (exact, bound)
}

/// The springs' energy from the fast kernel (each spring's in the build's precision, summed in
/// f64 by chunk) against the same sum in f64 from f64 positions. A spring's term `½ k e²` with
/// `e = l − L` carries the error of `l` and of the subtraction, about `(l + L)·EPS` in `e`, so
/// `k |e| (l + L)·EPS` in the term, plus a few roundings of the term itself: the bound is four
/// times that, summed. Networks of 3000 particles (three chunks) and 300 (one), with
/// zero-length and self springs.
#[test]
fn spring_energy_equals_the_f64_sum_to_round_off() {
    for (seed, n, m) in [(11, 3000, 20_000), (12, 300, 2000)] {
        let (s, x, _) = network(seed, n, m, false);
        let (exact, bound) = spring_energy_f64(&s, &x);
        let fast = s.energy_fast(&x);
        println!(
            "{n} particles: fast {fast:.9e} J, f64 {exact:.9e} J, |difference| {:.2e} (bound {bound:.2e})",
            (fast - exact).abs()
        );
        assert!((fast - exact).abs() <= bound, "{fast} against {exact}");
        assert!(
            bound < 1e-3 * exact,
            "the bound must be round-off, not the energy"
        );
    }
}

#[cfg(feature = "parallel")]
#[test]
fn kernels_give_the_same_bits_on_one_and_two_threads() {
    use bevy_soft_body::core::kernels;
    let (s, x, v) = network(4, 3000, 20_000, true);
    let (tets, xt) = deformed_box(8);
    let run = |threads| {
        kernels::with_threads(threads, || {
            assert_eq!(kernels::current_threads(), threads);
            let mut f = vec![Vector::ZERO; x.len()];
            s.accumulate(&x, &v, &mut f);
            let mut g = vec![Vector::ZERO; xt.len()];
            tets.accumulate(&xt, &mut g);
            // The divergence guard's sums, by chunk on the team.
            let e = (s.energy_fast(&x).to_bits(), tets.energy_fast(&xt).to_bits());
            (f, g, e)
        })
    };
    let bits = |a: &[Vector]| a.iter().map(|v| v.to_f64()).collect::<Vec<_>>();
    let (f1, g1, e1) = run(1);
    // Two threads, and three on the machine's two cores (helpers descheduled mid-pass, their
    // shares taken by the others).
    for threads in [2, 3] {
        let (f2, g2, e2) = run(threads);
        assert_eq!(bits(&f1), bits(&f2), "{threads} threads");
        assert_eq!(bits(&g1), bits(&g2), "{threads} threads");
        assert_eq!(e1, e2, "{threads} threads");
    }
}

/// The bench cloth (64×64, six chunks of springs) and a 6000-tet box through the whole driver:
/// 200 symplectic Euler steps on one and on two threads end in the same bits.
#[cfg(feature = "parallel")]
#[test]
fn a_simulation_is_the_same_bits_on_one_and_two_threads() {
    use bevy_soft_body::core::kernels;
    use bevy_soft_body::prelude::*;
    let cloth = build::cloth(&build::ClothParams::default().resized(64, 64)).unwrap();
    for (scene, h) in [(cloth, 2e-4), (box_scene(), 2e-4)] {
        let run = |threads| {
            kernels::with_threads(threads, || {
                let (model, state) = scene.build().unwrap();
                let cfg = DriverConfig {
                    integrator: IntegratorKind::SymplecticEuler,
                    policy: StepPolicy::Fixed { h },
                    frame_dt: 0.01,
                    ..Default::default()
                };
                let mut sim = Simulation::new(model, state, cfg);
                sim.run(4, |_, _| {}).unwrap();
                sim.state
            })
        };
        let bits = |s: &ParticleState| {
            s.x.iter()
                .chain(&s.v)
                .map(|v| v.to_f64())
                .collect::<Vec<_>>()
        };
        let a = run(1);
        for threads in [2, 3] {
            assert_eq!(
                bits(&a),
                bits(&run(threads)),
                "{}, {threads} threads",
                scene.name
            );
        }
    }
}

/// The tet kernel's `x^(−1/3)` against the library's `1/∛x` over the range it is used on
/// (`J ≥ J_MIN = 0.1`, up to 10⁶): within 4 units of round-off.
#[test]
fn inverse_cube_root_is_accurate() {
    use bevy_soft_body::core::kernels::tets::inv_cbrt;
    let mut worst: f64 = 0.0;
    let mut x = 0.1f64;
    while x < 1e6 {
        let fast = inv_cbrt(x as Scalar) as f64;
        let exact = 1.0 / (x as Scalar as f64).cbrt();
        worst = worst.max((fast - exact).abs() / exact);
        x *= 1.0001;
    }
    println!("worst relative error {worst:.2e}");
    assert!(worst <= 4.0 * EPS as f64, "{worst:e}");
}

/// A 1000-particle tet box (`TetMesh::tet_box`, 10 cells a side) standing on its pinned
/// `x = 0` face, under gravity, as a scene.
fn box_scene() -> bevy_soft_body::core::scene::Scene {
    let mesh = TetMesh::tet_box([0.1, 0.1, 0.1], [10, 10, 10]).unwrap();
    let mut block = mesh.to_scene("box", NeoHookean::default());
    block.gravity = [0.0, 0.0, -9.81];
    for p in block.particles.iter_mut() {
        p.pinned = p.position[0] == 0.0;
    }
    block
}

/// The particle model's symplectic Euler step is `derivative` then `kick_drift`, bit for bit,
/// over 200 steps on two and three threads (with `parallel`): in one pass after the force
/// kernel's (springs or tets alone) on the PhysBAM wire (strain springs, dampers, a prescribed
/// rotating end), a cloth with wind, drag, an external force and pins, a 48² cloth cut into
/// three chunks with a free particle after it that no spring reaches (the pass's tail past
/// the kernel's particles), and the tet box, alone and with such a particle; in separate passes on the cloth and the box in
/// one model (two kernels).
#[test]
fn fused_symplectic_euler_is_derivative_then_kick_drift() {
    use bevy_soft_body::core::ode::{OdeState, OdeSystem, ParticleState};
    use bevy_soft_body::core::scene::ParticleDesc;
    use bevy_soft_body::prelude::*;
    let mut cloth = build::cloth(&build::ClothParams::default()).unwrap();
    cloth.wind = Some(Wind::default());
    cloth.drag = 0.01;
    cloth.forces.push(bevy_soft_body::core::scene::ForceDesc {
        particle: 5,
        force: [0.1, 0.2, -0.3],
    });
    let mut large = build::cloth(&build::ClothParams::default().resized(48, 48)).unwrap();
    large.surface = None;
    large.particles.push(ParticleDesc {
        position: [0.3, 0.2, 1.0],
        velocity: [0.5, 0.0, 0.0],
        mass: 0.01,
        pinned: false,
    });
    let mut boxed = box_scene();
    boxed.particles.push(ParticleDesc {
        position: [0.3, 0.2, 1.0],
        velocity: [0.5, 0.0, 0.0],
        mass: 0.01,
        pinned: false,
    });
    let both = box_scene().append(cloth.clone());
    let scenes = [
        build::wire(11, 0.05, 100).unwrap(),
        cloth,
        large,
        box_scene(),
        boxed,
        both,
    ];
    for (scene, threads) in scenes.into_iter().flat_map(|s| [(s.clone(), 2), (s, 3)]) {
        let (model, state) = scene.build().unwrap();
        let (mut a, mut b) = (state.clone(), state.clone());
        let (mut scratch, mut d) = (state.clone(), state.clone());
        let h = 1e-4 as Scalar;
        let bits = |s: &ParticleState| {
            s.x.iter()
                .chain(&s.v)
                .map(|v| v.to_f64())
                .collect::<Vec<_>>()
        };
        for k in 0..200 {
            let t = k as Scalar * h;
            model.apply_constraints(t, &mut a);
            model.apply_constraints(t, &mut b);
            let fused = || model.symplectic_euler(t, h, &mut a, &mut scratch);
            assert!(bevy_soft_body::core::kernels::with_threads(threads, fused));
            model.derivative(t, &b, &mut d);
            b.kick_drift(&d, h);
            assert_eq!(
                bits(&a),
                bits(&b),
                "{} step {k}, {threads} threads",
                scene.name
            );
        }
    }
}

/// A state that turns non-finite in a step is refused at that step, not only at the frame's
/// end, although the symplectic Euler step checks what it writes and the driver then skips
/// its own pass over the state: a NaN velocity in the middle of a 32² cloth, in its last
/// particle, in a free particle past the springs' particles, and in the middle of the tet box;
/// on one thread and on two. (The divergence's time is the step's start: 0.)
#[test]
fn a_step_that_turns_non_finite_is_refused_at_that_step() {
    use bevy_soft_body::core::driver::DivergenceReason;
    use bevy_soft_body::core::scene::ParticleDesc;
    use bevy_soft_body::prelude::*;
    let cloth = build::cloth(&build::ClothParams::default().resized(32, 32)).unwrap();
    let mut tail = cloth.clone();
    tail.surface = None;
    tail.particles.push(ParticleDesc {
        position: [0.3, 0.2, 1.0],
        velocity: [0.0; 3],
        mass: 0.01,
        pinned: false,
    });
    let cases = [
        (cloth.clone(), 500),
        (cloth.clone(), cloth.particles.len() - 1),
        (tail.clone(), tail.particles.len() - 1),
        (box_scene(), 555),
    ];
    for (scene, at) in cases {
        for threads in [1, 2] {
            let (model, state) = scene.build().unwrap();
            let cfg = DriverConfig {
                integrator: IntegratorKind::SymplecticEuler,
                policy: StepPolicy::Fixed { h: 1e-4 },
                frame_dt: 0.01,
                energy_guard: None,
                ..Default::default()
            };
            let mut sim = Simulation::new(model, state, cfg);
            sim.state.v[at].y = Scalar::NAN;
            let err = bevy_soft_body::core::kernels::with_threads(threads, || sim.advance_frame())
                .unwrap_err();
            assert_eq!(
                err.reason,
                DivergenceReason::NonFinite,
                "{} at {at}",
                scene.name
            );
            assert_eq!(err.time, 0.0, "{} at {at}, {threads} threads", scene.name);
        }
    }
}

/// A pinned particle moved between frames (as a game may move it) is back on its pin after the
/// next frame, at rest, as is a pin moved with `ParticleModel::pin`: the pins' writes that the
/// symplectic Euler steps of a frame skip are made again at every frame's start. On the tet
/// box, pinned on one face, on one thread and on two.
#[test]
fn pins_hold_when_the_state_is_moved_between_frames() {
    use bevy_soft_body::prelude::*;
    for threads in [1, 2] {
        let (model, state) = box_scene().build().unwrap();
        let pins: Vec<(u32, Vector)> = model.pins().to_vec();
        assert_eq!(pins.len(), 121);
        let cfg = DriverConfig {
            integrator: IntegratorKind::SymplecticEuler,
            policy: StepPolicy::Fixed { h: 2e-4 },
            frame_dt: 0.01,
            ..Default::default()
        };
        let mut sim = Simulation::new(model, state, cfg);
        let frame = |sim: &mut Simulation<ParticleState, ParticleModel>| {
            bevy_soft_body::core::kernels::with_threads(threads, || sim.advance_frame()).unwrap()
        };
        let check = |sim: &Simulation<ParticleState, ParticleModel>, moved: Option<Vector>| {
            for &(p, at) in &pins {
                let want = if p == pins[7].0 {
                    moved.unwrap_or(at)
                } else {
                    at
                };
                assert_eq!(sim.state.x[p as usize], want, "pin {p}, {threads} threads");
                assert_eq!(
                    sim.state.v[p as usize],
                    Vector::ZERO,
                    "pin {p}, {threads} threads"
                );
            }
        };
        frame(&mut sim);
        check(&sim, None);
        let moved = pins[60].0 as usize;
        sim.state.x[moved] += Vector::new(0.003, 0.0, 0.0);
        sim.state.v[moved] = Vector::new(1.0, 2.0, 3.0);
        frame(&mut sim);
        check(&sim, None);
        let to = pins[7].1 + Vector::new(0.0, 0.0, 0.002);
        sim.system.pin(pins[7].0 as usize, to);
        frame(&mut sim);
        check(&sim, Some(to));
    }
}

/// A random block-sparse matrix of `n` rows: `m` pairs at random (repeats and pairs of a row
/// with itself among them), the first `sym` blocks symmetric and the rest general, diagonal
/// blocks general too; entries uniform in [−1, 1).
fn random_matrix(
    r: &mut Rng,
    n: usize,
    m: usize,
    sym: usize,
) -> bevy_soft_body::core::solve::SpringMatrix {
    use bevy_soft_body::core::solve::SpringMatrix;
    use bevy_soft_body::math::Matrix3;
    let pairs: Vec<(u32, u32)> = (0..m)
        .map(|k| {
            let i = r.below(n) as u32;
            // Every 97th pair joins a row to itself; the rest mostly near the diagonal, as a
            // mesh's are, some anywhere.
            let j = if k % 97 == 0 {
                i
            } else if k % 5 == 0 {
                r.below(n) as u32
            } else {
                (i as usize + 1 + r.below(40)).min(n - 1) as u32
            };
            (i, j)
        })
        .collect();
    let mut a = SpringMatrix::with_pairs(n, pairs).with_symmetric_prefix(sym);
    let block = |r: &mut Rng, symmetric: bool| {
        let c = [random_vec(r, 1.0), random_vec(r, 1.0), random_vec(r, 1.0)];
        let mut b = Matrix3::from_cols(c[0], c[1], c[2]);
        if symmetric {
            b = Matrix3::from_cols(
                Vector::new(b.x_axis.x, b.y_axis.x, b.z_axis.x),
                Vector::new(b.y_axis.x, b.y_axis.y, b.z_axis.y),
                Vector::new(b.z_axis.x, b.z_axis.y, b.z_axis.z),
            );
        }
        b
    };
    for d in a.diag.iter_mut() {
        *d = block(r, false);
    }
    for k in 0..a.off.len() {
        a.off[k] = block(r, k < sym);
    }
    a
}

/// The matrix product against the dense matrix's, summed in `f64` apart from the solver's
/// code (`to_dense`, then a plain row-by-column loop): within `64 u S` per entry, `S` the
/// sum of the terms' magnitudes (a row of `t` blocks sums `3t + 3` terms with a few roundings
/// each, in another order). On matrices of springs only (every block symmetric), of general
/// blocks only, and mixed; on one, two and three threads, with the same bits.
#[test]
fn matrix_product_equals_the_dense_product_to_round_off() {
    let mut r = Rng(0x9e37_79b9_7f4a_7c15);
    for (n, m, sym) in [(300, 1500, 1500), (300, 1500, 0), (2500, 12_000, 7000)] {
        let a = random_matrix(&mut r, n, m, sym);
        let x: Vec<Vector> = (0..n).map(|_| random_vec(&mut r, 1.0)).collect();
        let dense = a.to_dense();
        let xs: Vec<f64> = x.iter().flat_map(|v| (0..3).map(|c| v[c] as f64)).collect();
        let mut y = vec![Vector::ZERO; n];
        a.mul(&x, &mut y);
        for (row, d) in dense.iter().enumerate() {
            let want: f64 = d.iter().zip(&xs).map(|(a, x)| a * x).sum();
            let scale: f64 = d.iter().zip(&xs).map(|(a, x)| (a * x).abs()).sum();
            let got = y[row / 3][row % 3] as f64;
            assert!(
                (got - want).abs() <= 64.0 * EPS as f64 * scale,
                "n {n}, {sym} symmetric: row {row}: {got} against {want} (scale {scale})"
            );
        }
        #[cfg(feature = "parallel")]
        for threads in [2, 3] {
            let mut yt = vec![Vector::ZERO; n];
            bevy_soft_body::core::kernels::with_threads(threads, || a.mul(&x, &mut yt));
            let bits = |v: &[Vector]| v.iter().map(|v| v.to_f64()).collect::<Vec<_>>();
            assert_eq!(bits(&y), bits(&yt), "n {n}: {threads} threads");
        }
    }
}

/// Linearly implicit Euler's whole solve (conjugate gradients, the vector updates and dot
/// products on the team, the products in AVX lanes where the processor has them) on a 64²
/// cloth (the multigrid) and a 40² one (block-Jacobi, two chunks of rows): ten steps end in
/// the same bits on one, two and three threads.
#[cfg(feature = "parallel")]
#[test]
fn implicit_steps_are_the_same_bits_on_one_two_and_three_threads() {
    use bevy_soft_body::core::integrate::{Integrator, LinearlyImplicitEuler};
    use bevy_soft_body::core::kernels;
    use bevy_soft_body::prelude::*;
    for size in [64, 40] {
        let run = |threads| {
            kernels::with_threads(threads, || {
                let p = build::ClothParams::default().resized(size, size);
                let (model, mut st) = build::cloth(&p).unwrap().build().unwrap();
                let mut integ = LinearlyImplicitEuler::default();
                let h = 1.0 / 60.0;
                for k in 0..10 {
                    integ.step(&model, k as Scalar * h, h, &mut st).unwrap();
                }
                st.x.iter()
                    .chain(&st.v)
                    .map(|v| v.to_f64())
                    .collect::<Vec<_>>()
            })
        };
        let one = run(1);
        for threads in [2, 3] {
            assert_eq!(one, run(threads), "{size}²: {threads} threads");
        }
    }
}
