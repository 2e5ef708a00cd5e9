//! Sparse direct solves of [`SpringMatrix`] systems with faer's Cholesky factorization.
//!
//! Only the free degrees of freedom enter the factorization (pinned and prescribed particles
//! are eliminated, their known values moved to the right-hand side), so the factored matrix
//! is the same symmetric positive definite one the filtered PCG iterates on. The symbolic
//! analysis (AMD ordering, elimination tree, supernodes) is done once per structure — the
//! spring list and the set of free particles — and every later solve only refills values,
//! factors and substitutes, in `f64` whatever the crate's precision, into buffers it keeps
//! (no allocation per solve).

use super::{PcgReport, PointRows, SpringMatrix};
use crate::math::{Matrix3, Scalar, ToScalar, Vector};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

/// Where a spring's off-diagonal block lands in the factored matrix.
#[derive(Clone, Copy, Debug)]
enum OffSlot {
    /// An end is constrained: the block only moves known values to the right-hand side.
    Skip,
    /// Both ends free and distinct: nine upper-triangle positions.
    Off([u32; 9]),
    /// A self spring on a free particle: added twice to its diagonal block.
    SelfBlock(u32),
}

/// The structure the factorization was analysed for.
struct Analysis {
    pairs: Vec<(u32, u32)>,
    free: Vec<u32>,
    dim: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    diag_pos: Vec<[u32; 6]>,
    off_pos: Vec<OffSlot>,
    symbolic: SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    buf: MemBuffer,
}

/// Sparse Cholesky solver for [`SpringMatrix`] systems (see the module docs). Reports a
/// failure — never a NaN answer — when the free part of the matrix is not numerically positive
/// definite (a zero-mass free particle, a wrong-signed stiffness).
#[derive(Default)]
pub struct SparseCholesky {
    analysis: Option<Analysis>,
    values: Vec<f64>,
    rhs: Vec<f64>,
    xc: Vec<Vector>,
    q: Vec<Vector>,
    /// True when `analysis.l_values` holds the factor of the last matrix solved with.
    factored: bool,
    /// The filters that matrix was solved with (see [`SparseCholesky::solve_filtered`]).
    factored_filters: Vec<(u32, Matrix3)>,
    /// Each particle's place in the filters being solved with (`u32::MAX`: none); every
    /// entry is `u32::MAX` between solves.
    filter_of: Vec<u32>,
    /// Symbolic analyses done so far (one per structure change).
    pub analyses: u64,
    /// Scratch of [`SparseCholesky::solve_constrained`]: `Â⁻¹ C'ᵀ p` by the free unknowns,
    /// the conjugate gradients' vectors by row, and the correction.
    schur: Vec<f64>,
    schur_m: Vec<f64>,
    schur_dx: Vec<f64>,
}

impl Clone for SparseCholesky {
    /// A fresh solver (the factorization is redone on first use).
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl std::fmt::Debug for SparseCholesky {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseCholesky")
            .field("dim", &self.analysis.as_ref().map(|a| a.dim))
            .field(
                "factor_len",
                &self.analysis.as_ref().map(|a| a.l_values.len()),
            )
            .field("analyses", &self.analyses)
            .finish()
    }
}

/// The symbolic Cholesky analysis (AMD ordering) of a `dim × dim` upper-triangle pattern in
/// compressed columns, a buffer for the factor's values, and scratch memory for factoring and
/// for solving `rhs_columns` right-hand sides at once; `None` when faer refuses the pattern or
/// the memory.
pub(crate) fn analyse_upper(
    dim: usize,
    col_ptr: &[usize],
    row_idx: &[usize],
    rhs_columns: usize,
) -> Option<(SymbolicCholesky<usize>, Vec<f64>, MemBuffer)> {
    let sym = SymbolicSparseColMatRef::new_checked(dim, dim, col_ptr, None, row_idx);
    let symbolic = factorize_symbolic_cholesky(
        sym,
        Side::Upper,
        SymmetricOrdering::Amd,
        // Supernodal always: faer's automatic choice took the simplicial factorization for the
        // armadillo (1,488 free unknowns), 5.57 ms per backward Euler step against 4.38
        // supernodal; the cloths and the bunny time the same either way.
        CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        },
    )
    .ok()?;
    let l_values = vec![0.0; symbolic.len_val()];
    let buf = MemBuffer::try_new(StackReq::any_of(&[
        symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
        symbolic.solve_in_place_scratch::<f64>(rhs_columns, Par::Seq),
    ]))
    .ok()?;
    Some((symbolic, l_values, buf))
}

