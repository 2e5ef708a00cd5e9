//! XPBD and projective dynamics against the spring model they integrate: XPBD converges to
//! its trajectory at first order and hangs a mass at exactly `m g / k`; projective dynamics'
//! local/global iterations never raise its incremental potential and converge to backward
//! Euler's step (the Newton solver, an independent computation of the same minimizer); both
//! stay bounded at a game's step where explicit methods blow up; tet bodies get an error.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::build::{self, ChainParams, ClothParams};
use bevy_soft_body::core::driver::{DriverConfig, Simulation, StepPolicy};
use bevy_soft_body::core::fem::NeoHookean;
use bevy_soft_body::core::fem::mesh::TetMesh;
use bevy_soft_body::core::integrate::{
    BackwardEuler, Integrator, IntegratorKind, ProjectiveDynamics, StepError,
};
use bevy_soft_body::core::ode::{OdeSystem, ParticleState};
use bevy_soft_body::core::particles::ParticleModel;
use bevy_soft_body::core::solve::LinearSolver;
use bevy_soft_body::core::study::{self, Problem};
use bevy_soft_body::math::Scalar;

const F64: bool = cfg!(feature = "f64");

/// The order of XPBD and projective dynamics on the 4-particle pendulum, undamped and with
/// spring dampers, measured against the study's reference (RK4 at a step far below the
/// sweep, cross-checked at half that step), on the work-precision study's full sweep.
#[test]
fn xpbd_and_projective_dynamics_converge_to_the_spring_models_trajectory_at_first_order() {
    for problem in [
        Problem::Pendulum { damped: false },
        Problem::Pendulum { damped: true },
    ] {
        let (_, reference_error) = study::reference(problem, false);
        let floor = study::error_floor(reference_error);
        let kinds = [IntegratorKind::Xpbd, IntegratorKind::ProjectiveDynamics];
        let points = study::work_precision(problem, &kinds, false);
        for kind in kinds {
            for p in points.iter().filter(|p| p.method == kind) {
                println!(
                    "{:<16} {:<22} h = {:.3e}  error {:>10}",
                    problem.name(),
                    kind.label(),
                    p.h,
                    p.error.map_or("diverged".into(), |e| format!("{e:.3e}"))
                );
            }
            let order = study::measured_order(&points, kind, floor, 0.1);
            println!(
                "{} {}: measured order {order:?}",
                problem.name(),
                kind.name()
            );
            let p = order.expect("measurable order");
            // Theory: first order (see the module docs of `core::integrate::position`); the
            // same ±0.15 band the study's test gives every method.
            assert!(
                (p - 1.0).abs() < 0.15,
                "{} {kind}: order {p:.2}",
                problem.name()
            );
        }
    }
}

/// One pinned particle and one hanging from it by a spring; drag lets it settle.
fn hanging(k: f64, m: f64) -> (ParticleModel, ParticleState) {
    build::chain(&ChainParams {
        particles: 2,
        link: 0.5,
        mass: m,
        stiffness: k,
        damping: 0.0,
        drag: 0.5,
        direction: [0.0, -1.0, 0.0],
        gravity: true,
    })
    .unwrap()
    .build()
    .unwrap()
}

/// A simulation of `model` by `kind` at fixed step `h` in 1/60 s frames, `frames` of them run.
fn simulate(
    model: ParticleModel,
    state: ParticleState,
    kind: IntegratorKind,
    h: f64,
    frames: usize,
) -> Simulation<ParticleState, ParticleModel> {
    let mut sim = Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: kind,
            policy: StepPolicy::Fixed { h },
            frame_dt: 1.0 / 60.0,
            ..Default::default()
        },
    );
    for _ in 0..frames {
        sim.advance_frame().expect("stays bounded");
    }
    sim
}

/// XPBD's equilibrium is exact whatever the step: with `λ` reset each step and one sweep,
/// a particle at rest satisfies `w (C + h² g) / (w + α̃) = h² g`, i.e. `C = α g / w = m g / k`.
/// Projective dynamics at rest minimizes `g` with `y = x + h² g`, whose minimizer is the
/// static equilibrium (to its iteration's convergence).
#[test]
fn a_hanging_mass_rests_at_m_g_over_k_under_xpbd_and_projective_dynamics() {
    let (k, m) = (50.0, 0.2);
    let expected = m * 9.81 / k;
    for kind in [IntegratorKind::Xpbd, IntegratorKind::ProjectiveDynamics] {
        for h in [1.0 / 60.0, 1.0 / 600.0] {
            let (model, state) = hanging(k, m);
            let g = model.gravity.length() as f64;
            let sim = simulate(model, state, kind, h, 600);
            let stretch = (sim.state.x[1] - sim.state.x[0]).length() as f64 - 0.5;
            let exact = expected * g / 9.81;
            println!("{kind} h = {h:.4}: stretch {stretch:.6} m, m g/k = {exact:.6} m");
            // f32: positions near 0.5 m carry ~3e-8 m of round-off; 1e-5 relative leaves room
            // for the settling's remaining motion after 10 s with drag.
            let tol = if F64 { 1e-6 } else { 1e-4 };
            assert!(
                (stretch - exact).abs() < tol * exact.max(1.0),
                "{kind} h = {h}: {stretch} vs {exact}"
            );
        }
    }
}

