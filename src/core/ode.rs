//! The ODE abstraction of the PhysBAM slides' driver–layout design: "a time integrator does not know anything about
//! the physics". An integrator advances any first-order system `dX/dt = f(X, t)` knowing only
//! that states form a vector space ([`OdeState`]) and that the system can evaluate its
//! derivative ([`OdeSystem`]).

use crate::math::{Scalar, Vector};

/// What an integrator needs of a state: vector-space operations that never allocate, a norm
/// for error control and a finiteness check for divergence detection.
///
/// All binary operations assume both operands have the same shape (same number of particles);
/// integrators create their scratch states by cloning the state they are given, so this holds.
pub trait OdeState: Clone + Send + Sync + 'static {
    /// `self ← other` (same shape, no allocation).
    fn copy_from(&mut self, other: &Self);
    /// `self ← self + a·x`.
    fn axpy(&mut self, a: Scalar, x: &Self);
    /// `self ← a·self`.
    fn scale(&mut self, a: Scalar);
    /// `self ← self + x`.
    fn add(&mut self, x: &Self) {
        self.axpy(1.0, x);
    }
    /// Number of scalar components.
    fn dim(&self) -> usize;
    /// True when every component is finite.
    fn is_finite(&self) -> bool;
    /// Euclidean norm over all components.
    fn norm(&self) -> Scalar;
    /// Hairer's scaled RMS error norm used by embedded Runge–Kutta pairs:
    /// `sqrt(mean_i (err_i / (atol + rtol·max(|a_i|, |b_i|)))²)`.
    fn error_norm(err: &Self, a: &Self, b: &Self, atol: Scalar, rtol: Scalar) -> Scalar;
    /// Bitwise-equal content (used to know whether a cached derivative is still valid).
    fn same_as(&self, other: &Self) -> bool;

    /// True for states of second-order systems `(x, v)` with `dx/dt = v`, which support the
    /// symplectic (semi-implicit) Euler update [`OdeState::kick_drift`].
    fn is_second_order(&self) -> bool {
        false
    }
    /// Symplectic Euler given the derivative `d = f(X, t)`: velocities first,
    /// `v ← v + h·dv`, then positions with the new velocity, `x ← x + h·(dx + h·dv)` (which is
    /// `x + h·v_new` for a free particle and leaves a particle whose position derivative the
    /// system zeroed — a pin — in place). Only called when [`OdeState::is_second_order`].
    fn kick_drift(&mut self, d: &Self, h: Scalar) {
        self.axpy(h, d);
    }

    /// The state as particle positions and velocities, for methods that need that structure
    /// (implicit ones); `None` for other states.
    fn as_particles_mut(&mut self) -> Option<&mut ParticleState> {
        None
    }
}

/// A first-order system `dX/dt = f(X, t)`.
pub trait OdeSystem<S: OdeState>: Sync {
    /// Writes `f(state, t)` into `out`, which has the shape of `state` (the caller owns it, so
    /// evaluating allocates nothing).
    fn derivative(&self, t: Scalar, state: &S, out: &mut S);

    /// Writes prescribed values into `state` at time `t` (kinematic particles, pins). The
    /// driver calls it before and after every step; the default does nothing.
    fn apply_constraints(&self, _t: Scalar, _state: &mut S) {}

    /// Total mechanical energy, when the system defines one (for diagnostics and the
    /// divergence guard).
    fn energy(&self, _t: Scalar, _state: &S) -> Option<Energy> {
        None
    }

    /// Kinetic energy (for the divergence guard; defaults to [`OdeSystem::energy`]'s).
    fn kinetic_energy(&self, state: &S) -> Scalar {
        self.energy(0.0, state).map_or(0.0, |e| e.kinetic)
    }

    /// The energy the divergence guard watches (default: kinetic energy). It should stay
    /// bounded for any physical motion, free fall included.
    fn guard_energy(&self, state: &S) -> Scalar {
        self.kinetic_energy(state)
    }

    /// A characteristic energy of the system in this state: the driver's divergence guard
    /// trips when [`OdeSystem::guard_energy`] exceeds a multiple of it. `None` turns the guard
    /// off.
    fn energy_scale(&self, _state: &S) -> Option<Scalar> {
        None
    }

    /// The characteristic explicit time step (for CFL step policies), if the system has one.
    fn time_scale(&self) -> Option<Scalar> {
        None
    }

