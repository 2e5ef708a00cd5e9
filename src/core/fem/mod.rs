//! Volumetric finite elements: linear tetrahedra with CSC417's neo-Hookean energy
//! ([`element`]), the material as users give it ([`NeoHookean`]), the packed tet list a model
//! composes with its springs ([`Tets`]), tet meshes and their loaders ([`mesh`]) and skinned
//! display meshes ([`skin`]).

pub mod element;
pub mod mesh;
pub mod skin;

use crate::math::{Matrix3, Scalar, ToScalar, Vector, VectorExt};
use element::{EDGES, NeoHookeanConstants, RestShape};
use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::OnceLock;

/// A neo-Hookean material as engineers give it.
///
/// Converted to CSC417's energy `ψ = C (J^(-2/3) tr(FᵀF) − 3) + D (J − 1)²` by matching
/// linear elasticity at rest: with the Lamé shear modulus `μ = E / (2 (1 + ν))` and bulk
/// modulus `κ = E / (3 (1 − 2ν))`, `C = μ/2` and `D = κ/2` (the deviatoric part linearizes to
/// `μ |ε_dev|²`, the volumetric part to `½ κ (tr ε)²`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NeoHookean {
    /// Young's modulus `E` (Pa).
    pub young: f64,
    /// Poisson ratio `ν`, in (−1, 0.5).
    pub poisson: f64,
    /// Density `ρ` (kg/m³), used to compute particle masses.
    pub density: f64,
}

impl Default for NeoHookean {
    /// A soft rubber: E = 100 kPa, ν = 0.4, ρ = 1000 kg/m³.
    fn default() -> Self {
        Self {
            young: 1e5,
            poisson: 0.4,
            density: 1000.0,
        }
    }
}

impl NeoHookean {
    /// Checks the parameters: `E > 0`, `−1 < ν < 0.5`, `ρ > 0`, all finite.
    pub fn validate(&self) -> Result<(), &'static str> {
        if !(self.young.is_finite() && self.young > 0.0) {
            return Err("Young's modulus must be positive and finite");
        }
        if !(self.poisson.is_finite() && self.poisson > -1.0 && self.poisson < 0.5) {
            return Err("Poisson ratio must lie strictly between -1 and 0.5");
        }
        if !(self.density.is_finite() && self.density > 0.0) {
            return Err("density must be positive and finite");
        }
        Ok(())
    }

    /// Lamé parameters `(μ, λ)`.
    pub fn lame(&self) -> (f64, f64) {
        let (e, nu) = (self.young, self.poisson);
        (
            e / (2.0 * (1.0 + nu)),
            e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
        )
    }

    /// The energy's constants `C = μ/2`, `D = κ/2`.
    pub fn constants(&self) -> NeoHookeanConstants {
        let (mu, _) = self.lame();
        let kappa = self.young / (3.0 * (1.0 - 2.0 * self.poisson));
        NeoHookeanConstants {
            c: 0.5 * mu,
            d: 0.5 * kappa,
        }
    }

    /// P-wave modulus `λ + 2μ` (Pa): the stiffest wave speed is `√((λ + 2μ)/ρ)`.
    pub fn p_wave_modulus(&self) -> f64 {
        let (mu, lambda) = self.lame();
        lambda + 2.0 * mu
    }
}

/// Why a tet cannot be added.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TetError {
    /// Two of its vertices are the same particle.
    RepeatedVertex,
    /// Its rest volume is zero, negative or not finite (flat or inverted rest shape).
    BadVolume(f64),
    /// Its material is not usable.
    BadMaterial(&'static str),
}

impl std::fmt::Display for TetError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::RepeatedVertex => write!(f, "uses the same particle twice"),
            Self::BadVolume(v) => write!(
                f,
                "rest volume {v:e} m³ is not positive (flat, inverted or degenerate rest shape)"
            ),
            Self::BadMaterial(m) => write!(f, "material: {m}"),
        }
    }
}

/// One tet as the kernels read it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PackedTet {
    /// Particle indices.
    pub v: [u32; 4],
    /// Rest shape: gradients and volume.
    pub rest: RestShape,
    /// Energy constants.
    pub material: NeoHookeanConstants,
    /// P-wave modulus `λ + 2μ`, for time-step bounds.
    pub p_wave: f64,
}

/// All tets of a model, with the edge structure their stiffness adds to implicit matrices.
#[derive(Clone, Debug, Default)]
pub struct Tets {
    tets: Vec<PackedTet>,
    edges: Vec<(u32, u32)>,
    /// For each tet, the index into `edges` of each local edge in [`EDGES`] order.
    slots: Vec<[u32; 6]>,
    edge_index: HashMap<(u32, u32), u32>,
    /// The fast kernel's layout, built on the first evaluation after a change.
    fast: LazyTetForces,
}

/// A [`TetForces`](crate::core::kernels::tets::TetForces) built when first needed; cloning or
/// adding tets drops it.
#[derive(Debug, Default)]
struct LazyTetForces(OnceLock<crate::core::kernels::tets::TetForces>);

