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
//! - a 16×16 cloth (the cloth assignment's material), to T = 0.25 s, against RK4 at a step 16× smaller than
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
    /// A 16×16 cloth of the cloth assignment's material.
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
            solver: Default::default(),
            auto: Default::default(),
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
            // XPBD on the cloth starts one halving lower: its single constraint sweep is not yet
            // in its asymptotic range at the common sweep's largest step (the error falls 3.6×
            // over that first halving, then 2.1×, measured in f64).
            let scale = match problem {
                Problem::Cloth if kind == IntegratorKind::Xpbd => 0.5,
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
            out.push(match problem {
                Problem::Circle => {
                    let (s, st, secs) = run(CircleSystem, Vector::X, kind, h, t);
                    point(kind, h, s.map(|x| vec![x]), st, secs, &reference)
                }
                _ => {
                    let (m, s) = problem.particles();
                    let (s, st, secs) = run(m, s, kind, h, t);
                    point(kind, h, s.map(|s| s.x), st, secs, &reference)
                }
            });
        }
    }
    out
}

fn point(
    method: IntegratorKind,
    h: f64,
    end: Option<Vec<Vector>>,
    stats: IntegratorStats,
    seconds: f64,
    reference: &[Vector],
) -> WorkPoint {
    WorkPoint {
        method,
        h,
        error: end.map(|x| max_distance(&x, reference)),
        evaluations: stats.evaluations,
        linear_solves: stats.linear_solves,
        seconds,
    }
}

/// A work-precision problem on a body the caller builds: the finite-element bodies, or any
/// scene at the step sizes games use. Every fixed-step method runs over the same `steps` (no
/// per-order shift: here the point is where the methods meet at large steps, and where the
/// explicit ones stop being stable); RK45 over `tolerances`. The reference is RK4 at
/// `reference_step`, cross-checked against RK4 at twice that step.
#[derive(Clone, Debug)]
pub struct BodyProblem {
    /// A short name for files and tables.
    pub name: String,
    /// The body.
    pub model: ParticleModel,
    /// Its initial state.
    pub state: ParticleState,
    /// The time the error is measured at (s); a multiple of every step.
    pub horizon: f64,
    /// The swept step sizes, largest first.
    pub steps: Vec<f64>,
    /// The tolerances swept for RK45 (rtol = atol).
    pub tolerances: Vec<f64>,
    /// RK4's step for the reference solution.
    pub reference_step: f64,
}

impl BodyProblem {
    /// The large-step sweep: one step per 1/60 s frame, then halved `count − 1` times.
    pub fn frame_steps(count: usize) -> Vec<f64> {
        (0..count)
            .map(|k| 1.0 / (60.0 * f64::powi(2.0, k as i32)))
            .collect()
    }

    /// A body swept from one step per 1/60 s frame down by halves until `h ω ≤ 1/4` for its
    /// fastest mode `ω` (Lanczos, [`crate::core::auto::spectrum`]), so that the explicit
    /// methods, stable below `h ω = 2` (symplectic Euler) or `2√2` (RK4), get at least three
    /// stable points; RK45 at tolerances 1e-2 … 1e-6; the reference at a quarter of the
    /// smallest step.
    pub fn from_frame(
        name: &str,
        model: ParticleModel,
        state: ParticleState,
        horizon: f64,
    ) -> Self {
        let omega = model
            .linearization()
            .map_or(0.0, |lin| crate::core::auto::spectrum(lin, &state).omega);
        let ratio = (omega / 60.0 / 0.25).max(1.0);
        let count = ratio.log2().ceil() as usize + 1;
        let steps = Self::frame_steps(count);
        let reference_step = steps.last().copied().unwrap_or(1.0 / 60.0) / 4.0;
        Self {
            name: name.into(),
            model,
            state,
            horizon,
            steps,
            tolerances: (0..5).map(|k| 1e-2 / f64::powi(10.0, k)).collect(),
            reference_step,
        }
    }

    /// True when `kind` steps this body: every method on springs; on finite elements, those
    /// with [`IntegratorKind::supports_elements`].
    pub fn supports(&self, kind: IntegratorKind) -> bool {
        kind != IntegratorKind::Auto && (self.model.tets.is_empty() || kind.supports_elements())
    }

