//! Particles against collider shapes: project a particle that is inside (closer than the
//! collider's thickness) back to the surface, reflect its normal velocity relative to the
//! collider with restitution, and reduce its tangential velocity by Coulomb friction.
//!
//! Spheres and planes are handled analytically (in the crate's precision); every other
//! shape goes through parry3d's point projection (in `f32`, parry's precision).
//!
//! A collider moves over the frame as a rigid body: its centre follows a [`Motion`] and it
//! turns about that centre at a constant angular velocity ([`Spin`]), so a contact sees the
//! surface velocity `v + ω × r`. A collider with a [`Response`] is a dynamic rigid body of
//! finite mass: each contact impulse is computed with the pair's effective mass (the
//! particle's inverse mass plus the body's `1/M + (r × n)·I⁻¹(r × n)`, as in a rigid-body
//! sequential-impulse solver), the body's velocity changes at once for the particles after it,
//! and the impulses it received are summed for the rigid-body engine to apply (momentum is
//! exchanged exactly: what the particles gain, the body loses).

use crate::core::kernels::{SharedMut, for_each_range};
use crate::core::motion::Motion;
use crate::math::{Scalar, ToScalar, Vector, VectorExt};
use parry3d::math::{Pose3, Rot3};
pub use parry3d::shape::SharedShape;
use serde::{Deserialize, Serialize};

/// A collider's shape, as layouts describe it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ShapeDesc {
    /// A ball of this radius centred on the collider's position.
    Sphere {
        /// Radius.
        radius: f64,
    },
    /// The half-space below the plane through the collider's position with this outward normal.
    Plane {
        /// Outward unit normal.
        normal: [f64; 3],
    },
    /// A box with these half extents.
    Cuboid {
        /// Half extents.
        half_extents: [f64; 3],
    },
    /// A capsule along y.
    Capsule {
        /// Half the length of the segment.
        half_height: f64,
        /// Radius.
        radius: f64,
    },
}

impl ShapeDesc {
    /// The parry3d shape.
    pub fn to_shared(&self) -> SharedShape {
        match *self {
            ShapeDesc::Sphere { radius } => SharedShape::ball(radius as f32),
            ShapeDesc::Plane { normal } => {
                SharedShape::halfspace(normal.to_scalar().to_f32().normalize())
            }
            ShapeDesc::Cuboid { half_extents: h } => {
                SharedShape::cuboid(h[0] as f32, h[1] as f32, h[2] as f32)
            }
            ShapeDesc::Capsule {
                half_height,
                radius,
            } => SharedShape::capsule_y(half_height as f32, radius as f32),
        }
    }

    /// True when the numbers make a valid shape.
    pub fn is_valid(&self) -> bool {
        match *self {
            ShapeDesc::Sphere { radius } => radius.is_finite() && radius > 0.0,
            ShapeDesc::Plane { normal } => {
                normal.iter().all(|x| x.is_finite())
                    && normal.iter().map(|x| x * x).sum::<f64>() > 1e-12
            }
            ShapeDesc::Cuboid { half_extents } => {
                half_extents.iter().all(|x| x.is_finite() && *x > 0.0)
            }
            ShapeDesc::Capsule {
                half_height,
                radius,
            } => {
                half_height.is_finite() && half_height >= 0.0 && radius.is_finite() && radius > 0.0
            }
        }
    }
}

/// Contact material of a collider.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ContactMaterial {
    /// Coulomb friction coefficient μ.
    pub friction: f64,
    /// Restitution e (0: no bounce, 1: elastic).
    pub restitution: f64,
    /// Particles closer than this to the surface are pushed out to it (m).
    pub thickness: f64,
    /// Normal approach speeds below this bounce with e = 0 (resting contact stays at rest).
    pub bounce_threshold: f64,
}

impl Default for ContactMaterial {
    fn default() -> Self {
        Self {
            friction: 0.3,
            restitution: 0.0,
            thickness: 0.01,
            bounce_threshold: 0.05,
        }
    }
}

