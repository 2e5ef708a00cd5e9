//! Linear algebra for implicit steps: a symmetric block-sparse matrix with the sparsity of a
//! spring network, preconditioned conjugate gradients with Baraff–Witkin's constraint filter,
//! and a sparse direct (Cholesky) solve through faer.
//!
//! The conjugate gradients' work runs in chunks of rows ([`CHUNK_ROWS`]) shared with the team
//! of threads the caller runs in ([`kernels::with_threads`]): the matrix product by rows
//! (each off-diagonal block used from both its rows, so no row is written by two chunks), the
//! vector updates, the multigrid's finest level, and the dot products summed per chunk and
//! then over the chunks in order. The chunks depend on the system's size alone, so a solve
//! gives the same bits on any number of threads. Where the processor has AVX, the products of
//! matrices whose blocks are all symmetric (springs') run eight rows (four in `f64`) at a time
//! from a packed copy of the blocks (`packed`), with the same bits as by rows. A structured
//! mesh's springs (a grid cloth's: a few offsets between their particles) take a band copy
//! instead (`bands`): each block stored once by offset, the rows read in lanes, its own order
//! of the sums, the same bits on every machine.

pub(crate) mod bands;
pub(crate) mod cholesky;
pub mod multigrid;
pub(crate) mod packed;
pub mod rows;

pub use cholesky::SparseCholesky;
pub use multigrid::Multigrid;
pub use rows::PointRows;

use crate::core::forces::Springs;
use crate::core::kernels::{self, SharedMut};
use crate::math::{Matrix3, Scalar, Vector};
use std::ops::Range;
use std::sync::Mutex;

/// Rows per chunk of the solvers' passes (the matrix product and the vector updates), shared
/// with the team of threads the caller runs in (see [`kernels::with_threads`]): at most this
/// many, cut by the system's size alone, so the results are the same bits on any number of
/// threads. Smaller under Miri.
pub const CHUNK_ROWS: usize = crate::core::kernels::chunk_limit(1024, 64);

/// Marks a row entry that uses its off-diagonal block at `(j, i)`: transposed, unless the
/// block is symmetric.
const AT_JI: u32 = 1 << 31;

/// The matrix's rows: for each block row, its off-diagonal blocks and their columns, sorted
/// by column. Each pair's block appears in both its rows, so a row's product is a sum over
/// its own entries and every row is written by one chunk alone: no scatter, no thread
/// writes another's rows, and the sum's order is fixed.
#[derive(Clone, Debug, Default)]
struct Rows {
    start: Vec<u32>,
    /// The block of each entry (its index in `off`, with [`AT_JI`] when this row is the
    /// pair's `j`).
    block: Vec<u32>,
    col: Vec<u32>,
}

impl Rows {
    fn new(n: usize, pairs: &[(u32, u32)]) -> Self {
        assert!(
            pairs.len() < AT_JI as usize && 2 * pairs.len() < u32::MAX as usize,
            "too many off-diagonal blocks"
        );
        let mut start = vec![0u32; n + 1];
        for &(i, j) in pairs {
            assert!(
                (i as usize) < n && (j as usize) < n,
                "block ({i}, {j}) outside a matrix of {n} block rows"
            );
            start[i as usize + 1] += 1;
            start[j as usize + 1] += 1;
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        let mut entries = vec![(0u32, 0u32); start[n] as usize];
        let mut fill = start.clone();
        for (k, &(i, j)) in pairs.iter().enumerate() {
            let k = k as u32;
            for (row, e) in [(i, (j, k)), (j, (i, k | AT_JI))] {
                entries[fill[row as usize] as usize] = e;
                fill[row as usize] += 1;
            }
        }
        for i in 0..n {
            entries[start[i] as usize..start[i + 1] as usize].sort_unstable();
        }
        let (col, block) = entries.into_iter().unzip();
        Self { start, block, col }
    }
}

/// Per-chunk partial sums for the solvers' dot products (cloned empty: scratch).
#[derive(Debug, Default)]
pub(crate) struct Partials(pub(crate) Mutex<Vec<f64>>);

impl Clone for Partials {
    fn clone(&self) -> Self {
        Self::default()
    }
}

/// `items` grouped by key (below `groups`), each group in the items' order (a stable counting
/// sort): group `g` is `list[start[g]..start[g + 1]]`; returns `(start, list)`.
pub(crate) fn group_by(
    groups: usize,
    items: impl Iterator<Item = (usize, u32)> + Clone,
) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; groups + 1];
    for (g, _) in items.clone() {
        start[g + 1] += 1;
    }
    for g in 0..groups {
        start[g + 1] += start[g];
    }
    let mut list = vec![0; start[groups] as usize];
    let mut fill = start.clone();
    for (g, item) in items {
        list[fill[g] as usize] = item;
        fill[g] += 1;
    }
    (start, list)
}

/// The chunking of a system of `n` rows for the solvers' passes: `(rows per chunk, chunks)`.
pub(crate) fn chunking(n: usize) -> (usize, usize) {
    // Whole groups of the packed product's lanes.
    let size = kernels::chunk_size(n, CHUNK_ROWS).next_multiple_of(packed::LANES);
    (size, n.div_ceil(size))
}

/// Runs `job(r)` for each chunk of rows `r` of a system of `n` rows ([`chunking`]), on the
/// team.
pub(crate) fn for_each_rows(n: usize, job: impl Fn(Range<usize>) + Sync + Send) {
    kernels::for_each_range(n, chunking(n).0, job);
}

