//! Implicit integration: exact Jacobians against central finite differences, the assembled
//! system matrix, PCG with the constraint filter and the sparse Cholesky against a direct
//! solve of the reduced system, linearly implicit Euler's stability where explicit methods
//! fail, Newton backward Euler's convergence order, line search and dissipation, and bad input
//! as reported, contained failures.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::collide::{FaceHold, NormalHolds};
use bevy_soft_body::core::integrate::{BackwardEuler, Integrator};
use bevy_soft_body::core::jacobian::Linearization;
use bevy_soft_body::core::scene::{ParticleDesc, SpringDesc};
use bevy_soft_body::core::solve::{
    LinearSolver, Multigrid, Pcg, Preconditioner, SparseCholesky, SpringMatrix,
};
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
    // With `definite = false` nothing is clamped: A = M − h ∂f/∂v − h² ∂f/∂x, symmetric, with
    // ∂f/∂x without the damper's position term (the only part implicit steps leave out): the
    // position Jacobian of the same network with its dampers taken off.
    for damped in [false, true] {
        assembled_matrix_holds(damped);
    }
}

fn assembled_matrix_holds(damped: bool) {
    let (model, st) = network(4, damped);
    let h = 0.01;
    let mut a = model.new_matrix();
    let mut kv = vec![Vector::ZERO; st.len()];
    model.assemble(&st, h as Scalar, false, &mut a, &mut kv);
    let dense = a.to_dense();
    let (_, jv) = model.dense_jacobians(&st);
    let mut undamped = model.clone();
    for s in undamped.springs.as_mut_slice() {
        s.damping = 0.0;
    }
    let (jx, jv_undamped) = undamped.dense_jacobians(&st);
    if damped {
        assert!(
            jv.iter()
                .flatten()
                .zip(jv_undamped.iter().flatten())
                .any(|(a, b)| a != b),
            "the damped network has dampers"
        );
    }
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

/// The implicit matrices are filled on the team (each spring's block in chunks of springs,
/// then each row's diagonal and `K v` gathered from its springs in chunks of rows): the same
/// bits on one, two and three threads, and, to round-off, the matrix a plain scatter over the
/// springs builds from the public per-spring blocks (`spring_stiffness`, `damper_block`),
/// written here apart from the assembly. A 48² cloth (three chunks of rows, thirteen of
/// springs) with its particles jittered, so that some springs are compressed and the clamp of
/// the definite option acts, for the linearly implicit matrix (definite and not), the
/// damping-only matrix and backward Euler's Hessian.
#[cfg(feature = "parallel")]
#[test]
fn implicit_matrices_filled_on_the_team_are_the_scatter_on_any_number_of_threads() {
    use bevy_soft_body::core::jacobian::{damper_block, spring_stiffness};
    use bevy_soft_body::core::kernels::with_threads;
    use bevy_soft_body::math::{Matrix3, VectorExt};
    let p = build::ClothParams::default().resized(48, 48);
    let (model, mut st) = build::cloth(&p).unwrap().build().unwrap();
    let mut r = 5u64;
    let mut jitter = |s: f64| {
        Vector::new(
            (lcg(&mut r) - 0.5) as Scalar,
            (lcg(&mut r) - 0.5) as Scalar,
            (lcg(&mut r) - 0.5) as Scalar,
        ) * s as Scalar
    };
    let edge = (st.x[1] - st.x[0]).length() as f64;
    for i in 0..st.len() {
        st.x[i] += jitter(0.6 * edge);
        st.v[i] = jitter(2.0);
    }
    let x1: Vec<Vector> = st.x.iter().map(|x| *x + jitter(0.1 * edge)).collect();
    let h = 1.0 / 60.0;
    let n = st.len();
    let springs = model.springs.as_slice();
    let compressed = springs
        .iter()
        .filter(|s| ((st.x[s.i as usize] - st.x[s.j as usize]).length()) < s.rest)
        .count();
    assert!(
        compressed > springs.len() / 10,
        "{compressed} compressed springs"
    );
    // kind: 0 linearly implicit (not definite), 1 the same definite, 2 damping only,
    // 3 backward Euler's Hessian at x1.
    let fill = |kind: u32, threads: usize| {
        with_threads(threads, || {
            let mut a = model.new_matrix();
            let mut kv = vec![Vector::ZERO; n];
            match kind {
                0 | 1 => model.assemble(&st, h, kind == 1, &mut a, &mut kv),
                2 => model.assemble_damping(&st, h, &mut a),
                _ => model.assemble_incremental_hessian(h, &st.x, &x1, true, &mut a),
            }
            (a.diag.clone(), a.off.clone(), kv)
        })
    };
    for kind in 0..4 {
        let one = fill(kind, 1);
        for threads in [2, 3] {
            assert!(one == fill(kind, threads), "kind {kind}: {threads} threads");
        }
        // The scatter, in f64.
        let c = (model.linear_drag() * h) as f64;
        let mut diag: Vec<[f64; 9]> = model
            .mass()
            .iter()
            .map(|&m| {
                let d = m as f64 + c;
                [d, 0.0, 0.0, 0.0, d, 0.0, 0.0, 0.0, d]
            })
            .collect();
        let mut kv = vec![[0.0f64; 3]; n];
        let (h, h2) = (h as f64, (h * h) as f64);
        let as64 = |m: Matrix3| m.to_cols_array().map(|v| v as f64);
        for (k, s) in springs.iter().enumerate() {
            let (i, j) = (s.i as usize, s.j as usize);
            let (ks, ds) = match kind {
                3 => (
                    as64(spring_stiffness(s, &x1, true)),
                    as64(damper_block(s, &st.x)),
                ),
                _ => (
                    as64(spring_stiffness(s, &st.x, kind == 1)),
                    as64(damper_block(s, &st.x)),
                ),
            };
            let blk: [f64; 9] = std::array::from_fn(|e| {
                if kind == 2 {
                    h * ds[e]
                } else {
                    h * ds[e] + h2 * ks[e]
                }
            });
            let off = as64(one.1[k]);
            let scale = blk.iter().fold(1e-30f64, |m, v| m.max(v.abs()));
            let tol = if F64 { 1e-12 } else { 1e-5 };
            for e in 0..9 {
                assert!(
                    (off[e] + blk[e]).abs() <= tol * scale,
                    "kind {kind}, spring {k}: off-diagonal {:?} against −{blk:?}",
                    one.1[k]
                );
                diag[i][e] += blk[e];
                diag[j][e] += blk[e];
            }
            if kind < 2 {
                let vr = (st.v[i] - st.v[j]).to_f64();
                for q in 0..3 {
                    let u = (0..3).map(|c| ks[3 * c + q] * vr[c]).sum::<f64>();
                    kv[i][q] -= u;
                    kv[j][q] += u;
                }
            }
        }
        // Each row sums about a dozen blocks: round-off of a dozen terms of its largest.
        let tol = if F64 { 1e-12 } else { 1e-5 };
        for i in 0..n {
            let d = as64(one.0[i]);
            let scale = diag[i].iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for e in 0..9 {
                assert!(
                    (d[e] - diag[i][e]).abs() <= tol * scale,
                    "kind {kind}, row {i}: diagonal {d:?} against {:?}",
                    diag[i]
                );
            }
            if kind < 2 {
                let got = one.2[i].to_f64();
                let scale = springs.iter().fold(0.0f64, |m, s| m.max(s.k as f64)) * 4.0;
                for q in 0..3 {
                    assert!(
                        (got[q] - kv[i][q]).abs() <= tol * scale,
                        "kind {kind}, row {i}: K v {got:?} against {:?}",
                        kv[i]
                    );
                }
            }
        }
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

/// The random network's system at `h = 0.02` (assembled, with the pin's mask) and a
/// right-hand side growing with the particle's index.
fn network_system() -> (ParticleModel, SpringMatrix, Vec<Scalar>, Vec<Vector>) {
    let (model, st) = network(5, true);
    let n = st.len();
    let mut a: SpringMatrix = model.new_matrix();
    let mut kv = vec![Vector::ZERO; n];
    model.assemble(&st, 0.02, true, &mut a, &mut kv);
    let mut mask = vec![0.0; n];
    model.free_mask(&mut mask);
    assert_eq!(mask[0], 0.0, "particle 0 is pinned");
    let b: Vec<Vector> = (0..n)
        .map(|i| Vector::new(1.0, -2.0, 0.5) * (i as Scalar + 1.0))
        .collect();
    (model, a, mask, b)
}

#[test]
fn filtered_pcg_equals_the_projected_reduced_solve() {
    // Baraff–Witkin's filter keeps pinned degrees of freedom out of the CG iteration; the
    // answer on the free ones must be the solution of the reduced system (pinned rows and
    // columns removed), computed here by dense elimination.
    let (_, a, mask, b) = network_system();
    let n = b.len();
    let tol = if F64 { 1e-10 } else { 1e-5 };
    let mut pcg = Pcg::new(tol as Scalar, 200);
    let mut x = vec![Vector::ZERO; n];
    let rep = pcg.solve(&a, &b, &mut x, &mask);
    println!("{rep:?}");
    assert!(rep.converged, "{rep:?}");
    assert_eq!(x[0], Vector::ZERO, "filtered DOFs keep their value");

    let dense = a.to_dense();
    let free: Vec<usize> = (0..3 * n).filter(|&r| mask[r / 3] == 1.0).collect();
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

/// Two unit vectors spanning the plane normal to unit `n`.
fn plane_basis(n: [f64; 3]) -> [[f64; 3]; 2] {
    let a = if n[0].abs() < 0.6 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let d = a[0] * n[0] + a[1] * n[1] + a[2] * n[2];
    let u = [a[0] - d * n[0], a[1] - d * n[1], a[2] - d * n[2]];
    let l = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    let u = u.map(|c| c / l);
    let w = [
        n[1] * u[2] - n[2] * u[1],
        n[2] * u[0] - n[0] * u[2],
        n[0] * u[1] - n[1] * u[0],
    ];
    [u, w]
}

#[test]
fn direction_filtered_solves_equal_the_solve_on_the_free_directions() {
    // Particles held along a direction (a contact normal) keep their starting value's part
    // along it and are free across it. The reference: with `U` a basis of the free directions
    // (three axes per free particle, the plane normal to `n` per held one, none for the pin),
    // `x = x₀ + U y` with `(Uᵀ A U) y = Uᵀ (b − A x₀)`, by dense elimination.
    let (_, a, mask, b) = network_system();
    let n = b.len();
    // Particles 2 and 5 held along unit normals (their prescribed parts in the start value),
    // particle 6 along two.
    let mut r = 99u64;
    let mut unit = || {
        let v = [lcg(&mut r) - 0.5, lcg(&mut r) - 0.5, lcg(&mut r) - 0.5];
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|c| c / l)
    };
    let (n2, n5) = (unit(), unit());
    let n6 = [unit(), unit()];
    let mut holds = NormalHolds::default();
    let vec = |v: [f64; 3]| Vector::new(v[0] as Scalar, v[1] as Scalar, v[2] as Scalar);
    holds.raw.push((2, vec(n2), vec(n2) * 0.7, 0.0));
    holds.raw.push((5, vec(n5), vec(n5) * -1.3, 0.0));
    holds.raw.push((6, vec(n6[0]), Vector::ZERO, 0.0));
    holds.raw.push((6, vec(n6[1]), Vector::ZERO, 0.0));
    let mut x0 = vec![Vector::ZERO; n];
    holds.settle(None, &mut x0);
    assert_eq!(holds.filters.len(), 3);

    // The free basis, as dense columns.
    let mut cols: Vec<Vec<f64>> = vec![];
    let mut put = |i: usize, d: [f64; 3]| {
        let mut c = vec![0.0; 3 * n];
        c[3 * i..3 * i + 3].copy_from_slice(&d);
        cols.push(c);
    };
    // Particle 6's plane: normal to both its directions.
    let [p, q] = n6;
    let c6 = [
        p[1] * q[2] - p[2] * q[1],
        p[2] * q[0] - p[0] * q[2],
        p[0] * q[1] - p[1] * q[0],
    ];
    let l6 = (c6[0] * c6[0] + c6[1] * c6[1] + c6[2] * c6[2]).sqrt();
    for (i, m) in mask.iter().enumerate() {
        match i {
            _ if *m == 0.0 => {}
            2 => plane_basis(n2).into_iter().for_each(|d| put(i, d)),
            5 => plane_basis(n5).into_iter().for_each(|d| put(i, d)),
            6 => put(i, c6.map(|c| c / l6)),
            _ => (0..3).for_each(|k| {
                let mut d = [0.0; 3];
                d[k] = 1.0;
                put(i, d)
            }),
        }
    }
    let dense = a.to_dense();
    // The right-hand side above, and none at all: then only the prescribed parts' coupling
    // `−A x₀` is left to solve for (a held particle whose force is nothing but the hold). And
    // one nearly all along the holds, its free part 10⁻⁷ of them, as at static equilibrium
    // on colliders (the held parts are the contact forces): the filters leave round-off of
    // `ε ‖b‖` in the residual, far above the tolerance times `‖S b‖`. Before the solve took
    // that floor as converged, block-Jacobi broke down on it in `f32` (a non-finite
    // curvature at the seventh iteration).
    let mut resting: Vec<Vector> = b.iter().map(|v| *v * 1e-7).collect();
    for (i, d) in [(2, n2), (5, n5), (6, n6[0]), (6, n6[1])] {
        resting[i] += vec(d) * 1e3;
    }
    for (case, b) in [
        ("b", b.clone()),
        ("b = 0", vec![Vector::ZERO; n]),
        ("b at rest", resting),
    ] {
        let x0f: Vec<f64> = x0
            .iter()
            .flat_map(|v| (0..3).map(|k| v[k] as f64))
            .collect();
        let res: Vec<f64> = (0..3 * n)
            .map(|r| b[r / 3][r % 3] as f64 - (0..3 * n).map(|c| dense[r][c] * x0f[c]).sum::<f64>())
            .collect();
        let au: Vec<Vec<f64>> = cols
            .iter()
            .map(|u| {
                (0..3 * n)
                    .map(|r| (0..3 * n).map(|c| dense[r][c] * u[c]).sum())
                    .collect()
            })
            .collect();
        let ar: Vec<Vec<f64>> = cols
            .iter()
            .map(|u| {
                au.iter()
                    .map(|av| (0..3 * n).map(|r| u[r] * av[r]).sum())
                    .collect()
            })
            .collect();
        let br: Vec<f64> = cols
            .iter()
            .map(|u| (0..3 * n).map(|r| u[r] * res[r]).sum())
            .collect();
        let y = dense_solve(ar, br);
        let mut xr = x0f.clone();
        for (u, yk) in cols.iter().zip(&y) {
            for r in 0..3 * n {
                xr[r] += u[r] * yk;
            }
        }
        let scale = xr.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let tol = if F64 { 1e-10 } else { 1e-5 };
        // Either preconditioner, filtered (the multigrid of so few particles is its finest
        // level alone: damped block-Jacobi on the filtered blocks; its coarse levels are
        // checked on a cloth below).
        for pre in [Preconditioner::BlockJacobi, Preconditioner::Multigrid] {
            let mut pcg = Pcg::new(tol as Scalar, 200).with_preconditioner(pre);
            let mut x = x0.clone();
            let rep = pcg.solve_filtered(&a, &b, &mut x, &mask, &holds.filters);
            println!("{case}, {pre:?}: {rep:?}");
            assert!(rep.converged, "{case}, {pre:?}: {rep:?}");
            assert_eq!(pcg.active_preconditioner(), pre);
            // Unfiltered too: a multigrid forced on a system too small to coarsen once
            // panicked (its one level keeps no rows to factor).
            let mut y = vec![Vector::ZERO; n];
            assert!(
                pcg.solve(&a, &b, &mut y, &mask).converged,
                "{case}, {pre:?}"
            );
            for r in 0..3 * n {
                let got = x[r / 3][r % 3] as f64;
                assert!(
                    (got - xr[r]).abs() <= 100.0 * tol * scale,
                    "{case}, {pre:?}, dof {r}: {got} vs {}",
                    xr[r]
                );
            }
        }
        // The sparse Cholesky of the filtered system `S A S + (I − S)`: the same answer, to
        // round-off of a direct solve in f64 (the matrix's own entries are the precision's).
        let direct = if F64 { 1e-10 } else { 1e-4 };
        let mut chol = SparseCholesky::new();
        let mut x = x0.clone();
        let rep = chol.solve_filtered(&a, &b, &mut x, &mask, &holds.filters);
        println!("{case}, Cholesky: {rep:?}");
        assert!(rep.converged && !rep.failed, "{case}: {rep:?}");
        // (At rest the residual relative to `‖S b‖` is the filters' round-off: the answer
        // below is the check.)
        assert!(
            case == "b at rest" || rep.relative_residual <= direct as Scalar,
            "{case}: {rep:?}"
        );
        for r in 0..3 * n {
            let got = x[r / 3][r % 3] as f64;
            assert!(
                (got - xr[r]).abs() <= direct * scale,
                "{case}, Cholesky, dof {r}: {got} vs {}",
                xr[r]
            );
        }
        // Its factor serves the same filters again (modified Newton), and no others.
        let mut again = x0.clone();
        let rep = chol
            .resolve(&a, &b, &mut again, &mask, &holds.filters)
            .expect("the factor of these filters");
        assert!(rep.converged, "{case}: {rep:?}");
        assert_eq!(again, x, "{case}: the same factor, the same substitution");
        assert!(
            chol.resolve(&a, &b, &mut again, &mask, &holds.filters[1..])
                .is_none(),
            "{case}: a factor used for other filters"
        );
        assert!(
            chol.resolve(&a, &b, &mut again, &mask, &[]).is_none(),
            "{case}: a filtered factor used unfiltered"
        );
        // With no filters, the plain solve's bits.
        let (mut p, mut q) = (x0.clone(), x0.clone());
        let rp = SparseCholesky::new().solve(&a, &b, &mut p, &mask);
        let rq = chol.solve_filtered(&a, &b, &mut q, &mask, &[]);
        assert_eq!((p, rp), (q, rq), "{case}");
    }
}

/// Triangles held at points inside them ([`FaceHold`]: a row `Σ wⱼ n · xⱼ = n · v` on three
/// particles), on top of particles held along directions and a pin: the constrained solve
/// equals the solution of the whole system with the constraints as Lagrange multipliers,
/// `[A Kᵀ; K 0] [x; λ] = [b; k]`, by dense elimination (the reference knows nothing of
/// projections), with PCG and with the sparse Cholesky. One triangle has the pinned particle as a corner (its part of the row is
/// known), one a particle held along a direction, and one is given twice (the copy is
/// dropped as dependent; the reference has it once).
#[test]
fn point_rows_solve_equals_the_lagrange_multiplier_solve() {
    let (_, a, mask, b) = network_system();
    let n = b.len();
    let mut r = 42u64;
    let mut unit = || {
        let v = Vector::new(
            (lcg(&mut r) - 0.5) as Scalar,
            (lcg(&mut r) - 0.5) as Scalar,
            (lcg(&mut r) - 0.5) as Scalar,
        );
        v / v.length()
    };
    let mut holds = NormalHolds::default();
    let (n2, n6a, n6b) = (unit(), unit(), unit());
    holds.raw.push((2, n2, n2 * 0.7, 0.0));
    holds.raw.push((6, n6a, Vector::ZERO, 0.0));
    holds.raw.push((6, n6b, Vector::ZERO, 0.0));
    let faces = [
        ([1, 3, 4], [0.2, 0.5, 0.3], -0.4),
        ([3, 5, 7], [0.6, 0.1, 0.3], 0.25),
        ([0, 4, 5], [0.5, 0.25, 0.25], 0.1),
        ([2, 5, 7], [0.3, 0.3, 0.4], -0.6),
    ];
    let mut normals = vec![];
    for (ids, w, speed) in faces {
        let nrm = unit();
        normals.push(nrm);
        holds.faces.push(FaceHold {
            ids,
            weights: w,
            free: ids.map(|i| mask[i as usize] != 0.0),
            normal: nrm,
            velocity: nrm * speed,
            friction: 0.0,
        });
    }
    let copy = holds.faces[0];
    holds.faces.push(copy);
    // The pin's start value (its row's known part) and the start of the solve.
    let mut x0 = vec![Vector::ZERO; n];
    x0[0] = Vector::new(0.3, -0.2, 0.1);
    holds.settle(None, &mut x0);
    assert_eq!(holds.rows.kept(), faces.len(), "the copy dropped");

    // The reference: every constraint a row of `K`.
    let dense = a.to_dense();
    let mut k: Vec<(Vec<f64>, f64)> = vec![];
    let mut row = |parts: &[(usize, Vector, f64)], value: f64| {
        let mut v = vec![0.0; 3 * n];
        for &(i, d, w) in parts {
            for c in 0..3 {
                v[3 * i + c] += w * d[c] as f64;
            }
        }
        k.push((v, value));
    };
    for c in 0..3 {
        let mut e = Vector::ZERO;
        e[c] = 1.0;
        row(&[(0, e, 1.0)], x0[0][c] as f64);
    }
    row(&[(2, n2, 1.0)], 0.7);
    row(&[(6, n6a, 1.0)], 0.0);
    row(&[(6, n6b, 1.0)], 0.0);
    for ((ids, w, speed), nrm) in faces.iter().zip(&normals) {
        let parts: Vec<_> = (0..3)
            .map(|j| (ids[j] as usize, *nrm, w[j] as f64))
            .collect();
        row(&parts, *speed as f64);
    }
    // `[A Kᵀ; K 0] [x; λ] = [b; k]` solved densely, with the constraints' values or zero.
    let kkt_solve = |b: &[Vector], values: bool| {
        let m = 3 * n + k.len();
        let mut kkt = vec![vec![0.0; m]; m];
        let mut rhs = vec![0.0; m];
        for i in 0..3 * n {
            kkt[i][..3 * n].copy_from_slice(&dense[i]);
            rhs[i] = b[i / 3][i % 3] as f64;
        }
        for (q, (v, value)) in k.iter().enumerate() {
            for c in 0..3 * n {
                kkt[3 * n + q][c] = v[c];
                kkt[c][3 * n + q] = v[c];
            }
            rhs[3 * n + q] = if values { *value } else { 0.0 };
        }
        dense_solve(kkt, rhs)
    };
    let xr = kkt_solve(&b, true);
    let scale = xr[..3 * n].iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let tol = if F64 { 1e-10 } else { 1e-5 };
    for pre in [Preconditioner::BlockJacobi, Preconditioner::Multigrid] {
        let mut pcg = Pcg::new(tol as Scalar, 200).with_preconditioner(pre);
        let mut x = x0.clone();
        let rep = pcg.solve_constrained(&a, &b, &mut x, &mask, &holds.filters, &mut holds.rows);
        println!("{pre:?}: {rep:?}");
        assert!(rep.converged, "{pre:?}: {rep:?}");
        for q in 0..3 * n {
            let got = x[q / 3][q % 3] as f64;
            assert!(
                (got - xr[q]).abs() <= 100.0 * tol * scale,
                "{pre:?}, dof {q}: {got} vs {}",
                xr[q]
            );
        }
    }
    // The sparse Cholesky, by the rows' Schur complement: to round-off of a direct solve.
    let direct = if F64 { 1e-10 } else { 1e-4 };
    let mut x = x0.clone();
    let rep = SparseCholesky::new().solve_constrained(
        &a,
        &b,
        &mut x,
        &mask,
        &holds.filters,
        &mut holds.rows,
    );
    assert!(rep.converged && !rep.failed, "Cholesky: {rep:?}");
    for q in 0..3 * n {
        let got = x[q / 3][q % 3] as f64;
        assert!(
            (got - xr[q]).abs() <= direct * scale,
            "Cholesky, dof {q}: {got} vs {}",
            xr[q]
        );
    }
    // A Newton direction from a point on the constraints (backward Euler's): every value
    // zero, `C d = 0` (`zero_targets`), another right-hand side, solved from zero by PCG and
    // by the Cholesky's last factor (modified Newton, `resolve_constrained`).
    holds.rows.zero_targets();
    let b2: Vec<Vector> = (0..n).map(|_| unit() * 0.8).collect();
    let dr = kkt_solve(&b2, false);
    let scale = dr[..3 * n].iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut pcg = Pcg::new(tol as Scalar, 200);
    let mut d = vec![Vector::ZERO; n];
    let rep = pcg.solve_constrained(&a, &b2, &mut d, &mask, &holds.filters, &mut holds.rows);
    assert!(rep.converged, "direction, PCG: {rep:?}");
    let mut chol = SparseCholesky::new();
    let mut e = vec![Vector::ZERO; n];
    chol.solve_filtered(&a, &b, &mut e, &mask, &holds.filters);
    e.fill(Vector::ZERO);
    let rep = chol
        .resolve_constrained(&a, &b2, &mut e, &mask, &holds.filters, &mut holds.rows)
        .expect("the factor of the same matrix and filters");
    assert!(rep.converged && !rep.failed, "direction, Cholesky: {rep:?}");
    for q in 0..3 * n {
        let (p, c) = (d[q / 3][q % 3] as f64, e[q / 3][q % 3] as f64);
        assert!(
            (p - dr[q]).abs() <= 100.0 * tol * scale,
            "direction, PCG, dof {q}: {p} vs {}",
            dr[q]
        );
        assert!(
            (c - dr[q]).abs() <= direct * scale,
            "direction, Cholesky, dof {q}: {c} vs {}",
            dr[q]
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
    // damping mode 4b/m = 400 s⁻¹, forward Euler needs h·400 < 2); the cloth assignment's elastic limit is
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

fn flat(v: &[Vector]) -> Vec<f64> {
    v.iter()
        .flat_map(|v| [v.x as f64, v.y as f64, v.z as f64])
        .collect()
}

/// Backward Euler's objective and its gradient at `v` for a step of `h` from `st`.
fn objective(
    model: &ParticleModel,
    st: &ParticleState,
    h: Scalar,
    v: &[Vector],
) -> (f64, Vec<f64>) {
    let mut x = vec![Vector::ZERO; st.len()];
    let mut g = vec![Vector::ZERO; st.len()];
    let phi = model.incremental_potential(h, h, &st.x, &st.v, v, &mut x, Some(&mut g));
    (phi as f64, flat(&g))
}

#[test]
fn incremental_potential_gradient_and_hessian_match_central_differences() {
    // Same ε and bounds as the force Jacobians (see above). The network has both spring laws,
    // stretched and compressed springs, dampers (whose dissipation is quadratic in v along
    // their direction at x₀), drag, wind and a pinned particle.
    let (eps, tol) = if F64 { (1e-6, 1e-6) } else { (1e-2, 2e-2) };
    let h = 0.05 as Scalar;
    for seed in [1, 2, 3] {
        let (model, st) = network(seed, true);
        let mut v: Vec<Vector> = (0..st.len())
            .map(|i| st.v[i] + Vector::new(0.3, -0.2, 0.1) * (i as Scalar).sin())
            .collect();
        model.constrained_velocities(h, h, &st.x, &mut v);
        let (_, g) = objective(&model, &st, h, &v);
        let mut mask = vec![0.0; st.len()];
        assert!(model.free_mask(&mut mask));
        let free: Vec<usize> = (0..3 * st.len()).filter(|&r| mask[r / 3] == 1.0).collect();
        // Gradient against differences of Φ; Hessian against differences of the gradient.
        let mut x = vec![Vector::ZERO; st.len()];
        model.incremental_potential(h, h, &st.x, &st.v, &v, &mut x, None);
        let mut a = model.new_matrix();
        model.assemble_incremental_hessian(h, &st.x, &x, false, &mut a);
        let dense = a.to_dense();
        let (mut eg, mut gscale, mut eh, mut hscale) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for &c in &free {
            let (mut vp, mut vm) = (v.clone(), v.clone());
            vp[c / 3][c % 3] += eps as Scalar;
            vm[c / 3][c % 3] -= eps as Scalar;
            let ((pp, gp), (pm, gm)) = (
                objective(&model, &st, h, &vp),
                objective(&model, &st, h, &vm),
            );
            eg = eg.max(((pp - pm) / (2.0 * eps) - g[c]).abs());
            gscale = gscale.max(g[c].abs());
            for &r in &free {
                let fd = (gp[r] - gm[r]) / (2.0 * eps);
                eh = eh.max((fd - dense[r][c]).abs());
                hscale = hscale.max(dense[r][c].abs());
            }
        }
        let (eg, eh) = (eg / gscale, eh / hscale);
        println!("seed {seed}: ∇Φ rel. error {eg:e}, ∇²Φ rel. error {eh:e}");
        assert!(eg < tol && eh < tol, "seed {seed}: {eg:e} {eh:e}");
    }
}

/// A 5×5 sheet of particles (10 g) spaced 1.5× the rest length of the springs between
/// neighbours and diagonals (k = 100 N/m): every spring stretched by half its length, no
/// gravity, at rest. One backward Euler step of h = 0.1 has h²k/m = 100: far from linear.
fn stretched_sheet() -> (ParticleModel, ParticleState) {
    let mut s = Scene {
        gravity: [0.0; 3],
        ..Default::default()
    };
    let (n, rest) = (5usize, 0.1);
    for r in 0..n {
        for c in 0..n {
            s.particles.push(ParticleDesc {
                position: [1.5 * rest * c as f64, 1.5 * rest * r as f64, 0.0],
                velocity: [0.0; 3],
                mass: 0.01,
                pinned: false,
            });
        }
    }
    let mut link = |a: usize, b: usize, len: f64| {
        s.springs.push(SpringDesc {
            a,
            b,
            stiffness: 100.0,
            damping: 0.0,
            rest_length: Some(len),
            law: SpringLaw::Hooke,
            kind: Default::default(),
        })
    };
    for r in 0..n {
        for c in 0..n {
            let i = r * n + c;
            if c + 1 < n {
                link(i, i + 1, rest);
            }
            if r + 1 < n {
                link(i, i + n, rest);
            }
            if r + 1 < n && c + 1 < n {
                link(i, i + n + 1, rest * 2f64.sqrt());
            }
        }
    }
    s.build().unwrap()
}

#[test]
fn newton_backward_euler_converges_quadratically() {
    // Newton's method on a smooth objective with a positive definite Hessian at the minimum
    // converges quadratically once close: ‖g_{k+1}‖ ≤ C ‖g_k‖². Checked on every iteration that
    // starts close (‖g_k‖ < 10 % of ‖g₀‖) and ends above the round-off floor (100 u ‖g₀‖):
    // the constants C_k = ‖g_{k+1}‖/‖g_k‖² must agree within a factor 10 — under merely linear
    // convergence they would grow like 1/‖g_k‖, by 100× or more from one such iteration to the
    // next — and each of these iterations must cut the norm at least tenfold.
    let (model, mut st) = stretched_sheet();
    let mut be = BackwardEuler::new(LinearSolver::cholesky(), 40);
    be.tolerance = 0.0; // run to the round-off floor
    be.definite = false; // the exact Hessian (every spring stretched: the same here)
    Integrator::<ParticleState, ParticleModel>::step(&mut be, &model, 0.0, 0.1, &mut st).unwrap();
    let rep = be.last_newton();
    let g: Vec<f64> = rep.gradient_norms.iter().map(|&x| x as f64).collect();
    println!("gradient norms: {g:?}");
    let floor = 100.0 * (Scalar::EPSILON as f64) * g[0];
    let pairs: Vec<(f64, f64)> = g
        .windows(2)
        .filter(|w| w[0] < 0.1 * g[0] && w[1] > floor)
        .map(|w| (w[1] / (w[0] * w[0]), w[1] / w[0]))
        .collect();
    println!("C_k and reduction per close iteration: {pairs:?}");
    assert!(
        pairs.len() >= if F64 { 2 } else { 1 },
        "too few close iterations: {g:?}"
    );
    let (cmin, cmax) = pairs
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &(c, _)| {
            (a.min(c), b.max(c))
        });
    assert!(cmax <= 10.0 * cmin, "C_k {pairs:?}: not quadratic");
    assert!(pairs.iter().all(|&(_, r)| r <= 0.1), "{pairs:?}");
    assert!(*g.last().unwrap() < 1e-3 * g[0], "did not converge: {g:?}");
    // The line search never increased the objective.
    assert!(
        rep.objective.windows(2).all(|w| w[1] <= w[0]),
        "{:?}",
        rep.objective
    );
}

#[test]
fn backward_euler_line_search_never_increases_the_objective() {
    // The 32×32 cloth at h = 0.1 (h ω ≈ 49, see above): every Newton iteration's accepted
    // step satisfies Armijo's test, so the objective sequence of every step is non-increasing.
    let (model, mut st) = cloth32();
    let mut be = BackwardEuler::default();
    let h = 0.1 as Scalar;
    let (mut iters, mut halvings) = (0, 0);
    for k in 0..30 {
        let t = k as Scalar * h;
        model.apply_constraints(t, &mut st);
        Integrator::<ParticleState, ParticleModel>::step(&mut be, &model, t, h, &mut st).unwrap();
        let rep = be.last_newton();
        iters += rep.iterations;
        halvings += rep.halvings;
        assert!(
            rep.objective.windows(2).all(|w| w[1] <= w[0]),
            "step {k}: objective {:?}",
            rep.objective
        );
    }
    println!("30 steps: {iters} Newton iterations, {halvings} halvings");
    assert!(st.is_finite());
}

#[test]
fn backward_euler_dissipates_energy_on_an_undamped_system() {
    // An undamped pendulum chain released horizontally (no dampers, no drag): its total
    // energy (kinetic + spring + gravity) is conserved exactly by the ODE. Backward Euler's
    // step satisfies E(n+1) − E(n) ≤ −½ ‖v⁺ − vⁿ‖²_M for a convex potential (CSC417), so the
    // energy must never rise — beyond round-off and the Newton tolerance — and must visibly
    // fall: numerical damping at rate about h ω²/2.
    let params = build::ChainParams {
        particles: 6,
        drag: 0.0,
        ..Default::default()
    };
    let (model, state) = build::chain(&params).unwrap().build().unwrap();
    let h = 0.01;
    let cfg = DriverConfig {
        integrator: IntegratorKind::BackwardEuler,
        policy: StepPolicy::Fixed { h },
        frame_dt: h,
        ..Default::default()
    };
    let mut sim = Simulation::new(model, state, cfg);
    let energy = |s: &Simulation<ParticleState, ParticleModel>| {
        s.system.energy(s.time, &s.state).unwrap().total() as f64
    };
    let e0 = energy(&sim);
    let scale = sim.system.energy_scale(&sim.state).unwrap() as f64;
    let slack = if F64 { 1e-9 } else { 1e-4 } * scale;
    let mut prev = e0;
    let mut worst_rise = 0.0f64;
    for _ in 0..500 {
        sim.advance_frame().unwrap();
        let e = energy(&sim);
        worst_rise = worst_rise.max(e - prev);
        prev = e;
    }
    let st = sim.stats();
    println!(
        "E: {e0:.6} → {prev:.6} J over 5 s; largest rise in a step {worst_rise:.2e} J (slack {slack:.1e}); {:.2} Newton iterations per step",
        st.newton_iterations as f64 / st.steps as f64
    );
    assert!(worst_rise <= slack, "energy rose by {worst_rise:e}");
    assert!(
        prev < e0 - 0.01 * (e0.abs() + scale),
        "no visible dissipation"
    );
}

#[test]
fn sparse_cholesky_equals_the_reduced_dense_solve() {
    // Pinned particle 0 gets a known nonzero value: both solvers move its coupling to the
    // right-hand side (b_f − A_fc x_c) and keep it; the free part must match the dense
    // elimination of the reduced system to round-off, and PCG at a tight tolerance.
    let (model, st) = network(6, true);
    let h = 0.05 as Scalar;
    let mut a: SpringMatrix = model.new_matrix();
    let mut kv = vec![Vector::ZERO; st.len()];
    model.assemble(&st, h, true, &mut a, &mut kv);
    let mut mask = vec![0.0; st.len()];
    model.free_mask(&mut mask);
    let b: Vec<Vector> = (0..st.len())
        .map(|i| Vector::new(0.5, 1.0, -1.5) * (i as Scalar - 2.0))
        .collect();
    let known = Vector::new(0.2, -0.1, 0.3);
    let mut xc = vec![Vector::ZERO; st.len()];
    xc[0] = known;
    let mut chol = SparseCholesky::new();
    let rep = chol.solve(&a, &b, &mut xc, &mask);
    println!(
        "cholesky: {rep:?}, factor nonzeros {:?}",
        chol.factor_nonzeros()
    );
    assert!(rep.converged && !rep.failed);
    assert_eq!(xc[0], known);
    let tol = if F64 { 1e-12 } else { 1e-5 };
    let mut pcg = Pcg::new(tol as Scalar, 500);
    let mut xp = vec![Vector::ZERO; st.len()];
    xp[0] = known;
    assert!(pcg.solve(&a, &b, &mut xp, &mask).converged);

    let dense = a.to_dense();
    let free: Vec<usize> = (0..3 * st.len()).filter(|&r| mask[r / 3] == 1.0).collect();
    let ar: Vec<Vec<f64>> = free
        .iter()
        .map(|&r| free.iter().map(|&c| dense[r][c]).collect())
        .collect();
    let br: Vec<f64> = free
        .iter()
        .map(|&r| {
            b[r / 3][r % 3] as f64 - (0..3).map(|c| dense[r][c] * known[c] as f64).sum::<f64>()
        })
        .collect();
    let xr = dense_solve(ar, br);
    let scale = xr.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (k, &r) in free.iter().enumerate() {
        let (c, p) = (xc[r / 3][r % 3] as f64, xp[r / 3][r % 3] as f64);
        assert!(
            (c - xr[k]).abs() <= 100.0 * tol * scale,
            "dof {r}: cholesky {c} vs {}",
            xr[k]
        );
        assert!(
            (p - xr[k]).abs() <= 100.0 * tol * scale,
            "dof {r}: pcg {p} vs {}",
            xr[k]
        );
    }
    // The structure is analysed once; a second solve with new values reuses it.
    for d in a.diag.iter_mut() {
        *d *= 2.0;
    }
    chol.solve(&a, &b, &mut xc, &mask);
    assert_eq!(chol.analyses, 1);
}

/// Steps every implicit method once and expects a reported solver failure with the state
/// untouched.
fn expect_contained_failure(model: &ParticleModel, st: &ParticleState, kinds: &[IntegratorKind]) {
    for &kind in kinds {
        let mut integ: Box<dyn Integrator<ParticleState, ParticleModel>> =
            kind.build(AdaptiveConfig::default());
        let mut s = st.clone();
        let r = integ.step(model, 0.0, 0.1, &mut s);
        println!("{kind}: {r:?}");
        assert_eq!(r, Err(StepError::SolverFailed(kind)), "{kind}");
        assert_eq!(s.x, st.x, "{kind}: state changed");
        assert_eq!(s.v, st.v, "{kind}: state changed");
    }
}

#[test]
fn singular_and_indefinite_systems_are_reported_failures_with_the_state_kept() {
    let implicit = [
        IntegratorKind::LinearlyImplicitEuler,
        IntegratorKind::ImplicitDampingTrapezoid,
        IntegratorKind::BackwardEuler,
    ];
    let st = ParticleState {
        x: vec![Vector::ZERO, Vector::X, Vector::X * 2.0],
        v: vec![Vector::ZERO; 3],
    };
    // Free particles without mass (the model was never validated): singular.
    let mut massless = ParticleModel::new(vec![0.0, 0.0, 0.0]);
    massless
        .springs
        .push(0, 1, 1.0, 10.0, 0.0, SpringLaw::Hooke);
    expect_contained_failure(&massless, &st, &implicit);
    // A negative stiffness (and a negative damper): M − h D − h² K is indefinite.
    let mut negative = ParticleModel::new(vec![0.01; 3]);
    negative
        .springs
        .push(0, 1, 0.5, -1e4, -10.0, SpringLaw::Hooke);
    negative
        .springs
        .push(1, 2, 0.5, -1e4, -10.0, SpringLaw::Hooke);
    expect_contained_failure(&negative, &st, &implicit);
    // Through the driver: a reported divergence, the last good state kept, nothing NaN.
    let cfg = DriverConfig {
        integrator: IntegratorKind::LinearlyImplicitEuler,
        policy: StepPolicy::Fixed { h: 0.1 },
        frame_dt: 0.1,
        ..Default::default()
    };
    let mut sim = Simulation::new(negative, st.clone(), cfg);
    let err = sim.advance_frame().unwrap_err();
    println!("{err}");
    assert!(matches!(
        err.reason,
        DivergenceReason::Step(StepError::SolverFailed(_))
    ));
    assert_eq!(sim.state.x, st.x);
    assert!(sim.state.is_finite());
}

/// A large system as the implicit methods see it: `model` stepped `steps` times by linearly
/// implicit Euler at `h` from its start (so springs are stretched and bent, tets deformed), its
/// matrix assembled positive definite at `h`, the free mask with every 61st particle also
/// cut loose (as contacts hold particles), and a right-hand side of the step's form.
fn large_system(
    model: &ParticleModel,
    mut st: ParticleState,
    h: Scalar,
    steps: usize,
) -> (SpringMatrix, Vec<Vector>, Vec<Scalar>) {
    let mut integ = bevy_soft_body::core::integrate::LinearlyImplicitEuler::default();
    for k in 0..steps {
        integ.step(model, k as Scalar * h, h, &mut st).unwrap();
    }
    let mut a: SpringMatrix = model.new_matrix();
    let mut kv = vec![Vector::ZERO; st.len()];
    model.assemble(&st, h, true, &mut a, &mut kv);
    let mut mask = vec![0.0; st.len()];
    model.free_mask(&mut mask);
    for m in mask.iter_mut().step_by(61) {
        *m = 0.0;
    }
    let mut f = vec![Vector::ZERO; st.len()];
    model.total_forces(0.0, &st, &mut f);
    let b = f
        .iter()
        .zip(&kv)
        .zip(&mask)
        .map(|((f, kv), m)| (*f + *kv * h) * (h * *m))
        .collect();
    (a, b, mask)
}

/// Holds on a system's free particles (`mask` non-zero), as contacts hold them: every
/// `every`-th along a random unit direction `e` at the velocity `speed(k) e` (`k` its place
/// among those held), and every `second`-th of those along a second random direction too, at
/// rest; the directions drawn from `r`.
fn random_holds(
    mask: &[Scalar],
    (every, second): (usize, usize),
    r: &mut u64,
    speed: impl Fn(usize) -> Scalar,
) -> NormalHolds {
    let mut unit = || {
        let v = Vector::new(
            lcg(r) as Scalar - 0.5,
            lcg(r) as Scalar - 0.5,
            lcg(r) as Scalar - 0.5,
        );
        v / v.length()
    };
    let mut holds = NormalHolds::default();
    let free = (0..mask.len()).filter(|&i| mask[i] != 0.0);
    for (k, i) in free.step_by(every).enumerate() {
        let e = unit();
        holds.raw.push((i as u32, e, e * speed(k), 0.0));
        if k % second == 0 {
            holds.raw.push((i as u32, unit(), Vector::ZERO, 0.0));
        }
    }
    holds
}

/// `Σ uᵢ · vᵢ` in f64.
fn dot64(u: &[Vector], v: &[Vector]) -> f64 {
    u.iter().zip(v).map(|(a, b)| a.dot(*b) as f64).sum()
}

/// The multigrid's cycle `B` on ten pairs of random vectors `u, v` of the free degrees of
/// freedom (those of `mask`, then `filter`ed): symmetric, `uᵀBv = vᵀBu` to the round-off of a
/// product over the matrix (relative: f32 sums of thousands of terms), and positive,
/// `uᵀBu > 0`; `check` looks at each `Bu`.
fn check_cycle(
    name: &str,
    mg: &mut Multigrid,
    a: &SpringMatrix,
    mask: &[Scalar],
    r: &mut u64,
    filter: impl Fn(&mut [Vector]),
    mut check: impl FnMut(&[Vector]),
) {
    let n = a.len();
    let random = |r: &mut u64| -> Vec<Vector> {
        let mut v: Vec<Vector> = (0..n)
            .map(|i| {
                Vector::new(lcg(r) as Scalar, lcg(r) as Scalar, lcg(r) as Scalar) * (2.0 * mask[i])
                    - Vector::ONE * mask[i]
            })
            .collect();
        filter(&mut v);
        v
    };
    let (mut bu, mut bv) = (vec![Vector::ZERO; n], vec![Vector::ZERO; n]);
    let eps = if F64 { 1e-10 } else { 1e-4 };
    for _ in 0..10 {
        let (u, v) = (random(r), random(r));
        mg.apply(a, mask, &u, &mut bu);
        mg.apply(a, mask, &v, &mut bv);
        let (ubv, vbu) = (dot64(&u, &bv), dot64(&v, &bu));
        let scale = dot64(&u, &bu).abs().sqrt() * dot64(&v, &bv).abs().sqrt();
        assert!(
            (ubv - vbu).abs() <= eps * scale,
            "{name}: uᵀBv = {ubv}, vᵀBu = {vbu}"
        );
        assert!(dot64(&u, &bu) > 0.0, "{name}: uᵀBu ≤ 0");
        check(&bu);
    }
}

/// The multigrid V-cycle is what conjugate gradients needs of a preconditioner: symmetric
/// (`uᵀ B v = vᵀ B u`) and positive definite on the free degrees of freedom, zero on the
/// cut-loose ones; and conjugate gradients with it converge to the solution block-Jacobi's
/// converge to, with the true residual `b − A x` (the matrix's own product, computed apart
/// from the solver) within the tolerance. On a 64² cloth and on a box of tets (blocks that
/// are not symmetric). The symmetry check also checks the post-smoothing, which takes its
/// residual from `A P` (the blocks summed by aggregate) instead of a product by `A`: a block
/// transposed on the wrong side, or a column's cut-loose filter taken from the row, breaks it.
#[test]
fn multigrid_preconditioner_is_symmetric_positive_definite_and_solves() {
    let cloth = build::ClothParams::default().resized(64, 64);
    let (cm, cs) = build::cloth(&cloth).unwrap().build().unwrap();
    let mesh =
        bevy_soft_body::core::fem::mesh::TetMesh::tet_box([0.6, 0.2, 0.2], [24, 8, 8]).unwrap();
    let mat = bevy_soft_body::core::fem::NeoHookean {
        young: 2e5,
        poisson: 0.4,
        density: 1000.0,
    };
    let (tm, ts) = build::hung_tet_body(&mesh, mat, 2.0).build().unwrap();
    let h = 1.0 / 60.0;
    let mut r = 11u64;
    for (name, model, st) in [("cloth 64²", &cm, cs), ("tet box", &tm, ts)] {
        let (a, b, mask) = large_system(model, st, h, 10);
        let n = a.len();
        let mut mg = Multigrid::default();
        mg.setup(&a, &mask);
        println!("{name}: {n} particles, levels {:?}", mg.sizes());
        assert!(mg.levels() >= 3, "{name}: a hierarchy, not one level");
        check_cycle(
            name,
            &mut mg,
            &a,
            &mask,
            &mut r,
            |_| {},
            |bu| {
                for (z, m) in bu.iter().zip(&mask) {
                    if *m == 0.0 {
                        assert_eq!(*z, Vector::ZERO, "{name}: cut-loose particle moved");
                    }
                }
            },
        );

        let tol = if F64 { 1e-10 } else { 1e-5 };
        let solve = |pre: Preconditioner| {
            let mut pcg = Pcg::new(tol as Scalar, 2000).with_preconditioner(pre);
            let mut x = vec![Vector::ZERO; n];
            let rep = pcg.solve(&a, &b, &mut x, &mask);
            assert!(rep.converged, "{name} {pre:?}: {rep:?}");
            assert_eq!(pcg.active_preconditioner(), pre);
            (x, rep.iterations)
        };
        let (xm, im) = solve(Preconditioner::Multigrid);
        let (xj, ij) = solve(Preconditioner::BlockJacobi);
        println!("{name}: CG iterations, multigrid {im}, block-Jacobi {ij}");
        let mut ax = vec![Vector::ZERO; n];
        a.mul(&xm, &mut ax);
        let res: f64 = ax
            .iter()
            .zip(&b)
            .zip(&mask)
            .map(|((ax, b), m)| ((*b - *ax) * *m).length_squared() as f64)
            .sum::<f64>()
            .sqrt();
        let bn = dot64(&b, &b).sqrt();
        // The solver's residual is updated, not recomputed: allow the drift of its updates.
        assert!(
            res <= 10.0 * tol * bn,
            "{name}: ‖b − Ax‖ = {res:e}, ‖b‖ = {bn:e}"
        );
        let xs = xj.iter().fold(0.0f64, |m, x| m.max(x.length() as f64));
        let diff = xm
            .iter()
            .zip(&xj)
            .fold(0.0f64, |m, (p, q)| m.max((*p - *q).length() as f64));
        // Both within the tolerance of one solution; the matrix's conditioning (h²k/m up to
        // about 1000) magnifies a residual's tolerance into the solution's.
        assert!(
            diff <= 1e4 * tol * xs,
            "{name}: |x_mg − x_jacobi| = {diff:e}, |x| = {xs:e}"
        );
        // The point of the multigrid: measured 19 against 83 iterations on the cloth in f32,
        // 36 against 160 in f64 (26 and 50 with the earlier smoothing weight ω e = 2/3); it
        // must stay at least 2.5 times ahead.
        if name.starts_with("cloth") {
            assert!(
                5 * im <= 2 * ij,
                "{name}: multigrid {im} vs block-Jacobi {ij} iterations"
            );
        }
        // New values on the same structure: no new analysis.
        mg.setup(&a, &mask);
        assert_eq!(mg.analyses, 1);
    }
}

/// A cloth lying on the ground: every free particle of the 64² cloth's system held along
/// the same normal, with springs of 1, 10 and 100 times the cloth's. Each aggregate of the
/// multigrid then holds only particles held alike, so its block of `Pᵀ S A S P` is singular
/// along the normal; those blocks' inverses fell back to the identity and smoothed the coarse
/// level at the wrong scale, and from ten times the stiffness conjugate gradients broke down
/// at their first iteration. Now the multigrid's filtered solves converge, symmetric and
/// positive on the free directions, to the sparse Cholesky's answer of the same filtered
/// system (an independent direct solve) within the tolerance, and in fewer iterations than
/// block-Jacobi's (at the cloth's own stiffness, 17 against 78 in f32; 42 before).
#[test]
fn multigrid_solves_a_cloth_held_along_one_normal_everywhere() {
    let tol = if F64 { 1e-10 } else { 1e-5 };
    for scale in [1.0, 10.0, 100.0] {
        let mut p = build::ClothParams::default().resized(64, 64);
        p.k_structural *= scale;
        p.k_shear *= scale;
        p.k_flex *= scale;
        let (cm, cs) = build::cloth(&p).unwrap().build().unwrap();
        let (a, b, mask) = large_system(&cm, cs, 1.0 / 60.0, 3);
        let n = a.len();
        let mut holds = NormalHolds::default();
        for i in (0..n).filter(|&i| mask[i] != 0.0) {
            holds.raw.push((i as u32, Vector::Y, Vector::ZERO, 0.0));
        }
        let mut x0 = vec![Vector::ZERO; n];
        holds.settle(None, &mut x0);
        let filters = holds.filters.clone();
        let mut mg = Multigrid::default();
        mg.setup_filtered(&a, &mask, &filters);
        assert!(mg.levels() >= 3, "a hierarchy: {:?}", mg.sizes());
        let mut r = 11u64;
        let filter = |v: &mut [Vector]| {
            for &(i, s) in &filters {
                v[i as usize] = s * v[i as usize];
            }
        };
        check_cycle("held along y", &mut mg, &a, &mask, &mut r, filter, |_| {});
        let mut xc = x0.clone();
        let direct = SparseCholesky::new().solve_filtered(&a, &b, &mut xc, &mask, &filters);
        assert!(direct.converged, "k × {scale}: {direct:?}");
        let scale_x = xc.iter().fold(0.0f64, |m, v| m.max(v.length() as f64));
        let mut iterations = [0u32; 2];
        for (k, pre) in [Preconditioner::Multigrid, Preconditioner::BlockJacobi]
            .into_iter()
            .enumerate()
        {
            let mut pcg = Pcg::new(tol as Scalar, 3000).with_preconditioner(pre);
            let mut x = x0.clone();
            let rep = pcg.solve_filtered(&a, &b, &mut x, &mask, &filters);
            println!("k × {scale}, {pre:?}: {rep:?}");
            assert!(
                rep.converged && !rep.failed,
                "k × {scale}, {pre:?}: {rep:?}"
            );
            let err = x
                .iter()
                .zip(&xc)
                .fold(0.0f64, |m, (p, q)| m.max((*p - *q).length() as f64));
            assert!(
                err <= 100.0 * tol * scale_x,
                "k × {scale}, {pre:?}: {err} from the Cholesky's answer (largest entry {scale_x})"
            );
            iterations[k] = rep.iterations;
        }
        assert!(
            iterations[0] < iterations[1],
            "k × {scale}: multigrid {} against block-Jacobi {}",
            iterations[0],
            iterations[1]
        );
    }
}

/// The multigrid built on a filtered system ([`Multigrid::setup_filtered`]: particles held
/// along one or two directions, as contacts hold a cloth's triangles): on the 64² cloth's
/// system with every 23rd free particle held (every third of them along two directions), the
/// V-cycle is symmetric and positive definite on the free directions and maps them to
/// themselves (its answer has no part along a held direction beyond round-off); filtered
/// conjugate gradients with it converge, the true filtered residual `S (b − A x)` (the
/// matrix's own product, computed apart) within the tolerance, to the answer block-Jacobi's
/// give, with the prescribed parts kept, the same bits on one thread and two; and in far
/// fewer iterations, which is its point. Built on the unfiltered matrix and filtered after, the cycle took ten times as many
/// iterations on a cloth held on a rod, and diverged in f32.
#[test]
fn multigrid_on_a_filtered_system_keeps_the_free_directions_and_solves() {
    let cloth = build::ClothParams::default().resized(64, 64);
    let (cm, cs) = build::cloth(&cloth).unwrap().build().unwrap();
    let h = 1.0 / 60.0;
    let (a, b, mask) = large_system(&cm, cs, h, 10);
    let n = a.len();
    let mut r = 5u64;
    let mut holds = random_holds(&mask, (23, 3), &mut r, |k| 0.1 * (k % 5) as Scalar);
    let mut x0 = vec![Vector::ZERO; n];
    holds.settle(None, &mut x0);
    let filters = holds.filters.clone();
    println!("{} of {n} particles held", filters.len());
    assert!(filters.len() > 150);
    let filter = |v: &mut [Vector]| {
        for &(i, s) in &filters {
            v[i as usize] = s * v[i as usize];
        }
    };
    let mut mg = Multigrid::default();
    mg.setup_filtered(&a, &mask, &filters);
    assert!(mg.levels() >= 3, "a hierarchy: {:?}", mg.sizes());
    check_cycle("filtered", &mut mg, &a, &mask, &mut r, filter, |bu| {
        // No part along a held direction: `(I − S) z` is the projector's round-off of `z`.
        let size = bu.iter().fold(0.0f64, |m, z| m.max(z.length() as f64));
        for &(i, s) in &filters {
            let z = bu[i as usize];
            let off = (z - s * z).length() as f64;
            assert!(
                off <= if F64 { 1e-12 } else { 1e-5 } * size,
                "particle {i}: {off} along its held directions"
            );
        }
    });

    let tol = if F64 { 1e-10 } else { 1e-5 };
    let solve = |pre: Preconditioner| {
        let mut pcg = Pcg::new(tol as Scalar, 3000).with_preconditioner(pre);
        let mut x = x0.clone();
        let rep = pcg.solve_filtered(&a, &b, &mut x, &mask, &filters);
        assert!(rep.converged, "{pre:?}: {rep:?}");
        assert_eq!(pcg.active_preconditioner(), pre);
        (x, rep.iterations)
    };
    let (xm, im) = solve(Preconditioner::Multigrid);
    let (xj, ij) = solve(Preconditioner::BlockJacobi);
    println!("filtered: CG iterations, multigrid {im}, block-Jacobi {ij}");
    // The cycle's passes on the team of threads, its filters on the caller: the same bits.
    #[cfg(feature = "parallel")]
    {
        let two =
            bevy_soft_body::core::kernels::with_threads(2, || solve(Preconditioner::Multigrid));
        assert!(two == (xm.clone(), im), "two threads differ from one");
    }
    // The prescribed parts kept: `(I − S)(x − x₀) = 0`.
    for &(i, s) in &filters {
        let d = xm[i as usize] - x0[i as usize];
        assert!(
            (d - s * d).length() as f64 <= 1e-4 * (x0[i as usize].length() as f64 + 1.0),
            "particle {i}: its prescribed part moved"
        );
    }
    let mut ax = vec![Vector::ZERO; n];
    a.mul(&xm, &mut ax);
    let mut res: Vec<Vector> = ax
        .iter()
        .zip(&b)
        .zip(&mask)
        .map(|((ax, b), m)| (*b - *ax) * *m)
        .collect();
    filter(&mut res);
    let res = dot64(&res, &res).sqrt();
    let mut sb: Vec<Vector> = b.iter().zip(&mask).map(|(b, m)| *b * *m).collect();
    filter(&mut sb);
    let mut r0: Vec<Vector> = vec![Vector::ZERO; n];
    a.mul(&x0, &mut r0);
    let mut r0: Vec<Vector> = r0
        .iter()
        .zip(&b)
        .zip(&mask)
        .map(|((ax, b), m)| (*b - *ax) * *m)
        .collect();
    filter(&mut r0);
    // The solver's tolerance is relative to the larger of `‖S b‖` and the first residual.
    let bn = dot64(&sb, &sb).sqrt().max(dot64(&r0, &r0).sqrt());
    assert!(
        res <= 10.0 * tol * bn,
        "‖S (b − Ax)‖ = {res:e}, against {bn:e}"
    );
    let xs = xj.iter().fold(0.0f64, |m, x| m.max(x.length() as f64));
    let diff = xm
        .iter()
        .zip(&xj)
        .fold(0.0f64, |m, (p, q)| m.max((*p - *q).length() as f64));
    assert!(
        diff <= 1e4 * tol * xs,
        "|x_mg − x_jacobi| = {diff:e}, |x| = {xs:e}"
    );
    assert!(
        5 * im <= 2 * ij,
        "multigrid {im} vs block-Jacobi {ij} iterations"
    );
}

/// Conjugate gradients on a filtered system whose prescribed parts dwarf its right-hand side
/// (held particles given 20–60 m/s along their normals, against a step's change of a few
/// cm/s elsewhere), asked for a tolerance below the precision: the filters leave their
/// rounding of `A x₀`'s held rows, `ε ‖A x₀‖` and far above `ε ‖b‖`, in the residual along the
/// held directions, where the preconditioned residual `z` does not see it. The iteration
/// must end there, converged, with the Cholesky's answer of the same system (an independent
/// direct solve) to the precision, rather than go on dividing round-off by round-off: a strip
/// hung on a thin rod in `f32` at 1/600 s did, its `α` jumping from 1 to 60–80 while `r · z`
/// fell to 10⁻²³ of its start, and its residual then grew eightfold an iteration until it
/// overflowed (a step reported as a failed solve).
#[test]
fn filtered_conjugate_gradients_end_at_the_round_off_of_large_prescribed_parts() {
    let cloth = build::ClothParams::default().resized(32, 32);
    let (cm, cs) = build::cloth(&cloth).unwrap().build().unwrap();
    let (a, b, mask) = large_system(&cm, cs, 1.0 / 60.0, 10);
    let n = a.len();
    let mut holds = random_holds(&mask, (7, 4), &mut 17, |k| 20.0 * (1 + k % 3) as Scalar);
    let mut x0 = vec![Vector::ZERO; n];
    holds.settle(None, &mut x0);
    let filters = holds.filters.clone();
    let mut xc = x0.clone();
    let direct = SparseCholesky::new().solve_filtered(&a, &b, &mut xc, &mask, &filters);
    assert!(direct.converged, "{direct:?}");
    let scale = xc.iter().fold(0.0f64, |m, v| m.max(v.length() as f64));
    let cap = 3000;
    for pre in [Preconditioner::BlockJacobi, Preconditioner::Multigrid] {
        let mut pcg = Pcg::new(0.0, cap).with_preconditioner(pre);
        let mut x = x0.clone();
        let rep = pcg.solve_filtered(&a, &b, &mut x, &mask, &filters);
        let err = x
            .iter()
            .zip(&xc)
            .fold(0.0f64, |m, (p, q)| m.max((*p - *q).length() as f64));
        println!(
            "{pre:?}: {rep:?}, {err:.3e} from the Cholesky's answer (largest entry {scale:.1})"
        );
        assert!(rep.converged && !rep.failed, "{pre:?}: {rep:?}");
        assert!(rep.iterations < cap / 10, "{pre:?}: {rep:?}");
        // The two solves' own round-off: 35 roundings of the largest entry in f32 and 37 in
        // f64 (measured, either preconditioner), bounded at a thousand.
        assert!(
            err <= 1e3 * Scalar::EPSILON as f64 * scale,
            "{pre:?}: {err} from the Cholesky's answer (largest entry {scale})"
        );
    }
}
