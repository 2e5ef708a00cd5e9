//! The methods games use: extended position-based dynamics (XPBD) with small steps, and
//! projective dynamics. Both work on a particle model's springs as constraints; both treat
//! the springs implicitly (no explicit stability bound) and the applied forces — gravity,
//! wind, external forces, fields — explicitly, at the step's start.
//!
//! How their parameters relate to the springs' (so that both integrate the same model as the
//! other methods, and converge to its trajectory):
//!
//! - **XPBD** (Macklin, Müller and Chentanez, *XPBD: Position-Based Simulation of Compliant
//!   Constrained Dynamics*, 2016): each spring is the constraint `C = |x_i − x_j| − L` with
//!   compliance `α = 1/k` (its energy `C²/(2α)` is the spring's `½ k (l − L)²`) and the
//!   damper `b` is the constraint's damping `β = b` (dissipation `½ β (∇C·v)²`). With small
//!   steps (Macklin, Storey, Lu, Terdiman, Chentanez, Jeschke and Müller, *Small Steps in
//!   Physics Simulation*, 2019) one Gauss–Seidel sweep per step is taken and the multipliers
//!   start from zero each step; the update, multiplied through by `k h²` so that `k = 0` and
//!   large `k` need no special case, is
//!   `Δλ = (−k h² C − λ − b h ∇C·(x − xⁿ)) / (1 + (k h² + b h)(w_i + w_j))`,
//!   `x_i += w_i Δλ ∇C`, `x_j −= w_j Δλ ∇C` (`λ/h²` is the spring's force). As `h → 0` the
//!   correction is `h² M⁻¹ f(x̃)` at the predicted positions, so the method is first-order
//!   consistent with the spring model (measured in the tests). Where its numerical damping
//!   shows: at large `h k/m`, a sweep does not satisfy the constraints, so stiff springs act
//!   softer and stretch more; at rest its equilibrium is exact (`C = m g/k` for a hanging
//!   mass, whatever `h`).
//! - **Projective dynamics** (Bouaziz, Martin, Liu, Kavan and Pauly, *Projective Dynamics:
//!   Fusing Constraint Projection for Fast Simulation*, 2014; for springs the same as Liu,
//!   Bargteil, O'Brien and Kavan, *Fast Simulation of Mass-Spring Systems*, 2013): backward
//!   Euler's incremental potential
//!   `g(x) = |x − y|²_M/(2h²) + c |x − xⁿ|²/(2h) + Σ_s [½ k |x_ij − d_s|² + b/(2h) |Δx_ij − q_s|²]`
//!   minimized by local/global iterations, `y = xⁿ + h vⁿ + h² M⁻¹ f_applied`. The local step
//!   projects each spring's direction `d_s = L x_ij/|x_ij|` (weight `k`, so the spring's own
//!   energy is `min_d ½ k |x_ij − d|² = ½ k (l − L)²`) and its damper's velocity onto the
//!   plane normal to the spring at the step's start (`q_s`, weight `b/h`: the damper's
//!   Rayleigh term `h ½ b (n₀·v_ij)²`, exactly as backward Euler has it). The global step
//!   solves `(M/h² + c/h + Σ (k + b/h) L_s) x = …`, one constant matrix prefactored by sparse
//!   Cholesky and shared by the three coordinates. Each half step minimizes `g` exactly over
//!   its variables, so `g` never rises (tested); converged, the result is backward Euler's
//!   (tested against the Newton solver). Where its numerical damping shows: it is backward
//!   Euler's (every mode with `h ω ≳ 1` loses most of its energy in a period), plus an
//!   under-converged solve at few iterations, which also acts as extra softness.

use super::{Integrator, IntegratorKind, IntegratorStats, StepError, check_h};
use crate::core::forces::Springs;
use crate::core::jacobian::Linearization;
use crate::core::ode::{OdeState, OdeSystem, ParticleState};
use crate::core::solve::cholesky::analyse_upper;
use crate::math::{Scalar, ToScalar, Vector};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{LltRef, SymbolicCholesky};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

