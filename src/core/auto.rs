//! Automatic method and step: per body, the cheapest method and substep count that is stable
//! at the frame's length and meets the user's tolerance.
//!
//! What it measures, and how:
//!
//! 1. **The body's fastest mode** ([`spectrum`]): the largest eigenvalue `ω²` of `M⁻¹K` and
//!    the largest damping rate `c` of `M⁻¹D` (dampers, drag and the wind's drag) on the free
//!    particles, by the Lanczos method on `M^{-1/2} K M^{-1/2}` (Golub and Van Loan, *Matrix
//!    Computations*, §10.1): 60 iterations find the extreme eigenvalue of a spring or tet
//!    network to within about a percent, where power iteration needs thousands. `K` is the
//!    exact stiffness (compressed springs' and inverted elements' indefinite part included)
//!    that the implicit methods assemble.
//! 2. **Each candidate on the test equation** ([`probe`]): the real integrator (the same code
//!    the body runs) steps one spring between a pinned particle and a free one, `ẍ = −ω² x −
//!    c ẋ` — Dahlquist's test equation for a second-order system, which is what a method does
//!    to one mode of a linearized body. *Stable* means: at `1.25 ω` (a margin for the
//!    Lanczos estimate, which approaches `ω` from below, and for the body's nonlinearity) and
//!    the largest damping rate, 500 steps show no growth (the energy's largest value over
//!    the last half is within 1.5× of its largest over the first, and never past 1000× the
//!    start). *Accurate* means: on an
//!    undamped mode at `ω_acc = min(ω, π / 4Δ)` — the fastest motion a frame rate `1/Δ` shows
//!    as motion, eight frames to a period — the relative energy error over one simulated
//!    second stays within the tolerance.
//! 3. **A cost model** ([`step_cost_ns`]): nanoseconds per step from the body's counts
//!    (springs, tets, particles) with per-unit costs measured on this crate's benchmarks
//!    (`docs/BENCHMARKS.md`, f32, one core). It ranks candidates; it is not a timing, and a
//!    choice never depends on a clock, so runs stay bitwise reproducible.
//!
//! The choice is the cheapest stable candidate that meets the tolerance within
//! [`AutoConfig::max_substeps`]; when none does, the most accurate stable one within the
//! budget, and the reason says so. Candidates: symplectic Euler and RK4 (explicit), linearly
//! implicit Euler, projective dynamics (springs only) and backward Euler. Left out: forward
//! Euler (unstable on undamped modes at any step), the trapezoid and the midpoint rule (RK4
//! is as stable per evaluation and more accurate), adaptive RK45 (its own error control
//! chooses the step), the trapezoid with implicit damping (bounded by its elastic limit
//! `2b/k`, which the test equation at the fastest mode does not show for every spring), and
//! XPBD with one sweep (its over-stretch at large steps is a property of the whole constraint
//! network, which a one-spring test equation cannot see).

use crate::core::integrate::{AdaptiveConfig, IntegratorKind};
use crate::core::jacobian::Linearization;
use crate::core::ode::{OdeState, OdeSystem, ParticleState};
use crate::core::particles::ParticleModel;
use crate::core::study::FastestMode;
use crate::math::{Scalar, Vector};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// What [`IntegratorKind::Auto`] aims for.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AutoConfig {
    /// Largest relative energy error per simulated second on the fastest motion the frame
    /// rate shows (see the module docs); `None`, the default: any stable method, the
    /// cheapest one. A game wants `None` (the damping implicit methods add to fast modes is
    /// welcome there); a study states a number, e.g. `0.01`.
    pub tolerance: Option<f64>,
    /// Most substeps per frame Auto will take.
    pub max_substeps: u32,
}

impl Default for AutoConfig {
    /// Any stable method, at most 64 substeps per frame (a 60 Hz frame in steps of 0.26 ms).
    fn default() -> Self {
        Self {
            tolerance: None,
            max_substeps: 64,
        }
    }
}

impl AutoConfig {
    /// Checks the numbers: `Err((field, message))`.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if let Some(t) = self.tolerance
            && !(t.is_finite() && t > 0.0)
        {
            return Err((
                "tolerance",
                format!("must be a positive number (relative energy error per second), got {t}"),
            ));
        }
        if self.max_substeps == 0 {
            return Err(("max_substeps", "must be at least 1".into()));
        }
        Ok(())
    }
}

