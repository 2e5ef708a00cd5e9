//! The matrix product in AVX lanes: a copy of a [`SpringMatrix`]'s symmetric off-diagonal
//! blocks packed for eight rows at a time (four in `f64`).
//!
//! Eight consecutive rows go through their entries together, one entry of each row per step:
//! a step holds the eight entries' blocks' six numbers (a symmetric block's `xx, yy, zz, xy,
//! xz, yz`) lane by lane and their columns, so a step is eight loads of the columns' vectors,
//! one transpose and nine multiplications and additions in 8-lane registers, where by rows
//! ([`SpringMatrix::mul_map`]) each entry takes three shuffles, three multiplications and
//! three additions of its own. Rows of a group shorter than its longest are padded with zero
//! blocks at their own column.
//!
//! What this buys depends on where the blocks live: a product reads every block twice (once
//! from each of its rows), 28 bytes an entry in `f32`, and once the matrix is larger than a
//! core's L2 cache the product is bound by those bytes (on the 128² cloth, 5.5 MB a product
//! at about 25 GB/s on one core of the project's machine), not by the arithmetic. On the 64²
//! bench cloth, whose copy fits, the lanes pay: its `f64` solve took 20.3 ms a step against
//! 22.2 by rows on one thread, 9.2 against 12.9 on two (see `docs/BENCHMARKS.md`, "Implicit
//! methods").
//!
//! The copy is refilled from the matrix at every solve (its structure once per structure).
//! The lanes compute each row's sum exactly as [`SpringMatrix::mul_map`] does by rows (the
//! same products and additions in the same order, no fused multiply-add), so the two give
//! the same bits: the product does not depend on the processor having AVX, nor on the number
//! of threads.

#[cfg(target_arch = "x86_64")]
use super::AT_JI;
use super::SpringMatrix;
#[cfg(target_arch = "x86_64")]
use crate::math::Scalar;
use crate::math::Vector;
use std::ops::Range;

/// Rows a group packs: one per lane of a 256-bit register (eight `f32`, four `f64`).
#[cfg(not(feature = "f64"))]
pub(crate) const LANES: usize = 8;
/// Rows a group packs: one per lane of a 256-bit register (eight `f32`, four `f64`).
#[cfg(feature = "f64")]
pub(crate) const LANES: usize = 4;

/// One step of a group: its rows' entries at one place in the rows.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
struct Step {
    /// `xx, yy, zz, xy, xz, yz`, lane by lane: each a whole, aligned 32-byte register.
    b: [[Scalar; LANES]; 6],
    col: [u32; LANES],
}

/// The packed copy (see the module docs). Empty, and not used, on other processors than
/// x86-64 with AVX, and for matrices with blocks that are not symmetric.
#[derive(Clone, Debug, Default)]
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))] // never filled there
pub(crate) struct Packed {
    /// The structure packed ([`SpringMatrix::structure`]), and whether this copy serves it.
    structure: u64,
    usable: bool,
    /// Each group's first step; one more at the end.
    group: Vec<u32>,
    /// Each step's lanes' blocks (indices into the matrix's `off`; `u32::MAX`: padding).
    slot: Vec<u32>,
    #[cfg(target_arch = "x86_64")]
    steps: Vec<Step>,
}

