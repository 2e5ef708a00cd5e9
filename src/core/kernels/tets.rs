//! Neo-Hookean tet forces in the build's precision: the forces of
//! [`Tets::accumulate_f64`] (element kernels in f64) to round-off of [`Scalar`], several times
//! faster, and parallel within one body.
//!
//! Each element keeps what its force needs and nothing else: its four particles, the gradients
//! `g₁, g₂, g₃` of its shape functions (`g₀ = −(g₁ + g₂ + g₃)`), its rest volume and the
//! material's `C`, `D`. `F = Σₐ (xₐ − x₀) gₐᵀ` uses edge vectors, which keeps f32 accurate far
//! from the origin. Forces go first to a per-element buffer (chunks of [`CHUNK_TETS`]
//! elements), then each particle sums its elements' forces in a fixed order (chunks of
//! [`CHUNK_PARTICLES`] particles): no two threads write the same memory, and the order of
//! every sum is independent of the thread count.
//!
//! In the f32 build, where the processor has AVX, the element pass takes eight elements at a
//! time from a copy of their data laid out by lanes (`Lanes`): the same operations as
//! `element_forces` in the same order, lane by lane (no fused multiply-add), so the same bits
//! on processors with and without it; only the cube root's first estimate, integer arithmetic
//! on the bits, is taken lane by lane in scalar code.
//!
//! [`Tets::accumulate_f64`]: crate::core::fem::Tets::accumulate_f64

use super::{SharedMut, for_each_chunk};
use crate::core::fem::PackedTet;
use crate::core::fem::element::J_MIN;
use crate::math::{Scalar, ToScalar, Vector};
use std::sync::Mutex;

/// Elements per chunk of the element pass.
pub const CHUNK_TETS: usize = 256;
/// Particles per chunk of the gather pass.
pub const CHUNK_PARTICLES: usize = 256;

#[derive(Clone, Copy, Debug)]
struct Element {
    v: [u32; 4],
    g: [Vector; 3],
    volume: Scalar,
    c: Scalar,
    d: Scalar,
}

/// Eight consecutive elements by lanes, for the AVX pass: lane `q` is element `8 b + q` of
/// block `b`.
#[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
struct Lanes {
    v: [[u32; 8]; 4],
    /// `g[3 (a − 1) + k]`: component `k` of gradient `g_a`, `a = 1, 2, 3`.
    g: [[f32; 8]; 9],
    volume: [f32; 8],
    c: [f32; 8],
    d: [f32; 8],
}

/// Tets laid out for the fast kernel (see the module docs).
#[derive(Debug)]
pub struct TetForces {
    elements: Vec<Element>,
    /// The elements of every whole group of eight, by lanes.
    #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
    lanes: Vec<Lanes>,
    /// For particle `p`, its element-force slots are `slots[start[p]..start[p + 1]]`.
    start: Vec<u32>,
    /// Slot `4 t + a`: element `t`'s force on its vertex `a`.
    slots: Vec<u32>,
    buffer: Mutex<Vec<Vector>>,
}

impl TetForces {
    /// Lays out `tets`.
    pub fn new(tets: &[PackedTet]) -> Self {
        let s = |x: f64| x as Scalar;
        Self::layout(
            tets.iter()
                .map(|t| Element {
                    v: t.v,
                    g: [1, 2, 3].map(|a| t.rest.grad[a].to_array().to_scalar()),
                    volume: s(t.rest.volume),
                    c: s(t.material.c),
                    d: s(t.material.d),
                })
                .collect(),
        )
    }

