//! Exact force Jacobians of the particle model, and the linearization implicit integrators ask
//! a system for.
//!
//! Per spring `(i, j)`, `d = x_i − x_j`, `l = |d|`, `n = d/l`, `v_r = v_i − v_j`:
//! - elastic: `∂f_i/∂x_i = −K_s`, `K_s = k [n nᵀ + (1 − L/l)(I − n nᵀ)]`, `∂f_i/∂x_j = +K_s`;
//!   the second term is indefinite for compressed springs (`l < L`), and the *definite* option
//!   clamps `1 − L/l` at zero (Choi & Ko 2002) so the implicit system stays positive definite;
//! - damper: `∂f_i/∂v_i = −b n nᵀ`, `∂f_i/∂v_j = +b n nᵀ`, and
//!   `∂f_i/∂x_i = −b [n v_rᵀ P + (n·v_r) P]` with `P = (I − n nᵀ)/l` — non-symmetric, so
//!   implicit steps leave it out, as Baraff & Witkin do (it is still exact here for tests);
//! - drag and wind: `∂f_i/∂v_i = −c I`.

use crate::core::forces::PackedSpring;
use crate::core::ode::ParticleState;
use crate::core::particles::ParticleModel;
use crate::core::solve::SpringMatrix;
use crate::math::{Matrix3, Scalar, Vector};

fn outer(a: Vector, b: Vector) -> Matrix3 {
    Matrix3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// `K_s`, `b n nᵀ` and the damper's position block `G_s` of one spring.
pub fn spring_blocks(
    s: &PackedSpring,
    x: &[Vector],
    v: &[Vector],
    definite: bool,
) -> (Matrix3, Matrix3, Matrix3) {
    let (i, j) = (s.i as usize, s.j as usize);
    let d = x[i] - x[j];
    let l = d.length();
    if l == 0.0 {
        // No direction: the force is zero around here to first order along d only; use the
        // isotropic stiffness k I as the (definite) linearization.
        return (Matrix3::IDENTITY * s.k, Matrix3::ZERO, Matrix3::ZERO);
    }
    let n = d / l;
    let nn = outer(n, n);
    let proj = Matrix3::IDENTITY - nn;
    let mut geo = 1.0 - s.rest / l;
    if definite && geo < 0.0 {
        geo = 0.0;
    }
    let ks = (nn + proj * geo) * s.k;
    let ds = nn * s.damping;
    let gs = if s.damping != 0.0 {
        let vr = v[i] - v[j];
        let p = proj * (1.0 / l);
        (outer(n, p.transpose() * vr) + p * n.dot(vr)) * s.damping
    } else {
        Matrix3::ZERO
    };
    (ks, ds, gs)
}

impl ParticleModel {
    /// Dense `∂f/∂x` and `∂f/∂v` (`3n × 3n`, row-major) of the total force, exact (the damper's
    /// position term included). For tests and small systems.
    pub fn dense_jacobians(&self, state: &ParticleState) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let n = 3 * self.len();
        let mut jx = vec![vec![0.0; n]; n];
        let mut jv = vec![vec![0.0; n]; n];
        let add = |m: &mut Vec<Vec<f64>>, bi: usize, bj: usize, b: &Matrix3, sign: f64| {
            for r in 0..3 {
                for c in 0..3 {
                    m[3 * bi + r][3 * bj + c] += sign * b.col(c)[r] as f64;
                }
            }
        };
        for s in self.springs.as_slice() {
            let (ks, ds, gs) = spring_blocks(s, &state.x, &state.v, false);
            let (i, j) = (s.i as usize, s.j as usize);
            for (a, b, sign) in [(i, i, -1.0), (i, j, 1.0), (j, i, 1.0), (j, j, -1.0)] {
                add(&mut jx, a, b, &ks, sign);
                add(&mut jx, a, b, &gs, sign);
                add(&mut jv, a, b, &ds, sign);
            }
        }
        let c = self.linear_drag();
        for (r, row) in jv.iter_mut().enumerate() {
            row[r] -= c as f64;
        }
        (jx, jv)
    }

    /// Total linear drag coefficient (drag plus wind's air drag).
    pub fn linear_drag(&self) -> Scalar {
        self.drag + self.wind_coefficient()
    }
}

