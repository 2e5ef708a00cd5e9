//! An aggregation multigrid preconditioner for [`SpringMatrix`] systems.
//!
//! Block-Jacobi leaves conjugate gradients with a number of iterations that grows with the
//! resolution (the smooth, long-wavelength errors of a cloth are barely touched by a local
//! preconditioner). A multigrid V-cycle removes them on coarser copies of the system:
//!
//! - **Aggregates.** Each level's particles are grouped by the greedy aggregation of Vaněk,
//!   Mandel and Brezina (1996, *Algebraic multigrid by smoothed aggregation for second and
//!   fourth order elliptic problems*): a particle none of whose neighbours is taken yet starts
//!   an aggregate with them; the rest join an aggregate next to them. One coarse node per
//!   aggregate, with three degrees of freedom (the aggregate's common translation: the
//!   prolongation `P` copies a coarse node's vector to every member).
//! - **Coarse matrices.** `A_c = Pᵀ A P` (Galerkin), which for this `P` is a sum of blocks:
//!   every block of `A` lands in the block of its two aggregates. The aggregates and where
//!   each block lands are computed once per structure; each solve only re-sums the values
//!   (unsmoothed aggregation: no matrix product).
//! - **Cycle.** A symmetric V-cycle: a pre-smoothing step, the residual restricted (`Pᵀ`),
//!   the coarse level's cycle, the correction prolonged (`P`), a post-smoothing step that is
//!   the pre-smoothing's adjoint; a dense Cholesky solve on the coarsest level. The finest
//!   level is smoothed by damped block-Jacobi (its weight is bounded in
//!   [`Multigrid::setup`]): the pre-smoothing's residual is one product by the matrix itself,
//!   and the post-smoothing's needs none, since after the correction `z₁ = z₀ + P e` the
//!   residual is the pre-smoothing's less `(A P) e` — and `A P`, the matrix's blocks summed
//!   by the aggregate of their column, has a few blocks a row where `A` has a dozen. The
//!   coarser levels are smoothed by a forward and a backward block Gauss–Seidel sweep. With
//!   convergent smoothers and symmetric positive definite coarse solves the cycle is a
//!   symmetric positive definite operator — what conjugate gradients needs of a
//!   preconditioner.
//!
//! Pinned and prescribed particles (mask zero) are cut loose: their rows and columns are
//! dropped and their diagonal blocks replaced by the identity, so the cycle returns zero for
//! them and the free part is preconditioned as the filtered conjugate gradients iterate on it.
//!
//! Particles held along one or two directions (Baraff and Witkin's filter with projectors
//! `Sᵢ = I − Σ eeᵀ`, [`Multigrid::setup_filtered`]) are cut loose along those directions only:
//! the cycle is built for the filtered matrix `Â = S A S + (I − S)` with the prolongation
//! `S P` (an aggregate's translation, each held member keeping its free part), so the coarse
//! matrices are `Pᵀ S A S P` — blocks `Sᵢ A_ij S_j` summed by aggregate — and the finest
//! level's diagonal blocks `Sᵢ Dᵢ Sᵢ + (I − Sᵢ)`. The held rows of the smoother's answer and
//! of its residual are filtered again where they are formed, so the cycle maps the free
//! directions to themselves, as conjugate gradients on the filtered system needs. Built on
//! the unfiltered matrix instead, the coarse levels would move held particles along their
//! normals, which the filtered system forbids.

use super::{AT_JI, Product, SpringMatrix, filter_rows, for_each_rows};
use crate::core::kernels::{self, SharedMut};
use crate::math::{Matrix3, Scalar, Vector};

/// A level stops being coarsened below this many nodes (solved densely), or when aggregation
/// no longer shrinks it to at most this fraction.
const COARSEST: usize = 48;
const SHRINK: f64 = 0.7;
/// The finest level's smoothing weight times the matrix's element size `e` (see
/// [`Multigrid::setup`]): `ω e < 2` keeps the cycle positive definite. Measured, conjugate
/// gradients' iterations at a relative 1e-6 (f32, linearly implicit Euler at h = 1/60, the
/// seed cloths): `ω e` = 2/3 → 1.6 takes the 128² cloth from 34.9 to 29.4 a step, the 64²
/// from 29.0 to 22.0, the bench cloth from 50.3 to 37.9; 1.8–2.0 were level with 1.6 on the
/// seed cloths and worse on the bench cloth (38.6, 42.0).
const OMEGA_TIMES_E: Scalar = 1.6;
/// Coarse rows per chunk of the first coarse level's sums (about 12 entries a row on a cloth).
const GATHER_ROWS: usize = 128;
/// Where a fine block lands: the coarse diagonal of its aggregate (both ends in one).
const TO_DIAG: u32 = u32::MAX;