    /// The reference positions at the horizon and their difference from the cross-check (an
    /// upper estimate of the reference's own error: RK4's error at twice the step is 16× its
    /// error at the step).
    pub fn reference(&self) -> (Vec<Vector>, f64) {
        let go = |h: f64| {
            run(
                self.model.clone(),
                self.state.clone(),
                IntegratorKind::Rk4,
                h,
                self.horizon,
            )
            .0
            .map(|s| s.x)
        };
        match (go(self.reference_step), go(2.0 * self.reference_step)) {
            (Some(x), Some(y)) => {
                let d = max_distance(&x, &y);
                (x, d)
            }
            _ => (self.state.x.clone(), f64::INFINITY),
        }
    }

    /// The sweep of `kinds` (those this body supports) against `reference`.
    pub fn work_precision(&self, kinds: &[IntegratorKind], reference: &[Vector]) -> Vec<WorkPoint> {
        let mut out = vec![];
        for &kind in kinds.iter().filter(|k| self.supports(**k)) {
            let sweep = if kind.is_adaptive() {
                &self.tolerances
            } else {
                &self.steps
            };
            for &h in sweep {
                let (s, st, secs) = run(
                    self.model.clone(),
                    self.state.clone(),
                    kind,
                    h,
                    self.horizon,
                );
                out.push(point(kind, h, s.map(|s| s.x), st, secs, reference));
            }
        }
        out
    }
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
    least_squares_slope(&xy)
}

/// The points of `method` after its last divergence (sweeps run largest step first): the
/// steps at which it is stable, for [`measured_order`] on a large-step sweep, where the
/// explicit methods diverge at the large end by design.
pub fn stable_tail(points: &[WorkPoint], method: IntegratorKind) -> Vec<WorkPoint> {
    let mine: Vec<&WorkPoint> = points.iter().filter(|p| p.method == method).collect();
    let start = mine
        .iter()
        .rposition(|p| p.error.is_none())
        .map_or(0, |i| i + 1);
    mine[start..].iter().map(|p| (*p).clone()).collect()
}

/// What `method` costs to reach `target` error on a sweep: the wall time (s), interpolated
/// log–log between the last stable point above the target and the first below it; with
/// `at_largest` true when the largest stable step already meets it (the cost is then that
/// step's, an upper bound). `None` when no stable point meets it.
pub fn cost_at(points: &[WorkPoint], method: IntegratorKind, target: f64) -> Option<(f64, bool)> {
    let tail = stable_tail(points, method);
    let first = tail
        .iter()
        .position(|p| p.error.is_some_and(|e| e <= target))?;
    let below = &tail[first];
    if first == 0 {
        return Some((below.seconds, true));
    }
    let above = &tail[first - 1];
    let (ea, eb) = (above.error?.ln(), below.error?.ln());
    let (ca, cb) = (above.seconds.max(1e-9).ln(), below.seconds.max(1e-9).ln());
    let s = if ea > eb {
        (ea - target.ln()) / (ea - eb)
    } else {
        1.0
    };
    Some(((ca + s * (cb - ca)).exp(), false))
}

/// The least-squares slope of `y` against `x` (`None` with fewer than two distinct `x`).
pub fn least_squares_slope(xy: &[(f64, f64)]) -> Option<f64> {
    let n = xy.len() as f64;
    let (sx, sy) = xy.iter().fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
    let (mx, my) = (sx / n, sy / n);
    let (sxy, sxx) = xy.iter().fold((0.0, 0.0), |(a, b), (x, y)| {
        (a + (x - mx) * (y - my), b + (x - mx) * (x - mx))
    });
    (sxx > 0.0).then(|| sxy / sxx)
}

/// The error floor of a problem: what accumulated round-off of the precision in use reaches
/// over the problem's scale (1 m) in thousands of steps, `10³ u`, or ten times the
/// reference's own error, whichever is larger. Points below it measure noise, not order.
pub fn error_floor(reference_error: f64) -> f64 {
    (1e3 * Scalar::EPSILON as f64).max(10.0 * reference_error)
}

/// A scene of the stability study.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StabilityScene {
    /// An 8-particle spring chain (the default material, no dampers, drag 0.01), released
    /// horizontally.
    Chain,
    /// The cloth assignment's 16×16 cloth (8×8 in quick mode), hanging from two corners, with dampers.
    Cloth,
    /// The default 6×6×6 jelly block (4×4×4 in quick mode) in free fall, with dampers.
    Jelly,
}

impl StabilityScene {
    /// Every scene.
    pub const ALL: [StabilityScene; 3] = [
        StabilityScene::Chain,
        StabilityScene::Cloth,
        StabilityScene::Jelly,
    ];