/// What implicit integrators need of a particle system.
pub trait Linearization: Sync {
    /// Number of particles.
    fn particles(&self) -> usize;
    /// A matrix with this system's structure.
    fn new_matrix(&self) -> SpringMatrix;
    /// True when `a` has this system's structure.
    fn matrix_matches(&self, a: &SpringMatrix) -> bool;
    /// Masses.
    fn masses(&self) -> &[Scalar];
    /// `mask[i] = 1` for particles moved by forces, 0 for pinned and prescribed ones.
    fn free_mask(&self, mask: &mut [Scalar]);
    /// Total force on each particle (gravity as `m g` included) at `(t, state)`.
    fn total_forces(&self, t: Scalar, state: &ParticleState, f: &mut [Vector]);
    /// Forces except the ones linear in velocity (dampers, drag, wind's drag): springs'
    /// elastic part, gravity, external forces and the wind's push `c w(t)`.
    fn elastic_forces(&self, t: Scalar, state: &ParticleState, f: &mut [Vector]);
    /// Fills `a = M − h G` with `G` the (constant in v) damping Jacobian: dampers, drag, wind.
    fn assemble_damping(&self, state: &ParticleState, h: Scalar, a: &mut SpringMatrix);
    /// Fills `a = M − h D − h² K` (K without the damper's non-symmetric position term; with
    /// `definite`, compressed springs' indefinite part dropped) and `kv = K v`.
    fn assemble(
        &self,
        state: &ParticleState,
        h: Scalar,
        definite: bool,
        a: &mut SpringMatrix,
        kv: &mut [Vector],
    );
}

impl Linearization for ParticleModel {
    fn particles(&self) -> usize {
        self.len()
    }

    fn new_matrix(&self) -> SpringMatrix {
        SpringMatrix::new(self.len(), &self.springs)
    }

    fn matrix_matches(&self, a: &SpringMatrix) -> bool {
        a.matches(self.len(), &self.springs)
    }

    fn masses(&self) -> &[Scalar] {
        self.mass()
    }

    fn free_mask(&self, mask: &mut [Scalar]) {
        // `pin` and `prescribe` zero a particle's inverse mass and `release` restores it, so a
        // positive inverse mass is exactly "free with a valid mass" — no scan of the pin list
        // per particle on every implicit step.
        for (m, w) in mask.iter_mut().zip(self.inv_mass()) {
            *m = if *w > 0.0 { 1.0 } else { 0.0 };
        }
    }

    fn total_forces(&self, t: Scalar, state: &ParticleState, f: &mut [Vector]) {
        f.fill(Vector::ZERO);
        self.accumulate_forces(t, state, f);
        for ((fi, m), w) in f.iter_mut().zip(self.mass()).zip(self.inv_mass()) {
            if *w > 0.0 {
                *fi += self.gravity * *m;
            }
        }
    }

    fn elastic_forces(&self, t: Scalar, state: &ParticleState, f: &mut [Vector]) {
        f.fill(Vector::ZERO);
        if !self.springs.is_empty() {
            self.springs.accumulate_elastic(&state.x, f);
        }
        let wc = self.wind_coefficient();
        let push = if wc > 0.0 {
            self.wind_velocity(t) * wc
        } else {
            Vector::ZERO
        };
        let ext = self.external_forces();
        for (i, fi) in f.iter_mut().enumerate() {
            if self.inv_mass()[i] > 0.0 {
                *fi += self.gravity * self.mass()[i] + push;
            }
            if let Some(e) = ext {
                *fi += e[i];
            }
        }
    }

    fn assemble_damping(&self, state: &ParticleState, h: Scalar, a: &mut SpringMatrix) {
        let c = self.linear_drag();
        for (d, m) in a.diag.iter_mut().zip(self.mass()) {
            *d = Matrix3::IDENTITY * (*m + h * c);
        }
        for (o, s) in a.off.iter_mut().zip(self.springs.as_slice()) {
            let (i, j) = (s.i as usize, s.j as usize);
            let d = state.x[i] - state.x[j];
            let l = d.length();
            let blk = if l > 0.0 && s.damping != 0.0 {
                let n = d / l;
                outer(n, n) * (h * s.damping)
            } else {
                Matrix3::ZERO
            };
            a.diag[i] += blk;
            a.diag[j] += blk;
            *o = -blk;
        }
    }

    fn assemble(
        &self,
        state: &ParticleState,
        h: Scalar,
        definite: bool,
        a: &mut SpringMatrix,
        kv: &mut [Vector],
    ) {
        let c = self.linear_drag();
        for ((d, m), k) in a.diag.iter_mut().zip(self.mass()).zip(kv.iter_mut()) {
            *d = Matrix3::IDENTITY * (*m + h * c);
            *k = Vector::ZERO;
        }
        let h2 = h * h;
        for (o, s) in a.off.iter_mut().zip(self.springs.as_slice()) {
            let (ks, ds, _) = spring_blocks(s, &state.x, &state.v, definite);
            let blk = ds * h + ks * h2;
            let (i, j) = (s.i as usize, s.j as usize);
            a.diag[i] += blk;
            a.diag[j] += blk;
            *o = -blk;
            // (K v)_i = −K_s (v_i − v_j), (K v)_j = +K_s (v_i − v_j)
            let kvr = ks * (state.v[i] - state.v[j]);
            kv[i] -= kvr;
            kv[j] += kvr;
        }
    }
}