    fn layout(elements: Vec<Element>) -> Self {
        let bound = elements
            .iter()
            .flat_map(|t| t.v)
            .map(|i| i as usize + 1)
            .max()
            .unwrap_or(0);
        let mut start = vec![0u32; bound + 1];
        for t in &elements {
            for &p in &t.v {
                start[p as usize + 1] += 1;
            }
        }
        for p in 0..bound {
            start[p + 1] += start[p];
        }
        let mut next = start.clone();
        let mut slots = vec![0u32; 4 * elements.len()];
        for (k, t) in elements.iter().enumerate() {
            for (a, &p) in t.v.iter().enumerate() {
                slots[next[p as usize] as usize] = (4 * k + a) as u32;
                next[p as usize] += 1;
            }
        }
        #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
        let lanes = elements
            .chunks_exact(8)
            .map(|e| Lanes {
                v: std::array::from_fn(|a| std::array::from_fn(|q| e[q].v[a])),
                g: std::array::from_fn(|i| std::array::from_fn(|q| e[q].g[i / 3][i % 3])),
                volume: std::array::from_fn(|q| e[q].volume),
                c: std::array::from_fn(|q| e[q].c),
                d: std::array::from_fn(|q| e[q].d),
            })
            .collect();
        Self {
            #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
            lanes,
            start,
            slots,
            buffer: Mutex::new(vec![Vector::ZERO; 4 * elements.len()]),
            elements,
        }
    }

    /// The elastic energy `Σ V ψ(F)`, each element's in the build's precision with
    /// [`inv_cbrt`], summed in f64: the reference [`Tets::energy`] to that precision's
    /// round-off, and several times faster (the divergence guard's check).
    ///
    /// [`Tets::energy`]: crate::core::fem::Tets::energy
    ///
    /// # Safety
    /// `x` holds every particle any element refers to.
    pub(crate) unsafe fn energy(&self, x: &[Vector]) -> f64 {
        let mut sum = 0.0;
        for e in &self.elements {
            // SAFETY: the caller guarantees the indices.
            let [fa, fb, fc] = unsafe { deformation(e, x) };
            let j = fa.dot(fb.cross(fc));
            let i1 = fa.dot(fa) + fb.dot(fb) + fc.dot(fc);
            let r = inv_cbrt(j.max(J_MIN as Scalar));
            let psi = e.c * (r * r * i1 - 3.0) + e.d * (j - 1.0) * (j - 1.0);
            sum += (e.volume * psi) as f64;
        }
        sum
    }

    /// One more than the largest particle index used.
    pub fn bound(&self) -> usize {
        self.start.len() - 1
    }

    /// Adds the elastic forces into `f`.
    ///
    /// # Safety
    /// `x` and `f` hold every particle any element refers to.
    pub(crate) unsafe fn accumulate(&self, x: &[Vector], f: &mut [Vector]) {
        let mut guard = self.buffer.lock().unwrap_or_else(|e| e.into_inner());
        let buf = SharedMut(guard.as_mut_ptr());
        let m = self.elements.len();
        #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
        let avx = std::arch::is_x86_feature_detected!("avx");
        for_each_chunk(m.div_ceil(CHUNK_TETS), |c| {
            #[allow(unused_mut)]
            let mut range = c * CHUNK_TETS..((c + 1) * CHUNK_TETS).min(m);
            #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
            if avx {
                // SAFETY: AVX is present; as below (chunks start at multiples of eight).
                range.start = unsafe { self.elements_avx(range.clone(), x, buf.ptr()) };
            }
            for (e, t) in self.elements[range.clone()].iter().zip(range) {
                // SAFETY: particle indices are below the bound the caller guarantees; element
                // `t` writes only its own four slots.
                unsafe {
                    let out = element_forces(e, x);
                    let b = buf.ptr().add(4 * t);
                    for (a, fa) in out.into_iter().enumerate() {
                        *b.add(a) = fa;
                    }
                }
            }
        });
        let buf = &*guard;
        let n = self.start.len() - 1;
        let fp = SharedMut(f.as_mut_ptr());
        for_each_chunk(n.div_ceil(CHUNK_PARTICLES), |c| {
            for p in c * CHUNK_PARTICLES..((c + 1) * CHUNK_PARTICLES).min(n) {
                // SAFETY: `p` is below the bound; each chunk writes its own particles only.
                unsafe {
                    let (s0, s1) = (
                        *self.start.get_unchecked(p),
                        *self.start.get_unchecked(p + 1),
                    );
                    if s0 == s1 {
                        continue;
                    }
                    let mut acc = Vector::ZERO;
                    for &s in self.slots.get_unchecked(s0 as usize..s1 as usize) {
                        acc += *buf.get_unchecked(s as usize);
                    }
                    *fp.ptr().add(p) += acc;
                }
            }
        });
    }
}

