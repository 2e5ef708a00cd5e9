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

use crate::core::collide::{NormalHolds, ROUND_OFF_SLACK};
use crate::core::forces::PackedSpring;
use crate::core::ode::ParticleState;
use crate::core::particles::ParticleModel;
use crate::core::solve::SpringMatrix;
use crate::math::{Matrix3, Scalar, Vector, VectorExt};

fn outer(a: Vector, b: Vector) -> Matrix3 {
    Matrix3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// `K_s = k [n nᵀ + (1 − L/l)(I − n nᵀ)]` of a spring of length `l > 0` along unit `n`, with
/// `n nᵀ` and `I − n nᵀ` (the definite option clamps `1 − L/l` at zero, which is exactly the
/// projection of `K_s` onto the positive semi-definite cone: its eigenvalues are `k` along `n`
/// and `k (1 − L/l)` twice across it).
fn stiffness_block(s: &PackedSpring, n: Vector, l: Scalar, definite: bool) -> [Matrix3; 3] {
    let nn = outer(n, n);
    let proj = Matrix3::IDENTITY - nn;
    let mut geo = 1.0 - s.rest / l;
    if definite && geo < 0.0 {
        geo = 0.0;
    }
    [(nn + proj * geo) * s.k, nn, proj]
}

/// `K_s` of one spring at positions `x` (`k I` for a zero-length spring, which has no
/// direction: a definite stand-in for the linearization).
pub fn spring_stiffness(s: &PackedSpring, x: &[Vector], definite: bool) -> Matrix3 {
    let d = x[s.i as usize] - x[s.j as usize];
    let l = d.length();
    if l == 0.0 {
        return Matrix3::IDENTITY * s.k;
    }
    stiffness_block(s, d / l, l, definite)[0]
}

/// The damper block `b n nᵀ` of one spring along its direction at positions `x` (zero for a
/// zero-length or undamped spring).
pub fn damper_block(s: &PackedSpring, x: &[Vector]) -> Matrix3 {
    let d = x[s.i as usize] - x[s.j as usize];
    let l = d.length();
    if l == 0.0 || s.damping == 0.0 {
        return Matrix3::ZERO;
    }
    let n = d / l;
    outer(n, n) * s.damping
}

/// One spring's block `h b n nᵀ + h² K_s` of the implicit matrix and its `K_s (v_i − v_j)`,
/// without forming `K_s`: with `g = 1 − L/l` (clamped at zero when `definite`),
/// `K_s = k [(1 − g) n nᵀ + g I]`, so the block is `(h b + h² k (1 − g)) n nᵀ + h² k g I` —
/// symmetric to the bit, as every `α n nᵀ + β I` is — and the product
/// `k (1 − g) (n · v_r) n + k g v_r`. A zero-length spring takes `K_s = k I` and no damper, as
/// [`spring_blocks`] does.
#[inline]
fn assembly_block(
    s: &PackedSpring,
    x: &[Vector],
    v: &[Vector],
    h: Scalar,
    definite: bool,
) -> (Matrix3, Vector) {
    let (i, j) = (s.i as usize, s.j as usize);
    let (d, vr) = (x[i] - x[j], v[i] - v[j]);
    let h2 = h * h;
    let l = d.length();
    if l == 0.0 {
        return (Matrix3::IDENTITY * (h2 * s.k), vr * s.k);
    }
    let n = d / l;
    let mut g = 1.0 - s.rest / l;
    if definite && g < 0.0 {
        g = 0.0;
    }
    let (along, across) = (s.k * (1.0 - g), s.k * g);
    let blk = outer(n, n) * (h * s.damping + h2 * along) + Matrix3::IDENTITY * (h2 * across);
    (blk, n * (along * n.dot(vr)) + vr * across)
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
    let [ks, nn, proj] = stiffness_block(s, n, l, definite);
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
        if !self.tets.is_empty() {
            let n = self.len();
            let mut diag = vec![Matrix3::ZERO; n];
            let mut off = vec![Matrix3::ZERO; self.tets.edges().len()];
            self.tets
                .add_stiffness(&state.x, 1.0, false, &mut diag, &mut off, None);
            for (i, b) in diag.iter().enumerate() {
                add(&mut jx, i, i, b, -1.0);
            }
            for (o, &(i, j)) in off.iter().zip(self.tets.edges()) {
                add(&mut jx, i as usize, j as usize, o, -1.0);
                add(&mut jx, j as usize, i as usize, &o.transpose(), -1.0);
            }
        }
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

    /// Off-diagonal structure of implicit matrices: each spring, then each tet edge.
    fn matrix_pairs(&self) -> impl Iterator<Item = (u32, u32)> + '_ {
        self.springs
            .as_slice()
            .iter()
            .map(|s| (s.i, s.j))
            .chain(self.tets.edges().iter().copied())
    }

    /// Adds `scale K_tets(x)` (and, with `product`, `kv −= K_tets v`) into the tet part of `a`
    /// (its off-diagonal blocks after the springs'), zeroing that part first.
    fn add_tet_stiffness(
        &self,
        x: &[Vector],
        scale: Scalar,
        project: bool,
        a: &mut SpringMatrix,
        product: Option<(&[Vector], &mut [Vector])>,
    ) {
        if self.tets.is_empty() {
            return;
        }
        let off = &mut a.off[self.springs.len()..];
        off.fill(Matrix3::ZERO);
        self.tets
            .add_stiffness(x, scale, project, &mut a.diag, off, product);
    }

    /// Total linear drag coefficient (drag plus wind's air drag).
    pub fn linear_drag(&self) -> Scalar {
        self.drag + self.wind_coefficient()
    }

    /// Each particle's diagonal block before the springs', `(m + h c) I`: mass plus `h`
    /// times the drag Jacobian, the part every implicit matrix starts from.
    fn mass_diagonal(&self, h: Scalar) -> impl Fn(usize) -> Matrix3 + Sync + Send + '_ {
        let (c, mass) = (self.linear_drag(), self.mass());
        move |i| Matrix3::IDENTITY * (mass[i] + h * c)
    }
}