/// What both methods start a step with: the step size checked, the model's linearization,
/// its springs as constraints, the particles and the free mask (`w_i = mask_i / m_i`).
fn setup<'a, S: OdeState, Sys: OdeSystem<S> + ?Sized>(
    kind: IntegratorKind,
    sys: &'a Sys,
    h: Scalar,
    state: &'a mut S,
    mask: &mut Vec<Scalar>,
) -> Result<(&'a dyn Linearization, &'a Springs, &'a mut ParticleState), StepError> {
    check_h(h)?;
    let lin = sys.linearization().ok_or(StepError::NeedsJacobians(kind))?;
    let springs = lin
        .constraint_springs()
        .ok_or(StepError::NeedsSprings(kind))?;
    let ps = state
        .as_particles_mut()
        .ok_or(StepError::NeedsSecondOrder(kind))?;
    mask.resize(lin.particles(), 0.0);
    if !lin.free_mask(mask) {
        return Err(StepError::SolverFailed(kind));
    }
    Ok((lin, springs, ps))
}

/// XPBD with small steps: one Gauss–Seidel sweep over the springs per step by default (see
/// the module docs for the update and how compliance relates to stiffness).
#[derive(Clone, Debug)]
pub struct Xpbd {
    /// Constraint sweeps per step (1: Macklin et al.'s small steps; more approach the
    /// implicit Euler step of the constraint formulation).
    pub iterations: u32,
    f: Vec<Vector>,
    x0: Vec<Vector>,
    dx: Vec<Vector>,
    inv_mass: Vec<Scalar>,
    mask: Vec<Scalar>,
    lambda: Vec<Scalar>,
    stats: IntegratorStats,
}

impl Default for Xpbd {
    fn default() -> Self {
        Self {
            iterations: 1,
            f: vec![],
            x0: vec![],
            dx: vec![],
            inv_mass: vec![],
            mask: vec![],
            lambda: vec![],
            stats: IntegratorStats::default(),
        }
    }
}

impl<S: OdeState, Sys: OdeSystem<S> + ?Sized> Integrator<S, Sys> for Xpbd {
    fn kind(&self) -> IntegratorKind {
        IntegratorKind::Xpbd
    }

    #[allow(clippy::needless_range_loop)] // one index over parallel arrays
    fn step(
        &mut self,
        sys: &Sys,
        t: Scalar,
        h: Scalar,
        state: &mut S,
    ) -> Result<Scalar, StepError> {
        let (lin, springs, ps) = setup(IntegratorKind::Xpbd, sys, h, state, &mut self.mask)?;
        let n = lin.particles();
        self.f.clear();
        self.f.resize(n, Vector::ZERO);
        self.x0.resize(n, Vector::ZERO);
        self.dx.resize(n, Vector::ZERO);
        self.inv_mass.resize(n, 0.0);
        self.lambda.clear();
        self.lambda.resize(springs.len(), 0.0);
        lin.applied_forces(t, ps, &mut self.f);
        let c = lin.drag_coefficient();
        let m = lin.masses();
        for i in 0..n {
            self.inv_mass[i] = if self.mask[i] != 0.0 { 1.0 / m[i] } else { 0.0 };
            self.v_kick(i, ps, h, c);
        }
        self.x0.copy_from_slice(&ps.x);
        lin.constrained_velocities(t + h, h, &self.x0, &mut ps.v);
        // The sweep works on displacements `δ = x − xⁿ` (`x` is `xⁿ + δ` throughout): the
        // velocity `δ/h` then carries no round-off of the positions' magnitude, which in f32
        // would swamp it at small steps (`ulp(x)/h`).
        for i in 0..n {
            self.dx[i] = ps.v[i] * h;
        }
        let (dx, x0, w) = (&mut self.dx, &self.x0, &self.inv_mass);
        for _ in 0..self.iterations {
            for (s, lambda) in springs.as_slice().iter().zip(&mut self.lambda) {
                let (i, j) = (s.i as usize, s.j as usize);
                let wsum = w[i] + w[j];
                let rel = dx[i] - dx[j];
                let d = (x0[i] - x0[j]) + rel;
                let l = d.length();
                // A zero-length spring has no direction (and exerts nothing in the model).
                if wsum == 0.0 || l == 0.0 {
                    continue;
                }
                let nrm = d / l;
                let kh2 = s.k * h * h;
                let bh = s.damping * h;
                let dl =
                    (-kh2 * (l - s.rest) - *lambda - bh * nrm.dot(rel)) / (1.0 + (kh2 + bh) * wsum);
                *lambda += dl;
                dx[i] += nrm * (w[i] * dl);
                dx[j] -= nrm * (w[j] * dl);
            }
        }
        let inv_h = 1.0 / h;
        for i in 0..n {
            if self.mask[i] != 0.0 {
                ps.v[i] = self.dx[i] * inv_h;
            }
            ps.x[i] = self.x0[i] + self.dx[i];
        }
        self.stats.steps += 1;
        self.stats.evaluations += self.iterations as u64;
        Ok(h)
    }