/// A collider as a layout describes it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColliderDesc {
    /// Shape.
    pub shape: ShapeDesc,
    /// Where the shape's origin is over time.
    pub motion: Motion,
    /// Orientation quaternion `[x, y, z, w]` (fixed).
    #[serde(default = "identity_quat")]
    pub rotation: [f64; 4],
    /// Contact material.
    #[serde(default)]
    pub material: ContactMaterial,
}

fn identity_quat() -> [f64; 4] {
    [0.0, 0.0, 0.0, 1.0]
}

enum Fast {
    Sphere(Scalar),
    /// The half-space's normal in the collider's frame.
    Plane(Vector),
    General,
}

/// How a collider turns over the frame: at `angular_velocity` (rad/s, world frame, constant)
/// about `center` (a point given in the collider's own frame, the origin by default), starting
/// from its `rotation` at time `t0`. The collider's `motion` is the path of that centre.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Spin {
    /// Angular velocity (rad/s, world frame).
    pub angular_velocity: Vector,
    /// The time at which the orientation is the collider's `rotation`.
    pub t0: Scalar,
    /// Centre of rotation in the collider's frame (a rigid body's centre of mass).
    pub center: Vector,
}

/// A dynamic rigid body behind a collider, for the duration of one frame starting at `t0`:
/// its inverse mass and world inverse inertia tensor (about its centre, the [`Spin::center`]),
/// the acceleration it has without contacts (gravity), and what the particles gave it so far.
///
/// Within the frame the body moves as the particles push it: its centre's velocity is the
/// collider's path velocity plus `gravity·τ` plus the impulses received so far over `M`, and
/// its position follows that velocity (each impulse `J` received at `τ_k` moves it by
/// `J (τ − τ_k)/M`); its angular velocity and orientation likewise, to first order in the
/// frame's rotation. The rigid-body engine reproduces the same end state from the
/// [`Exchange`] (see [`Exchange::split`]).
#[derive(Debug, Default)]
pub struct Response {
    /// `1/M` (1/kg); zero: infinitely heavy.
    pub inv_mass: Scalar,
    /// World-frame `I⁻¹` as three rows (1/(kg·m²)).
    pub inv_inertia: [Vector; 3],
    /// Acceleration of the free body (m/s²): the rigid-body engine's gravity on it.
    pub gravity: Vector,
    /// Start of the frame.
    pub t0: Scalar,
    exchange: std::sync::Mutex<Exchange>,
}

impl Clone for Response {
    fn clone(&self) -> Self {
        Self {
            inv_mass: self.inv_mass,
            inv_inertia: self.inv_inertia,
            gravity: self.gravity,
            t0: self.t0,
            exchange: std::sync::Mutex::new(self.exchange()),
        }
    }
}

impl Response {
    /// A body of inverse mass `inv_mass` and world inverse inertia rows `inv_inertia`, free of
    /// gravity, for a frame starting at `t0`.
    pub fn new(inv_mass: Scalar, inv_inertia: [Vector; 3], t0: Scalar) -> Self {
        Self {
            inv_mass,
            inv_inertia,
            gravity: Vector::ZERO,
            t0,
            exchange: Default::default(),
        }
    }

    /// The same body falling at `gravity` when free.
    pub fn with_gravity(mut self, gravity: Vector) -> Self {
        self.gravity = gravity;
        self
    }

    /// What the particles gave the body since it was made or last [taken](Response::take).
    pub fn exchange(&self) -> Exchange {
        *self.exchange.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Returns the exchange and starts a new one.
    pub fn take(&self) -> Exchange {
        std::mem::take(&mut *self.exchange.lock().unwrap_or_else(|e| e.into_inner()))
    }

    fn inv_inertia_mul(&self, v: Vector) -> Vector {
        let r = &self.inv_inertia;
        Vector::new(r[0].dot(v), r[1].dot(v), r[2].dot(v))
    }

    /// `1/M + (r × d)·I⁻¹(r × d)`: the body's inverse mass seen along `d` at arm `r`.
    fn inverse_mass_along(&self, r: Vector, d: Vector) -> Scalar {
        let rd = r.cross(d);
        self.inv_mass + rd.dot(self.inv_inertia_mul(rd))
    }
}

/// Impulses the particles gave a dynamic collider's body in a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Exchange {
    /// Linear impulse on the body, `ΣJ_k` (N·s).
    pub linear: Vector,
    /// Angular impulse on the body about its centre, `ΣL_k` (N·m·s).
    pub angular: Vector,
    /// `ΣJ_k τ_k`, each impulse times when in the frame it came (N·s²).
    pub linear_moment: Vector,
    /// `ΣL_k τ_k` (N·m·s²).
    pub angular_moment: Vector,
    /// Particle contacts that exchanged an impulse.
    pub contacts: u32,
}

