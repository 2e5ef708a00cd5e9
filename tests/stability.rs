//! The stability study's quick map (what `stability --quick` prints): on a spring chain, an
//! 8×8 cloth and a 4×4×4 jelly, the largest stable step of symplectic Euler and RK4 found by
//! bisection (1 % precision, 1 s, energy never above E₀ + 0.1 × scale) must agree within 10 %
//! with the linear stability bound of the fastest mode of M⁻¹K (power iteration) with its
//! modal damping; linearly implicit and backward Euler must be stable at the largest step
//! tried, one 1/60 s frame.

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
