//! Implicit methods for stiff particle systems.

use super::{Integrator, IntegratorKind, IntegratorStats, StepError, check_h};
use crate::core::collide::NormalHolds;
use crate::core::jacobian::Linearization;
use crate::core::ode::{OdeState, OdeSystem, ParticleState};
use crate::core::solve::{LinearSolver, Pcg, PcgReport, PointRows, SpringMatrix, filter_rows};
use crate::math::{Matrix3, Scalar, Vector};

/// What every implicit step starts with: the step size checked, the system's linearization
/// and the state's particles found (or the error saying which is missing), the matrix rebuilt
/// when the system's structure changed, and the free-particle mask filled (a free particle
/// without a valid mass is a reported solver failure). A step that holds a tet body's
/// particles on colliders along the contact normals with friction (`friction_holds`, where
/// the system holds any) leaves them to those holds; otherwise the particles pressed into
/// colliders are held still ([`Linearization::hold_contacts`], its forces in `scratch`).
#[allow(clippy::too_many_arguments)]
fn implicit_setup<'a, S: OdeState, Sys: OdeSystem<S> + ?Sized>(
    kind: IntegratorKind,
    sys: &'a Sys,
    t: Scalar,
    h: Scalar,
    state: &'a mut S,
    slot: &'a mut Option<SpringMatrix>,
    mask: &mut Vec<Scalar>,
    (friction_holds, scratch): (bool, &mut Vec<Vector>),
) -> Result<
    (
        &'a dyn Linearization,
        &'a mut ParticleState,
        &'a mut SpringMatrix,
    ),
    StepError,
> {
    check_h(h)?;
    let lin = sys.linearization().ok_or(StepError::NeedsJacobians(kind))?;
    let ps = state
        .as_particles_mut()
        .ok_or(StepError::NeedsSecondOrder(kind))?;
    if !slot.as_ref().is_some_and(|a| lin.matrix_matches(a)) {
        *slot = None;
    }
    let a = slot.get_or_insert_with(|| lin.new_matrix());
    mask.resize(lin.particles(), 0.0);
    if !lin.free_mask(mask) {
        return Err(StepError::SolverFailed(kind));
    }
    if !(friction_holds && lin.may_hold_faces(true)) {
        lin.hold_contacts(t, ps, mask, scratch);
    }
    Ok((lin, ps, a))
}

/// Linearly implicit (semi-implicit backward) Euler of Baraff & Witkin (1998): one Newton step
/// of backward Euler,
/// `(M − h ∂f/∂v − h² ∂f/∂x) Δv = h (f₀ + h ∂f/∂x v₀)`, `v ← v + Δv`, `x ← x + h v`,
/// solved with PCG (block-Jacobi, or multigrid for large systems) under the constraint filter
/// (pins and prescribed particles keep `Δv = 0`), or with the sparse Cholesky. Stable far
/// beyond explicit limits, first order, and it damps: energy is lost at large `h`.
///
/// With [`ParticleModel::hold_faces`](crate::core::particles::ParticleModel::hold_faces), the
/// particles and triangles' corners resting on colliders, or that the solve takes into them,
/// are held along the contact normals inside the solve ([`NormalHolds`]) — a cloth's and a
/// tet body's alike — and their Coulomb friction (pressed by the forces at the step's start;
/// once for a corner of several triangles on a collider) joins the system linearized at the
/// start's velocities, as the damping does: the first Newton iteration of backward
/// Euler's friction potential (Li et al. 2020, *Incremental Potential Contact*, §5). Holds
/// whose solve left that linearization's side of the smoothing zone (a sliding the friction
/// reversed, a rest the particle broke free of) have it linearized again and the system is
/// solved again, in the rounds that also hold what the last solve took into colliders
/// ([`NormalHolds::relinearize_leavers`]). A cloth on a slope slides as
/// far as Coulomb's law says, and one draped on a sphere in frame-long steps comes to
/// static equilibrium; with the contact left to after the step it came to rest with forces
/// of hundreds of times a particle's weight unbalanced (docs/BENCHMARKS.md).
///
/// A triangle spanning a collider at its start (resting on it, no corner within its
/// thickness) is held at its contact point rather than at its corners
/// ([`NormalHolds::faces`], [`PointRows`]): it can tip about the contact, and a strip
/// hung off-centre over a thin rod slides off towards its long side. Its friction is pressed by the contact force that balances its corners' pushes. What
/// the solve takes into a collider is still held at its corners (a triangle turning on a
/// rod within a step rolls, and held at one point it cut into the rod).
#[derive(Clone, Debug)]
pub struct LinearlyImplicitEuler {
    /// The linear solver (PCG by default: tolerance, iteration cap).
    pub solver: LinearSolver,
    /// Drop compressed springs' indefinite stiffness so the system is positive definite.
    pub definite: bool,
    a: Option<SpringMatrix>,
    f0: Vec<Vector>,
    kv: Vec<Vector>,
    rhs: Vec<Vector>,
    dv: Vec<Vector>,
    mask: Vec<Scalar>,
    holds: NormalHolds,
    last: PcgReport,
    stats: IntegratorStats,
}

impl Default for LinearlyImplicitEuler {
    fn default() -> Self {
        Self {
            solver: LinearSolver::default(),
            definite: true,
            a: None,
            f0: vec![],
            kv: vec![],
            rhs: vec![],
            dv: vec![],
            mask: vec![],
            // Its triangles' holds carry their collider's friction, its particles' too.
            holds: NormalHolds {
                face_friction: true,
                ..NormalHolds::default()
            },
            last: PcgReport::default(),
            stats: IntegratorStats::default(),
        }
    }
}

