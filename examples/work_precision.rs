//! Work-precision study: every integrator over a sweep of step sizes (tolerances for RK45) on
//! the circle, an undamped and a damped 4-particle spring pendulum and a 16×16 cloth; error at
//! the horizon against cost. Prints a table, writes `DIR/work_precision.csv` and log–log charts
//! `DIR/<problem>.png` / `.svg` (error against derivative evaluations) and
//! `DIR/<problem>_time.png` / `.svg` (error against wall time), one line per method with its
//! measured order in the legend; diverged runs are drawn as crosses on the top edge, never
//! dropped. No window, no keys.
//!
//! ```text
//! cargo run --release --example work_precision [-- --quick] [--out DIR]
//! cargo run --release --no-default-features --features f64 --example work_precision
//! ```
//!
//! The chart titles name the precision (f32 by default, f64 with `--features f64`).

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::core::study::{self, Problem, WorkPoint};
use bevy_soft_body::math::PRECISION;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

#[path = "headless/mod.rs"]
mod headless;

fn main() {
    let args = headless::args("work_precision");
    let (quick, out) = (args.quick, args.out);
    let mut csv =
        String::from("precision,problem,method,h_or_tol,error,evaluations,linear_solves,seconds\n");
    for problem in Problem::ALL {
        let (_, ref_err) = study::reference(problem, quick);
        let floor = study::error_floor(ref_err);
        let points = study::work_precision(problem, &IntegratorKind::ALL, quick);
        println!(
            "\n{} ({PRECISION}), T = {} s, reference cross-check {ref_err:.1e}, error floor {floor:.1e}",
            problem.name(),
            problem.horizon()
        );
        println!(
            "{:<34} {:>10} {:>11} {:>8} {:>7} {:>9}",
            "method", "h / tol", "error", "evals", "solves", "ms"
        );
        for p in &points {
            println!(
                "{:<34} {:>10.3e} {:>11} {:>8} {:>7} {:>9.3}",
                p.method.label(),
                p.h,
                p.error.map_or("diverged".into(), |e| format!("{e:.3e}")),
                p.evaluations,
                p.linear_solves,
                p.seconds * 1e3
            );
            let _ = writeln!(
                csv,
                "{PRECISION},{},{},{},{},{},{},{}",
                problem.name(),
                p.method.name(),
                p.h,
                p.error.map_or("diverged".into(), |e| e.to_string()),
                p.evaluations,
                p.linear_solves,
                p.seconds
            );
        }
        let orders: Vec<(IntegratorKind, Option<f64>)> = IntegratorKind::ALL
            .iter()
            .filter(|k| problem.supports(**k) && !k.is_adaptive())
            .map(|k| (*k, study::measured_order(&points, *k, floor, 0.1)))
            .collect();
        for (k, p) in &orders {
            println!(
                "  order {:<34} measured {:>6}  theory {}",
                k.label(),
                p.map_or("—".into(), |p| format!("{p:.2}")),
                k.order()
            );
        }
        for (suffix, cost) in [("", Cost::Evaluations), ("_time", Cost::WallTime)] {
            for ext in ["png", "svg"] {
                let path = out.join(format!("{}{suffix}.{ext}", problem.name()));
                if let Err(e) = chart(&path, problem, &points, &orders, cost) {
                    eprintln!("chart {}: {e}", path.display());
                }
            }
        }
    }
    let csv_path = out.join("work_precision.csv");
    std::fs::write(&csv_path, csv).expect("write CSV");
    println!("\nwrote {} and the charts beside it", csv_path.display());
}

/// What the x axis measures.
#[derive(Clone, Copy)]
enum Cost {
    Evaluations,
    WallTime,
}

impl Cost {
    fn of(self, p: &WorkPoint) -> f64 {
        match self {
            Cost::Evaluations => p.evaluations.max(1) as f64,
            Cost::WallTime => (p.seconds * 1e3).max(1e-4),
        }
    }

    fn label(self) -> &'static str {
        match self {
            Cost::Evaluations => "derivative evaluations",
            Cost::WallTime => "wall time (ms, one core)",
        }
    }
}

fn chart(
    path: &Path,
    problem: Problem,
    points: &[WorkPoint],
    orders: &[(IntegratorKind, Option<f64>)],
    cost: Cost,
) -> Result<(), Box<dyn std::error::Error>> {
    let finite: Vec<&WorkPoint> = points.iter().filter(|p| p.error.is_some()).collect();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, 0.0f64, f64::MAX, 0.0f64);
    for p in points {
        x0 = x0.min(cost.of(p));
        x1 = x1.max(cost.of(p));
    }
    for p in &finite {
        let e = p.error.unwrap().max(1e-16);
        y0 = y0.min(e);
        y1 = y1.max(e);
    }
    if finite.is_empty() {
        (y0, y1) = (1e-8, 1.0);
    }
    let (y0, y1) = (y0 / 3.0, y1 * 30.0);
    let title = format!(
        "{}: error at T = {} s vs cost ({PRECISION})",
        problem.name(),
        problem.horizon()
    );
    let frame = Frame {
        title,
        x: (x0, x1),
        y: (y0, y1),
        cost,
    };
    if path.extension().is_some_and(|e| e == "svg") {
        draw(
            SVGBackend::new(path, (900, 600)).into_drawing_area(),
            &frame,
            points,
            orders,
        )
    } else {
        draw(
            BitMapBackend::new(path, (900, 600)).into_drawing_area(),
            &frame,
            points,
            orders,
        )
    }
}

struct Frame {
    title: String,
    x: (f64, f64),
    y: (f64, f64),
    cost: Cost,
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    frame: &Frame,
    points: &[WorkPoint],
    orders: &[(IntegratorKind, Option<f64>)],
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let (x0, x1) = frame.x;
    let (y0, y1) = frame.y;
    let title = &frame.title;
    {
        root.fill(&WHITE)?;
        let mut c = ChartBuilder::on(&root)
            .caption(title.as_str(), ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d((x0 / 1.5..x1 * 1.5).log_scale(), (y0..y1).log_scale())?;
        c.configure_mesh()
            .x_desc(frame.cost.label())
            .y_desc("max position error (m)")
            .x_label_formatter(&|v| format!("{v:.3}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()?;
        for (i, kind) in IntegratorKind::ALL.iter().enumerate() {
            let pts: Vec<&WorkPoint> = points.iter().filter(|p| p.method == *kind).collect();
            if pts.is_empty() {
                continue;
            }
            let color = headless::PALETTE[i % headless::PALETTE.len()];
            let order = orders
                .iter()
                .find(|o| o.0 == *kind)
                .and_then(|o| o.1)
                .map_or(String::new(), |p| format!(" (p = {p:.2})"));
            let line: Vec<(f64, f64)> = pts
                .iter()
                .filter_map(|p| p.error.map(|e| (frame.cost.of(p), e.max(1e-16))))
                .collect();
            c.draw_series(LineSeries::new(line.clone(), color.stroke_width(2)))?
                .label(format!("{}{order}", kind.label()))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2))
                });
            c.draw_series(line.iter().map(|p| Circle::new(*p, 3, color.filled())))?;
            // Diverged runs: crosses on the top edge at their cost.
            c.draw_series(
                pts.iter()
                    .filter(|p| p.error.is_none())
                    .map(|p| Cross::new((frame.cost.of(p), y1 / 1.5), 5, color.stroke_width(2))),
            )?;
        }
        c.configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::LowerLeft)
            .draw()?;
        root.present()?;
        Ok(())
    }
}
