//! Implicit integration: exact Jacobians against central finite differences, the assembled
//! system matrix, PCG with the constraint filter against a direct solve of the reduced system,
//! and linearly implicit Euler's stability where explicit methods fail.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::jacobian::Linearization;
use bevy_soft_body::core::scene::{ParticleDesc, SpringDesc};
use bevy_soft_body::core::solve::{Pcg, SpringMatrix};
use bevy_soft_body::prelude::*;

const F64: bool = cfg!(feature = "f64");

fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

/// A random network: springs stretched and compressed, both laws, dampers, drag and wind, one
/// pinned particle.
fn network(seed: u64, damping: bool) -> (ParticleModel, ParticleState) {
    let mut r = seed;
    let mut s = Scene {
        drag: 0.3,
        wind: Some(Wind {
            coefficient: 0.2,
            ..Default::default()
        }),
        ..Default::default()
    };
    let n = 8;
    for i in 0..n {
        s.particles.push(ParticleDesc {
            position: [lcg(&mut r), lcg(&mut r), lcg(&mut r)],
            velocity: [lcg(&mut r) - 0.5, lcg(&mut r) - 0.5, lcg(&mut r) - 0.5],
            mass: 0.1 + lcg(&mut r),
            pinned: i == 0,
        });
    }
    for k in 0..20 {
        let a = k % n;
        let b = (a + 1 + (lcg(&mut r) * (n - 1) as f64) as usize) % n;
        s.springs.push(SpringDesc {
            a,
            b,
            stiffness: 10.0 + 50.0 * lcg(&mut r),
            damping: if damping { 0.5 * lcg(&mut r) } else { 0.0 },
            // Rest lengths from 0.3 to 1.5: some springs stretched, some compressed.
            rest_length: Some(0.3 + 1.2 * lcg(&mut r)),
            law: if k % 3 == 0 {
                SpringLaw::Strain
            } else {
                SpringLaw::Hooke
            },
            kind: Default::default(),
        });
    }
    s.build().unwrap()
}

fn forces(model: &ParticleModel, st: &ParticleState) -> Vec<f64> {
    let mut f = vec![Vector::ZERO; st.len()];
    model.accumulate_forces(0.0, st, &mut f);
    f.iter()
        .flat_map(|v| [v.x as f64, v.y as f64, v.z as f64])
        .collect()
}

/// Central differences of the force with respect to positions (`wrt_x`) or velocities.
fn fd_jacobian(model: &ParticleModel, st: &ParticleState, wrt_x: bool, eps: f64) -> Vec<Vec<f64>> {
    let n = 3 * st.len();
    let mut j = vec![vec![0.0; n]; n];
    for c in 0..n {
        let mut plus = st.clone();
        let mut minus = st.clone();
        let (p, q) = if wrt_x {
            (&mut plus.x, &mut minus.x)
        } else {
            (&mut plus.v, &mut minus.v)
        };
        p[c / 3][c % 3] += eps as Scalar;
        q[c / 3][c % 3] -= eps as Scalar;
        let (fp, fm) = (forces(model, &plus), forces(model, &minus));
        for r in 0..n {
            j[r][c] = (fp[r] - fm[r]) / (2.0 * eps);
        }
    }
    j
}