impl LinearlyImplicitEuler {
    /// A linearly implicit Euler with the given linear solver.
    pub fn with_solver(solver: LinearSolver) -> Self {
        Self {
            solver,
            ..Self::default()
        }
    }

    /// What the last linear solve did.
    pub fn last_solve(&self) -> PcgReport {
        self.last
    }
}

/// The PhysBAM slides' trapezoid with implicit damping:
/// `(M − h G(xⁿ)) vⁿ⁺¹ = M vⁿ + h f_el(xⁿ)`, `xⁿ⁺¹ = xⁿ + h/2 (vⁿ + vⁿ⁺¹)`, with `G` the
/// damping Jacobian (dampers, drag) and `f_el` every other force. Damping is linear in `v`, so
/// one CG solve is exact; the step is limited only by the elastic bound `h < 2 b l₀ / k`
/// (`2b/k` per spring in N/m terms), not by the damping bound `μ/b` of explicit methods.
#[derive(Clone, Debug, Default)]
pub struct ImplicitDampingTrapezoid {
    /// The linear solver.
    pub pcg: Pcg,
    a: Option<SpringMatrix>,
    f: Vec<Vector>,
    rhs: Vec<Vector>,
    v1: Vec<Vector>,
    mask: Vec<Scalar>,
    holds: NormalHolds,
    last: PcgReport,
    stats: IntegratorStats,
}

impl ImplicitDampingTrapezoid {
    /// What the last linear solve did.
    pub fn last_solve(&self) -> PcgReport {
        self.last
    }
}

impl<S: OdeState, Sys: OdeSystem<S> + ?Sized> Integrator<S, Sys> for ImplicitDampingTrapezoid {
    fn kind(&self) -> IntegratorKind {
        IntegratorKind::ImplicitDampingTrapezoid
    }

    #[allow(clippy::needless_range_loop)] // one index over five parallel arrays
    fn step(
        &mut self,
        sys: &Sys,
        t: Scalar,
        h: Scalar,
        state: &mut S,
    ) -> Result<Scalar, StepError> {
        let (lin, ps, a) = implicit_setup(
            IntegratorKind::ImplicitDampingTrapezoid,
            sys,
            t,
            h,
            state,
            &mut self.a,
            &mut self.mask,
            (false, &mut self.f),
        )?;
        let n = lin.particles();
        for v in [&mut self.f, &mut self.rhs, &mut self.v1] {
            v.resize(n, Vector::ZERO);
        }
        lin.elastic_forces(t, ps, &mut self.f);
        lin.hold_faces(t, h, ps, &self.f, &self.mask, false, &mut self.holds);
        lin.assemble_damping(ps, h, a);
        let m = lin.masses();
        for i in 0..n {
            self.rhs[i] = (ps.v[i] * m[i] + self.f[i] * h) * self.mask[i];
            // Warm start from vⁿ; constrained entries keep their velocity.
            self.v1[i] = ps.v[i];
        }
        // Triangles resting on colliders, or that the step would take into them: their
        // corners held along the normals inside the solve.
        let (pcg, mask) = (&mut self.pcg, &self.mask);
        let (x, v) = (&ps.x, &ps.v);
        self.last = solve_holding(
            lin,
            (t, h),
            ps,
            mask,
            &mut self.holds,
            None,
            (a, &mut self.rhs),
            &mut self.v1,
            |i, v1| x[i] + (v[i] + v1) * (0.5 * h * mask[i]),
            |a, rhs, (filters, rows), v1| pcg.solve_constrained(a, rhs, v1, mask, filters, rows),
            (false, true),
            &mut self.stats,
        );
        if self.last.failed {
            return Err(StepError::SolverFailed(
                IntegratorKind::ImplicitDampingTrapezoid,
            ));
        }
        for i in 0..n {
            if self.mask[i] != 0.0 {
                ps.x[i] += (ps.v[i] + self.v1[i]) * (0.5 * h);
                ps.v[i] = self.v1[i];
            }
        }
        self.stats.steps += 1;
        self.stats.evaluations += 1;
        Ok(h)
    }

    counters!();
}

/// Rounds of [`solve_holding`] after its first solve, each adding the particles and
/// triangles the last trial took into colliders and linearizing again the friction of the
/// holds it left on the other side of the smoothing zone.
const HOLD_ROUNDS: u32 = 3;

