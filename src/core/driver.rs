//! The headless driver of the PhysBAM slides: frames of length Δ, each advanced in substeps
//! of one size that land exactly on the frame's end (see [`equal_substep`]), with a divergence
//! guard that keeps the last good state and says what happened.

use crate::core::auto::{self, AutoChoice, AutoConfig};
use crate::core::integrate::{
    AdaptiveConfig, Integrator, IntegratorKind, IntegratorStats, SolverChoice, StepError,
};
use crate::core::ode::{OdeState, OdeSystem};
use crate::math::Scalar;
use serde::{Deserialize, Serialize};
use std::fmt;

/// How the substep size is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum StepPolicy {
    /// A fixed step `h` (the largest step for adaptive methods).
    Fixed {
        /// Step size (s).
        h: f64,
    },
    /// `h = number × (spring time scale)`, capped by `max`; the time scale is the smallest
    /// over springs of the bounds `limit` names.
    Cfl {
        /// CFL number (0.5 in the PhysBAM slides).
        number: f64,
        /// Upper bound on the step (s).
        max: f64,
        /// Which per-spring bounds.
        #[serde(default)]
        limit: CflLimit,
    },
}

/// Per-spring time bounds a CFL step policy takes the minimum of. `μ` is the reduced mass of
/// the spring's two free ends, `l₀` its rest length, `k` its Hooke stiffness (N/m) and `b` its
/// damper (N·s/m, the force `−b (n·v_rel) n` of the slides). A strain-law spring of "Young's
/// modulus" `E` (N), as in the PhysBAM slides, has `k = E/l₀`, so the slides' `b·l₀/E` is
/// `b/k`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CflLimit {
    /// `√(μ/k)` and `μ/b`: one spring's oscillation time (`1/ω`) and damping time — the
    /// explicit methods' limits up to their stability constants.
    #[default]
    Oscillation,
    /// The PhysBAM slides' `Maximum_Dt`, literally: `μ·l₀/b` (damping) and `b·l₀/E = b/k`
    /// (elastic). The damping term is the explicit damping limit `μ/b` times `l₀` in metres —
    /// not a time unless `l₀` is read as 1 — so it is more cautious than `μ/b` for springs
    /// shorter than a metre, as in the slides' wire (`l₀ = 0.1`).
    PhysBam,
    /// The slides' later form: `μ·l₀/b` and `2b/k` — the elastic term is exactly the stability
    /// limit of the implicit-damping trapezoid on one overdamped spring (characteristic
    /// polynomial `λ² − (1 − a)λ + a` with `a = hk/2b`, stable while `a < 1`).
    ///
    /// In both PhysBAM forms, springs without a damper use `√(μ/k)` for the elastic term.
    PhysBamLater,
}

impl Default for StepPolicy {
    fn default() -> Self {
        StepPolicy::Fixed { h: 1e-3 }
    }
}

/// Why a simulation stopped.
#[derive(Clone, Debug, PartialEq)]
pub enum DivergenceReason {
    /// A position or velocity became NaN or infinite.
    NonFinite,
    /// Internal energy (elastic plus kinetic relative to the centre of mass) exceeded the
    /// guard's bound.
    EnergyBlowup {
        /// Energy reached.
        energy: f64,
        /// The bound.
        bound: f64,
    },
    /// The integrator could not take a step.
    Step(StepError),
}

/// A detected divergence. The state and time were restored to the start of the failing frame:
/// the last state the driver delivered (and a renderer showed), which passed every check.
#[derive(Clone, Debug, PartialEq)]
pub struct Divergence {
    /// Frame being computed.
    pub frame: u64,
    /// Time at the start of the failing step.
    pub time: f64,
    /// Step size of the failing step.
    pub h: f64,
    /// Method in use.
    pub integrator: IntegratorKind,
    /// What happened.
    pub reason: DivergenceReason,
}