impl Packed {
    /// Packs `a`'s blocks (their places first, when `a`'s structure is new) and says whether
    /// the copy can serve `a`'s products.
    pub(crate) fn update(&mut self, a: &SpringMatrix) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            if self.structure != a.structure || self.group.is_empty() {
                self.analyse(a);
            }
            if self.usable {
                self.fill(a);
            }
            self.usable
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = a;
            false
        }
    }

    #[cfg(target_arch = "x86_64")]
    fn analyse(&mut self, a: &SpringMatrix) {
        self.structure = a.structure;
        self.usable = !a.is_empty()
            && a.symmetric_prefix() == a.off.len()
            && std::arch::is_x86_feature_detected!("avx");
        self.group.clear();
        self.slot.clear();
        self.steps.clear();
        if !self.usable {
            return;
        }
        let n = a.len();
        let rows = &a.rows;
        self.group.push(0);
        for g0 in (0..n).step_by(LANES) {
            let lanes = g0..(g0 + LANES).min(n);
            let len = lanes
                .clone()
                .map(|i| rows.start[i + 1] - rows.start[i])
                .max()
                .unwrap_or(0) as usize;
            for e in 0..len {
                let mut step = Step::default();
                for q in 0..LANES {
                    let i = g0 + q;
                    let (k, c) = if i < n && e < (rows.start[i + 1] - rows.start[i]) as usize {
                        let at = rows.start[i] as usize + e;
                        (rows.block[at] & !AT_JI, rows.col[at])
                    } else {
                        // Padding: a zero block at the row's own column (past the last row,
                        // the last row's).
                        (u32::MAX, i.min(n - 1) as u32)
                    };
                    step.col[q] = c;
                    self.slot.push(k);
                }
                self.steps.push(step);
            }
            self.group.push(self.steps.len() as u32);
        }
    }

    /// The blocks' values into the steps.
    #[cfg(target_arch = "x86_64")]
    fn fill(&mut self, a: &SpringMatrix) {
        // By the solve's chunks of rows, on the team: whole groups, so each chunk's steps are
        // its own.
        let (group, slot) = (&self.group, &self.slot);
        let out = crate::core::kernels::SharedMut(self.steps.as_mut_ptr());
        super::for_each_rows(a.len(), |rows| {
            let (g0, g1) = (rows.start / LANES, rows.end.div_ceil(LANES));
            let steps = group[g0] as usize..group[g1] as usize;
            let slots = slot[LANES * steps.start..LANES * steps.end].chunks_exact(LANES);
            // SAFETY: the chunks' groups, and so their steps, are disjoint and within `self.steps`.
            let steps = unsafe { out.slice(steps) };
            for (step, slot) in steps.iter_mut().zip(slots) {
                for (q, &k) in slot.iter().enumerate() {
                    let b = match a.off.get(k as usize) {
                        Some(o) => [
                            o.x_axis.x, o.y_axis.y, o.z_axis.z, o.x_axis.y, o.x_axis.z, o.y_axis.z,
                        ],
                        None => [0.0; 6],
                    };
                    for (c, v) in step.b.iter_mut().zip(b) {
                        c[q] = v;
                    }
                }
            }
        });
    }

    /// `put(i, (A x)_i)` for the rows `r` (`r.start` a multiple of [`LANES`]), `a` the matrix
    /// last [`update`](Self::update)d, which said the copy serves it.
    pub(crate) fn rows_times(
        &self,
        a: &SpringMatrix,
        r: Range<usize>,
        x: &[Vector],
        put: &mut impl FnMut(usize, Vector),
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            assert!(
                self.usable && self.structure == a.structure && x.len() >= a.len(),
                "the packed copy does not serve this product"
            );
            debug_assert_eq!(r.start % LANES, 0);
            for g in r.start / LANES..r.end.div_ceil(LANES) {
                let steps = &self.steps[self.group[g] as usize..self.group[g + 1] as usize];
                // SAFETY: AVX was detected when the copy was made usable; every column is a
                // row of `a` (below `a.len() ≤ x.len()`).
                let s = unsafe { group_sums(steps, x) };
                for (q, s) in s.into_iter().enumerate() {
                    let i = g * LANES + q;
                    if i < r.end {
                        put(i, a.diag[i] * x[i] + s);
                    }
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = (a, r, x, put);
            unreachable!("the packed copy is never usable in this build");
        }
    }
}

