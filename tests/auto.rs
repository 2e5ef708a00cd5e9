//! Automatic method and step: its spectrum against the stability map's power iteration, its
//! test-equation probe against the explicit methods' known stability limits, its choices
//! against the stability map's measured criterion on the map's scenes, its tolerance and
//! budget, and the driver's use of it (decided at a frame's start, again after a change).
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::auto::{self, AutoConfig, BodySize, OMEGA_MARGIN};
use bevy_soft_body::core::driver::{DriverConfig, Simulation, StepPolicy};
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::core::jacobian::Linearization;
use bevy_soft_body::core::ode::OdeSystem;
use bevy_soft_body::core::study::{self, FastestMode, StabilityScene};

fn auto_sim(
    scene: StabilityScene,
    frame_dt: f64,
    config: AutoConfig,
) -> Simulation<
    bevy_soft_body::core::ode::ParticleState,
    bevy_soft_body::core::particles::ParticleModel,
> {
    let (model, state) = scene.build(false);
    Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: IntegratorKind::Auto,
            policy: StepPolicy::Fixed { h: 1e-3 },
            frame_dt,
            auto: config,
            ..Default::default()
        },
    )
}

/// Lanczos' largest eigenvalue of `M⁻¹K` against the stability map's power iteration (run to
/// 1e-7 relative): within 0.5 % (Lanczos approaches it from below; the probe's margin of
/// 25 % covers far more). The damping rate is the largest of `M⁻¹D`, so it bounds the
/// Rayleigh quotient the power iteration reports for the fastest mode's shape.
#[test]
fn the_spectrum_matches_power_iteration_on_the_stability_scenes() {
    for scene in StabilityScene::ALL {
        let (model, state) = scene.build(false);
        let lanczos = auto::spectrum(&model as &dyn Linearization, &state);
        let power = study::fastest_mode(&model, &state);
        println!(
            "{}: ω Lanczos {:.3}, power {:.3}; damping Lanczos {:.3} (largest), power {:.3} (fastest mode's)",
            scene.name(),
            lanczos.omega,
            power.omega,
            lanczos.damping,
            power.damping
        );
        assert!(
            (lanczos.omega / power.omega - 1.0).abs() < 5e-3,
            "{}: {} against {}",
            scene.name(),
            lanczos.omega,
            power.omega
        );
        assert!(lanczos.damping >= power.damping * (1.0 - 1e-3));
    }
}

/// The probe is the real integrator on one spring: symplectic Euler's undamped limit is
/// `h ω = 2` and RK4's `2√2` (the imaginary-axis extent of its stability region); the probe
/// must find both to within 2 %, and call the implicit methods stable far beyond.
#[test]
fn the_probe_finds_the_explicit_methods_known_limits() {
    let omega = 100.0;
    for (kind, limit) in [
        (IntegratorKind::SymplecticEuler, 2.0),
        (IntegratorKind::Rk4, 2.0 * 2f64.sqrt()),
    ] {
        let stable = |hw: f64| {
            auto::probe(
                kind,
                omega,
                0.0,
                hw / omega,
                auto::STABILITY_STEPS,
                false,
                f64::INFINITY,
            )
            .stable
        };
        assert!(stable(0.98 * limit), "{kind} at 0.98 × {limit}");
        assert!(!stable(1.02 * limit), "{kind} at 1.02 × {limit}");
    }
    for kind in [
        IntegratorKind::LinearlyImplicitEuler,
        IntegratorKind::BackwardEuler,
        IntegratorKind::ProjectiveDynamics,
    ] {
        let p = auto::probe(
            kind,
            omega,
            0.0,
            1000.0 / omega,
            auto::STABILITY_STEPS,
            false,
            f64::INFINITY,
        );
        assert!(p.stable, "{kind} at h ω = 1000");
    }
}

/// On every stability-map scene, at 60 Hz and at 30 Hz frames, Auto's choice passes the
/// stability map's own measured criterion (3 s, total energy never above its start plus a
/// tenth of the energy scale) at the step it chose, and an explicit choice is not wasteful:
/// its step is at least 60 % of the largest stable step the map's bisection measures (the
/// probe's 25 % margin and the substep count's rounding take the rest).
#[test]
fn auto_never_picks_an_unstable_method_on_the_stability_scenes() {
    for scene in StabilityScene::ALL {
        for frame_dt in [1.0 / 60.0, 1.0 / 30.0] {
            let mut sim = auto_sim(scene, frame_dt, AutoConfig::default());
            sim.advance_frame().expect("first frame");
            let choice = sim.auto_choice().expect("decided").clone();
            println!("{} at {frame_dt:.4}: {}", scene.name(), choice.reason);
            assert!(
                study::is_stable(scene, choice.kind, choice.h, 3.0, false),
                "{}: {} at h = {} is unstable",
                scene.name(),
                choice.kind,
                choice.h
            );
            if !choice.kind.is_implicit() {
                let largest =
                    study::largest_stable_h(scene, choice.kind, choice.h, frame_dt, 3.0, false)
                        .expect("stable at the choice");
                println!(
                    "  measured largest stable step {largest:.3e}, chosen {:.3e}",
                    choice.h
                );
                assert!(
                    choice.h >= 0.6 * largest,
                    "{}: chose {} but {} is stable",
                    scene.name(),
                    choice.h,
                    largest
                );
            }
            // And the run itself goes on.
            for _ in 0..119 {
                sim.advance_frame().expect("Auto's choice stays stable");
            }
        }
    }
}

