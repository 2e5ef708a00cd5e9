//! Speed against accuracy, measured: work-precision sweeps of every integrator on problems
//! with known or computed reference solutions, and least-squares convergence orders. The
//! `work_precision` example prints, writes and charts what this computes; the tests run its
//! quick sweeps and assert the orders theory gives.
//!
//! Problems:
//! - the circle `dx/dt = (−y, x, 0)` from (1, 0, 0) to T = 2 s, against the exact solution;
//! - a 4-particle spring pendulum (the default chain: 0.1 kg, 200 N/m, links 0.25 m, released
//!   horizontally), undamped and with dampers of 0.5 N·s/m, to T = 1 s, against RK45 at
//!   tolerance 1e-12 (cross-checked against tolerance 1e-11: their difference is reported);
//! - a 16×16 cloth (the seed material), to T = 0.25 s, against RK4 at a step 16× smaller than
//!   the smallest in the sweep (cross-checked against RK4 at twice that step).
//!
//! Error: the largest distance of a particle (or of the circle's point) from the reference at
//! T. Cost: derivative evaluations, linear solves and wall time.

use crate::core::build;
use crate::core::driver::{DriverConfig, Simulation, StepPolicy};
use crate::core::integrate::{AdaptiveConfig, IntegratorKind, IntegratorStats};
use crate::core::ode::{CircleSystem, OdeState, OdeSystem, ParticleState};
use crate::core::particles::ParticleModel;
use crate::math::{Scalar, Vector};
use std::time::Instant;

/// A test problem of the work-precision study.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Problem {
    /// `dx/dt = (−y, x, 0)`, exact solution known.
    Circle,
    /// The 4-particle spring pendulum, undamped or damped.
    Pendulum {
        /// With dampers of 0.5 N·s/m on every spring.
        damped: bool,
    },
    /// A 16×16 cloth of the seed material.
    Cloth,
}

impl Problem {
    /// Every problem, in the order tables list them.
    pub const ALL: [Problem; 4] = [
        Problem::Circle,
        Problem::Pendulum { damped: false },
        Problem::Pendulum { damped: true },
        Problem::Cloth,
    ];

    /// A short name for files and tables.
    pub fn name(self) -> &'static str {
        match self {
            Problem::Circle => "circle",
            Problem::Pendulum { damped: false } => "pendulum",
            Problem::Pendulum { damped: true } => "damped_pendulum",
            Problem::Cloth => "cloth16",
        }
    }

    /// The time the error is measured at (s).
    pub fn horizon(self) -> f64 {
        match self {
            Problem::Circle => 2.0,
            Problem::Pendulum { .. } => 1.0,
            Problem::Cloth => 0.25,
        }
    }

    /// The swept step sizes, largest first (each halves the previous); `quick` keeps a
    /// shorter sweep inside every method's asymptotic range.
    pub fn steps(self, quick: bool) -> Vec<f64> {
        let (largest, count) = match (self, quick) {
            (Problem::Circle, false) => (0.1, 8),
            (Problem::Circle, true) => (0.05, 4),
            (Problem::Pendulum { .. }, false) => (1.0 / 200.0, 7),
            (Problem::Pendulum { .. }, true) => (1.0 / 400.0, 4),
            (Problem::Cloth, false) => (1.0 / 400.0, 6),
            (Problem::Cloth, true) => (1.0 / 800.0, 3),
        };
        (0..count).map(|k| largest / f64::powi(2.0, k)).collect()
    }

    /// The tolerances swept for RK45 (rtol = atol).
    pub fn tolerances(self, quick: bool) -> Vec<f64> {
        let n = if quick { 3 } else { 7 };
        (0..n).map(|k| 1e-3 / f64::powi(10.0, k)).collect()
    }

    /// True when `kind` applies: the circle is a first-order system without Jacobians, so it
    /// takes neither symplectic Euler (which needs positions and velocities) nor implicit
    /// methods.
    pub fn supports(self, kind: IntegratorKind) -> bool {
        match self {
            Problem::Circle => !kind.is_implicit() && kind != IntegratorKind::SymplecticEuler,
            _ => true,
        }
    }

    fn particles(self) -> (ParticleModel, ParticleState) {
        let scene = match self {
            Problem::Pendulum { damped } => build::chain(&build::ChainParams {
                particles: 4,
                damping: if damped { 0.5 } else { 0.0 },
                drag: 0.0,
                ..Default::default()
            }),
            _ => build::cloth(&build::ClothParams::default()),
        };
        scene
            .expect("built-in scene")
            .build()
            .expect("built-in scene is valid")
    }
}

/// One run of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkPoint {
    /// The method.
    pub method: IntegratorKind,
    /// Step size (fixed-step methods) or tolerance (RK45).
    pub h: f64,
    /// Largest position error at the horizon; `None` when the run diverged.
    pub error: Option<f64>,
    /// Derivative evaluations.
    pub evaluations: u64,
    /// Linear solves (implicit methods).
    pub linear_solves: u64,
    /// Wall time of the run (s).
    pub seconds: f64,
}

fn max_distance(a: &[Vector], b: &[Vector]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).length() as f64)
        .fold(0.0, f64::max)
}

