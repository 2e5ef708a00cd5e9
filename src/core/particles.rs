//! The mass-spring particle model as an [`OdeSystem`]: second-order dynamics
//! `x'' = M⁻¹ f(x, x', t)` written first-order as `X = (x, v)`, `X' = (v, M⁻¹ f)`.
//!
//! A model is layout only: masses, which particles are pinned or move on prescribed paths,
//! and the forces it has. Every force is optional and costs nothing when absent.

use crate::core::collide::Collider;
use crate::core::driver::CflLimit;
use crate::core::fem::Tets;
use crate::core::forces::{Springs, Wind, WindField};
use crate::core::motion::Motion;
use crate::core::ode::{Energy, OdeState, OdeSystem, ParticleState, slice_finite};
use crate::math::{Scalar, ToScalar, Vector};

/// How a particle's degrees of freedom are governed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Dof {
    /// Moved by forces.
    Free,
    /// Held at a fixed position.
    Pinned,
    /// Moved along a prescribed path (index into the model's motions).
    Prescribed(u32),
}

/// Particles, their masses and constraints, and the forces acting on them.
#[derive(Clone, Debug, Default)]
pub struct ParticleModel {
    mass: Vec<Scalar>,
    inv_mass: Vec<Scalar>,
    pinned: Vec<(u32, Vector)>,
    prescribed: Vec<(u32, Motion)>,
    /// Springs and spring dampers.
    pub springs: Springs,
    /// Linear tetrahedra (finite elements).
    pub tets: Tets,
    /// Gravitational acceleration (zero: no gravity term is evaluated).
    pub gravity: Vector,
    /// Viscous drag `−k v` on every free particle (zero: skipped).
    pub drag: Scalar,
    wind: Option<(Wind, WindField)>,
    external: Option<Vec<Vector>>,
    /// Force fields on every particle (empty: none evaluated).
    pub fields: Vec<crate::core::forces::SharedField>,
    /// Time of the last force evaluation with fields (for their Jacobians).
    field_time: FieldClock,
    /// Shapes the particles collide with (empty: no collision pass).
    pub colliders: Vec<Collider>,
    /// The surface's contact with itself (`None`: no pass, no cost).
    pub self_contact: Option<crate::core::self_contact::SelfContact>,
    /// The surface's triangles, for colliders to touch between the particles (empty: the
    /// particles alone touch colliders); tested only against colliders that can come between
    /// a surface's particles, see [`Collider::needs_faces`].
    pub contact_faces: Vec<[u32; 3]>,
    /// Implicit steps (linearly implicit Euler, the trapezoid with implicit damping, backward
    /// Euler's Newton iteration; with PCG or the sparse Cholesky) hold the corners of
    /// triangles resting on colliders, or that the step would take into them, along the
    /// contact normals inside the solve
    /// ([`Linearization::hold_faces`](crate::core::jacobian::Linearization::hold_faces)),
    /// instead of leaving them wholly to the contact after the step, which on a rod as wide
    /// as the cells left a cloth wedged (docs/BENCHMARKS.md, "holding triangles inside the
    /// implicit solve"); backward Euler and linearly implicit Euler hold a cloth's particles
    /// resting on colliders too, with Coulomb friction inside the solve, so that a cloth at
    /// rest is in static equilibrium. Linearly implicit Euler holds a tet body's particles so
    /// as well, and gives the triangles' corners it holds their collider's friction, so that
    /// a body on a slope slides as Coulomb's law says; otherwise (backward Euler, the
    /// trapezoid, or with this off) a tet body's particles pressed on colliders are held
    /// still ([`Linearization::hold_contacts`](crate::core::jacobian::Linearization::hold_contacts)). On by
    /// default ([`ParticleModel::new`]); off, a run in contact costs less (the 64² cloth on a
    /// rod 1.0–1.6 times less, docs/BENCHMARKS.md) but may wedge.
    pub hold_faces: bool,
    /// The longest edge of [`ParticleModel::contact_faces`] at the frame's start, times
    /// [`FACE_EDGE_GROWTH`] (infinite until measured).
    pub(crate) face_edge: Scalar,
    /// The features colliders touch between the particles: [`ParticleModel::contact_faces`],
    /// then each of their edges once, as a triangle `[a, b, b]` (see
    /// [`Collider::resolve_faces`]); made from `features_for`, a copy of the faces they were
    /// made from.
    features: Vec<[u32; 3]>,
    features_for: Vec<[u32; 3]>,
    /// The particles' positions at the step's start, for the features' swept test: `x − h v`
    /// before any contact (exact for the Euler methods, whose step ends at `x₀ + h v₁`; for
    /// the others the start of the straight path with the end's velocity).
    face_start: Vec<Vector>,
    /// The features the last collider's face contact met (reused: a step allocates nothing).
    faces_near: Vec<(u32, Vector)>,
    /// Whether the last fused symplectic Euler step found the particles it wrote finite.
    swept: SweptCheck,
    /// Whether the pins are known to hold in a state.
    pins_held: PinsHeld,
}