    /// A short name.
    pub fn name(self) -> &'static str {
        match self {
            StabilityScene::Chain => "chain",
            StabilityScene::Cloth => "cloth",
            StabilityScene::Jelly => "jelly",
        }
    }

    /// The scene's model and initial state.
    pub fn build(self, quick: bool) -> (ParticleModel, ParticleState) {
        let scene = match self {
            StabilityScene::Chain => build::chain(&build::ChainParams {
                particles: 8,
                ..Default::default()
            }),
            StabilityScene::Cloth => {
                let n = if quick { 8 } else { 16 };
                build::cloth(&build::ClothParams::default().resized(n, n))
            }
            StabilityScene::Jelly => {
                let n = if quick { 4 } else { 6 };
                let mut s = build::jelly(&build::JellyParams {
                    size: [n, n, n],
                    ..Default::default()
                });
                // Free fall: the ground's contacts are not part of the linear stability
                // question.
                if let Ok(s) = s.as_mut() {
                    s.colliders.clear();
                }
                s
            }
        };
        scene
            .expect("built-in scene")
            .build()
            .expect("built-in scene is valid")
    }
}

/// The fastest mode of a scene: its angular frequency and its modal damping rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FastestMode {
    /// `√λ_max` of `M⁻¹K` (rad/s).
    pub omega: f64,
    /// `c = φᵀ D φ / φᵀ M φ` (1/s) for the mode shape `φ`: the damping rate the dampers and
    /// drag give that mode (`ẍ + c ẋ + ω² x = 0`), exact for proportional damping.
    pub damping: f64,
}

/// `√λ_max` of `M⁻¹K` (rad/s): the fastest mode of the linearized spring network at `state`
/// (pinned and prescribed particles held), by power iteration. `K` is the exact stiffness
/// (compressed springs' indefinite part included), whose largest eigenvalue bounds explicit
/// steps.
pub fn omega_max(model: &ParticleModel, state: &ParticleState) -> f64 {
    fastest_mode(model, state).omega
}

/// The fastest mode (see [`FastestMode`]) by power iteration on `M⁻¹K`.
pub fn fastest_mode(model: &ParticleModel, state: &ParticleState) -> FastestMode {
    use crate::core::jacobian::{Linearization, spring_stiffness};
    let n = model.len();
    let mut mask = vec![0.0; n];
    model.free_mask(&mut mask);
    // A deterministic start with every mode in it.
    let mut v: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            let a = (i as f64 * 0.618_033_988_75).fract() - 0.5;
            let b = (i as f64 * 0.414_213_562_37).fract() - 0.5;
            let c = (i as f64 * 0.732_050_807_57).fract() - 0.5;
            [a, b, c].map(|x| x * mask[i] as f64)
        })
        .collect();
    let blocks: Vec<[[f64; 3]; 3]> = model
        .springs
        .as_slice()
        .iter()
        .map(|s| {
            let k = spring_stiffness(s, &state.x, false);
            let mut m = [[0.0; 3]; 3];
            for (c, col) in [k.x_axis, k.y_axis, k.z_axis].iter().enumerate() {
                for r in 0..3 {
                    m[r][c] = col[r] as f64;
                }
            }
            m
        })
        .collect();
    // Power iteration converges to λ_max from below at the rate λ₂/λ₁, which approaches 1
    // on fine grids: iterate until λ settles to 1e-7 relative (at most 20,000 iterations).
    let mut lambda = 0.0;
    for _ in 0..20_000 {
        let previous = lambda;
        let mut y = vec![[0.0f64; 3]; n];
        for (s, k) in model.springs.as_slice().iter().zip(&blocks) {
            let (i, j) = (s.i as usize, s.j as usize);
            let d = [v[i][0] - v[j][0], v[i][1] - v[j][1], v[i][2] - v[j][2]];
            for r in 0..3 {
                let f = k[r][0] * d[0] + k[r][1] * d[1] + k[r][2] * d[2];
                y[i][r] += f;
                y[j][r] -= f;
            }
        }
        let mut norm = 0.0f64;
        for ((yi, w), m) in y.iter_mut().zip(&mask).zip(model.mass()) {
            let w = *w as f64 / *m as f64;
            for c in yi.iter_mut() {
                *c *= w;
                norm += *c * *c;
            }
        }
        let norm = norm.sqrt();
        if norm == 0.0 {
            return FastestMode {
                omega: 0.0,
                damping: 0.0,
            };
        }
        let vnorm: f64 = v.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
        lambda = norm / vnorm;
        for (vi, yi) in v.iter_mut().zip(&y) {
            *vi = yi.map(|x| x / norm);
        }
        if (lambda - previous).abs() <= 1e-7 * lambda {
            break;
        }
    }
    // Modal damping: Rayleigh quotient of the damping matrix (dampers b n nᵀ along each
    // spring, drag c I on free particles) over the mass matrix, on the mode shape.
    let (mut num, mut den) = (0.0f64, 0.0f64);
    let drag = model.linear_drag() as f64;
    for i in 0..n {
        let vv: f64 = v[i].iter().map(|x| x * x).sum();
        den += model.mass()[i] as f64 * vv;
        num += drag * vv * mask[i] as f64;
    }
    for s in model.springs.as_slice() {
        let (i, j) = (s.i as usize, s.j as usize);
        let d = state.x[i] - state.x[j];
        let l = d.length();
        if l == 0.0 || s.damping == 0.0 {
            continue;
        }
        let nn = d / l;
        let rate = (0..3)
            .map(|r| nn[r] as f64 * (v[i][r] - v[j][r]))
            .sum::<f64>();
        num += s.damping as f64 * rate * rate;
    }
    FastestMode {
        omega: lambda.sqrt(),
        damping: if den > 0.0 { num / den } else { 0.0 },
    }
}