impl Exchange {
    /// How a rigid-body engine stepping the body over the frame `Δ` reproduces both the end
    /// velocity and the end position the body had in the soft step: an impulse at the start
    /// of its step and a constant force over it, linear and angular:
    /// `(J_a, F, A_a, T)` with `J_a = ΣJ − 2ΣJτ/Δ`, `F = 2ΣJτ/Δ²` (then `J_a + FΔ = ΣJ` and
    /// `J_a Δ + FΔ²/2 = Σ J (Δ − τ)`). Impulses spread evenly over the frame (resting
    /// contact) give `J_a = 0`: a steady force, felt in every substep as gravity is.
    pub fn split(&self, frame: Scalar) -> (Vector, Vector, Vector, Vector) {
        let d = frame;
        (
            self.linear - self.linear_moment * (2.0 / d),
            self.linear_moment * (2.0 / (d * d)),
            self.angular - self.angular_moment * (2.0 / d),
            self.angular_moment * (2.0 / (d * d)),
        )
    }
}

/// The collider's pose at one instant.
struct Pose {
    /// Its centre (the [`Spin::center`]) and that point's velocity.
    center: Vector,
    velocity: Vector,
    /// Its angular velocity.
    omega: Vector,
    /// The shape's origin and orientation.
    origin: Vector,
    rotation: Rot3,
    /// A half-space's outward normal at this orientation.
    normal: Vector,
}

/// A collider ready for queries.
pub struct Collider {
    /// The parry3d shape.
    pub shape: SharedShape,
    /// Where its centre (the origin unless [`Spin::center`] says otherwise) is over time.
    pub motion: Motion,
    /// Orientation (at [`Spin::t0`] when it turns).
    pub rotation: Rot3,
    /// Contact material.
    pub material: ContactMaterial,
    /// How it turns (not at all by default).
    pub spin: Spin,
    /// The dynamic rigid body behind it, if the particles' impulses act back on one.
    pub response: Option<Response>,
    fast: Fast,
}

impl Clone for Collider {
    fn clone(&self) -> Self {
        let mut c = Self::new(
            self.shape.clone(),
            self.motion,
            self.rotation,
            self.material,
        );
        c.spin = self.spin;
        c.response = self.response.clone();
        c
    }
}

impl std::fmt::Debug for Collider {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Collider")
            .field("shape", &self.shape.shape_type())
            .field("motion", &self.motion)
            .field("material", &self.material)
            .field("spin", &self.spin)
            .field("response", &self.response)
            .finish()
    }
}

impl Collider {
    /// True when it neither moves nor turns.
    pub fn is_still(&self) -> bool {
        self.motion.is_still() && self.spin.angular_velocity == Vector::ZERO
    }

    /// A collider from any parry3d shape, moving without turning.
    pub fn new(
        shape: SharedShape,
        motion: Motion,
        rotation: Rot3,
        material: ContactMaterial,
    ) -> Self {
        let fast = if let Some(b) = shape.as_ball() {
            Fast::Sphere(b.radius as Scalar)
        } else if let Some(h) = shape.as_halfspace() {
            Fast::Plane(h.normal.to_scalar())
        } else {
            Fast::General
        };
        Self {
            shape,
            motion,
            rotation,
            material,
            spin: Spin::default(),
            response: None,
            fast,
        }
    }

    /// The same collider turning as `spin` says.
    pub fn with_spin(mut self, spin: Spin) -> Self {
        self.spin = spin;
        self
    }

    /// The same collider as a dynamic body that the particles push back.
    pub fn with_response(mut self, response: Response) -> Self {
        self.response = Some(response);
        self
    }