/// `Σ_i part(i)` over each chunk's rows, summed per chunk and then over the chunks in order
/// (the same bits on any number of threads), `K` sums at once.
pub(crate) fn sum_rows<const K: usize>(
    partials: &Partials,
    n: usize,
    part: impl Fn(Range<usize>) -> [Scalar; K] + Sync + Send,
) -> [Scalar; K] {
    let (size, chunks) = chunking(n);
    kernels::sums_chunks(&partials.0, chunks, |c| {
        part(c * size..((c + 1) * size).min(n)).map(|v| v as f64)
    })
    .map(|v| v as Scalar)
}

/// A symmetric matrix of 3×3 blocks: one diagonal block per particle and one off-diagonal block
/// per pair `(i, j)` — each spring, then each tet edge — stored as the block at row `i`,
/// column `j` and used transposed at `(j, i)` (a spring's block is itself symmetric; a tet
/// edge's need not be). The structure is built once per topology; the values are refilled
/// every step.
#[derive(Clone, Debug, Default)]
pub struct SpringMatrix {
    /// Diagonal blocks.
    pub diag: Vec<Matrix3>,
    /// Off-diagonal block of each spring.
    pub off: Vec<Matrix3>,
    pairs: Vec<(u32, u32)>,
    /// The first this many off-diagonal blocks are symmetric (springs' blocks: `α n nᵀ + β I`,
    /// symmetric to the bit), so [`mul`](Self::mul) uses them untransposed at `(j, i)`: a
    /// column-wise product, where a transposed one costs three dot products (about half of a
    /// PCG iteration's time on a cloth).
    symmetric: usize,
    rows: Rows,
    /// Names the structure (a number no other structure built by this process has), so that
    /// copies made of it know when it changes.
    structure: u64,
    /// Each spring's vector of the last [`fill_springs`](Self::fill_springs) (scratch).
    edge: Vec<Vector>,
    /// The [`Springs::stamp`] of the springs [`matches`](Self::matches) last found this
    /// structure in (0: none).
    seen: Seen,
}

/// A stamp remembered through `&self` (the matrix is shared with the team while it is
/// checked), cloned with its value.
#[derive(Debug, Default)]
struct Seen(std::sync::atomic::AtomicU64);

impl Clone for Seen {
    fn clone(&self) -> Self {
        Self(self.get().into())
    }
}

impl Seen {
    fn get(&self) -> u64 {
        self.0.load(std::sync::atomic::Ordering::Relaxed)
    }
}

/// The next [`SpringMatrix::structure`].
fn next_structure() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

impl SpringMatrix {
    /// A zero matrix for `n` particles with the structure of `springs`.
    pub fn new(n: usize, springs: &Springs) -> Self {
        Self::with_pairs(n, springs.as_slice().iter().map(|s| (s.i, s.j)).collect())
            .with_symmetric_prefix(springs.len())
    }

    /// A zero matrix for `n` particles with off-diagonal blocks at `pairs`.
    ///
    /// # Panics
    /// If a pair names a row past `n`.
    pub fn with_pairs(n: usize, pairs: Vec<(u32, u32)>) -> Self {
        Self {
            diag: vec![Matrix3::ZERO; n],
            off: vec![Matrix3::ZERO; pairs.len()],
            rows: Rows::new(n, &pairs),
            pairs,
            symmetric: 0,
            structure: next_structure(),
            edge: vec![],
            seen: Seen::default(),
        }
    }

    /// Declares the first `k` off-diagonal blocks symmetric (whoever fills them keeps them
    /// so): [`mul`](Self::mul) then skips their transpose.
    pub fn with_symmetric_prefix(mut self, k: usize) -> Self {
        self.symmetric = k.min(self.off.len());
        self.structure = next_structure();
        self
    }

    /// True when this matrix has `n` block rows and off-diagonal blocks at `pairs`.
    pub fn matches_pairs(&self, n: usize, pairs: impl Iterator<Item = (u32, u32)>) -> bool {
        self.diag.len() == n && self.pairs.iter().copied().eq(pairs)
    }

    /// True when this matrix has the structure of `springs` over `n` particles: springs
    /// whose [`stamp`](Springs::stamp) this matrix matched last are taken at once; others are
    /// compared pair by pair (and their stamp remembered when they match).
    pub fn matches(&self, n: usize, springs: &Springs) -> bool {
        if self.diag.len() != n {
            return false;
        }
        let stamp = springs.stamp();
        if stamp != 0 && self.seen.get() == stamp {
            return true;
        }
        let same = self.pairs.len() == springs.len()
            && self
                .pairs
                .iter()
                .zip(springs.as_slice())
                .all(|(p, s)| p.0 == s.i && p.1 == s.j);
        if same {
            self.seen
                .0
                .store(stamp, std::sync::atomic::Ordering::Relaxed);
        }
        same
    }

    /// Number of block rows.
    pub fn len(&self) -> usize {
        self.diag.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.diag.is_empty()
    }

    /// The spring (block) index pairs.
    pub fn pairs(&self) -> &[(u32, u32)] {
        &self.pairs
    }

    /// How many leading off-diagonal blocks are symmetric (see
    /// [`with_symmetric_prefix`](Self::with_symmetric_prefix)).
    pub fn symmetric_prefix(&self) -> usize {
        self.symmetric
    }

    /// `y ← A x`, by rows, in chunks of [`CHUNK_ROWS`] shared with the team the caller runs in
    /// (the same bits on any number of threads).
    ///
    /// # Panics
    /// If `x` or `y` is shorter than the matrix.
    pub fn mul(&self, x: &[Vector], y: &mut [Vector]) {
        self.mul_map(x, y, |_, ax| ax, None);
    }

    /// `y_i ← f(i, (A x)_i)` for every row, as [`mul`](Self::mul) runs; with `dot`, returns
    /// `Σ_i x_i · y_i` (summed per chunk, then over the chunks in order), else zero.
    pub(crate) fn mul_map(
        &self,
        x: &[Vector],
        y: &mut [Vector],
        f: impl Fn(usize, Vector) -> Vector + Sync + Send,
        dot: Option<&Partials>,
    ) -> Scalar {
        Product::Rows(self).mul_map(x, y, f, dot)
    }