/// Runs `kind` on a system from its initial state to `t` in steps of `h` (one frame of length
/// `t`, so the last step lands on it), or with tolerance `h` for RK45.
fn run<S: OdeState, Sys: OdeSystem<S>>(
    system: Sys,
    state: S,
    kind: IntegratorKind,
    h: f64,
    t: f64,
) -> (Option<S>, IntegratorStats, f64) {
    let (policy, adaptive) = if kind.is_adaptive() {
        (
            StepPolicy::Fixed { h: t },
            AdaptiveConfig {
                rtol: h,
                atol: h,
                ..Default::default()
            },
        )
    } else {
        (StepPolicy::Fixed { h }, AdaptiveConfig::default())
    };
    let mut sim = Simulation::new(
        system,
        state,
        DriverConfig {
            integrator: kind,
            policy,
            frame_dt: t,
            adaptive,
            energy_guard: Some(1e3),
        },
    );
    let start = Instant::now();
    let ok = sim.advance_frame().is_ok();
    let secs = start.elapsed().as_secs_f64();
    let stats = sim.stats();
    (ok.then_some(sim.state), stats, secs)
}

/// The reference positions at the horizon and, for computed references, the difference
/// between the reference and its cross-check (an estimate of its own error).
pub fn reference(problem: Problem, quick: bool) -> (Vec<Vector>, f64) {
    let t = problem.horizon();
    match problem {
        Problem::Circle => (vec![CircleSystem::exact(Vector::X, t as Scalar)], 0.0),
        Problem::Pendulum { .. } => {
            let tight = if cfg!(feature = "f64") { 1e-12 } else { 1e-7 };
            let go = |tol: f64| {
                let (m, s) = problem.particles();
                run(m, s, IntegratorKind::Rk45, tol, t)
                    .0
                    .expect("the reference run is stable")
                    .x
            };
            let (a, b) = (go(tight), go(tight * 10.0));
            let d = max_distance(&a, &b);
            (a, d)
        }
        Problem::Cloth => {
            let h = problem.steps(quick).last().copied().unwrap_or(1e-3) / 16.0;
            let (m, s) = problem.particles();
            let x = run(m, s, IntegratorKind::Rk4, h, t)
                .0
                .expect("the reference run is stable")
                .x;
            // Cross-check: twice the reference step (RK4's error there is 16× the reference's,
            // so the difference bounds the reference's own error from above).
            let (m, s) = problem.particles();
            let y = run(m, s, IntegratorKind::Rk4, h * 2.0, t)
                .0
                .expect("stable")
                .x;
            let d = max_distance(&x, &y);
            (x, d)
        }
    }
}

/// The work-precision sweep of `kinds` on `problem`.
pub fn work_precision(problem: Problem, kinds: &[IntegratorKind], quick: bool) -> Vec<WorkPoint> {
    let (reference, _) = reference(problem, quick);
    let t = problem.horizon();
    let mut out = vec![];
    for &kind in kinds {
        if !problem.supports(kind) {
            continue;
        }
        let sweep = if kind.is_adaptive() {
            problem.tolerances(quick)
        } else {
            // Higher-order methods reach round-off at larger steps: start their sweep 2^(p−1)
            // times larger (at most 4×, which keeps RK4 on the pendulum at h ω < 1.3, well in
            // its asymptotic range) so more of it lies above the floor; for the cloth, whose
            // stiffest mode bounds every explicit step, keep the common sweep.
            let scale = match problem {
                Problem::Cloth => 1.0,
                _ => f64::powi(2.0, kind.order() as i32 - 1).min(4.0),
            };
            problem
                .steps(quick)
                .into_iter()
                .map(|h| h * scale)
                .collect()
        };
        for h in sweep {
            let (end, stats, seconds) = match problem {
                Problem::Circle => {
                    let (s, st, secs) = run(CircleSystem, Vector::X, kind, h, t);
                    (s.map(|x| vec![x]), st, secs)
                }
                _ => {
                    let (m, s) = problem.particles();
                    let (s, st, secs) = run(m, s, kind, h, t);
                    (s.map(|s| s.x), st, secs)
                }
            };
            out.push(WorkPoint {
                method: kind,
                h,
                error: end.map(|x| max_distance(&x, &reference)),
                evaluations: stats.evaluations,
                linear_solves: stats.linear_solves,
                seconds,
            });
        }
    }
    out
}

/// The least-squares slope of `log(error)` against `log(h)` over the points of `method` whose
/// error lies between `floor` and `ceiling` (below: round-off or the reference's own error;
/// above: outside the asymptotic range); `None` with fewer than three such points or any
/// divergence among them.
pub fn measured_order(
    points: &[WorkPoint],
    method: IntegratorKind,
    floor: f64,
    ceiling: f64,
) -> Option<f64> {
    let mut xy = vec![];
    for p in points.iter().filter(|p| p.method == method) {
        let e = p.error?;
        if e > floor && e < ceiling {
            xy.push((p.h.ln(), e.ln()));
        }
    }
    if xy.len() < 3 {
        return None;
    }
    let n = xy.len() as f64;
    let (sx, sy) = xy.iter().fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
    let (mx, my) = (sx / n, sy / n);
    let (sxy, sxx) = xy.iter().fold((0.0, 0.0), |(a, b), (x, y)| {
        (a + (x - mx) * (y - my), b + (x - mx) * (x - mx))
    });
    Some(sxy / sxx)
}

/// The error floor of a problem: what accumulated round-off of the precision in use reaches
/// over the problem's scale (1 m) in thousands of steps, `10³ u`, or ten times the
/// reference's own error, whichever is larger. Points below it measure noise, not order.
pub fn error_floor(reference_error: f64) -> f64 {
    (1e3 * Scalar::EPSILON as f64).max(10.0 * reference_error)
}
