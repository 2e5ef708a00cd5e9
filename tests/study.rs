//! The work-precision study's quick sweeps (what `work_precision --quick` prints) must show the
//! orders theory gives: forward and symplectic Euler, linearly implicit Euler, the
//! implicit-damping trapezoid and backward Euler 1, the explicit trapezoid and midpoint 2,
//! RK4 4 — each within ±0.15, fitted by least squares over the points between the error floor
//! (10³ u, or ten times the reference's own error) and 0.1 m. In f64 every fixed-step method
//! must be measurable on every problem; in f32 round-off (10³ u ≈ 1.2e-4 m) leaves RK4 and the
//! cloth no point above the floor, so there the first- and second-order methods on the circle
//! and the pendulums are required, and anything else measured must still agree.

use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::core::study::{self, Problem};

const F64: bool = cfg!(feature = "f64");

#[test]
fn quick_work_precision_orders_match_theory() {
    let mut failures = vec![];
    for problem in Problem::ALL {
        let (_, reference_error) = study::reference(problem, true);
        let floor = study::error_floor(reference_error);
        let points = study::work_precision(problem, &IntegratorKind::ALL, true);
        for kind in IntegratorKind::ALL {
            if !problem.supports(kind) || kind.is_adaptive() {
                continue;
            }
            let measured = study::measured_order(&points, kind, floor, 0.1);
            if std::env::var("STUDY_POINTS").is_ok() {
                for p in points.iter().filter(|p| p.method == kind) {
                    println!("  {:?}", p);
                }
            }
            let required = F64 || (problem != Problem::Cloth && kind.order() <= 2);
            println!(
                "{:<16} {:<34} measured {:>6} theory {}",
                problem.name(),
                kind.label(),
                measured.map_or("—".into(), |p| format!("{p:.2}")),
                kind.order()
            );
            match measured {
                Some(p) if (p - kind.order() as f64).abs() > 0.15 => {
                    failures.push(format!("{} {}: order {p:.2}", problem.name(), kind.name()))
                }
                None if required => failures.push(format!(
                    "{} {}: not measurable",
                    problem.name(),
                    kind.name()
                )),
                _ => {}
            }
        }
        // RK45: tighter tolerances give smaller errors (a hundredth of the tolerance range
        // buys at least a tenth of the error).
        let rk45: Vec<f64> = points
            .iter()
            .filter(|p| p.method == IntegratorKind::Rk45)
            .filter_map(|p| p.error)
            .collect();
        if let (Some(first), Some(last)) = (rk45.first(), rk45.last())
            && *first > floor
        {
            assert!(
                last < &(first / 10.0).max(floor),
                "{}: RK45 {rk45:?}",
                problem.name()
            );
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
