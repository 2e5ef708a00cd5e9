//! One linear tetrahedron (CSC417 assignment 3, *The finite element method for 3D elastic objects*), in `f64` whatever the crate's precision.
//!
//! Shape functions are the barycentric coordinates `φ_a(X)` of the rest tet; their gradients
//! `g_a = ∇φ_a` are constant: with `D_m = [X₁−X₀, X₂−X₀, X₃−X₀]`, `g₁..g₃` are the rows of
//! `D_m⁻¹` and `g₀ = −(g₁ + g₂ + g₃)`. The deformation gradient is constant too:
//! `F = Σ_a x_a g_aᵀ = D_s D_m⁻¹`. One quadrature point (the centroid) is exact for a constant
//! integrand, so the element energy is `V ψ(F)` with `V = det(D_m)/6` the rest volume.
//!
//! The energy density is CSC417's compressible neo-Hookean
//!
//! `ψ(F) = C (J^(-2/3) tr(FᵀF) − 3) + D (J − 1)²`, `J = det F`,
//!
//! with first Piola–Kirchhoff stress (`G = F⁻ᵀ`, `a = J^(-2/3)`, `I₁ = tr(FᵀF)`)
//!
//! `P = ∂ψ/∂F = C (2a F − ⅔ a I₁ G) + 2D (J − 1) J G`,
//!
//! and its differential (the 9×9 Hessian `∂P/∂F` applied to `dF`), with `G:dF = tr(F⁻¹dF)`,
//! `dJ = J G:dF`, `da = −⅔ a G:dF`, `dI₁ = 2 F:dF`, `dG = −G dFᵀ G`:
//!
//! `dP = C (2 da F + 2a dF − ⅔ (da I₁ + a dI₁) G − ⅔ a I₁ dG) + 2D ((2J − 1) dJ G + (J − 1) J dG)`.
//!
//! Forces are `f_a = −V P g_a`; the stiffness block `K_ab = ∂²E/∂x_a∂x_b` has column `j` equal
//! to `V dP(e_j g_bᵀ) g_a`. Every one of these is checked against central differences in the
//! tests. `J^(-2/3)` is taken as `1/∛J²` with the real cube root, so forces stay finite for an
//! inverted element (the volume term pushes it back); the *barrier* energy used by Newton's
//! line search is `+∞` for `J ≤ 0` instead.

// Small dense matrices (9×9, 12×12) read best with explicit indices.
#![allow(clippy::needless_range_loop)]

pub use glam::{DMat3, DVec3};

/// Local vertex pairs of a tet's six edges.
pub const EDGES: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];

/// The rest shape of a tet: shape-function gradients and volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RestShape {
    /// `g_a = ∇φ_a` (1/m), constant over the tet.
    pub grad: [DVec3; 4],
    /// Rest volume (m³), positive.
    pub volume: f64,
}

/// Signed volume of a tet: `dot(b − a, (c − a) × (d − a)) / 6` (positive when `d` is on the
/// side `(b − a) × (c − a)` points to).
pub fn signed_volume(x: [DVec3; 4]) -> f64 {
    (x[1] - x[0]).dot((x[2] - x[0]).cross(x[3] - x[0])) / 6.0
}

impl RestShape {
    /// The rest shape of the tet `x`, or `None` when its volume is not positive and finite
    /// (flat, inverted or degenerate: no gradients exist).
    pub fn new(x: [DVec3; 4]) -> Option<Self> {
        let dm = DMat3::from_cols(x[1] - x[0], x[2] - x[0], x[3] - x[0]);
        let volume = dm.determinant() / 6.0;
        // Reject slivers whose volume is round-off relative to their edges.
        let scale = (x[1] - x[0])
            .length()
            .max((x[2] - x[0]).length())
            .max((x[3] - x[0]).length());
        if !(volume.is_finite() && volume > 1e-12 * scale * scale * scale) {
            return None;
        }
        let inv = dm.inverse();
        // Rows of D_m⁻¹ are columns of its transpose.
        let t = inv.transpose();
        let (g1, g2, g3) = (t.x_axis, t.y_axis, t.z_axis);
        let grad = [-(g1 + g2 + g3), g1, g2, g3];
        if !grad.iter().all(|g| g.is_finite()) {
            return None;
        }
        Some(Self { grad, volume })
    }

