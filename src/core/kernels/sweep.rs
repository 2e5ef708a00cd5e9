//! The symplectic Euler sweep of a particle model, `v ← v + h a`, `x ← x + h (v₀ + h a)` with
//! `a = f w + g` for free particles and `a = 0` where `w = 0`: [`sweep_reference`] one particle
//! at a time, [`sweep`] the same operations in the same order (so the same bits), in the
//! f64 build four particles (twelve components, three AVX registers) at a time.
//!
//! A `DVec3` is three `f64`s, so a loop over particles keeps two of every three lanes of a
//! register busy at best; over the flat components the registers are full, and the only
//! shuffles are a particle's `w` spread over its three components. In the f32 build a
//! `Vec3A` is one register already and the reference loop is the kernel.

use super::springs::CHUNK_PARTICLES;
use super::{SharedMut, for_each_range};
use crate::math::{Scalar, Vector};

/// The sweep, one particle at a time: the reference [`sweep`] is tested against.
pub fn sweep_reference(
    x: &mut [Vector],
    v: &mut [Vector],
    f: &[Vector],
    inv_mass: &[Scalar],
    g: Vector,
    h: Scalar,
) {
    for (((x, v), f), &w) in x.iter_mut().zip(v.iter_mut()).zip(f).zip(inv_mass) {
        // Pinned and prescribed particles have w = 0 and get no gravity.
        let a = if w > 0.0 { *f * w + g } else { Vector::ZERO };
        let dv = a * h;
        let v0 = *v;
        *v += dv;
        *x += (v0 + dv) * h;
    }
}

/// The sweep over the shortest of the four slices, bit for bit [`sweep_reference`]; in
/// chunks of [`CHUNK_PARTICLES`] (the spring kernel's largest chunk), shared with the team the
/// caller runs in (see [`super::with_threads`]), for models the fused pass does not serve
/// (two kernels, or force fields). A thread then sweeps mostly the particles whose forces it
/// gathered, and writes the positions and velocities its next force pass reads: run on the
/// caller alone, the sweep read the helpers' forces and wrote their particles across cores,
/// and took 37 % of the caller's time on two threads (6 % on one).
pub fn sweep(
    x: &mut [Vector],
    v: &mut [Vector],
    f: &[Vector],
    inv_mass: &[Scalar],
    g: Vector,
    h: Scalar,
) {
    let n = x.len().min(v.len()).min(f.len()).min(inv_mass.len());
    let (xp, vp) = (SharedMut(x.as_mut_ptr()), SharedMut(v.as_mut_ptr()));
    for_each_range(n, CHUNK_PARTICLES, |r| {
        // SAFETY: chunks are disjoint ranges below `n`, the length of every slice; each
        // chunk's job alone touches its range of `x` and `v`.
        let (x, v) = unsafe { (xp.slice(r.clone()), vp.slice(r.clone())) };
        sweep_chunk(x, v, &f[r.clone()], &inv_mass[r], g, h);
    });
}

/// The sweep of one run of particles on this thread: [`sweep_reference`] over the shortest
/// of the four slices, in whole registers where the build has a faster form (the same bits).
/// The chunk job of [`sweep`], and of the force kernels' fused passes.
#[inline]
pub fn sweep_chunk(
    x: &mut [Vector],
    v: &mut [Vector],
    f: &[Vector],
    inv_mass: &[Scalar],
    g: Vector,
    h: Scalar,
) {
    let n = x.len().min(v.len()).min(f.len()).min(inv_mass.len());
    #[allow(unused_mut)]
    let mut done = 0;
    #[cfg(all(target_arch = "x86_64", feature = "f64"))]
    if std::arch::is_x86_feature_detected!("avx2") {
        let quads = n / 4 * 4;
        // SAFETY: AVX2 is present; every slice holds `n ≥ quads` particles.
        unsafe { sweep_avx(quads, x, v, f, inv_mass, g, h) };
        done = quads;
    }
    sweep_reference(
        &mut x[done..n],
        &mut v[done..n],
        &f[done..n],
        &inv_mass[done..n],
        g,
        h,
    );
}

/// Sets every force to zero, in the sweep's chunks (each thread clears the forces it will
/// gather and sweep, so that their lines stay in its cache).
pub fn clear(f: &mut [Vector]) {
    let n = f.len();
    let fp = SharedMut(f.as_mut_ptr());
    // SAFETY: chunks are disjoint ranges below `n`; each chunk's job alone writes its own.
    for_each_range(n, CHUNK_PARTICLES, |r| {
        unsafe { fp.slice(r) }.fill(Vector::ZERO)
    });
}