fn max_rel_diff(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let scale = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

#[test]
fn jacobians_match_central_differences() {
    // Central differences have truncation error O(ε²) and round-off O(u/ε): in f64 with
    // ε = 1e-6 both are far below 1e-6 relative. In f32 (u ≈ 6e-8), ε = 1e-2 balances them at
    // ≈ 1e-3 relative, the bound used there.
    let (eps, tol) = if F64 { (1e-6, 1e-6) } else { (1e-2, 2e-2) };
    for seed in [1, 2, 3] {
        let (model, st) = network(seed, true);
        let (jx, jv) = model.dense_jacobians(&st);
        let ex = max_rel_diff(&jx, &fd_jacobian(&model, &st, true, eps));
        let ev = max_rel_diff(&jv, &fd_jacobian(&model, &st, false, eps));
        println!("seed {seed}: ∂f/∂x rel. error {ex:e}, ∂f/∂v rel. error {ev:e}");
        assert!(ex < tol && ev < tol, "seed {seed}: {ex:e} {ev:e}");
    }
}

#[test]
fn assembled_matrix_is_m_minus_h_dv_minus_h2_dx() {
    // Without dampers the position Jacobian is exactly what the implicit system uses (the
    // damper's position term is the only part left out), and with `definite = false` nothing
    // is clamped: A = M − h ∂f/∂v − h² ∂f/∂x, symmetric.
    let (model, st) = network(4, false);
    let h = 0.01;
    let mut a = model.new_matrix();
    let mut kv = vec![Vector::ZERO; st.len()];
    model.assemble(&st, h as Scalar, false, &mut a, &mut kv);
    let dense = a.to_dense();
    let (jx, jv) = model.dense_jacobians(&st);
    let n = dense.len();
    let tol = if F64 { 1e-12 } else { 1e-4 };
    for r in 0..n {
        for c in 0..n {
            let m = if r == c {
                model.mass()[r / 3] as f64
            } else {
                0.0
            };
            let want = m - h * jv[r][c] - h * h * jx[r][c];
            assert!(
                (dense[r][c] - want).abs() <= tol * (1.0 + want.abs()),
                "A[{r}][{c}] = {} vs {want}",
                dense[r][c]
            );
            assert!(
                (dense[r][c] - dense[c][r]).abs() <= tol * (1.0 + want.abs()),
                "symmetric"
            );
        }
        // K v from the dense ∂f/∂x.
        let kvr: f64 = (0..n).map(|c| jx[r][c] * st.v[c / 3][c % 3] as f64).sum();
        assert!((kv[r / 3][r % 3] as f64 - kvr).abs() <= tol * (1.0 + kvr.abs()));
    }
}

/// Gaussian elimination with partial pivoting (dense, for the reference solution).
#[allow(clippy::needless_range_loop)]
fn dense_solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for k in 0..n {
        let p = (k..n)
            .max_by(|&i, &j| a[i][k].abs().total_cmp(&a[j][k].abs()))
            .unwrap();
        a.swap(k, p);
        b.swap(k, p);
        for i in k + 1..n {
            let f = a[i][k] / a[k][k];
            for j in k..n {
                a[i][j] -= f * a[k][j];
            }
            b[i] -= f * b[k];
        }
    }
    let mut x = vec![0.0; n];
    for k in (0..n).rev() {
        x[k] = (b[k] - (k + 1..n).map(|j| a[k][j] * x[j]).sum::<f64>()) / a[k][k];
    }
    x
}

#[test]
fn filtered_pcg_equals_the_projected_reduced_solve() {
    // Baraff–Witkin's filter keeps pinned degrees of freedom out of the CG iteration; the
    // answer on the free ones must be the solution of the reduced system (pinned rows and
    // columns removed), computed here by dense elimination.
    let (model, st) = network(5, true);
    let h = 0.02 as Scalar;
    let mut a: SpringMatrix = model.new_matrix();
    let mut kv = vec![Vector::ZERO; st.len()];
    model.assemble(&st, h, true, &mut a, &mut kv);
    let mut mask = vec![0.0; st.len()];
    model.free_mask(&mut mask);
    assert_eq!(mask[0], 0.0, "particle 0 is pinned");
    let b: Vec<Vector> = (0..st.len())
        .map(|i| Vector::new(1.0, -2.0, 0.5) * (i as Scalar + 1.0))
        .collect();
    let tol = if F64 { 1e-10 } else { 1e-5 };
    let mut pcg = Pcg::new(tol as Scalar, 200);
    let mut x = vec![Vector::ZERO; st.len()];
    let rep = pcg.solve(&a, &b, &mut x, &mask);
    println!("{rep:?}");
    assert!(rep.converged, "{rep:?}");
    assert_eq!(x[0], Vector::ZERO, "filtered DOFs keep their value");

    let dense = a.to_dense();
    let free: Vec<usize> = (0..3 * st.len()).filter(|&r| mask[r / 3] == 1.0).collect();
    let ar: Vec<Vec<f64>> = free
        .iter()
        .map(|&r| free.iter().map(|&c| dense[r][c]).collect())
        .collect();
    let br: Vec<f64> = free.iter().map(|&r| b[r / 3][r % 3] as f64).collect();
    let xr = dense_solve(ar, br);
    let scale = xr.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (k, &r) in free.iter().enumerate() {
        let got = x[r / 3][r % 3] as f64;
        assert!(
            (got - xr[k]).abs() <= 100.0 * tol * scale,
            "dof {r}: {got} vs {}",
            xr[k]
        );
    }
}

fn cloth32() -> (ParticleModel, ParticleState) {
    // The 16×16 reference material at 32×32: 1 m square, 2.5 g per particle, k = 100/50/20 N/m,
    // dampers 0.05 N·s/m; its stiffest mode has ω ≈ 490 rad/s.
    let p = build::ClothParams::default().resized(32, 32);
    build::cloth(&p).unwrap().build().unwrap()
}