/// How much longer than at the frame's start a surface triangle's edge is taken to grow
/// within the frame, for the test of which colliders need the triangles
/// ([`Collider::needs_faces`]): an edge stretched further than this within one frame (a
/// tearing cloth's) may let a round collider as far into the surface as between particles.
pub const FACE_EDGE_GROWTH: Scalar = 1.5;

/// What the model knows of its pins in one state (told apart by its positions' address):
/// nothing, written there by [`OdeSystem::apply_constraints`], or written there and not moved
/// since (see [`ParticleModel::apply_constraints`]).
#[derive(Debug, Default)]
struct PinsHeld {
    what: std::sync::atomic::AtomicU8,
    at: std::sync::atomic::AtomicUsize,
}

impl PinsHeld {
    const NOTHING: u8 = 0;
    const APPLIED: u8 = 1;
    const KEPT: u8 = 2;

    fn get(&self, x: &[Vector]) -> u8 {
        use std::sync::atomic::Ordering::Relaxed;
        if self.at.load(Relaxed) == x.as_ptr() as usize {
            self.what.load(Relaxed)
        } else {
            Self::NOTHING
        }
    }

    fn set(&self, what: u8, x: &[Vector]) {
        use std::sync::atomic::Ordering::Relaxed;
        self.at.store(x.as_ptr() as usize, Relaxed);
        self.what.store(what, Relaxed);
    }

    fn forget(&self) {
        self.what
            .store(Self::NOTHING, std::sync::atomic::Ordering::Relaxed);
    }
}

impl Clone for PinsHeld {
    /// A copy knows nothing of the original's states.
    fn clone(&self) -> Self {
        Self::default()
    }
}

/// What the last fused symplectic Euler step found of the state it wrote (see
/// [`ParticleModel::stepped_state_is_finite`]): taken, and so forgotten, by the check.
#[derive(Debug, Default)]
struct SweptCheck(std::sync::atomic::AtomicU8);

impl SweptCheck {
    const UNKNOWN: u8 = 0;
    const FINITE: u8 = 1;
    const NOT_FINITE: u8 = 2;

    fn set(&self, finite: bool) {
        let v = if finite {
            Self::FINITE
        } else {
            Self::NOT_FINITE
        };
        self.0.store(v, std::sync::atomic::Ordering::Relaxed);
    }

    fn take(&self) -> Option<bool> {
        // A load and a store, not a swap: the model is stepped by one thread at a time, and a
        // locked swap would wait for all of the step's stores to land.
        use std::sync::atomic::Ordering::Relaxed;
        let found = match self.0.load(Relaxed) {
            Self::FINITE => Some(true),
            Self::NOT_FINITE => Some(false),
            _ => return None,
        };
        self.0.store(Self::UNKNOWN, Relaxed);
        found
    }
}

impl Clone for SweptCheck {
    /// A copy knows nothing of the original's last step.
    fn clone(&self) -> Self {
        Self::default()
    }
}

/// The time of a model's last force evaluation with fields, shared by reference (force
/// evaluations take `&self`).
#[derive(Debug, Default)]
struct FieldClock(std::sync::atomic::AtomicU64);

impl FieldClock {
    fn set(&self, t: Scalar) {
        self.0
            .store((t as f64).to_bits(), std::sync::atomic::Ordering::Relaxed);
    }

    fn get(&self) -> Scalar {
        f64::from_bits(self.0.load(std::sync::atomic::Ordering::Relaxed)) as Scalar
    }
}

impl Clone for FieldClock {
    fn clone(&self) -> Self {
        let c = Self::default();
        c.set(self.get());
        c
    }
}

/// Why a model cannot be simulated.
#[derive(Clone, Debug, PartialEq)]
pub enum ModelError {
    /// A free particle's mass is zero, negative or not finite.
    BadMass {
        /// Particle index.
        particle: usize,
        /// The mass.
        mass: Scalar,
    },
    /// A spring refers to a particle that does not exist.
    SpringOutOfRange {
        /// Spring index.
        spring: usize,
        /// The bad particle index.
        particle: usize,
    },
    /// A spring's parameters are not usable.
    BadSpring {
        /// Spring index.
        spring: usize,
        /// What is wrong.
        reason: &'static str,
    },
    /// A particle index (pin, motion, force) is out of range.
    ParticleOutOfRange {
        /// The bad index.
        particle: usize,
    },
    /// A parameter is not finite.
    NonFinite(&'static str),
}

impl std::fmt::Display for ModelError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::BadMass { particle, mass } => {
                write!(
                    f,
                    "particle {particle}: mass {mass} must be positive and finite unless the particle is pinned"
                )
            }
            Self::SpringOutOfRange { spring, particle } => {
                write!(
                    f,
                    "spring {spring}: particle index {particle} is out of range"
                )
            }
            Self::BadSpring { spring, reason } => write!(f, "spring {spring}: {reason}"),
            Self::ParticleOutOfRange { particle } => {
                write!(f, "particle index {particle} is out of range")
            }
            Self::NonFinite(what) => write!(f, "{what} is not finite"),
        }
    }
}