impl fmt::Display for Divergence {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = match &self.reason {
            DivergenceReason::NonFinite => "the state became non-finite".to_string(),
            DivergenceReason::EnergyBlowup { energy, bound } => {
                format!("internal energy {energy:.3e} J exceeded the bound {bound:.3e} J")
            }
            DivergenceReason::Step(e) => e.to_string(),
        };
        let advice = match self.integrator {
            IntegratorKind::ForwardEuler | IntegratorKind::Trapezoid | IntegratorKind::Midpoint => {
                "a smaller h, more damping, or a more stable method (symplectic Euler, RK4 or linearly implicit Euler)"
            }
            IntegratorKind::ImplicitDampingTrapezoid => {
                "a smaller h (below the elastic limit 2b/k of the stiffest spring) or linearly implicit Euler"
            }
            IntegratorKind::LinearlyImplicitEuler => {
                "a smaller h, backward Euler (Newton), or check the scene for invalid or extreme parameters"
            }
            IntegratorKind::BackwardEuler => {
                "check the scene for free particles without mass, negative stiffness or non-finite values"
            }
            _ => "a smaller h, more damping, or an implicit method (linearly implicit Euler)",
        };
        write!(
            f,
            "{} diverged at frame {}, t = {:.6} s (h = {:.3e} s): {what}; kept the last good state. Try {advice}",
            self.integrator.label(),
            self.frame,
            self.time,
            self.h
        )
    }
}

impl std::error::Error for Divergence {}

/// What one frame cost.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameReport {
    /// Substeps taken.
    pub substeps: u32,
    /// Smallest and largest substep.
    pub h_min: Scalar,
    /// Largest substep.
    pub h_max: Scalar,
}

/// Settings of a [`Simulation`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DriverConfig {
    /// Which method.
    pub integrator: IntegratorKind,
    /// How substeps are sized.
    pub policy: StepPolicy,
    /// Frame length Δ (s).
    pub frame_dt: f64,
    /// Tolerances of adaptive methods.
    pub adaptive: AdaptiveConfig,
    /// Stop when the system's guard energy (for particles: elastic plus kinetic relative to
    /// the centre of mass) exceeds this multiple of its energy scale (`None`: only non-finite
    /// states stop a run). A physical motion stays within a few times the scale; 100 catches
    /// an explicit method's blow-up within a step or two.
    pub energy_guard: Option<f64>,
    /// Linear solver of the implicit methods.
    #[serde(default)]
    pub solver: SolverChoice,
    /// What [`IntegratorKind::Auto`] aims for (ignored by the other methods).
    #[serde(default)]
    pub auto: AutoConfig,
}

impl DriverConfig {
    /// Checks the numbers a run needs (a positive step or CFL number and cap, a positive frame
    /// length, guard and tolerances); the first problem as a sentence.
    pub fn validate(&self) -> Result<(), String> {
        let positive = |x: f64| x.is_finite() && x > 0.0;
        match self.policy {
            StepPolicy::Fixed { h } if !positive(h) => {
                return Err(format!("step h = {h} must be a positive number"));
            }
            StepPolicy::Cfl { number, max, .. } if !(positive(number) && positive(max)) => {
                return Err(format!(
                    "CFL number {number} and cap {max} must be positive numbers"
                ));
            }
            _ => {}
        }
        if !positive(self.frame_dt) {
            return Err(format!(
                "frame length {} must be a positive number",
                self.frame_dt
            ));
        }
        if let Some(g) = self.energy_guard
            && !positive(g)
        {
            return Err(format!("energy guard {g} must be a positive number"));
        }
        if let Err((field, message)) = self.auto.validate() {
            return Err(format!("auto {field} {message}"));
        }
        let a = &self.adaptive;
        if !(positive(a.rtol) && positive(a.atol) && positive(a.h_min) && positive(a.safety)) {
            return Err(format!(
                "adaptive tolerances (rtol {}, atol {}, h_min {}, safety {}) must be positive numbers",
                a.rtol, a.atol, a.h_min, a.safety
            ));
        }
        Ok(())
    }
}

impl Default for DriverConfig {
    fn default() -> Self {
        Self {
            integrator: IntegratorKind::Rk4,
            policy: StepPolicy::default(),
            frame_dt: 1.0 / 60.0,
            adaptive: AdaptiveConfig::default(),
            energy_guard: Some(100.0),
            solver: SolverChoice::Auto,
            auto: AutoConfig::default(),
        }
    }
}

/// When a body at rest stops stepping: once every free part has stayed slower than `speed`
/// for `time` under steady forces ([`OdeSystem::rest_speed`]; a frame's speed is how far a part
/// went from the frame's start to its end, over the frame's length: the motion its frames
/// show), its frames cost nothing until
/// something wakes it — a frame at whose start the forces are no longer steady (a collider
/// near it moves, a pin's path moves, a gust or a field that changes with time), or
/// [`Simulation::wake`] (an edit). A body that wakes must stay still for `time` again before
/// it sleeps, so one woken every frame never flickers; while it sleeps its state does not
/// change, so its own jitter cannot wake it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SleepParams {
    /// Speed (m/s) every free particle must stay below: how far it goes in a frame, over the
    /// frame's length.
    pub speed: f64,
    /// How long (s) it must stay below it.
    pub time: f64,
}

