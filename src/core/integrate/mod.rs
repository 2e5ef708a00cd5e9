//! Time integrators. Each is generic over the state ([`OdeState`]) and the system
//! ([`OdeSystem`]), owns its scratch states (created on the first step, reused afterwards: a
//! step allocates nothing), and is selected at run time by an [`IntegratorKind`].

/// The `stats` / `reset` pair of an integrator whose only memory is its counters.
macro_rules! counters {
    () => {
        fn stats(&self) -> IntegratorStats {
            self.stats
        }
        fn reset(&mut self) {
            self.stats = IntegratorStats::default();
        }
    };
}

mod adaptive;
mod explicit;
mod implicit;
mod position;

pub use adaptive::{AdaptiveConfig, DormandPrince};
pub use explicit::{ForwardEuler, Midpoint, Rk4, SymplecticEuler, Trapezoid};
pub use implicit::{BackwardEuler, ImplicitDampingTrapezoid, LinearlyImplicitEuler, NewtonReport};
pub use position::{ProjectiveDynamics, Xpbd};

use crate::core::ode::{OdeState, OdeSystem};
use crate::core::solve::LinearSolver;
use crate::math::Scalar;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Which time integrator advances a system. Parsed from names (`"rk4"`, `"forward_euler"`)
/// and from the one-letter codes of the classic sample solution's command line.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum IntegratorKind {
    /// `e`: forward (explicit) Euler, order 1.
    ForwardEuler,
    /// `s`: symplectic (semi-implicit) Euler, order 1, for second-order systems.
    SymplecticEuler,
    /// `t`: explicit trapezoid (Heun), order 2.
    Trapezoid,
    /// `m`: explicit midpoint, order 2.
    Midpoint,
    /// `r`: classic Runge–Kutta, order 4.
    #[default]
    Rk4,
    /// `a`: adaptive Dormand–Prince 5(4) with error control.
    Rk45,
    /// `i`: linearly implicit Euler (Baraff & Witkin 1998), one Newton step solved with PCG.
    LinearlyImplicitEuler,
    /// `d`: the PhysBAM slides' trapezoid with implicit damping, solved with PCG.
    ImplicitDampingTrapezoid,
    /// `b`: backward Euler as minimization, Newton with a backtracking line search.
    BackwardEuler,
    /// `x`: XPBD with small steps (Macklin et al. 2016, 2019): springs as compliant
    /// constraints, one Gauss–Seidel sweep per step.
    Xpbd,
    /// `p`: projective dynamics (Bouaziz et al. 2014): backward Euler by local/global
    /// iterations with a prefactored sparse Cholesky.
    ProjectiveDynamics,
    /// `u`: automatic: per body, the cheapest method and substep count that is stable at the
    /// frame's length and meets a tolerance, chosen by the driver from the body's fastest mode
    /// (see [`crate::core::auto`]). Not a method of its own: it is not in [`Self::ALL`], and
    /// built alone (outside a [`Simulation`](crate::core::driver::Simulation)) it is RK4.
    Auto,
}

/// Number of explicit kinds in [`IntegratorKind::ALL`].
const N_EXPLICIT: usize = {
    let mut n = 0;
    let mut i = 0;
    while i < IntegratorKind::ALL.len() {
        if !IntegratorKind::ALL[i].is_implicit() {
            n += 1;
        }
        i += 1;
    }
    n
};

impl IntegratorKind {
    /// Every kind, in the order charts and tables list them.
    pub const ALL: [IntegratorKind; 11] = [
        IntegratorKind::ForwardEuler,
        IntegratorKind::SymplecticEuler,
        IntegratorKind::Trapezoid,
        IntegratorKind::Midpoint,
        IntegratorKind::Rk4,
        IntegratorKind::Rk45,
        IntegratorKind::LinearlyImplicitEuler,
        IntegratorKind::ImplicitDampingTrapezoid,
        IntegratorKind::BackwardEuler,
        IntegratorKind::Xpbd,
        IntegratorKind::ProjectiveDynamics,
    ];

    /// The explicit kinds (those that work on any [`OdeSystem`]): [`IntegratorKind::ALL`]
    /// without the implicit ones, in the same order, computed at compile time.
    pub const EXPLICIT: [IntegratorKind; N_EXPLICIT] = {
        let mut out = [IntegratorKind::ForwardEuler; N_EXPLICIT];
        let (mut i, mut k) = (0, 0);
        while i < Self::ALL.len() {
            if !Self::ALL[i].is_implicit() {
                out[k] = Self::ALL[i];
                k += 1;
            }
            i += 1;
        }
        out
    };