impl std::error::Error for ModelError {}

impl ParticleModel {
    /// A self-contact pass at time `t`, with the particles touching a collider (within its
    /// thickness plus half the surface's, at a particle or at a triangle) marked as
    /// supported.
    fn self_contact_pass(&mut self, t: Scalar, state: &mut ParticleState) {
        let Some(sc) = &mut self.self_contact else {
            return;
        };
        let slack = 0.5 * sc.params.thickness as Scalar;
        let support = sc.support_mut(state.x.len());
        for c in &self.colliders {
            c.touching(t, slack, &state.x, support);
            let (faces, edge) = (&self.contact_faces, self.face_edge);
            c.touching_faces(t, slack, faces, edge, &state.x, support);
        }
        sc.pass(&mut state.x, &mut state.v, &self.inv_mass);
    }

    /// Remakes [`ParticleModel::features`] when the faces changed since they were made.
    fn refresh_features(&mut self) {
        if self.features_for == self.contact_faces {
            return;
        }
        self.features_for.clone_from(&self.contact_faces);
        let mut edges: Vec<[u32; 2]> = self
            .contact_faces
            .iter()
            .flat_map(|&[a, b, c]| [[a, b], [b, c], [c, a]])
            .map(|[a, b]| [a.min(b), a.max(b)])
            .filter(|[a, b]| a != b)
            .collect();
        edges.sort_unstable();
        edges.dedup();
        self.features.clear();
        self.features.extend_from_slice(&self.contact_faces);
        self.features.extend(edges.iter().map(|&[a, b]| [a, b, b]));
    }

    /// A model of particles with the given masses, all free, with no forces.
    pub fn new(mass: Vec<Scalar>) -> Self {
        let inv_mass = mass
            .iter()
            .map(|&m| {
                if m > 0.0 && m.is_finite() {
                    1.0 / m
                } else {
                    0.0
                }
            })
            .collect();
        Self {
            mass,
            inv_mass,
            face_edge: Scalar::INFINITY,
            hold_faces: true,
            ..Default::default()
        }
    }

    /// Time of the last force evaluation that involved force fields.
    pub(crate) fn field_time(&self) -> Scalar {
        self.field_time.get()
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.mass.len()
    }

    /// True when there are no particles.
    pub fn is_empty(&self) -> bool {
        self.mass.is_empty()
    }

    /// Masses.
    pub fn mass(&self) -> &[Scalar] {
        &self.mass
    }

    /// Inverse masses (zero for pinned and prescribed particles).
    pub fn inv_mass(&self) -> &[Scalar] {
        &self.inv_mass
    }

    /// Pins particle `i` at `position`.
    pub fn pin(&mut self, i: usize, position: Vector) {
        self.release(i);
        // Kept in particle order: a chunk of particles finds its pins by bisection.
        let at = self.pinned.partition_point(|&(p, _)| (p as usize) < i);
        self.pinned.insert(at, (i as u32, position));
        self.inv_mass[i] = 0.0;
    }

    /// Moves particle `i` along `motion`.
    pub fn prescribe(&mut self, i: usize, motion: Motion) {
        self.release(i);
        self.prescribed.push((i as u32, motion));
        self.inv_mass[i] = 0.0;
    }

    /// Frees particle `i` (from a pin or a prescribed motion).
    pub fn release(&mut self, i: usize) {
        self.pins_held.forget();
        self.pinned.retain(|(p, _)| *p as usize != i);
        self.prescribed.retain(|(p, _)| *p as usize != i);
        let m = self.mass[i];
        self.inv_mass[i] = if m > 0.0 && m.is_finite() {
            1.0 / m
        } else {
            0.0
        };
    }

    /// How particle `i` moves.
    pub fn dof(&self, i: usize) -> Dof {
        if self.pinned.iter().any(|(p, _)| *p as usize == i) {
            return Dof::Pinned;
        }
        match self.prescribed.iter().position(|(p, _)| *p as usize == i) {
            Some(k) => Dof::Prescribed(k as u32),
            None => Dof::Free,
        }
    }

    /// Pinned particles and where they are held.
    pub fn pins(&self) -> &[(u32, Vector)] {
        &self.pinned
    }

    /// Particles with prescribed motion.
    pub fn motions(&self) -> &[(u32, Motion)] {
        &self.prescribed
    }

    /// Turns wind on (or off with `None`).
    pub fn set_wind(&mut self, wind: Option<Wind>) {
        self.wind = wind.filter(|w| w.enabled).map(|w| (w, w.field()));
    }

    /// Air-drag coefficient of the wind (0 when off).
    pub fn wind_coefficient(&self) -> Scalar {
        self.wind.as_ref().map_or(0.0, |(_, w)| w.coefficient())
    }

    /// Air velocity of the wind at time `t` (zero when off).
    pub fn wind_velocity(&self, t: Scalar) -> Vector {
        self.wind
            .as_ref()
            .map_or(Vector::ZERO, |(_, w)| w.velocity(t))
    }