    /// `F = Σ_a x_a g_aᵀ`.
    pub fn deformation_gradient(&self, x: [DVec3; 4]) -> DMat3 {
        let g = &self.grad;
        let mut f = DMat3::ZERO;
        for a in 0..4 {
            f += outer(x[a], g[a]);
        }
        f
    }
}

/// `a bᵀ`.
#[inline]
pub fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

#[inline]
fn frob(a: &DMat3, b: &DMat3) -> f64 {
    a.x_axis.dot(b.x_axis) + a.y_axis.dot(b.y_axis) + a.z_axis.dot(b.z_axis)
}

/// Below this volume ratio the isochoric term is evaluated at `J = J_MIN` (its `J^(-2/3)`
/// frozen): an element squashed flat or inverted — by a contact projection, a hard drag, an
/// explicit step — keeps finite energy and forces, and the volumetric term `D (J − 1)²`
/// pushes it back. Above it the energy is exactly CSC417's.
pub const J_MIN: f64 = 0.1;

/// `J^(-2/3)` (as `(J^(-1/3))²`), frozen below [`J_MIN`].
#[inline]
fn j_two_thirds(j: f64) -> f64 {
    let y = inv_cbrt_f64(j.max(J_MIN));
    y * y
}

/// `x^(−1/3)` for positive, finite `x`, to within a few units in the last place of the
/// library's `1/∛x` (the unit test bounds it): an estimate from the exponent bits (within
/// 3 %) and four Newton steps `y ← y (4 − x y³)/3`, which converge quadratically (3e-2,
/// 2e-3, 6e-6, 1e-10, then round-off). The f64 build's tet kernel takes the same steps
/// ([`crate::core::kernels::tets::inv_cbrt`]); the library `cbrt` was 14 % of a backward Euler
/// step on the armadillo.
#[inline]
pub fn inv_cbrt_f64(x: f64) -> f64 {
    let mut y = f64::from_bits(0x553e_f0ff_289d_d796 - x.to_bits() / 3);
    for _ in 0..4 {
        y *= (4.0 - x * y * y * y) * (1.0 / 3.0);
    }
    y
}

/// The cofactor matrix `cof F = J F⁻ᵀ = [b × c, c × a, a × b]` for columns `a, b, c`: the
/// derivative of `det F`, finite for flat and inverted `F`.
#[inline]
pub fn cofactor(f: &DMat3) -> DMat3 {
    let (a, b, c) = (f.x_axis, f.y_axis, f.z_axis);
    DMat3::from_cols(b.cross(c), c.cross(a), a.cross(b))
}

/// `d(cof F)` for a change `dF`.
#[inline]
fn cofactor_differential(f: &DMat3, df: &DMat3) -> DMat3 {
    let (a, b, c) = (f.x_axis, f.y_axis, f.z_axis);
    let (da, db, dc) = (df.x_axis, df.y_axis, df.z_axis);
    DMat3::from_cols(
        db.cross(c) + b.cross(dc),
        dc.cross(a) + c.cross(da),
        da.cross(b) + a.cross(db),
    )
}

/// CSC417's neo-Hookean energy density constants: `C` (isochoric, Pa) and `D` (volumetric,
/// Pa).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NeoHookeanConstants {
    /// `C = μ/2`.
    pub c: f64,
    /// `D = κ/2`, `κ = λ + ⅔ μ` the bulk modulus.
    pub d: f64,
}

impl NeoHookeanConstants {
    /// `ψ(F)`; finite for flat and inverted elements (see [`J_MIN`]).
    pub fn energy_density(&self, f: &DMat3) -> f64 {
        let j = f.determinant();
        let i1 = frob(f, f);
        self.c * (j_two_thirds(j) * i1 - 3.0) + self.d * (j - 1.0) * (j - 1.0)
    }

