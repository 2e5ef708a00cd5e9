//! Automatic method and step against every fixed choice: on the chain, the seed cloth at 32²
//! and 64², the shared bench's 64² cloth (when `../shared/bench` is there), the jelly, the
//! soft bunny and the stiff armadillo, Auto's choice and reason, then the wall time per
//! simulated second of Auto and of each candidate method at 1, 2, 4, … 64 substeps per 1/60 s
//! frame that runs the scene for `--seconds` without diverging (the first frame untimed:
//! Auto's decision, a one-off cost per body and rebuild, is timed and printed apart). Prints
//! the table, the best fixed choice, and Auto's ratio to it. No window, no keys.
//!
//! ```text
//! cargo run --release --no-default-features --example auto [-- --seconds 1] [--scenes chain,jelly]
//! ```

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::auto::{self, AutoConfig, CANDIDATES};
use bevy_soft_body::core::build;
use bevy_soft_body::core::driver::{DriverConfig, Simulation, StepPolicy};
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::core::ode::{OdeSystem, ParticleState};
use bevy_soft_body::core::particles::ParticleModel;
use bevy_soft_body::core::scene::Scene;
use bevy_soft_body::core::study::{self, StabilityScene};
use bevy_soft_body::math::PRECISION;
use std::time::Instant;

#[path = "headless/mod.rs"]
mod headless;
use headless::{read, tet_body};

const FRAME: f64 = 1.0 / 60.0;

/// The scenes by name.
fn scene(name: &str) -> Option<(ParticleModel, ParticleState)> {
    Some(match name {
        "chain" => StabilityScene::Chain.build(false),
        "cloth16" => StabilityScene::Cloth.build(false),
        "jelly" => StabilityScene::Jelly.build(false),
        "cloth32" | "cloth64" => {
            let n = if name == "cloth32" { 32 } else { 64 };
            build::cloth(&build::ClothParams::default().resized(n, n))
                .ok()?
                .build()
                .ok()?
        }
        "bench_cloth64" => {
            let (_, text) = read("../shared/bench/cloth_64.json")?;
            Scene::from_json(&text).ok()?.build().ok()?
        }
        // The examples' materials: fem_bunny's soft rubber, fem_armadillo's stiff one.
        "bunny" => tet_body("bunny", 2e5, 0.4)?,
        "armadillo" => tet_body("armadillo", 1e6, 0.45)?,
        _ => return None,
    })
}

/// Runs `frames` frames; wall ms per simulated second, or `None` when it diverged.
fn run(
    model: ParticleModel,
    state: ParticleState,
    kind: IntegratorKind,
    substeps: u32,
    frames: u32,
) -> (Option<f64>, Simulation<ParticleState, ParticleModel>) {
    let mut sim = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: kind,
            policy: StepPolicy::Fixed {
                h: FRAME / substeps as f64,
            },
            frame_dt: FRAME,
            auto: AutoConfig::default(),
            ..Default::default()
        },
    );
    // The first frame is not timed: Auto decides in it (its one-off cost is printed apart),
    // and every method allocates its buffers there.
    if sim.advance_frame().is_err() {
        return (None, sim);
    }
    // Short runs are repeated (the best of up to five rounds of the same frames, each from
    // where the last ended) so that microsecond costs are not one timer's noise.
    let mut best = f64::INFINITY;
    let mut spent = 0.0;
    for _ in 0..5 {
        let start = Instant::now();
        for _ in 1..frames {
            if sim.advance_frame().is_err() {
                return (None, sim);
            }
        }
        let secs = start.elapsed().as_secs_f64();
        best = best.min(secs);
        spent += secs;
        if spent > 0.5 {
            break;
        }
    }
    (Some(best * 1e3 / ((frames - 1).max(1) as f64 * FRAME)), sim)
}