/// The counts the cost model needs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BodySize {
    /// Particles.
    pub particles: usize,
    /// Springs.
    pub springs: usize,
    /// Tetrahedra.
    pub tets: usize,
    /// The implicit methods solve with the sparse Cholesky factorization (else PCG).
    pub direct: bool,
}

/// One method at one substep count, as Auto measured it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// The method.
    pub kind: IntegratorKind,
    /// Substeps per frame.
    pub substeps: u32,
    /// Relative energy error over one simulated second at `ω_acc` (test equation).
    pub energy_error: f64,
    /// Model cost of a frame (ms).
    pub cost_ms: f64,
    /// Meets the tolerance (always, without one).
    pub meets: bool,
}

/// What Auto chose for a body, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct AutoChoice {
    /// The method.
    pub kind: IntegratorKind,
    /// Substeps per frame.
    pub substeps: u32,
    /// The substep (s).
    pub h: f64,
    /// The fastest mode it was chosen for.
    pub mode: FastestMode,
    /// The frequency the tolerance was checked at (rad/s).
    pub omega_accuracy: f64,
    /// The chosen candidate's relative energy error per simulated second at `omega_accuracy`.
    pub energy_error: f64,
    /// Model cost of a frame (ms).
    pub cost_ms: f64,
    /// The tolerance is met (`false`: none of the candidates met it within the budget and this
    /// is the most accurate stable one).
    pub meets_tolerance: bool,
    /// Every candidate's cheapest stable substep count within the budget (unstable methods
    /// are not listed).
    pub candidates: Vec<Candidate>,
    /// One line for the status and the panel.
    pub reason: String,
}

/// The methods Auto chooses from (see the module docs for the others).
pub const CANDIDATES: [IntegratorKind; 5] = [
    IntegratorKind::SymplecticEuler,
    IntegratorKind::Rk4,
    IntegratorKind::LinearlyImplicitEuler,
    IntegratorKind::ProjectiveDynamics,
    IntegratorKind::BackwardEuler,
];

/// Steps of the stability probe: a mode that grows by a factor `ρ > 1` per step shows as
/// growth `ρ^250` between the halves (the margin [`OMEGA_MARGIN`] keeps the body's own `ω`
/// clear of the marginal `ρ ≈ 1` that would need a longer run to see).
pub const STABILITY_STEPS: u32 = 500;

/// The stability probe's margin on `ω`.
pub const OMEGA_MARGIN: f64 = 1.25;

/// The fastest mode of a linearized body at `state`: `ω = √λ_max(M⁻¹K)` and the largest
/// damping rate `c = λ_max(M⁻¹D)`, on the free particles, by 60 Lanczos iterations each.
pub fn spectrum(lin: &dyn Linearization, state: &ParticleState) -> FastestMode {
    let n = lin.particles();
    let mut mask = vec![0.0 as Scalar; n];
    lin.free_mask(&mut mask);
    let scale: Vec<f64> = lin
        .masses()
        .iter()
        .zip(&mask)
        .map(|(m, w)| {
            if *w > 0.0 && *m > 0.0 {
                1.0 / (*m as f64).sqrt()
            } else {
                0.0
            }
        })
        .collect();
    // A = M − D − K (h = 1) and A_d = M − D: −K = A − A_d, −D' = A_d − M (D' the damping
    // Jacobian, negative semidefinite).
    let mut a = lin.new_matrix();
    let mut ad = lin.new_matrix();
    let mut kv = vec![Vector::ZERO; n];
    lin.assemble(state, 1.0, false, &mut a, &mut kv);
    lin.assemble_damping(state, 1.0, &mut ad);
    let masses: Vec<f64> = lin.masses().iter().map(|m| *m as f64).collect();
    let mut u = vec![Vector::ZERO; n];
    let mut y1 = vec![Vector::ZERO; n];
    let mut y2 = vec![Vector::ZERO; n];
    let mut apply = |stiffness: bool, w: &[f64], out: &mut [f64]| {
        for i in 0..n {
            let s = scale[i];
            u[i] = Vector::new(
                (w[3 * i] * s) as Scalar,
                (w[3 * i + 1] * s) as Scalar,
                (w[3 * i + 2] * s) as Scalar,
            );
        }
        if stiffness {
            a.mul(&u, &mut y1);
            ad.mul(&u, &mut y2);
            for i in 0..n {
                let d = y1[i] - y2[i];
                for c in 0..3 {
                    out[3 * i + c] = d[c] as f64 * scale[i];
                }
            }
        } else {
            ad.mul(&u, &mut y1);
            for i in 0..n {
                for c in 0..3 {
                    let d = y1[i][c] as f64 - masses[i] * u[i][c] as f64;
                    out[3 * i + c] = d * scale[i];
                }
            }
        }
    };
    let lambda = lanczos_max(3 * n, &scale, |w, o| apply(true, w, o));
    let damping = lanczos_max(3 * n, &scale, |w, o| apply(false, w, o));
    FastestMode {
        omega: lambda.max(0.0).sqrt(),
        damping: damping.max(0.0),
    }
}