/// A level's matrix, rows stored in full (`(i, j)` and `(j, i)` both present).
#[derive(Clone, Debug, Default)]
struct Level {
    start: Vec<u32>,
    col: Vec<u32>,
    off: Vec<Matrix3>,
    diag: Vec<Matrix3>,
    inv: Vec<Matrix3>,
    /// This level's node → the next level's (empty on the coarsest level).
    agg: Vec<u32>,
    /// For each off-diagonal entry, where it lands on the next level (an index into its
    /// `off`, or [`TO_DIAG`]).
    land: Vec<u32>,
    r: Vec<Vector>,
    z: Vec<Vector>,
    t: Vec<Vector>,
}

impl Level {
    fn len(&self) -> usize {
        self.diag.len()
    }

    /// `z_i ← D_i⁻¹ (r_i − Σ_{j≠i} A_ij z_j)` for `i` in `order`.
    fn sweep(&mut self, order: impl Iterator<Item = usize>) {
        for i in order {
            let mut s = self.r[i];
            for e in self.start[i] as usize..self.start[i + 1] as usize {
                s -= self.off[e] * self.z[self.col[e] as usize];
            }
            self.z[i] = self.inv[i] * s;
        }
    }

    /// `t ← r − A z`.
    fn residual(&mut self) {
        for i in 0..self.len() {
            let mut s = self.r[i] - self.diag[i] * self.z[i];
            for e in self.start[i] as usize..self.start[i + 1] as usize {
                s -= self.off[e] * self.z[self.col[e] as usize];
            }
            self.t[i] = s;
        }
    }

    fn invert(&mut self) {
        super::invert_blocks(&self.diag, &mut self.inv);
    }
}

/// Rows in full from a list of node pairs (each pair in both rows, sorted by column, repeats
/// merged): `(start, col, entry of each pair's (i, j), entry of its (j, i))`; a pair joining
/// a node to itself gets `TO_DIAG` for both.
fn rows_of(n: usize, pairs: &[(u32, u32)]) -> (Vec<u32>, Vec<u32>, Vec<u32>, Vec<u32>) {
    let mut adj: Vec<Vec<u32>> = vec![vec![]; n];
    for &(i, j) in pairs {
        if i != j {
            adj[i as usize].push(j);
            adj[j as usize].push(i);
        }
    }
    let mut start = vec![0u32; n + 1];
    let mut col = vec![];
    for (i, a) in adj.iter_mut().enumerate() {
        a.sort_unstable();
        a.dedup();
        col.extend_from_slice(a);
        start[i + 1] = col.len() as u32;
    }
    let find = |i: u32, j: u32| -> u32 {
        let (s, e) = (start[i as usize] as usize, start[i as usize + 1] as usize);
        s as u32 + col[s..e].binary_search(&j).expect("pair in its row") as u32
    };
    let (ij, ji) = pairs
        .iter()
        .map(|&(i, j)| {
            if i == j {
                (TO_DIAG, TO_DIAG)
            } else {
                (find(i, j), find(j, i))
            }
        })
        .unzip();
    (start, col, ij, ji)
}

/// Greedy aggregation of the graph in rows `(start, col)`: node → aggregate, and the count.
#[allow(clippy::needless_range_loop)] // `i` indexes the rows and the aggregates alike
fn aggregate(start: &[u32], col: &[u32]) -> (Vec<u32>, usize) {
    let n = start.len() - 1;
    let nbrs = |i: usize| &col[start[i] as usize..start[i + 1] as usize];
    let mut agg = vec![u32::MAX; n];
    let mut count = 0u32;
    // 1: a node whose neighbours are all free takes them.
    for i in 0..n {
        if agg[i] == u32::MAX && nbrs(i).iter().all(|&j| agg[j as usize] == u32::MAX) {
            agg[i] = count;
            for &j in nbrs(i) {
                agg[j as usize] = count;
            }
            count += 1;
        }
    }
    // 2: the rest join a neighbouring aggregate from step 1 (the first in column order).
    let first = agg.clone();
    for i in 0..n {
        if agg[i] == u32::MAX
            && let Some(&j) = nbrs(i).iter().find(|&&j| first[j as usize] != u32::MAX)
        {
            agg[i] = first[j as usize];
        }
    }
    // 3: nodes with no aggregated neighbour (isolated ones) are their own.
    for a in agg.iter_mut().filter(|a| **a == u32::MAX) {
        *a = count;
        count += 1;
    }
    (agg, count as usize)
}

