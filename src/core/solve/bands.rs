//! The matrix product of a structured mesh's springs in bands: each spring's symmetric block
//! stored once, by the offset between its particles, and the rows read in AVX lanes.
//!
//! A cloth built as a grid numbers its particles row by row, so its springs join `p` to
//! `p + o` for a few offsets `o` (see [`crate::core::kernels::bands`]). When every
//! off-diagonal block of a [`SpringMatrix`] is symmetric and the pairs fall on a few
//! offsets, the copy keeps, per offset (a *band*), one block per particle `p` (the block of
//! the pair `(p, p + o)`; zeros where there is none; pairs that meet twice add up in their
//! slot), as six columns (`xx, yy, zz, xy, xz, yz`). Row `p`'s product is then
//!
//! ```text
//! (A x)_p = D_p x_p + (Σ_bands B[p] x_{p+o} + Σ_bands B[p−o] x_{p−o})
//! ```
//!
//! with the two sums kept apart (two chains of additions) and each term
//! `(b_xx x + b_xy y) + b_xz z` and so on, as the packed product computes its terms. Every
//! block is stored once (24 bytes in `f32`; the packed copy stores each twice, 28 bytes an
//! entry, with its column), and row `p + o` reads block `p` again `o` rows after row `p`,
//! while it is still in the cache: a product reads about half the bytes the packed one reads,
//! which bound it on the 128² cloth. In AVX, eight rows (four in `f64`) go at a time: each
//! band's block columns and the chunk's positions, copied into columns once per product, are
//! read at consecutive places, with no index and no gather.
//!
//! The slots before the first particle are zeros, as are the positions past either end in
//! the columns, so every row adds every band's two terms (a zero block times a zero vector
//! where a term falls outside the system) and every whole register of rows goes in lanes.
//! The order of the sums is the copy's own (not [`SpringMatrix::row_times`]'s), the same in
//! the lanes and in the scalar rows (a chunk's last rows short of a register, and every row
//! without AVX), so the product has the same bits on every machine and any number of
//! threads. It reads fewer bytes than the packed product, not half the time: see
//! `docs/BENCHMARKS.md` (implicit methods) for what it gained and what bounds it.

use super::SpringMatrix;
use crate::core::kernels::{self, SharedMut};
use crate::math::{Scalar, Vector};
use std::collections::BTreeMap;
use std::ops::Range;
use std::sync::{Mutex, MutexGuard};

/// Most offsets a copy takes: more, and the matrix is not a structured mesh's.
const MAX_BANDS: usize = 16;

/// Fewest rows the copy takes a matrix of. Below, the packed copy (which reads each block
/// twice) fits a core's L2 cache and its products are as fast or faster: linearly implicit
/// Euler on grid cloths, f32, two threads, PCG at 1e-6, the same run: 64² (4096 rows) 3.86–4.01
/// ms a step packed against 4.28–4.30 in bands; 96² (9216 rows) 11.0–11.9 against 10.3; 128²
/// 23.6–25.0 against 20.4–21.2.
const MIN_ROWS: usize = 8192;

/// Largest offset (the chunks' copies of the positions reach this far past their rows).
const MAX_OFFSET: usize = 4096;

/// Rows the lanes take at a time: one AVX register of the build's scalars.
const LANES: usize = 32 / std::mem::size_of::<Scalar>();

/// The band copy of a matrix (see the module docs). Empty, and not used, for matrices that
/// are not a structured mesh's springs.
#[derive(Clone, Debug, Default)]
pub(crate) struct BandCopy {
    /// The structure analysed ([`SpringMatrix::structure`]), and whether the copy serves it.
    structure: u64,
    usable: bool,
    /// Block rows.
    n: usize,
    /// The bands' offsets, increasing.
    offsets: Vec<usize>,
    /// Each pair's band and slot (its lower particle).
    place: Vec<(u32, u32)>,
    /// The pairs of band `b`, in order: `by_band[band_start[b]..band_start[b + 1]]`.
    by_band: Vec<u32>,
    band_start: Vec<u32>,
    /// The largest offset.
    omax: usize,
    /// Band `b`'s component `c` of slot `p` (for `−omax ≤ p < n`: the slots before the first
    /// particle are zeros, as are those of particles with no pair) at
    /// `(6 b + c)(n + omax) + omax + p`.
    blocks: Vec<Scalar>,
    /// Per chunk of rows, the positions its rows read, in columns.
    columns: Columns,
}