/// Upper-triangle entries of a 3×3 block, in (column, row) order.
const UPPER: [(usize, usize); 6] = [(0, 0), (1, 0), (1, 1), (2, 0), (2, 1), (2, 2)];

fn failed() -> PcgReport {
    PcgReport {
        iterations: 0,
        relative_residual: Scalar::INFINITY,
        converged: false,
        failed: true,
    }
}

impl SparseCholesky {
    /// A solver with nothing analysed yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Nonzeros of the Cholesky factor (fill-in included), once analysed.
    pub fn factor_nonzeros(&self) -> Option<usize> {
        self.analysis.as_ref().map(|a| a.l_values.len())
    }

    fn matches(an: &Analysis, a: &SpringMatrix, mask: &[Scalar]) -> bool {
        an.pairs == a.pairs()
            && an.free.len() == mask.len()
            && an
                .free
                .iter()
                .zip(mask)
                .all(|(f, m)| (*f != u32::MAX) == (*m != 0.0))
    }

    fn analyse(a: &SpringMatrix, mask: &[Scalar]) -> Option<Analysis> {
        let mut free = Vec::with_capacity(mask.len());
        let mut m = 0u32;
        for &w in mask {
            if w != 0.0 {
                free.push(m);
                m += 1;
            } else {
                free.push(u32::MAX);
            }
        }
        let dim = 3 * m as usize;
        // Upper-triangle keys (column, row) of every structural nonzero.
        let mut keys: Vec<(usize, usize)> = Vec::new();
        for &c in &free {
            if c != u32::MAX {
                let b = 3 * c as usize;
                keys.extend(UPPER.iter().map(|&(cc, r)| (b + cc, b + r)));
            }
        }
        for &(i, j) in a.pairs() {
            let (ci, cj) = (free[i as usize], free[j as usize]);
            if ci != u32::MAX && cj != u32::MAX && ci != cj {
                let (p, q) = (3 * ci.min(cj) as usize, 3 * ci.max(cj) as usize);
                for c in 0..3 {
                    for r in 0..3 {
                        keys.push((q + c, p + r));
                    }
                }
            }
        }
        keys.sort_unstable();
        keys.dedup();
        let mut col_ptr = vec![0usize; dim + 1];
        for &(c, _) in &keys {
            col_ptr[c + 1] += 1;
        }
        for c in 0..dim {
            col_ptr[c + 1] += col_ptr[c];
        }
        let row_idx: Vec<usize> = keys.iter().map(|&(_, r)| r).collect();
        let pos = |key: (usize, usize)| keys.binary_search(&key).expect("structural key") as u32;
        let diag_pos = free
            .iter()
            .map(|&c| {
                let mut out = [0u32; 6];
                if c != u32::MAX {
                    let b = 3 * c as usize;
                    for (o, &(cc, r)) in out.iter_mut().zip(&UPPER) {
                        *o = pos((b + cc, b + r));
                    }
                }
                out
            })
            .collect();
        let off_pos = a
            .pairs()
            .iter()
            .map(|&(i, j)| {
                let (ci, cj) = (free[i as usize], free[j as usize]);
                if ci == u32::MAX || cj == u32::MAX {
                    OffSlot::Skip
                } else if ci == cj {
                    OffSlot::SelfBlock(i)
                } else {
                    let (p, q) = (3 * ci.min(cj) as usize, 3 * ci.max(cj) as usize);
                    let mut out = [0u32; 9];
                    // The block is A_ij (row i); the upper triangle holds the block at row
                    // min(i, j), which is its transpose when i is the larger.
                    for c in 0..3 {
                        for r in 0..3 {
                            out[3 * c + r] = if ci < cj {
                                pos((q + c, p + r))
                            } else {
                                pos((q + r, p + c))
                            };
                        }
                    }
                    OffSlot::Off(out)
                }
            })
            .collect();
        let (symbolic, l_values, buf) = analyse_upper(dim, &col_ptr, &row_idx, 1)?;
        Some(Analysis {
            pairs: a.pairs().to_vec(),
            free,
            dim,
            col_ptr,
            row_idx,
            diag_pos,
            off_pos,
            symbolic,
            l_values,
            buf,
        })
    }