/// The aggregation multigrid preconditioner (see the module docs). Owns its levels and
/// buffers; the structure is rebuilt when the matrix's changes, values on every
/// [`setup`](Self::setup).
#[derive(Clone, Debug, Default)]
pub struct Multigrid {
    /// The structure of the matrix analysed last ([`SpringMatrix`]'s name for it; 0: none).
    structure: u64,
    /// The first coarse level's entries as sums of the matrix's blocks: entry `e` (a coarse
    /// row's diagonal, `e < count`, or its off-diagonal entry `e − count`) is the sum of the
    /// sources `sources[start[e]..start[e + 1]]`, each a fine row `i < n` (its diagonal block)
    /// or `n + 2k + side` (pair `k`'s block, transposed on side 1 unless symmetric), in the
    /// order a scatter over the rows and then the pairs would add them.
    gather_start: Vec<u32>,
    gather: Vec<u32>,
    /// The finest level's aggregates' members, in order: aggregate `a`'s are
    /// `members[members_start[a]..members_start[a + 1]]` (the restriction's gathers).
    members_start: Vec<u32>,
    members: Vec<u32>,
    /// The finest level's `A S P` (the matrix, times the cut-loose filter `S`, times the
    /// prolongation) by rows, so that the post-smoothing needs no product by `A`: row `i`'s
    /// entries are `ap_start[i]..ap_start[i + 1]`, each a coarse node `ap_col[e]` and a block
    /// `ap[e]` summed from the sources `ap_sources[ap_source_start[e]..]` (encoded as in
    /// [`Multigrid::gather`]).
    ap_start: Vec<u32>,
    ap_col: Vec<u32>,
    ap: Vec<Matrix3>,
    ap_source_start: Vec<u32>,
    ap_sources: Vec<u32>,
    /// Where each pair's blocks `(i, j)` and `(j, i)` of the matrix land on the first
    /// coarse level.
    land_ij: Vec<u32>,
    land_ji: Vec<u32>,
    /// The finest level's smoothing weight (see [`Multigrid::setup`]).
    omega: Scalar,
    /// The finest level keeps no rows of its own (its products are the matrix's); the
    /// coarser ones do.
    levels: Vec<Level>,
    /// The coarsest level's Cholesky factor (dense, lower, row-major, `f64`), and whether the
    /// factorization succeeded (if not, the coarsest level is smoothed instead).
    chol: Vec<f64>,
    dense_ok: bool,
    rhs: Vec<f64>,
    /// Structures analysed so far.
    pub analyses: u64,
    /// The last setup's filters (particle, projector), and each particle's index into them
    /// (or [`NO_FILTER`]; empty when there were none).
    held: Vec<(u32, Matrix3)>,
    filter_of: Vec<u32>,
}

/// A particle without a filter in [`Multigrid::filter_of`].
const NO_FILTER: u32 = u32::MAX;

impl Multigrid {
    /// Number of levels (the finest included) of the last structure.
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// Nodes on each level, finest first.
    pub fn sizes(&self) -> Vec<usize> {
        self.levels.iter().map(Level::len).collect()
    }

