//! Fixed-step explicit methods: forward Euler, symplectic Euler, trapezoid (Heun), midpoint
//! and classic RK4.

use super::{Integrator, IntegratorKind, IntegratorStats, StepError, check_h, scratch};
use crate::core::ode::{OdeState, OdeSystem};
use crate::math::Scalar;

/// `X ← X + h f(X, t)`. Order 1. Unstable for every undamped oscillation: on the circle system
/// the radius grows by `√(1 + h²)` per step.
pub struct ForwardEuler<S> {
    k: Option<S>,
    stats: IntegratorStats,
}

impl<S: OdeState, Sys: OdeSystem<S> + ?Sized> Integrator<S, Sys> for ForwardEuler<S> {
    fn kind(&self) -> IntegratorKind {
        IntegratorKind::ForwardEuler
    }
    fn step(&mut self, sys: &Sys, t: Scalar, h: Scalar, x: &mut S) -> Result<Scalar, StepError> {
        check_h(h)?;
        let k = scratch(&mut self.k, x);
        sys.derivative(t, x, k);
        x.axpy(h, k);
        self.stats.steps += 1;
        self.stats.evaluations += 1;
        Ok(h)
    }
    counters!();
}

/// Symplectic (semi-implicit) Euler for second-order systems: `v ← v + h a(x, v)`, then
/// `x ← x + h v_new`. Order 1, but symplectic: on undamped oscillators its energy error stays
/// bounded (it exactly conserves a modified energy) and it is stable for `h ω < 2`.
pub struct SymplecticEuler<S> {
    k: Option<S>,
    stats: IntegratorStats,
}

impl<S: OdeState, Sys: OdeSystem<S> + ?Sized> Integrator<S, Sys> for SymplecticEuler<S> {
    fn kind(&self) -> IntegratorKind {
        IntegratorKind::SymplecticEuler
    }
    fn step(&mut self, sys: &Sys, t: Scalar, h: Scalar, x: &mut S) -> Result<Scalar, StepError> {
        check_h(h)?;
        if !x.is_second_order() {
            return Err(StepError::NeedsSecondOrder(IntegratorKind::SymplecticEuler));
        }
        let k = scratch(&mut self.k, x);
        if !sys.symplectic_euler(t, h, x, k) {
            sys.derivative(t, x, k);
            x.kick_drift(k, h);
        }
        self.stats.steps += 1;
        self.stats.evaluations += 1;
        Ok(h)
    }
    counters!();
}

/// Explicit trapezoid (Heun): `f0 = f(X, t)`, `f1 = f(X + h f0, t + h)`,
/// `X ← X + h/2 (f0 + f1)`. Order 2; amplification `1 + z + z²/2`.
pub struct Trapezoid<S> {
    f0: Option<S>,
    f1: Option<S>,
    tmp: Option<S>,
    stats: IntegratorStats,
}

impl<S: OdeState, Sys: OdeSystem<S> + ?Sized> Integrator<S, Sys> for Trapezoid<S> {
    fn kind(&self) -> IntegratorKind {
        IntegratorKind::Trapezoid
    }
    fn step(&mut self, sys: &Sys, t: Scalar, h: Scalar, x: &mut S) -> Result<Scalar, StepError> {
        check_h(h)?;
        let f0 = scratch(&mut self.f0, x);
        let f1 = scratch(&mut self.f1, x);
        let tmp = scratch(&mut self.tmp, x);
        sys.derivative(t, x, f0);
        tmp.copy_from(x);
        tmp.axpy(h, f0);
        sys.derivative(t + h, tmp, f1);
        x.axpy(0.5 * h, f0);
        x.axpy(0.5 * h, f1);
        self.stats.steps += 1;
        self.stats.evaluations += 2;
        Ok(h)
    }
    counters!();
}

/// Explicit midpoint: `X ← X + h f(X + h/2 f(X, t), t + h/2)`. Order 2.
pub struct Midpoint<S> {
    k: Option<S>,
    tmp: Option<S>,
    stats: IntegratorStats,
}

impl<S: OdeState, Sys: OdeSystem<S> + ?Sized> Integrator<S, Sys> for Midpoint<S> {
    fn kind(&self) -> IntegratorKind {
        IntegratorKind::Midpoint
    }
    fn step(&mut self, sys: &Sys, t: Scalar, h: Scalar, x: &mut S) -> Result<Scalar, StepError> {
        check_h(h)?;
        let k = scratch(&mut self.k, x);
        let tmp = scratch(&mut self.tmp, x);
        sys.derivative(t, x, k);
        tmp.copy_from(x);
        tmp.axpy(0.5 * h, k);
        sys.derivative(t + 0.5 * h, tmp, k);
        x.axpy(h, k);
        self.stats.steps += 1;
        self.stats.evaluations += 2;
        Ok(h)
    }
    counters!();
}

/// Classic fourth-order Runge–Kutta. Stable on the imaginary axis up to `|h ω| ≤ 2√2`.
pub struct Rk4<S> {
    k: Option<S>,
    acc: Option<S>,
    tmp: Option<S>,
    stats: IntegratorStats,
}

impl<S: OdeState, Sys: OdeSystem<S> + ?Sized> Integrator<S, Sys> for Rk4<S> {
    fn kind(&self) -> IntegratorKind {
        IntegratorKind::Rk4
    }
    fn step(&mut self, sys: &Sys, t: Scalar, h: Scalar, x: &mut S) -> Result<Scalar, StepError> {
        check_h(h)?;
        let k = scratch(&mut self.k, x);
        let acc = scratch(&mut self.acc, x);
        let tmp = scratch(&mut self.tmp, x);
        // k1
        sys.derivative(t, x, k);
        acc.copy_from(k);
        tmp.copy_from(x);
        tmp.axpy(0.5 * h, k);
        // k2
        sys.derivative(t + 0.5 * h, tmp, k);
        acc.axpy(2.0, k);
        tmp.copy_from(x);
        tmp.axpy(0.5 * h, k);
        // k3
        sys.derivative(t + 0.5 * h, tmp, k);
        acc.axpy(2.0, k);
        tmp.copy_from(x);
        tmp.axpy(h, k);
        // k4
        sys.derivative(t + h, tmp, k);
        acc.add(k);
        x.axpy(h / 6.0, acc);
        self.stats.steps += 1;
        self.stats.evaluations += 4;
        Ok(h)
    }
    counters!();
}

macro_rules! scratch_default {
    ($($t:ident { $($f:ident),* }),*) => {$(
        impl<S> Default for $t<S> {
            fn default() -> Self {
                Self { $($f: None,)* stats: IntegratorStats::default() }
            }
        }
    )*};
}

scratch_default!(
    ForwardEuler { k },
    SymplecticEuler { k },
    Trapezoid { f0, f1, tmp },
    Midpoint { k, tmp },
    Rk4 { k, acc, tmp }
);