#[test]
fn linearly_implicit_euler_is_stable_where_explicit_methods_fail() {
    for h in [1.0 / 60.0, 0.1] {
        // h ω ≈ 8 and 49: far outside every explicit method's stability region.
        for kind in [IntegratorKind::ForwardEuler, IntegratorKind::Rk4] {
            let (model, state) = cloth32();
            let cfg = DriverConfig {
                integrator: kind,
                policy: StepPolicy::Fixed { h },
                frame_dt: h,
                ..Default::default()
            };
            let mut sim = Simulation::new(model, state, cfg);
            let err = sim
                .run_until(10.0)
                .expect_err("explicit methods must diverge here");
            println!("h = {h}: {err}");
        }
        let (model, state) = cloth32();
        let cfg = DriverConfig {
            integrator: IntegratorKind::LinearlyImplicitEuler,
            policy: StepPolicy::Fixed { h },
            frame_dt: h,
            ..Default::default()
        };
        let mut sim = Simulation::new(model, state, cfg);
        sim.run_until(10.0)
            .unwrap_or_else(|e| panic!("h = {h}: {e}"));
        let st = sim.stats();
        // After 10 s the damped cloth hangs nearly at rest below its pins.
        let vmax = sim
            .state
            .v
            .iter()
            .map(|v| v.length())
            .fold(0.0, Scalar::max);
        let lowest = sim
            .state
            .x
            .iter()
            .map(|x| x.y)
            .fold(Scalar::INFINITY, Scalar::min);
        println!(
            "h = {h}: linearly implicit Euler, {} steps, {:.1} CG iterations per step, max speed {vmax:.3} m/s, lowest point {lowest:.3} m",
            st.steps,
            st.linear_iterations as f64 / st.steps as f64
        );
        assert!(vmax < 0.5, "h = {h}: still moving at {vmax} m/s");
        assert!(
            lowest < 0.0 && lowest > -1.0,
            "h = {h}: lowest point {lowest}"
        );
    }
}

#[test]
fn implicit_methods_refuse_systems_without_jacobians() {
    use bevy_soft_body::core::integrate::Integrator;
    let mut integ: Box<dyn Integrator<Vector, CircleSystem>> =
        IntegratorKind::LinearlyImplicitEuler.build(AdaptiveConfig::default());
    let mut x = Vector::X;
    let r = integ.step(&CircleSystem, 0.0, 0.1, &mut x);
    assert_eq!(
        r,
        Err(StepError::NeedsJacobians(
            IntegratorKind::LinearlyImplicitEuler
        ))
    );
    assert_eq!(x, Vector::X);
}

#[test]
fn implicit_damping_trapezoid_is_stable_ten_times_past_the_damping_limit() {
    // A hanging chain of 10 particles (m = 10 g, Hooke k = 10 N/m, dampers b = 1 N·s/m, links
    // 0.1 m, no drag). Explicitly, damping alone limits h to about m/(2b) = 5 ms (stiffest
    // damping mode 4b/m = 400 s⁻¹, forward Euler needs h·400 < 2); the seed's elastic limit is
    // 2b/k = 0.2 s. At h = 0.05 — ten times the damping limit, a quarter of the elastic one —
    // forward Euler blows up and the implicit-damping trapezoid settles to the analytic static
    // equilibrium: link i carries 10 − i particles, total extension Σ (10−i) m g / k =
    // 45 · 0.01 · 9.81 / 10 = 0.441 m, bottom at y = −(0.9 + 0.441).
    let params = build::ChainParams {
        particles: 10,
        link: 0.1,
        mass: 0.01,
        stiffness: 10.0,
        damping: 1.0,
        drag: 0.0,
        direction: [0.0, -1.0, 0.0],
        gravity: true,
    };
    let h = 0.05;
    let run = |kind| {
        let (model, state) = build::chain(&params).unwrap().build().unwrap();
        let cfg = DriverConfig {
            integrator: kind,
            policy: StepPolicy::Fixed { h },
            frame_dt: h,
            ..Default::default()
        };
        let mut sim = Simulation::new(model, state, cfg);
        sim.run_until(20.0).map(|_| sim)
    };
    let err = run(IntegratorKind::ForwardEuler)
        .err()
        .expect("forward Euler must diverge at h = 0.05");
    println!("{err}");
    let sim = run(IntegratorKind::ImplicitDampingTrapezoid).unwrap_or_else(|e| panic!("{e}"));
    let bottom = sim.state.x[9].y as f64;
    let expected = -(0.9 + 45.0 * 0.01 * build::G / 10.0);
    let vmax = sim
        .state
        .v
        .iter()
        .map(|v| v.length())
        .fold(0.0, Scalar::max);
    let st = sim.stats();
    println!(
        "implicit-damping trapezoid at h = {h}: bottom {bottom:.5} m (static {expected:.5}), max speed {vmax:.2e}, {:.1} CG iterations per step",
        st.linear_iterations as f64 / st.steps as f64
    );
    assert!(
        (bottom - expected).abs() < 1e-3 * expected.abs(),
        "bottom {bottom} vs {expected}"
    );
    assert!(vmax < 1e-3);
}