/// A cost with three significant digits.
fn fmt(x: f64) -> String {
    if x < 1.0 {
        format!("{x:.3}")
    } else {
        format!("{x:.1}")
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |k: &str| {
        args.iter()
            .position(|a| a == k)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let seconds: f64 = arg("--seconds").map_or(1.0, |s| s.parse().expect("--seconds"));
    let frames = (seconds / FRAME).round().max(2.0) as u32;
    let names = arg("--scenes").unwrap_or_else(|| {
        "chain,cloth16,cloth32,cloth64,bench_cloth64,jelly,bunny,armadillo".into()
    });
    println!(
        "Auto against fixed choices ({PRECISION}, one core, {seconds} s per run, 1/60 s frames)"
    );
    let mut summary = Vec::new();
    for name in names.split(',') {
        let Some((model, state)) = scene(name) else {
            println!("\n{name}: not available, skipped");
            continue;
        };
        let t = Instant::now();
        let lin = model.linearization().expect("particle model");
        let mode = auto::spectrum(lin, &state);
        let spectrum_ms = t.elapsed().as_secs_f64() * 1e3;
        let power = if model.tets.is_empty() {
            format!("{:.1}", study::fastest_mode(&model, &state).omega)
        } else {
            "—".into()
        };
        let t = Instant::now();
        let choice = auto::decide_for(
            lin,
            &state,
            FRAME,
            &AutoConfig::default(),
            1.0,
            model.prefers_direct_solver(),
            &[],
        );
        let decide_ms = t.elapsed().as_secs_f64() * 1e3;
        println!(
            "\n{name}: {} particles, {} springs, {} tets; ω (Lanczos) {:.1} rad/s, power iteration {power}; damping rate {:.2}/s; spectrum {spectrum_ms:.1} ms, decision {decide_ms:.1} ms",
            model.len(),
            model.springs.len(),
            model.tets.len(),
            mode.omega,
            mode.damping
        );
        println!("  auto: {}", choice.reason);
        println!("  | method | substeps | ms per simulated s | model ms per frame |");
        println!("  | --- | ---: | ---: | ---: |");
        let (auto_cost, sim) = run(
            model.clone(),
            state.clone(),
            IntegratorKind::Auto,
            1,
            frames,
        );
        let used = sim.auto_choice().map_or("—".into(), |c| {
            format!("{} ×{}", c.kind.name(), c.substeps)
        });
        println!(
            "  | **auto** ({used}) | | {} | {:.3} |",
            auto_cost.map_or("diverged".into(), fmt),
            choice.cost_ms
        );
        let mut best: Option<(f64, IntegratorKind, u32)> = None;
        for kind in CANDIDATES {
            if !model.tets.is_empty() && !kind.supports_elements() {
                continue;
            }
            let model_cost = |n: u32| {
                choice
                    .candidates
                    .iter()
                    .find(|c| c.kind == kind)
                    .map(|c| c.cost_ms / c.substeps as f64 * n as f64)
            };
            let mut n = 1;
            while n <= 64 {
                let (cost, _) = run(model.clone(), state.clone(), kind, n, frames);
                if let Some(c) = cost {
                    println!(
                        "  | {} | {n} | {} | {} |",
                        kind.name(),
                        fmt(c),
                        model_cost(n).map_or("—".into(), |m| format!("{m:.3}"))
                    );
                    if best.is_none_or(|b| c < b.0) {
                        best = Some((c, kind, n));
                    }
                    break; // more substeps only cost more
                }
                n *= 2;
            }
            if n > 64 {
                println!("  | {} | ≤ 64 | diverged at every count | |", kind.name());
            }
        }
        if let (Some(a), Some((b, kind, n))) = (auto_cost, best) {
            println!(
                "  best fixed: {} ×{n} at {} ms/s; auto / best = {:.2}",
                kind.name(),
                fmt(b),
                a / b
            );
            summary.push((
                name.to_string(),
                used,
                a,
                format!("{} ×{n}", kind.name()),
                b,
            ));
        }
    }
    println!(
        "\n| scene | auto's choice | auto ms/s | best fixed choice | its ms/s | auto / best |"
    );
    println!("| --- | --- | ---: | --- | ---: | ---: |");
    for (name, used, a, best, b) in summary {
        println!(
            "| {name} | {used} | {} | {best} | {} | {:.2} |",
            fmt(a),
            fmt(b),
            a / b
        );
    }
}