    /// `ψ(F)` as a barrier: `+∞` when `J ≤ 0` (an inverted or flat element), so a line search
    /// rejects steps that invert an element.
    pub fn barrier_density(&self, f: &DMat3) -> f64 {
        let j = f.determinant();
        if j > 0.0 {
            self.energy_density(f)
        } else {
            f64::INFINITY
        }
    }

    /// The first Piola–Kirchhoff stress `P = ∂ψ/∂F` (with `J G = cof F`, finite everywhere).
    pub fn stress(&self, f: &DMat3) -> DMat3 {
        let j = f.determinant();
        let cof = cofactor(f);
        let a = j_two_thirds(j);
        let i1 = frob(f, f);
        let iso = if j > J_MIN {
            -2.0 / 3.0 * self.c * a * i1 / j
        } else {
            0.0
        };
        *f * (2.0 * self.c * a) + cof * (iso + 2.0 * self.d * (j - 1.0))
    }

    /// `dP = (∂P/∂F) : dF`.
    pub fn stress_differential(&self, f: &DMat3, df: &DMat3) -> DMat3 {
        let j = f.determinant();
        if j > J_MIN {
            let g = cofactor(f) * (1.0 / j);
            return self.stress_differential_with(f, &g, j, df);
        }
        // Frozen isochoric factor: P = 2C a F + 2D (J − 1) cof F.
        let a = j_two_thirds(j);
        let cof = cofactor(f);
        let dj = frob(&cof, df);
        *df * (2.0 * self.c * a)
            + cof * (2.0 * self.d * dj)
            + cofactor_differential(f, df) * (2.0 * self.d * (j - 1.0))
    }

    #[inline]
    fn stress_differential_with(&self, f: &DMat3, g: &DMat3, j: f64, df: &DMat3) -> DMat3 {
        let a = j_two_thirds(j);
        let i1 = frob(f, f);
        let gdf = frob(g, df);
        let dj = j * gdf;
        let da = -2.0 / 3.0 * a * gdf;
        let di1 = 2.0 * frob(f, df);
        let dg = -(*g * df.transpose() * *g);
        let (c, d) = (self.c, self.d);
        *f * (2.0 * c * da) + *df * (2.0 * c * a) - *g * (2.0 / 3.0 * c * (da * i1 + a * di1))
            + dg * (-2.0 / 3.0 * c * a * i1)
            + *g * (2.0 * d * (2.0 * j - 1.0) * dj)
            + dg * (2.0 * d * (j - 1.0) * j)
    }

    /// The 9×9 Hessian `H[p][q] = ∂P_p/∂F_q`, entries indexed column-major (`p = i + 3k` for
    /// `P_ik`), symmetrized.
    pub fn hessian(&self, f: &DMat3) -> [[f64; 9]; 9] {
        // Column q = i + 3j of H is dP for dF = e_i e_jᵀ. Then G:dF = G_ij, F:dF = F_ij and
        // dG = −G dFᵀ G = −(G e_j)(e_iᵀ G), so
        // dP = α F + β dF + γ G + δ (G e_j)(e_iᵀ G) with
        // α = 2C da, β = 2C a, γ = −⅔ C (da I₁ + a dI₁) + 2D (2J − 1) dJ,
        // δ = ⅔ C a I₁ − 2D (J − 1) J: a few flops per entry instead of matrix products
        // (`stress_differential` is the general form; the tests check both).
        let j = f.determinant();
        if j <= J_MIN {
            // Flat, inverted or nearly so: the general differential, column by column.
            let mut h = [[0.0; 9]; 9];
            for q in 0..9 {
                let mut e = DMat3::ZERO;
                e.col_mut(q / 3)[q % 3] = 1.0;
                let dp = self.stress_differential(f, &e);
                for (p, row) in h.iter_mut().enumerate() {
                    row[q] = dp.col(p / 3)[p % 3];
                }
            }
            for p in 0..9 {
                for q in p + 1..9 {
                    let s = 0.5 * (h[p][q] + h[q][p]);
                    h[p][q] = s;
                    h[q][p] = s;
                }
            }
            return h;
        }
        let g = cofactor(f) * (1.0 / j);
        let a = j_two_thirds(j);
        let i1 = frob(f, f);
        let (c, d) = (self.c, self.d);
        let beta = 2.0 * c * a;
        let delta = 2.0 / 3.0 * c * a * i1 - 2.0 * d * (j - 1.0) * j;
        let fa = f.to_cols_array();
        let ga = g.to_cols_array();
        let mut h = [[0.0; 9]; 9];
        for q in 0..9 {
            let (qi, qj) = (q % 3, q / 3);
            let gij = ga[q];
            let da = -2.0 / 3.0 * a * gij;
            let alpha = 2.0 * c * da;
            let gamma =
                -2.0 / 3.0 * c * (da * i1 + a * 2.0 * fa[q]) + 2.0 * d * (2.0 * j - 1.0) * j * gij;
            // (G e_j)_r = G[r][qj] = ga[r + 3 qj]; (e_iᵀ G)_s = G[qi][s] = ga[qi + 3 s].
            for p in 0..9 {
                let (r, sc) = (p % 3, p / 3);
                h[p][q] = alpha * fa[p] + gamma * ga[p] + delta * ga[r + 3 * qj] * ga[qi + 3 * sc];
            }
            h[q][q] += beta;
        }
        for p in 0..9 {
            for q in p + 1..9 {
                let s = 0.5 * (h[p][q] + h[q][p]);
                h[p][q] = s;
                h[q][p] = s;
            }
        }
        h
    }
}