impl Default for SleepParams {
    /// 1 cm/s for half a second: a cloth that moves less than a millimetre per tenth of a
    /// second is still to the eye, and avian's bodies wait the same half second.
    fn default() -> Self {
        Self {
            speed: 0.01,
            time: 0.5,
        }
    }
}

impl SleepParams {
    /// Checks the numbers: `Err((field, message))`.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if !(self.speed.is_finite() && self.speed >= 0.0) {
            return Err((
                "speed",
                format!("must be finite and non-negative (m/s), got {}", self.speed),
            ));
        }
        if !(self.time.is_finite() && self.time >= 0.0) {
            return Err((
                "time",
                format!("must be finite and non-negative (s), got {}", self.time),
            ));
        }
        Ok(())
    }
}

/// The substep for a frame of length `frame` under a policy's step `h`: the frame in
/// `n = ⌈frame/h − 0.001⌉` substeps of one size `frame / n` — as many as the slides' rule takes
/// (steps of `h` while more than `1.001 h` remain, then the rest), so at most `1.001 h` — and
/// `h` itself when that is `frame / n` to round-off, so frames of whole steps take exactly the
/// policy's step.
///
/// Substeps of `h` and one short remainder (the slides' `min(dt_max, 1.001 (t_frame − t))` on
/// its own) make each frame's map a product of two different steps' maps. Near symplectic
/// Euler's stability bound each is stable and their product need not be: a step of `h` has
/// the oscillator map `[[1 − (hω)², h], [−hω², 1]]` (`x` and `v`, `|trace| < 2` while
/// `hω < 2`), and the remainder every `n` steps pumps the stiffest mode. The bench box of 5000
/// tets diverged at `h` = 4·10⁻⁴ and 3.5·10⁻⁴ s in frames of 1/60 s, yet ran at the larger
/// 1/2400 s that divides them.
pub fn equal_substep(frame: f64, h: Scalar) -> Scalar {
    let h64 = h as f64;
    if !(frame > 0.0 && h64 > 0.0 && frame.is_finite() && h64.is_finite()) {
        return h;
    }
    let n = (frame / h64 - 0.001).ceil().max(1.0);
    let equal = frame / n;
    if (equal - h64).abs() <= 1e-6 * h64 {
        h
    } else {
        equal as Scalar
    }
}

/// The divergence guard's energy check runs every this many substeps (and on each frame's
/// last substep).
pub const GUARD_EVERY: u32 = 64;

/// A system, its state and a method, advanced frame by frame.
pub struct Simulation<S: OdeState, Sys: OdeSystem<S>> {
    /// The layout.
    pub system: Sys,
    /// The current state.
    pub state: S,
    /// Current time (s).
    pub time: Scalar,
    /// Frames completed.
    pub frame: u64,
    config: DriverConfig,
    integrator: Box<dyn Integrator<S, Sys>>,
    backup: S,
    energy_bound: Option<Scalar>,
    /// The time in f64: frame ends and substep lengths are computed from it, so frames stay
    /// exactly `frame_dt` long however late (an f32 clock at 10⁴ s resolves only 1 ms).
    time64: f64,
    /// Sleeping (`None`: never).
    sleep: Option<SleepParams>,
    /// How long the body has been still (s).
    still_for: f64,
    asleep: bool,
    /// [`IntegratorKind::Auto`]'s current choice (`None`: decide at the next frame's start).
    auto: Option<AutoChoice>,
    /// Multiplies the fastest mode's frequency in Auto's stability probe: doubled after each
    /// divergence of a choice (at most three times), so the frame is retried more cautiously.
    auto_margin: f64,
    /// Methods that diverged on this body under Auto: left out of its later choices (a
    /// nonlinear blow-up the test equation does not show).
    auto_excluded: Vec<IntegratorKind>,
}

/// How many times Auto retries a diverging frame with a more cautious choice.
const AUTO_RETRIES: u32 = 3;

impl<S: OdeState, Sys: OdeSystem<S>> Simulation<S, Sys> {
    /// A simulation starting at time 0.
    pub fn new(system: Sys, mut state: S, config: DriverConfig) -> Self {
        system.apply_constraints(0.0, &mut state);
        let integrator = Self::build_integrator(&system, &config);
        let energy_bound = config
            .energy_guard
            .and_then(|f| system.energy_scale(&state).map(|s| s * f as Scalar));
        let backup = state.clone();
        Self {
            system,
            state,
            time: 0.0,
            frame: 0,
            config,
            integrator,
            backup,
            energy_bound,
            time64: 0.0,
            sleep: None,
            still_for: 0.0,
            asleep: false,
            auto: None,
            auto_margin: 1.0,
            auto_excluded: Vec::new(),
        }
    }