    /// Solves `A x = b` on the free degrees of freedom (`mask[i] = 1`); constrained entries of
    /// `x` keep their value and their coupling to free ones is moved to the right-hand side,
    /// exactly as [`super::Pcg::solve`] filters them, so both give the same answer.
    pub fn solve(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
    ) -> PcgReport {
        self.solve_filtered(a, b, x, mask, &[])
    }

    /// [`SparseCholesky::solve`] with some particles free only along directions
    /// (`filters`: a particle and the projector `S = I − Σ nₖnₖᵀ` onto the directions it is
    /// free in), as [`super::Pcg::solve_filtered`] takes them. A filtered particle's `x` is
    /// `S y + (I − S) x₀`: its start value's part outside `S` kept (prescribed), `y` the
    /// unknown. The factored matrix is Baraff and Witkin's filtered system made whole,
    /// `Â = S A S + (I − S)` (Ascher and Boxerman, *On the modified conjugate gradient method
    /// in cloth simulation*, 2003): block `(i, j)` is `Sᵢ A_ij S_j`, and `I − Sᵢ` on a filtered
    /// diagonal block fixes the held directions' unknowns at zero. Its right-hand side is
    /// `S (b − A x_c)`, `x_c` the known values (constrained particles' `x`, the filtered ones'
    /// `(I − S) x₀`). `Â` has `A`'s structure, so the symbolic analysis is shared with the
    /// unfiltered solves; it is positive definite wherever `A` is on the free directions. With
    /// no filters this is [`SparseCholesky::solve`], bit for bit.
    ///
    /// # Panics
    /// If a filter's particle is not in the matrix.
    pub fn solve_filtered(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
    ) -> PcgReport {
        self.factored = false;
        if !self
            .analysis
            .as_ref()
            .is_some_and(|an| Self::matches(an, a, mask))
        {
            self.analysis = Self::analyse(a, mask);
            self.analyses += 1;
        }
        self.set_filters(a.len(), filters);
        let report = self.factor_and_substitute(a, b, x, mask, filters);
        self.clear_filters(filters);
        if self.factored {
            self.factored_filters.clear();
            self.factored_filters.extend_from_slice(filters);
        }
        report
    }

    /// [`SparseCholesky::solve_filtered`] with constraints on combinations of particles as
    /// well ([`PointRows`], factored with these `filters`): the range-space method (Nocedal
    /// and Wright, *Numerical Optimization*, §16.2). With `x₀` the filtered solve's answer,
    /// `x = x₀ + Â⁻¹ C'ᵀ λ` where the rows' Schur complement `M = C' Â⁻¹ C'ᵀ` gives
    /// `M λ = c − C x₀`: the rows' prescribed values, and `A x − b` along the rows only. `M`
    /// is not formed (a pair of triangular solves a row: 54 a solve for a 32² cloth on a rod);
    /// conjugate gradients solve for `λ`, each iteration one pair of triangular solves (24 a
    /// solve on that cloth, 5.6 for a tet slab on the rod), preconditioned by
    /// `H = C' D⁻¹ C'ᵀ` ([`PointRows::set_metric`]), which `M` equals where `A` is its
    /// diagonal blocks, to `10⁻¹²` of the first shortfall (in `f64`). With no rows this is
    /// [`SparseCholesky::solve_filtered`], bit for bit.
    pub fn solve_constrained(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
        rows: &mut PointRows,
    ) -> PcgReport {
        let report = self.solve_filtered(a, b, x, mask, filters);
        if report.failed || rows.is_empty() {
            return report;
        }
        self.correct_for_rows(a, x, filters, rows, report)
    }

    /// [`SparseCholesky::resolve`] with the rows as well, as
    /// [`SparseCholesky::solve_constrained`] takes them (the factor of the last matrix, and
    /// its Schur complement's conjugate gradients again).
    pub fn resolve_constrained(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
        rows: &mut PointRows,
    ) -> Option<PcgReport> {
        let report = self.resolve(a, b, x, mask, filters)?;
        if report.failed || rows.is_empty() {
            return Some(report);
        }
        Some(self.correct_for_rows(a, x, filters, rows, report))
    }