    /// The time scale a CFL step policy with the given per-spring bounds multiplies
    /// (default: [`OdeSystem::time_scale`]).
    fn cfl_time_scale(&self, limit: crate::core::driver::CflLimit) -> Option<Scalar> {
        let _ = limit;
        self.time_scale()
    }

    /// Symplectic Euler in one pass over the particles, when the system can do better than
    /// [`OdeSystem::derivative`] followed by [`OdeState::kick_drift`] (which evaluates the
    /// derivative into `scratch`, then reads it back): the same arithmetic, so the same bits,
    /// with fewer sweeps over memory. `scratch` has the state's shape. Returns `false` (the
    /// default) when the system has no such path.
    fn symplectic_euler(&self, _t: Scalar, _h: Scalar, _state: &mut S, _scratch: &mut S) -> bool {
        false
    }

    /// Whether `state` — just advanced by one integrator step of this system, then
    /// constrained ([`OdeSystem::apply_constraints`]) and its contacts resolved
    /// ([`OdeSystem::resolve_contacts`]) — is finite everywhere. The default checks every
    /// component; a system whose step checked what it wrote as it wrote it may answer from
    /// that, sparing a pass over the state.
    fn stepped_state_is_finite(&self, state: &S) -> bool {
        state.is_finite()
    }

    /// How fast the system moved over a frame `dt` long from `start` to `end` (at `t`), for
    /// sleeping: the largest distance a free part went, over `dt` — the speed the frames show
    /// — when nothing drives it but steady forces (no moving pins or colliders, no gusts, no
    /// field that changes with time); `None` (the default) when something does, or the
    /// system does not say. A body whose rest speed stays below a threshold for a while
    /// sleeps ([`crate::core::driver::Simulation::set_sleep`]).
    fn rest_speed(&self, _t: Scalar, _start: &S, _end: &S, _dt: Scalar) -> Option<Scalar> {
        None
    }

    /// Called at the start of each frame with the state it starts from (default: nothing).
    fn begin_frame(&mut self, _state: &S) {}

    /// Collision response after a step ending at `t` of size `h` (default: none).
    fn resolve_contacts(&mut self, _t: Scalar, _h: Scalar, _state: &mut S) {}

    /// Collision response at the end `t` of a frame, after its last step (default: none): what
    /// must hold in every state a frame delivers (a surface free of self-intersections).
    fn end_frame(&mut self, _t: Scalar, _state: &mut S) {}

    /// True when implicit methods should solve with a direct factorization by default
    /// (finite-element bodies).
    fn prefers_direct_solver(&self) -> bool {
        false
    }

    /// Force Jacobians for implicit methods, when the system has them.
    fn linearization(&self) -> Option<&dyn crate::core::jacobian::Linearization> {
        None
    }
}

/// Kinetic and potential energy of a state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Energy {
    /// `½ Σ m v²`.
    pub kinetic: Scalar,
    /// Gravity, springs and constant external forces.
    pub potential: Scalar,
}

impl Energy {
    /// Kinetic plus potential.
    pub fn total(&self) -> Scalar {
        self.kinetic + self.potential
    }
}

// ---------------------------------------------------------------------------------------
// Slice helpers shared by every state made of vectors.

#[inline]
fn comps(v: Vector) -> [Scalar; 3] {
    [v.x, v.y, v.z]
}

pub(crate) fn slice_axpy(y: &mut [Vector], a: Scalar, x: &[Vector]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += *xi * a;
    }
}

pub(crate) fn slice_scale(y: &mut [Vector], a: Scalar) {
    for yi in y {
        *yi *= a;
    }
}

#[allow(clippy::eq_op)] // `v − v` on purpose: zero exactly when finite
#[cfg(not(feature = "f64"))]
pub(crate) fn slice_finite(y: &[Vector]) -> bool {
    // `v − v` is zero for a finite component and NaN for an infinite or NaN one, and a NaN
    // survives the sum: one branch-free pass (the short-circuiting `all` does not vectorize).
    // Four sums, so the additions do not wait on each other.
    let mut acc = [Vector::ZERO; 4];
    let mut quads = y.chunks_exact(4);
    for q in &mut quads {
        for (a, v) in acc.iter_mut().zip(q) {
            *a += *v - *v;
        }
    }
    for v in quads.remainder() {
        acc[0] += *v - *v;
    }
    (acc[0] + acc[1] + acc[2] + acc[3]).is_finite()
}