/// The largest eigenvalue of a symmetric operator on `dim` unknowns (those whose `scale` is
/// non-zero take part), by 60 Lanczos steps without reorthogonalization (its lost
/// orthogonality makes copies of converged eigenvalues, not wrong extreme ones) and
/// bisection on the tridiagonal matrix's Sturm sequence.
fn lanczos_max(dim: usize, scale: &[f64], mut op: impl FnMut(&[f64], &mut [f64])) -> f64 {
    // A deterministic start with every mode in it.
    let mut q: Vec<f64> = (0..dim)
        .map(|k| {
            let x = ((k as f64 + 1.0) * 0.618_033_988_75).fract() - 0.5;
            if scale[k / 3] > 0.0 { x } else { 0.0 }
        })
        .collect();
    let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm == 0.0 {
        return 0.0;
    }
    q.iter_mut().for_each(|x| *x /= norm);
    let mut prev = vec![0.0; dim];
    let mut w = vec![0.0; dim];
    let (mut alpha, mut beta) = (Vec::new(), Vec::new());
    let mut b_prev = 0.0;
    for _ in 0..60.min(dim) {
        op(&q, &mut w);
        let a: f64 = w.iter().zip(&q).map(|(x, y)| x * y).sum();
        for k in 0..dim {
            w[k] -= a * q[k] + b_prev * prev[k];
        }
        alpha.push(a);
        let b = w.iter().map(|x| x * x).sum::<f64>().sqrt();
        // A breakdown (an invariant subspace found) or a non-finite value: stop.
        if b.is_nan() || b <= 1e-12 * a.abs().max(1e-300) {
            break;
        }
        beta.push(b);
        for k in 0..dim {
            prev[k] = q[k];
            q[k] = w[k] / b;
        }
        b_prev = b;
    }
    beta.truncate(alpha.len().saturating_sub(1));
    tridiagonal_max(&alpha, &beta)
}