impl Clone for LazyTetForces {
    fn clone(&self) -> Self {
        Self::default()
    }
}

fn d(v: Vector) -> DVec3 {
    DVec3::from_array(v.to_f64())
}

fn to_matrix(m: &DMat3) -> Matrix3 {
    let c = |v: DVec3| v.to_array().to_scalar();
    Matrix3::from_cols(c(m.x_axis), c(m.y_axis), c(m.z_axis))
}

impl Tets {
    /// No tets.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a tet over particles `v` whose rest positions are `rest`.
    pub fn push(
        &mut self,
        v: [usize; 4],
        rest: [DVec3; 4],
        material: &NeoHookean,
    ) -> Result<(), TetError> {
        for a in 0..4 {
            for b in a + 1..4 {
                if v[a] == v[b] {
                    return Err(TetError::RepeatedVertex);
                }
            }
        }
        material.validate().map_err(TetError::BadMaterial)?;
        let shape =
            RestShape::new(rest).ok_or(TetError::BadVolume(element::signed_volume(rest)))?;
        let vv = v.map(|i| i as u32);
        let mut slot = [0u32; 6];
        for (s, &(a, b)) in slot.iter_mut().zip(&EDGES) {
            let key = (vv[a].min(vv[b]), vv[a].max(vv[b]));
            let next = self.edges.len() as u32;
            *s = *self.edge_index.entry(key).or_insert(next);
            if *s == next {
                self.edges.push(key);
            }
        }
        self.slots.push(slot);
        self.fast = LazyTetForces::default();
        self.tets.push(PackedTet {
            v: vv,
            rest: shape,
            material: material.constants(),
            p_wave: material.p_wave_modulus(),
        });
        Ok(())
    }

    /// Number of tets.
    pub fn len(&self) -> usize {
        self.tets.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.tets.is_empty()
    }

    /// The packed tets.
    pub fn as_slice(&self) -> &[PackedTet] {
        &self.tets
    }

    /// Unique edges `(i, j)`, `i < j`, of all tets: the off-diagonal blocks they add.
    pub fn edges(&self) -> &[(u32, u32)] {
        &self.edges
    }

    /// One more than the largest particle index used (0 when empty).
    pub fn bound(&self) -> usize {
        self.edges
            .iter()
            .map(|&(_, j)| j as usize + 1)
            .max()
            .unwrap_or(0)
    }

    /// Total rest volume (m³).
    pub fn volume(&self) -> f64 {
        self.tets.iter().map(|t| t.rest.volume).sum()
    }

    fn positions(t: &PackedTet, x: &[Vector]) -> [DVec3; 4] {
        t.v.map(|i| d(x[i as usize]))
    }

    /// Adds the elastic forces of every tet into `f`, with the fast kernel
    /// ([`crate::core::kernels::tets`]) in the build's precision: equal to
    /// [`Tets::accumulate_f64`] to that precision's round-off, and the same bits on any number
    /// of threads.
    ///
    /// # Panics
    /// If `x` and `f` differ in length or a tet refers past their end.
    pub fn accumulate(&self, x: &[Vector], f: &mut [Vector]) {
        let fast = self.fast();
        assert!(
            f.len() == x.len() && fast.bound() <= x.len(),
            "tets refer past the state, or state and forces differ in length"
        );
        // SAFETY: lengths and index bound checked just above.
        unsafe { fast.accumulate(x, f) }
    }

    /// Sets `f` to the elastic forces — the bits of zeroing it and [`Tets::accumulate`] —
    /// then runs `finish` on each chunk of particles, on the thread that summed its forces
    /// (see [`crate::core::kernels::Chunk`]).
    ///
    /// # Panics
    /// As [`Tets::accumulate`], or if `v` differs from `x` in length.
    pub(crate) fn set_then(
        &self,
        x: &mut [Vector],
        v: &mut [Vector],
        f: &mut [Vector],
        finish: crate::core::kernels::Finish<'_>,
    ) {
        let fast = self.fast();
        assert!(
            f.len() == x.len() && v.len() == x.len() && fast.bound() <= x.len(),
            "tets refer past the state, or state and forces differ in length"
        );
        // SAFETY: lengths and index bound checked just above.
        unsafe { fast.set_then(x, v, f, finish) }
    }

    /// The elastic energy from the fast kernel's layout: each element's in the build's
    /// precision, summed in f64 — [`Self::energy`] to that precision's round-off, several
    /// times faster. The divergence guard's check; energy reports use [`Self::energy`].
    ///
    /// # Panics
    /// If a tet refers past the end of `x`.
    pub fn energy_fast(&self, x: &[Vector]) -> f64 {
        let fast = self.fast();
        assert!(fast.bound() <= x.len(), "tets refer past the state");
        // SAFETY: index bound checked just above.
        unsafe { fast.energy(x) }
    }

    /// Number of chunks of the fast kernel's passes (parallel work units).
    pub fn chunks(&self) -> usize {
        if self.tets.is_empty() {
            0
        } else {
            self.fast().chunks()
        }
    }

