//! Implicit methods for stiff particle systems.

use super::{Integrator, IntegratorKind, IntegratorStats, StepError, check_h};
use crate::core::jacobian::Linearization;
use crate::core::ode::{OdeState, OdeSystem, ParticleState};
use crate::core::solve::{Pcg, PcgReport, SpringMatrix};
use crate::math::{Scalar, Vector};

/// What every implicit step starts with: the step size checked, the system's linearization
/// and the state's particles found (or the error saying which is missing), and the matrix
/// rebuilt when the system's structure changed.
fn implicit_setup<'a, S: OdeState, Sys: OdeSystem<S> + ?Sized>(
    kind: IntegratorKind,
    sys: &'a Sys,
    h: Scalar,
    state: &'a mut S,
    slot: &'a mut Option<SpringMatrix>,
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
    Ok((lin, ps, a))
}

/// Linearly implicit (semi-implicit backward) Euler of Baraff & Witkin (1998): one Newton step
/// of backward Euler,
/// `(M − h ∂f/∂v − h² ∂f/∂x) Δv = h (f₀ + h ∂f/∂x v₀)`, `v ← v + Δv`, `x ← x + h v`,
/// solved with block-Jacobi PCG under the constraint filter (pins and prescribed particles
/// keep `Δv = 0`). Stable far beyond explicit limits, first order, and it damps: energy is
/// lost at large `h`.
#[derive(Clone, Debug)]
pub struct LinearlyImplicitEuler {
    /// The linear solver (tolerance, iteration cap).
    pub pcg: Pcg,
    /// Drop compressed springs' indefinite stiffness so the system is positive definite.
    pub definite: bool,
    a: Option<SpringMatrix>,
    f0: Vec<Vector>,
    kv: Vec<Vector>,
    rhs: Vec<Vector>,
    dv: Vec<Vector>,
    mask: Vec<Scalar>,
    last: PcgReport,
    stats: IntegratorStats,
}

impl Default for LinearlyImplicitEuler {
    fn default() -> Self {
        Self {
            pcg: Pcg::default(),
            definite: true,
            a: None,
            f0: vec![],
            kv: vec![],
            rhs: vec![],
            dv: vec![],
            mask: vec![],
            last: PcgReport::default(),
            stats: IntegratorStats::default(),
        }
    }
}

impl LinearlyImplicitEuler {
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
            h,
            state,
            &mut self.a,
        )?;
        let n = lin.particles();
        for v in [&mut self.f, &mut self.rhs, &mut self.v1] {
            v.resize(n, Vector::ZERO);
        }
        self.mask.resize(n, 0.0);
        lin.elastic_forces(t, ps, &mut self.f);
        lin.assemble_damping(ps, h, a);
        lin.free_mask(&mut self.mask);
        let m = lin.masses();
        for i in 0..n {
            self.rhs[i] = (ps.v[i] * m[i] + self.f[i] * h) * self.mask[i];
            // Warm start from vⁿ; constrained entries keep their velocity.
            self.v1[i] = ps.v[i];
        }
        self.last = self.pcg.solve(a, &self.rhs, &mut self.v1, &self.mask);
        for i in 0..n {
            if self.mask[i] != 0.0 {
                ps.x[i] += (ps.v[i] + self.v1[i]) * (0.5 * h);
                ps.v[i] = self.v1[i];
            }
        }
        self.stats.steps += 1;
        self.stats.evaluations += 1;
        self.stats.linear_iterations += self.last.iterations as u64;
        Ok(h)
    }

    counters!();
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
            h,
            state,
            &mut self.a,
        )?;
        let n = lin.particles();
        for v in [&mut self.f0, &mut self.kv, &mut self.rhs, &mut self.dv] {
            v.resize(n, Vector::ZERO);
        }
        self.mask.resize(n, 0.0);
        lin.total_forces(t, ps, &mut self.f0);
        lin.assemble(ps, h, self.definite, a, &mut self.kv);
        lin.free_mask(&mut self.mask);
        for i in 0..n {
            self.rhs[i] = (self.f0[i] + self.kv[i] * h) * (h * self.mask[i]);
            // Warm start from the previous step's Δv (zero on the first step and for
            // constrained particles): consecutive steps change velocity similarly.
            self.dv[i] *= self.mask[i];
        }
        self.last = self.pcg.solve(a, &self.rhs, &mut self.dv, &self.mask);
        for i in 0..n {
            ps.v[i] += self.dv[i];
            ps.x[i] += ps.v[i] * (h * self.mask[i]);
        }
        self.stats.steps += 1;
        self.stats.evaluations += 1;
        self.stats.linear_iterations += self.last.iterations as u64;
        Ok(h)
    }

    counters!();
}