/// Per lane, the sums of a group's steps' `terms` (x, y and z of the lanes' rows) in the order
/// [`SpringMatrix::row_times`] sums a row: the even steps' into one set of sums and the odd
/// steps' into another, two steps at a time (the sums stay in registers), then the two added.
/// `add` is the lanes' addition of either precision's kernel.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn even_odd_sums<T: Copy>(
    steps: &[Step],
    zero: T,
    terms: impl Fn(&Step) -> [T; 3],
    add: impl Fn(T, T) -> T,
) -> [T; 3] {
    let add3 = |s: [T; 3], t: [T; 3]| [add(s[0], t[0]), add(s[1], t[1]), add(s[2], t[2])];
    let mut s = [[zero; 3]; 2];
    let pairs = steps.chunks_exact(2);
    let last = pairs.remainder();
    for pair in pairs {
        s[0] = add3(s[0], terms(&pair[0]));
        s[1] = add3(s[1], terms(&pair[1]));
    }
    if let [step] = last {
        s[0] = add3(s[0], terms(step));
    }
    add3(s[0], s[1])
}

/// The eight rows' sums of a group's steps: per lane, the even steps' terms and the odd
/// steps' summed apart and then added, each term `(b_x0 x + b_x1 y) + b_x2 z` (and so on for
/// y and z), as [`SpringMatrix::row_times`] sums a row.
///
/// # Safety
/// AVX is available; every step's columns index `x`.
#[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
#[target_feature(enable = "avx")]
unsafe fn group_sums(steps: &[Step], x: &[Vector]) -> [Vector; LANES] {
    use crate::core::kernels::avx;
    use std::arch::x86_64::*;
    let zero = _mm256_setzero_ps();
    // The step's three terms, x, y and z of the eight rows.
    let terms = |step: &Step| {
        // SAFETY: the columns are within `x` (the caller's promise); `Vector` is an aligned
        // 16-byte vector; the step is 32-byte aligned.
        let r: [__m128; LANES] = std::array::from_fn(|q| unsafe {
            _mm_load_ps(x.get_unchecked(step.col[q] as usize) as *const Vector as *const f32)
        });
        let [cx, cy, cz, _] = avx::columns(&r);
        let b = |c: usize| unsafe { _mm256_load_ps(step.b[c].as_ptr()) };
        let (xx, yy, zz, xy, xz, yz) = (b(0), b(1), b(2), b(3), b(4), b(5));
        let term = |p: __m256, q: __m256, w: __m256| {
            _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(p, cx), _mm256_mul_ps(q, cy)),
                _mm256_mul_ps(w, cz),
            )
        };
        [term(xx, xy, xz), term(xy, yy, yz), term(xz, yz, zz)]
    };
    let [sx, sy, sz] = even_odd_sums(steps, zero, terms, |a, b| _mm256_add_ps(a, b));
    avx::rows(sx, sy, sz).map(Vector::from)
}

/// [`group_sums`] in the `f64` build: four rows, each column's `DVec3` loaded whole (a masked
/// load: its 24 bytes, never the next vector's).
///
/// # Safety
/// AVX is available; every step's columns index `x`.
#[cfg(all(target_arch = "x86_64", feature = "f64"))]
#[target_feature(enable = "avx")]
unsafe fn group_sums(steps: &[Step], x: &[Vector]) -> [Vector; LANES] {
    use crate::core::kernels::avx::transpose_pd;
    use std::arch::x86_64::*;
    let zero = _mm256_setzero_pd();
    let xyz = _mm256_set_epi64x(0, -1, -1, -1);
    let terms = |step: &Step| {
        // SAFETY: the columns are within `x` (the caller's promise); the masked load reads
        // the vector's three lanes only; the step is 32-byte aligned.
        let r: [__m256d; LANES] = std::array::from_fn(|q| unsafe {
            _mm256_maskload_pd(
                x.get_unchecked(step.col[q] as usize) as *const Vector as *const f64,
                xyz,
            )
        });
        let [cx, cy, cz, _] = transpose_pd(r[0], r[1], r[2], r[3]);
        let b = |c: usize| unsafe { _mm256_load_pd(step.b[c].as_ptr()) };
        let (xx, yy, zz, xy, xz, yz) = (b(0), b(1), b(2), b(3), b(4), b(5));
        let term = |p: __m256d, q: __m256d, w: __m256d| {
            _mm256_add_pd(
                _mm256_add_pd(_mm256_mul_pd(p, cx), _mm256_mul_pd(q, cy)),
                _mm256_mul_pd(w, cz),
            )
        };
        [term(xx, xy, xz), term(xy, yy, yz), term(xz, yz, zz)]
    };
    let [sx, sy, sz] = even_odd_sums(steps, zero, terms, |a, b| _mm256_add_pd(a, b));
    let rows = transpose_pd(sx, sy, sz, zero);
    rows.map(|r| {
        let mut v = [0.0; 4];
        // SAFETY: four f64s into a four-f64 array.
        unsafe { _mm256_storeu_pd(v.as_mut_ptr(), r) };
        Vector::new(v[0], v[1], v[2])
    })
}

