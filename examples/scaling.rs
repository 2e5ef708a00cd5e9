//! Cost against size: every method on 32×32, 64×64 and 128×128 cloths of the cloth assignment's material,
//! each at its own largest stable step — symplectic Euler and RK4 at 0.9× the linear bound of
//! the cloth's fastest mode (which the stability study matches within 5 %), the methods
//! without an undamped bound (forward Euler, trapezoid, midpoint, implicit-damping trapezoid)
//! at 0.9× the largest step that survives 0.5 s by bisection, linearly implicit and backward
//! Euler at one step per 1/60 s frame — timed over 0.25 simulated seconds on one core. A run
//! that diverges anyway (a slower, less damped mode can bind before the fastest one) is
//! repeated at 0.8× the step until it holds; the table shows the step used.
//! Prints ms of wall time per simulated second and the fitted slope of log cost against log
//! particle count; writes `DIR/scaling.csv` and `DIR/scaling.png` / `.svg`. No window, no keys.
//!
//! ```text
//! cargo run --release --example scaling [-- --out DIR] [--sizes 32,64,128]
//! ```

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::build;
use bevy_soft_body::core::driver::{DriverConfig, Simulation, StepPolicy};
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::core::study;
use bevy_soft_body::math::PRECISION;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::time::Instant;

fn cloth(n: usize) -> build::ClothParams {
    build::ClothParams::default().resized(n, n)
}

/// The largest step of `kind` on an n×n cloth that survives `t` seconds (bisection, 2 %).
fn bisect(n: usize, kind: IntegratorKind, lo: f64, hi: f64, t: f64) -> f64 {
    let stable = |h: f64| {
        let (m, s) = build::cloth(&cloth(n)).unwrap().build().unwrap();
        let mut sim = Simulation::new(
            m,
            s,
            DriverConfig {
                integrator: kind,
                policy: StepPolicy::Fixed { h },
                frame_dt: t,
                ..Default::default()
            },
        );
        sim.advance_frame().is_ok()
    };
    let (mut a, mut b) = (lo, hi);
    if !stable(a) {
        return a;
    }
    while b / a > 1.02 {
        let m = (a * b).sqrt();
        if stable(m) { a = m } else { b = m }
    }
    a
}

#[path = "headless/mod.rs"]
mod headless;

fn main() {
    let args = headless::args("scaling");
    let out = args.out;
    let sizes = args.sizes.unwrap_or(vec![32, 64, 128]);
    let kinds: Vec<IntegratorKind> = IntegratorKind::ALL
        .into_iter()
        .filter(|k| !k.is_adaptive())
        .collect();
    let mut rows: Vec<(IntegratorKind, usize, f64, f64)> = vec![]; // kind, particles, h, ms per s
    println!("cost per simulated second ({PRECISION}, one core)\n");
    println!(
        "{:<34} {:>9} {:>11} {:>14}",
        "method", "particles", "h (s)", "ms / sim. s"
    );
    for &n in &sizes {
        let (m, s) = build::cloth(&cloth(n)).unwrap().build().unwrap();
        let mode = study::fastest_mode(&m, &s);
        for &kind in &kinds {
            let h = if kind.is_implicit() && kind != IntegratorKind::ImplicitDampingTrapezoid {
                1.0 / 60.0
            } else if let Some(b) = study::theoretical_bound_damped(kind, mode) {
                0.9 * b
            } else {
                0.9 * bisect(n, kind, 0.01 / mode.omega, 4.0 / mode.omega, 0.5)
            };
            let t = 0.25;
            // A step the bound allows can still fail where a slower, less damped mode binds
            // (damping lowers symplectic Euler's bound): step down by 0.8× until the run is
            // stable, and report the step that was used.
            let (mut h, mut ok, mut ms) = (h, false, 0.0);
            for _ in 0..6 {
                let (m, s) = build::cloth(&cloth(n)).unwrap().build().unwrap();
                let mut sim = Simulation::new(
                    m,
                    s,
                    DriverConfig {
                        integrator: kind,
                        policy: StepPolicy::Fixed { h },
                        frame_dt: t,
                        ..Default::default()
                    },
                );
                let start = Instant::now();
                ok = sim.advance_frame().is_ok();
                ms = start.elapsed().as_secs_f64() * 1e3 / t;
                if ok {
                    break;
                }
                h *= 0.8;
            }
            println!(
                "{:<34} {:>9} {:>11.3e} {:>14}",
                kind.label(),
                n * n,
                h,
                if ok {
                    format!("{ms:.1}")
                } else {
                    "diverged".into()
                }
            );
            if ok {
                rows.push((kind, n * n, h, ms));
            }
        }
    }
    println!("\nfitted slope of log(ms per simulated second) against log(particles):");
    let mut slopes = vec![];
    for &kind in &kinds {
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.0 == kind)
            .map(|r| ((r.1 as f64).ln(), r.3.ln()))
            .collect();
        let slope = study::least_squares_slope(&pts);
        println!(
            "  {:<34} {}",
            kind.label(),
            slope.map_or("—".into(), |s| format!("{s:.2}"))
        );
        slopes.push((kind, slope));
    }
    let mut csv = String::from("precision,method,particles,h,ms_per_simulated_second\n");
    for r in &rows {
        let _ = writeln!(csv, "{PRECISION},{},{},{},{}", r.0.name(), r.1, r.2, r.3);
    }
    std::fs::write(out.join("scaling.csv"), csv).expect("write CSV");
    headless::save(&out, "scaling", (900, 600), &ScalingChart(&rows, &slopes));
    println!("\nwrote {}", out.join("scaling.csv").display());
}

type Rows = [(IntegratorKind, usize, f64, f64)];

struct ScalingChart<'a>(&'a Rows, &'a [(IntegratorKind, Option<f64>)]);

impl headless::Chart for ScalingChart<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, plotters::coord::Shift>,
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        let (rows, slopes) = (self.0, self.1);
        root.fill(&WHITE)?;
        let (x0, x1) = rows.iter().fold((f64::MAX, 0.0f64), |(a, b), r| {
            (a.min(r.1 as f64), b.max(r.1 as f64))
        });
        let (y0, y1) = rows
            .iter()
            .fold((f64::MAX, 0.0f64), |(a, b), r| (a.min(r.3), b.max(r.3)));
        let mut c = ChartBuilder::on(&root)
            .caption(
                format!(
                    "cost per simulated second at each method's largest stable h ({PRECISION})"
                ),
                ("sans-serif", 20),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(
                (x0 / 1.5..x1 * 1.5).log_scale(),
                (y0 / 2.0..y1 * 2.0).log_scale(),
            )?;
        c.configure_mesh()
            .x_desc("particles")
            .y_desc("ms of wall time per simulated second")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .draw()?;
        for (i, (kind, slope)) in slopes.iter().enumerate() {
            let color = headless::PALETTE[i % headless::PALETTE.len()];
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.0 == *kind)
                .map(|r| (r.1 as f64, r.3))
                .collect();
            if pts.is_empty() {
                continue;
            }
            c.draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
                .label(format!(
                    "{} (slope {})",
                    kind.label(),
                    slope.map_or("—".into(), |s| format!("{s:.2}"))
                ))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2))
                });
            c.draw_series(pts.iter().map(|p| Circle::new(*p, 3, color.filled())))?;
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