/// Projects a symmetric 9×9 matrix onto the positive semi-definite cone (eigenvalues below
/// zero set to zero). Returns true when it changed the matrix. A Cholesky attempt first makes
/// the common definite case cheap; otherwise cyclic Jacobi rotations find the eigen-system.
pub fn project_psd9(h: &mut [[f64; 9]; 9]) -> bool {
    if cholesky_ok(h) {
        return false;
    }
    let mut a = *h;
    let mut v = [[0.0; 9]; 9];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let scale: f64 = a.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
    // Cyclic Jacobi converges quadratically: a 9×9 matrix is diagonal to 1e-12 of its norm
    // within 6–8 sweeps (eigenvalues to round-off of that; the clamp needs no more).
    for _sweep in 0..12 {
        let off: f64 = (0..9)
            .flat_map(|p| (0..9).filter(move |&q| q != p).map(move |q| (p, q)))
            .map(|(p, q)| a[p][q] * a[p][q])
            .sum::<f64>();
        if off.sqrt() <= 1e-12 * scale {
            break;
        }
        for p in 0..9 {
            for q in p + 1..9 {
                if a[p][q].abs() <= 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..9 {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..9 {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    let lam: [f64; 9] = std::array::from_fn(|i| a[i][i].max(0.0));
    for p in 0..9 {
        for q in 0..9 {
            h[p][q] = (0..9).map(|k| v[p][k] * lam[k] * v[q][k]).sum();
        }
    }
    true
}

/// True when `H + δ I` has a Cholesky factor, `δ = 1e-9 max|H_ii|`: `H` has no eigenvalue below
/// `−δ`. The shift lets the exactly singular Hessian of a stress-free element (zero along the
/// three infinitesimal rotations) pass without a needless eigen-decomposition.
fn cholesky_ok(h: &[[f64; 9]; 9]) -> bool {
    let mut l = [[0.0; 9]; 9];
    let shift = 1e-9 * (0..9).map(|i| h[i][i].abs()).fold(0.0, f64::max);
    for j in 0..9 {
        let mut d = h[j][j] + shift;
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        // Not `d <= 0.0`: a NaN pivot must fail too.
        if d.is_nan() || d <= 0.0 {
            return false;
        }
        let d = d.sqrt();
        l[j][j] = d;
        for i in j + 1..9 {
            let mut s = h[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            l[i][j] = s / d;
        }
    }
    true
}

/// Elastic energy `V ψ(F)` of one element.
pub fn element_energy(m: &NeoHookeanConstants, rest: &RestShape, x: [DVec3; 4]) -> f64 {
    rest.volume * m.energy_density(&rest.deformation_gradient(x))
}

/// The 12-vector of elastic forces `f_a = −V P g_a`.
pub fn element_forces(m: &NeoHookeanConstants, rest: &RestShape, x: [DVec3; 4]) -> [DVec3; 4] {
    let p = m.stress(&rest.deformation_gradient(x));
    rest.grad.map(|g| -(p * g) * rest.volume)
}

/// The 12×12 stiffness `K_ab = ∂²E/∂x_a∂x_b` as 4×4 blocks (`K[a][b]`, symmetric:
/// `K[b][a] = K[a][b]ᵀ`); the force Jacobian is `−K`. With `project`, the 9×9 Hessian in `F`
/// is first projected onto the positive semi-definite cone, which makes `K` semi-definite
/// (`K = V Bᵀ H B`).
pub fn element_stiffness(
    m: &NeoHookeanConstants,
    rest: &RestShape,
    x: [DVec3; 4],
    project: bool,
) -> [[DMat3; 4]; 4] {
    let f = rest.deformation_gradient(x);
    let mut h = m.hessian(&f);
    if project {
        project_psd9(&mut h);
    }
    stiffness_from_hessian(&h, rest)
}

/// `K[a][b][i][j] = V Σ_kl H[i+3k][j+3l] g_a[k] g_b[l]`.
pub fn stiffness_from_hessian(h: &[[f64; 9]; 9], rest: &RestShape) -> [[DMat3; 4]; 4] {
    let g = &rest.grad;
    // t[p][3b + j] = Σ_l H[p][j + 3l] g_b[l]
    let mut t = [[0.0; 12]; 9];
    for (p, row) in t.iter_mut().enumerate() {
        for b in 0..4 {
            for jj in 0..3 {
                row[3 * b + jj] = h[p][jj] * g[b].x + h[p][jj + 3] * g[b].y + h[p][jj + 6] * g[b].z;
            }
        }
    }
    let mut k = [[DMat3::ZERO; 4]; 4];
    for a in 0..4 {
        for b in 0..4 {
            let mut blk = DMat3::ZERO;
            for ii in 0..3 {
                for jj in 0..3 {
                    let v = t[ii][3 * b + jj] * g[a].x
                        + t[ii + 3][3 * b + jj] * g[a].y
                        + t[ii + 6][3 * b + jj] * g[a].z;
                    blk.col_mut(jj)[ii] = v * rest.volume;
                }
            }
            k[a][b] = blk;
        }
    }
    k
}

/// The consistent element mass matrix `M_e = ∫ ρ Nᵀ N dV` of a linear tet, per axis:
/// `M_ab = ρ V (1 + δ_ab) / 20` (times the 3×3 identity). Its row sums are `ρ V / 4`, the
/// lumped masses.
pub fn consistent_mass(density: f64, volume: f64) -> [[f64; 4]; 4] {
    let m = density * volume / 20.0;
    std::array::from_fn(|a| std::array::from_fn(|b| if a == b { 2.0 * m } else { m }))
}

/// The lumped element mass: `ρ V / 4` per vertex.
pub fn lumped_mass(density: f64, volume: f64) -> f64 {
    density * volume / 4.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Newton inverse cube root against the library's `1 / cbrt`, over the range the
    /// isochoric factor sees (`J_MIN` up to a million-fold volume) and a dense sample of one
    /// binade (every estimate's error pattern repeats per three binades): within 4 units in
    /// the last place (two roundings on each side).
    #[test]
    fn newton_inverse_cube_root_matches_the_library() {
        let mut worst = 0.0f64;
        let mut check = |x: f64| {
            let (y, r) = (inv_cbrt_f64(x), 1.0 / x.cbrt());
            let ulps = ((y - r) / (r * f64::EPSILON)).abs();
            worst = worst.max(ulps);
            assert!(ulps <= 4.0, "x = {x}: {y} against {r} ({ulps} ulp)");
        };
        let mut x = J_MIN;
        while x < 1e6 {
            check(x);
            x *= 1.0 + 1.0 / 1024.0;
        }
        for k in 0..=30_000 {
            check(1.0 + 7.0 * k as f64 / 30_000.0);
        }
        println!("worst: {worst} ulp");
    }
}
