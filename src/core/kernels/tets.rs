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

/// Tets laid out for the fast kernel (see the module docs).
#[derive(Debug)]
pub struct TetForces {
    elements: Vec<Element>,
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
        let elements: Vec<Element> = tets
            .iter()
            .map(|t| Element {
                v: t.v,
                g: [1, 2, 3].map(|a| t.rest.grad[a].to_array().to_scalar()),
                volume: s(t.rest.volume),
                c: s(t.material.c),
                d: s(t.material.d),
            })
            .collect();
        let bound = tets
            .iter()
            .flat_map(|t| t.v)
            .map(|i| i as usize + 1)
            .max()
            .unwrap_or(0);
        let mut start = vec![0u32; bound + 1];
        for t in tets {
            for &p in &t.v {
                start[p as usize + 1] += 1;
            }
        }
        for p in 0..bound {
            start[p + 1] += start[p];
        }
        let mut next = start.clone();
        let mut slots = vec![0u32; 4 * tets.len()];
        for (k, t) in tets.iter().enumerate() {
            for (a, &p) in t.v.iter().enumerate() {
                slots[next[p as usize] as usize] = (4 * k + a) as u32;
                next[p as usize] += 1;
            }
        }
        Self {
            elements,
            start,
            slots,
            buffer: Mutex::new(vec![Vector::ZERO; 4 * tets.len()]),
        }
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
        for_each_chunk(m.div_ceil(CHUNK_TETS), |c| {
            let range = c * CHUNK_TETS..((c + 1) * CHUNK_TETS).min(m);
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

/// The forces `f_a = −V P g_a` of one element, with CSC417's `P` (see
/// [`NeoHookeanConstants::stress`](crate::core::fem::element::NeoHookeanConstants::stress)).
///
/// # Safety
/// The element's particles are in `x`.
#[inline(always)]
unsafe fn element_forces(e: &Element, x: &[Vector]) -> [Vector; 4] {
    // SAFETY: the caller guarantees the indices.
    let p = |a: usize| unsafe { *x.get_unchecked(e.v[a] as usize) };
    let x0 = p(0);
    let (e1, e2, e3) = (p(1) - x0, p(2) - x0, p(3) - x0);
    let [g1, g2, g3] = e.g;
    // Columns of F = Σ e_a g_aᵀ.
    let fa = e1 * g1.x + e2 * g2.x + e3 * g3.x;
    let fb = e1 * g1.y + e2 * g2.y + e3 * g3.y;
    let fc = e1 * g1.z + e2 * g2.z + e3 * g3.z;
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
            start: self.start.clone(),
            slots: self.slots.clone(),
            buffer: Mutex::new(buffer),
        }
    }
}
