//! Work-precision study: every integrator over a sweep of step sizes (tolerances for RK45) on
//! the circle, an undamped and a damped 4-particle spring pendulum and a 16×16 cloth; then the
//! large-step problems, from one step per 1/60 s frame down, on the 16×16 cloth and on the
//! finite-element bodies (the soft bunny, the stiff armadillo and, when `../shared/bench` is
//! there, the bench's 5000-tet box), where the implicit methods meet the explicit ones at the
//! steps the explicit ones first survive; error at the horizon against cost. Prints a table,
//! writes `DIR/work_precision.csv` and log–log charts `DIR/<problem>.png` / `.svg` (error
//! against derivative evaluations) and `DIR/<problem>_time.png` / `.svg` (error against wall
//! time), one line per method with its measured order in the legend (least squares over the
//! steps below its last divergence, between the error floor and 0.1 m); diverged runs are
//! drawn as crosses on the top edge, never dropped. No window, no keys.
//!
//! ```text
//! cargo run --release --example work_precision [-- --quick] [--out DIR] [--only bunny,armadillo]
//! cargo run --release --no-default-features --features f64 --example work_precision
//! ```
//!
//! The chart titles name the precision (f32 by default, f64 with `--features f64`).

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::build;
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::core::scene::Scene;
use bevy_soft_body::core::study::{self, BodyProblem, Problem, WorkPoint};
use bevy_soft_body::math::PRECISION;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

#[path = "headless/mod.rs"]
mod headless;

fn main() {
    let args = headless::args("work_precision");
    let (quick, out) = (args.quick, args.out.clone());
    let mut csv =
        String::from("precision,problem,method,h_or_tol,error,evaluations,linear_solves,seconds\n");
    for problem in Problem::ALL {
        if !args.wants(problem.name()) {
            continue;
        }
        let (_, ref_err) = study::reference(problem, quick);
        let points = study::work_precision(problem, &IntegratorKind::ALL, quick);
        let kinds: Vec<IntegratorKind> = IntegratorKind::ALL
            .into_iter()
            .filter(|k| problem.supports(*k))
            .collect();
        let run = Run {
            name: problem.name().into(),
            horizon: problem.horizon(),
            ref_err,
            kinds,
            points,
        };
        run.report(&out, &mut csv);
    }
    for body in bodies(quick) {
        if !args.wants(&body.name) {
            continue;
        }
        let (reference, ref_err) = body.reference();
        let points = body.work_precision(&IntegratorKind::ALL, &reference);
        let kinds: Vec<IntegratorKind> = IntegratorKind::ALL
            .into_iter()
            .filter(|k| body.supports(*k))
            .collect();
        println!(
            "\n{}: {} particles, {} springs, {} tets; steps {:.3e} … {:.3e} s, reference RK4 at {:.3e} s",
            body.name,
            body.model.len(),
            body.model.springs.len(),
            body.model.tets.len(),
            body.steps[0],
            body.steps.last().copied().unwrap_or(0.0),
            body.reference_step
        );
        let run = Run {
            name: body.name.clone(),
            horizon: body.horizon,
            ref_err,
            kinds,
            points,
        };
        run.report(&out, &mut csv);
    }
    if args.wants("resolution") {
        let sizes = args
            .sizes
            .clone()
            .unwrap_or(if quick { vec![8, 16] } else { vec![8, 16, 32] });
        resolution(&sizes, &out);
    }
    let csv_path = out.join("work_precision.csv");
    std::fs::write(&csv_path, csv).expect("write CSV");
    println!("\nwrote {} and the charts beside it", csv_path.display());
}

/// The large-step problems, swept from one step per 1/60 s frame down by halves until
/// `h ω ≤ 1/4` ([`BodyProblem::from_frame`]): the 16×16 cloth over 0.5 s (where the implicit,
/// XPBD and projective dynamics methods meet the explicit ones), the soft bunny over 0.1 s,
/// the stiff armadillo over 0.05 s (both hung and kicked, `headless::tet_body`) and, when
/// `../shared/bench` is there, the bench's box of 5000 tets over 0.1 s. `quick`: the cloth
/// and the bunny.
fn bodies(quick: bool) -> Vec<BodyProblem> {
    let mut out = vec![];
    if let Some((m, s)) = build::cloth(&build::ClothParams::default())
        .ok()
        .and_then(|c| c.build().ok())
    {
        out.push(BodyProblem::from_frame("cloth16_large", m, s, 0.5));
    }
    if let Some((m, s)) = headless::tet_body("bunny", 2e5, 0.4) {
        out.push(BodyProblem::from_frame("bunny", m, s, 0.1));
    }
    if quick {
        return out;
    }
    if let Some((m, s)) = headless::tet_body("armadillo", 1e6, 0.45) {
        out.push(BodyProblem::from_frame("armadillo", m, s, 0.05));
    }
    if let Some((m, s)) = headless::read("../shared/bench/box5k.json")
        .and_then(|(_, text)| Scene::from_json(&text).ok())
        .and_then(|scene| scene.build().ok())
    {
        out.push(BodyProblem::from_frame("box5k", m, s, 0.1));
    }
    out
}