/// A step's linear solve `a x = rhs` with particles and triangles' corners held along
/// contact normals (Baraff and Witkin's filter, see [`NormalHolds`]), as an active set: the
/// holds `hold_faces` found at the step's start; then, while the solve's trial end of the
/// step (`end(i, xᵢ)`: particle `i`'s position for unknown `xᵢ`) takes triangles (and with
/// `points`, particles) into colliders, or leaves a held particle's friction on the other
/// side of its smoothing zone than it was linearized on
/// ([`NormalHolds::relinearize_leavers`]: `a` and `rhs` change), those are held or
/// linearized again and the system solved again from the last answer (at most
/// [`HOLD_ROUNDS`] times). `base` is what [`NormalHolds::settle`] takes: the step's start
/// velocities when the unknown is a change of velocity (then `base + x` is the end
/// velocity), `None` when it is the end velocity (no friction is linearized then). Counts
/// each solve in `stats`. When the first solve fails, the holds are dropped and the system
/// solved without them if `last_try`; otherwise the failure is returned with the holds kept,
/// for the caller's next try (a projected matrix).
#[allow(clippy::too_many_arguments)]
fn solve_holding(
    lin: &dyn Linearization,
    (t, h): (Scalar, Scalar),
    ps: &ParticleState,
    mask: &[Scalar],
    holds: &mut NormalHolds,
    base: Option<&[Vector]>,
    (a, rhs): (&mut SpringMatrix, &mut [Vector]),
    x: &mut [Vector],
    end: impl Fn(usize, Vector) -> Vector,
    mut solve: impl FnMut(
        &SpringMatrix,
        &[Vector],
        (&[(u32, Matrix3)], &mut PointRows),
        &mut [Vector],
    ) -> PcgReport,
    (points, last_try): (bool, bool),
    stats: &mut IntegratorStats,
) -> PcgReport {
    let n = lin.particles().min(x.len());
    holds.settle(base, x);
    let mut report = solve(a, rhs, (&holds.filters, &mut holds.rows), x);
    stats.linear_solves += 1;
    stats.linear_iterations += report.iterations as u64;
    if report.failed && !last_try {
        return report;
    }
    if report.failed && (!holds.filters.is_empty() || !holds.rows.is_empty()) {
        // Round-off can end a filtered solve that needs hundreds of iterations with a
        // non-positive curvature: solved without the holds instead, as before them (the
        // contact after the step still stops what goes in). From a fresh start: the failed
        // solve's iterate may be anything, overflowed included.
        holds.clear();
        x[..n].fill(Vector::ZERO);
        report = solve(a, rhs, (&[], &mut holds.rows), x);
        stats.linear_solves += 1;
        stats.linear_iterations += report.iterations as u64;
    }
    let trials = lin.may_hold_faces(points);
    let rounds = if trials || base.is_some() && !holds.drag.is_empty() {
        HOLD_ROUNDS
    } else {
        0
    };
    for _ in 0..rounds {
        if report.failed {
            break;
        }
        let mut again = false;
        if trials {
            holds.trial.clear();
            holds.trial.extend((0..n).map(|i| end(i, x[i])));
            again |= lin.hold_faces_trial(t, h, ps, mask, points, holds);
        }
        if let Some(v) = base {
            again |= holds.relinearize_leavers(|i| v[i] + x[i], h, &mut a.diag, rhs);
        }
        if !again {
            break;
        }
        // A round that does not converge keeps the last answer.
        holds.kept.clear();
        holds.kept.extend_from_slice(&x[..n]);
        holds.settle(base, x);
        let next = solve(a, rhs, (&holds.filters, &mut holds.rows), x);
        stats.linear_solves += 1;
        stats.linear_iterations += next.iterations as u64;
        if next.failed || !next.converged && report.converged {
            x[..n].copy_from_slice(&holds.kept);
            break;
        }
        report = next;
    }
    report
}

impl<S: OdeState, Sys: OdeSystem<S> + ?Sized> Integrator<S, Sys> for LinearlyImplicitEuler {
    fn kind(&self) -> IntegratorKind {
        IntegratorKind::LinearlyImplicitEuler
    }

    fn step(
        &mut self,
        sys: &Sys,
        t: Scalar,
        h: Scalar,
        state: &mut S,
    ) -> Result<Scalar, StepError> {
        let (lin, ps, a) = implicit_setup(
            IntegratorKind::LinearlyImplicitEuler,
            sys,
            t,
            h,
            state,
            &mut self.a,
            &mut self.mask,
            (true, &mut self.f0),
        )?;
        let n = lin.particles();
        for v in [&mut self.f0, &mut self.kv, &mut self.rhs, &mut self.dv] {
            v.resize(n, Vector::ZERO);
        }
        lin.total_forces(t, ps, &mut self.f0);
        self.holds.reserve_for(n);
        // Particles and triangles resting on colliders, or that the step would take into
        // them: held along the normals inside the solve. The particles' friction, pressed by
        // the forces at the step's start, is linearized at the start's velocities as the
        // damping is: its drag `F(v₀) + ∂F/∂v Δv` (the first Newton iteration of backward
        // Euler's friction potential, Li et al. 2020, §5).
        lin.hold_faces(t, h, ps, &self.f0, &self.mask, true, &mut self.holds);
        let f0 = &self.f0;
        self.holds.start_friction(|i| f0[i]);
        // Elements with a costly projection (tets): try their exact Hessians first, project
        // only if the matrix turns out indefinite.
        let lazy = self.definite && lin.has_costly_projection();
        let tries: &[bool] = if lazy { &[false, true] } else { &[true] };
        for (k, &project) in tries.iter().enumerate() {
            if lazy {
                lin.assemble_elements(ps, h, project, a, &mut self.kv);
            } else {
                lin.assemble(ps, h, self.definite, a, &mut self.kv);
            }
            for i in 0..n {
                self.rhs[i] = (self.f0[i] + self.kv[i] * h) * (h * self.mask[i]);
                // Warm start from the previous step's Δv (zero on the first step and for
                // constrained particles): consecutive steps change velocity similarly.
                self.dv[i] *= self.mask[i];
            }
            // The friction's force at the start and its Jacobian join the system as the
            // damping's do.
            self.holds
                .linearize_friction(&ps.v, h, &mut a.diag, &mut self.rhs);
            let (solver, mask) = (&mut self.solver, &self.mask);
            let (x, v) = (&ps.x, &ps.v);
            self.last = solve_holding(
                lin,
                (t, h),
                ps,
                mask,
                &mut self.holds,
                Some(v),
                (a, &mut self.rhs),
                &mut self.dv,
                |i, dv| x[i] + (v[i] + dv) * (h * mask[i]),
                |a, rhs, (filters, rows), dv| {
                    solver.solve_constrained(a, rhs, dv, mask, filters, rows)
                },
                (true, k + 1 == tries.len()),
                &mut self.stats,
            );
            if !self.last.failed {
                break;
            }
            self.dv.fill(Vector::ZERO);
        }
        if self.last.failed {
            // Forget the unusable warm start; the state has not been touched.
            self.dv.fill(Vector::ZERO);
            return Err(StepError::SolverFailed(
                IntegratorKind::LinearlyImplicitEuler,
            ));
        }
        if self.holds.filters.is_empty() {
            for i in 0..n {
                ps.v[i] += self.dv[i];
                ps.x[i] += ps.v[i] * (h * self.mask[i]);
            }
        } else {
            // The holds' impacts lose velocity across the normals to Coulomb's friction, as
            // in backward Euler (the contact after the step would have applied it).
            self.kv.copy_from_slice(&ps.v[..n]);
            for i in 0..n {
                ps.v[i] += self.dv[i];
            }
            self.holds.impact_friction(&self.kv, &mut ps.v);
            for i in 0..n {
                ps.x[i] += ps.v[i] * (h * self.mask[i]);
            }
        }
        self.stats.steps += 1;
        self.stats.evaluations += 1;
        Ok(h)
    }