    /// From a layout description.
    pub fn from_desc(d: &ColliderDesc) -> Self {
        let q = d.rotation;
        let rot = Rot3::from_xyzw(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32).normalize();
        Self::new(d.shape.to_shared(), d.motion, rot, d.material)
    }

    fn turns(&self) -> bool {
        self.spin.angular_velocity != Vector::ZERO || self.spin.center != Vector::ZERO
    }

    /// The pose at time `t` (for a dynamic body, as the impulses received so far moved it).
    fn pose(&self, t: Scalar) -> Pose {
        let (mut center, mut velocity, _) = self.motion.eval(t);
        let normal = |rotation: Rot3| match self.fast {
            Fast::Plane(local) => (rotation * local.to_f32()).to_scalar(),
            _ => Vector::ZERO,
        };
        let mut omega = self.spin.angular_velocity;
        let mut turn = omega * (t - self.spin.t0);
        if let Some(r) = &self.response {
            let ex = r.exchange();
            let tau = t - r.t0;
            center +=
                r.gravity * (0.5 * tau * tau) + (ex.linear * tau - ex.linear_moment) * r.inv_mass;
            velocity += r.gravity * tau + ex.linear * r.inv_mass;
            omega += r.inv_inertia_mul(ex.angular);
            turn += r.inv_inertia_mul(ex.angular * tau - ex.angular_moment);
        } else if !self.turns() {
            return Pose {
                center,
                velocity,
                omega: Vector::ZERO,
                origin: center,
                rotation: self.rotation,
                normal: normal(self.rotation),
            };
        }
        let rotation = (Rot3::from_scaled_axis(turn.to_f32()) * self.rotation).normalize();
        let origin = center - (rotation * self.spin.center.to_f32()).to_scalar();
        Pose {
            center,
            velocity,
            omega,
            origin,
            rotation,
            normal: normal(rotation),
        }
    }

    /// Where particle position `p` should be and the contact normal, when it is inside the
    /// collider (at `pose`) or closer to its surface than `thick`.
    fn contact(&self, pose: &Pose, thick: Scalar, p: Vector) -> Option<(Vector, Vector)> {
        let c = pose.origin;
        match self.fast {
            Fast::Sphere(r) => {
                let d = p - c;
                let dist = d.length();
                if dist < r + thick {
                    let n = if dist > 0.0 { d / dist } else { Vector::Y };
                    Some((c + n * (r + thick), n))
                } else {
                    None
                }
            }
            Fast::Plane(_) => {
                let n = pose.normal;
                let s = (p - c).dot(n);
                if s < thick {
                    Some((p + n * (thick - s), n))
                } else {
                    None
                }
            }
            Fast::General => {
                let pose = Pose3::from_parts(c.to_f32(), pose.rotation);
                let pf = p.to_f32();
                let proj = self.shape.project_point(&pose, pf, true);
                let d = pf - proj.point;
                let dist = d.length();
                if proj.is_inside {
                    // Inside: the way out is towards the projection.
                    let (n, _) = if dist > 1e-9 {
                        (-d / dist, dist)
                    } else {
                        (glam::Vec3::Y, 0.0)
                    };
                    let n = n.to_scalar();
                    Some((proj.point.to_scalar() + n * thick, n))
                } else if (dist as Scalar) < thick && dist > 1e-9 {
                    let n = (d / dist).to_scalar();
                    Some((proj.point.to_scalar() + n * thick, n))
                } else {
                    None
                }
            }
        }
    }