    /// `(A x)_i`: the row's entries in column order, summed into two partial sums by their
    /// place in the row (even, odd: two independent chains of additions), then the diagonal
    /// block's product and the two sums added.
    #[inline]
    fn row_times(&self, i: usize, x: &[Vector]) -> Vector {
        let rows = &self.rows;
        let (a, b) = (rows.start[i] as usize, rows.start[i + 1] as usize);
        let (block, col) = (&rows.block[a..b], &rows.col[a..b]);
        let mut s = [Vector::ZERO; 2];
        if self.symmetric == self.off.len() {
            let off = &self.off[..];
            let mut e = 0;
            while e + 2 <= block.len() {
                for q in 0..2 {
                    let (k, c) = ((block[e + q] & !AT_JI) as usize, col[e + q] as usize);
                    s[q] += off[k] * x[c];
                }
                e += 2;
            }
            if e < block.len() {
                let (k, c) = ((block[e] & !AT_JI) as usize, col[e] as usize);
                s[0] += off[k] * x[c];
            }
        } else {
            let sym = self.symmetric as u32;
            for (e, (&k, &c)) in block.iter().zip(col).enumerate() {
                let (o, xc) = (&self.off[(k & !AT_JI) as usize], x[c as usize]);
                s[e & 1] += if k & AT_JI == 0 || (k & !AT_JI) < sym {
                    *o * xc
                } else {
                    // (oᵀ x)_k = col_k · x
                    Vector::new(o.x_axis.dot(xc), o.y_axis.dot(xc), o.z_axis.dot(xc))
                };
            }
        }
        self.diag[i] * x[i] + (s[0] + s[1])
    }

    /// Fills the springs' part of the matrix on the team the caller runs in: the first
    /// `springs` off-diagonal blocks (the springs', symmetric) are `−B_k` and each spring's
    /// vector `u_k`, from `spring(k) = (B_k, u_k)`, in chunks of springs; then each diagonal
    /// block is `diag(i) + Σ B_k` over the row's springs and, with `kv`, `kv_i = Σ ∓u_k`
    /// (`−` where the row is the spring's `i`, `+` where it is its `j`), in chunks of rows,
    /// each row's sums in its entries' (column) order. Every block and row is written by one
    /// chunk alone, so the bits are the same on any number of threads; the blocks of other
    /// pairs (tet edges) are left alone.
    pub(crate) fn fill_springs(
        &mut self,
        springs: usize,
        diag: impl Fn(usize) -> Matrix3 + Sync + Send,
        spring: impl Fn(usize) -> (Matrix3, Vector) + Sync + Send,
        kv: Option<&mut [Vector]>,
    ) {
        debug_assert!(
            springs <= self.symmetric,
            "springs past the symmetric blocks"
        );
        let springs = springs.min(self.symmetric);
        let n = self.len();
        let with_kv = kv.is_some();
        assert!(
            kv.as_ref().is_none_or(|kv| kv.len() >= n),
            "kv shorter than the matrix"
        );
        if with_kv {
            self.edge.resize(springs, Vector::ZERO);
        }
        let (off, edge) = (
            SharedMut(self.off.as_mut_ptr()),
            SharedMut(self.edge.as_mut_ptr()),
        );
        kernels::for_each_range(springs, kernels::chunk_size(springs, CHUNK_ROWS), |r| {
            // SAFETY: disjoint ranges of `off` and `edge`, within their first `springs`.
            let off = unsafe { off.slice(r.clone()) };
            if with_kv {
                // SAFETY: as above.
                let edge = unsafe { edge.slice(r.clone()) };
                for ((o, u), k) in off.iter_mut().zip(edge).zip(r) {
                    let (b, v) = spring(k);
                    (*o, *u) = (-b, v);
                }
            } else {
                for (o, k) in off.iter_mut().zip(r) {
                    *o = -spring(k).0;
                }
            }
        });
        let (dp, kvp) = (
            SharedMut(self.diag.as_mut_ptr()),
            SharedMut(kv.map_or(std::ptr::null_mut(), <[Vector]>::as_mut_ptr)),
        );
        let (rows, off, edge) = (&self.rows, &self.off, &self.edge);
        for_each_rows(n, |r| {
            // SAFETY: disjoint ranges of the diagonal and of `kv` (as long as the matrix when
            // given).
            let d = unsafe { dp.slice(r.clone()) };
            let mut kv = with_kv.then(|| unsafe { kvp.slice(r.clone()) });
            for (k, i) in r.enumerate() {
                let (mut di, mut ui) = (diag(i), Vector::ZERO);
                for e in rows.start[i] as usize..rows.start[i + 1] as usize {
                    let b = (rows.block[e] & !AT_JI) as usize;
                    if b < springs {
                        di -= off[b];
                        if with_kv {
                            if rows.block[e] & AT_JI == 0 {
                                ui -= edge[b];
                            } else {
                                ui += edge[b];
                            }
                        }
                    }
                }
                d[k] = di;
                if let Some(kv) = kv.as_deref_mut() {
                    kv[k] = ui;
                }
            }
        });
    }

    /// The dense matrix (row-major, `3n × 3n`), for tests and small systems.
    pub fn to_dense(&self) -> Vec<Vec<f64>> {
        let n = 3 * self.len();
        let mut a = vec![vec![0.0; n]; n];
        let mut put = |bi: usize, bj: usize, m: &Matrix3| {
            for r in 0..3 {
                for c in 0..3 {
                    a[3 * bi + r][3 * bj + c] += m.col(c)[r] as f64;
                }
            }
        };
        for (i, d) in self.diag.iter().enumerate() {
            put(i, i, d);
        }
        for (o, &(i, j)) in self.off.iter().zip(&self.pairs) {
            put(i as usize, j as usize, o);
            put(j as usize, i as usize, &o.transpose());
        }
        a
    }
}