    /// The wind, if on.
    pub fn wind(&self) -> Option<&Wind> {
        self.wind.as_ref().map(|(w, _)| w)
    }

    /// Sets a constant external force on particle `i`.
    pub fn set_external_force(&mut self, i: usize, f: Vector) {
        let n = self.len();
        self.external.get_or_insert_with(|| vec![Vector::ZERO; n])[i] = f;
    }

    /// Per-particle external forces, if any were set.
    pub fn external_forces(&self) -> Option<&[Vector]> {
        self.external.as_deref()
    }

    /// Checks that the model can be simulated: masses of free particles positive and finite,
    /// spring indices in range, parameters finite.
    pub fn validate(&self) -> Result<(), ModelError> {
        let n = self.len();
        for (i, &m) in self.mass.iter().enumerate() {
            if self.inv_mass[i] == 0.0 && matches!(self.dof(i), Dof::Free)
                || !m.is_finite() && m != 0.0
            {
                return Err(ModelError::BadMass {
                    particle: i,
                    mass: m,
                });
            }
        }
        for (k, s) in self.springs.as_slice().iter().enumerate() {
            for p in [s.i as usize, s.j as usize] {
                if p >= n {
                    return Err(ModelError::SpringOutOfRange {
                        spring: k,
                        particle: p,
                    });
                }
            }
            if s.i == s.j {
                return Err(ModelError::BadSpring {
                    spring: k,
                    reason: "joins a particle to itself",
                });
            }
            if !(s.k.is_finite() && s.k >= 0.0) {
                return Err(ModelError::BadSpring {
                    spring: k,
                    reason: "stiffness must be finite and non-negative",
                });
            }
            if !(s.rest.is_finite() && s.rest >= 0.0) {
                return Err(ModelError::BadSpring {
                    spring: k,
                    reason: "rest length must be finite and non-negative",
                });
            }
            if !(s.damping.is_finite() && s.damping >= 0.0) {
                return Err(ModelError::BadSpring {
                    spring: k,
                    reason: "damping must be finite and non-negative",
                });
            }
        }
        if self.tets.bound() > n {
            return Err(ModelError::ParticleOutOfRange {
                particle: self.tets.bound() - 1,
            });
        }
        for &(p, x) in &self.pinned {
            if p as usize >= n {
                return Err(ModelError::ParticleOutOfRange {
                    particle: p as usize,
                });
            }
            if !x.is_finite() {
                return Err(ModelError::NonFinite("pin position"));
            }
        }
        for (p, m) in &self.prescribed {
            if *p as usize >= n {
                return Err(ModelError::ParticleOutOfRange {
                    particle: *p as usize,
                });
            }
            if !m.is_finite() {
                return Err(ModelError::NonFinite("prescribed motion"));
            }
        }
        if !self.gravity.is_finite() {
            return Err(ModelError::NonFinite("gravity"));
        }
        if !(self.drag.is_finite() && self.drag >= 0.0) {
            return Err(ModelError::NonFinite(
                "drag (must be finite and non-negative)",
            ));
        }
        if let Some(e) = &self.external {
            if e.len() != n {
                return Err(ModelError::ParticleOutOfRange { particle: e.len() });
            }
            if !e.iter().all(|f| f.is_finite()) {
                return Err(ModelError::NonFinite("external force"));
            }
        }
        Ok(())
    }

    /// Adds every force into `f` (one entry per particle), without dividing by mass.
    pub fn accumulate_forces(&self, t: Scalar, state: &ParticleState, f: &mut [Vector]) {
        if !self.springs.is_empty() {
            self.springs.accumulate(&state.x, &state.v, f);
        }
        if !self.tets.is_empty() {
            self.tets.accumulate(&state.x, f);
        }
        let (c, push) = self.drag_terms(t);
        if c != 0.0 {
            for (fi, vi) in f.iter_mut().zip(&state.v) {
                *fi += push - *vi * c;
            }
        }
        if let Some(ext) = &self.external {
            for (fi, e) in f.iter_mut().zip(ext) {
                *fi += *e;
            }
        }
        self.accumulate_fields(t, &state.x, &state.v, f);
    }

    /// The drag and wind coefficient `c` and the wind's push `c w(t)`: the per-particle force
    /// `push − c v` (both zero without drag or wind).
    fn drag_terms(&self, t: Scalar) -> (Scalar, Vector) {
        let wind_c = self.wind.as_ref().map_or(0.0, |(_, w)| w.coefficient());
        let c = self.drag + wind_c;
        let push = match &self.wind {
            Some((_, w)) if c != 0.0 => w.velocity(t) * wind_c,
            _ => Vector::ZERO,
        };
        (c, push)
    }

    /// After a symplectic Euler sweep: pinned particles stay where `scratch.x` saved them.
    fn fix_pinned(&self, h: Scalar, state: &mut ParticleState, scratch: &ParticleState) {
        for &(p, _) in &self.pinned {
            // The derivative of a pin is zero: x and v stay (v got + 0 in the sweep).
            let p = p as usize;
            let dv = Vector::ZERO * h;
            state.x[p] = scratch.x[p] + (Vector::ZERO + dv) * h;
        }
    }