    /// Lets the body sleep when at rest ([`SleepParams`]; `None`, the default: never). Bad
    /// numbers (see [`SleepParams::validate`]) count as `None`.
    pub fn set_sleep(&mut self, sleep: Option<SleepParams>) {
        let sleep = sleep.filter(|p| p.validate().is_ok());
        if sleep.is_none() {
            self.wake();
        }
        self.sleep = sleep;
    }

    /// The sleep settings.
    pub fn sleep(&self) -> Option<SleepParams> {
        self.sleep
    }

    /// True while the body sleeps: its frames take no step.
    pub fn is_asleep(&self) -> bool {
        self.asleep
    }

    /// Wakes the body (it steps from the next frame on, and must be still for the sleep
    /// time again before it sleeps).
    pub fn wake(&mut self) {
        self.asleep = false;
        self.still_for = 0.0;
    }

    /// Below the sleep speed under steady forces at `t`, over the frame from `start` to the
    /// state now (from the state to itself: the forces' steadiness alone).
    fn at_rest(&self, t: Scalar, start: &S) -> bool {
        let dt = self.config.frame_dt as Scalar;
        match (
            self.sleep,
            self.system.rest_speed(t, start, &self.state, dt),
        ) {
            (Some(p), Some(s)) => (s as f64) < p.speed,
            _ => false,
        }
    }

    /// Replaces the model and state with ones of a changed layout (a tear adds particles and
    /// removes springs), keeping the clock, the frame count, the settings and the energy
    /// guard's bound; the integrator starts afresh (its history belongs to the old layout).
    pub fn replace(&mut self, system: Sys, mut state: S) {
        self.wake();
        self.auto = None;
        system.apply_constraints(self.time, &mut state);
        self.integrator = Self::build_integrator(&system, &self.config);
        self.backup = state.clone();
        self.system = system;
        self.state = state;
    }

    /// The settings.
    pub fn config(&self) -> &DriverConfig {
        &self.config
    }

    /// Switches method (the step-size policy and state are kept).
    pub fn set_integrator(&mut self, kind: IntegratorKind) {
        self.config.integrator = kind;
        self.auto = None;
        self.auto_margin = 1.0;
        self.auto_excluded.clear();
        self.integrator = Self::build_integrator(&self.system, &self.config);
    }

    /// Sets what [`IntegratorKind::Auto`] aims for; it decides again at the next frame.
    pub fn set_auto(&mut self, auto: AutoConfig) {
        self.config.auto = auto;
        self.auto = None;
    }

    /// [`IntegratorKind::Auto`]'s choice in force (`None` before the first frame, or with
    /// another method).
    pub fn auto_choice(&self) -> Option<&AutoChoice> {
        self.auto.as_ref()
    }

    /// Makes [`IntegratorKind::Auto`] decide again at the next frame's start — after an edit
    /// of the model's stiffness, masses or topology made through [`Simulation::system`]
    /// directly ([`Simulation::replace`] and the plugin's rebuilds do this themselves).
    pub fn redecide(&mut self) {
        self.auto = None;
    }

    /// The method stepping now: the configured one, or Auto's choice.
    pub fn method(&self) -> IntegratorKind {
        self.integrator.kind()
    }

    /// Auto's decision from the body's spectrum (a system without one, not a particle model,
    /// gets RK4 at the step policy's `h`), and the integrator for it.
    fn decide_auto(&mut self) {
        let frame_dt = self.config.frame_dt;
        let direct = match self.config.solver {
            SolverChoice::Auto => self.system.prefers_direct_solver(),
            SolverChoice::Pcg => false,
            SolverChoice::Cholesky => true,
        };
        let choice = match (self.system.linearization(), self.state.as_particles_mut()) {
            (Some(lin), Some(state)) => auto::decide_for(
                lin,
                state,
                frame_dt,
                &self.config.auto,
                self.auto_margin,
                direct,
                &self.auto_excluded,
            ),
            _ => {
                let h = match self.config.policy {
                    StepPolicy::Fixed { h } => h,
                    StepPolicy::Cfl { max, .. } => max,
                };
                let substeps = (frame_dt / h - 1e-9).ceil().max(1.0) as u32;
                AutoChoice {
                    kind: IntegratorKind::Rk4,
                    substeps,
                    h: frame_dt / substeps as f64,
                    mode: crate::core::study::FastestMode {
                        omega: 0.0,
                        damping: 0.0,
                    },
                    omega_accuracy: 0.0,
                    energy_error: 0.0,
                    cost_ms: 0.0,
                    meets_tolerance: true,
                    candidates: Vec::new(),
                    reason: format!(
                        "RK4, {substeps} substeps: not a particle model, so no spectrum to choose from; the step policy's h"
                    ),
                }
            }
        };
        let mut config = self.config;
        config.integrator = choice.kind;
        self.integrator = Self::build_integrator(&self.system, &config);
        self.auto = Some(choice);
    }