    counters!();
}

/// What the last backward Euler step's Newton iteration did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NewtonReport {
    /// Newton iterations taken (linear solves).
    pub iterations: u32,
    /// True when the residual `M⁻¹ ∇Φ` or the last Newton step met the tolerance within the
    /// iteration cap.
    pub converged: bool,
    /// `‖∇Φ‖₂` over the free particles before each iteration and after the last.
    pub gradient_norms: Vec<Scalar>,
    /// The objective `Φ` at the same points (never increasing: every accepted step passed
    /// the Armijo test).
    pub objective: Vec<f64>,
    /// Step halvings of the line search, summed over the iterations.
    pub halvings: u32,
    /// Iterations whose linear solve failed or gave no descent direction, which fell back to
    /// the block-Jacobi-scaled gradient.
    pub fallbacks: u32,
    /// True when the iteration stopped at the round-off floor: a full Newton step (α = 1)
    /// that did not halve the gradient norm, which near a minimum happens only when the
    /// gradient is round-off, or an accepted step that changed the objective by round-off
    /// only.
    pub stagnated: bool,
}

/// Backward Euler as minimization (CSC417): `vⁿ⁺¹ = argmin Φ(v)`,
/// `Φ(v) = ½ (v − vⁿ)ᵀ M (v − vⁿ) + E(xⁿ + h v) + h R(v)` (see
/// [`Linearization::incremental_potential`]; damping enters as the dissipation potential `R`),
/// `xⁿ⁺¹ = xⁿ + h vⁿ⁺¹`. Newton's method with a backtracking line search (start at `α = 1`,
/// shrink by `ρ = 0.5` until `Φ(v + α d) ≤ Φ(v) + c α ∇Φ·d` with `c = 10⁻⁸`), at most
/// [`BackwardEuler::max_iterations`] iterations (5 by default), stopping when every free
/// particle's velocity correction is below [`BackwardEuler::tolerance`] (m/s): the residual's
/// `M⁻¹ ∇Φ`, or the Newton step's own (the step's largest entry, as in Li et al. 2020,
/// *Incremental Potential Contact*, Algorithm 1; a step that small is taken whole, without a
/// line search). The Hessian `M + h D + h² K` is projected to positive definite per spring by
/// default, so every Newton direction descends. Fully implicit: it dissipates energy and is
/// stable at any `h`. With
/// [`ParticleModel::hold_faces`](crate::core::particles::ParticleModel::hold_faces), the
/// corners of a surface's triangles resting on colliders, and the particles resting on
/// colliders, or that an iterate takes into them, are held along the
/// contact normals ([`NormalHolds`]): Φ is minimized over the velocities that keep the holds,
/// its gradient and the Newton directions projected onto the free ones. A triangle spanning
/// a collider (no corner within its thickness) is held at its contact point instead, as
/// linearly implicit Euler holds it ([`PointRows`]): the velocities are put on its row, and
/// the gradient, the Newton directions (by [`LinearSolver::solve_constrained`], the rows made
/// homogeneous) and the fallback direction are projected onto the rows' null space too, so
/// the line search stays on them. A frictionless strip hung off-centre over a thin rod
/// slides off, where held at its corners it stayed. The particles' holds
/// have Coulomb friction as a dissipation potential of Φ (Li et al. 2020, *Incremental
/// Potential Contact*, §5: the normal force and the normal lagged from the step's start,
/// smoothed below [`NormalHolds::STATIC_SPEED`]), so a cloth resting on colliders comes to
/// static equilibrium; with the contact left to after the step it came to a standstill with
/// forces of hundreds of times a particle's weight unbalanced (docs/BENCHMARKS.md). A tet
/// body's particles pressed on colliders are held still instead. The triangles' corner
/// holds are frictionless: with Coulomb friction there, a tet slab's impact on a rod kept the
/// Newton iteration from converging within its cap, and the iterate it stopped at threw
/// the slab along the rod at 0.5 m/s (docs/BENCHMARKS.md, "tet bodies slide on colliders").
/// So are those held at their contact points: with their friction, a 32² cloth resting on a
/// 1 cm rod in steps of 1/120 s ran into the iteration cap in 319 of 360 steps, each full
/// Newton step overshooting (its line search halving it), and the tet slab on the rod was
/// still moving at 4 s with PCG (42 mJ).
#[derive(Clone, Debug)]
pub struct BackwardEuler {
    /// Iteration cap per step (with [`BackwardEuler::reuse_factorization`], the cap on
    /// factorizations).
    pub max_iterations: u32,
    /// Stop when `max_i |∇Φ_i| / m_i` (a velocity, m/s) is at most this, or when a Newton
    /// step's largest velocity change `max_i |d_i|` is (after taking it). Default 1 mm/s in
    /// f32 and 0.01 mm/s in f64: in f32 the forces of a hanging cloth carry round-off of
    /// about `u k |x|` per spring, which `h/m` turns into a velocity floor of 10⁻⁴–10⁻³ m/s
    /// at h = 1/60; a tolerance below that floor only burns the iteration cap.
    pub tolerance: Scalar,
    /// Armijo constant `c`.
    pub armijo: Scalar,
    /// Line-search shrink factor `ρ`.
    pub shrink: Scalar,
    /// Line-search halvings before giving up on an iteration.
    pub max_halvings: u32,
    /// Project each spring's stiffness onto the positive semi-definite cone (Choi & Ko's
    /// clamp); off: the exact Hessian, which compressed springs make indefinite.
    pub definite: bool,
    /// The linear solver of the Newton systems.
    pub solver: LinearSolver,
    /// Modified Newton: with a direct solver, every iteration after the first first tries the
    /// last matrix and its factorization (no assembly, no factorization: two triangular
    /// solves), and refactors when that direction does not descend or when the previous reused
    /// step failed to cut the gradient fourfold. Converges to the same tolerance, linearly
    /// instead of quadratically, at a fraction of the cost per iteration when factoring
    /// dominates (finite elements). [`BackwardEuler::max_iterations`] then counts the
    /// factorizations; reused steps come on top, at most as many again. Off by default; on for
    /// bodies that prefer the direct solver.
    pub reuse_factorization: bool,
    a: Option<SpringMatrix>,
    x0: Vec<Vector>,
    v0: Vec<Vector>,
    v: Vec<Vector>,
    x: Vec<Vector>,
    g: Vec<Vector>,
    d: Vec<Vector>,
    vt: Vec<Vector>,
    mask: Vec<Scalar>,
    holds: NormalHolds,
    report: NewtonReport,
    stats: IntegratorStats,
}