    fn analyse(&mut self, a: &SpringMatrix) {
        let n = a.len();
        self.structure = a.structure;
        let (start, col, ij, ji) = rows_of(n, a.pairs());
        let mut levels = vec![Level {
            off: vec![Matrix3::ZERO; col.len()],
            diag: vec![Matrix3::ZERO; n],
            start,
            col,
            ..Default::default()
        }];
        loop {
            let fine = levels.last_mut().expect("a level");
            let m = fine.len();
            if m <= COARSEST {
                break;
            }
            let (agg, count) = aggregate(&fine.start, &fine.col);
            if count as f64 > SHRINK * m as f64 {
                break;
            }
            // The coarse graph: aggregates joined by any fine entry between them.
            let mut pairs = vec![];
            for i in 0..m {
                for e in fine.start[i] as usize..fine.start[i + 1] as usize {
                    let (a, b) = (agg[i], agg[fine.col[e] as usize]);
                    if a < b {
                        pairs.push((a, b));
                    }
                }
            }
            pairs.sort_unstable();
            pairs.dedup();
            let (start, col, ..) = rows_of(count, &pairs);
            let coarse = Level {
                off: vec![Matrix3::ZERO; col.len()],
                diag: vec![Matrix3::ZERO; count],
                start,
                col,
                ..Default::default()
            };
            let mut land = vec![TO_DIAG; fine.col.len()];
            for i in 0..m {
                let a = agg[i];
                for e in fine.start[i] as usize..fine.start[i + 1] as usize {
                    let b = agg[fine.col[e] as usize];
                    if a != b {
                        let (s, t) = (
                            coarse.start[a as usize] as usize,
                            coarse.start[a as usize + 1] as usize,
                        );
                        land[e] =
                            (s + coarse.col[s..t].binary_search(&b).expect("coarse entry")) as u32;
                    }
                }
            }
            fine.agg = agg;
            fine.land = land;
            levels.push(coarse);
        }
        let fine = &mut levels[0];
        let land = |e: u32| fine.land.get(e as usize).copied().unwrap_or(TO_DIAG);
        self.land_ij = ij.iter().map(|&e| land(e)).collect();
        self.land_ji = ji.iter().map(|&e| land(e)).collect();
        fine.start.clear();
        fine.col.clear();
        fine.off.clear();
        fine.land.clear();
        for l in &mut levels {
            let m = l.len();
            l.r = vec![Vector::ZERO; m];
            l.z = vec![Vector::ZERO; m];
            l.t = vec![Vector::ZERO; m];
        }
        self.gathers(&levels, a.pairs());
        self.rows_by_aggregate(a, levels.first().map_or(&[][..], |l| &l.agg[..]));
        let last = levels.last().map_or(0, Level::len);
        self.chol = vec![0.0; 9 * last * last];
        self.rhs = vec![0.0; 3 * last];
        self.levels = levels;
        self.analyses += 1;
    }

    /// The first coarse level's gather lists (see [`Multigrid::gather`]), from the finest
    /// level's aggregates and where each pair lands.
    fn gathers(&mut self, levels: &[Level], pairs: &[(u32, u32)]) {
        let (start, list) = (&mut self.gather_start, &mut self.gather);
        start.clear();
        list.clear();
        self.members_start.clear();
        self.members.clear();
        let (Some(fine), Some(coarse)) = (levels.first(), levels.get(1)) else {
            return;
        };
        let (n, count) = (fine.len(), coarse.len());
        (self.members_start, self.members) = super::group_by(
            count,
            (fine.agg.iter().enumerate()).map(|(i, &a)| (a as usize, i as u32)),
        );
        assert!(
            n + 2 * pairs.len() < u32::MAX as usize,
            "too many blocks for the multigrid"
        );
        let (agg, land_ij, land_ji) = (&fine.agg, &self.land_ij, &self.land_ji);
        let entry = move |to: u32, at: u32| -> usize {
            if to == TO_DIAG {
                agg[at as usize] as usize
            } else {
                count + to as usize
            }
        };
        // Every source in the order a scatter adds it: rows, then pairs (side ij, side ji).
        let sources =
            (0..n)
                .map(|i| (agg[i] as usize, i as u32))
                .chain(pairs.iter().enumerate().flat_map(move |(k, &(i, j))| {
                    [
                        (entry(land_ij[k], i), (n + 2 * k) as u32),
                        (entry(land_ji[k], j), (n + 2 * k + 1) as u32),
                    ]
                }));
        (*start, *list) = super::group_by(count + coarse.off.len(), sources);
    }

    /// The structure of the finest level's `A S P` (see [`Multigrid::ap`]): each row's
    /// sources (its diagonal block and its entries' blocks) grouped by the aggregate of their
    /// column, the groups in the order of their aggregates, each group's sources in the row's
    /// order.
    fn rows_by_aggregate(&mut self, a: &SpringMatrix, agg: &[u32]) {
        let (start, col, srcs, src_start) = (
            &mut self.ap_start,
            &mut self.ap_col,
            &mut self.ap_sources,
            &mut self.ap_source_start,
        );
        for v in [&mut *start, &mut *col, &mut *srcs, &mut *src_start] {
            v.clear();
        }
        self.ap.clear();
        if agg.is_empty() {
            return;
        }
        let (n, rows) = (a.len(), &a.rows);
        start.push(0);
        src_start.push(0);
        let mut row: Vec<(u32, u32)> = vec![];
        for i in 0..n {
            row.clear();
            row.push((agg[i], i as u32));
            for e in rows.start[i] as usize..rows.start[i + 1] as usize {
                let (b, c) = (rows.block[e], rows.col[e]);
                let side = u32::from(b & AT_JI != 0);
                row.push((agg[c as usize], (n as u32) + 2 * (b & !AT_JI) + side));
            }
            // Stable: the row's order within each aggregate.
            row.sort_by_key(|&(g, _)| g);
            for (k, &(g, src)) in row.iter().enumerate() {
                if k == 0 || row[k - 1].0 != g {
                    if k > 0 {
                        src_start.push(srcs.len() as u32);
                    }
                    col.push(g);
                }
                srcs.push(src);
            }
            src_start.push(srcs.len() as u32);
            start.push(col.len() as u32);
        }
        self.ap.resize(col.len(), Matrix3::ZERO);
    }