/// What implicit integrators need of a particle system.
pub trait Linearization: Sync {
    /// Number of particles.
    fn particles(&self) -> usize;
    /// Springs and tetrahedra (what a step's cost grows with).
    fn element_counts(&self) -> (usize, usize) {
        (0, 0)
    }
    /// A matrix with this system's structure.
    fn new_matrix(&self) -> SpringMatrix;
    /// True when `a` has this system's structure.
    fn matrix_matches(&self, a: &SpringMatrix) -> bool;
    /// Masses.
    fn masses(&self) -> &[Scalar];
    /// `mask[i] = 1` for particles moved by forces, 0 for pinned and prescribed ones. Returns
    /// false when some particle that is neither pinned nor prescribed has no valid mass (the
    /// implicit system is singular there: a reported failure, not a step).
    fn free_mask(&self, mask: &mut [Scalar]) -> bool;
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
    /// Velocities of the constrained particles over a step of length `h` ending at `t_end`:
    /// zero for pinned ones, `(p(t_end) − x₀)/h` for prescribed ones, so that `x₀ + h v` lands
    /// on their path. Free entries of `v` are left alone.
    fn constrained_velocities(&self, t_end: Scalar, h: Scalar, x0: &[Vector], v: &mut [Vector]);
    /// Backward Euler's incremental potential (CSC417's "backward Euler as minimization"):
    ///
    /// `Φ(v) = ½ (v − v₀)ᵀ M (v − v₀) + E(x₀ + h v) + h R(v)`,
    ///
    /// `E` the potential energy (springs, gravity, external forces and the wind's push at
    /// `t_end`), `R` the Rayleigh dissipation `½ Σ b (n₀·(v_i − v_j))² + ½ c Σ |v_i|²` of the
    /// dampers (along their direction at `x₀`) and of drag. `∇Φ = M (v − v₀) − h f(x₀ + h v, v)`,
    /// so its minimizer is the backward Euler velocity. Writes `x = x₀ + h v` and, when asked,
    /// the gradient (zero on constrained particles). Sums over free particles only. The value
    /// is computed and summed in `f64` whatever the crate's precision: a line search compares
    /// values that differ in their last digits near convergence.
    #[allow(clippy::too_many_arguments)]
    fn incremental_potential(
        &self,
        t_end: Scalar,
        h: Scalar,
        x0: &[Vector],
        v0: &[Vector],
        v: &[Vector],
        x: &mut [Vector],
        grad: Option<&mut [Vector]>,
    ) -> f64;
    /// The springs as constraints, for the position-based and projective methods (XPBD,
    /// projective dynamics): `None` when the system has forces those methods cannot express
    /// as constraints here (finite elements).
    fn constraint_springs(&self) -> Option<&crate::core::forces::Springs> {
        None
    }
    /// Adds the applied forces into `f` at `(t, state)`: gravity as `m g` on free particles,
    /// the wind's push `c w(t)`, external forces and force fields — every force except the
    /// springs, the elements and the drag linear in velocity
    /// ([`Linearization::drag_coefficient`]).
    fn applied_forces(&self, t: Scalar, state: &ParticleState, f: &mut [Vector]) {
        let _ = (t, state, f);
    }
    /// The coefficient `c` of the drag `−c v` on every free particle (drag plus the wind's
    /// drag coefficient).
    fn drag_coefficient(&self) -> Scalar {
        0.0
    }
    /// Holds particles resting on or pressed into colliders still for the coming implicit
    /// step (their `mask` set to 0 and velocity to the collider's): sticking contact as a
    /// constraint of the solve, for steps that do not hold them along the contact normals
    /// with friction ([`Linearization::hold_faces`] with `points`: linearly implicit Euler
    /// does, for a tet body's as for a cloth's). `scratch` takes the forces (resized to the
    /// particles, so a step reusing it allocates nothing). The default holds none.
    fn hold_contacts(
        &self,
        t: Scalar,
        state: &mut ParticleState,
        mask: &mut [Scalar],
        scratch: &mut Vec<Vector>,
    ) {
        let _ = (t, state, mask, scratch);
    }
    /// Holds the corners of triangles resting on colliders along the contact normals for
    /// the step of length `h` from `t`
    /// ([`Collider::hold_faces`](crate::core::collide::Collider::hold_faces)), and with
    /// `points` the particles resting on colliders as well
    /// ([`Collider::hold_points`](crate::core::collide::Collider::hold_points)): fills
    /// `holds`' raw list (cleared first); `f` is the total force at the step's start. None
    /// by default.
    #[allow(clippy::too_many_arguments)]
    fn hold_faces(
        &self,
        t: Scalar,
        h: Scalar,
        state: &ParticleState,
        f: &[Vector],
        mask: &[Scalar],
        points: bool,
        holds: &mut NormalHolds,
    ) {
        let _ = (t, h, state, f, mask, points);
        holds.clear();
    }
    /// True when [`Linearization::hold_faces`] and [`Linearization::hold_faces_trial`] can
    /// hold anything (holding switched on, colliders, and a surface whose triangles meet
    /// them or, with `points`, particles): steps skip building trial ends otherwise. False
    /// by default.
    fn may_hold_faces(&self, points: bool) -> bool {
        let _ = points;
        false
    }
    /// Adds to `holds` the corners of triangles that the trial end of the step in
    /// `holds.trial` takes into colliders
    /// ([`Collider::hold_faces_trial`](crate::core::collide::Collider::hold_faces_trial)),
    /// and with `points` the particles it takes into them
    /// ([`Collider::hold_points_trial`](crate::core::collide::Collider::hold_points_trial));
    /// `state` is the step's start. Returns true when it added any. None by default.
    fn hold_faces_trial(
        &self,
        t: Scalar,
        h: Scalar,
        state: &ParticleState,
        mask: &[Scalar],
        points: bool,
        holds: &mut NormalHolds,
    ) -> bool {
        let _ = (t, h, state, mask, points, holds);
        false
    }
    /// True when the system has elements whose semi-definite projection is costly (tets: a
    /// 9×9 eigen-decomposition each). Implicit methods then first try the exact element
    /// Hessians (springs still clamped) and project only when the solve reports an indefinite
    /// matrix: at game step sizes `M` usually dominates the indefinite part of `h² K`.
    fn has_costly_projection(&self) -> bool {
        false
    }
    /// [`Linearization::assemble`] with springs' stiffness clamped and element Hessians
    /// projected only when `project_elements`.
    fn assemble_elements(
        &self,
        state: &ParticleState,
        h: Scalar,
        project_elements: bool,
        a: &mut SpringMatrix,
        kv: &mut [Vector],
    ) {
        let _ = project_elements;
        self.assemble(state, h, true, a, kv)
    }
    /// [`Linearization::assemble_incremental_hessian`] with springs' stiffness clamped and
    /// element Hessians projected only when `project_elements`.
    fn assemble_incremental_hessian_elements(
        &self,
        h: Scalar,
        x0: &[Vector],
        x: &[Vector],
        project_elements: bool,
        a: &mut SpringMatrix,
    ) {
        let _ = project_elements;
        self.assemble_incremental_hessian(h, x0, x, true, a)
    }
    /// The Hessian of [`Linearization::incremental_potential`] at `x = x₀ + h v`:
    /// `a = M + h c I + h Σ b n₀n₀ᵀ + h² K(x)`, with `definite` projecting each spring's `K_s`
    /// onto the positive semi-definite cone.
    fn assemble_incremental_hessian(
        &self,
        h: Scalar,
        x0: &[Vector],
        x: &[Vector],
        definite: bool,
        a: &mut SpringMatrix,
    );
}

