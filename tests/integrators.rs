//! Integrators against theory: exact amplification factors on the circle system, measured
//! convergence orders on the circle and on an undamped harmonic oscillator, RK45's error
//! following its tolerance.
//!
//! Orders are measured in f64 (`cargo test --features f64`); the f32 build runs the same
//! tests on larger steps so that truncation error stays well above f32 round-off (≈1e-7
//! relative), with the same ±0.15 order band.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::integrate::{AdaptiveConfig, Integrator};
use bevy_soft_body::core::ode::{CircleSystem, FnSystem, OdeState, OdeSystem, ParticleState};
use bevy_soft_body::prelude::*;

const F64: bool = cfg!(feature = "f64");

fn integrate<S: OdeState, Sys: OdeSystem<S>>(
    kind: IntegratorKind,
    sys: &Sys,
    x0: &S,
    h: f64,
    n: usize,
) -> S {
    let mut integ: Box<dyn Integrator<S, Sys>> = kind.build(AdaptiveConfig::default());
    let mut x = x0.clone();
    let mut t: Scalar = 0.0;
    for _ in 0..n {
        let taken = integ.step(sys, t, h as Scalar, &mut x).unwrap();
        assert_eq!(taken, h as Scalar);
        t += taken;
    }
    x
}

/// Least-squares slope of log(err) against log(h).
fn slope(h: &[f64], e: &[f64]) -> f64 {
    let lx: Vec<f64> = h.iter().map(|v| v.ln()).collect();
    let ly: Vec<f64> = e.iter().map(|v| v.ln()).collect();
    let n = lx.len() as f64;
    let mx = lx.iter().sum::<f64>() / n;
    let my = ly.iter().sum::<f64>() / n;
    let sxy: f64 = lx.iter().zip(&ly).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = lx.iter().map(|x| (x - mx).powi(2)).sum();
    sxy / sxx
}

fn radius(v: Vector) -> f64 {
    (v.x as f64).hypot(v.y as f64)
}

#[test]
fn forward_euler_radius_grows_exactly_as_sqrt_1_plus_h2_per_step() {
    // One Euler step multiplies x + iy by (1 + i h), whose modulus is √(1 + h²).
    let x0 = Vector::new(1.0, 0.0, 0.0);
    for (h, n) in [(0.1, 50), (0.01, 628), (0.3, 20)] {
        let x = integrate(IntegratorKind::ForwardEuler, &CircleSystem, &x0, h, n);
        let expected = (1.0 + h * h).powf(n as f64 / 2.0);
        // Round-off: n steps of a few ulps each.
        let tol = if F64 { 1e-12 } else { 2e-6 } * n as f64;
        assert!(
            (radius(x) - expected).abs() <= tol * expected,
            "h={h}: radius {} vs {expected}",
            radius(x)
        );
        assert!(radius(x) > 1.0, "Euler spirals outward");
    }
}

#[test]
fn trapezoid_radius_grows_slower_as_its_amplification_factor_predicts() {
    // Heun on z' = i z: R(ih) = 1 + ih − h²/2, |R|² = 1 + h⁴/4.
    let x0 = Vector::new(1.0, 0.0, 0.0);
    for (h, n) in [(0.1, 50), (0.3, 40), (0.5, 30)] {
        let x = integrate(IntegratorKind::Trapezoid, &CircleSystem, &x0, h, n);
        let expected = (1.0 + h.powi(4) / 4.0).powf(n as f64 / 2.0);
        let tol = if F64 { 1e-12 } else { 2e-6 } * n as f64;
        assert!(
            (radius(x) - expected).abs() <= tol * expected,
            "h={h}: radius {} vs {expected}",
            radius(x)
        );
        let euler = integrate(IntegratorKind::ForwardEuler, &CircleSystem, &x0, h, n);
        assert!(
            radius(x) > 1.0 && radius(x) < radius(euler),
            "trapezoid grows, but slower than Euler"
        );
    }
}

#[test]
fn rk4_one_revolution_at_h_001() {
    // RK4's radius error per step on the circle is h⁶/144 (|R(ih)|² = 1 − h⁶/72 + h⁸/576);
    // over 2π/h steps that is ≈ 4.4e-11 at h = 0.01: far below 1e-8 in f64. In f32 the bound
    // is round-off, ≈ 628 steps × 1e-7.
    let n = 628;
    let h = std::f64::consts::TAU / n as f64;
    let x = integrate(
        IntegratorKind::Rk4,
        &CircleSystem,
        &Vector::new(1.0, 0.0, 0.0),
        h,
        n,
    );
    let err = (radius(x) - 1.0).abs();
    let bound = if F64 { 1e-8 } else { 1e-4 };
    assert!(err < bound, "radius error {err:e}");
    let pos_err = ((x.x as f64 - 1.0).powi(2) + (x.y as f64).powi(2)).sqrt();
    assert!(
        pos_err < if F64 { 1e-8 } else { 1e-4 },
        "position error after one revolution {pos_err:e}"
    );
}