/// Particles `0..n` (`n` a multiple of four), four at a time.
///
/// # Safety
/// AVX2 is present; every slice holds at least `n` particles.
#[cfg(all(target_arch = "x86_64", feature = "f64"))]
#[target_feature(enable = "avx2")]
unsafe fn sweep_avx(
    n: usize,
    x: &mut [Vector],
    v: &mut [Vector],
    f: &[Vector],
    inv_mass: &[Scalar],
    g: Vector,
    h: Scalar,
) {
    use std::arch::x86_64::*;
    // SAFETY: a `DVec3` is three `f64`s (`#[repr(C)]`), so four particles are twelve
    // consecutive `f64`s; all indices are below `3 n` and `n` respectively.
    unsafe {
        let (xp, vp) = (x.as_mut_ptr() as *mut f64, v.as_mut_ptr() as *mut f64);
        let fp = f.as_ptr() as *const f64;
        let hh = _mm256_set1_pd(h);
        let zero = _mm256_setzero_pd();
        // Gravity along the twelve components: x y z x | y z x y | z x y z.
        let gs = [
            _mm256_setr_pd(g.x, g.y, g.z, g.x),
            _mm256_setr_pd(g.y, g.z, g.x, g.y),
            _mm256_setr_pd(g.z, g.x, g.y, g.z),
        ];
        let mut p = 0;
        while p < n {
            let w4 = _mm256_loadu_pd(inv_mass.as_ptr().add(p));
            // Each particle's `w` over its components: w0 w0 w0 w1 | w1 w1 w2 w2 | w2 w3 w3 w3.
            let ws = [
                _mm256_permute4x64_pd::<0x40>(w4),
                _mm256_permute4x64_pd::<0xa5>(w4),
                _mm256_permute4x64_pd::<0xfe>(w4),
            ];
            for r in 0..3 {
                let at = 3 * p + 4 * r;
                let free = _mm256_cmp_pd::<_CMP_GT_OQ>(ws[r], zero);
                let a = _mm256_add_pd(_mm256_mul_pd(_mm256_loadu_pd(fp.add(at)), ws[r]), gs[r]);
                let dv = _mm256_mul_pd(_mm256_and_pd(a, free), hh);
                let v0 = _mm256_loadu_pd(vp.add(at));
                _mm256_storeu_pd(vp.add(at), _mm256_add_pd(v0, dv));
                let x0 = _mm256_loadu_pd(xp.add(at));
                let step = _mm256_mul_pd(_mm256_add_pd(v0, dv), hh);
                _mm256_storeu_pd(xp.add(at), _mm256_add_pd(x0, step));
            }
            p += 4;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bit for bit the reference on random particles, with pinned ones (`w = 0`) among them
    /// and every count from 0 to 13 (the four-wide groups and the tail).
    #[test]
    fn sweep_matches_the_reference_bit_for_bit() {
        let mut rnd = crate::math::test_rng(0x9e37_79b9_7f4a_7c15u64);
        for n in 0..14 {
            let mut vecs = |s: f64| -> Vec<Vector> {
                (0..n)
                    .map(|_| {
                        [rnd() * s, rnd() * s, rnd() * s]
                            .map(|c| c as Scalar)
                            .into()
                    })
                    .collect()
            };
            let (x, v, f) = (vecs(2.0), vecs(5.0), vecs(300.0));
            let w: Vec<Scalar> = (0..n)
                .map(|i| {
                    if i % 5 == 2 {
                        0.0
                    } else {
                        (rnd().abs() * 40.0) as Scalar
                    }
                })
                .collect();
            let g = Vector::new(0.1, -9.81, 0.3);
            let h = 2e-4 as Scalar;
            let (mut xa, mut va) = (x.clone(), v.clone());
            let (mut xb, mut vb) = (x, v);
            sweep(&mut xa, &mut va, &f, &w, g, h);
            sweep_reference(&mut xb, &mut vb, &f, &w, g, h);
            let bits = |a: &[Vector]| {
                a.iter()
                    .flat_map(|v| v.to_array())
                    .map(|c| c.to_bits() as u64)
                    .collect::<Vec<_>>()
            };
            assert_eq!(bits(&xa), bits(&xb), "positions, {n} particles");
            assert_eq!(bits(&va), bits(&vb), "velocities, {n} particles");
        }
    }
}