    /// The one-letter code (`e`, `s`, `t`, `m`, `r`, `a`, `i`, `d`, `b`, `x`, `p`; `u` for
    /// [`Auto`](Self::Auto)).
    pub fn letter(self) -> char {
        match self {
            Self::ForwardEuler => 'e',
            Self::SymplecticEuler => 's',
            Self::Trapezoid => 't',
            Self::Midpoint => 'm',
            Self::Rk4 => 'r',
            Self::Rk45 => 'a',
            Self::LinearlyImplicitEuler => 'i',
            Self::ImplicitDampingTrapezoid => 'd',
            Self::BackwardEuler => 'b',
            Self::Xpbd => 'x',
            Self::ProjectiveDynamics => 'p',
            Self::Auto => 'u',
        }
    }

    /// The canonical name (`forward_euler`, `rk4`, ...), also used in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Self::ForwardEuler => "forward_euler",
            Self::SymplecticEuler => "symplectic_euler",
            Self::Trapezoid => "trapezoid",
            Self::Midpoint => "midpoint",
            Self::Rk4 => "rk4",
            Self::Rk45 => "rk45",
            Self::LinearlyImplicitEuler => "linearly_implicit_euler",
            Self::ImplicitDampingTrapezoid => "implicit_damping_trapezoid",
            Self::BackwardEuler => "backward_euler",
            Self::Xpbd => "xpbd",
            Self::ProjectiveDynamics => "projective_dynamics",
            Self::Auto => "auto",
        }
    }

    /// A human label for panels and charts.
    pub fn label(self) -> &'static str {
        match self {
            Self::ForwardEuler => "forward Euler",
            Self::SymplecticEuler => "symplectic Euler",
            Self::Trapezoid => "trapezoid (Heun)",
            Self::Midpoint => "midpoint",
            Self::Rk4 => "RK4",
            Self::Rk45 => "RK45 (Dormand-Prince)",
            Self::LinearlyImplicitEuler => "linearly implicit Euler",
            Self::ImplicitDampingTrapezoid => "trapezoid with implicit damping",
            Self::BackwardEuler => "backward Euler (Newton)",
            Self::Xpbd => "XPBD (small steps)",
            Self::ProjectiveDynamics => "projective dynamics",
            Self::Auto => "auto (chosen per body)",
        }
    }

    /// Order of accuracy (global error `O(h^p)`); for RK45 the order of the propagated
    /// solution.
    pub fn order(self) -> u32 {
        match self {
            Self::ForwardEuler
            | Self::SymplecticEuler
            | Self::LinearlyImplicitEuler
            | Self::ImplicitDampingTrapezoid
            | Self::BackwardEuler
            | Self::Xpbd
            | Self::ProjectiveDynamics => 1,
            Self::Trapezoid | Self::Midpoint => 2,
            Self::Rk4 | Self::Auto => 4,
            Self::Rk45 => 5,
        }
    }

    /// Derivative evaluations per (accepted, fixed) step (for backward Euler, per Newton
    /// iteration without line-search backtracking; for XPBD and projective dynamics, per
    /// sweep over the constraints).
    pub fn stages(self) -> u32 {
        match self {
            Self::ForwardEuler
            | Self::SymplecticEuler
            | Self::LinearlyImplicitEuler
            | Self::ImplicitDampingTrapezoid
            | Self::BackwardEuler
            | Self::Xpbd
            | Self::ProjectiveDynamics => 1,
            Self::Trapezoid | Self::Midpoint => 2,
            Self::Rk4 | Self::Auto => 4,
            Self::Rk45 => 6,
        }
    }

    /// True when the step size is chosen by error control rather than given.
    pub fn is_adaptive(self) -> bool {
        matches!(self, Self::Rk45)
    }

    /// True for methods that treat the elastic forces implicitly: they have no explicit
    /// stability bound and need a particle model's structure (its Jacobians, or its springs
    /// as constraints), so they do not apply to arbitrary [`OdeSystem`]s.
    pub const fn is_implicit(self) -> bool {
        matches!(
            self,
            Self::LinearlyImplicitEuler
                | Self::ImplicitDampingTrapezoid
                | Self::BackwardEuler
                | Self::Xpbd
                | Self::ProjectiveDynamics
        )
    }

    /// True for methods that step finite elements (tets) as well as springs. XPBD and
    /// projective dynamics work on springs only here: the crate's neo-Hookean elements have
    /// no constraint (or projection) form in them.
    pub const fn supports_elements(self) -> bool {
        !matches!(self, Self::Xpbd | Self::ProjectiveDynamics)
    }

    /// Builds the integrator for states of type `S` and systems of type `Sys` (implicit
    /// methods with their default linear solver, PCG).
    pub fn build<S: OdeState, Sys: OdeSystem<S> + ?Sized>(
        self,
        adaptive: AdaptiveConfig,
    ) -> Box<dyn Integrator<S, Sys>> {
        self.build_with(adaptive, false)
    }

    /// Builds the integrator; with `direct`, linearly implicit and backward Euler solve with
    /// the sparse Cholesky factorization instead of PCG.
    pub fn build_with<S: OdeState, Sys: OdeSystem<S> + ?Sized>(
        self,
        adaptive: AdaptiveConfig,
        direct: bool,
    ) -> Box<dyn Integrator<S, Sys>> {
        if direct {
            match self {
                Self::LinearlyImplicitEuler => {
                    let mut m = LinearlyImplicitEuler::default();
                    m.solver = LinearSolver::cholesky();
                    return Box::new(m);
                }
                Self::BackwardEuler => {
                    let mut m = BackwardEuler::default();
                    m.solver = LinearSolver::cholesky();
                    m.reuse_factorization = true;
                    return Box::new(m);
                }
                _ => {}
            }
        }
        match self {
            Self::ForwardEuler => Box::new(ForwardEuler::default()),
            Self::SymplecticEuler => Box::new(SymplecticEuler::default()),
            Self::Trapezoid => Box::new(Trapezoid::default()),
            Self::Midpoint => Box::new(Midpoint::default()),
            Self::Rk4 | Self::Auto => Box::new(Rk4::default()),
            Self::Rk45 => Box::new(DormandPrince::new(adaptive)),
            Self::LinearlyImplicitEuler => Box::new(LinearlyImplicitEuler::default()),
            Self::ImplicitDampingTrapezoid => Box::new(ImplicitDampingTrapezoid::default()),
            Self::BackwardEuler => Box::new(BackwardEuler::default()),
            Self::Xpbd => Box::new(Xpbd::default()),
            Self::ProjectiveDynamics => Box::new(ProjectiveDynamics::default()),
        }
    }
}