/// A matrix's product as the solvers run it: by rows, or from the packed copy of its blocks
/// in AVX lanes ([`packed`]); the two give the same bits.
#[derive(Clone, Copy)]
pub(crate) enum Product<'a> {
    /// [`SpringMatrix::row_times`], row by row.
    Rows(&'a SpringMatrix),
    /// The packed copy, eight rows at a time (the copy said it serves the matrix).
    Packed(&'a SpringMatrix, &'a packed::Packed),
    /// The band copy of a structured mesh's springs (the copy said it serves the matrix):
    /// its own order of the sums, the same on every machine.
    Bands(&'a SpringMatrix, &'a bands::BandCopy),
}

impl<'a> Product<'a> {
    /// The packed product when `packed` (just updated from `a`) serves it, else by rows.
    pub(crate) fn of(a: &'a SpringMatrix, packed: &'a packed::Packed, usable: bool) -> Self {
        if usable {
            Product::Packed(a, packed)
        } else {
            Product::Rows(a)
        }
    }

    /// The matrix.
    pub(crate) fn matrix(self) -> &'a SpringMatrix {
        match self {
            Product::Rows(a) | Product::Packed(a, _) | Product::Bands(a, _) => a,
        }
    }

    /// `y_i ← f(i, (A x)_i)` for every row, in chunks of [`CHUNK_ROWS`] on the team; with
    /// `dot`, returns `Σ_i x_i · y_i` (summed per chunk, then over the chunks in order), else
    /// zero.
    ///
    /// # Panics
    /// If `x` or `y` is shorter than the matrix, or the matrix's structure changed after it
    /// was built (its public block vectors resized).
    pub(crate) fn mul_map(
        self,
        x: &[Vector],
        y: &mut [Vector],
        f: impl Fn(usize, Vector) -> Vector + Sync + Send,
        dot: Option<&Partials>,
    ) -> Scalar {
        let a = self.matrix();
        let n = a.len();
        assert!(
            x.len() >= n && y.len() >= n,
            "vectors shorter than the matrix"
        );
        assert!(
            a.rows.start.len() == n + 1 && a.off.len() == a.pairs.len(),
            "the matrix's structure changed after it was built"
        );
        let yp = SharedMut(y.as_mut_ptr());
        // The band copy's columns of positions, each chunk its own part, held for the pass.
        let mut columns = match self {
            Product::Bands(_, b) => Some(b.columns()),
            _ => None,
        };
        let cols = SharedMut(
            columns
                .as_mut()
                .map_or(std::ptr::null_mut(), |c| c.as_mut_ptr()),
        );
        let chunk = |r: Range<usize>| {
            // SAFETY: the chunks' ranges are disjoint and below `n ≤ y.len()`; `y` is
            // borrowed exclusively for the call.
            let y = unsafe { yp.slice(r.clone()) };
            let mut d: Scalar = 0.0;
            let mut put = |i: usize, ax: Vector| {
                let yi = f(i, ax);
                y[i - r.start] = yi;
                d += x[i].dot(yi);
            };
            match self {
                Product::Rows(a) => {
                    for i in r.clone() {
                        put(i, a.row_times(i, x));
                    }
                }
                Product::Packed(a, p) => p.rows_times(a, r.clone(), x, &mut put),
                // SAFETY: the columns are held for the pass; each chunk uses its own part.
                Product::Bands(a, b) => unsafe {
                    b.rows_times(a, r.clone(), x, cols.ptr(), &mut put)
                },
            }
            [d]
        };
        match dot {
            Some(p) => sum_rows(p, n, chunk)[0],
            None => {
                for_each_rows(n, |r| {
                    chunk(r);
                });
                0.0
            }
        }
    }
}

/// What a conjugate-gradient solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PcgReport {
    /// Iterations taken.
    pub iterations: u32,
    /// Final filtered residual norm relative to the filtered right-hand side.
    pub relative_residual: Scalar,
    /// True when the tolerance was met.
    pub converged: bool,
    /// True when the solve broke down: the matrix is not positive definite on the free
    /// degrees of freedom (a non-positive curvature or pivot), or a value is not finite. The
    /// solution must not be used.
    pub failed: bool,
}

/// What a linear solve did (both solvers report the same way; direct solves report zero
/// iterations).
pub type SolveReport = PcgReport;

/// Which linear solver an implicit method uses.
#[derive(Clone, Debug)]
pub enum LinearSolver {
    /// Preconditioned conjugate gradients (no factorization; block-Jacobi for small systems,
    /// aggregation multigrid for large ones: see [`Preconditioner`]).
    Pcg(Pcg),
    /// Sparse Cholesky `L Lᵀ` of the free degrees of freedom (faer; fill-reducing AMD
    /// ordering; symbolic factorization once per structure). Exact to round-off, for Newton
    /// steps that need accurate directions.
    Cholesky(Box<SparseCholesky>),
}

impl Default for LinearSolver {
    fn default() -> Self {
        LinearSolver::Pcg(Pcg::default())
    }
}

impl LinearSolver {
    /// The sparse Cholesky solver.
    pub fn cholesky() -> Self {
        LinearSolver::Cholesky(Box::default())
    }

    /// Solves `A x = b` on the free degrees of freedom (`mask[i] = 1`); entries with
    /// `mask[i] = 0` keep their value in `x` (and their coupling is moved to the right-hand
    /// side). `x` is the starting guess for PCG.
    pub fn solve(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
    ) -> SolveReport {
        match self {
            LinearSolver::Pcg(p) => p.solve(a, b, x, mask),
            LinearSolver::Cholesky(c) => c.solve(a, b, x, mask),
        }
    }