    /// Takes the values of `a`, with the particles whose `mask` is zero cut loose (see the
    /// module docs), and sums the coarse levels.
    ///
    /// The finest level is smoothed by damped block-Jacobi, `z ← z + ω D⁻¹ (r − A z)`, which
    /// needs only the matrix's own product. The cycle is positive definite when
    /// `ω A < 2 D`. Every block of the matrix comes from an element's positive semidefinite
    /// matrix over `e` particles (a spring's `e = 2`, a tet's `4`; masses add to the diagonal
    /// only), and such a matrix is at most `e` times its own block diagonal (Cauchy–Schwarz
    /// on `‖Σ_k B_k x_k‖²`), so `A ≤ e D` with `e` the largest element's: `ω = 1.6/e` keeps
    /// a fifth of the margin (`ω A ≤ 1.6 D`). Matrices with blocks that are not symmetric
    /// (tets' edges) are taken to hold tets.
    pub fn setup(&mut self, a: &SpringMatrix, mask: &[Scalar]) {
        self.setup_filtered(a, mask, &[]);
    }

    /// [`setup`](Self::setup) for the system filtered by `filters` (each a particle and its
    /// projector `S` onto the directions it stays free in; see the module docs): the cycle
    /// then maps vectors of the free directions to vectors of the free directions.
    pub fn setup_filtered(
        &mut self,
        a: &SpringMatrix,
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
    ) {
        let n = a.len();
        if self.levels.first().map(Level::len) != Some(n) || self.structure != a.structure {
            self.analyse(a);
        }
        self.filter_of.clear();
        self.held.clear();
        if !filters.is_empty() {
            self.filter_of.resize(n, NO_FILTER);
            for &(i, s) in filters {
                if let Some(f) = self.filter_of.get_mut(i as usize) {
                    *f = self.held.len() as u32;
                    self.held.push((i, s));
                }
            }
        }
        let (filter_of, held) = (&self.filter_of, &self.held);
        let proj = |i: usize| {
            filter_of
                .get(i)
                .filter(|&&k| k != NO_FILTER)
                .map(|&k| held[k as usize].1)
        };
        // A block of rows `i` and column `j` of the filtered matrix: `Sᵢ A_ij S_j`.
        let filtered = |i: usize, j: usize, b: Matrix3| match (proj(i), proj(j)) {
            (None, None) => b,
            (si, sj) => si.map_or(b, |s| s * b) * sj.unwrap_or(Matrix3::IDENTITY),
        };
        let sym = a.symmetric_prefix();
        let e = if sym < a.off.len() { 4.0 } else { 2.0 };
        self.omega = OMEGA_TIMES_E / e;
        let (fine, rest) = self.levels.split_at_mut(1);
        let fine = &mut fine[0];
        for (i, (d, m)) in a.diag.iter().zip(mask).enumerate() {
            fine.diag[i] = if *m == 0.0 { Matrix3::IDENTITY } else { *d };
        }
        // Held particles: `S D S + (I − S)`, cut loose along their held directions.
        for &(i, s) in held {
            if mask[i as usize] != 0.0 {
                let d = &mut fine.diag[i as usize];
                *d = s * *d * s + (Matrix3::IDENTITY - s);
            }
        }
        fine.invert();
        // `A S P`, in chunks of rows on the team: a source counts when its column is free.
        let (start, srcs, src_start) = (&self.ap_start, &self.ap_sources, &self.ap_source_start);
        if !start.is_empty() {
            let app = SharedMut(self.ap.as_mut_ptr());
            for_each_rows(n, |rows| {
                let entries = start[rows.start] as usize..start[rows.end] as usize;
                // SAFETY: disjoint ranges of `ap`, the entries of disjoint rows.
                let ap = unsafe { app.slice(entries.clone()) };
                for (b, e) in ap.iter_mut().zip(entries) {
                    let sources = &srcs[src_start[e] as usize..src_start[e + 1] as usize];
                    // The pair's block counts when its column is free.
                    *b = sum_sources(
                        a,
                        mask,
                        sources,
                        |i, j, side| mask[if side == 0 { j } else { i }] != 0.0,
                        filtered,
                    );
                }
            });
        }
        if let Some(coarse) = rest.first_mut() {
            // Each coarse row's entries summed from their sources, in chunks of coarse rows
            // on the team (every entry's sum in its list's order: the same bits on any number
            // of threads).
            let (start, list) = (&self.gather_start, &self.gather);
            let sum = |e: usize| {
                let sources = &list[start[e] as usize..start[e + 1] as usize];
                // The pair's block counts when both its particles are free (`Pᵀ S A S P`).
                sum_sources(
                    a,
                    mask,
                    sources,
                    |i, j, _| mask[i] != 0.0 && mask[j] != 0.0,
                    filtered,
                )
            };
            let count = coarse.len();
            let (cd, co, cs) = (
                SharedMut(coarse.diag.as_mut_ptr()),
                SharedMut(coarse.off.as_mut_ptr()),
                &coarse.start,
            );
            kernels::for_each_range(count, kernels::chunk_size(count, GATHER_ROWS), |rows| {
                let entries = cs[rows.start] as usize..cs[rows.end] as usize;
                // SAFETY: disjoint ranges of the coarse rows and of their entries.
                let (diag, off) = unsafe { (cd.slice(rows.clone()), co.slice(entries.clone())) };
                for (d, r) in diag.iter_mut().zip(rows) {
                    *d = sum(r);
                }
                fill_empty(diag);
                for (o, e) in off.iter_mut().zip(entries) {
                    *o = sum(count + e);
                }
            });
            // `Pᵀ S A S P` is singular along the directions every member of an aggregate is
            // held in (a cloth lying on the ground, each particle held along the normal), and
            // those blocks' inverses fell back to the identity, which smoothed the coarse level
            // at the wrong scale: with springs ten times the cloth's, conjugate gradients broke
            // down at once. The held directions get their members' stiffness back, averaged
            // over the aggregate (`Σ (I − Sᵢ) tr(Dᵢ)/3` over the free members, `/ k`): exactly
            // the common held directions where all are held alike, a fraction of a member's
            // stiffness where few are. The coarse correction is the same along them (`S P`
            // keeps nothing there), and the coarse matrix stays symmetric positive definite.
            if !held.is_empty() {
                let (ms, mem) = (&self.members_start, &self.members);
                for (agg, d) in coarse.diag.iter_mut().enumerate() {
                    let members = &mem[ms[agg] as usize..ms[agg + 1] as usize];
                    let (mut add, mut free) = (Matrix3::ZERO, 0u32);
                    for &i in members {
                        let i = i as usize;
                        if mask[i] == 0.0 {
                            continue;
                        }
                        free += 1;
                        if let Some(s) = proj(i) {
                            let di = a.diag[i];
                            let c = (di.x_axis.x + di.y_axis.y + di.z_axis.z) / 3.0;
                            add += (Matrix3::IDENTITY - s) * c;
                        }
                    }
                    if free > 0 && add != Matrix3::ZERO {
                        *d += add * (1.0 / free as Scalar);
                    }
                }
            }
        }
        for l in 1..self.levels.len() {
            let (done, rest) = self.levels.split_at_mut(l + 1);
            let fine = &mut done[l];
            fine.invert();
            let Some(coarse) = rest.first_mut() else {
                break;
            };
            coarse.diag.fill(Matrix3::ZERO);
            coarse.off.fill(Matrix3::ZERO);
            for i in 0..fine.len() {
                let ai = fine.agg[i] as usize;
                coarse.diag[ai] += fine.diag[i];
                for e in fine.start[i] as usize..fine.start[i + 1] as usize {
                    let to = fine.land[e];
                    if to == TO_DIAG {
                        coarse.diag[ai] += fine.off[e];
                    } else {
                        coarse.off[to as usize] += fine.off[e];
                    }
                }
            }
            fill_empty(&mut coarse.diag);
        }
        // A system too small to coarsen is its finest level alone, smoothed only (`apply`):
        // that level keeps no rows to factor.
        if self.levels.len() > 1 {
            self.factor_coarsest();
        }
    }