    /// After a symplectic Euler sweep: prescribed particles follow their motions' velocity
    /// and acceleration at `t` from where `scratch.x` saved them.
    fn fix_prescribed(
        &self,
        t: Scalar,
        h: Scalar,
        state: &mut ParticleState,
        scratch: &ParticleState,
    ) {
        for (p, m) in &self.prescribed {
            let p = *p as usize;
            let (_, vp, ap) = m.eval(t);
            let dv = ap * h;
            state.v[p] += dv;
            state.x[p] = scratch.x[p] + (vp + dv) * h;
        }
    }

    /// Adds the force fields' forces into `f` (nothing when there are none).
    pub fn accumulate_fields(&self, t: Scalar, x: &[Vector], v: &[Vector], f: &mut [Vector]) {
        if self.fields.is_empty() {
            return;
        }
        self.field_time.set(t);
        for (i, fi) in f.iter_mut().enumerate() {
            for field in &self.fields {
                *fi += field.force(t, x[i], v[i], self.mass[i]);
            }
        }
    }

    /// True when the force kernels cut this model into more than one chunk of work, so that
    /// evaluating it on several threads pays ([`crate::core::kernels`]).
    pub fn is_chunked(&self) -> bool {
        self.springs.rows().chunks() > 1 || self.tets.chunks() > 1
    }

    /// Elastic energy of springs and tets.
    pub fn elastic_energy(&self, x: &[Vector]) -> Scalar {
        let mut e = self.springs.energy(x);
        if !self.tets.is_empty() {
            e += self.tets.energy(x) as Scalar;
        }
        e
    }

    /// Smallest explicit step bound over the springs: `min(√(μ/k), μ/b)` with `μ` the reduced
    /// mass of the two free ends (the period and damping time of one spring, up to 2π);
    /// `None` when no spring constrains it.
    pub fn spring_time_scale(&self) -> Option<Scalar> {
        self.spring_bound(CflLimit::Oscillation)
    }

    /// Smallest per-spring time bound of the given form (see [`CflLimit`]) over springs with a
    /// free end; `None` when no spring constrains the step.
    pub fn spring_bound(&self, limit: CflLimit) -> Option<Scalar> {
        let mut best: Option<Scalar> = None;
        for s in self.springs.as_slice() {
            let (wi, wj) = (self.inv_mass[s.i as usize], self.inv_mass[s.j as usize]);
            let w = wi + wj; // 1/μ
            if w == 0.0 {
                continue;
            }
            let mu = 1.0 / w;
            let mut dt = Scalar::INFINITY;
            let damped = s.damping > 0.0;
            if s.k > 0.0 {
                dt = dt.min(match limit {
                    CflLimit::PhysBam if damped => s.damping / s.k,
                    CflLimit::PhysBamLater if damped => 2.0 * s.damping / s.k,
                    _ => (mu / s.k).sqrt(),
                });
            }
            if damped {
                dt = dt.min(match limit {
                    CflLimit::Oscillation => mu / s.damping,
                    CflLimit::PhysBam | CflLimit::PhysBamLater => mu * s.rest / s.damping,
                });
            }
            if dt.is_finite() {
                best = Some(best.map_or(dt, |b: Scalar| b.min(dt)));
            }
        }
        best
    }
}

/// The pins (in particle order) of the particles `r`.
fn pins_in(pins: &[(u32, Vector)], r: std::ops::Range<usize>) -> &[(u32, Vector)] {
    let a = pins.partition_point(|&(p, _)| (p as usize) < r.start);
    let b = pins.partition_point(|&(p, _)| (p as usize) < r.end);
    &pins[a..b]
}

impl OdeSystem<ParticleState> for ParticleModel {
    fn derivative(&self, t: Scalar, state: &ParticleState, out: &mut ParticleState) {
        out.x.copy_from_slice(&state.v);
        out.v.fill(Vector::ZERO);
        self.accumulate_forces(t, state, &mut out.v);
        let g = self.gravity;
        for (a, &w) in out.v.iter_mut().zip(&self.inv_mass) {
            // Pinned and prescribed particles have w = 0 and get no gravity.
            *a = if w > 0.0 { *a * w + g } else { Vector::ZERO };
        }
        for &(p, _) in &self.pinned {
            out.x[p as usize] = Vector::ZERO;
        }
        for (p, m) in &self.prescribed {
            let (_, v, a) = m.eval(t);
            out.x[*p as usize] = v;
            out.v[*p as usize] = a;
        }
    }