    /// [`Collider::contact`] for a particle that ended a step of length `h` at `p` with
    /// velocity `v`: when it moved relative to the surface by more than the thickness, the
    /// segment it swept (back from `p` by `h` times its relative velocity — its exact start
    /// under symplectic Euler) is cast against the shape, and a hit from outside is the
    /// contact, on the side it came from. Without this a particle crossing a shape thinner
    /// than its travel in one step would pass through (or be pushed out the far side).
    fn swept_contact(
        &self,
        pose: &Pose,
        thick: Scalar,
        h: Scalar,
        p: Vector,
        v: Vector,
    ) -> Option<(Vector, Vector)> {
        let travel = (v - Self::surface_velocity(pose, p)) * h;
        if matches!(self.fast, Fast::Plane(_)) || travel.length_squared() <= thick * thick {
            return self.contact(pose, thick, p);
        }
        let start = p - travel;
        let shape_pose = Pose3::from_parts(pose.origin.to_f32(), pose.rotation);
        let ray = parry3d::query::Ray::new(start.to_f32(), travel.to_f32());
        match self
            .shape
            .cast_ray_and_get_normal(&shape_pose, &ray, 1.0, true)
        {
            Some(hit) if hit.time_of_impact > 0.0 => {
                let n = hit.normal.to_scalar();
                let at = start + travel * hit.time_of_impact as Scalar;
                Some((at + n * thick, n))
            }
            _ => self.contact(pose, thick, p),
        }
    }

    /// Whether a particle at `p` moving at `v` is certainly clear of a half-space or a
    /// sphere not turning: what [`Collider::swept_contact`] would find nothing for, told
    /// without it (most particles of a body are clear of each collider, and the response
    /// loops are then a few operations a particle). A half-space's test is its own; a
    /// sphere's, that the particle is farther from the centre than the sphere and the
    /// thickness by more than its path over the step (so is every point of the path), with a
    /// margin over the round-off. Anything else is never called clear.
    #[inline(always)]
    fn clear(&self, pose: &Pose, thick: Scalar, h: Scalar, p: Vector, v: Vector) -> bool {
        match self.fast {
            Fast::Plane(_) => (p - pose.origin).dot(pose.normal) >= thick,
            Fast::Sphere(r) if pose.omega == Vector::ZERO => {
                let reach = r + thick + (v - pose.velocity).length() * h;
                (p - pose.origin).length_squared() > reach * reach * 1.0001
            }
            _ => false,
        }
    }

    /// Velocity of the collider's surface at `p` (at `pose`).
    fn surface_velocity(pose: &Pose, p: Vector) -> Vector {
        if pose.omega == Vector::ZERO {
            pose.velocity
        } else {
            pose.velocity + pose.omega.cross(p - pose.center)
        }
    }

    /// Particles resting on or pressed into this collider at time `t`: touching (within the
    /// thickness plus `slack`), not moving away, and pushed into it by `f` (their total force).
    /// Implicit steps hold them still (Baraff & Witkin's constraint filter: sticking contact)
    /// instead of letting the step drive them in and projecting them out afterwards, which
    /// pumps energy into stiff elements. Marks them in `held` and sets their velocity to the
    /// collider's surface velocity. A collider with a [`Response`] holds nothing: the
    /// constraint force of a held particle would never reach its body, so its contacts are
    /// resolved after the step like an explicit method's, where the impulse is exchanged.
    #[allow(clippy::too_many_arguments)]
    pub fn hold(
        &self,
        t: Scalar,
        slack: Scalar,
        x: &[Vector],
        v: &mut [Vector],
        f: &[Vector],
        inv_mass: &[Scalar],
        held: &mut [bool],
    ) {
        if self.response.is_some() {
            return;
        }
        let pose = self.pose(t);
        let thick = self.material.thickness as Scalar + slack;
        for i in 0..x.len() {
            if inv_mass[i] == 0.0 || held[i] {
                continue;
            }
            if let Some((_, n)) = self.contact(&pose, thick, x[i]) {
                let vc = Self::surface_velocity(&pose, x[i]);
                if (v[i] - vc).dot(n) <= 0.0 && f[i].dot(n) <= 0.0 {
                    held[i] = true;
                    v[i] = vc;
                }
            }
        }
    }

    /// Marks in `out` the particles within the collider's thickness plus `slack` of it at
    /// time `t` (resting on it or pressed into it).
    pub fn touching(&self, t: Scalar, slack: Scalar, x: &[Vector], out: &mut [bool]) {
        let pose = self.pose(t);
        let thick = self.material.thickness as Scalar + slack;
        for (i, p) in x.iter().enumerate() {
            if !out[i]
                && !self.clear(&pose, thick, 0.0, *p, pose.velocity)
                && self.contact(&pose, thick, *p).is_some()
            {
                out[i] = true;
            }
        }
    }