#[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
impl TetForces {
    /// [`element_forces`] for the whole groups of eight in `range` (which starts at a multiple
    /// of eight), into their slots of `buf`; returns where the elements left over start.
    ///
    /// # Safety
    /// As [`Self::accumulate`]; `buf` holds four slots per element.
    #[target_feature(enable = "avx")]
    unsafe fn elements_avx(
        &self,
        range: std::ops::Range<usize>,
        x: &[Vector],
        buf: *mut Vector,
    ) -> usize {
        use super::avx::{columns, rows};
        use std::arch::x86_64::*;
        let mut t = range.start;
        while t + 8 <= range.end {
            // SAFETY: `t + 8 ≤ m`, so block `t / 8` is whole; particle indices are below the
            // bound the caller guarantees; `Vec3A` is one `__m128`.
            unsafe {
                let l = self.lanes.get_unchecked(t / 8);
                let ld = |a: &[f32; 8]| _mm256_load_ps(a.as_ptr());
                let p = |a: usize| {
                    let r: [__m128; 8] =
                        std::array::from_fn(|q| (*x.get_unchecked(l.v[a][q] as usize)).into());
                    let [cx, cy, cz, _] = columns(&r);
                    V8([cx, cy, cz])
                };
                let x0 = p(0);
                let (e1, e2, e3) = (p(1).sub(x0), p(2).sub(x0), p(3).sub(x0));
                let g: [__m256; 9] = std::array::from_fn(|i| ld(&l.g[i]));
                let fa = e1.scale(g[0]).add(e2.scale(g[3])).add(e3.scale(g[6]));
                let fb = e1.scale(g[1]).add(e2.scale(g[4])).add(e3.scale(g[7]));
                let fc = e1.scale(g[2]).add(e2.scale(g[5])).add(e3.scale(g[8]));
                let (ca, cb, cc) = (fb.cross(fc), fc.cross(fa), fa.cross(fb));
                let j = fa.dot(ca);
                let i1 = _mm256_add_ps(_mm256_add_ps(fa.dot(fa), fb.dot(fb)), fc.dot(fc));
                let j_min = _mm256_set1_ps(J_MIN as Scalar);
                let r = inv_cbrt8(_mm256_max_ps(j, j_min));
                let a23 = _mm256_mul_ps(r, r);
                let c = ld(&l.c);
                let iso = _mm256_and_ps(
                    _mm256_div_ps(
                        _mm256_mul_ps(
                            _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(-2.0 / 3.0), c), a23),
                            i1,
                        ),
                        j,
                    ),
                    _mm256_cmp_ps::<_CMP_GT_OQ>(j, j_min),
                );
                let two = _mm256_set1_ps(2.0);
                let s_f = _mm256_mul_ps(_mm256_mul_ps(two, c), a23);
                let s_c = _mm256_add_ps(
                    iso,
                    _mm256_mul_ps(
                        _mm256_mul_ps(two, ld(&l.d)),
                        _mm256_sub_ps(j, _mm256_set1_ps(1.0)),
                    ),
                );
                let (pa, pb, pc) = (
                    fa.scale(s_f).add(ca.scale(s_c)),
                    fb.scale(s_f).add(cb.scale(s_c)),
                    fc.scale(s_f).add(cc.scale(s_c)),
                );
                let mv = _mm256_xor_ps(ld(&l.volume), _mm256_set1_ps(-0.0));
                let f = |a: usize| {
                    pa.scale(g[3 * a])
                        .add(pb.scale(g[3 * a + 1]))
                        .add(pc.scale(g[3 * a + 2]))
                        .scale(mv)
                };
                let (f1, f2, f3) = (f(0), f(1), f(2));
                let f0 = f1.add(f2).add(f3).neg();
                for (a, fa) in [f0, f1, f2, f3].into_iter().enumerate() {
                    for (q, row) in rows(fa.0[0], fa.0[1], fa.0[2]).into_iter().enumerate() {
                        _mm_store_ps(buf.add(4 * (t + q) + a) as *mut f32, row);
                    }
                }
            }
            t += 8;
        }
        t
    }
}