impl Linearization for ParticleModel {
    fn particles(&self) -> usize {
        self.len()
    }
    fn element_counts(&self) -> (usize, usize) {
        (self.springs.len(), self.tets.len())
    }

    fn new_matrix(&self) -> SpringMatrix {
        if self.tets.is_empty() {
            return SpringMatrix::new(self.len(), &self.springs);
        }
        SpringMatrix::with_pairs(self.len(), self.matrix_pairs().collect())
            .with_symmetric_prefix(self.springs.len())
    }

    fn matrix_matches(&self, a: &SpringMatrix) -> bool {
        if self.tets.is_empty() {
            return a.matches(self.len(), &self.springs);
        }
        a.matches_pairs(self.len(), self.matrix_pairs())
    }

    fn masses(&self) -> &[Scalar] {
        self.mass()
    }

    fn free_mask(&self, mask: &mut [Scalar]) -> bool {
        // `pin` and `prescribe` zero a particle's inverse mass and `release` restores it, so a
        // positive inverse mass is exactly "free with a valid mass" — no scan of the pin list
        // per particle on every implicit step. A particle is pinned or prescribed at most once,
        // so any other zero is a free particle without a valid mass.
        let mut zeros = 0;
        for (m, w) in mask.iter_mut().zip(self.inv_mass()) {
            *m = if *w > 0.0 { 1.0 } else { 0.0 };
            zeros += (*w <= 0.0) as usize;
        }
        zeros == self.pins().len() + self.motions().len()
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
        if !self.tets.is_empty() {
            self.tets.accumulate_f64(&state.x, f);
        }
        self.applied_forces(t, state, f);
    }

