//! The stability study's quick map (what `stability --quick` prints): on a spring chain, an
//! 8×8 cloth and a 4×4×4 jelly, the largest stable step of symplectic Euler and RK4 found by
//! bisection (1 % precision, 1 s, energy never above E₀ + 0.1 × scale) must agree within 10 %
//! with the linear stability bound of the fastest mode of M⁻¹K (power iteration) with its
//! modal damping; linearly implicit and backward Euler must be stable at the largest step
//! tried, one 1/60 s frame. And the driver's frames that are not a whole number of steps keep
//! symplectic Euler within its bound: one spring at hω = 1.9 in 1/60 s frames follows the
//! exact map of the frame's equal substeps, where whole steps and a short remainder grow it.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::core::study::{self, StabilityScene};

#[test]
fn measured_stability_bounds_agree_with_theory() {
    for scene in StabilityScene::ALL {
        let (m, s) = scene.build(true);
        let mode = study::fastest_mode(&m, &s);
        for kind in [IntegratorKind::SymplecticEuler, IntegratorKind::Rk4] {
            let theory = study::theoretical_bound_damped(kind, mode).unwrap();
            let measured = study::largest_stable_h(
                scene,
                kind,
                0.01 / mode.omega,
                4.0 / mode.omega,
                1.0,
                true,
            )
            .expect("stable at 0.01/ω");
            let ratio = measured / theory;
            println!(
                "{} (ω = {:.1}, c = {:.2}): {} measured {measured:.4e}, theory {theory:.4e}, ratio {ratio:.3}",
                scene.name(),
                mode.omega,
                mode.damping,
                kind.label()
            );
            assert!(
                (ratio - 1.0).abs() <= 0.1,
                "{} {}: ratio {ratio}",
                scene.name(),
                kind.name()
            );
        }
        for kind in [
            IntegratorKind::LinearlyImplicitEuler,
            IntegratorKind::BackwardEuler,
        ] {
            assert!(
                study::is_stable(scene, kind, 1.0 / 60.0, 1.0, true),
                "{} {} unstable at 1/60 s",
                scene.name(),
                kind.name()
            );
        }
    }
}

/// Symplectic Euler's map of one undamped oscillator `ẍ = −ω²x` over a step `h`, on `(x, v)`:
/// `v' = v − hω²x`, `x' = x + hv'` (the velocity first, as the method steps).
fn se_map(h: f64, w: f64) -> [[f64; 2]; 2] {
    [[1.0 - (h * w).powi(2), h], [-h * w * w, 1.0]]
}

fn mul(a: [[f64; 2]; 2], b: [[f64; 2]; 2]) -> [[f64; 2]; 2] {
    let c = |i: usize, j: usize| a[i][0] * b[0][j] + a[i][1] * b[1][j];
    [[c(0, 0), c(0, 1)], [c(1, 0), c(1, 1)]]
}

/// Spectral radius of a 2×2 map of determinant one (symplectic Euler's are): 1 while
/// `|trace| ≤ 2`, else the larger real eigenvalue's size.
fn radius(p: [[f64; 2]; 2]) -> f64 {
    let half = 0.5 * (p[0][0] + p[1][1]).abs();
    if half <= 1.0 {
        1.0
    } else {
        half + (half * half - 1.0).sqrt()
    }
}