    /// `derivative` then `kick_drift` fused: forces into `scratch.v`, then one sweep
    /// `v ← v + h a`, `x ← x + h (v₀ + h a)`; pinned and prescribed particles (few) are redone
    /// afterwards with the derivative's values for them, from positions saved in `scratch.x`.
    ///
    /// A model whose forces are one kernel's (springs or tets) and per-particle terms (drag,
    /// wind, external forces) runs the step as two passes over memory: the kernel's element
    /// forces, then one pass in which each chunk of particles sums its forces, adds the rest,
    /// is swept and checked for finiteness (see [`Self::stepped_state_is_finite`]) — where
    /// clearing, gathering, sweeping and checking were four passes, each handed to the team.
    /// That pass sweeps the runs between pinned particles and leaves the pinned ones as they
    /// are (their derivative is zero); prescribed ones are redone as above. The same
    /// operations in the same order: the same bits.
    fn symplectic_euler(
        &self,
        t: Scalar,
        h: Scalar,
        state: &mut ParticleState,
        scratch: &mut ParticleState,
    ) -> bool {
        let _ = self.swept.take();
        let pins_held = self.pins_held.get(&state.x) >= PinsHeld::APPLIED;
        self.pins_held.forget();
        let one_kernel = self.springs.is_empty() != self.tets.is_empty();
        let fused = one_kernel && self.fields.is_empty();
        // The fused pass leaves pinned particles alone; the other ways sweep them and put
        // them back.
        let saved = if fused { &[][..] } else { &self.pinned[..] };
        for p in (saved.iter().map(|p| p.0)).chain(self.prescribed.iter().map(|p| p.0)) {
            scratch.x[p as usize] = state.x[p as usize];
        }
        let f = &mut scratch.v;
        if fused {
            let (c, push) = self.drag_terms(t);
            let external = self.external.as_deref();
            let (inv_mass, g) = (&self.inv_mass[..], self.gravity);
            let finite = std::sync::atomic::AtomicBool::new(true);
            let finish = |ch: crate::core::kernels::Chunk<'_>| {
                if c != 0.0 {
                    for (fi, vi) in ch.f.iter_mut().zip(ch.v.iter()) {
                        *fi += push - *vi * c;
                    }
                }
                if let Some(ext) = external {
                    for (fi, e) in ch.f.iter_mut().zip(&ext[ch.range.clone()]) {
                        *fi += *e;
                    }
                }
                // The runs of particles between pins, swept (prescribed ones have w = 0 and
                // get no gravity); a pinned particle's derivative is zero, so it stays as it
                // is. Where one thread swept and then put back every pin of the body, its
                // stores went to lines the other threads' chunks hold: a box of 1331
                // particles pinned on one face (every eleventh) took 6 µs a step longer on
                // two threads than unpinned.
                let sweep = crate::core::kernels::sweep::sweep_chunk;
                let first = ch.range.start;
                let mut from = 0;
                for &(p, _) in pins_in(&self.pinned, ch.range.clone()) {
                    let q = p as usize - first;
                    let w = &inv_mass[first + from..first + q];
                    sweep(
                        &mut ch.x[from..q],
                        &mut ch.v[from..q],
                        &ch.f[from..q],
                        w,
                        g,
                        h,
                    );
                    from = q + 1;
                }
                let w = &inv_mass[first + from..ch.range.end];
                sweep(&mut ch.x[from..], &mut ch.v[from..], &ch.f[from..], w, g, h);
                if !(slice_finite(ch.x) && slice_finite(ch.v)) {
                    finite.store(false, std::sync::atomic::Ordering::Relaxed);
                }
            };
            let (x, v) = (&mut state.x, &mut state.v);
            if self.springs.is_empty() {
                self.tets.set_then(x, v, f, &finish);
            } else {
                self.springs.set_then(x, v, f, &finish);
            }
            self.fix_prescribed(t, h, state, scratch);
            // Prescribed particles are checked after the driver's `apply_constraints`, which
            // rewrites them (`stepped_state_is_finite`).
            self.swept.set(finite.into_inner());
            if pins_held {
                self.pins_held.set(PinsHeld::KEPT, &state.x);
            }
            return true;
        }
        crate::core::kernels::sweep::clear(f);
        self.accumulate_forces(t, state, f);
        // Pinned and prescribed particles have w = 0 and get no gravity.
        crate::core::kernels::sweep::sweep(
            &mut state.x,
            &mut state.v,
            &scratch.v,
            &self.inv_mass,
            self.gravity,
            h,
        );
        self.fix_pinned(h, state, scratch);
        self.fix_prescribed(t, h, state, scratch);
        true
    }

    /// True when `state`, just stepped by this model's fused symplectic Euler and then
    /// constrained (with no colliders and no self-contact to move particles since), was
    /// found finite by the step itself, and its prescribed particles (few) are finite; any
    /// other state is checked whole. The step's own answer is used once.
    fn stepped_state_is_finite(&self, state: &ParticleState) -> bool {
        let swept = self.swept.take();
        let untouched = self.colliders.is_empty() && self.self_contact.is_none();
        if swept == Some(true) && untouched {
            return self.prescribed.iter().all(|&(p, _)| {
                let p = p as usize;
                slice_finite(&state.x[p..=p]) && slice_finite(&state.v[p..=p])
            });
        }
        state.is_finite()
    }

    /// Pinned particles to their pins at rest, prescribed ones onto their paths. The pins are
    /// skipped when they are known to hold already: written by the last call on this state,
    /// and the state since changed only by this model's fused symplectic Euler step (which
    /// leaves pinned particles alone) and colliders (which move only free ones). In the
    /// driver's loop, for a body without self-collision, that is every call but a frame's
    /// first; on two threads the writes went to
    /// lines of the other thread's chunks, and a tet box pinned on one face (121 of 1331
    /// particles, every eleventh) stepped 5.1 µs slower for them (41.5 against 36.4).
    fn apply_constraints(&self, t: Scalar, state: &mut ParticleState) {
        if self.pins_held.get(&state.x) != PinsHeld::KEPT {
            for &(p, x) in &self.pinned {
                state.x[p as usize] = x;
                state.v[p as usize] = Vector::ZERO;
            }
        }
        for (p, m) in &self.prescribed {
            let (x, v, _) = m.eval(t);
            state.x[*p as usize] = x;
            state.v[*p as usize] = v;
        }
        self.pins_held.set(PinsHeld::APPLIED, &state.x);
    }

    fn energy(&self, _t: Scalar, state: &ParticleState) -> Option<Energy> {
        let mut kinetic = 0.0;
        let mut potential = 0.0;
        for i in 0..self.len() {
            let m = self.mass[i];
            if m > 0.0 {
                kinetic += 0.5 * m * state.v[i].length_squared();
                if self.inv_mass[i] > 0.0 {
                    potential -= m * self.gravity.dot(state.x[i]);
                }
            }
        }
        potential += self.elastic_energy(&state.x);
        if let Some(ext) = &self.external {
            for (i, e) in ext.iter().enumerate() {
                if self.inv_mass[i] > 0.0 {
                    potential -= e.dot(state.x[i]);
                }
            }
        }
        Some(Energy { kinetic, potential })
    }

    fn kinetic_energy(&self, state: &ParticleState) -> Scalar {
        self.mass
            .iter()
            .zip(&state.v)
            .filter(|(m, _)| **m > 0.0)
            .map(|(m, v)| 0.5 * m * v.length_squared())
            .sum()
    }

    /// Internal energy: elastic energy plus kinetic energy relative to the centre of mass.
    /// A falling or thrown body keeps it constant (or loses it to damping); an integrator that
    /// diverges inflates it at once.
    fn guard_energy(&self, state: &ParticleState) -> Scalar {
        let mut m_tot = 0.0;
        let mut p = Vector::ZERO;
        let mut k = 0.0;
        for (m, v) in self.mass.iter().zip(&state.v) {
            if *m > 0.0 {
                m_tot += *m;
                p += *v * *m;
                k += 0.5 * *m * v.length_squared();
            }
        }
        let k_cm = if m_tot > 0.0 {
            0.5 * p.length_squared() / m_tot
        } else {
            0.0
        };
        // From the fast kernels, in their chunks on the team: the tets' reference f64 element
        // loop was 8 % of an explicit step on a 5000-tet box, at one check every 64 substeps,
        // and the springs' reference loop 1 % of the bench cloth's on the caller alone.
        let mut elastic = self.springs.energy_fast(&state.x) as Scalar;
        if !self.tets.is_empty() {
            elastic += self.tets.energy_fast(&state.x) as Scalar;
        }
        (k - k_cm).max(0.0) + elastic
    }

    /// Kinetic plus elastic energy now, plus the work gravity and external forces could do
    /// over the body's extent plus one metre: a body that stays physical never gets kinetic
    /// energy many times this.
    fn energy_scale(&self, state: &ParticleState) -> Option<Scalar> {
        if self.is_empty() {
            return None;
        }
        let (mut lo, mut hi) = (state.x[0], state.x[0]);
        for x in &state.x {
            lo = lo.min(*x);
            hi = hi.max(*x);
        }
        let reach = (hi - lo).length() + 1.0;
        let total_mass: Scalar = self.mass.iter().filter(|m| m.is_finite()).sum();
        let ext: Scalar = self
            .external
            .as_ref()
            .map_or(0.0, |e| e.iter().map(|f| f.length()).sum());
        let wind = self.wind.as_ref().map_or(0.0, |(w, _)| {
            let speed = w.velocity.to_scalar().length() + w.gust as Scalar * 3.0;
            0.5 * total_mass * speed * speed
        });
        let motion: Scalar = self
            .prescribed
            .iter()
            .map(|(p, m)| {
                let (_, v, a) = m.eval(0.0);
                let mi = self.mass[*p as usize].max(0.0);
                0.5 * total_mass.max(mi) * (v.length_squared() + a.length() * reach)
            })
            .sum();
        let e = self.kinetic_energy(state)
            + self.elastic_energy(&state.x)
            + (total_mass * self.gravity.length() + ext) * reach
            + wind
            + motion;
        Some(e.max(1e-6))
    }

    fn time_scale(&self) -> Option<Scalar> {
        self.cfl_time_scale(CflLimit::Oscillation)
    }

    fn cfl_time_scale(&self, limit: CflLimit) -> Option<Scalar> {
        let s = self.spring_bound(limit);
        match (s, self.tets.time_scale(&self.mass, &self.inv_mass)) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    fn prefers_direct_solver(&self) -> bool {
        !self.tets.is_empty()
    }

    fn linearization(&self) -> Option<&dyn crate::core::jacobian::Linearization> {
        Some(self)
    }

    /// The farthest a free particle went from `start` to `end`, over `dt`, when only steady
    /// forces act: no gusting wind, no particle on a moving path, no moving or turning
    /// collider, no force field that changes with time. Not the particles' velocities at the
    /// end: a particle can hold one a step's acceleration large while it stays where it is.
    /// A cloth held up by a collider at points inside its triangles is: each step's impulse
    /// stops the point, its corners share it by their weights, and those the tension pulls
    /// hardest end the step turning about the point, at 2–5 cm/s on a 12² cloth tented on a
    /// ball of 6–8 cm, while its particles move under a hundredth of a millimetre a frame
    /// (`tests/sleep.rs`).
    fn rest_speed(
        &self,
        t: Scalar,
        start: &ParticleState,
        end: &ParticleState,
        dt: Scalar,
    ) -> Option<Scalar> {
        let gusting = self
            .wind
            .as_ref()
            .is_some_and(|(w, _)| w.enabled && w.gust != 0.0);
        if gusting
            || !self.prescribed.iter().all(|(_, m)| m.is_still())
            || !self.colliders.iter().all(Collider::is_still)
            || !self.fields.iter().all(|f| f.steady_from(t))
        {
            return None;
        }
        if start.x.len() != end.x.len() || dt.is_nan() || dt <= 0.0 {
            return None;
        }
        let d2 = start
            .x
            .iter()
            .zip(&end.x)
            .zip(&self.inv_mass)
            .filter(|(_, w)| **w > 0.0)
            .map(|((a, b), _)| a.distance_squared(*b))
            .fold(0.0, Scalar::max);
        Some(d2.sqrt() / dt)
    }

    fn begin_frame(&mut self, state: &ParticleState) {
        // Between frames anyone may have moved the particles.
        self.pins_held.forget();
        if let Some(sc) = &mut self.self_contact {
            sc.begin_frame(&state.x);
        }
        if !self.contact_faces.is_empty() && !self.colliders.is_empty() {
            self.refresh_features();
            let x = &state.x;
            let longest = self
                .contact_faces
                .iter()
                .map(|f| {
                    let [a, b, c] = f.map(|i| x.get(i as usize).copied().unwrap_or_default());
                    a.distance_squared(b)
                        .max(b.distance_squared(c))
                        .max(c.distance_squared(a))
                })
                .fold(0.0, Scalar::max)
                .sqrt();
            // A triangle with a corner out of range or not finite: measured as unknown.
            self.face_edge = if longest.is_finite() {
                longest * FACE_EDGE_GROWTH
            } else {
                Scalar::INFINITY
            };
        }
    }

    /// Colliders (continuous against each), then the surface against itself when its parts
    /// may have come closer by half its thickness since the last pass.
    fn resolve_contacts(&mut self, t: Scalar, h: Scalar, state: &mut ParticleState) {
        // The step's start, for the features' swept test, before any contact moves them.
        let faces = !self.contact_faces.is_empty()
            && self.colliders.iter().any(|c| c.needs_faces(self.face_edge));
        if faces {
            // Made at each frame's start; here only for a model stepped without frames.
            if self.features.is_empty() {
                self.refresh_features();
            }
            self.face_start.clear();
            self.face_start
                .extend(state.x.iter().zip(&state.v).map(|(&x, &v)| x - v * h));
        }
        crate::core::collide::resolve_all(
            &self.colliders,
            t,
            h,
            &mut state.x,
            &mut state.v,
            &self.inv_mass,
        );
        if faces {
            for c in &self.colliders {
                c.resolve_faces(
                    t,
                    h,
                    &self.features,
                    self.face_edge,
                    &self.face_start,
                    &mut state.x,
                    &mut state.v,
                    &self.inv_mass,
                    &mut self.faces_near,
                );
            }
        }
        // Colliders move free particles only: pins written just before still hold.
        if self.self_contact.is_none() && self.pins_held.get(&state.x) == PinsHeld::APPLIED {
            self.pins_held.set(PinsHeld::KEPT, &state.x);
        }
        if self
            .self_contact
            .as_mut()
            .is_some_and(|sc| sc.advance(h, &state.x, &state.v))
        {
            self.self_contact_pass(t, state);
        }
    }

    /// The surface's last pass of the frame (Bridson, Fedkiw and Anderson 2002: the collision
    /// step spans internal-dynamics steps; here it spans as many steps as keep the motion
    /// within half the thickness, and ends with the frame), so every state a frame delivers
    /// is free of self-intersections.
    fn end_frame(&mut self, t: Scalar, state: &mut ParticleState) {
        // What the pins' record says holds within a frame only (see `begin_frame`).
        self.pins_held.forget();
        if self.self_contact.as_ref().is_some_and(|sc| sc.pending()) {
            self.self_contact_pass(t, state);
        }
    }
}
