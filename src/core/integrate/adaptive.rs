//! Adaptive Dormand–Prince 5(4) (the method of MATLAB's `ode45`) with FSAL, Hairer's scaled
//! error norm and a PI step-size controller (Hairer, Nørsett & Wanner, *Solving ODEs I*,
//! §II.4, code DOPRI5).

use super::{Integrator, IntegratorKind, IntegratorStats, StepError, check_h, scratch};
use crate::core::ode::{OdeState, OdeSystem};
use crate::math::Scalar;
use serde::{Deserialize, Serialize};

/// Tolerances and controller settings of the adaptive method.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct AdaptiveConfig {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance.
    pub atol: f64,
    /// Smallest step the controller may take before it reports failure.
    pub h_min: f64,
    /// Safety factor on the predicted step (0.9 in DOPRI5).
    pub safety: f64,
}

impl Default for AdaptiveConfig {
    fn default() -> Self {
        Self {
            rtol: 1e-4,
            atol: 1e-6,
            h_min: 1e-10,
            safety: 0.9,
        }
    }
}

// Butcher tableau of Dormand & Prince (1980).
const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const A71: f64 = 35.0 / 384.0;
const A73: f64 = 500.0 / 1113.0;
const A74: f64 = 125.0 / 192.0;
const A75: f64 = -2187.0 / 6784.0;
const A76: f64 = 11.0 / 84.0;
// Error coefficients: 5th-order weights minus the embedded 4th-order ones.
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;

/// PI controller exponents of DOPRI5: `β = 0.04`, `α = 1/5 − 0.75 β`.
const BETA: f64 = 0.04;
const EXPO1: f64 = 0.2 - BETA * 0.75;
/// Step change per step is kept within `[1/10, 5]`.
const FAC_MIN: f64 = 0.2;
const FAC_MAX: f64 = 10.0;

/// Dormand–Prince 5(4) with first-same-as-last and a PI step controller.
pub struct DormandPrince<S> {
    cfg: AdaptiveConfig,
    k: [Option<S>; 7],
    y: Option<S>,
    tmp: Option<S>,
    /// Where the cached `k1` (FSAL) was evaluated.
    last: Option<S>,
    last_t: Scalar,
    fsal: bool,
    h_est: Option<Scalar>,
    err_old: f64,
    stats: IntegratorStats,
}

impl<S> DormandPrince<S> {
    /// A fresh integrator with the given tolerances.
    pub fn new(cfg: AdaptiveConfig) -> Self {
        Self {
            cfg,
            k: [None, None, None, None, None, None, None],
            y: None,
            tmp: None,
            last: None,
            last_t: 0.0,
            fsal: false,
            h_est: None,
            err_old: 1e-4,
            stats: IntegratorStats::default(),
        }
    }

    /// The step size the controller proposes next, once it has taken a step.
    pub fn proposed_step(&self) -> Option<Scalar> {
        self.h_est
    }
}

impl<S: OdeState> DormandPrince<S> {
    fn ensure_scratch(&mut self, x: &S) {
        for k in self.k.iter_mut() {
            scratch(k, x);
        }
        scratch(&mut self.y, x);
        scratch(&mut self.tmp, x);
        scratch(&mut self.last, x);
    }
}

fn s(x: f64) -> Scalar {
    x as Scalar
}

impl<S: OdeState, Sys: OdeSystem<S> + ?Sized> Integrator<S, Sys> for DormandPrince<S> {
    fn kind(&self) -> IntegratorKind {
        IntegratorKind::Rk45
    }