    /// Pushes particles out of the collider at the end `t` of a step of length `h` and applies
    /// restitution and friction; particles that moved more than the thickness in the step are
    /// tested along the path they swept (continuous detection). `inv_mass` selects the
    /// particles that respond (zero: pinned or prescribed). Returns the number of particles in
    /// contact.
    pub fn resolve(
        &self,
        t: Scalar,
        h: Scalar,
        x: &mut [Vector],
        v: &mut [Vector],
        inv_mass: &[Scalar],
    ) -> usize {
        if let Some(r) = &self.response {
            return self.resolve_exchanging(r, t, h, x, v, inv_mass);
        }
        self.resolve_one_way(&self.pose(t), h, x, v, inv_mass)
    }

    /// [`Collider::resolve`] of a collider that takes nothing back (no [`Response`]), at
    /// `pose`: each particle on its own, so any run of them can be resolved apart from the
    /// others.
    fn resolve_one_way(
        &self,
        pose: &Pose,
        h: Scalar,
        x: &mut [Vector],
        v: &mut [Vector],
        inv_mass: &[Scalar],
    ) -> usize {
        let m = &self.material;
        let thick = m.thickness as Scalar;
        let mut contacts = 0;
        for i in 0..x.len() {
            if inv_mass[i] == 0.0 || self.clear(pose, thick, h, x[i], v[i]) {
                continue;
            }
            let hit = self.swept_contact(pose, thick, h, x[i], v[i]);
            if let Some((target, n)) = hit {
                contacts += 1;
                x[i] = target;
                let vc = Self::surface_velocity(pose, target);
                let rel = v[i] - vc;
                let vn = rel.dot(n);
                if vn < 0.0 {
                    let vt = rel - n * vn;
                    let e = self.restitution_for(vn);
                    let dvn = -(1.0 + e) * vn;
                    let vt_len = vt.length();
                    let keep = if vt_len > 0.0 {
                        (1.0 - m.friction as Scalar * dvn / vt_len).max(0.0)
                    } else {
                        0.0
                    };
                    v[i] = vc + n * (-e * vn) + vt * keep;
                }
            }
        }
        contacts
    }

    fn restitution_for(&self, vn: Scalar) -> Scalar {
        let m = &self.material;
        if -vn > m.bounce_threshold as Scalar {
            m.restitution as Scalar
        } else {
            0.0
        }
    }

    /// [`Collider::resolve`] against a dynamic body: sequential impulses with the pair's
    /// effective mass, the body's velocity updated after each contact (Gauss–Seidel, in
    /// particle order), the impulses summed into the [`Exchange`].
    fn resolve_exchanging(
        &self,
        body: &Response,
        t: Scalar,
        h: Scalar,
        x: &mut [Vector],
        v: &mut [Vector],
        inv_mass: &[Scalar],
    ) -> usize {
        let pose = self.pose(t);
        let m = &self.material;
        let thick = m.thickness as Scalar;
        let mu = m.friction as Scalar;
        let tau = t - body.t0;
        let mut ex = body.exchange.lock().unwrap_or_else(|e| e.into_inner());
        // The body's velocity at this instant before this call's contacts.
        let (v0, w0) = (pose.velocity, pose.omega);
        let (j0, l0) = (ex.linear, ex.angular);
        let mut contacts = 0;
        for i in 0..x.len() {
            let wp = inv_mass[i];
            if wp == 0.0 || self.clear(&pose, thick, h, x[i], v[i]) {
                continue;
            }
            let Some((target, n)) = self.swept_contact(&pose, thick, h, x[i], v[i]) else {
                continue;
            };
            contacts += 1;
            x[i] = target;
            // Gauss–Seidel: the contacts before this one in the sweep already pushed the body.
            let vb = v0 + (ex.linear - j0) * body.inv_mass;
            let wb = w0 + body.inv_inertia_mul(ex.angular - l0);
            let r = target - pose.center;
            let rel = v[i] - (vb + wb.cross(r));
            let vn = rel.dot(n);
            if vn >= 0.0 {
                continue;
            }
            let e = self.restitution_for(vn);
            let jn = -(1.0 + e) * vn / (wp + body.inverse_mass_along(r, n));
            let vt = rel - n * vn;
            let vt_len = vt.length();
            let mut impulse = n * jn;
            if vt_len > 0.0 && mu > 0.0 {
                let tdir = vt / vt_len;
                let jt = (mu * jn).min(vt_len / (wp + body.inverse_mass_along(r, tdir)));
                impulse -= tdir * jt;
            }
            v[i] += impulse * wp;
            let torque = r.cross(impulse);
            ex.linear -= impulse;
            ex.angular -= torque;
            ex.linear_moment -= impulse * tau;
            ex.angular_moment -= torque * tau;
            ex.contacts += 1;
        }
        contacts
    }
}