    /// The range-space correction of [`SparseCholesky::solve_constrained`]:
    /// `x ← x + Â⁻¹ C'ᵀ λ` with the factor in place, `x` the filtered solve's answer whose
    /// `report` it returns (or a failure).
    fn correct_for_rows(
        &mut self,
        a: &SpringMatrix,
        x: &mut [Vector],
        filters: &[(u32, Matrix3)],
        rows: &mut PointRows,
        report: PcgReport,
    ) -> PcgReport {
        rows.set_metric(&a.diag, filters);
        let Some(an) = self.analysis.as_mut() else {
            return failed();
        };
        let (dim, k) = (an.dim, rows.len());
        let llt = faer::sparse::linalg::cholesky::LltRef::<'_, usize, f64>::new(
            &an.symbolic,
            &an.l_values,
        );
        // `schur_m`: r, z, p and M p by row (λ itself is not needed); `schur_dx`: Â⁻¹ C'ᵀ λ;
        // `schur`: Â⁻¹ C'ᵀ p.
        let v = &mut self.schur_m;
        v.clear();
        crate::core::room(v, 4 * rows.room().max(k));
        v.resize(4 * k, 0.0);
        let (r, rest) = v.split_at_mut(k);
        let (z, rest) = rest.split_at_mut(k);
        let (p, mp) = rest.split_at_mut(k);
        for (q, r) in r.iter_mut().enumerate() {
            *r = rows.shortfall(q, x);
        }
        let first: f64 = r.iter().map(|v| v * v).sum::<f64>().sqrt();
        self.schur_dx.clear();
        self.schur_dx.resize(dim, 0.0);
        z.copy_from_slice(r);
        rows.solve_h(z);
        p.copy_from_slice(z);
        let mut rz: f64 = r.iter().zip(z.iter()).map(|(a, b)| a * b).sum();
        let mut residual = first;
        for _ in 0..k + 10 {
            // (A non-finite residual ends it too; the answer is checked below.)
            if residual <= 1e-12 * first || !residual.is_finite() {
                break;
            }
            // w = Â⁻¹ C'ᵀ p (on the free unknowns), M p = C' w.
            let w = &mut self.schur;
            w.clear();
            w.resize(dim, 0.0);
            for (q, &pq) in p.iter().enumerate() {
                let (row, kept) = rows.row(q);
                if !kept || pq == 0.0 {
                    continue;
                }
                for &(i, c) in row {
                    let f = an.free[i as usize];
                    if f != u32::MAX {
                        for d in 0..3 {
                            w[3 * f as usize + d] += c[d] as f64 * pq;
                        }
                    }
                }
            }
            llt.solve_in_place_with_conj(
                Conj::No,
                MatMut::from_column_major_slice_mut(w, dim, 1),
                Par::Seq,
                MemStack::new(&mut an.buf),
            );
            for (q, mp) in mp.iter_mut().enumerate() {
                let (row, kept) = rows.row(q);
                *mp = 0.0;
                if !kept {
                    continue;
                }
                for &(i, c) in row {
                    let f = an.free[i as usize];
                    if f != u32::MAX {
                        let f = 3 * f as usize;
                        *mp += c.x as f64 * w[f] + c.y as f64 * w[f + 1] + c.z as f64 * w[f + 2];
                    }
                }
            }
            let pmp: f64 = p.iter().zip(mp.iter()).map(|(a, b)| a * b).sum();
            if !(pmp > 0.0 && pmp.is_finite()) {
                return failed();
            }
            let alpha = rz / pmp;
            for (r, mp) in r.iter_mut().zip(mp.iter()) {
                *r -= alpha * mp;
            }
            for (dx, w) in self.schur_dx.iter_mut().zip(w.iter()) {
                *dx += alpha * w;
            }
            residual = r.iter().map(|v| v * v).sum::<f64>().sqrt();
            z.copy_from_slice(r);
            rows.solve_h(z);
            let rz_new: f64 = r.iter().zip(z.iter()).map(|(a, b)| a * b).sum();
            let beta = rz_new / rz;
            rz = rz_new;
            for (p, z) in p.iter_mut().zip(z.iter()) {
                *p = z + beta * *p;
            }
        }
        if !self.schur_dx.iter().all(|v| v.is_finite()) {
            return failed();
        }
        for (i, xi) in x.iter_mut().enumerate().take(a.len()) {
            let f = an.free[i];
            if f != u32::MAX {
                let f = 3 * f as usize;
                *xi += [self.schur_dx[f], self.schur_dx[f + 1], self.schur_dx[f + 2]].to_scalar();
            }
        }
        report
    }

    /// Marks each filtered particle's place in `filter_of`.
    fn set_filters(&mut self, n: usize, filters: &[(u32, Matrix3)]) {
        if self.filter_of.len() < n {
            self.filter_of.resize(n, u32::MAX);
        }
        for (k, &(i, _)) in filters.iter().enumerate() {
            self.filter_of[i as usize] = k as u32;
        }
    }

    /// Puts `filter_of` back to all `u32::MAX`.
    fn clear_filters(&mut self, filters: &[(u32, Matrix3)]) {
        for &(i, _) in filters {
            self.filter_of[i as usize] = u32::MAX;
        }
    }

    /// Particle `i`'s projector among `filters`, if it has one.
    fn filter(filter_of: &[u32], filters: &[(u32, Matrix3)], i: usize) -> Option<Matrix3> {
        match filter_of[i] {
            u32::MAX => None,
            k => Some(filters[k as usize].1),
        }
    }

    /// Assembles `Â`, factors it and substitutes (`filter_of` set for `filters`).
    fn factor_and_substitute(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
    ) -> PcgReport {
        let Some(bnorm2) = self.right_hand_side(a, b, x, mask, filters) else {
            return failed();
        };
        let Some(an) = self.analysis.as_mut() else {
            return failed();
        };
        let filter = |i: usize| Self::filter(&self.filter_of, filters, i);
        // Values of the free-free upper triangle.
        self.values.clear();
        self.values.resize(an.row_idx.len(), 0.0);
        for (i, d) in a.diag.iter().enumerate() {
            if an.free[i] != u32::MAX {
                let d = match filter(i) {
                    None => *d,
                    Some(s) => s * *d * s + (Matrix3::IDENTITY - s),
                };
                for (&p, &(c, r)) in an.diag_pos[i].iter().zip(&UPPER) {
                    self.values[p as usize] += d.col(c)[r] as f64;
                }
            }
        }
        for ((o, slot), &(i, j)) in a.off.iter().zip(&an.off_pos).zip(a.pairs()) {
            let o = match (filter(i as usize), filter(j as usize)) {
                (None, None) => *o,
                (si, sj) => si.unwrap_or(Matrix3::IDENTITY) * *o * sj.unwrap_or(Matrix3::IDENTITY),
            };
            match slot {
                OffSlot::Skip => {}
                OffSlot::Off(pos) => {
                    for c in 0..3 {
                        for r in 0..3 {
                            self.values[pos[3 * c + r] as usize] += o.col(c)[r] as f64;
                        }
                    }
                }
                OffSlot::SelfBlock(i) => {
                    for (&p, &(c, r)) in an.diag_pos[*i as usize].iter().zip(&UPPER) {
                        self.values[p as usize] += 2.0 * o.col(c)[r] as f64;
                    }
                }
            }
        }
        if !self.values.iter().all(|v| v.is_finite()) {
            return failed();
        }
        if an.dim == 0 {
            return PcgReport {
                iterations: 0,
                relative_residual: 0.0,
                converged: true,
                failed: false,
            };
        }
        let sym =
            SymbolicSparseColMatRef::new_checked(an.dim, an.dim, &an.col_ptr, None, &an.row_idx);
        let mat = SparseColMatRef::new(sym, &self.values);
        if an
            .symbolic
            .factorize_numeric_llt::<f64>(
                &mut an.l_values,
                mat,
                Side::Upper,
                LltRegularization::default(),
                Par::Seq,
                MemStack::new(&mut an.buf),
                Default::default(),
            )
            .is_err()
        {
            return failed();
        }
        self.factored = true;
        self.substitute(a, b, x, mask, filters, bnorm2)
    }

    /// Solves `A' x = b` with the factor of the last matrix `A'` [`SparseCholesky::solve`]
    /// or [`SparseCholesky::solve_filtered`] factored (a modified Newton step: no assembly,
    /// no factorization, two triangular solves). `a` must be that same matrix (its structure
    /// is checked; its values give the constrained entries' coupling and the reported
    /// residual). `None` when there is no usable factor for this structure, or when `filters`
    /// are not the ones it was factored with.
    pub fn resolve(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
    ) -> Option<PcgReport> {
        if !self.factored
            || self.factored_filters != filters
            || !self
                .analysis
                .as_ref()
                .is_some_and(|an| an.dim > 0 && Self::matches(an, a, mask))
        {
            return None;
        }
        self.set_filters(a.len(), filters);
        let report = match self.right_hand_side(a, b, x, mask, filters) {
            None => failed(),
            Some(bnorm2) => self.substitute(a, b, x, mask, filters, bnorm2),
        };
        self.clear_filters(filters);
        Some(report)
    }

    /// `S (b_f − A_fc x_c)` into `rhs` (the known values moved to the right-hand side:
    /// constrained entries' `x`, filtered ones' `(I − S) x`); returns `‖S b_f‖²`, `None` when
    /// not finite or not analysed. `filter_of` is set for `filters`.
    #[allow(clippy::needless_range_loop)] // one index over parallel arrays
    fn right_hand_side(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &[Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
    ) -> Option<f64> {
        let n = a.len();
        let an = self.analysis.as_ref()?;
        let filter = |i: usize| Self::filter(&self.filter_of, filters, i);
        self.xc.resize(n, Vector::ZERO);
        self.q.resize(n, Vector::ZERO);
        for i in 0..n {
            self.xc[i] = if mask[i] != 0.0 { Vector::ZERO } else { x[i] };
        }
        for &(i, s) in filters {
            let i = i as usize;
            if mask[i] != 0.0 {
                self.xc[i] = x[i] - s * x[i];
            }
        }
        a.mul(&self.xc, &mut self.q);
        self.rhs.resize(an.dim, 0.0);
        let mut bnorm2 = 0.0f64;
        for i in 0..n {
            let c = an.free[i];
            if c != u32::MAX {
                let (r, bi) = match filter(i) {
                    None => (b[i] - self.q[i], b[i] * mask[i]),
                    Some(s) => (s * (b[i] - self.q[i]), s * (b[i] * mask[i])),
                };
                for k in 0..3 {
                    self.rhs[3 * c as usize + k] = r[k] as f64;
                }
                bnorm2 += bi.length_squared() as f64;
            }
        }
        bnorm2.is_finite().then_some(bnorm2)
    }

    /// Forward and back substitution with the stored factor, the free entries of `x` set from
    /// the result (a filtered particle's `S y + (I − S) x`), and the residual `‖S (b − A x)‖`
    /// for the report. `filter_of` is set for `filters`.
    #[allow(clippy::needless_range_loop)] // one index over parallel arrays
    fn substitute(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
        filters: &[(u32, Matrix3)],
        bnorm2: f64,
    ) -> PcgReport {
        let n = a.len();
        let Some(an) = self.analysis.as_mut() else {
            return failed();
        };
        let llt = faer::sparse::linalg::cholesky::LltRef::<'_, usize, f64>::new(
            &an.symbolic,
            &an.l_values,
        );
        llt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut self.rhs, an.dim, 1),
            Par::Seq,
            MemStack::new(&mut an.buf),
        );
        if !self.rhs.iter().all(|v| v.is_finite()) {
            return failed();
        }
        for i in 0..n {
            let c = an.free[i];
            if c != u32::MAX {
                let s = 3 * c as usize;
                let y: Vector = ([self.rhs[s], self.rhs[s + 1], self.rhs[s + 2]]).to_scalar();
                x[i] = match Self::filter(&self.filter_of, filters, i) {
                    None => y,
                    Some(s) => s * y + (x[i] - s * x[i]),
                };
            }
        }
        // The residual, for the report (one product; direct solves should reach round-off).
        a.mul(x, &mut self.q);
        let mut r2 = 0.0f64;
        for i in 0..n {
            let r = (b[i] - self.q[i]) * mask[i];
            r2 += match Self::filter(&self.filter_of, filters, i) {
                None => r,
                Some(s) => s * r,
            }
            .length_squared() as f64;
        }
        let rel = if bnorm2 > 0.0 {
            (r2 / bnorm2).sqrt()
        } else {
            r2.sqrt()
        };
        PcgReport {
            iterations: 0,
            relative_residual: rel as Scalar,
            converged: true,
            failed: false,
        }
    }
}