    /// [`LinearSolver::solve`] with some particles constrained along directions only
    /// (`filters`: a particle and the projector `S = I − Σ nₖnₖᵀ` onto the directions it is
    /// free in): [`Pcg::solve_filtered`], or the sparse Cholesky of the filtered system
    /// ([`SparseCholesky::solve_filtered`]).
    pub fn solve_filtered(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
    ) -> SolveReport {
        self.solve_constrained(a, b, x, mask, filters, &mut PointRows::default())
    }

    /// [`LinearSolver::solve_filtered`] with constraints on combinations of particles as
    /// well ([`PointRows`]: triangles held at their contact points):
    /// [`Pcg::solve_constrained`] or [`SparseCholesky::solve_constrained`].
    pub fn solve_constrained(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
        rows: &mut PointRows,
    ) -> SolveReport {
        match self {
            LinearSolver::Pcg(p) => p.solve_constrained(a, b, x, mask, filters, rows),
            LinearSolver::Cholesky(c) => c.solve_constrained(a, b, x, mask, filters, rows),
        }
    }

    /// Solves with the factorization of the last matrix solved (modified Newton); `None`
    /// when the solver keeps none (PCG) or has none for this structure and these filters.
    /// See [`SparseCholesky::resolve`].
    pub fn resolve(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
    ) -> Option<SolveReport> {
        self.resolve_constrained(a, b, x, mask, filters, &mut PointRows::default())
    }

    /// [`LinearSolver::resolve`] with constraints on combinations of particles as well
    /// ([`SparseCholesky::resolve_constrained`]).
    pub fn resolve_constrained(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
        rows: &mut PointRows,
    ) -> Option<SolveReport> {
        match self {
            LinearSolver::Pcg(_) => None,
            LinearSolver::Cholesky(c) => c.resolve_constrained(a, b, x, mask, filters, rows),
        }
    }

    /// A short name for tables.
    pub fn name(&self) -> &'static str {
        match self {
            LinearSolver::Pcg(_) => "pcg",
            LinearSolver::Cholesky(_) => "cholesky",
        }
    }
}

/// Preconditioned conjugate gradients ([`Preconditioner`]) for symmetric positive
/// definite [`SpringMatrix`] systems, with Baraff & Witkin's filter: degrees of freedom whose
/// mask is zero (pins, prescribed motion) keep their initial value and are projected out of
/// every residual and search direction, so the iteration stays in the SPD subspace of free
/// particles. Owns its scratch vectors.
#[derive(Clone, Debug)]
pub struct Pcg {
    /// Stop when `‖r‖ ≤ tolerance · ‖b‖` (filtered norms).
    pub tolerance: Scalar,
    /// Iteration cap.
    pub max_iterations: u32,
    /// The preconditioner.
    pub preconditioner: Preconditioner,
    /// The one the last solve used.
    active: Preconditioner,
    multigrid: Box<Multigrid>,
    r: Vec<Vector>,
    z: Vec<Vector>,
    p: Vec<Vector>,
    q: Vec<Vector>,
    inv_diag: Vec<Matrix3>,
    /// Boxed, and taken out for each solve (see [`Scratch`]).
    scratch: Option<Box<Scratch>>,
}

/// What a solve borrows while the preconditioner borrows the solver: the dot products'
/// partial sums and the packed copy of the matrix.
#[derive(Clone, Debug, Default)]
struct Scratch {
    partials: Partials,
    packed: packed::Packed,
    bands: bands::BandCopy,
}

impl Default for Pcg {
    fn default() -> Self {
        Self::new(1e-6, 500)
    }
}

/// A preconditioner for [`Pcg`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Preconditioner {
    /// [`Multigrid`](Preconditioner::Multigrid) for systems of at least
    /// [`MULTIGRID_MIN_PARTICLES`] particles, [`BlockJacobi`](Preconditioner::BlockJacobi)
    /// below.
    #[default]
    Auto,
    /// The inverse of each particle's 3×3 diagonal block: cheapest per iteration; the
    /// iterations grow with the resolution.
    BlockJacobi,
    /// An aggregation multigrid V-cycle ([`Multigrid`]): a few matrix products' work per
    /// iteration, and iteration counts that grow far more slowly with the resolution.
    Multigrid,
}

/// The size from which [`Preconditioner::Auto`] takes the multigrid. Measured on cloths
/// (linearly implicit Euler, h = 1/60, tolerance 1e-6; see `docs/BENCHMARKS.md`): the two
/// cost the same near 48² particles; block-Jacobi is 2.4× faster at 24², the multigrid 1.26×
/// at 64² and 1.9× at 128².
pub const MULTIGRID_MIN_PARTICLES: usize = 4096;

impl Preconditioner {
    /// The preconditioner used for a system of `n` particles.
    pub fn for_size(self, n: usize) -> Self {
        match self {
            Preconditioner::Auto if n >= MULTIGRID_MIN_PARTICLES => Preconditioner::Multigrid,
            Preconditioner::Auto => Preconditioner::BlockJacobi,
            p => p,
        }
    }
}

/// `d⁻¹`, the identity where the block is singular or not finite.
pub(crate) fn invert_block(d: &Matrix3) -> Matrix3 {
    if d.determinant().is_normal() {
        d.inverse()
    } else {
        Matrix3::IDENTITY
    }
}