/// [`slice_finite`] of the f64 build: the same test over the components as one flat slice
/// (a `DVec3` is three `f64`s, `#[repr(C)]`), eight sums, so it vectorizes in whole
/// registers; a `DVec3` at a time it took twice as long (6 % of the bench cloth's explicit
/// step).
#[cfg(feature = "f64")]
#[allow(clippy::eq_op)] // `c − c`: zero for a finite `c`, NaN otherwise
pub(crate) fn slice_finite(y: &[Vector]) -> bool {
    // SAFETY: `DVec3` is `#[repr(C)]` with three `f64` fields and no padding.
    let flat: &[f64] = unsafe { std::slice::from_raw_parts(y.as_ptr().cast(), y.len() * 3) };
    let mut acc = [0.0f64; 8];
    let mut octs = flat.chunks_exact(8);
    for o in &mut octs {
        for (a, c) in acc.iter_mut().zip(o) {
            *a += *c - *c;
        }
    }
    for c in octs.remainder() {
        acc[0] += *c - *c;
    }
    acc.iter().sum::<f64>().is_finite()
}

pub(crate) fn slice_norm2(y: &[Vector]) -> Scalar {
    y.iter().map(|v| v.length_squared()).sum()
}

/// Sum of squared scaled errors over a slice (see [`OdeState::error_norm`]).
pub(crate) fn slice_err2(
    e: &[Vector],
    a: &[Vector],
    b: &[Vector],
    atol: Scalar,
    rtol: Scalar,
) -> Scalar {
    let mut s = 0.0;
    for ((ei, ai), bi) in e.iter().zip(a).zip(b) {
        let (ei, ai, bi) = (comps(*ei), comps(*ai), comps(*bi));
        for k in 0..3 {
            let sk = atol + rtol * ai[k].abs().max(bi[k].abs());
            let r = ei[k] / sk;
            s += r * r;
        }
    }
    s
}

pub(crate) fn slice_same(a: &[Vector], b: &[Vector]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_array() == y.to_array())
}

// ---------------------------------------------------------------------------------------
// Implementations.

/// A single 3-vector: the state of the circle system (first order, no velocity carried).
impl OdeState for Vector {
    fn copy_from(&mut self, other: &Self) {
        *self = *other;
    }
    fn axpy(&mut self, a: Scalar, x: &Self) {
        *self += *x * a;
    }
    fn scale(&mut self, a: Scalar) {
        *self *= a;
    }
    fn dim(&self) -> usize {
        3
    }
    fn is_finite(&self) -> bool {
        Vector::is_finite(*self)
    }
    fn norm(&self) -> Scalar {
        self.length()
    }
    fn error_norm(err: &Self, a: &Self, b: &Self, atol: Scalar, rtol: Scalar) -> Scalar {
        (slice_err2(&[*err], &[*a], &[*b], atol, rtol) / 3.0).sqrt()
    }
    fn same_as(&self, other: &Self) -> bool {
        self.to_array() == other.to_array()
    }
}

/// A plain vector of scalars: any finite-dimensional first-order system.
impl OdeState for Vec<Scalar> {
    fn copy_from(&mut self, other: &Self) {
        self.copy_from_slice(other);
    }
    fn axpy(&mut self, a: Scalar, x: &Self) {
        for (yi, xi) in self.iter_mut().zip(x) {
            *yi += a * xi;
        }
    }
    fn scale(&mut self, a: Scalar) {
        for yi in self.iter_mut() {
            *yi *= a;
        }
    }
    fn dim(&self) -> usize {
        self.len()
    }
    fn is_finite(&self) -> bool {
        self.iter().all(|x| x.is_finite())
    }
    fn norm(&self) -> Scalar {
        self.iter().map(|x| x * x).sum::<Scalar>().sqrt()
    }
    fn error_norm(err: &Self, a: &Self, b: &Self, atol: Scalar, rtol: Scalar) -> Scalar {
        if err.is_empty() {
            return 0.0;
        }
        let mut s = 0.0;
        for ((e, x), y) in err.iter().zip(a).zip(b) {
            let r = e / (atol + rtol * x.abs().max(y.abs()));
            s += r * r;
        }
        (s / err.len() as Scalar).sqrt()
    }
    fn same_as(&self, other: &Self) -> bool {
        self.len() == other.len()
            && self
                .iter()
                .zip(other)
                .all(|(a, b)| a.to_bits() == b.to_bits())
    }
}

/// Positions and velocities of a particle system, as two packed arrays. The derivative of a
/// `ParticleState` is again a `ParticleState`: `(dx/dt, dv/dt) = (v, a)`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParticleState {
    /// Positions.
    pub x: Vec<Vector>,
    /// Velocities.
    pub v: Vec<Vector>,
}