/// The linear stability bound of `kind` on the mode `ẍ + c ẋ + ω² x = 0`:
/// symplectic Euler `2(√(1+ζ²) − ζ)/ω` with `ζ = c/2ω` (Jury's test on its 2×2 step
/// matrix; `2/ω` undamped), RK4 the largest `h` with `|R(hλ)| ≤ 1` at `λ = −c/2 ± i√(ω² −
/// c²/4)` for its stability polynomial `R` (`2√2/ω` undamped, where its region meets the
/// imaginary axis); `None` for forward Euler, the explicit trapezoid and midpoint (no bound
/// without damping: they amplify every undamped oscillation) and for implicit or adaptive
/// methods.
pub fn theoretical_bound_damped(kind: IntegratorKind, mode: FastestMode) -> Option<f64> {
    let (w, c) = (mode.omega, mode.damping);
    if w <= 0.0 {
        return None;
    }
    match kind {
        IntegratorKind::SymplecticEuler => {
            let z = c / (2.0 * w);
            Some(2.0 * ((1.0 + z * z).sqrt() - z) / w)
        }
        IntegratorKind::Rk4 => {
            let (re, im) = (-c / 2.0, (w * w - c * c / 4.0).max(0.0).sqrt());
            let amp = |h: f64| {
                // R(z) = 1 + z + z²/2 + z³/6 + z⁴/24 at z = h λ (complex).
                let (zr, zi) = (h * re, h * im);
                let (mut pr, mut pi) = (1.0, 0.0); // z^k / k!
                let (mut sr, mut si) = (1.0, 0.0);
                for k in 1..=4 {
                    let (nr, ni) = (pr * zr - pi * zi, pr * zi + pi * zr);
                    pr = nr / k as f64;
                    pi = ni / k as f64;
                    sr += pr;
                    si += pi;
                }
                (sr * sr + si * si).sqrt()
            };
            // Bisection on the first crossing of |R| = 1 (|R| < 1 just above 0 for c > 0 and
            // tangent to 1 for c = 0, where the crossing is 2√2/ω).
            let (mut a, mut b) = (0.5 / w, 4.0 / w);
            if amp(b) <= 1.0 {
                return Some(b);
            }
            for _ in 0..60 {
                let m = 0.5 * (a + b);
                if amp(m) <= 1.0 { a = m } else { b = m }
            }
            Some(a)
        }
        _ => None,
    }
}

/// The explicit stability bound of `kind` for an undamped mode of angular frequency `omega`:
/// `2/ω` for symplectic Euler, `2√2/ω` for RK4 (where its stability region meets the
/// imaginary axis); `None` where there is none (forward Euler, the explicit trapezoid and
/// midpoint amplify every undamped oscillation) or the method is implicit or adaptive.
pub fn theoretical_bound(kind: IntegratorKind, omega: f64) -> Option<f64> {
    match kind {
        IntegratorKind::SymplecticEuler => Some(2.0 / omega),
        IntegratorKind::Rk4 => Some(2.0 * std::f64::consts::SQRT_2 / omega),
        _ => None,
    }
}