/// `inv[i] ← diag[i]⁻¹` ([`invert_block`]).
fn invert_blocks(diag: &[Matrix3], inv: &mut Vec<Matrix3>) {
    inv.resize(diag.len(), Matrix3::IDENTITY);
    let out = SharedMut(inv.as_mut_ptr());
    for_each_rows(diag.len(), |rows| {
        // SAFETY: disjoint ranges of `inv`, which has the diagonal's length.
        let inv = unsafe { out.slice(rows.clone()) };
        for (inv, d) in inv.iter_mut().zip(&diag[rows]) {
            *inv = invert_block(d);
        }
    });
}

/// The filtered rows' preconditioning made symmetric: `zᵢ = Sᵢ Dᵢ⁻¹ Sᵢ rᵢ` with block-Jacobi's
/// `Dᵢ⁻¹`, where the fused update wrote `Dᵢ⁻¹ rᵢ`; returns the change in `r · z`. A
/// projector rounded to the precision is idempotent only to a few units in the last place,
/// so `r` strays from its range by as much: preconditioned as `S D⁻¹` the iteration is not
/// symmetric at that level, and a 32² cloth's solves on a rod stalled there and diverged
/// (measured, in `f64` arithmetic on the `f32` projectors). As `S D⁻¹ S` they converge.
fn symmetric_rows(
    filters: &[(u32, Matrix3)],
    inv: &[Matrix3],
    r: &[Vector],
    z: &mut [Vector],
) -> Scalar {
    let mut change = 0.0;
    for &(i, s) in filters {
        let i = i as usize;
        let zi = s * (inv[i] * (s * r[i]));
        change += r[i].dot(zi) - r[i].dot(z[i]);
        z[i] = zi;
    }
    change
}

/// `vᵢ ← Sᵢ vᵢ` for each filtered particle `(i, Sᵢ)`: the directions it stays free in (see
/// [`Pcg::solve_filtered`]).
pub(crate) fn filter_rows(filters: &[(u32, Matrix3)], v: &mut [Vector]) {
    for &(i, s) in filters {
        v[i as usize] = s * v[i as usize];
    }
}

/// `Σ a_i · b_i` over rows `r`.
fn dot(a: &[Vector], b: &[Vector], r: Range<usize>) -> Scalar {
    a[r.clone()].iter().zip(&b[r]).map(|(x, y)| x.dot(*y)).sum()
}

impl Pcg {
    /// The same solver with the given preconditioner.
    pub fn with_preconditioner(mut self, preconditioner: Preconditioner) -> Self {
        self.preconditioner = preconditioner;
        self
    }

    /// The preconditioner the last solve used.
    pub fn active_preconditioner(&self) -> Preconditioner {
        self.active
    }

    /// The multigrid preconditioner's state (its levels after a solve with it).
    pub fn multigrid(&self) -> &Multigrid {
        &self.multigrid
    }

    /// `z ← B r` for the preconditioner `B`.
    fn precondition(&mut self, a: Product<'_>, mask: &[Scalar]) {
        match self.active {
            Preconditioner::BlockJacobi => {
                let (z, inv, r) = (SharedMut(self.z.as_mut_ptr()), &self.inv_diag, &self.r);
                for_each_rows(a.matrix().len(), |rows| {
                    // SAFETY: disjoint ranges of `z`, which has the matrix's length.
                    let z = unsafe { z.slice(rows.clone()) };
                    for (z, i) in z.iter_mut().zip(rows) {
                        *z = inv[i] * r[i];
                    }
                });
            }
            _ => self.multigrid.apply_with(a, mask, &self.r, &mut self.z),
        }
    }

    /// A solver with relative tolerance `tolerance` and at most `max_iterations` iterations.
    pub fn new(tolerance: Scalar, max_iterations: u32) -> Self {
        Self {
            tolerance,
            max_iterations,
            preconditioner: Preconditioner::default(),
            active: Preconditioner::BlockJacobi,
            multigrid: Box::default(),
            r: vec![],
            z: vec![],
            p: vec![],
            q: vec![],
            inv_diag: vec![],
            scratch: None,
        }
    }

    /// Solves `A x = b` on the free degrees of freedom (`mask[i] = 1`) starting from `x`;
    /// entries with `mask[i] = 0` keep their value in `x`.
    ///
    /// # Panics
    /// If `b`, `x` or `mask` is shorter than the matrix.
    pub fn solve(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
    ) -> PcgReport {
        self.solve_filtered(a, b, x, mask, &[])
    }

    /// [`Pcg::solve`] with Baraff and Witkin's filter in its general form (*Large steps in
    /// cloth simulation*, 1998, §5.3): each particle of `filters` is free only in the
    /// subspace its projector `S` (symmetric, `S² = S`) keeps, along the normal of a contact
    /// it rests on, say. Its residual, its search directions and its product `A p` are
    /// filtered by `S`, so its component of `x` outside that subspace keeps its starting
    /// value. The preconditioner is filtered too: block-Jacobi on both sides, `S D⁻¹ S`, so
    /// the iteration stays symmetric (Ascher and Boxerman, *On the modified conjugate
    /// gradient method in cloth simulation*, 2003); the multigrid built on the filtered
    /// system ([`Multigrid::setup_filtered`]). The tolerance is relative to the larger
    /// of `‖S b‖` and the first residual, which also measures what the prescribed parts
    /// ask. Particles not listed are filtered by their `mask` alone; with no filters this is
    /// [`Pcg::solve`], bit for bit.
    ///
    /// # Panics
    /// If `b`, `x` or `mask` is shorter than the matrix, or a filter's particle is not in it.
    pub fn solve_filtered(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
    ) -> PcgReport {
        self.solve_constrained(a, b, x, mask, filters, &mut PointRows::default())
    }