/// Eight 3-vectors by components, with the operations [`element_forces`] uses on `Vec3A`, in
/// the same order (glam's dot sums `(x + y) + z`; its cross takes the same two products).
#[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
#[derive(Clone, Copy)]
struct V8([std::arch::x86_64::__m256; 3]);

#[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
impl V8 {
    #[target_feature(enable = "avx")]
    #[inline]
    fn add(self, o: Self) -> Self {
        use std::arch::x86_64::_mm256_add_ps;
        Self(std::array::from_fn(|k| _mm256_add_ps(self.0[k], o.0[k])))
    }

    #[target_feature(enable = "avx")]
    #[inline]
    fn sub(self, o: Self) -> Self {
        use std::arch::x86_64::_mm256_sub_ps;
        Self(std::array::from_fn(|k| _mm256_sub_ps(self.0[k], o.0[k])))
    }

    #[target_feature(enable = "avx")]
    #[inline]
    fn scale(self, s: std::arch::x86_64::__m256) -> Self {
        use std::arch::x86_64::_mm256_mul_ps;
        Self(self.0.map(|c| _mm256_mul_ps(c, s)))
    }

    #[target_feature(enable = "avx")]
    #[inline]
    fn neg(self) -> Self {
        use std::arch::x86_64::*;
        Self(self.0.map(|c| _mm256_xor_ps(c, _mm256_set1_ps(-0.0))))
    }

    #[target_feature(enable = "avx")]
    #[inline]
    fn dot(self, o: Self) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        let [x, y, z] = std::array::from_fn(|k| _mm256_mul_ps(self.0[k], o.0[k]));
        _mm256_add_ps(_mm256_add_ps(x, y), z)
    }

    #[target_feature(enable = "avx")]
    #[inline]
    fn cross(self, o: Self) -> Self {
        use std::arch::x86_64::*;
        let ([ax, ay, az], [bx, by, bz]) = (self.0, o.0);
        let m = _mm256_mul_ps;
        Self([
            _mm256_sub_ps(m(ay, bz), m(az, by)),
            _mm256_sub_ps(m(az, bx), m(ax, bz)),
            _mm256_sub_ps(m(ax, by), m(ay, bx)),
        ])
    }
}

/// [`inv_cbrt`] in eight lanes: the first estimate lane by lane (integer division of the
/// bits), then the same Newton steps.
#[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
#[target_feature(enable = "avx")]
#[inline]
fn inv_cbrt8(x: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let mut a = [0.0f32; 8];
    // SAFETY: `a` holds eight floats.
    unsafe { _mm256_storeu_ps(a.as_mut_ptr(), x) };
    let est = a.map(|v| f32::from_bits(0x54a2_fa8c - v.to_bits() / 3));
    // SAFETY: as above.
    let mut y = unsafe { _mm256_loadu_ps(est.as_ptr()) };
    for _ in 0..3 {
        let xyyy = _mm256_mul_ps(_mm256_mul_ps(_mm256_mul_ps(x, y), y), y);
        y = _mm256_mul_ps(
            y,
            _mm256_mul_ps(
                _mm256_sub_ps(_mm256_set1_ps(4.0), xyyy),
                _mm256_set1_ps(1.0 / 3.0),
            ),
        );
    }
    y
}