    fn factor_coarsest(&mut self) {
        let last = self.levels.last().expect("a level");
        let m = 3 * last.len();
        let c = &mut self.chol;
        c.fill(0.0);
        for i in 0..last.len() {
            let mut put = |bi: usize, bj: usize, b: &Matrix3| {
                for r in 0..3 {
                    for q in 0..3 {
                        c[(3 * bi + r) * m + 3 * bj + q] += b.col(q)[r] as f64;
                    }
                }
            };
            put(i, i, &last.diag[i]);
            for e in last.start[i] as usize..last.start[i + 1] as usize {
                put(i, last.col[e] as usize, &last.off[e]);
            }
        }
        // In-place Cholesky, lower triangle.
        self.dense_ok = true;
        for j in 0..m {
            let mut d = c[j * m + j];
            for k in 0..j {
                d -= c[j * m + k] * c[j * m + k];
            }
            if d.is_nan() || d <= 0.0 {
                self.dense_ok = false;
                return;
            }
            let d = d.sqrt();
            c[j * m + j] = d;
            for i in j + 1..m {
                let mut s = c[i * m + j];
                for k in 0..j {
                    s -= c[i * m + k] * c[j * m + k];
                }
                c[i * m + j] = s / d;
            }
        }
    }

    fn solve_coarsest(&mut self) {
        let last = self.levels.last_mut().expect("a level");
        if !self.dense_ok {
            // Not numerically definite: symmetric Gauss–Seidel instead (still symmetric).
            last.z.fill(Vector::ZERO);
            let m = last.len();
            last.sweep(0..m);
            last.sweep((0..m).rev());
            return;
        }
        let m = 3 * last.len();
        let (c, y) = (&self.chol, &mut self.rhs);
        for (i, r) in last.r.iter().enumerate() {
            for q in 0..3 {
                y[3 * i + q] = r[q] as f64;
            }
        }
        for i in 0..m {
            let mut s = y[i];
            for k in 0..i {
                s -= c[i * m + k] * y[k];
            }
            y[i] = s / c[i * m + i];
        }
        for i in (0..m).rev() {
            let mut s = y[i];
            for k in i + 1..m {
                s -= c[k * m + i] * y[k];
            }
            y[i] = s / c[i * m + i];
        }
        for (i, z) in last.z.iter_mut().enumerate() {
            *z = Vector::new(
                y[3 * i] as Scalar,
                y[3 * i + 1] as Scalar,
                y[3 * i + 2] as Scalar,
            );
        }
    }