fn circle_error(kind: IntegratorKind, h: f64, t_end: f64) -> f64 {
    let n = (t_end / h).round() as usize;
    let x0 = Vector::new(1.0, 0.0, 0.0);
    let x = integrate(kind, &CircleSystem, &x0, h, n);
    let exact = CircleSystem::exact(x0, (n as f64 * h) as Scalar);
    (x - exact).length() as f64
}

/// Step sizes for measuring order `p`: errors between ~1e-2 and well above round-off.
/// RK4's global error on these problems is ≈ T h⁴/120 and f32 round-off ≈ (T/h)·6e-8, so in
/// f32 it must be measured at h ≫ (7e-6)^(1/5) ≈ 0.09: steps 0.8 … 0.2 in ratios of √2.
fn sweep(order: u32) -> Vec<f64> {
    if order == 4 && !F64 {
        return (0..5).map(|k| 0.8 / 2f64.sqrt().powi(k)).collect();
    }
    let base = match (order, F64) {
        (1, true) => 0.01,
        (1, false) => 0.02,
        (2, true) => 0.02,
        (2, false) => 0.05,
        (_, true) => 0.1,
        (_, false) => 0.4,
    };
    (0..5).map(|k| base / 2f64.powi(k)).collect()
}

#[test]
fn convergence_orders_on_the_circle() {
    for kind in [
        IntegratorKind::ForwardEuler,
        IntegratorKind::Trapezoid,
        IntegratorKind::Midpoint,
        IntegratorKind::Rk4,
    ] {
        let hs = sweep(kind.order());
        let errs: Vec<f64> = hs.iter().map(|&h| circle_error(kind, h, 1.6)).collect();
        let p = slope(&hs, &errs);
        println!("{kind}: errors {errs:?} -> order {p:.3}");
        assert!(
            (p - kind.order() as f64).abs() <= 0.15,
            "{kind}: measured order {p:.3}, theory {}",
            kind.order()
        );
    }
}

/// Undamped oscillator x'' = −ω² x as a one-particle second-order state, with ω = 2.
fn oscillator() -> impl OdeSystem<ParticleState> {
    FnSystem(|_t: Scalar, s: &ParticleState, d: &mut ParticleState| {
        d.x[0] = s.v[0];
        d.v[0] = -4.0 * s.x[0];
    })
}

fn oscillator_error(kind: IntegratorKind, h: f64, t_end: f64) -> f64 {
    let n = (t_end / h).round() as usize;
    let t = n as f64 * h;
    let x0 = ParticleState {
        x: vec![Vector::new(1.0, 0.0, 0.0)],
        v: vec![Vector::ZERO],
    };
    let s = integrate(kind, &oscillator(), &x0, h, n);
    let (xe, ve) = ((2.0 * t).cos(), -2.0 * (2.0 * t).sin());
    ((s.x[0].x as f64 - xe).powi(2) + (s.v[0].x as f64 - ve).powi(2)).sqrt()
}

#[test]
fn convergence_orders_on_the_harmonic_oscillator() {
    for kind in [
        IntegratorKind::ForwardEuler,
        IntegratorKind::SymplecticEuler,
        IntegratorKind::Trapezoid,
        IntegratorKind::Midpoint,
        IntegratorKind::Rk4,
    ] {
        let hs: Vec<f64> = sweep(kind.order()).iter().map(|h| h / 2.0).collect();
        let errs: Vec<f64> = hs.iter().map(|&h| oscillator_error(kind, h, 1.0)).collect();
        let p = slope(&hs, &errs);
        println!("{kind}: errors {errs:?} -> order {p:.3}");
        assert!(
            (p - kind.order() as f64).abs() <= 0.15,
            "{kind}: measured order {p:.3}, theory {}",
            kind.order()
        );
    }
}

#[test]
fn symplectic_euler_refuses_first_order_states() {
    let mut integ: Box<dyn Integrator<Vector, CircleSystem>> =
        IntegratorKind::SymplecticEuler.build(AdaptiveConfig::default());
    let mut x = Vector::X;
    let r = integ.step(&CircleSystem, 0.0, 0.1, &mut x);
    assert_eq!(
        r,
        Err(StepError::NeedsSecondOrder(IntegratorKind::SymplecticEuler))
    );
    assert_eq!(x, Vector::X, "state unchanged on error");
}