    fn constraint_springs(&self) -> Option<&crate::core::forces::Springs> {
        self.tets.is_empty().then_some(&self.springs)
    }

    fn drag_coefficient(&self) -> Scalar {
        self.linear_drag()
    }

    fn applied_forces(&self, t: Scalar, state: &ParticleState, f: &mut [Vector]) {
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
        self.accumulate_fields(t, &state.x, &state.v, f);
    }

    fn assemble_damping(&self, state: &ParticleState, h: Scalar, a: &mut SpringMatrix) {
        let (springs, x) = (self.springs.as_slice(), &state.x);
        a.fill_springs(
            springs.len(),
            self.mass_diagonal(h),
            |k| {
                let s = &springs[k];
                let d = x[s.i as usize] - x[s.j as usize];
                let l = d.length();
                let blk = if l > 0.0 && s.damping != 0.0 {
                    let n = d / l;
                    outer(n, n) * (h * s.damping)
                } else {
                    Matrix3::ZERO
                };
                (blk, Vector::ZERO)
            },
            None,
        );
        a.off[self.springs.len()..].fill(Matrix3::ZERO);
    }

    fn assemble(
        &self,
        state: &ParticleState,
        h: Scalar,
        definite: bool,
        a: &mut SpringMatrix,
        kv: &mut [Vector],
    ) {
        self.assemble_with(state, h, definite, definite, a, kv)
    }