    counters!();
}

impl Xpbd {
    /// The explicit half of the step for particle `i`: `v += h w (f − c v)` on free particles.
    #[inline]
    fn v_kick(&self, i: usize, ps: &mut ParticleState, h: Scalar, c: Scalar) {
        let w = self.inv_mass[i];
        if w > 0.0 {
            let v = ps.v[i];
            ps.v[i] = v + (self.f[i] - v * c) * (h * w);
        }
    }
}

/// The global step's matrix, factored once per structure, step size and set of parameters.
struct Factor {
    /// The parameters it was built from (compared each step: a change refactors).
    key_h: f64,
    key_c: f64,
    key_mass: Vec<Scalar>,
    key_springs: Vec<(u32, u32, Scalar, Scalar)>,
    /// Column of each particle in the factored matrix (`u32::MAX`: constrained).
    col: Vec<u32>,
    dim: usize,
    symbolic: SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    buf: MemBuffer,
}

impl Factor {
    fn matches(&self, h: f64, c: f64, mass: &[Scalar], mask: &[Scalar], springs: &Springs) -> bool {
        // A frame's landing step differs between frames by the round-off of the time sums
        // (about 1e-11 relative in f64): a factor within 1e-9 of the step is the same matrix
        // to far below the method's error, and refactoring every frame would not be.
        (self.key_h - h).abs() <= 1e-9 * h
            && self.key_c == c
            && self.key_mass.len() == mass.len()
            && self
                .key_mass
                .iter()
                .zip(mass.iter().zip(mask))
                .all(|(k, (m, f))| *k == *m * *f)
            && self.key_springs.len() == springs.len()
            && self
                .key_springs
                .iter()
                .zip(springs.as_slice())
                .all(|(k, s)| *k == (s.i, s.j, s.k, s.damping))
    }