/// The chunks' columns of positions (scratch: cloned as zeros of the same length, since a
/// clone of a usable copy serves the same structure).
#[derive(Debug, Default)]
struct Columns(Mutex<Vec<Scalar>>);

impl Clone for Columns {
    fn clone(&self) -> Self {
        let len = self.0.lock().unwrap_or_else(|e| e.into_inner()).len();
        Self(Mutex::new(vec![0.0; len]))
    }
}

impl BandCopy {
    /// Copies `a`'s blocks into bands (their places first, when `a`'s structure is new) and
    /// says whether the copy can serve `a`'s products.
    pub(crate) fn update(&mut self, a: &SpringMatrix) -> bool {
        self.update_from(a, MIN_ROWS)
    }

    /// [`Self::update`] for matrices of at least `min_rows` rows.
    fn update_from(&mut self, a: &SpringMatrix, min_rows: usize) -> bool {
        if self.structure != a.structure || self.n != a.len() {
            self.analyse(a, min_rows);
        }
        if self.usable {
            self.fill(a);
        }
        self.usable
    }

    /// The bands of `a`'s pairs, if they make few, dense enough bands.
    fn analyse(&mut self, a: &SpringMatrix, min_rows: usize) {
        self.structure = a.structure;
        self.n = a.len();
        self.usable = false;
        self.offsets.clear();
        self.place.clear();
        self.by_band.clear();
        self.band_start.clear();
        self.blocks.clear();
        let n = a.len();
        if n < min_rows.max(LANES) || a.symmetric_prefix() != a.off.len() || a.pairs.is_empty() {
            return;
        }
        let mut count: BTreeMap<usize, usize> = BTreeMap::new();
        for &(i, j) in &a.pairs {
            let o = i.abs_diff(j) as usize;
            if o == 0 || o > MAX_OFFSET {
                return;
            }
            *count.entry(o).or_default() += 1;
        }
        // A band costs a slot per row whatever it holds: the bands must hold at least half
        // as many pairs as slots.
        if count.len() > MAX_BANDS || 2 * a.pairs.len() < count.len() * n {
            return;
        }
        self.offsets = count.keys().copied().collect();
        let band: BTreeMap<usize, u32> = (self.offsets.iter().enumerate())
            .map(|(b, &o)| (o, b as u32))
            .collect();
        self.place = (a.pairs.iter())
            .map(|&(i, j)| (band[&(i.abs_diff(j) as usize)], i.min(j)))
            .collect();
        (self.band_start, self.by_band) = super::group_by(
            self.offsets.len(),
            (self.place.iter().enumerate()).map(|(k, &(b, _))| (b as usize, k as u32)),
        );
        let omax = self.offsets.last().copied().unwrap_or(0);
        self.omax = omax;
        self.blocks.resize(6 * self.offsets.len() * (n + omax), 0.0);
        self.usable = true;
        let len = self.columns_len();
        self.columns
            .0
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .resize(len, 0.0);
    }

    /// The blocks' values into the bands, a band at a time on the team (a band's columns
    /// are written by its own pairs alone, in their order: the same bits on any number of
    /// threads).
    fn fill(&mut self, a: &SpringMatrix) {
        let (m, omax) = (self.n + self.omax, self.omax);
        let blocks = SharedMut(self.blocks.as_mut_ptr());
        let (by_band, start, place) = (&self.by_band, &self.band_start, &self.place);
        kernels::for_each_chunk(self.offsets.len(), |b| {
            // SAFETY: band `b`'s six columns, within `blocks` (`6 · bands · m` long), written
            // by this job alone.
            let cols = unsafe { blocks.slice(6 * b * m..6 * (b + 1) * m) };
            cols.fill(0.0);
            for &k in &by_band[start[b] as usize..start[b + 1] as usize] {
                let (o, p) = (&a.off[k as usize], place[k as usize].1 as usize);
                let v = [
                    o.x_axis.x, o.y_axis.y, o.z_axis.z, o.x_axis.y, o.x_axis.z, o.y_axis.z,
                ];
                for (c, v) in v.into_iter().enumerate() {
                    cols[c * m + omax + p] += v;
                }
            }
        });
    }