    fn has_costly_projection(&self) -> bool {
        !self.tets.is_empty()
    }

    /// Finite-element bodies hold their contacts still (see
    /// [`Collider::hold`](crate::core::collide::Collider::hold)); spring bodies keep the
    /// post-step projection alone, as before.
    fn hold_contacts(
        &self,
        t: Scalar,
        state: &mut ParticleState,
        mask: &mut [Scalar],
        scratch: &mut Vec<Vector>,
    ) {
        if self.tets.is_empty() || self.colliders.is_empty() {
            return;
        }
        scratch.resize(self.len(), Vector::ZERO);
        self.total_forces(t, state, scratch);
        // A particle projected onto the surface last step is touching it.
        for c in &self.colliders {
            c.hold(
                t,
                ROUND_OFF_SLACK,
                &state.x,
                &mut state.v,
                scratch,
                self.inv_mass(),
                mask,
            );
        }
    }

    fn hold_faces(
        &self,
        t: Scalar,
        h: Scalar,
        state: &ParticleState,
        f: &[Vector],
        mask: &[Scalar],
        points: bool,
        holds: &mut NormalHolds,
    ) {
        holds.clear();
        if !self.may_hold_faces(points) {
            return;
        }
        for c in &self.colliders {
            // A fiftieth of the thickness of slack: a triangle whose corners the last step
            // held at the thickness is resting on the collider, though its nearest point may
            // have come out a little (each corner is held along one normal). On a collider
            // without thickness, the round-off of a particle the contact put on its surface.
            let slack = (0.02 * c.material.thickness as Scalar).max(ROUND_OFF_SLACK);
            let from = holds.raw.len();
            if points {
                c.hold_points(
                    t,
                    h,
                    slack,
                    &state.x,
                    &state.v,
                    f,
                    self.inv_mass(),
                    mask,
                    &mut holds.raw,
                );
            }
            let faces_from = holds.raw.len();
            c.hold_faces(
                t,
                h,
                slack,
                &self.contact_faces,
                self.face_edge,
                &state.x,
                &state.v,
                f,
                self.inv_mass(),
                mask,
                &mut holds.raw,
                &mut holds.faces,
            );
            holds.face_friction_from(faces_from);
            // A corner of several triangles on this collider, or a particle resting on it
            // that is also a corner, touches it once: one friction. (The particles' own
            // holds are one a particle.)
            if holds.face_friction && holds.raw.len() > faces_from {
                holds.one_friction_per_particle(from);
            }
        }
    }

    fn may_hold_faces(&self, points: bool) -> bool {
        self.hold_faces && !self.colliders.is_empty() && (points || !self.contact_faces.is_empty())
    }

    fn hold_faces_trial(
        &self,
        t: Scalar,
        h: Scalar,
        state: &ParticleState,
        mask: &[Scalar],
        points: bool,
        holds: &mut NormalHolds,
    ) -> bool {
        if !self.may_hold_faces(points) {
            return false;
        }
        let mut added = 0;
        for c in &self.colliders {
            if points {
                added += c.hold_points_trial(
                    t,
                    h,
                    &state.x,
                    &holds.trial,
                    self.inv_mass(),
                    mask,
                    &mut holds.raw,
                );
            }
            let faces_from = holds.raw.len();
            added += c.hold_faces_trial(
                t,
                h,
                &self.contact_faces,
                self.face_edge,
                &state.x,
                &holds.trial,
                self.inv_mass(),
                mask,
                &mut holds.raw,
            );
            holds.face_friction_from(faces_from);
        }
        added > 0
    }

