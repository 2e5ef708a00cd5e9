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
use crate::core::ode::{Energy, OdeSystem, ParticleState};
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
    /// thickness plus half the surface's) marked as supported.
    fn self_contact_pass(
        sc: &mut crate::core::self_contact::SelfContact,
        colliders: &[Collider],
        inv_mass: &[Scalar],
        t: Scalar,
        state: &mut ParticleState,
    ) {
        let slack = 0.5 * sc.params.thickness as Scalar;
        let support = sc.support_mut(state.x.len());
        for c in colliders {
            c.touching(t, slack, &state.x, support);
        }
        sc.pass(&mut state.x, &mut state.v, inv_mass);
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
        self.pinned.push((i as u32, position));
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
        let wind_c = self.wind.as_ref().map_or(0.0, |(_, w)| w.coefficient());
        let c = self.drag + wind_c;
        if c != 0.0 {
            let push = match &self.wind {
                Some((_, w)) => w.velocity(t) * wind_c,
                None => Vector::ZERO,
            };
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
        self.springs.rows().chunks() > 1 || self.tets.len() > crate::core::kernels::tets::CHUNK_TETS
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
    fn symplectic_euler(
        &self,
        t: Scalar,
        h: Scalar,
        state: &mut ParticleState,
        scratch: &mut ParticleState,
    ) -> bool {
        let f = &mut scratch.v;
        crate::core::kernels::sweep::clear(f);
        self.accumulate_forces(t, state, f);
        for p in self
            .pinned
            .iter()
            .map(|p| p.0)
            .chain(self.prescribed.iter().map(|p| p.0))
        {
            scratch.x[p as usize] = state.x[p as usize];
        }
        // Pinned and prescribed particles have w = 0 and get no gravity.
        crate::core::kernels::sweep::sweep(
            &mut state.x,
            &mut state.v,
            &scratch.v,
            &self.inv_mass,
            self.gravity,
            h,
        );
        for &(p, _) in &self.pinned {
            // The derivative of a pin is zero: x and v stay (v got + 0 above).
            let p = p as usize;
            let dv = Vector::ZERO * h;
            state.x[p] = scratch.x[p] + (Vector::ZERO + dv) * h;
        }
        for (p, m) in &self.prescribed {
            let p = *p as usize;
            let (_, vp, ap) = m.eval(t);
            let dv = ap * h;
            state.v[p] += dv;
            state.x[p] = scratch.x[p] + (vp + dv) * h;
        }
        true
    }

    fn apply_constraints(&self, t: Scalar, state: &mut ParticleState) {
        for &(p, x) in &self.pinned {
            state.x[p as usize] = x;
            state.v[p as usize] = Vector::ZERO;
        }
        for (p, m) in &self.prescribed {
            let (x, v, _) = m.eval(t);
            state.x[*p as usize] = x;
            state.v[*p as usize] = v;
        }
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
        // The tets' energy from the fast kernel: the reference's f64 element loop was 8 % of an
        // explicit step on a 5000-tet box, at one check every 64 substeps.
        let mut elastic = self.springs.energy(&state.x);
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

    /// The fastest free particle's speed, when only steady forces act: no gusting wind, no
    /// particle on a moving path, no moving or turning collider, no force field that changes
    /// with time.
    fn rest_speed(&self, t: Scalar, state: &ParticleState) -> Option<Scalar> {
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
        let v2 = state
            .v
            .iter()
            .zip(&self.inv_mass)
            .filter(|(_, w)| **w > 0.0)
            .map(|(v, _)| v.length_squared())
            .fold(0.0, Scalar::max);
        Some(v2.sqrt())
    }

    fn begin_frame(&mut self, state: &ParticleState) {
        if let Some(sc) = &mut self.self_contact {
            sc.begin_frame(&state.x);
        }
    }

    /// Colliders (continuous against each), then the surface against itself when its parts
    /// may have come closer by half its thickness since the last pass.
    fn resolve_contacts(&mut self, t: Scalar, h: Scalar, state: &mut ParticleState) {
        for c in &self.colliders {
            c.resolve(t, h, &mut state.x, &mut state.v, &self.inv_mass);
        }
        if let Some(sc) = &mut self.self_contact
            && sc.advance(h, &state.x, &state.v)
        {
            Self::self_contact_pass(sc, &self.colliders, &self.inv_mass, t, state);
        }
    }

    /// The surface's last pass of the frame (Bridson, Fedkiw and Anderson 2002: the collision
    /// step spans internal-dynamics steps; here it spans as many steps as keep the motion
    /// within half the thickness, and ends with the frame), so every state a frame delivers
    /// is free of self-intersections.
    fn end_frame(&mut self, t: Scalar, state: &mut ParticleState) {
        if let Some(sc) = &mut self.self_contact
            && sc.pending()
        {
            Self::self_contact_pass(sc, &self.colliders, &self.inv_mass, t, state);
        }
    }
}