    /// `M/h² + c/h + Σ (k + b/h) L_s` on the free particles, factored; `None` when it is not
    /// numerically positive definite (a spring of negative stiffness).
    fn new(h: f64, c: f64, mass: &[Scalar], mask: &[Scalar], springs: &Springs) -> Option<Self> {
        let n = mass.len();
        let mut col = vec![u32::MAX; n];
        let mut dim = 0usize;
        for i in 0..n {
            if mask[i] != 0.0 {
                col[i] = dim as u32;
                dim += 1;
            }
        }
        // Upper-triangle (column, row, value) triplets, summed by position below.
        let mut trip: Vec<(usize, usize, f64)> = Vec::with_capacity(dim + springs.len());
        for i in 0..n {
            if col[i] != u32::MAX {
                let d = col[i] as usize;
                trip.push((d, d, mass[i] as f64 / (h * h) + c / h));
            }
        }
        for s in springs.as_slice() {
            let wgt = s.k as f64 + s.damping as f64 / h;
            let (ci, cj) = (col[s.i as usize], col[s.j as usize]);
            if wgt == 0.0 || s.i == s.j {
                continue;
            }
            for cc in [ci, cj] {
                if cc != u32::MAX {
                    trip.push((cc as usize, cc as usize, wgt));
                }
            }
            if ci != u32::MAX && cj != u32::MAX {
                let (r, cl) = (ci.min(cj) as usize, ci.max(cj) as usize);
                trip.push((cl, r, -wgt));
            }
        }
        trip.sort_unstable_by_key(|&(c, r, _)| (c, r));
        let mut col_ptr = vec![0usize; dim + 1];
        let mut row_idx = Vec::with_capacity(trip.len());
        let mut values: Vec<f64> = Vec::with_capacity(trip.len());
        let mut last = None;
        for (c, r, v) in trip {
            if last == Some((c, r)) {
                *values.last_mut().expect("a value per key") += v;
            } else {
                col_ptr[c + 1] += 1;
                row_idx.push(r);
                values.push(v);
                last = Some((c, r));
            }
        }
        for c in 0..dim {
            col_ptr[c + 1] += col_ptr[c];
        }
        if !values.iter().all(|v| v.is_finite()) {
            return None;
        }
        let (symbolic, mut l_values, mut buf) = analyse_upper(dim, &col_ptr, &row_idx, 3)?;
        let sym = SymbolicSparseColMatRef::new_checked(dim, dim, &col_ptr, None, &row_idx);
        if dim > 0 {
            symbolic
                .factorize_numeric_llt::<f64>(
                    &mut l_values,
                    SparseColMatRef::new(sym, &values),
                    Side::Upper,
                    LltRegularization::default(),
                    Par::Seq,
                    MemStack::new(&mut buf),
                    Default::default(),
                )
                .ok()?;
        }
        Some(Self {
            key_h: h,
            key_c: c,
            key_mass: mass.iter().zip(mask).map(|(m, f)| *m * *f).collect(),
            key_springs: springs
                .as_slice()
                .iter()
                .map(|s| (s.i, s.j, s.k, s.damping))
                .collect(),
            col,
            dim,
            symbolic,
            l_values,
            buf,
        })
    }

    /// Solves in place for the three coordinates (`rhs` column-major, `dim × 3`).
    fn solve(&mut self, rhs: &mut [f64]) {
        if self.dim == 0 {
            return;
        }
        LltRef::<'_, usize, f64>::new(&self.symbolic, &self.l_values).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, self.dim, 3),
            Par::Seq,
            MemStack::new(&mut self.buf),
        );
    }
}

/// Projective dynamics: backward Euler's incremental potential minimized by a fixed number of
/// local/global iterations with a prefactored global matrix (see the module docs). The
/// iterate is kept in `f64` whatever the crate's precision.
pub struct ProjectiveDynamics {
    /// Local/global iterations per step (Bouaziz et al. use about ten).
    pub iterations: u32,
    /// Record `g` after each global step of the last step ([`ProjectiveDynamics::objectives`]).
    pub trace: bool,
    /// The factors of the last two distinct matrices, most recent last.
    factors: Vec<Factor>,
    mask: Vec<Scalar>,
    f: Vec<Vector>,
    x0: Vec<[f64; 3]>,
    y: Vec<[f64; 3]>,
    x: Vec<[f64; 3]>,
    /// Per spring: the local step's target `k d_s + (b/h)(x⁰_ij + q_s)`.
    target: Vec<[f64; 3]>,
    rhs: Vec<f64>,
    objectives: Vec<f64>,
    /// Refactorizations so far (one per change of step size, structure or parameters).
    pub factorizations: u64,
    stats: IntegratorStats,
}

impl Clone for ProjectiveDynamics {
    /// A fresh solver with the same settings (the factorization is redone on first use).
    fn clone(&self) -> Self {
        Self {
            iterations: self.iterations,
            trace: self.trace,
            ..Self::default()
        }
    }
}

impl std::fmt::Debug for ProjectiveDynamics {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ProjectiveDynamics")
            .field("iterations", &self.iterations)
            .field("factorizations", &self.factorizations)
            .finish()
    }
}

impl Default for ProjectiveDynamics {
    fn default() -> Self {
        Self {
            iterations: 10,
            trace: false,
            factors: Vec::with_capacity(2),
            mask: vec![],
            f: vec![],
            x0: vec![],
            y: vec![],
            x: vec![],
            target: vec![],
            rhs: vec![],
            objectives: vec![],
            factorizations: 0,
            stats: IntegratorStats::default(),
        }
    }
}