/// The error every resolution must reach: 1 mm at T = 0.5 s.
const TARGET: f64 = 1e-3;

/// Cost against resolution at fixed accuracy: the cloth assignment's cloth at each size `n²`,
/// swept from one step per frame down ([`BodyProblem::from_frame`], T = 0.5 s), and for each
/// method the wall time per simulated second that reaches [`TARGET`] ([`study::cost_at`]:
/// interpolated between the sweep's points; where the method's largest stable step already
/// meets it, that step's cost, an upper bound).
/// Prints the table with each method's slope (log cost / log particles), writes
/// `DIR/resolution.csv` and the chart `DIR/resolution.png` / `.svg`.
fn resolution(sizes: &[usize], out: &Path) {
    let horizon = 0.5;
    let mut rows: Vec<CostRow> = IntegratorKind::ALL
        .into_iter()
        .map(|k| (k, vec![]))
        .collect();
    let mut particles = vec![];
    for &n in sizes {
        let Some((m, st)) = build::cloth(&build::ClothParams::default().resized(n, n))
            .ok()
            .and_then(|c| c.build().ok())
        else {
            continue;
        };
        particles.push(m.len());
        let mut body = BodyProblem::from_frame(&format!("cloth{n}"), m, st, horizon);
        // First-order methods need h ≈ 1e-3 for the target (symplectic Euler's error is about
        // 0.65 h m/s at T on the 16² cloth): sweep at least to 1/3840 s whatever the size.
        while let Some(&h) = body.steps.last().filter(|h| **h > 1.0 / 3840.0 + 1e-12) {
            body.steps.push(h / 2.0);
        }
        body.reference_step = body.steps.last().copied().unwrap_or(1.0 / 60.0) / 4.0;
        let (reference, ref_err) = body.reference();
        let points = body.work_precision(&IntegratorKind::ALL, &reference);
        println!(
            "resolution {n}×{n}: steps {:.3e} … {:.3e} s, reference cross-check {ref_err:.1e}",
            body.steps[0],
            body.steps.last().copied().unwrap_or(0.0)
        );
        for (k, costs) in &mut rows {
            costs.push(
                study::cost_at(&points, *k, TARGET).map(|(s, first)| (s * 1e3 / horizon, first)),
            );
        }
    }
    println!(
        "\nwall ms per simulated second to reach {TARGET:.0e} m at T = {horizon} s ({PRECISION}, one core; ≤: already met at the method's largest stable step of the sweep, an upper bound)"
    );
    print!("{:<34}", "method");
    for n in sizes {
        print!(" {:>12}", format!("{n}×{n}"));
    }
    println!(" {:>7}", "slope");
    let mut csv =
        String::from("precision,method,particles,ms_per_simulated_second,largest_step_meets\n");
    for (k, costs) in &rows {
        print!("{:<34}", k.label());
        let mut xy = vec![];
        for (c, np) in costs.iter().zip(&particles) {
            match c {
                Some((ms, first)) => {
                    print!(
                        " {:>12}",
                        format!("{}{ms:.1}", if *first { "≤" } else { "" })
                    );
                    xy.push(((*np as f64).ln(), ms.ln()));
                    let _ = writeln!(csv, "{PRECISION},{},{np},{ms},{first}", k.name());
                }
                None => print!(" {:>12}", "—"),
            }
        }
        let slope = (xy.len() == costs.len())
            .then(|| study::least_squares_slope(&xy))
            .flatten();
        println!(" {:>7}", slope.map_or("—".into(), |p| format!("{p:.2}")));
    }
    let _ = std::fs::write(out.join("resolution.csv"), csv);
    headless::save(
        out,
        "resolution",
        (900, 600),
        &ResolutionChart(&rows, &particles),
    );
}

/// A method and its cost to the target at each size (ms per simulated second, and whether
/// that is an upper bound).
type CostRow = (IntegratorKind, Vec<Option<(f64, bool)>>);
type CostRows = [CostRow];

struct ResolutionChart<'a>(&'a CostRows, &'a [usize]);

