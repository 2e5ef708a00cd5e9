//! Stability map: for every method on a spring chain, a cloth and a jelly block, the largest
//! stable step found by bisection (stable: finite, and total energy never above its initial
//! value plus a tenth of the scene's energy scale, over the stated time), next to the
//! explicit bound theory gives from the fastest mode ω of `M⁻¹K` (power iteration) and its
//! modal damping c: 2(√(1+ζ²) − ζ)/ω for symplectic Euler (2/ω undamped), the |R(hλ)| = 1
//! crossing for RK4 (2√2/ω undamped); none for forward Euler, the trapezoid and midpoint on
//! an undamped mode (what they reach over the stated time comes from damping, and from the
//! fastest mode growing from round-off too slowly to show). Implicit methods are tried up to
//! the frame, 1/60 s. Prints a table, writes `DIR/stability.csv` and `DIR/stability.png` /
//! `.svg` (h ω per method and scene, theory marked). No window, no keys.
//!
//! ```text
//! cargo run --release --example stability [-- --quick] [--out DIR]
//! ```

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::core::study::{self, StabilityScene};
use bevy_soft_body::math::PRECISION;
use plotters::prelude::*;
use std::fmt::Write as _;

/// One row of the map.
struct Row {
    scene: StabilityScene,
    omega: f64,
    kind: IntegratorKind,
    measured: Option<f64>,
    theory: Option<f64>,
}

#[path = "headless/mod.rs"]
mod headless;

fn main() {
    let args = headless::args("stability");
    let (quick, out) = (args.quick, args.out);
    let duration = if quick { 1.0 } else { 3.0 };
    let mut rows = vec![];
    println!(
        "largest stable h ({PRECISION}; stable: finite and energy ≤ E₀ + 0.1 scale over {duration} s)\n"
    );
    println!(
        "{:<6} {:>9} {:>8} {:<34} {:>11} {:>11} {:>8} {:>7}",
        "scene", "ω (1/s)", "c (1/s)", "method", "measured h", "theory h", "ratio", "h ω"
    );
    for scene in StabilityScene::ALL {
        let (m, s) = scene.build(quick);
        let mode = study::fastest_mode(&m, &s);
        let omega = mode.omega;
        for kind in IntegratorKind::ALL {
            if kind.is_adaptive() {
                continue;
            }
            let (lo, hi) = if kind.is_implicit() {
                (1e-3, 1.0 / 60.0)
            } else {
                (0.01 / omega, 4.0 / omega)
            };
            let measured = study::largest_stable_h(scene, kind, lo, hi, duration, quick);
            let theory = study::theoretical_bound_damped(kind, mode);
            println!(
                "{:<6} {:>9.1} {:>8.2} {:<34} {:>11} {:>11} {:>8} {:>7}",
                scene.name(),
                omega,
                mode.damping,
                kind.label(),
                measured.map_or("< lo".into(), |h| if kind.is_implicit() && h >= hi {
                    format!("≥ {h:.3e}")
                } else {
                    format!("{h:.3e}")
                }),
                theory.map_or("none".into(), |h| format!("{h:.3e}")),
                match (measured, theory) {
                    (Some(m), Some(t)) => format!("{:.3}", m / t),
                    _ => "—".into(),
                },
                measured.map_or("—".into(), |h| format!("{:.2}", h * omega)),
            );
            rows.push(Row {
                scene,
                omega,
                kind,
                measured,
                theory,
            });
        }
    }
    let mut csv = String::from("precision,scene,omega,method,measured_h,theory_h\n");
    for r in &rows {
        let _ = writeln!(
            csv,
            "{PRECISION},{},{},{},{},{}",
            r.scene.name(),
            r.omega,
            r.kind.name(),
            r.measured.map_or(String::new(), |h| h.to_string()),
            r.theory.map_or(String::new(), |h| h.to_string())
        );
    }
    std::fs::write(out.join("stability.csv"), csv).expect("write CSV");
    headless::save(&out, "stability", (900, 560), &StabilityChart(&rows));
    println!(
        "\nwrote {} and the chart beside it",
        out.join("stability.csv").display()
    );
}

struct StabilityChart<'a>(&'a [Row]);

impl headless::Chart for StabilityChart<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, plotters::coord::Shift>,
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        let rows = self.0;
        root.fill(&WHITE)?;
        let kinds: Vec<IntegratorKind> = IntegratorKind::ALL
            .into_iter()
            .filter(|k| !k.is_adaptive())
            .collect();
        let mut c = ChartBuilder::on(&root)
            .caption(
                format!(
                    "largest stable h·ω_max ({PRECISION}); bars: undamped theory; implicit methods (i d b x p) tried up to h = 1/60 s"
                ),
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(60)
            .y_label_area_size(60)
            .build_cartesian_2d(
                -0.5f64..kinds.len() as f64 - 0.5,
                (0.01f64..1000.0).log_scale(),
            )?;
        c.configure_mesh()
            .x_labels(kinds.len())
            .x_label_formatter(&|x| {
                let i = x.round() as usize;
                kinds
                    .get(i)
                    .map_or(String::new(), |k| k.letter().to_string())
            })
            .x_desc("method (e s t m r i d b x p)")
            .y_desc("h · ω_max")
            .draw()?;
        let colors = [
            RGBColor(55, 126, 184),
            RGBColor(228, 26, 28),
            RGBColor(77, 175, 74),
        ];
        for (si, scene) in StabilityScene::ALL.iter().enumerate() {
            let color = colors[si];
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.scene == *scene)
                .filter_map(|r| {
                    let i = kinds.iter().position(|k| *k == r.kind)? as f64;
                    r.measured
                        .map(|h| (i + (si as f64 - 1.0) * 0.15, h * r.omega))
                })
                .collect();
            c.draw_series(pts.iter().map(|p| Circle::new(*p, 5, color.filled())))?
                .label(format!("{} measured", scene.name()))
                .legend(move |(x, y)| Circle::new((x, y), 5, color.filled()));
        }
        // Theory: 2 (symplectic Euler) and 2√2 (RK4), as short black bars at their method.
        for (k, bound) in [
            (IntegratorKind::SymplecticEuler, 2.0),
            (IntegratorKind::Rk4, 2.0 * std::f64::consts::SQRT_2),
        ] {
            let i = kinds.iter().position(|x| *x == k).unwrap_or(0) as f64;
            c.draw_series(LineSeries::new(
                vec![(i - 0.35, bound), (i + 0.35, bound)],
                BLACK.stroke_width(3),
            ))?;
        }
        c.configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()?;
        root.present()?;
        Ok(())
    }
}