/// Particles a chunk of [`resolve_all`] holds on the team (about ten microseconds of work
/// against a sphere and the ground; smaller under Miri).
const RESOLVE_CHUNK: usize = crate::core::kernels::chunk_limit(512, 64);

/// Every collider's [`Collider::resolve`], in order, at the end `t` of a step of length `h`.
/// When none of them takes impulses back (no [`Response`]: each particle's response is its
/// own), the particles are cut into chunks shared with the team of threads the caller runs
/// in (see [`crate::core::kernels::with_threads`]), every collider in turn on a chunk: each
/// particle meets the colliders in the same order as one collider after another over all of
/// them, so the bits are the same on any number of threads. A collider that does (two-way
/// coupling, which sums the impulses it takes) keeps them all on the caller, in order.
pub fn resolve_all(
    colliders: &[Collider],
    t: Scalar,
    h: Scalar,
    x: &mut [Vector],
    v: &mut [Vector],
    inv_mass: &[Scalar],
) {
    let n = x.len().min(v.len()).min(inv_mass.len());
    if n < 2 * RESOLVE_CHUNK || colliders.iter().any(|c| c.response.is_some()) {
        for c in colliders {
            c.resolve(t, h, x, v, inv_mass);
        }
        return;
    }
    let (xs, vs) = (SharedMut(x.as_mut_ptr()), SharedMut(v.as_mut_ptr()));
    for_each_range(n, RESOLVE_CHUNK, |r| {
        // SAFETY: each range is its own chunk's, within `x` and `v`.
        let (x, v) = unsafe { (xs.slice(r.clone()), vs.slice(r.clone())) };
        for c in colliders {
            c.resolve_one_way(&c.pose(t), h, x, v, &inv_mass[r.clone()]);
        }
    });
}

/// The box a body's particles can reach within `dt`: their bounds grown by twice the fastest
/// particle's travel (room for what forces add within the frame) and `margin` (`None` for a
/// body without particles or with a non-finite one). A broad phase: a collider whose own box
/// over the frame misses this one cannot touch the body in the frame.
pub fn reach_bounds(
    x: &[Vector],
    v: &[Vector],
    dt: Scalar,
    margin: Scalar,
) -> Option<(Vector, Vector)> {
    let (mut lo, mut hi) = (
        Vector::splat(Scalar::INFINITY),
        Vector::splat(-Scalar::INFINITY),
    );
    let mut vmax2: Scalar = 0.0;
    for (x, v) in x.iter().zip(v) {
        lo = lo.min(*x);
        hi = hi.max(*x);
        vmax2 = vmax2.max(v.length_squared());
    }
    if x.is_empty() || !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    let grow = 2.0 * vmax2.sqrt() * dt + margin;
    Some((lo - Vector::splat(grow), hi + Vector::splat(grow)))
}

/// True when boxes `a` and `b` (corner pairs) overlap.
pub fn boxes_overlap(a: (Vector, Vector), b: (Vector, Vector)) -> bool {
    a.0.cmple(b.1).all() && b.0.cmple(a.1).all()
}