    fn step(
        &mut self,
        sys: &Sys,
        t: Scalar,
        h_max: Scalar,
        x: &mut S,
    ) -> Result<Scalar, StepError> {
        check_h(h_max)?;
        self.ensure_scratch(x);
        let (atol, rtol) = (s(self.cfg.atol), s(self.cfg.rtol));
        let [k1, k2, k3, k4, k5, k6, k7] = &mut self.k;
        let (k1, k2, k3, k4, k5, k6, k7) = (
            k1.as_mut().unwrap(),
            k2.as_mut().unwrap(),
            k3.as_mut().unwrap(),
            k4.as_mut().unwrap(),
            k5.as_mut().unwrap(),
            k6.as_mut().unwrap(),
            k7.as_mut().unwrap(),
        );
        let y = self.y.as_mut().unwrap();
        let tmp = self.tmp.as_mut().unwrap();
        let last = self.last.as_mut().unwrap();

        // First same as last: k1 is the previous step's k7 if the state was not touched since.
        let same_t = (self.last_t - t).abs() <= 4.0 * crate::math::EPS * t.abs().max(1.0);
        if !(self.fsal && same_t && last.same_as(x)) {
            sys.derivative(t, x, k1);
            self.stats.evaluations += 1;
        }

        let mut h = match self.h_est {
            Some(h) => h.min(h_max),
            None => {
                // Hairer's starting step (HINIT), in the scaled norm.
                let d0 = S::error_norm(x, x, x, atol, rtol);
                let d1 = S::error_norm(k1, x, x, atol, rtol);
                let h0 = if d0 < 1e-5 || d1 < 1e-5 {
                    1e-6
                } else {
                    0.01 * d0 / d1
                };
                let h0 = h0.min(h_max);
                tmp.copy_from(x);
                tmp.axpy(h0, k1);
                sys.derivative(t + h0, tmp, k2);
                self.stats.evaluations += 1;
                k2.axpy(-1.0, k1);
                let d2 = S::error_norm(k2, x, x, atol, rtol) / h0;
                let dm = d1.max(d2);
                let h1 = if dm <= 1e-15 {
                    (h0 * 1e-3).max(1e-6)
                } else {
                    (0.01 / dm).powf(0.2)
                };
                (100.0 * h0).min(h1).min(h_max)
            }
        };

        loop {
            if h.is_nan() || h < s(self.cfg.h_min) {
                self.fsal = false;
                return Err(StepError::StepSizeUnderflow { h });
            }
            tmp.copy_from(x);
            tmp.axpy(h * s(A21), k1);
            sys.derivative(t + s(C2) * h, tmp, k2);

            tmp.copy_from(x);
            tmp.axpy(h * s(A31), k1);
            tmp.axpy(h * s(A32), k2);
            sys.derivative(t + s(C3) * h, tmp, k3);

            tmp.copy_from(x);
            tmp.axpy(h * s(A41), k1);
            tmp.axpy(h * s(A42), k2);
            tmp.axpy(h * s(A43), k3);
            sys.derivative(t + s(C4) * h, tmp, k4);

            tmp.copy_from(x);
            tmp.axpy(h * s(A51), k1);
            tmp.axpy(h * s(A52), k2);
            tmp.axpy(h * s(A53), k3);
            tmp.axpy(h * s(A54), k4);
            sys.derivative(t + s(C5) * h, tmp, k5);

            tmp.copy_from(x);
            tmp.axpy(h * s(A61), k1);
            tmp.axpy(h * s(A62), k2);
            tmp.axpy(h * s(A63), k3);
            tmp.axpy(h * s(A64), k4);
            tmp.axpy(h * s(A65), k5);
            sys.derivative(t + h, tmp, k6);

            y.copy_from(x);
            y.axpy(h * s(A71), k1);
            y.axpy(h * s(A73), k3);
            y.axpy(h * s(A74), k4);
            y.axpy(h * s(A75), k5);
            y.axpy(h * s(A76), k6);
            sys.derivative(t + h, y, k7);
            self.stats.evaluations += 6;

            // Error estimate h Σ e_i k_i.
            tmp.copy_from(k1);
            tmp.scale(h * s(E1));
            tmp.axpy(h * s(E3), k3);
            tmp.axpy(h * s(E4), k4);
            tmp.axpy(h * s(E5), k5);
            tmp.axpy(h * s(E6), k6);
            tmp.axpy(h * s(E7), k7);
            let err = S::error_norm(tmp, x, y, atol, rtol) as f64;

            let fac11 = err.powf(EXPO1);
            if err <= 1.0 {
                // Accept.
                let fac = (fac11 / self.err_old.powf(BETA) / self.cfg.safety)
                    .clamp(1.0 / FAC_MAX, 1.0 / FAC_MIN);
                let h_new = h / fac as Scalar;
                self.err_old = err.max(1e-4);
                let capped = self.h_est.is_some_and(|he| h < he);
                self.h_est = Some(if capped {
                    h_new.max(self.h_est.unwrap())
                } else {
                    h_new
                });
                x.copy_from(y);
                std::mem::swap(k1, k7);
                last.copy_from(x);
                self.last_t = t + h;
                self.fsal = true;
                self.stats.steps += 1;
                return Ok(h);
            }
            // Reject: shrink, never grow, after a rejection.
            self.stats.rejected += 1;
            let fac = if err.is_finite() {
                (fac11 / self.cfg.safety).min(1.0 / FAC_MIN)
            } else {
                10.0
            };
            h /= fac as Scalar;
            self.h_est = Some(h);
        }
    }

    fn stats(&self) -> IntegratorStats {
        self.stats
    }

    fn reset(&mut self) {
        self.fsal = false;
        self.h_est = None;
        self.err_old = 1e-4;
        self.stats = IntegratorStats::default();
    }
}
