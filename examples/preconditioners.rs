//! PCG's preconditioners side by side: block-Jacobi against the default (`Preconditioner::Auto`,
//! the aggregation multigrid from 4096 particles) on the seed cloth at 64² and 128² and, when
//! `../shared/bench` is there, the shared bench's 64² cloth: linearly implicit Euler at PCG
//! tolerances 1e-6 and 1e-3 and Newton backward Euler, h = 1/60, on `--threads N` threads
//! (default: all cores; the solves' passes are shared, with the same bits). Each run takes
//! 30 warm-up steps, then five samples of six steps; prints the fastest sample and the mean
//! (ms per step), CG iterations per step and the speed-up, as a Markdown table. No window, no
//! keys.
//!
//! ```text
//! cargo run --release --no-default-features --features parallel --example preconditioners [-- --threads N]
//! ```

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::build;
use bevy_soft_body::core::integrate::{BackwardEuler, Integrator, LinearlyImplicitEuler};
use bevy_soft_body::core::ode::ParticleState;
use bevy_soft_body::core::particles::ParticleModel;
use bevy_soft_body::core::scene::Scene;
use bevy_soft_body::core::solve::{LinearSolver, Pcg, Preconditioner};
use bevy_soft_body::math::{PRECISION, Scalar};
use std::time::Instant;

type Boxed = Box<dyn Integrator<ParticleState, ParticleModel>>;

/// Linearly implicit Euler (`tolerance` given) or backward Euler (`None`) with `pre`.
fn method(pre: Preconditioner, tolerance: Option<Scalar>) -> Boxed {
    match tolerance {
        Some(tol) => Box::new(LinearlyImplicitEuler::with_solver(LinearSolver::Pcg(
            Pcg::new(tol, 500).with_preconditioner(pre),
        ))),
        None => {
            let mut be = BackwardEuler::default();
            be.solver = LinearSolver::Pcg(Pcg::default().with_preconditioner(pre));
            Box::new(be)
        }
    }
}

/// Fastest and mean ms per step over five samples of six steps (after 30 warm-up steps),
/// and CG iterations per step.
fn time(model: &ParticleModel, start: &ParticleState, mut integ: Boxed) -> (f64, f64, f64) {
    let h: Scalar = 1.0 / 60.0;
    let mut state = start.clone();
    let mut t = 0.0;
    let mut step = |integ: &mut Boxed, state: &mut ParticleState| {
        t += integ.step(model, t, h, state).expect("stable at h = 1/60");
    };
    for _ in 0..30 {
        step(&mut integ, &mut state);
    }
    integ.reset();
    let (mut best, mut total) = (f64::MAX, 0.0);
    for _ in 0..5 {
        let clock = Instant::now();
        for _ in 0..6 {
            step(&mut integ, &mut state);
        }
        let ms = clock.elapsed().as_secs_f64() * 1e3 / 6.0;
        best = best.min(ms);
        total += ms;
    }
    let st = integ.stats();
    (
        best,
        total / 5.0,
        st.linear_iterations as f64 / st.steps.max(1) as f64,
    )
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let threads = match args.iter().position(|a| a == "--threads") {
        Some(k) => match args.get(k + 1).and_then(|t| t.parse::<usize>().ok()) {
            Some(t) => t,
            None => {
                eprintln!("--threads: not a count");
                std::process::exit(2);
            }
        },
        None => 0,
    };
    bevy_soft_body::core::kernels::with_threads(threads, run);
}

fn run() {
    let threads = bevy_soft_body::core::kernels::current_threads();
    let mut cases: Vec<(String, ParticleModel, ParticleState)> = vec![];
    for n in [64, 128] {
        let p = build::ClothParams::default().resized(n, n);
        let (m, s) = build::cloth(&p)
            .expect("the seed cloth's parameters are valid")
            .build()
            .expect("the seed cloth builds");
        cases.push((format!("seed cloth {n}²"), m, s));
    }
    match std::fs::read_to_string("../shared/bench/cloth_64.json")
        .map_err(|e| e.to_string())
        .and_then(|text| Scene::from_json(&text).map_err(|e| e.to_string()))
        .and_then(|scene| scene.build().map_err(|e| e.to_string()))
    {
        Ok((m, s)) => cases.push(("bench cloth_64.json".into(), m, s)),
        Err(e) => eprintln!("../shared/bench/cloth_64.json left out: {e}"),
    }
    println!(
        "PCG preconditioners, h = 1/60, {PRECISION}, {threads} thread(s); ms per step (fastest, mean of 5 × 6 steps) and CG iterations per step"
    );
    println!();
    println!("| system | particles | method | tolerance | block-Jacobi | default | speed-up |");
    println!("| --- | ---: | --- | ---: | ---: | ---: | ---: |");
    for (name, model, start) in &cases {
        let runs: [(&str, Option<Scalar>); 3] = [
            ("linearly implicit Euler", Some(1e-6)),
            ("linearly implicit Euler", Some(1e-3)),
            ("backward Euler (Newton)", None),
        ];
        for (label, tol) in runs {
            let (jb, jm, ji) = time(model, start, method(Preconditioner::BlockJacobi, tol));
            let (ab, am, ai) = time(model, start, method(Preconditioner::Auto, tol));
            let tol = tol.map_or("default".to_string(), |t| format!("{t:.0e}"));
            println!(
                "| {name} | {} | {label} | {tol} | {jb:.2} ({jm:.2}), {ji:.1} its | {ab:.2} ({am:.2}), {ai:.1} its | {:.2}× |",
                model.len(),
                jb / ab
            );
        }
    }
}