/// With a tolerance, the choice meets it on the test equation (measured again here), and a
/// tighter tolerance never costs less; the choice is stable on the scene.
#[test]
fn a_tolerance_is_met_and_tighter_ones_cost_more() {
    let mode = FastestMode {
        omega: 243.9,
        damping: 50.0,
    };
    let size = BodySize {
        particles: 256,
        springs: 1378,
        tets: 0,
        direct: false,
    };
    let mut last = 0.0;
    for tol in [0.3, 0.1, 0.03, 0.01] {
        let config = AutoConfig {
            tolerance: Some(tol),
            max_substeps: 256,
        };
        let c = auto::decide(mode, 1.0 / 60.0, size, &config, 1.0, &[]);
        println!("tolerance {tol}: {}", c.reason);
        assert!(c.meets_tolerance, "{tol}: {}", c.reason);
        let again = auto::probe(
            c.kind,
            c.omega_accuracy,
            0.0,
            c.h,
            (1.0 / c.h).round() as u32,
            false,
            f64::INFINITY,
        );
        assert!(again.energy_error <= tol, "{tol}: {}", again.energy_error);
        assert!(c.cost_ms >= last, "{tol}: {} < {last}", c.cost_ms);
        last = c.cost_ms;
        // The 60 Hz frame shows motion up to π/(4Δ) ≈ 47 rad/s: that is where it was checked.
        assert!((c.omega_accuracy - std::f64::consts::PI * 15.0).abs() < 1e-9);
    }
}

/// A tolerance nothing meets within the budget: the most accurate stable candidate, reported
/// as such, and the body does not diverge.
#[test]
fn an_unmeetable_tolerance_gives_the_most_accurate_affordable_method_and_says_so() {
    let config = AutoConfig {
        tolerance: Some(1e-9),
        max_substeps: 4,
    };
    let mut sim = auto_sim(StabilityScene::Cloth, 1.0 / 60.0, config);
    for _ in 0..120 {
        sim.advance_frame().expect("bounded");
    }
    let c = sim.auto_choice().expect("decided");
    println!("{}", c.reason);
    assert!(!c.meets_tolerance);
    assert!(c.reason.contains("no method meets"), "{}", c.reason);
    assert!(c.substeps <= 4);
    let best = c
        .candidates
        .iter()
        .map(|k| k.energy_error)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(c.energy_error, best);
    // Bad numbers are refused with the field's name.
    for bad in [Some(0.0), Some(-1.0), Some(f64::NAN)] {
        let e = AutoConfig {
            tolerance: bad,
            max_substeps: 8,
        }
        .validate()
        .expect_err("refused");
        assert_eq!(e.0, "tolerance");
    }
}

/// The driver decides at the first frame, keeps the choice, decides again after
/// `set_auto` and `replace`, and two runs are bitwise the same.
#[test]
fn the_driver_decides_at_frame_starts_and_runs_reproducibly() {
    let mut a = auto_sim(StabilityScene::Jelly, 1.0 / 60.0, AutoConfig::default());
    assert!(a.auto_choice().is_none());
    for _ in 0..30 {
        a.advance_frame().unwrap();
    }
    let first = a.auto_choice().unwrap().clone();
    assert_eq!(a.method(), first.kind);
    let mut b = auto_sim(StabilityScene::Jelly, 1.0 / 60.0, AutoConfig::default());
    for _ in 0..30 {
        b.advance_frame().unwrap();
    }
    assert_eq!(a.state.x, b.state.x);
    assert_eq!(a.state.v, b.state.v);
    // A stiffer jelly (springs four times as stiff: ω doubles) is decided again on replace.
    let mut model = a.system.clone();
    for s in model.springs.as_mut_slice() {
        s.k *= 4.0;
    }
    let state = a.state.clone();
    a.replace(model, state);
    assert!(a.auto_choice().is_none());
    a.advance_frame().unwrap();
    let second = a.auto_choice().unwrap().clone();
    println!("{}\n{}", first.reason, second.reason);
    assert!((second.mode.omega / first.mode.omega - 2.0).abs() < 0.05);
    assert!(
        second.substeps > first.substeps || second.kind != first.kind,
        "{} then {}",
        first.reason,
        second.reason
    );
    a.set_auto(AutoConfig {
        tolerance: Some(0.05),
        max_substeps: 64,
    });
    assert!(a.auto_choice().is_none());
    // The margin the stability probe keeps is the one documented.
    assert_eq!(OMEGA_MARGIN, 1.25);
    // Parsing.
    assert_eq!(
        "auto".parse::<IntegratorKind>().unwrap(),
        IntegratorKind::Auto
    );
    assert!(!IntegratorKind::ALL.contains(&IntegratorKind::Auto));
    let _ = a.system.linearization().unwrap();
}