#[cfg(test)]
mod tests {
    use super::super::{Product, SpringMatrix};
    use super::*;
    use crate::math::Matrix3;

    /// The packed product and the product by rows give the same bits, on symmetric matrices
    /// whose rows differ in length (so groups carry padding), with pairs of a row with
    /// itself, a last group that is not full, and values of every magnitude.
    #[test]
    fn packed_product_is_the_rows_product_bit_for_bit() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for n in [1, 7, 8, 9, 333, 2050] {
            let pairs: Vec<(u32, u32)> = (0..4 * n)
                .map(|k| {
                    let i = (rnd() * n as f64) as u32 % n as u32;
                    let j = if k % 31 == 0 {
                        i
                    } else {
                        (rnd() * n as f64) as u32 % n as u32
                    };
                    (i, j)
                })
                .collect();
            let m = pairs.len();
            let mut a = SpringMatrix::with_pairs(n, pairs).with_symmetric_prefix(m);
            let mut v = |s: f64| (s * (2.0 * rnd() - 1.0)) as crate::math::Scalar;
            for d in a.diag.iter_mut() {
                let s = 10f64.powi((v(4.0) as i32).clamp(-3, 3));
                *d = Matrix3::from_cols(
                    Vector::new(v(s), v(s), v(s)),
                    Vector::new(v(s), v(s), v(s)),
                    Vector::new(v(s), v(s), v(s)),
                );
            }
            for o in a.off.iter_mut() {
                let s = 10f64.powi((v(4.0) as i32).clamp(-3, 3));
                let (xx, yy, zz, xy, xz, yz) = (v(s), v(s), v(s), v(s), v(s), v(s));
                *o = Matrix3::from_cols(
                    Vector::new(xx, xy, xz),
                    Vector::new(xy, yy, yz),
                    Vector::new(xz, yz, zz),
                );
            }
            let x: Vec<Vector> = (0..n)
                .map(|_| Vector::new(v(1.0), v(1.0), v(1.0)))
                .collect();
            let mut packed = Packed::default();
            let usable = packed.update(&a);
            #[cfg(target_arch = "x86_64")]
            assert_eq!(usable, std::arch::is_x86_feature_detected!("avx"));
            if !usable {
                return;
            }
            let (mut y1, mut y2) = (vec![Vector::ZERO; n], vec![Vector::ZERO; n]);
            #[allow(clippy::unnecessary_cast)] // f32 in one build, f64 in the other
            let bits = |y: &[Vector]| -> Vec<[u64; 3]> {
                y.iter()
                    .map(|v| [v.x as f64, v.y as f64, v.z as f64].map(f64::to_bits))
                    .collect()
            };
            Product::Rows(&a).mul_map(&x, &mut y1, |_, v| v, None);
            Product::Packed(&a, &packed).mul_map(&x, &mut y2, |_, v| v, None);
            assert_eq!(bits(&y1), bits(&y2), "{n} rows");
            // New values, the same structure: refilled, not re-analysed.
            for o in a.off.iter_mut() {
                *o *= 0.5;
            }
            assert!(packed.update(&a));
            Product::Rows(&a).mul_map(&x, &mut y1, |_, v| v, None);
            Product::Packed(&a, &packed).mul_map(&x, &mut y2, |_, v| v, None);
            assert_eq!(bits(&y1), bits(&y2), "{n} rows, refilled");
        }
    }
}