    /// [`Pcg::solve_filtered`] with constraints on combinations of particles as well
    /// ([`PointRows`], factored with these `filters`, and `x` on them): the residual, the
    /// search directions and `A p` are projected onto the rows' null space too (Gould,
    /// Hribar and Nocedal 2001), so `x` keeps the rows' prescribed values. The preconditioner
    /// `B` (the filtered block-Jacobi or multigrid) is wrapped as the constraint
    /// preconditioner `Π B Πᵀ` ([`PointRows::precondition_in`]), positive definite on that
    /// subspace. With no rows this is [`Pcg::solve_filtered`], bit for bit.
    ///
    /// # Panics
    /// As [`Pcg::solve_filtered`], and if a row's particle is not in the matrix.
    pub fn solve_constrained(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
        rows: &mut PointRows,
    ) -> PcgReport {
        let n = a.len();
        for v in [&mut self.r, &mut self.z, &mut self.p, &mut self.q] {
            v.resize(n, Vector::ZERO);
        }
        // The multigrid is built on the filtered system (`Multigrid::setup_filtered`); built
        // for whole particles, free or cut loose, and filtered after, its iterations grew
        // tenfold and a solve in f32 diverged (a 64² cloth on a rod).
        self.active = self.preconditioner.for_size(n);
        match self.active {
            Preconditioner::BlockJacobi => {
                invert_blocks(&a.diag, &mut self.inv_diag);
            }
            _ => self.multigrid.setup_filtered(a, mask, filters),
        }
        if !rows.is_empty() {
            rows.set_metric(&a.diag, filters);
        }
        assert!(
            b.len() >= n && x.len() >= n && mask.len() >= n,
            "vectors shorter than the matrix"
        );
        // Taken out for the solve (the preconditioner borrows `self`), put back at the end.
        let mut scratch = self.scratch.take().unwrap_or_default();
        let op = if scratch.bands.update(a) {
            Product::Bands(a, &scratch.bands)
        } else {
            let usable = scratch.packed.update(a);
            Product::of(a, &scratch.packed, usable)
        };
        let report = self.iterate(op, b, x, mask, (filters, rows), &scratch.partials);
        self.scratch = Some(scratch);
        report
    }