impl fmt::Display for IntegratorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Which linear solver implicit methods use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SolverChoice {
    /// What suits the system: the sparse Cholesky factorization for finite-element bodies
    /// (stiff, small, and Newton needs accurate directions), PCG for springs.
    #[default]
    Auto,
    /// Preconditioned conjugate gradients.
    Pcg,
    /// Sparse Cholesky (faer).
    Cholesky,
}

/// The text did not name an integrator.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnknownIntegrator(pub String);

impl fmt::Display for UnknownIntegrator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unknown integrator '{}'; expected one of: ", self.0)?;
        for (i, k) in IntegratorKind::ALL.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{} ({})", k.letter(), k.name())?;
        }
        f.write_str(", u (auto)")
    }
}

impl std::error::Error for UnknownIntegrator {}

impl FromStr for IntegratorKind {
    type Err = UnknownIntegrator;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let l = s.trim().to_ascii_lowercase().replace(['-', ' '], "_");
        let k = match l.as_str() {
            "e" | "euler" | "forward_euler" | "explicit_euler" => Self::ForwardEuler,
            "s" | "symplectic" | "symplectic_euler" | "semi_implicit_euler" => {
                Self::SymplecticEuler
            }
            "t" | "trapezoid" | "trapezoidal" | "heun" => Self::Trapezoid,
            "m" | "midpoint" => Self::Midpoint,
            "r" | "rk4" | "runge_kutta" => Self::Rk4,
            "a" | "rk45" | "adaptive" | "dopri5" | "dormand_prince" | "ode45" => Self::Rk45,
            "i"
            | "implicit"
            | "linearly_implicit"
            | "linearly_implicit_euler"
            | "baraff_witkin" => Self::LinearlyImplicitEuler,
            "d" | "implicit_damping" | "implicit_damping_trapezoid" | "physbam" => {
                Self::ImplicitDampingTrapezoid
            }
            "b" | "backward_euler" | "implicit_euler" | "newton" => Self::BackwardEuler,
            "x" | "xpbd" | "pbd" | "position_based" => Self::Xpbd,
            "p" | "pd" | "projective" | "projective_dynamics" => Self::ProjectiveDynamics,
            "u" | "auto" | "automatic" => Self::Auto,
            _ => return Err(UnknownIntegrator(s.to_string())),
        };
        Ok(k)
    }
}