    /// `z ← B r` for the V-cycle `B ≈ A⁻¹` of the last [`setup`](Self::setup) (`a` and
    /// `mask` the ones given to it), its finest level's passes in chunks of rows on the team
    /// the caller runs in (the same bits on any number of threads).
    ///
    /// # Panics
    /// If `r`, `z` or `mask` is shorter than the matrix, or before any setup.
    pub fn apply(&mut self, a: &SpringMatrix, mask: &[Scalar], r: &[Vector], z: &mut [Vector]) {
        self.apply_with(Product::Rows(a), mask, r, z);
    }

    /// [`apply`](Self::apply) with the matrix's product `a`.
    pub(crate) fn apply_with(
        &mut self,
        a: Product<'_>,
        mask: &[Scalar],
        r: &[Vector],
        z: &mut [Vector],
    ) {
        let nl = self.levels.len();
        let n = self.levels.first().map_or(0, Level::len);
        assert!(
            r.len() >= n && z.len() >= n && mask.len() >= n,
            "vectors shorter than the multigrid's finest level"
        );
        let w = self.omega;
        {
            let fine = &mut self.levels[0];
            let (zp, inv) = (SharedMut(fine.z.as_mut_ptr()), &fine.inv);
            for_each_rows(fine.len(), |rows| {
                // SAFETY: disjoint ranges of the level's `z`.
                let z = unsafe { zp.slice(rows.clone()) };
                for (z, i) in z.iter_mut().zip(rows) {
                    *z = inv[i] * r[i] * w;
                }
            });
            filter_rows(&self.held, &mut fine.z);
            if nl == 1 {
                z[..n].copy_from_slice(&fine.z);
                return;
            }
            a.mul_map(&fine.z, &mut fine.t, |i, az| (r[i] - az) * mask[i], None);
            filter_rows(&self.held, &mut fine.t);
        }
        for l in 0..nl - 1 {
            let (done, rest) = self.levels.split_at_mut(l + 1);
            let (fine, coarse) = (&mut done[l], &mut rest[0]);
            if l > 0 {
                let m = fine.len();
                fine.z.fill(Vector::ZERO);
                fine.sweep(0..m);
                fine.residual();
            }
            if l == 0 {
                // Each aggregate's sum over its members in order (the order of a scatter over
                // the rows), in chunks of aggregates on the team.
                let (rp, t) = (SharedMut(coarse.r.as_mut_ptr()), &fine.t);
                let (start, members) = (&self.members_start, &self.members);
                let count = coarse.len();
                kernels::for_each_range(count, kernels::chunk_size(count, GATHER_ROWS), |rows| {
                    // SAFETY: disjoint ranges of the coarse level's `r`.
                    let r = unsafe { rp.slice(rows.clone()) };
                    for (r, a) in r.iter_mut().zip(rows) {
                        let mut s = Vector::ZERO;
                        for &i in &members[start[a] as usize..start[a + 1] as usize] {
                            s += t[i as usize];
                        }
                        *r = s;
                    }
                });
                continue;
            }
            coarse.r.fill(Vector::ZERO);
            for (t, &a) in fine.t.iter().zip(&fine.agg) {
                coarse.r[a as usize] += *t;
            }
        }
        self.solve_coarsest();
        for l in (0..nl - 1).rev() {
            let (done, rest) = self.levels.split_at_mut(l + 1);
            let (fine, coarse) = (&mut done[l], &rest[0]);
            if l > 0 {
                for (z, &a) in fine.z.iter_mut().zip(&fine.agg) {
                    *z += coarse.z[a as usize];
                }
                let m = fine.len();
                fine.sweep((0..m).rev());
            } else {
                // The prolongation and the post-smoothing in one pass, without a product by
                // `A`: with `z₀` the pre-smoothing's answer and `t = S (r − A z₀)` its
                // residual, the corrected `z₁ = z₀ + S P e` has, on a free row,
                // `r − A z₁ = t − (A S P) e`. Masked particles: r = 0, D⁻¹ = I and z = 0,
                // so they stay at zero.
                let (agg, inv, t) = (&fine.agg, &fine.inv, &fine.t);
                let (z0, ec) = (&fine.z, &coarse.z);
                let (start, col, ap) = (&self.ap_start, &self.ap_col, &self.ap);
                let zp = SharedMut(z.as_mut_ptr());
                for_each_rows(fine.len(), |rows| {
                    // SAFETY: disjoint ranges of `z`, at least as long as the level.
                    let z = unsafe { zp.slice(rows.clone()) };
                    for (z, i) in z.iter_mut().zip(rows) {
                        let mut ape = Vector::ZERO;
                        for e in start[i] as usize..start[i + 1] as usize {
                            ape += ap[e] * ec[col[e] as usize];
                        }
                        let z1 = z0[i] + ec[agg[i] as usize] * mask[i];
                        *z = z1 + inv[i] * (t[i] - ape) * (w * mask[i]);
                    }
                });
                // Held rows: the prolongation `S P` and the smoother keep them free.
                filter_rows(&self.held, &mut z[..n]);
            }
        }
    }
}