impl Default for BackwardEuler {
    fn default() -> Self {
        Self {
            max_iterations: 5,
            tolerance: if cfg!(feature = "f64") { 1e-5 } else { 1e-3 },
            armijo: 1e-8,
            shrink: 0.5,
            max_halvings: 30,
            definite: true,
            solver: LinearSolver::default(),
            reuse_factorization: false,
            a: None,
            x0: vec![],
            v0: vec![],
            v: vec![],
            x: vec![],
            g: vec![],
            d: vec![],
            vt: vec![],
            mask: vec![],
            holds: NormalHolds::default(),
            report: NewtonReport::default(),
            stats: IntegratorStats::default(),
        }
    }
}

impl BackwardEuler {
    /// A Newton backward Euler with the given linear solver and iteration cap.
    pub fn new(solver: LinearSolver, max_iterations: u32) -> Self {
        Self {
            solver,
            max_iterations,
            ..Self::default()
        }
    }

    /// What the last step's Newton iteration did.
    pub fn last_newton(&self) -> &NewtonReport {
        &self.report
    }
}

/// Puts backward Euler's velocities `v` on the holds in `holds.raw`
/// ([`NormalHolds::settle`]) and returns `Φ` there, its gradient in `g` filtered. Velocities
/// at which `Φ` is not finite (an element inverted by a held corner's velocity) are not
/// taken: the holds are dropped for the step, `v` and `g` restored, and `phi`, their `Φ`,
/// returned.
#[allow(clippy::too_many_arguments)]
fn settle_on_holds(
    lin: &dyn Linearization,
    (t_end, h): (Scalar, Scalar),
    (x0, v0): (&[Vector], &[Vector]),
    holds: &mut NormalHolds,
    v: &mut [Vector],
    x: &mut [Vector],
    g: &mut [Vector],
    phi: f64,
    stats: &mut IntegratorStats,
) -> f64 {
    holds.kept.clear();
    holds.kept.extend_from_slice(v);
    holds.settle(None, v);
    // `v` is on the triangles' rows now: the Newton directions keep them (`C d = 0`).
    holds.rows.zero_targets();
    stats.evaluations += 1;
    let held = potential(lin, holds, t_end, h, x0, v0, v, x, Some(g));
    if held.is_finite() {
        filter_rows(&holds.filters, g);
        holds.rows.project(g);
        return held;
    }
    holds.clear();
    v.copy_from_slice(&holds.kept);
    stats.evaluations += 1;
    let free = potential(lin, holds, t_end, h, x0, v0, v, x, Some(g));
    if free.is_finite() { free } else { phi }
}