    /// The chunks' columns of positions, for the products of one solve's pass: the caller
    /// holds them while the pass's chunks run.
    pub(crate) fn columns(&self) -> MutexGuard<'_, Vec<Scalar>> {
        let mut columns = self.columns.0.lock().unwrap_or_else(|e| e.into_inner());
        let len = self.columns_len();
        if columns.len() < len {
            columns.resize(len, 0.0);
        }
        columns
    }

    /// Length of the chunks' columns of positions: three columns of a chunk's rows and the
    /// `omax` on either side, for each chunk.
    fn columns_len(&self) -> usize {
        if !self.usable {
            return 0;
        }
        let (size, chunks) = super::chunking(self.n);
        3 * (size + 2 * self.omax) * chunks
    }

    /// Slot `p`'s block of band `b` (`p ≥ −omax`, given as `p + omax`) times `v`:
    /// `(b_xx v_x + b_xy v_y) + b_xz v_z`, and so on.
    #[inline(always)]
    fn term(&self, b: usize, p_omax: usize, v: Vector) -> Vector {
        let m = self.n + self.omax;
        let c = |k: usize| self.blocks[(6 * b + k) * m + p_omax];
        let (xx, yy, zz, xy, xz, yz) = (c(0), c(1), c(2), c(3), c(4), c(5));
        Vector::new(
            (xx * v.x + xy * v.y) + xz * v.z,
            (xy * v.x + yy * v.y) + yz * v.z,
            (xz * v.x + yz * v.y) + zz * v.z,
        )
    }

    /// `(A x)_p` one row at a time: the reference the lanes give the bits of. Every band adds
    /// both its terms to every row, a term past either end of the system a zero block times
    /// a zero vector (as the lanes read them from the padding).
    pub(crate) fn row_times(&self, a: &SpringMatrix, p: usize, x: &[Vector]) -> Vector {
        let (n, omax) = (self.n, self.omax);
        let at = |q: usize| if q < n { x[q] } else { Vector::ZERO };
        let (mut s0, mut s1) = (Vector::ZERO, Vector::ZERO);
        for (b, &o) in self.offsets.iter().enumerate() {
            s0 += self.term(b, omax + p, at(p + o));
            let below = p.checked_sub(o).map_or(Vector::ZERO, at);
            s1 += self.term(b, omax + p - o, below);
        }
        a.diag[p] * x[p] + (s0 + s1)
    }

    /// `put(p, (A x)_p)` for the rows `r` (a chunk of [`super::chunking`]), `a` the matrix
    /// last [`update`](Self::update)d, which said the copy serves it.
    ///
    /// # Safety
    /// `columns` is the copy's [`columns`](Self::columns), held for the pass, of which this
    /// chunk alone uses its own part.
    pub(crate) unsafe fn rows_times(
        &self,
        a: &SpringMatrix,
        r: Range<usize>,
        x: &[Vector],
        columns: *mut Scalar,
        put: &mut impl FnMut(usize, Vector),
    ) {
        assert!(
            self.usable && self.structure == a.structure && self.n == a.len() && x.len() >= a.len(),
            "the band copy does not serve this product"
        );
        #[allow(unused_mut)]
        let mut p = r.start;
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: AVX is present; as the caller guarantees.
            p = unsafe { self.lanes(a, r.clone(), x, columns, put) };
        }
        for p in p..r.end {
            put(p, self.row_times(a, p, x));
        }
    }

    /// [`Self::rows_times`]'s rows in AVX lanes, as far as whole registers of rows go;
    /// returns the first row left.
    ///
    /// # Safety
    /// AVX is present; as for [`Self::rows_times`].
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn lanes(
        &self,
        a: &SpringMatrix,
        r: Range<usize>,
        x: &[Vector],
        columns: *mut Scalar,
        put: &mut impl FnMut(usize, Vector),
    ) -> usize {
        let (n, omax) = (self.n, self.omax);
        let (size, _) = super::chunking(n);
        let t1 = r.start + r.len() / LANES * LANES;
        if t1 == r.start {
            return r.start;
        }
        // The positions of rows `r.start − omax..t1 + omax` in this chunk's columns, zeros
        // past the system's ends: row `t` at `t − r.start + omax`.
        let w = size + 2 * omax;
        let m = t1 - r.start + 2 * omax;
        // SAFETY: the chunk's own three columns of `w ≥ m` (the caller's promise).
        let (xs, ys, zs) = unsafe {
            let base = columns.add(3 * w * (r.start / size));
            let col = |k: usize| std::slice::from_raw_parts_mut(base.add(k * w), m);
            (col(0), col(1), col(2))
        };
        let (from, to) = (r.start.saturating_sub(omax), (t1 + omax).min(n));
        let lead = from + omax - r.start;
        for c in [&mut *xs, &mut *ys, &mut *zs] {
            c[..lead].fill(0.0);
            c[lead + to - from..].fill(0.0);
        }
        crate::core::kernels::bands::to_columns(
            &x[from..to],
            &mut xs[lead..lead + to - from],
            &mut ys[lead..lead + to - from],
            &mut zs[lead..lead + to - from],
        );
        for t in (r.start..t1).step_by(LANES) {
            // SAFETY: every band's slots `t ± o` (`t − o ≥ −omax`, `t + LANES ≤ n`) and the
            // columns' places `t ± o − r.start + omax` (within `0..m`) are within their
            // columns.
            let s = unsafe { self.lane_sums(t, t - r.start + omax, [&*xs, &*ys, &*zs]) };
            for (q, s) in s.into_iter().enumerate() {
                let p = t + q;
                put(p, a.diag[p] * x[p] + s);
            }
        }
        t1
    }

    /// Rows `t..t + LANES`'s two sums added, in lanes; `c` is row `t`'s place in the columns
    /// `xyz`.
    ///
    /// # Safety
    /// AVX is present; `t + LANES ≤ n`, and the columns hold `c − omax..c + omax + LANES`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn lane_sums(&self, t: usize, c: usize, xyz: [&[Scalar]; 3]) -> [Vector; LANES] {
        #[cfg(not(feature = "f64"))]
        use std::arch::x86_64::{
            __m256 as R, _mm256_add_ps as add, _mm256_loadu_ps as load, _mm256_mul_ps as mul,
            _mm256_setzero_ps as zero,
        };
        #[cfg(feature = "f64")]
        use std::arch::x86_64::{
            __m256d as R, _mm256_add_pd as add, _mm256_loadu_pd as load, _mm256_mul_pd as mul,
            _mm256_setzero_pd as zero,
        };
        let m = self.n + self.omax;
        let (mut s0, mut s1) = ([zero(); 3], [zero(); 3]);
        // SAFETY: within the columns, as the caller guarantees.
        let ld = |s: &[Scalar], at: usize| unsafe { load(s.as_ptr().add(at)) };
        let add3 = |s: [R; 3], u: [R; 3]| [add(s[0], u[0]), add(s[1], u[1]), add(s[2], u[2])];
        for (b, &o) in self.offsets.iter().enumerate() {
            let term = |slot: usize, at: usize| {
                let k = |k: usize| ld(&self.blocks, (6 * b + k) * m + slot);
                let (xx, yy, zz, xy, xz, yz) = (k(0), k(1), k(2), k(3), k(4), k(5));
                let (vx, vy, vz) = (ld(xyz[0], at), ld(xyz[1], at), ld(xyz[2], at));
                let dot = |p: R, q: R, w: R| add(add(mul(p, vx), mul(q, vy)), mul(w, vz));
                [dot(xx, xy, xz), dot(xy, yy, yz), dot(xz, yz, zz)]
            };
            s0 = add3(s0, term(self.omax + t, c + o));
            s1 = add3(s1, term(self.omax + t - o, c - o));
        }
        let s = add3(s0, s1);
        #[cfg(not(feature = "f64"))]
        {
            crate::core::kernels::avx::rows(s[0], s[1], s[2]).map(Vector::from)
        }
        #[cfg(feature = "f64")]
        {
            let rows = crate::core::kernels::avx::rows3(s[0], s[1], s[2]);
            let mut v = [0.0; 12];
            for (k, r) in rows.into_iter().enumerate() {
                // SAFETY: four f64s into the array's `4 k..4 k + 4`.
                unsafe { std::arch::x86_64::_mm256_storeu_pd(v.as_mut_ptr().add(4 * k), r) };
            }
            std::array::from_fn(|q| Vector::new(v[3 * q], v[3 * q + 1], v[3 * q + 2]))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Partials, Product, SpringMatrix};
    use super::*;
    use crate::math::Matrix3;

    /// A `w × w` grid's pairs at the offsets of a cloth's springs (structural, shear,
    /// bending), with one in eight left out and a few pairs twice, in an order that mixes
    /// orientations; random symmetric blocks of magnitudes from 10⁻³ to 10³, random diagonal
    /// blocks.
    fn grid(w: u32, seed: u64) -> SpringMatrix {
        let mut seed = seed;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut pairs = Vec::new();
        for p in 0..w * w {
            for o in [1, 2, w - 1, w, w + 1, 2 * w] {
                if p + o < w * w && rnd() > 0.125 {
                    let pair = if rnd() < 0.5 { (p, p + o) } else { (p + o, p) };
                    pairs.push(pair);
                    if rnd() < 0.01 {
                        pairs.push(pair);
                    }
                }
            }
        }
        let n = (w * w) as usize;
        let k = pairs.len();
        let mut a = SpringMatrix::with_pairs(n, pairs).with_symmetric_prefix(k);
        let mut v = |s: f64| ((rnd() - 0.5) * s) as Scalar;
        for o in a.off.iter_mut() {
            let s = 10f64.powi((v(6.0) as i32).clamp(-3, 3));
            let (xx, yy, zz, xy, xz, yz) = (v(s), v(s), v(s), v(s), v(s), v(s));
            *o = Matrix3::from_cols(
                Vector::new(xx, xy, xz),
                Vector::new(xy, yy, yz),
                Vector::new(xz, yz, zz),
            );
        }
        for d in a.diag.iter_mut() {
            *d = Matrix3::from_cols(
                Vector::new(v(10.0), v(1.0), v(1.0)),
                Vector::new(v(1.0), v(10.0), v(1.0)),
                Vector::new(v(1.0), v(1.0), v(10.0)),
            );
        }
        a
    }

    #[allow(clippy::unnecessary_cast)] // f32 in one build, f64 in the other
    fn bits(y: &[Vector]) -> Vec<[u64; 3]> {
        y.iter()
            .map(|v| [v.x as f64, v.y as f64, v.z as f64].map(f64::to_bits))
            .collect()
    }

    /// The band product (in lanes where the processor has AVX, on one, two and three
    /// threads) gives the bits of its rows one by one, and the matrix's product by rows to
    /// round-off: grids of 37² (rows not a whole number of lanes) and 70² (five chunks),
    /// refilled with new values.
    #[test]
    fn band_product_is_its_rows_bit_for_bit_and_the_matrix_to_round_off() {
        for (w, seed) in [(37u32, 3u64), (70, 5)] {
            let mut a = grid(w, seed);
            let n = a.len();
            let mut copy = BandCopy::default();
            assert!(copy.update_from(&a, 0), "a grid's springs make bands");
            assert_eq!(
                copy.offsets,
                [1, 2, w - 1, w, w + 1, 2 * w].map(|o| o as usize)
            );
            let x: Vec<Vector> = (0..n)
                .map(|p| {
                    let p = p as Scalar;
                    Vector::new((p * 0.37).sin(), (p * 0.11).cos(), p * 1e-3 - 0.5)
                })
                .collect();
            for round in 0..2 {
                let reference: Vec<Vector> = (0..n).map(|p| copy.row_times(&a, p, &x)).collect();
                for threads in [1, 2, 3] {
                    let mut y = vec![Vector::ZERO; n];
                    crate::core::kernels::with_threads(threads, || {
                        Product::Bands(&a, &copy).mul_map(&x, &mut y, |_, v| v, None);
                    });
                    assert_eq!(bits(&y), bits(&reference), "{w}², {threads} threads");
                }
                // Against the matrix by rows, each row within a few units of the largest
                // term's magnitude (another order of the same sums).
                let mut rows = vec![Vector::ZERO; n];
                Product::Rows(&a).mul_map(&x, &mut rows, |_, v| v, None);
                let mut scale = vec![0.0f64; n];
                for (o, &(i, j)) in a.off.iter().zip(&a.pairs) {
                    let m = (o.abs().x_axis + o.abs().y_axis + o.abs().z_axis).max_element() as f64;
                    let (i, j) = (i as usize, j as usize);
                    scale[i] = scale[i].max(m * x[j].abs().max_element() as f64);
                    scale[j] = scale[j].max(m * x[i].abs().max_element() as f64);
                }
                for p in 0..n {
                    let d = a.diag[p].abs();
                    let m = (d.x_axis + d.y_axis + d.z_axis).max_element() as f64;
                    let s = scale[p].max(m * x[p].abs().max_element() as f64);
                    // 40 terms at most a row, each rounded a few times.
                    let bound = 64.0 * Scalar::EPSILON as f64 * s * 3.0;
                    let e = (rows[p] - reference[p]).abs().max_element() as f64;
                    assert!(e <= bound, "{w}² row {p}: {e} > {bound} (round {round})");
                }
                // New values, the same structure: refilled, not re-analysed.
                for o in a.off.iter_mut() {
                    *o *= -0.75;
                }
                assert!(copy.update_from(&a, 0));
            }
        }
    }

    /// A clone of a usable copy (a solver cloned with its body) serves the same products,
    /// with the same bits.
    #[test]
    fn a_clone_of_the_copy_serves_the_same_products() {
        let a = grid(40, 17);
        let n = a.len();
        let mut copy = BandCopy::default();
        assert!(copy.update_from(&a, 0));
        let mut clone = copy.clone();
        assert!(clone.update_from(&a, 0));
        let x: Vec<Vector> = (0..n).map(|p| Vector::splat(p as Scalar * 0.01)).collect();
        let (mut y1, mut y2) = (vec![Vector::ZERO; n], vec![Vector::ZERO; n]);
        Product::Bands(&a, &copy).mul_map(&x, &mut y1, |_, v| v, None);
        Product::Bands(&a, &clone).mul_map(&x, &mut y2, |_, v| v, None);
        assert_eq!(bits(&y1), bits(&y2));
    }

    /// A dot product through the band product sums as the solver's do (per chunk, then in
    /// order): the same on any number of threads.
    #[test]
    fn band_product_dot_is_the_same_on_any_number_of_threads() {
        let a = grid(70, 11);
        let n = a.len();
        let mut copy = BandCopy::default();
        assert!(copy.update_from(&a, 0));
        let x: Vec<Vector> = (0..n)
            .map(|p| Vector::splat((p as Scalar).sqrt()))
            .collect();
        let dots: Vec<u64> = [1, 2]
            .map(|threads| {
                let mut y = vec![Vector::ZERO; n];
                let partials = Partials::default();
                let d = crate::core::kernels::with_threads(threads, || {
                    Product::Bands(&a, &copy).mul_map(&x, &mut y, |_, v| v, Some(&partials))
                });
                (d as f64).to_bits()
            })
            .to_vec();
        assert_eq!(dots[0], dots[1]);
    }

    /// Matrices that are not a structured mesh's springs are left to the other products: a
    /// random network (too many offsets), a tet's unsymmetric blocks, a pair of a row with
    /// itself.
    #[test]
    fn other_matrices_are_not_taken() {
        let n = 500u32;
        let pairs: Vec<(u32, u32)> = (0..n).map(|i| (i, (i * 7919 + 13) % n)).collect();
        let k = pairs.len();
        let random = SpringMatrix::with_pairs(n as usize, pairs).with_symmetric_prefix(k);
        assert!(!BandCopy::default().update_from(&random, 0));
        let mut tet = grid(20, 7);
        let k = tet.pairs.len();
        tet = SpringMatrix::with_pairs(tet.len(), tet.pairs.clone()).with_symmetric_prefix(k - 1);
        assert!(!BandCopy::default().update_from(&tet, 0));
        let mut pairs = grid(20, 7).pairs.clone();
        pairs.push((5, 5));
        let k = pairs.len();
        let own = SpringMatrix::with_pairs(400, pairs).with_symmetric_prefix(k);
        assert!(!BandCopy::default().update_from(&own, 0));
        // A grid below the size the copy takes.
        assert!(!BandCopy::default().update(&grid(90, 13)));
        assert!(BandCopy::default().update(&grid(91, 13)));
    }
}