/// True when `kind` at step `h` keeps the scene finite and its total energy within its
/// initial value plus a tenth of its energy scale (gravity is in the potential, pins do no
/// work, so no physical motion raises the total) over `duration` seconds.
pub fn is_stable(
    scene: StabilityScene,
    kind: IntegratorKind,
    h: f64,
    duration: f64,
    quick: bool,
) -> bool {
    let (model, state) = scene.build(quick);
    let e0 = model.energy(0.0, &state).map_or(0.0, |e| e.total() as f64);
    let scale = model.energy_scale(&state).unwrap_or(1.0) as f64;
    let mut sim = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: kind,
            policy: StepPolicy::Fixed { h },
            frame_dt: h,
            energy_guard: None,
            ..Default::default()
        },
    );
    let steps = (duration / h).ceil() as u64;
    for _ in 0..steps {
        if sim.advance_frame().is_err() {
            return false;
        }
        let e = sim
            .system
            .energy(sim.time, &sim.state)
            .map_or(0.0, |e| e.total() as f64);
        if !e.is_finite() || e > e0 + 0.1 * scale {
            return false;
        }
    }
    true
}

/// The largest stable step of `kind` on `scene` by bisection between `lo` (must be stable)
/// and `hi`, to a relative precision of 1 %; `None` when even `lo` is unstable, `Some(hi)`
/// when `hi` is stable.
pub fn largest_stable_h(
    scene: StabilityScene,
    kind: IntegratorKind,
    lo: f64,
    hi: f64,
    duration: f64,
    quick: bool,
) -> Option<f64> {
    if !is_stable(scene, kind, lo, duration, quick) {
        return None;
    }
    if is_stable(scene, kind, hi, duration, quick) {
        return Some(hi);
    }
    let (mut a, mut b) = (lo, hi);
    while b / a > 1.01 {
        let m = (a * b).sqrt();
        if is_stable(scene, kind, m, duration, quick) {
            a = m;
        } else {
            b = m;
        }
    }
    Some(a)
}

/// A cantilever brought to rest: what [`cantilever_tip`] measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cantilever {
    /// Mean downward displacement of the free end's vertices (m).
    pub tip: f64,
    /// Tets in the mesh.
    pub tets: usize,
    /// Frames (backward Euler steps) taken to rest.
    pub frames: u32,
    /// Newton iterations in all.
    pub newton_iterations: u64,
}

/// Tip deflection of a beam of `length` and square section `side` (cells `n × m × m`),
/// clamped at x = 0, brought to rest under gravity by backward Euler with h = 5 s (each step
/// nearly a static Newton solve), stopping when the tip moves by less than 1e-4 of its
/// deflection in a step (f32 positions near 1 m round off at 6e-8 m, 6e-6 of a 1 cm
/// deflection). Compare with Euler–Bernoulli's `w L⁴ / (8 E I)`.
pub fn cantilever_tip(
    length: f64,
    side: f64,
    n: usize,
    m: usize,
    material: crate::core::fem::NeoHookean,
) -> Result<Cantilever, String> {
    let mesh = crate::core::fem::mesh::TetMesh::beam(length, side, n, m).map_err(|e| e.0)?;
    let scene = mesh.to_scene("beam", material);
    let (mut model, state) = scene.build().map_err(|e| e.to_string())?;
    for (i, p) in scene.particles.iter().enumerate() {
        if p.position[0] == 0.0 {
            model.pin(i, state.x[i]);
        }
    }
    let tets = model.tets.len();
    let h = 5.0;
    let mut sim = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: IntegratorKind::BackwardEuler,
            policy: StepPolicy::Fixed { h },
            frame_dt: h,
            energy_guard: None,
            ..Default::default()
        },
    );
    let tip: Vec<usize> = (0..scene.particles.len())
        .filter(|&i| (scene.particles[i].position[0] - length).abs() < 1e-9)
        .collect();
    let deflection = |sim: &Simulation<ParticleState, ParticleModel>| {
        -tip.iter()
            .map(|&i| sim.state.x[i].y as f64 - scene.particles[i].position[1])
            .sum::<f64>()
            / tip.len() as f64
    };
    let (mut frames, mut last) = (0, 0.0);
    for _ in 0..100 {
        sim.advance_frame().map_err(|d| d.to_string())?;
        frames += 1;
        let w = deflection(&sim);
        if (w - last).abs() < 1e-4 * w.abs() {
            break;
        }
        last = w;
    }
    Ok(Cantilever {
        tip: deflection(&sim),
        tets,
        frames,
        newton_iterations: sim.stats().newton_iterations,
    })
}