/// Backward Euler's objective: the incremental potential
/// ([`Linearization::incremental_potential`]) and `h` times the dissipation potential of
/// the holds' friction ([`NormalHolds::friction_potential`]), with their gradient in `g`.
#[allow(clippy::too_many_arguments)]
fn potential(
    lin: &dyn Linearization,
    holds: &NormalHolds,
    t_end: Scalar,
    h: Scalar,
    x0: &[Vector],
    v0: &[Vector],
    v: &[Vector],
    x: &mut [Vector],
    mut g: Option<&mut [Vector]>,
) -> f64 {
    let phi = lin.incremental_potential(t_end, h, x0, v0, v, x, g.as_deref_mut());
    if holds.drag.is_empty() {
        return phi;
    }
    phi + h as f64 * holds.friction_potential(v, h, g)
}

fn masked_norm(g: &[Vector], mask: &[Scalar]) -> Scalar {
    g.iter()
        .zip(mask)
        .map(|(g, m)| (*g * *m).length_squared())
        .sum::<Scalar>()
        .sqrt()
}

impl<S: OdeState, Sys: OdeSystem<S> + ?Sized> Integrator<S, Sys> for BackwardEuler {
    fn kind(&self) -> IntegratorKind {
        IntegratorKind::BackwardEuler
    }