    /// Sets the linear solver of implicit methods (restarts the integrator).
    pub fn set_solver(&mut self, solver: SolverChoice) {
        self.config.solver = solver;
        self.integrator = Self::build_integrator(&self.system, &self.config);
    }

    fn build_integrator(system: &Sys, config: &DriverConfig) -> Box<dyn Integrator<S, Sys>> {
        let direct = match config.solver {
            SolverChoice::Auto => system.prefers_direct_solver(),
            SolverChoice::Pcg => false,
            SolverChoice::Cholesky => true,
        };
        config
            .integrator
            .build_with::<S, Sys>(config.adaptive, direct)
    }

    /// Counters of the current integrator.
    pub fn stats(&self) -> IntegratorStats {
        self.integrator.stats()
    }

    /// The step size the policy gives now.
    pub fn step_size(&self) -> Scalar {
        if let Some(choice) = self.auto.as_ref() {
            return (self.config.frame_dt / choice.substeps as f64) as Scalar;
        }
        match self.config.policy {
            StepPolicy::Fixed { h } => h as Scalar,
            StepPolicy::Cfl { number, max, limit } => {
                let ts = self
                    .system
                    .cfl_time_scale(limit)
                    .unwrap_or(Scalar::INFINITY);
                (number as Scalar * ts).min(max as Scalar)
            }
        }
    }

    /// End time of frame `k` (computed from the frame index, so time never drifts).
    fn frame_end(&self, k: u64) -> f64 {
        k as f64 * self.config.frame_dt
    }

    /// Advances one frame in substeps of one size ([`equal_substep`]) that land exactly on its
    /// end. Under
    /// [`IntegratorKind::Auto`], the choice is made at the frame's start when there is none,
    /// and a frame that diverges is retried (from the same start) with a more cautious one
    /// (the stability probe's frequency doubled, and an implicit method that blew up left out
    /// from then on), at most three times.
    pub fn advance_frame(&mut self) -> Result<FrameReport, Divergence> {
        if self.config.integrator != IntegratorKind::Auto {
            return self.advance_frame_once();
        }
        let mut retries = 0;
        loop {
            if self.auto.is_none() && !self.asleep {
                self.decide_auto();
            }
            match self.advance_frame_once() {
                Err(d)
                    if retries < AUTO_RETRIES
                        && !matches!(
                            d.reason,
                            DivergenceReason::Step(StepError::BadStepSize(_))
                        ) =>
                {
                    retries += 1;
                    self.auto_margin *= 2.0;
                    // A method that blew up here is not chosen again for this body (explicit
                    // ones get the wider margin instead: more substeps may hold them).
                    if d.integrator.is_implicit() && !self.auto_excluded.contains(&d.integrator) {
                        self.auto_excluded.push(d.integrator);
                    }
                    self.auto = None;
                }
                other => return other,
            }
        }
    }