/// The sum of `a`'s blocks named by `sources` (encoded as in [`Multigrid::gather`]): a row's
/// diagonal block when its particle is free, pair `k = (i, j)`'s block on side `s` (transposed
/// on side 1 unless symmetric) when `counts(i, j, s)`; in the sources' order. Each block of
/// row `r` and column `c` is taken as `map(r, c, block)` (the filter's `S_r A_rc S_c`).
fn sum_sources(
    a: &SpringMatrix,
    mask: &[Scalar],
    sources: &[u32],
    counts: impl Fn(usize, usize, usize) -> bool,
    map: impl Fn(usize, usize, Matrix3) -> Matrix3,
) -> Matrix3 {
    let (n, sym) = (a.len(), a.symmetric_prefix());
    let mut sum = Matrix3::ZERO;
    for &src in sources {
        let src = src as usize;
        if src < n {
            if mask[src] != 0.0 {
                sum += map(src, src, a.diag[src]);
            }
            continue;
        }
        let (k, side) = ((src - n) / 2, (src - n) % 2);
        let (i, j) = a.pairs[k];
        if !counts(i as usize, j as usize, side) {
            continue;
        }
        let (i, j) = (i as usize, j as usize);
        let o = a.off[k];
        sum += if side == 0 {
            map(i, j, o)
        } else if k < sym {
            map(j, i, o)
        } else {
            map(j, i, o.transpose())
        };
    }
    sum
}

/// Aggregates of cut-loose particles only: their own unknowns, decoupled.
fn fill_empty(diag: &mut [Matrix3]) {
    for d in diag {
        if *d == Matrix3::ZERO {
            *d = Matrix3::IDENTITY;
        }
    }
}