    fn fast(&self) -> &crate::core::kernels::tets::TetForces {
        self.fast
            .0
            .get_or_init(|| crate::core::kernels::tets::TetForces::new(&self.tets))
    }

    /// Adds the elastic forces of every tet into `f`, element by element in f64 (the reference
    /// kernel; implicit methods use it for their gradients).
    pub fn accumulate_f64(&self, x: &[Vector], f: &mut [Vector]) {
        for t in &self.tets {
            let fe = element::element_forces(&t.material, &t.rest, Self::positions(t, x));
            for (a, fa) in fe.iter().enumerate() {
                f[t.v[a] as usize] += fa.to_array().to_scalar();
            }
        }
    }

    /// Elastic energy (finite for inverted elements).
    pub fn energy(&self, x: &[Vector]) -> f64 {
        self.tets
            .iter()
            .map(|t| element::element_energy(&t.material, &t.rest, Self::positions(t, x)))
            .sum()
    }

    /// Elastic energy as a barrier for a step from `x0` to `x`: `+∞` when the step inverts or
    /// flattens an element that was not inverted at `x0`. An element already inverted at `x0`
    /// (a state an explicit method or a user's drag left behind) keeps its finite energy, so
    /// backward Euler can still step out of it.
    pub fn barrier_energy(&self, x0: &[Vector], x: &[Vector]) -> f64 {
        let mut e = 0.0;
        for t in &self.tets {
            let f = t.rest.deformation_gradient(Self::positions(t, x));
            let j = f.determinant();
            if j <= 0.0
                && t.rest
                    .deformation_gradient(Self::positions(t, x0))
                    .determinant()
                    > 0.0
            {
                return f64::INFINITY;
            }
            e += t.rest.volume * t.material.energy_density(&f);
        }
        e
    }

    /// Number of elements with `J ≤ 0` at `x`.
    pub fn inverted(&self, x: &[Vector]) -> usize {
        self.tets
            .iter()
            .filter(|t| {
                t.rest
                    .deformation_gradient(Self::positions(t, x))
                    .determinant()
                    <= 0.0
            })
            .count()
    }

    /// Adds `scale · K(x)` (`K = ∂²E/∂x²`, the negative force Jacobian) into the blocks of a
    /// symmetric block matrix: diagonal blocks in `diag`, the block of edge `e = (i, j)`,
    /// `i < j` (row `i`, column `j`) in `off[e]`. With `project`, each element's Hessian in `F`
    /// is projected onto the semi-definite cone first. With `product = Some((v, kv))`, also
    /// subtracts `K v` from `kv` (adds the force Jacobian times `v`).
    pub fn add_stiffness(
        &self,
        x: &[Vector],
        scale: Scalar,
        project: bool,
        diag: &mut [Matrix3],
        off: &mut [Matrix3],
        mut product: Option<(&[Vector], &mut [Vector])>,
    ) {
        let s = scale as f64;
        for (t, slot) in self.tets.iter().zip(&self.slots) {
            let k =
                element::element_stiffness(&t.material, &t.rest, Self::positions(t, x), project);
            if let Some((v, kv)) = product.as_mut() {
                for a in 0..4 {
                    let mut acc = DVec3::ZERO;
                    for b in 0..4 {
                        acc += k[a][b] * d(v[t.v[b] as usize]);
                    }
                    kv[t.v[a] as usize] -= acc.to_array().to_scalar();
                }
            }
            for a in 0..4 {
                diag[t.v[a] as usize] += to_matrix(&(k[a][a] * s));
            }
            for (e, &(a, b)) in slot.iter().zip(&EDGES) {
                // Block (row v_a, column v_b) is K_ab; stored with row min(v_a, v_b).
                let blk = if t.v[a] < t.v[b] {
                    k[a][b]
                } else {
                    k[a][b].transpose()
                };
                off[*e as usize] += to_matrix(&(blk * s));
            }
        }
    }

    /// Smallest explicit time scale `√(m_a / k_a)` over tet vertices with a free particle,
    /// with `k_a = V (λ + 2μ) |g_a|²` the element's stiffness on that vertex at rest (summed
    /// over the tets that share it); `None` without tets or free vertices.
    pub fn time_scale(&self, mass: &[Scalar], inv_mass: &[Scalar]) -> Option<Scalar> {
        if self.tets.is_empty() {
            return None;
        }
        let mut k = vec![0.0f64; mass.len()];
        for t in &self.tets {
            for a in 0..4 {
                k[t.v[a] as usize] += t.rest.volume * t.p_wave * t.rest.grad[a].length_squared();
            }
        }
        let mut best: Option<f64> = None;
        for (i, ki) in k.iter().enumerate() {
            if *ki > 0.0 && inv_mass[i] > 0.0 {
                let dt = (mass[i] as f64 / ki).sqrt();
                best = Some(best.map_or(dt, |b| b.min(dt)));
            }
        }
        best.map(|b| b as Scalar)
    }
}