    fn assemble_elements(
        &self,
        state: &ParticleState,
        h: Scalar,
        project_elements: bool,
        a: &mut SpringMatrix,
        kv: &mut [Vector],
    ) {
        self.assemble_with(state, h, true, project_elements, a, kv)
    }

    fn assemble_incremental_hessian_elements(
        &self,
        h: Scalar,
        x0: &[Vector],
        x: &[Vector],
        project_elements: bool,
        a: &mut SpringMatrix,
    ) {
        self.hessian_with(h, x0, x, true, project_elements, a)
    }

    fn constrained_velocities(&self, t_end: Scalar, h: Scalar, x0: &[Vector], v: &mut [Vector]) {
        for &(p, _) in self.pins() {
            v[p as usize] = Vector::ZERO;
        }
        for (p, m) in self.motions() {
            let p = *p as usize;
            v[p] = (m.eval(t_end).0 - x0[p]) / h;
        }
    }

    fn incremental_potential(
        &self,
        t_end: Scalar,
        h: Scalar,
        x0: &[Vector],
        v0: &[Vector],
        v: &[Vector],
        x: &mut [Vector],
        mut grad: Option<&mut [Vector]>,
    ) -> f64 {
        for ((xi, x0i), vi) in x.iter_mut().zip(x0).zip(v) {
            *xi = *x0i + *vi * h;
        }
        let d64 = |a: Vector| glam::DVec3::from_array(a.to_f64());
        let h64 = h as f64;
        let pos = |i: usize| d64(x0[i]) + d64(v[i]) * h64;
        let mut phi = 0.0f64;
        for s in self.springs.as_slice() {
            let e = (pos(s.i as usize) - pos(s.j as usize)).length() - s.rest as f64;
            phi += 0.5 * s.k as f64 * e * e;
        }
        if let Some(g) = grad.as_deref_mut() {
            g.fill(Vector::ZERO);
            if !self.springs.is_empty() {
                self.springs.accumulate_elastic(x, g);
            }
            if !self.tets.is_empty() {
                self.tets.accumulate_f64(x, g);
            }
            for gi in g.iter_mut() {
                *gi *= -h;
            }
        }
        if !self.tets.is_empty() {
            // A barrier: a step that inverts or flattens an element has infinite energy, so
            // the line search shrinks it.
            phi += self.tets.barrier_energy(x0, x);
            if phi == f64::INFINITY {
                return phi;
            }
        }
        let c = self.linear_drag();
        let wc = self.wind_coefficient();
        let push = if wc > 0.0 {
            self.wind_velocity(t_end) * wc
        } else {
            Vector::ZERO
        };
        let ext = self.external_forces();
        for i in 0..self.len() {
            if self.inv_mass()[i] <= 0.0 {
                if let Some(g) = grad.as_deref_mut() {
                    g[i] = Vector::ZERO;
                }
                continue;
            }
            let m = self.mass()[i];
            let dv = v[i] - v0[i];
            let mut fc = self.gravity * m + push;
            if let Some(e) = ext {
                fc += e[i];
            }
            // Force fields: constant over the step, at its start (no potential to minimize).
            for field in &self.fields {
                fc += field.force(t_end - h, x0[i], v0[i], m);
            }
            let (dv64, v64) = (d64(v[i]) - d64(v0[i]), d64(v[i]));
            phi += 0.5 * m as f64 * dv64.length_squared() - d64(fc).dot(pos(i))
                + 0.5 * h64 * c as f64 * v64.length_squared();
            if let Some(g) = grad.as_deref_mut() {
                g[i] += dv * m - fc * h + v[i] * (h * c);
            }
        }
        if self.springs.has_damping() {
            for s in self.springs.as_slice() {
                let (i, j) = (s.i as usize, s.j as usize);
                let d = x0[i] - x0[j];
                let l = d.length();
                if s.damping == 0.0 || l == 0.0 {
                    continue;
                }
                let n = d / l;
                let rate = n.dot(v[i] - v[j]);
                let rate64 = d64(n).dot(d64(v[i]) - d64(v[j]));
                phi += 0.5 * h64 * s.damping as f64 * rate64 * rate64;
                if let Some(g) = grad.as_deref_mut() {
                    let gi = n * (h * s.damping * rate);
                    if self.inv_mass()[i] > 0.0 {
                        g[i] += gi;
                    }
                    if self.inv_mass()[j] > 0.0 {
                        g[j] -= gi;
                    }
                }
            }
        }
        phi
    }