/// The forces `f_a = −V P g_a` of one element, with CSC417's `P` (see
/// [`NeoHookeanConstants::stress`](crate::core::fem::element::NeoHookeanConstants::stress)).
///
/// # Safety
/// The element's particles are in `x`.
#[inline(always)]
unsafe fn element_forces(e: &Element, x: &[Vector]) -> [Vector; 4] {
    // SAFETY: the caller guarantees the indices.
    let [fa, fb, fc] = unsafe { deformation(e, x) };
    let [g1, g2, g3] = e.g;
    // cof F = J F⁻ᵀ, finite for flat and inverted elements.
    let (ca, cb, cc) = (fb.cross(fc), fc.cross(fa), fa.cross(fb));
    let j = fa.dot(ca);
    let i1 = fa.dot(fa) + fb.dot(fb) + fc.dot(fc);
    let r = inv_cbrt(j.max(J_MIN as Scalar));
    let a23 = r * r;
    let iso = if j > J_MIN as Scalar {
        -2.0 / 3.0 * e.c * a23 * i1 / j
    } else {
        0.0
    };
    let s_f = 2.0 * e.c * a23;
    let s_c = iso + 2.0 * e.d * (j - 1.0);
    // P = s_f F + s_c cof F, by columns; f_a = −V P g_a.
    let (pa, pb, pc) = (
        fa * s_f + ca * s_c,
        fb * s_f + cb * s_c,
        fc * s_f + cc * s_c,
    );
    let mv = -e.volume;
    let f1 = (pa * g1.x + pb * g1.y + pc * g1.z) * mv;
    let f2 = (pa * g2.x + pb * g2.y + pc * g2.z) * mv;
    let f3 = (pa * g3.x + pb * g3.y + pc * g3.z) * mv;
    [-(f1 + f2 + f3), f1, f2, f3]
}

/// The columns of `F = Σ_a (x_a − x_0) g_aᵀ`.
///
/// # Safety
/// The element's particles are in `x`.
#[inline(always)]
unsafe fn deformation(e: &Element, x: &[Vector]) -> [Vector; 3] {
    // SAFETY: the caller guarantees the indices.
    let p = |a: usize| unsafe { *x.get_unchecked(e.v[a] as usize) };
    let x0 = p(0);
    let (e1, e2, e3) = (p(1) - x0, p(2) - x0, p(3) - x0);
    let [g1, g2, g3] = e.g;
    [
        e1 * g1.x + e2 * g2.x + e3 * g3.x,
        e1 * g1.y + e2 * g2.y + e3 * g3.y,
        e1 * g1.z + e2 * g2.z + e3 * g3.z,
    ]
}

/// `x^(−1/3)` for `x ≥ J_MIN` (the isochoric factor's argument): an exponent-bit estimate
/// refined by Newton's iteration `y ← y (4 − x y³)/3`, which converges quadratically from the
/// estimate's 3 % to the precision's round-off in 3 (f32) or 4 (f64) steps — the library `cbrt`
/// was a third of the element kernel's time.
#[inline(always)]
pub fn inv_cbrt(x: Scalar) -> Scalar {
    #[cfg(not(feature = "f64"))]
    let (mut y, steps) = (f32::from_bits(0x54a2_fa8c - x.to_bits() / 3), 3);
    #[cfg(feature = "f64")]
    let (mut y, steps) = (f64::from_bits(0x553e_f0ff_289d_d796 - x.to_bits() / 3), 4);
    for _ in 0..steps {
        y *= (4.0 - x * y * y * y) * (1.0 / 3.0);
    }
    y
}