impl headless::Chart for ResolutionChart<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, plotters::coord::Shift>,
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        let (rows, particles) = (self.0, self.1);
        let all: Vec<f64> = rows
            .iter()
            .flat_map(|(_, c)| c.iter().flatten().map(|(ms, _)| *ms))
            .collect();
        let (y0, y1) = all
            .iter()
            .fold((f64::MAX, 0.0f64), |(a, b), v| (a.min(*v), b.max(*v)));
        let (y0, y1) = if all.is_empty() {
            (1.0, 10.0)
        } else {
            (y0 / 2.0, y1 * 2.0)
        };
        let (x0, x1) = (
            *particles.first().unwrap_or(&1) as f64 / 1.5,
            *particles.last().unwrap_or(&1) as f64 * 1.5,
        );
        root.fill(&WHITE)?;
        let mut c = ChartBuilder::on(&root)
            .caption(
                format!("cloth: cost to reach {TARGET:.0e} m at T = 0.5 s ({PRECISION})"),
                ("sans-serif", 22),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())?;
        c.configure_mesh()
            .x_desc("particles (hollow: upper bound, met at the largest stable step)")
            .y_desc("wall ms per simulated second (one core)")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.1}"))
            .draw()?;
        for (i, (kind, costs)) in rows.iter().enumerate() {
            let marked: Vec<((f64, f64), bool)> = costs
                .iter()
                .zip(particles)
                .filter_map(|(c, n)| c.map(|(ms, bound)| ((*n as f64, ms), bound)))
                .collect();
            if marked.is_empty() {
                continue;
            }
            let color = headless::PALETTE[i % headless::PALETTE.len()];
            c.draw_series(LineSeries::new(
                marked.iter().map(|m| m.0),
                color.stroke_width(2),
            ))?
            .label(kind.label())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2))
            });
            // Filled: interpolated to the target; hollow: an upper bound (the largest stable step
            // already meets it).
            c.draw_series(marked.iter().map(|(p, bound)| {
                let style = if *bound {
                    color.stroke_width(2)
                } else {
                    color.filled()
                };
                Circle::new(*p, 4, style)
            }))?;
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

/// One problem's sweep, ready to print and chart.
struct Run {
    name: String,
    horizon: f64,
    ref_err: f64,
    kinds: Vec<IntegratorKind>,
    points: Vec<WorkPoint>,
}

impl Run {
    /// Prints the table and the measured orders, appends to the CSV, draws the two charts.
    fn report(&self, out: &Path, csv: &mut String) {
        let floor = study::error_floor(self.ref_err);
        println!(
            "\n{} ({PRECISION}), T = {} s, reference cross-check {:.1e}, error floor {floor:.1e}",
            self.name, self.horizon, self.ref_err
        );
        println!(
            "{:<34} {:>10} {:>11} {:>8} {:>7} {:>9}",
            "method", "h / tol", "error", "evals", "solves", "ms"
        );
        for p in &self.points {
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
                self.name,
                p.method.name(),
                p.h,
                p.error.map_or("diverged".into(), |e| e.to_string()),
                p.evaluations,
                p.linear_solves,
                p.seconds
            );
        }
        let orders: Vec<(IntegratorKind, Option<f64>)> = self
            .kinds
            .iter()
            .filter(|k| !k.is_adaptive())
            .map(|k| {
                let tail = study::stable_tail(&self.points, *k);
                (*k, study::measured_order(&tail, *k, floor, 0.1))
            })
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
            let chart = WorkChart {
                frame: frame(self, cost),
                points: &self.points,
                orders: &orders,
            };
            headless::save(out, &format!("{}{suffix}", self.name), (900, 600), &chart);
        }
    }
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

/// The axes and title of `run`'s chart against `cost`.
fn frame(run: &Run, cost: Cost) -> Frame {
    let points = &run.points;
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
    Frame {
        title: format!(
            "{}: error at T = {} s vs cost ({PRECISION})",
            run.name, run.horizon
        ),
        x: (x0, x1),
        y: (y0 / 3.0, y1 * 30.0),
        cost,
    }
}

struct WorkChart<'a> {
    frame: Frame,
    points: &'a [WorkPoint],
    orders: &'a [(IntegratorKind, Option<f64>)],
}

struct Frame {
    title: String,
    x: (f64, f64),
    y: (f64, f64),
    cost: Cost,
}

impl headless::Chart for WorkChart<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, plotters::coord::Shift>,
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        let (frame, points, orders) = (&self.frame, self.points, self.orders);
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
                    pts.iter().filter(|p| p.error.is_none()).map(|p| {
                        Cross::new((frame.cost.of(p), y1 / 1.5), 5, color.stroke_width(2))
                    }),
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
}