    fn assemble_incremental_hessian(
        &self,
        h: Scalar,
        x0: &[Vector],
        x: &[Vector],
        definite: bool,
        a: &mut SpringMatrix,
    ) {
        self.hessian_with(h, x0, x, definite, definite, a)
    }
}

impl ParticleModel {
    fn hessian_with(
        &self,
        h: Scalar,
        x0: &[Vector],
        x: &[Vector],
        definite: bool,
        project_tets: bool,
        a: &mut SpringMatrix,
    ) {
        let h2 = h * h;
        let springs = self.springs.as_slice();
        a.fill_springs(
            springs.len(),
            self.mass_diagonal(h),
            |k| {
                let s = &springs[k];
                let blk = spring_stiffness(s, x, definite) * h2 + damper_block(s, x0) * h;
                (blk, Vector::ZERO)
            },
            None,
        );
        self.add_tet_stiffness(x, h2, project_tets, a, None);
    }

    fn assemble_with(
        &self,
        state: &ParticleState,
        h: Scalar,
        definite: bool,
        project_tets: bool,
        a: &mut SpringMatrix,
        kv: &mut [Vector],
    ) {
        let h2 = h * h;
        let (springs, x, v) = (self.springs.as_slice(), &state.x, &state.v);
        // (K v)_i = −K_s (v_i − v_j), (K v)_j = +K_s (v_i − v_j)
        a.fill_springs(
            springs.len(),
            self.mass_diagonal(h),
            |k| assembly_block(&springs[k], x, v, h, definite),
            Some(kv),
        );
        self.add_tet_stiffness(&state.x, h2, project_tets, a, Some((&state.v, kv)));
        self.add_field_diagonal(state, h, h2, a, Some(kv));
    }

    /// The force fields' Jacobians where they stiffen or damp: the positive part of the
    /// diagonal of `−∂f/∂x` (times `h2`) and of `−∂f/∂v` (times `h`) added to `a`'s diagonal
    /// blocks, and that stiffness's `K v` to `kv`. The rest of a field acts explicitly.
    fn add_field_diagonal(
        &self,
        state: &ParticleState,
        h: Scalar,
        h2: Scalar,
        a: &mut SpringMatrix,
        mut kv: Option<&mut [Vector]>,
    ) {
        if self.fields.is_empty() {
            return;
        }
        // The time of the last force evaluation: the step's (the methods evaluate the forces,
        // then assemble).
        let t = self.field_time();
        for i in 0..self.len() {
            for field in &self.fields {
                let Some(j) = field.jacobian(t, state.x[i], state.v[i], self.mass()[i]) else {
                    continue;
                };
                let mut k = Vector::ZERO;
                let mut d = Vector::ZERO;
                for c in 0..3 {
                    k[c] = (-j.dx[c][c]).max(0.0);
                    d[c] = (-j.dv[c][c]).max(0.0);
                }
                let g = k * h2 + d * h;
                a.diag[i] += Matrix3::from_cols(Vector::X * g.x, Vector::Y * g.y, Vector::Z * g.z);
                if let Some(kv) = kv.as_deref_mut() {
                    kv[i] -= k * state.v[i];
                }
            }
        }
    }
}