/// A pinned 20×20 cloth at a game's step (h = 1/60 s, 10 iterations): in every step of three
/// seconds the local/global iterations lower `g` monotonically (up to f64 round-off of the
/// sum, 1e-12 relative) and end below where they started.
#[test]
fn projective_dynamics_iterations_never_raise_the_incremental_potential() {
    let (model, state) = build::cloth(&ClothParams::default())
        .unwrap()
        .build()
        .unwrap();
    let mut pd = ProjectiveDynamics::default();
    pd.trace = true;
    let mut state = state;
    let h: Scalar = 1.0 / 60.0;
    let mut t = 0.0;
    let mut worst_rise = 0.0f64;
    let mut total_drop = 0.0f64;
    for step in 0..180 {
        model.apply_constraints(t, &mut state);
        Integrator::<ParticleState, ParticleModel>::step(&mut pd, &model, t, h, &mut state)
            .unwrap();
        t += h;
        let g = pd.objectives();
        assert_eq!(g.len(), 11);
        for w in g.windows(2) {
            let rise = (w[1] - w[0]) / w[0].abs().max(1e-300);
            worst_rise = worst_rise.max(rise);
            assert!(
                w[1] <= w[0] + 1e-12 * w[0].abs(),
                "step {step}: g rose from {} to {}",
                w[0],
                w[1]
            );
        }
        assert!(g[10] < g[0], "step {step}: no progress {g:?}");
        total_drop += g[0] - g[10];
    }
    assert!(state.x.iter().all(|x| x.is_finite()));
    assert_eq!(pd.factorizations, 1, "one factorization for a fixed h");
    println!("largest relative rise {worst_rise:e}; summed drop {total_drop:e}");
}

/// Converged, projective dynamics is backward Euler: one h = 1/60 step of a swinging cloth,
/// against the Newton solver (sparse Cholesky, tolerance far below the differences shown),
/// gets closer with every doubling of the iterations.
#[test]
fn projective_dynamics_converges_to_the_backward_euler_step() {
    let mut scene = build::cloth(&ClothParams {
        damping: 0.05,
        ..Default::default()
    })
    .unwrap();
    scene.drag = 0.01;
    let (model, state) = scene.build().unwrap();
    // A few symplectic Euler frames first, so the cloth moves and springs stretch.
    let mut sim = Simulation::new(
        model.clone(),
        state,
        DriverConfig {
            integrator: IntegratorKind::SymplecticEuler,
            policy: StepPolicy::Fixed { h: 1e-3 },
            frame_dt: 0.05,
            ..Default::default()
        },
    );
    for _ in 0..6 {
        sim.advance_frame().unwrap();
    }
    let start = sim.state.clone();
    let t = sim.time;
    let h: Scalar = 1.0 / 60.0;
    let mut be = BackwardEuler::default();
    be.solver = LinearSolver::cholesky();
    be.tolerance = if F64 { 1e-10 } else { 1e-5 };
    be.max_iterations = 100;
    let mut exact = start.clone();
    model.apply_constraints(t, &mut exact);
    Integrator::<ParticleState, ParticleModel>::step(&mut be, &model, t, h, &mut exact).unwrap();
    let moved = exact
        .x
        .iter()
        .zip(&start.x)
        .map(|(a, b)| (*a - *b).length() as f64)
        .fold(0.0, f64::max);
    // Near the f32 floor the Newton solution itself is only good to about its tolerance.
    let floor = if F64 { 1e-9 } else { 1e-6 };
    let mut last = f64::INFINITY;
    let mut errors = vec![];
    for iterations in [1, 2, 4, 8, 16, 32, 64, 128] {
        let mut pd = ProjectiveDynamics::default();
        pd.iterations = iterations;
        let mut s = start.clone();
        model.apply_constraints(t, &mut s);
        Integrator::<ParticleState, ParticleModel>::step(&mut pd, &model, t, h, &mut s).unwrap();
        let err =
            s.x.iter()
                .zip(&exact.x)
                .map(|(a, b)| (*a - *b).length() as f64)
                .fold(0.0, f64::max);
        println!(
            "{iterations:>4} iterations: {err:.3e} m from backward Euler (step moved {moved:.3e} m)"
        );
        errors.push(err);
        assert!(
            err < last || err < floor,
            "{iterations} iterations: {err} after {last}"
        );
        last = err;
    }
    assert!(last < floor, "{errors:?}");
}