#[test]
fn frames_that_are_not_whole_steps_keep_symplectic_euler_stable() {
    use bevy_soft_body::core::driver::{DriverConfig, Simulation, StepPolicy, equal_substep};
    use bevy_soft_body::core::scene::{ParticleDesc, Scene, SpringDesc};
    use bevy_soft_body::prelude::{Scalar, SpringLaw};
    // One 10 g particle on a Hooke spring from an anchor, no gravity, no damping: a linear
    // oscillator of ω = √(k/m). The step is 4·10⁻⁴ s (the bench box's), hω = 1.9: stable on its
    // own (|trace| < 2 while hω < 2). A 1/60 s frame is 41.67 such steps.
    let (m, h, frame): (f64, f64, f64) = (0.01, 4e-4, 1.0 / 60.0);
    let w = 1.9 / h;
    let k = m * w * w;
    // Whole steps of h and a short remainder: the frame's map grows the mode (theory, in f64).
    let whole = (frame / h).floor() as usize;
    let mut old = se_map(frame - whole as f64 * h, w);
    for _ in 0..whole {
        old = mul(old, se_map(h, w));
    }
    let grows = radius(old);
    // The driver's equal substeps: n = 42 of frame/42, hω = 1.885.
    let he = equal_substep(frame, h as Scalar) as f64;
    let n = (frame / he).round() as usize;
    assert_eq!(n, 42);
    assert!(((n as f64) * he - frame).abs() < 1e-6 * frame);
    let mut new = [[1.0, 0.0], [0.0, 1.0]];
    for _ in 0..n {
        new = mul(new, se_map(he, w));
    }
    println!(
        "frame map's spectral radius: h and a remainder {grows:.3}, equal substeps {:.3}",
        radius(new)
    );
    assert!(
        grows > 2.0,
        "the remainder's frame map must grow the mode: {grows}"
    );
    assert_eq!(radius(new), 1.0);
    // A step that divides the frame is the step itself, bit for bit.
    assert_eq!(
        equal_substep(frame, (frame / 40.0) as Scalar),
        (frame / 40.0) as Scalar
    );
    assert_eq!(equal_substep(0.25, 2e-4), 2e-4 as Scalar);
    // As many substeps as whole steps and a remainder took: a frame a hair over a whole
    // number of steps (within the slides' 0.1 %) is that many, a hair longer, not one more
    // step and a sliver; a little more is one more.
    for (ratio, steps) in [(42.0005, 42.0), (42.03, 43.0), (41.67, 42.0), (0.5, 1.0)] {
        let h = 1e-3;
        let got = equal_substep(ratio * h, h as Scalar) as f64;
        let want = ratio * h / steps;
        assert!(
            (got - want).abs() <= 1e-6 * want,
            "{ratio}: {got} against {want}"
        );
    }

    let amp = 1e-3;
    let mut s = Scene::default();
    let particle = |x: f64, mass: f64, pinned: bool| ParticleDesc {
        position: [x, 0.0, 0.0],
        velocity: [0.0; 3],
        mass,
        pinned,
    };
    s.particles.push(particle(0.0, 0.0, true));
    s.particles.push(particle(0.1 + amp, m, false));
    s.springs.push(SpringDesc {
        a: 0,
        b: 1,
        stiffness: k,
        damping: 0.0,
        rest_length: Some(0.1),
        law: SpringLaw::Hooke,
        kind: Default::default(),
    });
    let (model, state) = s.build().unwrap();
    let mut sim = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: IntegratorKind::SymplecticEuler,
            policy: StepPolicy::Fixed { h },
            frame_dt: frame,
            ..Default::default()
        },
    );
    // The exact map of the equal substeps from the same start, frame by frame: the driver
    // follows it to round-off, and the largest excursion along it bounds the driver's.
    let mut exact = [amp, 0.0];
    let (mut most, mut worst): (f64, f64) = (0.0, 0.0);
    for f in 0..120 {
        let rep = sim
            .advance_frame()
            .unwrap_or_else(|e| panic!("frame {f}: {e}"));
        assert_eq!(rep.substeps as usize, n);
        for _ in 0..n {
            let p = se_map(he, w);
            exact = [
                p[0][0] * exact[0] + p[0][1] * exact[1],
                p[1][0] * exact[0] + p[1][1] * exact[1],
            ];
            most = most.max(exact[0].abs());
        }
        let x = sim.state.x[1].x as f64 - 0.1;
        assert!(x.abs() <= most * 1.02, "frame {f}: {x:e} past {most:e}");
        worst = worst.max((x - exact[0]).abs());
    }
    assert!(
        worst <= 0.02 * amp,
        "off the equal substeps' map by {worst:e} (amplitude {amp:e})"
    );
    // Over 2 s the remainder's map would have grown the mode by `grows`¹²⁰.
    assert!(grows.powi(120) > 1e40);
}