/// `shape` stretched by `scale` along its own axes (a transform's scale), or `None` for a
/// shape or scale this cannot represent (a zero or non-finite factor, a compound shape). A
/// ball, capsule, cylinder or cone under a non-uniform scale becomes a convex polyhedron of
/// `subdivisions` segments around, as in avian; a half-space's normal is transformed by the
/// inverse scale, which keeps the plane through the origin where the stretched plane is.
pub fn scale_shape(
    shape: &SharedShape,
    scale: glam::Vec3,
    subdivisions: u32,
) -> Option<SharedShape> {
    use parry3d::either::Either;
    use parry3d::shape::TypedShape;
    if !(scale.is_finite() && scale.abs().min_element() > 0.0) {
        return None;
    }
    if scale == glam::Vec3::ONE {
        return Some(shape.clone());
    }
    let s = scale.abs();
    fn either<A, B>(e: Option<Either<A, B>>) -> Option<SharedShape>
    where
        A: parry3d::shape::Shape,
        B: parry3d::shape::Shape,
    {
        e.map(|e| match e {
            Either::Left(a) => SharedShape::new(a),
            Either::Right(b) => SharedShape::new(b),
        })
    }
    match shape.as_typed_shape() {
        TypedShape::Ball(b) => either(b.scaled(s, subdivisions)),
        TypedShape::Cuboid(c) => Some(SharedShape::new(c.scaled(s))),
        TypedShape::Capsule(c) => either(c.scaled(s, subdivisions)),
        TypedShape::Cylinder(c) => either(c.scaled(s, subdivisions)),
        TypedShape::Cone(c) => either(c.scaled(s, subdivisions)),
        TypedShape::HalfSpace(h) => (h.normal / scale)
            .try_normalize()
            .map(SharedShape::halfspace),
        TypedShape::TriMesh(m) => Some(SharedShape::new(m.clone().scaled(scale))),
        TypedShape::ConvexPolyhedron(c) => c.clone().scaled(scale).map(SharedShape::new),
        TypedShape::HeightField(h) => Some(SharedShape::new(h.clone().scaled(scale))),
        TypedShape::Triangle(t) => Some(SharedShape::new(t.scaled(scale))),
        TypedShape::Segment(g) => Some(SharedShape::new(g.scaled(scale))),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Collider::clear` stands for `swept_contact` finding nothing: over random particles
    /// near a sphere (still, and moving) and a tilted half-space, with paths up to several
    /// thicknesses long, no particle it calls clear has a contact, and it calls clear most of
    /// those far away (so the response loops skip them).
    #[test]
    fn a_particle_called_clear_has_no_contact() {
        let mut rng = crate::math::test_rng(0x2545_f491_4f6c_dd1du64);
        let mut rnd = move || rng() as Scalar;
        let material = ContactMaterial {
            thickness: 0.02,
            ..Default::default()
        };
        let tilt = Rot3::from_scaled_axis(glam::Vec3::new(0.3, 0.0, 0.2));
        let colliders = [
            Collider::new(
                SharedShape::ball(0.3),
                Motion::Fixed {
                    position: [0.1, 0.2, -0.1],
                },
                Rot3::IDENTITY,
                material,
            ),
            Collider::new(
                SharedShape::ball(0.3),
                Motion::Linear {
                    start: [0.0; 3],
                    velocity: [2.0, -1.0, 0.5],
                    t0: 0.0,
                },
                Rot3::IDENTITY,
                material,
            ),
            Collider::new(
                SharedShape::halfspace(parry3d::math::Vector::Y),
                Motion::Fixed {
                    position: [0.0, -0.2, 0.0],
                },
                tilt,
                material,
            ),
        ];
        let h = 0.01;
        for c in &colliders {
            let pose = c.pose(0.3);
            let thick = material.thickness as Scalar;
            let (mut clear, mut far) = (0, 0);
            for _ in 0..20_000 {
                let p = pose.origin + Vector::new(rnd(), rnd(), rnd()) * 0.6;
                let v = Vector::new(rnd(), rnd(), rnd()) * (10.0 * rnd().abs());
                let hit = c.swept_contact(&pose, thick, h, p, v);
                if c.clear(&pose, thick, h, p, v) {
                    clear += 1;
                    assert!(hit.is_none(), "{p:?} at {v:?} called clear has {hit:?}");
                }
                far += usize::from(hit.is_none());
            }
            assert!(
                clear > far / 2,
                "{clear} of {far} without contact called clear"
            );
        }
    }
}