/// Why a step could not be taken.
#[derive(Clone, Debug, PartialEq)]
pub enum StepError {
    /// The step size was not a positive finite number.
    BadStepSize(Scalar),
    /// An adaptive method needed a step below its minimum to meet its tolerance.
    StepSizeUnderflow {
        /// The step it would have needed.
        h: Scalar,
    },
    /// The method needs a second-order state (positions and velocities).
    NeedsSecondOrder(IntegratorKind),
    /// The method needs the system's force Jacobians, which this system does not provide.
    NeedsJacobians(IntegratorKind),
    /// The method works on springs only and the system has finite elements.
    NeedsSprings(IntegratorKind),
    /// The linear solve failed: the system matrix is not positive definite on the free
    /// degrees of freedom (a free particle without mass, a negative stiffness) or a value was
    /// not finite. The state is unchanged.
    SolverFailed(IntegratorKind),
}

impl fmt::Display for StepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadStepSize(h) => write!(f, "step size {h} is not a positive finite number"),
            Self::StepSizeUnderflow { h } => {
                write!(
                    f,
                    "adaptive step size fell to {h:e} to meet the tolerance (stiff or diverging system)"
                )
            }
            Self::NeedsSecondOrder(k) => {
                write!(
                    f,
                    "{} needs a second-order (position, velocity) state",
                    k.label()
                )
            }
            Self::NeedsJacobians(k) => {
                write!(f, "{} needs a system with force Jacobians", k.label())
            }
            Self::NeedsSprings(k) => write!(
                f,
                "{} works on springs only: finite elements have no constraint form here; pick another method for this body",
                k.label()
            ),
            Self::SolverFailed(k) => write!(
                f,
                "{}: the linear solve failed (matrix not positive definite on the free particles, or not finite); check for free particles without mass and negative stiffness",
                k.label()
            ),
        }
    }
}

impl std::error::Error for StepError {}

/// Counters an integrator keeps over its life (reset with [`Integrator::reset`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct IntegratorStats {
    /// Accepted steps.
    pub steps: u64,
    /// Rejected steps (adaptive methods).
    pub rejected: u64,
    /// Derivative (force) evaluations.
    pub evaluations: u64,
    /// Linear-solver iterations (implicit methods; direct solves count none).
    pub linear_iterations: u64,
    /// Linear solves (implicit methods: one per step, one per Newton iteration).
    pub linear_solves: u64,
    /// Newton iterations (backward Euler).
    pub newton_iterations: u64,
    /// Backward Euler's last step: its final residual `max_i |∇Φ_i| / m_i` (m/s).
    pub newton_residual: f64,
}

/// A time integrator for states `S` of systems `Sys`.
pub trait Integrator<S: OdeState, Sys: OdeSystem<S> + ?Sized>: Send + Sync {
    /// Which method this is.
    fn kind(&self) -> IntegratorKind;

    /// Advances `state` from time `t` by at most `h`, returning the step actually taken.
    /// Fixed-step methods always take `h`; adaptive ones take the largest step their error
    /// control accepts, never more than `h` (so the caller can land on frame boundaries).
    /// On error the state is unchanged.
    fn step(&mut self, sys: &Sys, t: Scalar, h: Scalar, state: &mut S)
    -> Result<Scalar, StepError>;

    /// Counters since construction or the last reset.
    fn stats(&self) -> IntegratorStats;

    /// Forgets step-size history and cached derivatives and zeroes the counters.
    fn reset(&mut self);
}

/// Checks a step size.
pub(crate) fn check_h(h: Scalar) -> Result<(), StepError> {
    if h.is_finite() && h > 0.0 {
        Ok(())
    } else {
        Err(StepError::BadStepSize(h))
    }
}

/// Returns the scratch slot, cloning `like` into it the first time (the only allocation an
/// integrator makes).
pub(crate) fn scratch<'a, S: OdeState>(slot: &'a mut Option<S>, like: &S) -> &'a mut S {
    if slot.as_ref().is_none_or(|s| s.dim() != like.dim()) {
        *slot = Some(like.clone());
    }
    slot.get_or_insert_with(|| like.clone())
}