impl ParticleState {
    /// A state of `n` particles at the origin, at rest.
    pub fn zeros(n: usize) -> Self {
        Self {
            x: vec![Vector::ZERO; n],
            v: vec![Vector::ZERO; n],
        }
    }
    /// Number of particles.
    pub fn len(&self) -> usize {
        self.x.len()
    }
    /// True when there are no particles.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
}

impl OdeState for ParticleState {
    fn copy_from(&mut self, other: &Self) {
        self.x.copy_from_slice(&other.x);
        self.v.copy_from_slice(&other.v);
    }
    fn axpy(&mut self, a: Scalar, x: &Self) {
        slice_axpy(&mut self.x, a, &x.x);
        slice_axpy(&mut self.v, a, &x.v);
    }
    fn scale(&mut self, a: Scalar) {
        slice_scale(&mut self.x, a);
        slice_scale(&mut self.v, a);
    }
    fn dim(&self) -> usize {
        6 * self.x.len()
    }
    fn is_finite(&self) -> bool {
        // In chunks of the spring kernel's largest size, on the team this runs in (if any):
        // each thread reads mostly the particles it swept, where one thread reading them all
        // would pull every other thread's lines across.
        use crate::core::kernels::{for_each_range, springs::CHUNK_PARTICLES};
        use std::sync::atomic::{AtomicBool, Ordering};
        let n = self.x.len();
        if self.v.len() != n {
            return slice_finite(&self.x) && slice_finite(&self.v);
        }
        let finite = AtomicBool::new(true);
        for_each_range(n, CHUNK_PARTICLES, |r| {
            if !(slice_finite(&self.x[r.clone()]) && slice_finite(&self.v[r])) {
                finite.store(false, Ordering::Relaxed);
            }
        });
        finite.into_inner()
    }
    fn norm(&self) -> Scalar {
        (slice_norm2(&self.x) + slice_norm2(&self.v)).sqrt()
    }
    fn error_norm(err: &Self, a: &Self, b: &Self, atol: Scalar, rtol: Scalar) -> Scalar {
        let n = err.dim();
        if n == 0 {
            return 0.0;
        }
        let s =
            slice_err2(&err.x, &a.x, &b.x, atol, rtol) + slice_err2(&err.v, &a.v, &b.v, atol, rtol);
        (s / n as Scalar).sqrt()
    }
    fn same_as(&self, other: &Self) -> bool {
        slice_same(&self.x, &other.x) && slice_same(&self.v, &other.v)
    }
    fn is_second_order(&self) -> bool {
        true
    }
    fn as_particles_mut(&mut self) -> Option<&mut ParticleState> {
        Some(self)
    }
    fn kick_drift(&mut self, d: &Self, h: Scalar) {
        for i in 0..self.x.len() {
            let dv = d.v[i] * h;
            self.v[i] += dv;
            self.x[i] += (d.x[i] + dv) * h;
        }
    }
}

/// A system given by a closure, handy for tests and one-off studies.
pub struct FnSystem<F>(pub F);

impl<S: OdeState, F: Fn(Scalar, &S, &mut S) + Sync> OdeSystem<S> for FnSystem<F> {
    fn derivative(&self, t: Scalar, state: &S, out: &mut S) {
        (self.0)(t, state, out)
    }
}

/// The circle system of the cloth assignment: one particle, first order,
/// `f((x, y, z), t) = (-y, x, 0)`. Its exact solution rotates the initial point about the z
/// axis with unit angular velocity, so the radius is conserved.
#[derive(Clone, Copy, Debug, Default)]
pub struct CircleSystem;

impl CircleSystem {
    /// The exact solution at time `t` from `x0` at time 0.
    pub fn exact(x0: Vector, t: Scalar) -> Vector {
        let (s, c) = t.sin_cos();
        Vector::new(c * x0.x - s * x0.y, s * x0.x + c * x0.y, x0.z)
    }
}

impl OdeSystem<Vector> for CircleSystem {
    fn derivative(&self, _t: Scalar, x: &Vector, out: &mut Vector) {
        *out = Vector::new(-x.y, x.x, 0.0);
    }
    fn energy(&self, _t: Scalar, x: &Vector) -> Option<Energy> {
        // The conserved quantity r²/2 plays the role of energy for diagnostics.
        Some(Energy {
            kinetic: 0.0,
            potential: 0.5 * (x.x * x.x + x.y * x.y),
        })
    }
}