/// The largest strain `l/L − 1` over the springs.
fn largest_strain(model: &ParticleModel, x: &[bevy_soft_body::math::Vector]) -> f64 {
    model
        .springs
        .as_slice()
        .iter()
        .map(|s| ((x[s.i as usize] - x[s.j as usize]).length() / s.rest - 1.0) as f64)
        .fold(0.0, f64::max)
}

/// Runs the pinned cloth for 5 s at step `h`; returns the largest total energy over the run,
/// the kinetic energy and largest strain at the end, or `None` when it diverged.
fn cloth_run(kind: IntegratorKind, h: f64) -> Option<(f64, f64, f64, f64)> {
    let (model, state) = build::cloth(&ClothParams::default())
        .unwrap()
        .build()
        .unwrap();
    let mut sim = simulate(model.clone(), state, kind, h, 0);
    let e0 = model.energy(0.0, &sim.state).unwrap().total() as f64;
    let mut highest = f64::NEG_INFINITY;
    for _ in 0..300 {
        sim.advance_frame().ok()?;
        assert!(sim.state.x.iter().all(|x| x.is_finite()));
        highest = highest.max(model.energy(0.0, &sim.state).unwrap().total() as f64);
    }
    let end = model.energy(0.0, &sim.state).unwrap();
    let strain = largest_strain(&model, &sim.state.x);
    println!(
        "{:<22} h = 1/{:<4.0}: start energy {e0:.3} J, highest {highest:.3} J, end kinetic {:.2e} J, largest strain {strain:.4}",
        kind.label(),
        1.0 / h,
        end.kinetic
    );
    Some((e0, highest, end.kinetic as f64, strain))
}

/// At h = 1/60 s a pinned cloth blows up under symplectic Euler (its fastest mode has
/// h ω ≈ 4 > 2); XPBD and projective dynamics stay bounded for 5 s and come to rest. Projective
/// dynamics (backward Euler) never gains energy of the spring model. XPBD's single sweep per
/// step is where its numerical softness shows: at h = 1/60 the cloth stretches far beyond the
/// spring model's sag (measured against symplectic Euler at a stable h = 1/600), and ten
/// substeps (its "small steps") bring the strain most of the way back.
#[test]
fn xpbd_and_projective_dynamics_stay_bounded_at_a_games_step() {
    assert!(
        cloth_run(IntegratorKind::SymplecticEuler, 1.0 / 60.0).is_none(),
        "symplectic Euler should diverge at h = 1/60 on this cloth"
    );
    let (_, _, _, reference_strain) =
        cloth_run(IntegratorKind::SymplecticEuler, 1.0 / 600.0).expect("stable at 1/600");
    let (e0, highest, kinetic, _) =
        cloth_run(IntegratorKind::ProjectiveDynamics, 1.0 / 60.0).expect("bounded");
    assert!(
        highest <= e0 + 1e-3 * e0.abs(),
        "PD gained energy: {highest} > {e0}"
    );
    assert!(kinetic < 1e-3 * e0.abs(), "PD at rest: kinetic {kinetic}");
    let (_, _, kinetic, coarse) = cloth_run(IntegratorKind::Xpbd, 1.0 / 60.0).expect("bounded");
    assert!(kinetic < 1e-3 * e0.abs(), "XPBD at rest: kinetic {kinetic}");
    let (_, _, _, fine) = cloth_run(IntegratorKind::Xpbd, 1.0 / 600.0).expect("bounded");
    assert!(
        coarse > fine && fine > reference_strain,
        "XPBD strain {coarse} at 1/60, {fine} at 1/600, spring model {reference_strain}"
    );
    assert!(
        fine - reference_strain < 0.5 * (coarse - reference_strain),
        "ten substeps should remove most of the excess strain: {coarse} → {fine} (model {reference_strain})"
    );
}

#[test]
fn tet_bodies_get_an_error_naming_the_method_not_a_step() {
    let mesh = TetMesh::tet_box([0.3, 0.2, 0.2], [3, 2, 2]).unwrap();
    let mat = NeoHookean {
        young: 2e5,
        poisson: 0.4,
        density: 1000.0,
    };
    let (model, state) = mesh.to_scene("box", mat).build().unwrap();
    for kind in [IntegratorKind::Xpbd, IntegratorKind::ProjectiveDynamics] {
        assert!(!kind.supports_elements());
        let mut integ: Box<dyn Integrator<ParticleState, ParticleModel>> =
            kind.build(Default::default());
        let mut s = state.clone();
        let r = integ.step(&model, 0.0, 0.01, &mut s);
        assert_eq!(r, Err(StepError::NeedsSprings(kind)));
        assert_eq!(s, state, "state unchanged");
        let msg = r.unwrap_err().to_string();
        assert!(msg.contains("springs only"), "{msg}");
    }
}