/// Largest eigenvalue of the symmetric tridiagonal matrix with diagonal `a` and
/// off-diagonal `b`, by bisection on Sturm counts between Gershgorin's bounds.
fn tridiagonal_max(a: &[f64], b: &[f64]) -> f64 {
    if a.is_empty() {
        return 0.0;
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..a.len() {
        let r = b.get(i).map_or(0.0, |x| x.abs()) + if i > 0 { b[i - 1].abs() } else { 0.0 };
        lo = lo.min(a[i] - r);
        hi = hi.max(a[i] + r);
    }
    // Number of eigenvalues below x.
    let below = |x: f64| {
        let mut count = 0;
        let mut d = 1.0;
        for i in 0..a.len() {
            let b2 = if i > 0 { b[i - 1] * b[i - 1] } else { 0.0 };
            d = a[i] - x - if i > 0 { b2 / d } else { 0.0 };
            if d == 0.0 {
                d = -1e-300;
            }
            if d < 0.0 {
                count += 1;
            }
        }
        count
    };
    let n = a.len();
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if below(mid) < n {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// What one run on the test equation showed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Probe {
    /// No growth (see the module docs).
    pub stable: bool,
    /// Largest relative energy error over the run.
    pub energy_error: f64,
}

/// Runs `kind` for `steps` steps of `h` on `ẍ = −ω² x − c ẋ` (one spring of stiffness `ω²`
/// and damper `c` between a pinned particle and a free unit mass, 1 km long — so that the
/// motion stays far from the nonlinearity of a spring through zero length — stretched 1 m),
/// with the same linear solver choice a body would use. The energy error is measured against
/// the undamped energy (use `c = 0` for it); stability by growth between the run's halves.
/// The run stops early once the energy error exceeds `stop_above` (`f64::INFINITY`: never).
#[allow(clippy::too_many_arguments)]
pub fn probe(
    kind: IntegratorKind,
    omega: f64,
    c: f64,
    h: f64,
    steps: u32,
    direct: bool,
    stop_above: f64,
) -> Probe {
    let mut model = ParticleModel::new(vec![1.0, 1.0]);
    model.pin(0, Vector::ZERO);
    model.springs.push(
        0,
        1,
        1000.0,
        (omega * omega) as Scalar,
        c as Scalar,
        Default::default(),
    );
    model.gravity = Vector::ZERO;
    let mut state = ParticleState::zeros(2);
    state.x[1] = Vector::new(1001.0, 0.0, 0.0);
    let mut method =
        kind.build_with::<ParticleState, ParticleModel>(AdaptiveConfig::default(), direct);
    let e0 = 0.5 * omega * omega;
    let energy = |s: &ParticleState| {
        let x = s.x[1].x as f64 - 1000.0;
        let v = s.v[1].x as f64;
        0.5 * v * v + 0.5 * omega * omega * x * x
    };
    let (mut first, mut second, mut error) = (0.0f64, 0.0f64, 0.0f64);
    let mut t = 0.0 as Scalar;
    for k in 0..steps {
        if method.step(&model, t, h as Scalar, &mut state).is_err() || !state.is_finite() {
            return Probe {
                stable: false,
                energy_error: f64::INFINITY,
            };
        }
        model.apply_constraints(t, &mut state);
        t += h as Scalar;
        let e = energy(&state);
        // Past a thousand times its start the amplitude is 30 m of a 1 km spring: still
        // linear, and growth no stable method shows (symplectic Euler's largest, near its
        // limit, is `1/(1 − h²ω²/4)` times the start: 100× at h ω = 1.99).
        if !e.is_finite() || e > 1e3 * e0 {
            return Probe {
                stable: false,
                energy_error: f64::INFINITY,
            };
        }
        error = error.max((e - e0).abs() / e0);
        if error > stop_above {
            // Already past what the caller accepts: the rest of the run cannot bring it back.
            return Probe {
                stable: true,
                energy_error: error,
            };
        }
        if k < steps / 2 {
            first = first.max(e);
        } else {
            second = second.max(e);
        }
    }
    Probe {
        stable: second <= 1.5 * first,
        energy_error: error,
    }
}

/// Model cost of one step of `kind` on a body of `size` at `h ω` (ns), fitted to the fixed
/// choices the `auto` example times (f32, one core, each scene from rest; `docs/BENCHMARKS.md`
/// has the table): a symplectic Euler step 2.8 ns per spring (seed cloths 16² to 64², the
/// bench cloth, within 10 %) and 11.3 ns per tet (the bunny); RK4 four of those; a PCG
/// iteration 2.8 ns per spring and 3 ns per particle, `12 (h ω)^0.8` iterations (40, 71, 141
/// and 422 measured at `h ω` = 4, 8, 17 and 95) with block-Jacobi, and from
/// [`MULTIGRID_MIN_PARTICLES`](crate::core::solve::MULTIGRID_MIN_PARTICLES) particles the
/// multigrid's `2.8 √k` iterations where block-Jacobi takes `k`, each 2.9 times the cost
/// (27, 33 and 54 iterations against 93, 190 and 304 on the 64² and 128² seed cloths and the
/// bench cloth, at 2.8–2.9 times block-Jacobi's cost per iteration); a Cholesky
/// factorization and solve of a tet body `270 ns × particles^1.5` (bunny 2.3 ms, armadillo
/// 2.7 ms); Newton backward Euler 2.5 linearly implicit steps on springs and 1.5 on tets
/// (bunny 1.47, armadillo 1.50); projective dynamics' ten iterations, each
/// `3.8 ns × springs × log₂ particles` (the factor's fill, fitted on the seed cloths and the
/// jelly within 5 %).
pub fn step_cost_ns(kind: IntegratorKind, size: BodySize, h_omega: f64) -> f64 {
    let (n, s, t) = (size.particles as f64, size.springs as f64, size.tets as f64);
    let eval = 2.8 * s + 11.3 * t + 4.0 * n;
    let solve = if size.direct {
        270.0 * n.powf(1.5) + 2.0 * eval
    } else {
        let iterations = 12.0 * h_omega.max(1.0).powf(0.8);
        let per = 2.8 * s + 3.0 * n + 20.0 * t;
        if size.particles >= crate::core::solve::MULTIGRID_MIN_PARTICLES {
            // The multigrid preconditioner (the default at this size): `2.8 √k` iterations
            // where block-Jacobi takes `k`, each 2.9 of block-Jacobi's.
            2.0 * eval + 2.8 * iterations.sqrt() * 2.9 * per
        } else {
            2.0 * eval + iterations * per
        }
    };
    match kind {
        IntegratorKind::SymplecticEuler | IntegratorKind::ForwardEuler => eval,
        IntegratorKind::Rk4 => 4.0 * eval + 12.0 * n,
        IntegratorKind::Trapezoid | IntegratorKind::Midpoint => 2.0 * eval + 6.0 * n,
        IntegratorKind::LinearlyImplicitEuler | IntegratorKind::ImplicitDampingTrapezoid => solve,
        IntegratorKind::BackwardEuler => {
            if t > 0.0 {
                1.5 * solve
            } else {
                2.5 * solve
            }
        }
        IntegratorKind::ProjectiveDynamics => 10.0 * 3.8 * s * n.max(2.0).log2(),
        IntegratorKind::Xpbd => 2.0 * eval,
        IntegratorKind::Rk45 => 6.0 * eval,
        IntegratorKind::Auto => eval,
    }
}

/// Chooses a method and substep count for a body whose fastest mode is `mode`, stepped in
/// frames of `frame_dt`, with `margin` multiplying the stability probe's `ω` (1 at first;
/// the driver doubles it after a divergence), leaving out the methods in `excluded` (those
/// that diverged on this body: a nonlinear blow-up the test equation cannot show, such as
/// linearly implicit Euler's single Newton step on a hard-yanked stiff solid).
pub fn decide(
    mode: FastestMode,
    frame_dt: f64,
    size: BodySize,
    config: &AutoConfig,
    margin: f64,
    excluded: &[IntegratorKind],
) -> AutoChoice {
    let omega = mode.omega;
    let omega_acc = omega.min(std::f64::consts::PI / (4.0 * frame_dt));
    let budget = config.max_substeps.max(1);
    let elements = size.tets > 0;
    let mut candidates = Vec::new();
    for kind in CANDIDATES {
        if (elements && !kind.supports_elements()) || excluded.contains(&kind) {
            continue;
        }
        let stable_at = |n: u32| {
            let h = frame_dt / n as f64;
            probe(
                kind,
                omega * OMEGA_MARGIN * margin,
                mode.damping,
                h,
                STABILITY_STEPS,
                size.direct,
                f64::INFINITY,
            )
            .stable
        };
        let accuracy = |n: u32, stop: f64| {
            let h = frame_dt / n as f64;
            let steps = (1.0 / h).round().max(1.0) as u32;
            probe(kind, omega_acc, 0.0, h, steps, size.direct, stop).energy_error
        };
        let meets = |n: u32| config.tolerance.is_none_or(|tol| accuracy(n, tol) <= tol);
        let ok = |n: u32| stable_at(n) && meets(n);
        // Smallest substep count that is stable and accurate (both improve with more
        // substeps): doubling, then bisection; else the smallest stable one.
        let n = match smallest(budget, ok) {
            Some(n) => Some(n),
            None => smallest(budget, stable_at),
        };
        let Some(n) = n else { continue };
        let h = frame_dt / n as f64;
        let energy_error = accuracy(n, f64::INFINITY);
        candidates.push(Candidate {
            kind,
            substeps: n,
            energy_error,
            cost_ms: n as f64 * step_cost_ns(kind, size, h * omega) * 1e-6,
            meets: config.tolerance.is_none_or(|tol| energy_error <= tol),
        });
    }
    let best = candidates
        .iter()
        .filter(|c| c.meets)
        .min_by(|a, b| a.cost_ms.total_cmp(&b.cost_ms))
        .or_else(|| {
            candidates
                .iter()
                .min_by(|a, b| a.energy_error.total_cmp(&b.energy_error))
        })
        .copied();
    let Some(best) = best else {
        // Nothing stable within the budget (not even backward Euler): the most stable method
        // at the budget's step, reported.
        let kind = if elements {
            IntegratorKind::BackwardEuler
        } else {
            IntegratorKind::ProjectiveDynamics
        };
        return AutoChoice {
            kind,
            substeps: budget,
            h: frame_dt / budget as f64,
            mode,
            omega_accuracy: omega_acc,
            energy_error: f64::INFINITY,
            cost_ms: budget as f64
                * step_cost_ns(kind, size, frame_dt / budget as f64 * omega)
                * 1e-6,
            meets_tolerance: false,
            candidates,
            reason: format!(
                "{}, {budget} substeps: no candidate stable within {budget} substeps on the test equation at ω = {omega:.3e} rad/s",
                kind.label()
            ),
        };
    };
    let h = frame_dt / best.substeps as f64;
    let mut reason = format!(
        "{}, {} substep{}: h·ω = {:.2}",
        best.kind.label(),
        best.substeps,
        if best.substeps == 1 { "" } else { "s" },
        h * omega
    );
    if let Some(limit) = explicit_limit(best.kind) {
        let _ = write!(reason, " < {limit}");
    }
    if margin > 1.0 {
        let _ = write!(
            reason,
            " (probed at {:.1}× the fastest mode after a diverging frame",
            OMEGA_MARGIN * margin
        );
        for k in excluded {
            let _ = write!(reason, "; {} diverged here", k.label());
        }
        reason.push(')');
    }
    match config.tolerance {
        Some(tol) if best.meets => {
            let _ = write!(
                reason,
                ", energy error {:.1e}/s ≤ {tol:.0e} at ω = {omega_acc:.0}",
                best.energy_error
            );
        }
        Some(tol) => {
            let _ = write!(
                reason,
                "; no method meets {tol:.0e}/s within {budget} substeps: the most accurate stable one ({:.1e}/s)",
                best.energy_error
            );
        }
        None => {}
    }
    if let Some(next) = candidates
        .iter()
        .filter(|c| c.kind != best.kind && c.meets == best.meets)
        .min_by(|a, b| a.cost_ms.total_cmp(&b.cost_ms))
    {
        let _ = write!(
            reason,
            "; cheaper than {}'s {} step{} at {} (model: {} a frame)",
            next.kind.label(),
            next.substeps,
            if next.substeps == 1 { "" } else { "s" },
            ms(next.cost_ms),
            ms(best.cost_ms)
        );
    }
    AutoChoice {
        kind: best.kind,
        substeps: best.substeps,
        h,
        mode,
        omega_accuracy: omega_acc,
        energy_error: best.energy_error,
        cost_ms: best.cost_ms,
        meets_tolerance: best.meets,
        candidates,
        reason,
    }
}

/// A model cost in ms, or µs below a tenth of a millisecond.
fn ms(x: f64) -> String {
    if x < 1e-3 {
        format!("{:.2} µs", x * 1e3)
    } else if x < 0.1 {
        format!("{:.1} µs", x * 1e3)
    } else {
        format!("{x:.2} ms")
    }
}

/// The explicit methods' stability limits on `h ω` for an undamped mode (Hairer, Lubich and
/// Wanner, *Geometric Numerical Integration*, for symplectic Euler; the RK4 stability
/// region's imaginary-axis extent 2√2), quoted in the reason; the choice itself rests on the
/// probe.
fn explicit_limit(kind: IntegratorKind) -> Option<&'static str> {
    match kind {
        IntegratorKind::SymplecticEuler => Some("2"),
        IntegratorKind::Rk4 => Some("2.83"),
        _ => None,
    }
}

/// The smallest `n` in `1..=budget` with `ok(n)`, assuming `ok` is monotone: doubling, then
/// bisection.
fn smallest(budget: u32, ok: impl Fn(u32) -> bool) -> Option<u32> {
    let mut hi = 1;
    while !ok(hi) {
        if hi >= budget {
            return None;
        }
        hi = (hi * 2).min(budget);
    }
    let mut lo = hi / 2; // not ok (or 0)
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if ok(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Some(hi)
}

/// Auto's decision for a linearized body at `state`, its implicit methods solving directly
/// (`direct`) or with PCG, without the methods in `excluded` (see [`decide`]).
#[allow(clippy::too_many_arguments)]
pub fn decide_for(
    lin: &dyn Linearization,
    state: &ParticleState,
    frame_dt: f64,
    config: &AutoConfig,
    margin: f64,
    direct: bool,
    excluded: &[IntegratorKind],
) -> AutoChoice {
    let mode = spectrum(lin, state);
    let (springs, tets) = lin.element_counts();
    let size = BodySize {
        particles: lin.particles(),
        springs,
        tets,
        direct,
    };
    decide(mode, frame_dt, size, config, margin, excluded)
}