#[inline]
fn d3(v: Vector) -> [f64; 3] {
    [v.x as f64, v.y as f64, v.z as f64]
}

#[inline]
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

impl ProjectiveDynamics {
    /// `g` after each global step of the last step, when [`ProjectiveDynamics::trace`] is on
    /// (the first entry is `g` at the initial guess `y`).
    pub fn objectives(&self) -> &[f64] {
        &self.objectives
    }

    /// The incremental potential `g(x)` of the module docs at the current iterate (springs'
    /// and dampers' terms at their exact minimum over the projections).
    #[allow(clippy::needless_range_loop)] // one index over parallel arrays
    fn objective(&self, h: f64, c: f64, mass: &[Scalar], springs: &Springs) -> f64 {
        let mut g = 0.0;
        for i in 0..self.x.len() {
            if self.mask[i] != 0.0 {
                let e = sub(self.x[i], self.y[i]);
                let dx = sub(self.x[i], self.x0[i]);
                g += 0.5 * mass[i] as f64 / (h * h) * dot(e, e) + 0.5 * c / h * dot(dx, dx);
            }
        }
        for s in springs.as_slice() {
            let (i, j) = (s.i as usize, s.j as usize);
            let xij = sub(self.x[i], self.x[j]);
            let e = dot(xij, xij).sqrt() - s.rest as f64;
            g += 0.5 * s.k as f64 * e * e;
            let x0ij = sub(self.x0[i], self.x0[j]);
            let l0 = dot(x0ij, x0ij).sqrt();
            if s.damping != 0.0 && l0 > 0.0 {
                let rate = dot(sub(xij, x0ij), x0ij) / l0;
                g += 0.5 * s.damping as f64 / h * rate * rate;
            }
        }
        g
    }
}

impl<S: OdeState, Sys: OdeSystem<S> + ?Sized> Integrator<S, Sys> for ProjectiveDynamics {
    fn kind(&self) -> IntegratorKind {
        IntegratorKind::ProjectiveDynamics
    }

