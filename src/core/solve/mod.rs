//! Linear algebra for implicit steps: a symmetric block-sparse matrix with the sparsity of a
//! spring network, preconditioned conjugate gradients with Baraff–Witkin's constraint filter,
//! and a sparse direct (Cholesky) solve through faer.

pub(crate) mod cholesky;
pub mod multigrid;

pub use cholesky::SparseCholesky;
pub use multigrid::Multigrid;

use crate::core::forces::Springs;
use crate::math::{Matrix3, Scalar, Vector};

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
}

impl SpringMatrix {
    /// A zero matrix for `n` particles with the structure of `springs`.
    pub fn new(n: usize, springs: &Springs) -> Self {
        Self {
            diag: vec![Matrix3::ZERO; n],
            off: vec![Matrix3::ZERO; springs.len()],
            pairs: springs.as_slice().iter().map(|s| (s.i, s.j)).collect(),
            symmetric: springs.len(),
        }
    }

    /// A zero matrix for `n` particles with off-diagonal blocks at `pairs`.
    pub fn with_pairs(n: usize, pairs: Vec<(u32, u32)>) -> Self {
        Self {
            diag: vec![Matrix3::ZERO; n],
            off: vec![Matrix3::ZERO; pairs.len()],
            pairs,
            symmetric: 0,
        }
    }

    /// Declares the first `k` off-diagonal blocks symmetric (whoever fills them keeps them
    /// so): [`mul`](Self::mul) then skips their transpose.
    pub fn with_symmetric_prefix(mut self, k: usize) -> Self {
        self.symmetric = k.min(self.off.len());
        self
    }

    /// True when this matrix has `n` block rows and off-diagonal blocks at `pairs`.
    pub fn matches_pairs(
        &self,
        n: usize,
        pairs: impl ExactSizeIterator<Item = (u32, u32)>,
    ) -> bool {
        self.diag.len() == n
            && self.pairs.len() == pairs.len()
            && self.pairs.iter().copied().eq(pairs)
    }