impl Clone for TetForces {
    fn clone(&self) -> Self {
        let buffer = self
            .buffer
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        Self {
            elements: self.elements.clone(),
            #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
            lanes: self.lanes.clone(),
            start: self.start.clone(),
            slots: self.slots.clone(),
            buffer: Mutex::new(buffer),
        }
    }
}

#[cfg(all(test, target_arch = "x86_64", not(feature = "f64")))]
mod tests {
    use super::*;

    /// The eight-lane pass gives the scalar kernel's bits, element by element: on random
    /// elements of both orientations, elements squashed flat (coplanar vertices) or with two
    /// vertices at one point, elements shrunk to `J = 0.4³ < J_MIN` (the frozen isochoric
    /// branch), and a tail of five that the scalar kernel takes.
    #[test]
    fn eight_lanes_give_the_scalar_bits() {
        if !std::arch::is_x86_feature_detected!("avx") {
            return;
        }
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f32 / (1u64 << 53) as f32 * 2.0 - 1.0
        };
        let n = 40;
        let x: Vec<Vector> = (0..n)
            .map(|_| Vector::new(rnd(), rnd(), rnd()) * 0.1 + Vector::new(3.0, -2.0, 1.0))
            .collect();
        let mut x = x;
        // Flat: particle 3 in the plane of 0, 1, 2; coincident: 7 on 4.
        x[3] = x[0] + (x[1] - x[0]) * 0.3 + (x[2] - x[0]) * 0.5;
        x[7] = x[4];
        // A unit right tet (gradients e_x, e_y, e_z) shrunk to 0.4: F = 0.4 I.
        for (a, dx) in [Vector::ZERO, Vector::X, Vector::Y, Vector::Z]
            .into_iter()
            .enumerate()
        {
            x[36 + a] = x[36] + dx * 0.4;
        }
        let m = 8 * 6 + 5;
        let elements: Vec<Element> = (0..m)
            .map(|t| {
                let (v, g) = match t % 4 {
                    0 => ([0, 1, 2, 3], None),
                    1 => ([4, 5, 6, 7], None),
                    2 => ([36, 37, 38, 39], Some([Vector::X, Vector::Y, Vector::Z])),
                    _ => (std::array::from_fn(|a| ((t * 7 + a * 11) % n) as u32), None),
                };
                Element {
                    v,
                    g: g.unwrap_or_else(|| {
                        std::array::from_fn(|_| Vector::new(rnd(), rnd(), rnd()) * 20.0)
                    }),
                    volume: 1e-4 * (1.5 + rnd()),
                    c: 1e5 * (1.5 + rnd()),
                    d: 1e6 * (1.5 + rnd()),
                }
            })
            .collect();
        let forces = TetForces::layout(elements.clone());
        let mut buf = vec![Vector::splat(f32::NAN); 4 * m];
        // SAFETY: AVX is present; `x` holds every particle; `buf` four slots per element.
        let rest = unsafe { forces.elements_avx(0..m, &x, buf.as_mut_ptr()) };
        assert_eq!(rest, m - 5);
        let mut signs = [0; 3];
        for (t, e) in elements.iter().enumerate().take(rest) {
            // SAFETY: as above.
            let want = unsafe { element_forces(e, &x) };
            for a in 0..4 {
                let got = buf[4 * t + a];
                assert_eq!(
                    got.to_array().map(f32::to_bits),
                    want[a].to_array().map(f32::to_bits),
                    "element {t}, vertex {a}"
                );
            }
            let p = |a: usize| x[e.v[a] as usize] - x[e.v[0] as usize];
            let col = |k: usize| (1..4).map(|a| p(a) * e.g[a - 1][k]).sum::<Vector>();
            let j = col(0).cross(col(1)).dot(col(2));
            signs[(j > 0.0) as usize + (j > J_MIN as f32) as usize] += 1;
        }
        // Every branch is taken: J ≤ 0, 0 < J ≤ J_MIN, J > J_MIN.
        assert!(signs.iter().all(|&k| k > 0), "{signs:?}");
    }
}