    #[allow(clippy::needless_range_loop)] // one index over parallel arrays
    fn step(
        &mut self,
        sys: &Sys,
        t: Scalar,
        h: Scalar,
        state: &mut S,
    ) -> Result<Scalar, StepError> {
        let kind = IntegratorKind::BackwardEuler;
        let (lin, ps, a) = implicit_setup(
            kind,
            sys,
            t,
            h,
            state,
            &mut self.a,
            &mut self.mask,
            (false, &mut self.vt),
        )?;
        let n = lin.particles();
        for b in [
            &mut self.x0,
            &mut self.v0,
            &mut self.v,
            &mut self.x,
            &mut self.g,
            &mut self.d,
            &mut self.vt,
        ] {
            b.resize(n, Vector::ZERO);
        }
        self.x0.copy_from_slice(&ps.x);
        self.v0.copy_from_slice(&ps.v);
        self.v.copy_from_slice(&ps.v);
        // The last step's holds and their friction go: Φ is the incremental potential alone
        // until this step's are found.
        self.holds.clear();
        self.holds.reserve_for(n);
        let t_end = t + h;
        lin.constrained_velocities(t_end, h, &self.x0, &mut self.v);
        let m = lin.masses();
        let rep = &mut self.report;
        rep.iterations = 0;
        rep.converged = false;
        rep.halvings = 0;
        rep.fallbacks = 0;
        rep.stagnated = false;
        rep.gradient_norms.clear();
        rep.objective.clear();
        let mut phi = potential(
            lin,
            &self.holds,
            t_end,
            h,
            &self.x0,
            &self.v0,
            &self.v,
            &mut self.x,
            Some(&mut self.g),
        );
        self.stats.evaluations += 1;
        if phi == f64::INFINITY {
            // Carrying on at the old velocity inverts an element (a barrier): start from rest
            // instead, where every element keeps its current orientation.
            for (vi, w) in self.v.iter_mut().zip(&self.mask) {
                if *w != 0.0 {
                    *vi = Vector::ZERO;
                }
            }
            phi = potential(
                lin,
                &self.holds,
                t_end,
                h,
                &self.x0,
                &self.v0,
                &self.v,
                &mut self.x,
                Some(&mut self.g),
            );
            self.stats.evaluations += 1;
        }
        // Triangles resting on colliders: their corners held along the contact normals (see
        // `NormalHolds`), the Newton iteration minimizing Φ over the velocities that keep the
        // holds, its gradient and directions projected onto the free ones. What presses a
        // triangle onto a collider is `−∇Φ` at the first guess: at `v = v₀` that is
        // `h f(x₀ + h v₀)`.
        for i in 0..n {
            self.vt[i] = -self.g[i];
        }
        lin.hold_faces(t, h, ps, &self.vt, &self.mask, true, &mut self.holds);
        // Their friction, as a drag whose dissipation potential joins Φ (Li et al. 2020, §5),
        // pressed by `−∇Φ / h` at the first guess; `settle_on_holds` evaluates Φ with it (a
        // hold with friction is a hold).
        let (vt, inv_h) = (&self.vt, 1.0 / h);
        self.holds.start_friction(|i| vt[i] * inv_h);
        if !self.holds.raw.is_empty() || !self.holds.faces.is_empty() {
            phi = settle_on_holds(
                lin,
                (t_end, h),
                (&self.x0, &self.v0),
                &mut self.holds,
                &mut self.v,
                &mut self.x,
                &mut self.g,
                phi,
                &mut self.stats,
            );
        }
        let mut rounds = 0;
        let mut full_step = false;
        let mut last_reused = false;
        let mut small_step = false;
        let mut reused_iterations = 0;
        loop {
            let gnorm = masked_norm(&self.g, &self.mask);
            // A reused factorization converges linearly: its slow step calls for a fresh one
            // (below), not for giving up. And only near the minimum (the gradient already
            // below a tenth of the step's first) does a full Newton step that fails to halve it
            // mean round-off: farther out the gradient may grow while Φ falls (the swinging
            // armadillo's first step: 5.0 → 6.3 with a 1.6 m/s correction still to come).
            let g0 = rep.gradient_norms.first().copied().unwrap_or(gnorm);
            if full_step
                && !last_reused
                && rep
                    .gradient_norms
                    .last()
                    .is_some_and(|&p| gnorm > 0.5 * p && p <= 0.1 * g0)
            {
                rep.stagnated = true;
            }
            rep.gradient_norms.push(gnorm);
            rep.objective.push(phi);
            let worst = self
                .g
                .iter()
                .zip(m)
                .zip(&self.mask)
                .filter(|(_, w)| **w != 0.0)
                .map(|((g, m), _)| g.length() / *m)
                .fold(0.0, Scalar::max);
            if !worst.is_finite() || !phi.is_finite() {
                return Err(StepError::SolverFailed(kind));
            }
            self.stats.newton_residual = worst as f64;
            // At least one Newton iteration: at small h the whole velocity change h·a can be
            // below the tolerance, and stopping at the initial guess v = v₀ would drop the
            // step's acceleration (an O(tolerance) error that does not shrink with h: the
            // quick study measured order −1 on the cloth in f32 at h = 3.1e-4 s).
            if (worst <= self.tolerance || small_step) && rep.iterations > 0 {
                rep.converged = true;
                break;
            }
            // The cap counts fresh factorizations: a reused one's iteration comes on top (at
            // most as many again), so modified Newton gets as many Newton steps as Newton.
            if rep.stagnated
                || rep.iterations - reused_iterations >= self.max_iterations
                || rep.iterations >= 2 * self.max_iterations
            {
                break;
            }
            rep.iterations += 1;
            self.stats.newton_iterations += 1;
            let mut solve = Default::default();
            let mut slope = 0.0f64;
            // Modified Newton: the last factorization, unless a reused one has just failed to
            // cut the gradient fourfold. A step of a fresh one costs about five reused ones on
            // the armadillo and cuts the gradient 10–100× near the minimum, so reuse pays
            // while it contracts at least that fast; slower, it would spend the iteration cap
            // (f64 needed ten reused steps at 0.4 each for what Newton did in three).
            let g = &rep.gradient_norms;
            let reused = self.reuse_factorization
                && g.len() >= 2
                && (!last_reused || g[g.len() - 1] <= 0.25 * g[g.len() - 2])
                && {
                    for i in 0..n {
                        self.vt[i] = -self.g[i] * self.mask[i];
                        self.d[i] = Vector::ZERO;
                    }
                    match self.solver.resolve_constrained(
                        a,
                        &self.vt,
                        &mut self.d,
                        &self.mask,
                        &self.holds.filters,
                        &mut self.holds.rows,
                    ) {
                        Some(r) if !r.failed => {
                            slope = (0..n).map(|i| self.g[i].dot(self.d[i]) as f64).sum();
                            solve = r;
                            self.stats.linear_solves += 1;
                            slope < 0.0
                        }
                        _ => false,
                    }
                };
            // Elements with a costly projection (tets): exact Hessians first, projected only
            // when the solve finds the matrix indefinite or the direction does not descend.
            let lazy = self.definite && lin.has_costly_projection();
            last_reused = reused;
            reused_iterations += u32::from(reused);
            let tries: &[bool] = match (reused, lazy) {
                (true, _) => &[],
                (false, true) => &[false, true],
                (false, false) => &[true],
            };
            for (k, &project) in tries.iter().enumerate() {
                if lazy {
                    lin.assemble_incremental_hessian_elements(h, &self.x0, &self.x, project, a);
                } else {
                    lin.assemble_incremental_hessian(h, &self.x0, &self.x, self.definite, a);
                }
                // The holds' friction: its dissipation potential's Hessian, times `h`.
                self.holds.friction_hessian(&self.v, h, &mut a.diag);
                for i in 0..n {
                    self.vt[i] = -self.g[i] * self.mask[i];
                    self.d[i] = Vector::ZERO;
                }
                solve = self.solver.solve_constrained(
                    a,
                    &self.vt,
                    &mut self.d,
                    &self.mask,
                    &self.holds.filters,
                    &mut self.holds.rows,
                );
                self.stats.linear_solves += 1;
                self.stats.linear_iterations += solve.iterations as u64;
                let held = !self.holds.filters.is_empty() || !self.holds.rows.is_empty();
                if solve.failed && held && k + 1 == tries.len() {
                    // Round-off can end a filtered solve with a non-positive curvature (see
                    // `solve_holding`): the holds are dropped for the rest of the step, the
                    // contact after it stopping what goes in, as before them. Not before the
                    // last try: an exact element Hessian that is indefinite fails with or
                    // without the holds, and its projection takes them.
                    self.holds.clear();
                    phi = potential(
                        lin,
                        &self.holds,
                        t_end,
                        h,
                        &self.x0,
                        &self.v0,
                        &self.v,
                        &mut self.x,
                        Some(&mut self.g),
                    );
                    self.stats.evaluations += 1;
                    for i in 0..n {
                        self.vt[i] = -self.g[i] * self.mask[i];
                        self.d[i] = Vector::ZERO;
                    }
                    solve = self.solver.solve(a, &self.vt, &mut self.d, &self.mask);
                    self.stats.linear_solves += 1;
                    self.stats.linear_iterations += solve.iterations as u64;
                }
                slope = (0..n).map(|i| self.g[i].dot(self.d[i]) as f64).sum();
                if !solve.failed && slope < 0.0 {
                    break;
                }
            }
            if solve.failed && self.definite {
                // With the projected Hessian only bad input (a negative stiffness) makes the
                // Newton matrix indefinite: report it rather than wander downhill.
                return Err(StepError::SolverFailed(kind));
            }
            let newton_direction = !(solve.failed || slope.is_nan() || slope >= 0.0);
            // The step criterion of Li et al. 2020 (Incremental Potential Contact, Algorithm 1):
            // a Newton step whose largest velocity correction is within the tolerance leaves
            // the velocities that close to the minimizer of the quadratic model. It decides
            // where the residual `M⁻¹ ∇Φ` cannot: on light particles held by stiff elements
            // that residual is the stiffness's round-off over a small mass (0.3 m/s on the
            // coarse armadillo in f32 while the Newton step is 4 μm/s). A fresh Newton step
            // converges quadratically, leaving far less than itself; a reused factorization's
            // converges linearly and can leave about its own size behind, so it must be within
            // half the tolerance.
            let step_limit = if reused {
                0.5 * self.tolerance
            } else {
                self.tolerance
            };
            small_step = newton_direction
                && (0..n)
                    .filter(|&i| self.mask[i] != 0.0)
                    .all(|i| self.d[i].length() <= step_limit);
            if !newton_direction {
                // No usable Newton direction: descend along the block-Jacobi-scaled gradient
                // (the diagonal blocks are mass plus positive terms, so this descends).
                rep.fallbacks += 1;
                for i in 0..n {
                    let di = a.diag[i];
                    self.d[i] = if self.mask[i] != 0.0 && di.determinant().is_normal() {
                        -(di.inverse() * self.g[i])
                    } else {
                        Vector::ZERO
                    };
                }
                // Along the held particles' free directions and the triangles' rows only:
                // `−P D⁻¹ P ∇Φ` descends (`P` the orthogonal projector onto them).
                filter_rows(&self.holds.filters, &mut self.d);
                self.holds.rows.project(&mut self.d);
                slope = (0..n).map(|i| self.g[i].dot(self.d[i]) as f64).sum();
                if slope.is_nan() || slope >= 0.0 {
                    break;
                }
            }
            // Backtracking line search on Φ.
            // A small step is tried whole only: whether it lowers Φ is then round-off, and
            // halving it cannot make a difference above the tolerance.
            let mut alpha: f64 = 1.0;
            let mut accepted = None;
            let halvings = if small_step { 0 } else { self.max_halvings };
            for _ in 0..=halvings {
                for i in 0..n {
                    self.vt[i] = self.v[i] + self.d[i] * (alpha as Scalar * self.mask[i]);
                }
                let trial = potential(
                    lin,
                    &self.holds,
                    t_end,
                    h,
                    &self.x0,
                    &self.v0,
                    &self.vt,
                    &mut self.x,
                    None,
                );
                self.stats.evaluations += 1;
                if trial <= phi + self.armijo as f64 * alpha * slope {
                    accepted = Some(trial);
                    break;
                }
                alpha *= self.shrink as f64;
                rep.halvings += 1;
            }
            let Some(trial) = accepted else {
                // No decrease to round-off: the current velocity is as good as this precision
                // resolves. Keep it.
                rep.converged = small_step;
                break;
            };
            full_step = alpha == 1.0;
            // An accepted step that changed Φ by round-off only: the minimum is resolved as
            // far as this precision can tell.
            if phi - trial <= 16.0 * f64::EPSILON * phi.abs() {
                rep.stagnated = true;
            }
            std::mem::swap(&mut self.v, &mut self.vt);
            phi = potential(
                lin,
                &self.holds,
                t_end,
                h,
                &self.x0,
                &self.v0,
                &self.v,
                &mut self.x,
                Some(&mut self.g),
            );
            debug_assert!(phi <= trial || (phi - trial).abs() <= 1e-3 * trial.abs().max(1.0));
            self.stats.evaluations += 1;
            filter_rows(&self.holds.filters, &mut self.g);
            self.holds.rows.project(&mut self.g);
            // The active set (as `solve_holding` runs it for the linear solves, but within the
            // Newton iteration): triangles that this iterate's end of the step takes into
            // colliders are held as well, at most `HOLD_ROUNDS` times a step, and the
            // iteration goes on from the velocities that keep the holds.
            if rounds < HOLD_ROUNDS && lin.may_hold_faces(true) {
                self.holds.trial.clear();
                let (x0, v) = (&self.x0, &self.v);
                self.holds.trial.extend((0..n).map(|i| x0[i] + v[i] * h));
                if lin.hold_faces_trial(t, h, ps, &self.mask, true, &mut self.holds) {
                    rounds += 1;
                    phi = settle_on_holds(
                        lin,
                        (t_end, h),
                        (&self.x0, &self.v0),
                        &mut self.holds,
                        &mut self.v,
                        &mut self.x,
                        &mut self.g,
                        phi,
                        &mut self.stats,
                    );
                    // The velocities moved: neither the last step's size nor its gradient
                    // ratio says anything about convergence now.
                    small_step = false;
                    full_step = false;
                }
            }
        }
        if !self.v.iter().all(|v| v.is_finite()) {
            return Err(StepError::SolverFailed(kind));
        }
        self.holds.impact_friction(&self.v0, &mut self.v);
        for i in 0..n {
            if self.mask[i] != 0.0 {
                ps.v[i] = self.v[i];
                ps.x[i] = self.x0[i] + self.v[i] * h;
            }
        }
        self.stats.steps += 1;
        Ok(h)
    }

    counters!();
}