#[test]
fn bad_step_sizes_are_errors_not_panics() {
    for h in [0.0, -1.0, Scalar::NAN, Scalar::INFINITY] {
        for kind in IntegratorKind::ALL {
            if kind == IntegratorKind::SymplecticEuler {
                continue;
            }
            let mut integ: Box<dyn Integrator<Vector, CircleSystem>> =
                kind.build(AdaptiveConfig::default());
            let mut x = Vector::X;
            assert!(
                matches!(
                    integ.step(&CircleSystem, 0.0, h, &mut x),
                    Err(StepError::BadStepSize(_))
                ),
                "{kind} h={h}"
            );
            assert_eq!(x, Vector::X);
        }
    }
}

/// Runs RK45 to `t_end` (steps capped to land on it) and returns the error and the counters.
fn rk45_circle(tol: f64, t_end: f64) -> (f64, bevy_soft_body::core::integrate::IntegratorStats) {
    let cfg = AdaptiveConfig {
        rtol: tol,
        atol: tol,
        ..Default::default()
    };
    let mut integ: Box<dyn Integrator<Vector, CircleSystem>> = IntegratorKind::Rk45.build(cfg);
    let x0 = Vector::new(1.0, 0.0, 0.0);
    let mut x = x0;
    let mut t: Scalar = 0.0;
    let te = t_end as Scalar;
    while t < te {
        let cap = te - t;
        let taken = integ.step(&CircleSystem, t, cap, &mut x).unwrap();
        t = if taken >= cap { te } else { t + taken };
    }
    assert_eq!(t, te, "lands exactly on the end time");
    (
        (x - CircleSystem::exact(x0, te)).length() as f64,
        integ.stats(),
    )
}

#[test]
fn rk45_error_follows_its_tolerance() {
    // A step-controlled method keeps the local error per step below tol, so the global error
    // over a fixed interval scales like tol (slope ≈ 1 in log-log; DOPRI5's local
    // extrapolation makes it slightly flatter), and stays within a modest multiple of tol.
    let tols: Vec<f64> = if F64 {
        vec![1e-4, 1e-6, 1e-8, 1e-10]
    } else {
        vec![1e-2, 1e-3, 1e-4, 1e-5]
    };
    let mut errs = Vec::new();
    let mut evals = Vec::new();
    for &tol in &tols {
        let (e, st) = rk45_circle(tol, 10.0);
        println!(
            "tol {tol:e}: error {e:e}, steps {}, rejected {}, evaluations {}",
            st.steps, st.rejected, st.evaluations
        );
        assert!(e < 50.0 * tol, "error {e:e} at tol {tol:e}");
        errs.push(e);
        evals.push(st.evaluations as f64);
    }
    let p = slope(&tols, &errs);
    println!("error ~ tol^{p:.3}");
    assert!((0.6..=1.3).contains(&p), "error-vs-tolerance slope {p}");
    // Work grows like tol^(-1/5) for a fifth-order method: tighter tolerance, more evaluations.
    assert!(evals.windows(2).all(|w| w[1] > w[0]));
}

#[test]
fn rk45_reuses_its_last_stage_fsal() {
    // With FSAL, each accepted step after the first costs 6 evaluations (7 stages, the last
    // reused); rejected steps cost 6 as well.
    let (_, st) = rk45_circle(if F64 { 1e-8 } else { 1e-4 }, 20.0);
    let expected = 6 * (st.steps + st.rejected) + 2; // + first k1 + the initial-step probe
    assert_eq!(st.evaluations, expected, "{st:?}");
}

#[test]
fn every_kind_parses_from_its_letter_and_name() {
    for kind in IntegratorKind::ALL {
        assert_eq!(
            kind.letter().to_string().parse::<IntegratorKind>(),
            Ok(kind)
        );
        assert_eq!(kind.name().parse::<IntegratorKind>(), Ok(kind));
    }
    let letters: std::collections::HashSet<char> =
        IntegratorKind::ALL.iter().map(|k| k.letter()).collect();
    assert_eq!(
        letters.len(),
        IntegratorKind::ALL.len(),
        "letters are unique"
    );
    assert!("z".parse::<IntegratorKind>().is_err());
    // EXPLICIT is ALL without the implicit kinds, in order.
    let explicit: Vec<IntegratorKind> = IntegratorKind::ALL
        .into_iter()
        .filter(|k| !k.is_implicit())
        .collect();
    assert_eq!(IntegratorKind::EXPLICIT.to_vec(), explicit);
    assert_eq!(IntegratorKind::EXPLICIT.len(), 6);
}