    #[allow(clippy::needless_range_loop)] // one index over parallel arrays
    fn step(
        &mut self,
        sys: &Sys,
        t: Scalar,
        h: Scalar,
        state: &mut S,
    ) -> Result<Scalar, StepError> {
        let kind = IntegratorKind::ProjectiveDynamics;
        let (lin, springs, ps) = setup(kind, sys, h, state, &mut self.mask)?;
        let n = lin.particles();
        let (h64, c) = (h as f64, lin.drag_coefficient() as f64);
        let mass = lin.masses();
        // Two factors are kept: a frame that does not divide into whole steps alternates
        // between the step and the shorter one that lands on the frame's end.
        let found = self
            .factors
            .iter()
            .position(|f| f.matches(h64, c, mass, &self.mask, springs));
        let mut factor = match found {
            Some(k) => self.factors.swap_remove(k),
            None => {
                self.factorizations += 1;
                match Factor::new(h64, c, mass, &self.mask, springs) {
                    Some(f) => f,
                    None => return Err(StepError::SolverFailed(kind)),
                }
            }
        };
        if self.factors.len() > 1 {
            self.factors.remove(0);
        }
        self.f.clear();
        self.f.resize(n, Vector::ZERO);
        lin.applied_forces(t, ps, &mut self.f);
        // Constrained particles' end-of-step positions come from their velocities.
        lin.constrained_velocities(t + h, h, &ps.x, &mut ps.v);
        for buf in [&mut self.x0, &mut self.y, &mut self.x] {
            buf.resize(n, [0.0; 3]);
        }
        for i in 0..n {
            self.x0[i] = d3(ps.x[i]);
            // In f64: the f32 sum would drop the part of `h v` below the positions' ulp.
            let pred = {
                let v = d3(ps.v[i]);
                [
                    self.x0[i][0] + h64 * v[0],
                    self.x0[i][1] + h64 * v[1],
                    self.x0[i][2] + h64 * v[2],
                ]
            };
            self.y[i] = if self.mask[i] != 0.0 {
                let a = d3(self.f[i]);
                let s = h64 * h64 / mass[i] as f64;
                [pred[0] + s * a[0], pred[1] + s * a[1], pred[2] + s * a[2]]
            } else {
                pred
            };
            self.x[i] = self.y[i];
        }
        self.target.resize(springs.len(), [0.0; 3]);
        let dim = factor.dim;
        self.rhs.resize(3 * dim, 0.0);
        self.objectives.clear();
        if self.trace {
            self.objectives.push(self.objective(h64, c, mass, springs));
        }
        for _ in 0..self.iterations {
            // Local step: each spring's projection, folded into its right-hand-side target.
            for (s, tg) in springs.as_slice().iter().zip(&mut self.target) {
                let (i, j) = (s.i as usize, s.j as usize);
                let xij = sub(self.x[i], self.x[j]);
                let x0ij = sub(self.x0[i], self.x0[j]);
                let l = dot(xij, xij).sqrt();
                let l0 = dot(x0ij, x0ij).sqrt();
                // d = L x_ij/|x_ij| (any direction minimizes at l = 0: the start's).
                let dir = if l > 0.0 {
                    scale(xij, 1.0 / l)
                } else if l0 > 0.0 {
                    scale(x0ij, 1.0 / l0)
                } else {
                    [1.0, 0.0, 0.0]
                };
                let d = scale(dir, s.rest as f64);
                // q = (I − n₀n₀ᵀ) Δx_ij: the damper's cost is its rate along n₀ (none at l₀ = 0).
                let dx = sub(xij, x0ij);
                let q = if l0 > 0.0 {
                    let n0 = scale(x0ij, 1.0 / l0);
                    sub(dx, scale(n0, dot(dx, n0)))
                } else {
                    dx
                };
                let (k, bh) = (s.k as f64, s.damping as f64 / h64);
                for a in 0..3 {
                    tg[a] = k * d[a] + bh * (x0ij[a] + q[a]);
                }
            }
            // Global step: right-hand side, constrained ends moved to it, then the solve.
            for i in 0..n {
                let cl = factor.col[i];
                if cl != u32::MAX {
                    let (mh, ch) = (mass[i] as f64 / (h64 * h64), c / h64);
                    for a in 0..3 {
                        self.rhs[a * dim + cl as usize] = mh * self.y[i][a] + ch * self.x0[i][a];
                    }
                }
            }
            for (s, tg) in springs.as_slice().iter().zip(&self.target) {
                let (i, j) = (s.i as usize, s.j as usize);
                if i == j {
                    continue;
                }
                let wgt = s.k as f64 + s.damping as f64 / h64;
                let (ci, cj) = (factor.col[i], factor.col[j]);
                for a in 0..3 {
                    if ci != u32::MAX {
                        let r = &mut self.rhs[a * dim + ci as usize];
                        *r += tg[a];
                        if cj == u32::MAX {
                            *r += wgt * self.x[j][a];
                        }
                    }
                    if cj != u32::MAX {
                        let r = &mut self.rhs[a * dim + cj as usize];
                        *r -= tg[a];
                        if ci == u32::MAX {
                            *r += wgt * self.x[i][a];
                        }
                    }
                }
            }
            factor.solve(&mut self.rhs);
            for i in 0..n {
                let cl = factor.col[i];
                if cl != u32::MAX {
                    for a in 0..3 {
                        self.x[i][a] = self.rhs[a * dim + cl as usize];
                    }
                }
            }
            if self.trace {
                self.objectives.push(self.objective(h64, c, mass, springs));
            }
        }
        self.factors.push(factor);
        if !self.x.iter().all(|p| p.iter().all(|c| c.is_finite())) {
            return Err(StepError::SolverFailed(kind));
        }
        let inv_h = 1.0 / h64;
        for i in 0..n {
            if self.mask[i] != 0.0 {
                ps.v[i] = scale(sub(self.x[i], self.x0[i]), inv_h).to_scalar();
                ps.x[i] = self.x[i].to_scalar();
            } else {
                ps.x[i] += ps.v[i] * h;
            }
        }
        self.stats.steps += 1;
        self.stats.evaluations += self.iterations as u64;
        self.stats.linear_solves += self.iterations as u64;
        Ok(h)
    }

    counters!();
}