    fn iterate(
        &mut self,
        op: Product<'_>,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        (filters, rows): (&[(u32, Matrix3)], &mut PointRows),
        partials: &Partials,
    ) -> PcgReport {
        let n = op.matrix().len();
        // Held along directions or combinations: the constrained solve's rules.
        let has_rows = !rows.is_empty();
        let constrained = !filters.is_empty() || has_rows;
        // The filters' rows after each masked pass, then the combinations' projection (a few
        // particles: on the caller).
        let filter = |v: &mut [Vector], rows: &mut PointRows| {
            filter_rows(filters, v);
            rows.project(v);
        };
        // r = S (b − A x), and ‖S b‖²
        op.mul_map(x, &mut self.r, |i, ax| (b[i] - ax) * mask[i], None);
        filter(&mut self.r, rows);
        let [mut bb] = sum_rows(partials, n, |rows| {
            [rows.map(|i| (b[i] * mask[i]).length_squared()).sum()]
        });
        // The filters take the held parts out of `b` with round-off of `ε ‖b‖`, which no
        // iteration removes from the residual: the floor it can reach.
        let floor = if !constrained {
            0.0
        } else {
            Scalar::EPSILON * bb.sqrt()
        };
        for &(i, s) in filters {
            let bi = b[i as usize] * mask[i as usize];
            bb += (s * bi).length_squared() - bi.length_squared();
        }
        let bnorm = bb.max(0.0).sqrt();
        // With filters, `S b = 0` still leaves the prescribed parts' residual to solve for.
        let prescribed = bnorm == 0.0
            && constrained
            && sum_rows(partials, n, |rows| [dot(&self.r, &self.r, rows)])[0] > 0.0;
        if bnorm == 0.0 && !prescribed && has_rows {
            // `x` already solves the constrained system (its residual is zero).
            return PcgReport {
                iterations: 0,
                relative_residual: 0.0,
                converged: true,
                failed: false,
            };
        }
        if bnorm == 0.0 && !prescribed {
            for (xi, m) in x.iter_mut().zip(mask) {
                if *m != 0.0 {
                    *xi = Vector::ZERO;
                }
            }
            // Filtered particles keep their constrained part.
            for &(i, s) in filters {
                let xi = &mut x[i as usize];
                *xi -= s * *xi;
            }
            return PcgReport {
                iterations: 0,
                relative_residual: 0.0,
                converged: true,
                failed: false,
            };
        }
        // Block-Jacobi's filtered rows made symmetric; the multigrid filters its own. With
        // rows, the preconditioner wrapped as `Π B Πᵀ` ([`PointRows::precondition_in`]).
        let jacobi = self.active == Preconditioner::BlockJacobi;
        if has_rows {
            rows.precondition_in(&mut self.r);
        }
        self.precondition(op, mask);
        if jacobi {
            symmetric_rows(filters, &self.inv_diag, &self.r, &mut self.z);
        }
        if has_rows {
            rows.restore(&mut self.r);
            rows.precondition_out(&mut self.z);
        }
        let [mut rz, rr] = {
            let (p, r, z) = (SharedMut(self.p.as_mut_ptr()), &self.r, &self.z);
            sum_rows(partials, n, |rows| {
                // SAFETY: disjoint ranges of `p`, which has the matrix's length.
                let p = unsafe { p.slice(rows.clone()) };
                for (p, i) in p.iter_mut().zip(rows.clone()) {
                    *p = z[i] * mask[i];
                }
                [dot(r, z, rows.clone()), dot(r, r, rows)]
            })
        };
        filter(&mut self.p, rows);
        // With filters, the prescribed parts of `x` act as a right-hand side `−A x_c` that
        // `S b` does not measure (a contact stopping a falling cloth: `S b` is nearly zero,
        // the prescribed change is not): the tolerance is taken relative to the larger of
        // `‖S b‖` and the first residual, which holds both.
        let bnorm = if !constrained {
            bnorm
        } else {
            bnorm.max(rr.sqrt())
        };
        let mut it = 0;
        let mut rel = rr.sqrt() / bnorm;
        let mut failed = !rel.is_finite();
        let xp = SharedMut(x.as_mut_ptr());
        // Near static equilibrium on colliders `S b` is small against `b` (the held parts are
        // the contact forces), and the residual reaches the filters' round-off floor above
        // the tolerance: in `f32` filtered solves of cloths resting on colliders stagnated
        // at relative residuals of 10⁻⁵ to 10⁻³ (`‖S b‖` 10⁻⁷ against `‖b‖` 10⁻²), their
        // `r · z` underflowed to zero or lost its sign, and the iteration broke down or
        // diverged (the steps then dropped their holds and threw the cloth off its rest).
        // At the floor, or once `r · z = 0` (the residual's free part vanished: `z = M⁻¹ r`
        // with `M` positive definite on the free directions), the solve has converged.
        let mut exhausted = rz == 0.0;
        // With filters, what the preconditioned residual may fall to before it is round-off:
        // `r · z` falls with the square of the residual, and below `ε²` of its start only the
        // rounding of the filters is left in `r`, along the held directions `z` does not see
        // (see `exhausted` below). Without filters, only `r · z = 0` ends the iteration so.
        let rz_floor = if !constrained {
            0.0
        } else {
            rz * Scalar::EPSILON * Scalar::EPSILON
        };
        while rel > self.tolerance
            && rel * bnorm > floor
            && it < self.max_iterations
            && !failed
            && !exhausted
        {
            // q = S A p, and p · q
            // (`p = S p`, so `p · A p = p · S A p`.)
            let pq = op.mul_map(&self.p, &mut self.q, |i, ap| ap * mask[i], Some(partials));
            filter(&mut self.q, rows);
            if pq.is_nan() || pq <= 0.0 {
                // Not positive definite along p, or a non-finite value: the answer is unusable.
                failed = true;
                break;
            }
            let alpha = rz / pq;
            let (rp, zp) = (
                SharedMut(self.r.as_mut_ptr()),
                SharedMut(self.z.as_mut_ptr()),
            );
            let (p, q, inv) = (&self.p, &self.q, &self.inv_diag);
            // Block-Jacobi without rows: fused, one pass over the vectors.
            let fused = jacobi && !has_rows;
            let [mut rz_new, rr] = if fused {
                sum_rows(partials, n, |rows| {
                    // SAFETY: disjoint ranges of `x`, `r` and `z`, which have the matrix's
                    // length.
                    let (x, r, z) = unsafe {
                        (
                            xp.slice(rows.clone()),
                            rp.slice(rows.clone()),
                            zp.slice(rows.clone()),
                        )
                    };
                    let (mut rz, mut rr): (Scalar, Scalar) = (0.0, 0.0);
                    for (k, i) in rows.enumerate() {
                        x[k] += p[i] * alpha;
                        r[k] -= q[i] * alpha;
                        z[k] = inv[i] * r[k];
                        rz += r[k].dot(z[k]);
                        rr += r[k].length_squared();
                    }
                    [rz, rr]
                })
            } else {
                let [rr] = sum_rows(partials, n, |rows| {
                    // SAFETY: disjoint ranges of `x` and `r`, which have the matrix's length.
                    let (x, r) = unsafe { (xp.slice(rows.clone()), rp.slice(rows.clone())) };
                    let mut rr: Scalar = 0.0;
                    for (k, i) in rows.enumerate() {
                        x[k] += p[i] * alpha;
                        r[k] -= q[i] * alpha;
                        rr += r[k].length_squared();
                    }
                    [rr]
                });
                if has_rows {
                    rows.precondition_in(&mut self.r);
                }
                self.precondition(op, mask);
                if jacobi {
                    symmetric_rows(filters, &self.inv_diag, &self.r, &mut self.z);
                }
                if has_rows {
                    rows.restore(&mut self.r);
                    rows.precondition_out(&mut self.z);
                }
                let (r, z) = (&self.r, &self.z);
                [sum_rows(partials, n, |rows| [dot(r, z, rows)])[0], rr]
            };
            if fused {
                rz_new += symmetric_rows(filters, &self.inv_diag, &self.r, &mut self.z);
            }
            // A residual whose `r · z` fell below `ε²` of the start's is the filters' rounding
            // along the held directions (where `z` is zero): nothing is left to solve for, and
            // going on divides round-off by round-off. A strip hung on a thin rod in `f32` at
            // 1/600 s stalled at 1.1 times the floor above, its `r · z` falling to 10⁻²³ of
            // the start's while `α` jumped from 1 to 60–80, and its residual then grew eightfold
            // an iteration until it overflowed.
            exhausted = if !constrained {
                rz_new == 0.0
            } else {
                rz_new <= rz_floor
            };
            let beta = if exhausted { 0.0 } else { rz_new / rz };
            rz = rz_new;
            let (pp, z) = (SharedMut(self.p.as_mut_ptr()), &self.z);
            for_each_rows(n, |rows| {
                // SAFETY: disjoint ranges of `p`, which has the matrix's length.
                let p = unsafe { pp.slice(rows.clone()) };
                for (p, i) in p.iter_mut().zip(rows) {
                    *p = (z[i] + *p * beta) * mask[i];
                }
            });
            filter(&mut self.p, rows);
            it += 1;
            rel = rr.sqrt() / bnorm;
            failed |= !rel.is_finite();
        }
        PcgReport {
            iterations: it,
            relative_residual: rel,
            converged: !failed && (rel <= self.tolerance || rel * bnorm <= floor || exhausted),
            failed,
        }
    }
}