    /// True when this matrix has the structure of `springs` over `n` particles.
    pub fn matches(&self, n: usize, springs: &Springs) -> bool {
        self.diag.len() == n
            && self.pairs.len() == springs.len()
            && self
                .pairs
                .iter()
                .zip(springs.as_slice())
                .all(|(p, s)| p.0 == s.i && p.1 == s.j)
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

    /// `y ← A x`.
    pub fn mul(&self, x: &[Vector], y: &mut [Vector]) {
        for ((yi, d), xi) in y.iter_mut().zip(&self.diag).zip(x) {
            *yi = *d * *xi;
        }
        let k = self.symmetric;
        for (o, &(i, j)) in self.off[..k].iter().zip(&self.pairs[..k]) {
            let (i, j) = (i as usize, j as usize);
            y[i] += *o * x[j];
            y[j] += *o * x[i];
        }
        for (o, &(i, j)) in self.off[k..].iter().zip(&self.pairs[k..]) {
            let (i, j) = (i as usize, j as usize);
            y[i] += *o * x[j];
            // (oᵀ x_i)_k = col_k · x_i
            let xi = x[i];
            y[j] += Vector::new(o.x_axis.dot(xi), o.y_axis.dot(xi), o.z_axis.dot(xi));
        }
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

    /// Solves with the factorization of the last matrix solved (modified Newton); `None`
    /// when the solver keeps none (PCG) or has none for this structure. See
    /// [`SparseCholesky::resolve`].
    pub fn resolve(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
    ) -> Option<SolveReport> {
        match self {
            LinearSolver::Pcg(_) => None,
            LinearSolver::Cholesky(c) => c.resolve(a, b, x, mask),
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

/// `inv[i] ← diag[i]⁻¹`, the identity where a block is singular or not finite.
fn invert_blocks(diag: &[Matrix3], inv: &mut Vec<Matrix3>) {
    inv.resize(diag.len(), Matrix3::IDENTITY);
    for (inv, d) in inv.iter_mut().zip(diag) {
        let det = d.determinant();
        *inv = if det.is_normal() {
            d.inverse()
        } else {
            Matrix3::IDENTITY
        };
    }
}

fn dot(a: &[Vector], b: &[Vector]) -> Scalar {
    a.iter().zip(b).map(|(x, y)| x.dot(*y)).sum()
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
    fn precondition(&mut self, a: &SpringMatrix, mask: &[Scalar]) {
        match self.active {
            Preconditioner::BlockJacobi => {
                for ((z, inv), r) in self.z.iter_mut().zip(&self.inv_diag).zip(&self.r) {
                    *z = *inv * *r;
                }
            }
            _ => self.multigrid.apply(a, mask, &self.r, &mut self.z),
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
        }
    }

    /// Solves `A x = b` on the free degrees of freedom (`mask[i] = 1`) starting from `x`;
    /// entries with `mask[i] = 0` keep their value in `x`.
    #[allow(clippy::needless_range_loop)] // one index over five parallel arrays
    pub fn solve(
        &mut self,
        a: &SpringMatrix,
        b: &[Vector],
        x: &mut [Vector],
        mask: &[Scalar],
    ) -> PcgReport {
        let n = a.len();
        for v in [&mut self.r, &mut self.z, &mut self.p, &mut self.q] {
            v.resize(n, Vector::ZERO);
        }
        self.active = self.preconditioner.for_size(n);
        match self.active {
            Preconditioner::BlockJacobi => {
                invert_blocks(&a.diag, &mut self.inv_diag);
            }
            _ => self.multigrid.setup(a, mask),
        }
        // r = S (b − A x)
        a.mul(x, &mut self.q);
        for i in 0..n {
            self.r[i] = (b[i] - self.q[i]) * mask[i];
        }
        let bnorm = b
            .iter()
            .zip(mask)
            .map(|(v, m)| (*v * *m).length_squared())
            .sum::<Scalar>()
            .sqrt();
        if bnorm == 0.0 {
            for (xi, m) in x.iter_mut().zip(mask) {
                if *m != 0.0 {
                    *xi = Vector::ZERO;
                }
            }
            return PcgReport {
                iterations: 0,
                relative_residual: 0.0,
                converged: true,
                failed: false,
            };
        }
        self.precondition(a, mask);
        for i in 0..n {
            self.p[i] = self.z[i] * mask[i];
        }
        let mut rz = dot(&self.r, &self.z);
        let mut it = 0;
        let mut rel = dot(&self.r, &self.r).sqrt() / bnorm;
        let mut failed = !rel.is_finite();
        while rel > self.tolerance && it < self.max_iterations && !failed {
            a.mul(&self.p, &mut self.q);
            for (qi, m) in self.q.iter_mut().zip(mask) {
                *qi *= *m;
            }
            let pq = dot(&self.p, &self.q);
            if pq.is_nan() || pq <= 0.0 {
                // Not positive definite along p, or a non-finite value: the answer is unusable.
                failed = true;
                break;
            }
            let alpha = rz / pq;
            if self.active == Preconditioner::BlockJacobi {
                // Fused: one sweep over the vectors.
                for i in 0..n {
                    x[i] += self.p[i] * alpha;
                    self.r[i] -= self.q[i] * alpha;
                    self.z[i] = self.inv_diag[i] * self.r[i];
                }
            } else {
                for i in 0..n {
                    x[i] += self.p[i] * alpha;
                    self.r[i] -= self.q[i] * alpha;
                }
                self.precondition(a, mask);
            }
            let rz_new = dot(&self.r, &self.z);
            let beta = rz_new / rz;
            rz = rz_new;
            for i in 0..n {
                self.p[i] = (self.z[i] + self.p[i] * beta) * mask[i];
            }
            it += 1;
            rel = dot(&self.r, &self.r).sqrt() / bnorm;
            failed |= !rel.is_finite();
        }
        PcgReport {
            iterations: it,
            relative_residual: rel,
            converged: !failed && rel <= self.tolerance,
            failed,
        }
    }
}