    fn advance_frame_once(&mut self) -> Result<FrameReport, Divergence> {
        let t_end = self.frame_end(self.frame + 1);
        if self.time != self.time64 as Scalar {
            // Someone set `time`: follow it.
            self.time64 = self.time as f64;
        }
        if self.asleep {
            if self.at_rest(self.time, &self.state) {
                // Nothing moves it: the frame passes without a step.
                self.time64 = t_end;
                self.time = t_end as Scalar;
                self.frame += 1;
                return Ok(FrameReport::default());
            }
            self.wake();
        }
        // The last good state is the one delivered at the end of the previous frame: substeps
        // of a diverging frame may already be far from it while still finite.
        let t_start = self.time64;
        self.backup.copy_from(&self.state);
        self.system.begin_frame(&self.state);
        let h_pol = equal_substep(t_end - t_start, self.step_size());
        let mut rep = FrameReport {
            substeps: 0,
            h_min: Scalar::INFINITY,
            h_max: 0.0,
        };
        while self.time64 < t_end {
            let remaining = t_end - self.time64;
            // Within 0.1 % of the end: take the remainder rather than leave a sliver (the
            // slides' `min(dt_max, 1.001 (t_frame − t))`, landing exactly). With the equal
            // substeps of `equal_substep` the remainder is one of them, to round-off.
            let (h, last) = if remaining <= h_pol as f64 * 1.001 {
                (remaining as Scalar, true)
            } else {
                (h_pol, false)
            };
            let t = self.time64 as Scalar;
            self.system.apply_constraints(t, &mut self.state);
            let kind = self.integrator.kind();
            let fail = |reason, h| Divergence {
                frame: self.frame,
                time: t as f64,
                h: h as f64,
                integrator: kind,
                reason,
            };
            let taken = match self.integrator.step(&self.system, t, h, &mut self.state) {
                Ok(taken) => taken,
                Err(e) => {
                    self.state.copy_from(&self.backup);
                    self.time64 = t_start;
                    self.time = t_start as Scalar;
                    return Err(fail(DivergenceReason::Step(e), h));
                }
            };
            let t_new64 = if last && taken >= h {
                t_end
            } else {
                self.time64 + taken as f64
            };
            let t_new = t_new64 as Scalar;
            self.system.apply_constraints(t_new, &mut self.state);
            self.system.resolve_contacts(t_new, taken, &mut self.state);
            if !self.system.stepped_state_is_finite(&self.state) {
                self.state.copy_from(&self.backup);
                self.time64 = t_start;
                self.time = t_start as Scalar;
                return Err(fail(DivergenceReason::NonFinite, taken));
            }
            // The energy check costs about as much as a force evaluation: it runs every
            // `GUARD_EVERY` substeps and on the frame's last, so every delivered state has
            // passed it (a blow-up between checks turns the state non-finite first, caught
            // above, or is caught at the next check; either way the frame is refused).
            let check = t_new64 >= t_end || (rep.substeps + 1).is_multiple_of(GUARD_EVERY);
            if let Some(bound) = self.energy_bound.filter(|_| check) {
                let k = self.system.guard_energy(&self.state);
                if k.is_nan() || k > bound {
                    self.state.copy_from(&self.backup);
                    self.time64 = t_start;
                    self.time = t_start as Scalar;
                    return Err(fail(
                        DivergenceReason::EnergyBlowup {
                            energy: k as f64,
                            bound: bound as f64,
                        },
                        taken,
                    ));
                }
            }
            self.time64 = t_new64;
            self.time = t_new;
            rep.substeps += 1;
            rep.h_min = rep.h_min.min(taken);
            rep.h_max = rep.h_max.max(taken);
        }
        // Frame-level contact (self-collision): what must hold in every delivered state.
        self.system.end_frame(t_end as Scalar, &mut self.state);
        if !self.state.is_finite() {
            self.state.copy_from(&self.backup);
            let t = self.time64 as Scalar;
            self.time64 = t_start;
            self.time = t_start as Scalar;
            return Err(Divergence {
                frame: self.frame,
                time: t as f64,
                h: rep.h_max as f64,
                integrator: self.integrator.kind(),
                reason: DivergenceReason::NonFinite,
            });
        }
        self.frame += 1;
        if let Some(p) = self.sleep {
            // `backup` is the frame's start.
            if self.at_rest(self.time, &self.backup) {
                self.still_for += self.config.frame_dt;
                // Within round-off of the time: a whole number of frames reaches it.
                self.asleep = self.still_for >= p.time - 1e-9 * self.config.frame_dt;
            } else {
                self.still_for = 0.0;
            }
        }
        Ok(rep)
    }

    /// Advances `frames` frames, calling `on_frame` after each.
    pub fn run(
        &mut self,
        frames: u64,
        mut on_frame: impl FnMut(&Self, &FrameReport),
    ) -> Result<(), Divergence> {
        for _ in 0..frames {
            let rep = self.advance_frame()?;
            on_frame(self, &rep);
        }
        Ok(())
    }

    /// Advances until `time` (rounded up to whole frames).
    pub fn run_until(&mut self, time: f64) -> Result<(), Divergence> {
        let frames = ((time - self.time as f64) / self.config.frame_dt - 1e-9)
            .ceil()
            .max(0.0) as u64;
        self.run(frames, |_, _| {})
    }
}
