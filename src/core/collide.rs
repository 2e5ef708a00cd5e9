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
use crate::core::solve::PointRows;
use crate::math::{Matrix3, Scalar, ToScalar, Vector, VectorExt};
use parry3d::math::{Pose3, Rot3};
use std::sync::Arc;

mod hull;
use hull::{HullFoot, HullPlanes};
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
    /// A box's half extents (parry's precision).
    Cuboid(glam::Vec3),
    /// A capsule: its axis and radius (parry's precision).
    Capsule(parry3d::shape::Capsule),
    /// Any other shape: its box and its bounding sphere (centre and radius) in its own frame
    /// (parry's `compute_local_aabb` and `compute_local_bounding_sphere`, in parry's
    /// precision), for the clear test.
    General {
        mins: glam::Vec3,
        maxs: glam::Vec3,
        centre: glam::Vec3,
        radius: f32,
        /// A convex polyhedron's triangles' planes, for its point and triangle queries
        /// without GJK, and its support points for the GJK of triangles crossing it.
        hull: Option<Arc<HullPlanes>>,
    },
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
    /// Records an impulse `impulse` given to a particle at arm `arm` from the body's centre,
    /// `tau` into the frame: the body gets its opposite.
    fn give(&mut self, impulse: Vector, arm: Vector, tau: Scalar) {
        let torque = arm.cross(impulse);
        self.linear -= impulse;
        self.angular -= torque;
        self.linear_moment -= impulse * tau;
        self.angular_moment -= torque * tau;
        self.contacts += 1;
    }

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
        } else if let Some(c) = shape.as_cuboid() {
            Fast::Cuboid(c.half_extents)
        } else if let Some(c) = shape.as_capsule() {
            Fast::Capsule(*c)
        } else {
            let (aabb, ball) = (
                shape.compute_local_aabb(),
                shape.compute_local_bounding_sphere(),
            );
            Fast::General {
                mins: aabb.mins,
                maxs: aabb.maxs,
                centre: ball.center,
                radius: ball.radius,
                hull: HullPlanes::of(&shape),
            }
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
            Fast::Cuboid(half) => {
                // parry's projection onto a box, in its frame (in `f32` as parry's): clamped
                // from outside, to the nearest face from inside (or on it).
                let local = pose.rotation.inverse() * (p - c).to_f32();
                let out = local.abs() - half;
                let (q, n) = if out.max_element() > 0.0 {
                    let q = local.clamp(-half, half);
                    let d = local - q;
                    let dist = d.length();
                    if dist as Scalar >= thick || dist <= 1e-9 {
                        return None;
                    }
                    (q, d / dist)
                } else {
                    let axis = if out.x >= out.y && out.x >= out.z {
                        0
                    } else if out.y >= out.z {
                        1
                    } else {
                        2
                    };
                    let sign = if local[axis] < 0.0 { -1.0 } else { 1.0 };
                    let mut q = local;
                    q[axis] = sign * half[axis];
                    let mut n = glam::Vec3::ZERO;
                    n[axis] = sign;
                    (q, n)
                };
                let n = (pose.rotation * n).to_scalar();
                Some((c + (pose.rotation * q).to_scalar() + n * thick, n))
            }
            Fast::Capsule(cap) => {
                // Its own: the nearest point of its axis, in its frame (in `f32`, as parry's
                // projection, which it equals).
                let local = pose.rotation.inverse() * (p - c).to_f32();
                let (q, d, dist) = capsule_axis_nearest(&cap, local);
                let r = cap.radius as Scalar;
                if dist as Scalar >= r + thick {
                    return None;
                }
                let n = if dist > 1e-9 {
                    d / dist
                } else {
                    // On the axis: out across it.
                    (cap.segment.b - cap.segment.a).any_orthonormal_vector()
                };
                let n_world = (pose.rotation * n).to_scalar();
                Some((
                    c + (pose.rotation * q).to_scalar() + n_world * (r + thick),
                    n_world,
                ))
            }
            Fast::General { ref hull, .. } => {
                if let Some(hull) = hull {
                    // A convex polyhedron by its own triangles, not parry's GJK (`HullPlanes`).
                    let local = pose.rotation.inverse() * (p - c).to_f32();
                    let foot = hull.foot(local, thick as f32);
                    return match foot {
                        Some(HullFoot {
                            point,
                            normal,
                            signed,
                        }) if (signed as Scalar) < thick => {
                            let n = (pose.rotation * normal).to_scalar();
                            Some((c + (pose.rotation * point).to_scalar() + n * thick, n))
                        }
                        _ => None,
                    };
                }
                let pose = Pose3::from_parts(c.to_f32(), pose.rotation);
                let pf = p.to_f32();
                // Not `solid`: a point inside is its own projection then, and its way out
                // would be lost.
                let proj = self.shape.project_point(&pose, pf, false);
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
    /// under symplectic Euler and the implicit methods) is followed from its start: the
    /// first point within the thickness ([`Collider::first_within`]) is the contact, or, for
    /// a segment starting within the thickness, a hit of the shape itself from outside, on
    /// the side it came from. Without this a particle crossing a shape thinner than its
    /// travel in one step would pass through (or be pushed out the far side), and one
    /// passing within the thickness and on would pass a rod's side that its neighbour, in
    /// the cloth, was stopped on top of: the rod between them.
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
        // Along its path the particle may come within the thickness and pass on (a cloth's
        // particle falling past a rod's side, its neighbour stopped on top): the first
        // point of the path within the thickness is the contact. A path that starts within
        // the thickness is cast against the shape itself.
        if let Some((at, n)) = self.first_within(&shape_pose, thick, start, travel) {
            return Some((at, n));
        }
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

    /// The most steps of [`Collider::first_within`]'s conservative advancement: a path
    /// that grazes the thickness without reaching it in as many is taken as missing it.
    const ADVANCE: usize = 64;

    /// Where the segment from `start` by `travel` first comes within `thick` of the shape at
    /// `shape_pose`, and the shape's outward normal there (the direction from its nearest
    /// point): the segment cast against the shape grown by the thickness, exactly for a
    /// sphere, a capsule and a box (the first time into each of the grown shape's parts),
    /// by conservative advancement for any other shape. `None` when the segment never comes
    /// that near, or starts within it.
    fn first_within(
        &self,
        shape_pose: &Pose3,
        thick: Scalar,
        start: Vector,
        travel: Vector,
    ) -> Option<(Vector, Vector)> {
        // A round shape in its own frame, exactly: the first time the segment comes within
        // the grown radius of the centre or the axis, and the direction from there.
        let local = |p: Vector| {
            (shape_pose.rotation.inverse() * (p - shape_pose.translation.to_scalar()).to_f32())
                .to_scalar()
        };
        let (o, d) = {
            let o = local(start);
            (o, local(start + travel) - o)
        };
        let round = |a: Vector, b: Vector, r: Scalar| {
            let t = first_within_capsule(a, b, r + thick, o, d)?;
            let at = o + d * t;
            let (_, off, _) = segment_nearest(a, b, at);
            Some((t, shape_pose.rotation * off.normalize().to_f32()))
        };
        let hit = match self.fast {
            Fast::Sphere(r) => round(Vector::ZERO, Vector::ZERO, r),
            Fast::Cuboid(half) => {
                let half = half.to_scalar();
                let t = first_within_box(half, thick, o, d)?;
                let at = o + d * t;
                let off = at - at.clamp(-half, half);
                Some((t, shape_pose.rotation * off.normalize().to_f32()))
            }
            Fast::Capsule(cap) => round(
                cap.segment.a.to_scalar(),
                cap.segment.b.to_scalar(),
                cap.radius as Scalar,
            ),
            // Any other shape by conservative advancement (Mirtich, *Impulse-based dynamic
            // simulation of rigid body systems*, 1996): the distance is 1-Lipschitz along
            // the path, so a step of what is left to the thickness never passes it. (Parry's
            // cast of a ball against a convex polyhedron stopped up to 5 mm short of it.)
            //
            // A convex shape's distance is convex along the path too, so its tangent meets
            // the thickness no later than the path does: the step is Newton's where that is
            // longer (a path nearly along a face closes its distance a little each step),
            // and a path whose distance grows never comes nearer.
            _ => {
                let len = travel.length();
                let convex = self.shape.is_convex();
                let mut t: Scalar = 0.0;
                let mut found = None;
                for _ in 0..Self::ADVANCE {
                    let at = start + travel * t;
                    let (foot, inside) = self.project_solid(shape_pose, at);
                    let off = at - foot;
                    let d = if inside { 0.0 } else { off.length() };
                    if d <= thick * (1.0 + 1e-4) {
                        found = (t > 0.0 && d > 0.0).then(|| (t, (off / d).to_f32()));
                        break;
                    }
                    let mut step = (d - thick) / len;
                    if convex {
                        let rate = (off / d).dot(travel);
                        if rate >= 0.0 {
                            break;
                        }
                        step = step.max((d - thick) / -rate);
                    }
                    t += step;
                    if t > 1.0 {
                        break;
                    }
                }
                found
            }
        };
        let (toi, n) = hit?;
        (toi > 0.0 && n.is_finite()).then(|| (start + travel * toi, n.to_scalar()))
    }

    /// The nearest point of a general shape at `shape_pose` to `p`, and whether `p` is
    /// inside it (then the point is `p`): parry's solid projection, a convex polyhedron's
    /// by its triangles ([`HullPlanes::foot`]).
    fn project_solid(&self, shape_pose: &Pose3, p: Vector) -> (Vector, bool) {
        if let Fast::General {
            hull: Some(hull), ..
        } = &self.fast
        {
            let local =
                shape_pose.rotation.inverse() * (p - shape_pose.translation.to_scalar()).to_f32();
            if let Some(foot) = hull.foot(local, f32::INFINITY) {
                return if foot.signed <= 0.0 {
                    (p, true)
                } else {
                    ((*shape_pose * foot.point).to_scalar(), false)
                };
            }
        }
        let foot = self.shape.project_point(shape_pose, p.to_f32(), true);
        (foot.point.to_scalar(), foot.is_inside)
    }

    /// Whether a particle at `p` moving at `v` is certainly clear of the collider: what
    /// [`Collider::swept_contact`] would find nothing for, told without it (most particles
    /// of a body are clear of each collider, and the response loops are then a few
    /// operations a particle). A half-space's test is its own; a shape not turning is left
    /// when the particle is farther from a simple shape around it (a sphere's or a box's
    /// bounding sphere, a capsule's axis, any other shape's box and bounding sphere) than the
    /// thickness by more than its path over the step (so is every point of the path), with a
    /// margin over the round-off. A turning shape is never called clear. (Without the box
    /// and sphere of a general shape, every particle of a cloth falling past a small convex
    /// hull paid parry's point projection every step: 314 against 96 ms a frame in
    /// `benches/colliders.rs`.)
    #[inline(always)]
    fn clear(&self, pose: &Pose, thick: Scalar, h: Scalar, p: Vector, v: Vector) -> bool {
        match self.fast {
            Fast::Plane(_) => (p - pose.origin).dot(pose.normal) >= thick,
            Fast::Sphere(r) if pose.omega == Vector::ZERO => {
                let reach = r + thick + (v - pose.velocity).length() * h;
                (p - pose.origin).length_squared() > reach * reach * 1.0001
            }
            // A box not turning: beyond the sphere around it, by as much.
            Fast::Cuboid(half) if pose.omega == Vector::ZERO => {
                let reach = half.length() as Scalar + thick + (v - pose.velocity).length() * h;
                (p - pose.origin).length_squared() > reach * reach * 1.0001
            }
            // A capsule not turning: farther from its axis than its radius and the thickness,
            // by as much.
            Fast::Capsule(cap) if pose.omega == Vector::ZERO => {
                let local = pose.rotation.inverse() * (p - pose.origin).to_f32();
                let (_, _, dist) = capsule_axis_nearest(&cap, local);
                let reach = cap.radius as Scalar + thick + (v - pose.velocity).length() * h;
                dist as Scalar > reach * 1.0001 + 1e-6
            }
            // Any other shape not turning: outside its box grown by as much along some axis
            // of its frame, or outside its bounding sphere grown by as much (the path's every
            // point then farther than the thickness from the box or the sphere, and so from
            // the shape), with a margin over the turn's round-off.
            Fast::General {
                mins,
                maxs,
                centre,
                radius,
                ..
            } if pose.omega == Vector::ZERO => {
                let off = p - pose.origin;
                let local = (pose.rotation.inverse() * off.to_f32()).to_scalar();
                let reach = thick + (v - pose.velocity).length() * h;
                let margin = reach * 1.0001 + 1e-6 * (1.0 + off.abs().max_element());
                (local - maxs.to_scalar()).max_element() > margin
                    || (mins.to_scalar() - local).max_element() > margin
                    || (local - centre.to_scalar()).length() > radius as Scalar + margin
            }
            _ => false,
        }
    }

    /// The square of how far a particle that ended a step of length `h` at `x`, from `x0`,
    /// moved relative to the collider's surface at `pose` (the surface's velocity taken at
    /// `x`, as [`Collider::swept_contact`] takes it).
    #[inline(always)]
    fn travel_sq(pose: &Pose, h: Scalar, x0: Vector, x: Vector) -> Scalar {
        (x - x0 - Self::surface_velocity(pose, x) * h).length_squared()
    }

    /// The farthest any of the first `n` particles moved relative to the collider's surface
    /// over a step from `x0` to `x` ([`Collider::travel_sq`]): the margin within which a
    /// feature may have met the collider along its path.
    fn fastest(pose: &Pose, h: Scalar, x0: &[Vector], x: &[Vector], n: usize) -> Scalar {
        (0..n)
            .map(|i| Self::travel_sq(pose, h, x0[i], x[i]))
            .fold(0.0, Scalar::max)
            .sqrt()
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
    /// Implicit steps that do not hold them along the contact normals with friction hold
    /// them still (Baraff & Witkin's constraint filter: sticking contact) instead of letting
    /// the step drive them in and projecting them out afterwards, which pumps energy into
    /// stiff elements. Sets their `mask` to 0 and their velocity to the collider's surface
    /// velocity; particles with `mask` 0 already are left alone. A collider with a
    /// [`Response`] holds nothing: the constraint force of a held particle would never reach
    /// its body, so its contacts are resolved after the step like an explicit method's, where
    /// the impulse is exchanged.
    #[allow(clippy::too_many_arguments)]
    pub fn hold(
        &self,
        t: Scalar,
        slack: Scalar,
        x: &[Vector],
        v: &mut [Vector],
        f: &[Vector],
        inv_mass: &[Scalar],
        mask: &mut [Scalar],
    ) {
        if self.response.is_some() {
            return;
        }
        let pose = self.pose(t);
        let thick = self.material.thickness as Scalar + slack;
        let n = x
            .len()
            .min(v.len())
            .min(f.len())
            .min(inv_mass.len())
            .min(mask.len());
        for i in 0..n {
            if inv_mass[i] == 0.0 || mask[i] == 0.0 {
                continue;
            }
            if let Some((_, nrm)) = self.contact(&pose, thick, x[i]) {
                let vc = Self::surface_velocity(&pose, x[i]);
                if (v[i] - vc).dot(nrm) <= 0.0 && f[i].dot(nrm) <= 0.0 {
                    mask[i] = 0.0;
                    v[i] = vc;
                }
            }
        }
    }

    /// Particles resting on this collider, held along the contact normal for the step
    /// (Baraff and Witkin's constraint filter with one constrained direction: free to slide
    /// and to be pulled off): each particle within the thickness plus `slack` of it at time
    /// `t`, not moving away from its surface along the normal, pushed towards it by `f` (its
    /// total force), and not crossing more than the thickness in the step, approaching no
    /// faster than reaching the thickness does. Pushes the particle, the normal and the
    /// surface's velocity with the allowed approach onto `out`, as [`Collider::hold_faces`]
    /// does for triangles' corners. Particles with `mask` zero are left out; a collider with
    /// a [`Response`] holds nothing.
    #[allow(clippy::too_many_arguments)]
    pub fn hold_points(
        &self,
        t: Scalar,
        h: Scalar,
        slack: Scalar,
        x: &[Vector],
        v: &[Vector],
        f: &[Vector],
        inv_mass: &[Scalar],
        mask: &[Scalar],
        out: &mut Vec<(u32, Vector, Vector, Scalar)>,
    ) {
        if self.response.is_some() || h <= 0.0 {
            return;
        }
        let pose = self.pose(t);
        let material = self.material.thickness as Scalar;
        let thick = material + slack;
        let mu = self.material.friction as Scalar;
        let n = x
            .len()
            .min(v.len())
            .min(f.len())
            .min(inv_mass.len())
            .min(mask.len());
        for i in 0..n {
            if inv_mass[i] == 0.0 || mask[i] == 0.0 || self.clear(&pose, thick, 0.0, x[i], v[i]) {
                continue;
            }
            let Some((at, nrm)) = self.contact(&pose, thick, x[i]) else {
                continue;
            };
            let vc = Self::surface_velocity(&pose, x[i]);
            let vn = (v[i] - vc).dot(nrm);
            // Approaching faster than the thickness a step: the contact after the step knows
            // the side it came from (its swept test); should the step take it in, the trial
            // holds it. Sliding along the surface, at any speed, it is held.
            if -vn * h > material.max(ROUND_OFF_SLACK) {
                continue;
            }
            // The distance from the collider's surface: `at` lies `thick` out along `nrm`.
            let dist = thick - (at - x[i]).dot(nrm);
            let allowed = -(dist - material).max(0.0) / h;
            // Not moving away (by more than a hundredth of the thickness over the step: a
            // particle the last step held moves along the surface with round-off across it).
            if vn * h <= (0.01 * material).max(ROUND_OFF_SLACK) && f[i].dot(nrm) <= 0.0 {
                out.push((i as u32, nrm, vc + nrm * vn.clamp(allowed, 0.0), mu));
            }
        }
    }

    /// The second look of an implicit step at the particles ([`Collider::hold_points`] was
    /// the first), as [`Collider::hold_faces_trial`] takes it at the triangles: each particle
    /// the trial end `trial` (at `t + h`) leaves nearer the collider than its thickness, by
    /// more than a hundredth of it, is met at the step's start `x0` (normal `n`, distance
    /// `d₀`) and, if the trial moves it along `n` slower than `−(d₀ − thickness)⁺ / h`
    /// relative to the surface, held along `n` at that velocity. Returns how many holds it
    /// pushed onto `out`.
    #[allow(clippy::too_many_arguments)]
    pub fn hold_points_trial(
        &self,
        t: Scalar,
        h: Scalar,
        x0: &[Vector],
        trial: &[Vector],
        inv_mass: &[Scalar],
        mask: &[Scalar],
        out: &mut Vec<(u32, Vector, Vector, Scalar)>,
    ) -> usize {
        if self.response.is_some() || h <= 0.0 {
            return 0;
        }
        let (start, end) = (self.pose(t), self.pose(t + h));
        let thick = self.material.thickness as Scalar;
        let mu = self.material.friction as Scalar;
        let inside = 0.99 * thick;
        let n = x0
            .len()
            .min(trial.len())
            .min(inv_mass.len())
            .min(mask.len());
        let before = out.len();
        for i in 0..n {
            if inv_mass[i] == 0.0
                || mask[i] == 0.0
                || self.clear(&end, inside, 0.0, trial[i], end.velocity)
                || self.contact(&end, inside, trial[i]).is_none()
            {
                continue;
            }
            let travel = (trial[i] - x0[i]).length();
            let reach = thick + 2.0 * travel;
            let Some((at, nrm)) = self.contact(&start, reach, x0[i]) else {
                continue;
            };
            let d0 = reach - (at - x0[i]).dot(nrm);
            let vc = Self::surface_velocity(&start, x0[i]);
            let allowed = -(d0 - thick).max(0.0) / h;
            let vi = (trial[i] - x0[i]) / h;
            if (vi - vc).dot(nrm) < allowed {
                out.push((i as u32, nrm, vc + nrm * allowed, mu));
            }
        }
        out.len() - before
    }

    /// The triangles' form of [`Collider::hold`], for a surface whose cells are wider than
    /// the collider needs ([`Collider::needs_faces`]): a triangle within the thickness plus
    /// `slack` of the collider at time `t` rests on it at its closest point, and each of its
    /// corners that is not moving away from the collider's surface there along the contact
    /// normal and is pushed towards it by `f` (its total force) is held along that normal for
    /// the step (Baraff and Witkin's constraint filter with one constrained direction: the
    /// corner stays free to slide and to be pulled across). Pushes each such corner, the
    /// normal, the surface's velocity at the contact and the collider's friction coefficient
    /// onto `out`; the caller turns them into filters ([`NormalHolds::settle`]), and gives
    /// each corner Coulomb's friction once where its step takes the triangles' friction
    /// ([`NormalHolds::face_friction`], [`NormalHolds::one_friction_per_particle`]).
    /// Particles with `mask` zero (pinned, or already held whole) are left out. A collider
    /// with a [`Response`] holds nothing, as in [`Collider::hold`]: its body would never feel
    /// the constraint's force.
    ///
    /// A triangle spanning the collider (no corner within the thickness of it) is held at
    /// its contact point instead ([`FaceHold`], pushed onto `at_points`; nothing onto
    /// `out`): if the point is not moving away from
    /// the collider and the free corners' forces push it towards it (`Σ wⱼ fⱼ · n / mⱼ ≤ 0`),
    /// its velocity along the normal is held, and the triangle stays free to tip about it.
    ///
    /// An implicit step that instead let its springs pull a cloth's corners round a rod
    /// about as wide as its cells, and pushed the triangles back out after the step, did
    /// work against the stretched springs at every step: the cloth stayed wedged on the rod.
    #[allow(clippy::too_many_arguments)]
    pub fn hold_faces(
        &self,
        t: Scalar,
        h: Scalar,
        slack: Scalar,
        faces: &[[u32; 3]],
        edge: Scalar,
        x: &[Vector],
        v: &[Vector],
        f: &[Vector],
        inv_mass: &[Scalar],
        mask: &[Scalar],
        out: &mut Vec<(u32, Vector, Vector, Scalar)>,
        at_points: &mut Vec<FaceHold>,
    ) {
        if self.response.is_some() || faces.is_empty() || !self.needs_faces(edge) {
            return;
        }
        let pose = self.pose(t);
        let thick = self.material.thickness as Scalar + slack;
        let mu = self.material.friction as Scalar;
        let n = x
            .len()
            .min(v.len())
            .min(f.len())
            .min(inv_mass.len())
            .min(mask.len());
        for (ids, (bary, point, nrm, dist)) in self.faces_within(&pose, thick, edge, faces, x, n) {
            let vc = Self::surface_velocity(&pose, point);
            // A triangle that may cross more than the thickness in the step is not held: the
            // contact after the step knows the side it came from (`resolve_faces`' swept
            // test), and a corner held along the normal it has now stops short of where
            // that puts it (a cloth thrown at a rod at 10 m/s in frame-long steps then ended
            // a frame 0.1 mm from the rod). Should the step take it in, the trial holds it.
            if ids.iter().any(|&i| (v[i] - vc).length() * h > thick) {
                continue;
            }
            // Approaching no faster than it does, and not past the thickness.
            let allowed = -(dist - thick + slack).max(0.0) / h;
            // At its contact point, where it spans the collider (no corner within the
            // thickness of it). A triangle with a corner on the surface is held at its
            // corners: wrapped round a curved surface, a flat triangle turning about a point
            // of it cuts into it, and a cloth wrapped round a rod as wide as its cells was
            // left stretched 11 % there (4 % held at corners; 12 % where only triangles with
            // two or three corners on the surface were).
            let spans = ids
                .iter()
                .all(|&i| self.contact(&pose, thick, x[i]).is_none());
            if spans {
                // Held at the contact point: its velocity along the normal, and its
                // acceleration by the free corners' forces.
                let free = ids.map(|i| inv_mass[i] != 0.0 && mask[i] != 0.0);
                let (mut vn, mut an) = (0.0, 0.0);
                for k in 0..3 {
                    let i = ids[k];
                    vn += bary[k] * (v[i] - vc).dot(nrm);
                    if free[k] {
                        an += bary[k] * inv_mass[i] * f[i].dot(nrm);
                    }
                }
                if free.iter().any(|&f| f) && vn <= 0.0 && an <= 0.0 {
                    at_points.push(FaceHold {
                        ids: ids.map(|i| i as u32),
                        weights: bary,
                        free,
                        normal: nrm,
                        velocity: vc + nrm * vn.max(allowed),
                        friction: mu,
                    });
                }
                continue;
            }
            for i in ids {
                let vn = (v[i] - vc).dot(nrm);
                if inv_mass[i] != 0.0 && mask[i] != 0.0 && vn <= 0.0 && f[i].dot(nrm) <= 0.0 {
                    out.push((i as u32, nrm, vc + nrm * vn.max(allowed), mu));
                }
            }
        }
    }

    /// The second look of an implicit step at the triangles ([`Collider::hold_faces`] was
    /// the first): `trial` holds where a solve would end the step (at `t + h`), `x0` and
    /// `v` the particles at its start `t`. Each triangle the trial leaves nearer the
    /// collider than its thickness, by more than a hundredth of it, or takes through the
    /// collider (its corners moved by more than the thickness, and the direction from the
    /// collider to its nearest point turned past a right angle: the swept test of
    /// [`Collider::resolve_faces`]), is met at the step's start (its nearest point, normal
    /// `n` and distance `d₀` there); each of its corners that the trial moves along `n`
    /// slower than `−(d₀ − thickness)⁺ / h` relative to the collider's surface is held
    /// along `n` at that velocity, so the triangle arrives at the thickness instead of
    /// going in (an active set: the caller solves again with the holds). Returns how many
    /// holds it pushed onto `out`.
    ///
    /// Without the swept test a cloth falling onto a rod thinner than a frame's fall went
    /// through it in the trial, was put back on its side after each step, and stretched
    /// over the rod from step to step until the rod cut through a cell
    /// (`tests/collider_faces.rs`).
    #[allow(clippy::too_many_arguments)]
    pub fn hold_faces_trial(
        &self,
        t: Scalar,
        h: Scalar,
        faces: &[[u32; 3]],
        edge: Scalar,
        x0: &[Vector],
        trial: &[Vector],
        inv_mass: &[Scalar],
        mask: &[Scalar],
        out: &mut Vec<(u32, Vector, Vector, Scalar)>,
    ) -> usize {
        if self.response.is_some() || faces.is_empty() || !self.needs_faces(edge) || h <= 0.0 {
            return 0;
        }
        let (start, end) = (self.pose(t), self.pose(t + h));
        let thick = self.material.thickness as Scalar;
        let mu = self.material.friction as Scalar;
        let shape_start = Pose3::from_parts(start.origin.to_f32(), start.rotation);
        let n = x0
            .len()
            .min(trial.len())
            .min(inv_mass.len())
            .min(mask.len());
        let before = out.len();
        let shape_end = Pose3::from_parts(end.origin.to_f32(), end.rotation);
        let clear = self.face_filter(&end, &shape_end, thick, edge);
        // Corners that moved relative to the collider's surface by more than the thickness
        // may have been taken through it (a rod thinner than a frame's fall): such a
        // triangle is looked at within twice that. Triangles clear by twice the fastest
        // particle's travel are clear by their own corners' (`clear` is monotone in its
        // margin): skipped before their travel is measured, as in `resolve_faces`.
        let fastest = Self::fastest(&end, h, x0, trial, n);
        let grow_any = if fastest > thick { 2.0 * fastest } else { 0.0 };
        for face in faces {
            let ids = face.map(|i| i as usize);
            if ids[0].max(ids[1]).max(ids[2]) >= n {
                continue;
            }
            let tri = ids.map(|i| trial[i]);
            if clear(tri, grow_any) {
                continue;
            }
            // The particles' bound on the triangle is asked over the step when its corners
            // travelled that far, as `resolve_faces`' swept test asks it.
            let swept = ids
                .map(|i| Self::travel_sq(&end, h, x0[i], trial[i]))
                .into_iter()
                .fold(0.0, Scalar::max)
                .sqrt();
            let grow = if swept > thick { 2.0 * swept } else { 0.0 };
            let then = (grow > 0.0).then(|| (&start, ids.map(|i| x0[i])));
            if grow < grow_any && clear(tri, grow) || self.feature_held(&end, thick, tri, then) {
                continue;
            }
            let Some((_, _, n_end, dist)) = self.face_contact(&end, &shape_end, thick + grow, tri)
            else {
                continue;
            };
            let inside = thick - dist > 0.01 * thick;
            if !inside && grow == 0.0 {
                continue;
            }
            // Met at the start within what its corners travelled (and the thickness).
            let travel = ids
                .map(|i| (trial[i] - x0[i]).length())
                .into_iter()
                .fold(0.0, Scalar::max);
            let tri0 = ids.map(|i| x0[i]);
            let reach = thick + 2.0 * travel;
            let Some((_, point, nrm, d0)) = self.face_contact(&start, &shape_start, reach, tri0)
            else {
                continue;
            };
            // Not within the thickness at the trial's end, but through: the direction from
            // the collider to it turned past a right angle.
            if !inside && n_end.dot(nrm) >= 0.0 {
                continue;
            }
            let vc = Self::surface_velocity(&start, point);
            let allowed = -(d0 - thick).max(0.0) / h;
            for i in ids {
                let vi = (trial[i] - x0[i]) / h;
                if inv_mass[i] != 0.0 && mask[i] != 0.0 && (vi - vc).dot(nrm) < allowed {
                    out.push((i as u32, nrm, vc + nrm * allowed, mu));
                }
            }
        }
        out.len() - before
    }

    /// The triangles of `faces` (their corners below `n`, at positions `x`) nearer the
    /// collider at `pose` than `thick`, with their corners and [`Collider::face_contact`]:
    /// the cheap filter and the per-feature bound told first.
    fn faces_within<'a>(
        &'a self,
        pose: &'a Pose,
        thick: Scalar,
        edge: Scalar,
        faces: &'a [[u32; 3]],
        x: &'a [Vector],
        n: usize,
    ) -> impl Iterator<Item = ([usize; 3], ([Scalar; 3], Vector, Vector, Scalar))> + 'a {
        let shape_pose = Pose3::from_parts(pose.origin.to_f32(), pose.rotation);
        let clear = self.face_filter(pose, &shape_pose, thick, edge);
        faces.iter().filter_map(move |face| {
            let ids = face.map(|i| i as usize);
            if ids[0].max(ids[1]).max(ids[2]) >= n {
                return None;
            }
            let tri = ids.map(|i| x[i]);
            if clear(tri, 0.0) || self.feature_held(pose, thick, tri, None) {
                return None;
            }
            Some((ids, self.face_contact(pose, &shape_pose, thick, tri)?))
        })
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
            ex.give(impulse, r, tau);
        }
        contacts
    }
}

impl Collider {
    /// Whether contact at the particles alone could let this collider come closer than half
    /// its thickness to the inside of a surface triangle whose edges are at most `edge` long
    /// while each of its corners is held at the thickness: only then need the triangles be
    /// tested ([`Collider::resolve_faces`]). Every point of such a triangle lies within
    /// `edge/√3` of a corner (the equilateral triangle's centre is the farthest).
    ///
    /// - A half-space: never (the distance to it is affine along a triangle, least at a
    ///   corner).
    /// - A sphere of radius `R`, thickness `t`: the triangle's plane, at `d` from the centre,
    ///   meets the shell of radius `s = R + t` in a circle that the triangle's corners lie on
    ///   or outside of, so a point of the triangle nearer the centre than `s` lies within
    ///   `√(s² − d²) ≤ edge/√3` of the plane's foot, and the triangle comes no nearer than
    ///   `√(s² − edge²/3)`. That is at least `R + t/2` unless `edge² > 3t(R + ¾t)`: a cloth
    ///   whose cells are small against the sphere needs its particles alone. A capsule's
    ///   round ends are such spheres, and along its side the strip a triangle crosses is
    ///   spanned by an edge (half-width at most `edge/2`): the same test with its radius.
    /// - Any other shape may have an edge or a corner as sharp as a knife: the distance is
    ///   1-Lipschitz, so a triangle comes no nearer than `t − edge/√3`, at least `t/2`
    ///   unless `edge > (√3/2) t`.
    pub fn needs_faces(&self, edge: Scalar) -> bool {
        let t = self.material.thickness as Scalar;
        let round = |r: Scalar| edge * edge > 3.0 * t * (r + 0.75 * t);
        match self.fast {
            Fast::Plane(_) => false,
            Fast::Sphere(r) => round(r),
            Fast::Cuboid(_) => edge > 0.5 * (3.0 as Scalar).sqrt() * t,
            Fast::Capsule(c) => round(c.radius as Scalar),
            Fast::General { .. } => edge > 0.5 * (3.0 as Scalar).sqrt() * t,
        }
    }

    /// Contact between the surface's triangles `faces` and the collider at the end `t` of a
    /// step of length `h`, after the particles' own ([`Collider::resolve`]): a triangle
    /// whose closest point to the collider is nearer than its thickness is pushed out along
    /// the contact normal, its corners moved in proportion to their barycentric weights and
    /// inverse masses so that the closest point itself reaches the thickness, and the
    /// point's velocity relative to the collider's surface loses its approach (with the
    /// collider's restitution) and is held by Coulomb friction, as one impulse of the
    /// triangle's effective mass `1 / Σ bᵢ² wᵢ` (Bridson, Fedkiw and Anderson, *Robust
    /// treatment of collisions, contact and friction for cloth animation*, 2002, §7.1: the
    /// impulse at a point of a triangle). A collider with a [`Response`] takes the impulse
    /// back as for a particle. Triangles in turn (Gauss–Seidel), on the caller.
    ///
    /// A triangle whose corners moved relative to the collider by more than the thickness in
    /// the step is also tested at the step's start (its corners back by `h` times their
    /// velocities, as [`Collider::resolve`]'s swept test takes them): when the direction
    /// from the collider to the triangle's nearest point turned by more than a right angle
    /// over the step, the collider passed through it (a rod between a cloth's particles in
    /// one frame-long step), and the triangle is put back on the side it came from, past the
    /// collider's extreme point that way by the thickness.
    ///
    /// `faces` are the features: triangles, and edges written `[a, b, b]` (tested only when
    /// they moved more than the thickness, the triangles covering them otherwise). `edge`
    /// bounds their edges (see [`Collider::needs_faces`]: when the particles' contact suffices
    /// for triangles that long, nothing is tested). `x0` holds the particles' positions at
    /// the step's start, before any contact moved them; `near` is scratch, the features met
    /// and the side each came from. Returns the number of features pushed in the first sweep.
    #[allow(clippy::too_many_arguments)]
    pub fn resolve_faces(
        &self,
        t: Scalar,
        h: Scalar,
        faces: &[[u32; 3]],
        edge: Scalar,
        x0: &[Vector],
        x: &mut [Vector],
        v: &mut [Vector],
        inv_mass: &[Scalar],
        near: &mut Vec<(u32, Vector)>,
    ) -> usize {
        near.clear();
        if faces.is_empty() || !self.needs_faces(edge) {
            return 0;
        }
        let pose = self.pose(t);
        let before = self.pose(t - h);
        let thick = self.material.thickness as Scalar;
        let shape_pose = Pose3::from_parts(pose.origin.to_f32(), pose.rotation);
        let shape_before = Pose3::from_parts(before.origin.to_f32(), before.rotation);
        let clear = self.face_filter(&pose, &shape_pose, thick, edge);
        let mut body = self.response.as_ref().map(|r| {
            let ex = r.exchange.lock().unwrap_or_else(|e| e.into_inner());
            let (j0, l0) = (ex.linear, ex.angular);
            (r, ex, j0, l0)
        });
        let n = x.len().min(x0.len()).min(v.len()).min(inv_mass.len());
        // The corners' inverse masses, unless all are pinned.
        let weights = |ids: [usize; 3]| {
            let w = ids.map(|i| inv_mass[i]);
            (w != [0.0; 3]).then_some(w)
        };
        // The farthest any particle moved relative to the collider: features farther than
        // twice that (and the thickness) are skipped before their own travel is measured.
        let moved = |x: &[Vector], i: usize| Self::travel_sq(&pose, h, x0[i], x[i]);
        let fastest = Self::fastest(&pose, h, x0, x, n);
        let grow = if fastest > thick { 2.0 * fastest } else { 0.0 };
        // A round shape's bound holds over the step too (see `feature_held`): told first, on
        // the positions alone.
        let round = matches!(self.fast, Fast::Sphere(_) | Fast::Capsule(_));
        let mut pushed = 0;
        for (k, f) in faces.iter().enumerate() {
            // At the end of a step the triangles cover their edges; an edge is tested for
            // itself only when it may have passed through the collider.
            let edge = f[1] == f[2];
            if edge && grow == 0.0 {
                continue;
            }
            let ids = f.map(|i| i as usize);
            if ids[0].max(ids[1]).max(ids[2]) >= n {
                continue;
            }
            let tri = ids.map(|i| x[i]);
            if clear(tri, grow) || round && self.feature_held(&pose, thick, tri, None) {
                continue;
            }
            let Some(w) = weights(ids) else { continue };
            let travel = ids
                .map(|i| moved(x, i))
                .into_iter()
                .fold(0.0, Scalar::max)
                .sqrt();
            let swept = travel > thick;
            if !swept && edge {
                continue;
            }
            let reach = if swept { thick + 2.0 * travel } else { thick };
            let then = swept.then(|| (&before, ids.map(|i| x0[i])));
            if clear(tri, reach - thick) || !round && self.feature_held(&pose, thick, tri, then) {
                continue;
            }
            let Some((bary, point, mut nrm, dist)) =
                self.face_contact(&pose, &shape_pose, reach, tri)
            else {
                continue;
            };
            let mut depth = thick - dist;
            if swept {
                // A triangle farther than `reach` at the start cannot be within the thickness
                // now (it came at most `travel` closer).
                let start = ids.map(|i| x0[i]);
                let Some((_, _, n0, _)) = self.face_contact(&before, &shape_before, reach, start)
                else {
                    continue;
                };
                let Some(out) = self.back(&shape_pose, thick, (point, nrm, dist), n0) else {
                    continue;
                };
                (nrm, depth) = out;
            }
            near.push((k as u32, nrm));
            if depth > 0.0 {
                // A feature that went through the collider in the step is stopped whole.
                let settle = (!swept).then_some(h);
                pushed += usize::from(self.face_response(
                    &pose,
                    &mut body,
                    (t, settle),
                    ids,
                    w,
                    (bary, point, nrm, depth),
                    x,
                    v,
                ));
            }
        }
        // Triangles sharing corners push each other back in (a cloth wrapped round a rod
        // pulls on both sides): Gauss–Seidel sweeps over the triangles met, until none is
        // short of the thickness by more than a hundredth of it.
        for _ in 1..FACE_SWEEPS {
            let mut worst: Scalar = 0.0;
            for &(k, side) in near.iter() {
                // In range: the first sweep met it.
                let ids = faces[k as usize].map(|i| i as usize);
                let Some(w) = weights(ids) else { continue };
                let tri = ids.map(|i| x[i]);
                // Looked at up to several thicknesses away: a triangle pushed through by its
                // neighbours goes back to the side it was on.
                let Some((bary, point, nrm, dist)) =
                    self.face_contact(&pose, &shape_pose, 4.0 * thick, tri)
                else {
                    continue;
                };
                let Some((nrm, depth)) = self.back(&shape_pose, thick, (point, nrm, dist), side)
                else {
                    continue;
                };
                worst = worst.max(depth);
                if depth > 0.0 {
                    self.face_response(
                        &pose,
                        &mut body,
                        (t, Some(h)),
                        ids,
                        w,
                        (bary, point, nrm, depth),
                        x,
                        v,
                    );
                }
            }
            if worst <= 0.01 * thick {
                break;
            }
        }
        pushed
    }

    /// Which way a feature in contact `(point, normal, dist)` goes back out of the collider
    /// (at `shape_pose`), given the side it came from: the direction from the collider to it
    /// at the step's start, `side`. A feature whose nearest direction turned past a right
    /// angle went through: it goes back along `side`, the thickness past the collider's
    /// extreme point that way. One inside the collider (a rod through a triangle) goes out
    /// along the contact normal or that way, whichever is the shorter push: the penetration
    /// depth of a flat feature may point along its plane, and triangles on either side of
    /// the rod would then push their shared corners back and forth. The normal and the depth
    /// to push by (along the contact normal, `thick − dist`, when it did neither); `None`
    /// when it must go back but the collider has no extreme point to go by.
    fn back(
        &self,
        shape_pose: &Pose3,
        thick: Scalar,
        (point, nrm, dist): (Vector, Vector, Scalar),
        side: Vector,
    ) -> Option<(Vector, Scalar)> {
        let through = nrm.dot(side) < 0.0;
        if !through && dist >= 0.0 {
            return Some((nrm, thick - dist));
        }
        let far = self
            .shape
            .as_support_map()?
            .support_point(shape_pose, side.to_f32())
            .to_scalar();
        let d = thick - (point - far).dot(side);
        Some(if through || d < thick - dist {
            (side, d)
        } else {
            (nrm, thick - dist)
        })
    }

    /// One triangle's response to its contact `(bary, point, normal, depth)` (see
    /// [`Collider::resolve_faces`]): false when its corners cannot move.
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn face_response(
        &self,
        pose: &Pose,
        body: &mut Option<(
            &Response,
            std::sync::MutexGuard<'_, Exchange>,
            Vector,
            Vector,
        )>,
        (t, settle): (Scalar, Option<Scalar>),
        ids: [usize; 3],
        w: [Scalar; 3],
        (bary, point, nrm, depth): ([Scalar; 3], Vector, Vector, Scalar),
        x: &mut [Vector],
        v: &mut [Vector],
    ) -> bool {
        let mu = self.material.friction as Scalar;
        let denom: Scalar = (0..3).map(|k| bary[k] * bary[k] * w[k]).sum();
        if denom.is_nan() || denom <= 0.0 {
            return false;
        }
        // A corner moves `bᵢ wᵢ / Σ bⱼ² wⱼ` times as far as the point (at most 1.21 times when
        // the corners weigh the same; without bound as the point nears a pinned corner): a
        // point carried less than half by free corners is pushed only as far as keeps each
        // corner within twice the push, and its impulse scaled alike (a fraction of an
        // inelastic impulse adds no energy either).
        let lever = (0..3)
            .map(|k| bary[k] * w[k] / denom)
            .fold(0.0, Scalar::max);
        let part = (LEVER / lever).min(1.0);
        for (k, &i) in ids.iter().enumerate() {
            x[i] += nrm * (part * depth * bary[k] * w[k] / denom);
        }
        let vp = v[ids[0]] * bary[0] + v[ids[1]] * bary[1] + v[ids[2]] * bary[2];
        // Gauss–Seidel: the contacts before this one already pushed the body.
        let (vb, wb) = match body {
            Some((r, ex, j0, l0)) => (
                pose.velocity + (ex.linear - *j0) * r.inv_mass,
                pose.omega + r.inv_inertia_mul(ex.angular - *l0),
            ),
            None => (pose.velocity, pose.omega),
        };
        let arm = point - pose.center;
        let vc = if wb == Vector::ZERO {
            vb
        } else {
            vb + wb.cross(arm)
        };
        let rel = vp - vc;
        let vn = rel.dot(nrm);
        if vn >= 0.0 {
            return true;
        }
        let dynamic = body.as_ref().map(|(r, ..)| *r);
        let along = |d: Vector| dynamic.map_or(0.0, |r| r.inverse_mass_along(arm, d));
        let e = self.restitution_for(vn);
        // With `settle` (the step's length) and no bounce, the approach is stopped only as far
        // as the push does (a speculative contact: Firth, *Speculative contacts – a
        // continuous collision engine approach*, 2011): a point that came from outside the
        // thickness within the step keeps approaching at what brought it to the thickness
        // and stops in the next step; one that was inside already stops. The corners then end
        // the step where their velocities say (the push is the impulse's over the step).
        // Stopped whole in the step it arrives, a point took from the corners it shares with
        // a neighbouring contact the velocity that had brought them in, and that neighbour's
        // push then moved them out with no impulse to match: energy from nowhere, which kept
        // a coarse cloth tented on a small ball quivering 0.3–1 mm a frame for good. A feature
        // that went through the collider in the step (no `settle`) is stopped whole, and so
        // is one meeting a dynamic body: the body moves by the impulses it is given at the
        // frame's end, not along the step, so its side of the contact has no path for the
        // push to follow (a rigid ball resting on a trampoline kept 2.5 cm/s so, 4 mm/s
        // stopped whole).
        let stop = match settle {
            Some(h) if e == 0.0 && dynamic.is_none() => {
                (-vn).min(part * depth / h.max(Scalar::MIN_POSITIVE))
            }
            _ => -(1.0 + e) * vn,
        };
        let jn = stop / (denom + along(nrm));
        let vt = rel - nrm * vn;
        let vt_len = vt.length();
        let mut impulse = nrm * jn;
        if vt_len > 0.0 && mu > 0.0 {
            let tdir = vt / vt_len;
            let jt = (mu * jn).min(vt_len / (denom + along(tdir)));
            impulse -= tdir * jt;
        }
        impulse *= part;
        for (k, &i) in ids.iter().enumerate() {
            v[i] += impulse * (bary[k] * w[k]);
        }
        if let Some((r, ex, ..)) = body {
            ex.give(impulse, arm, t - r.t0);
        }
        true
    }

    /// [`Collider::touching`] for the surface's triangles `faces` (edges at most `edge`
    /// long) where the collider needs them ([`Collider::needs_faces`]): marks in `out` the
    /// corners of each triangle within the thickness plus `slack` of it at time `t`.
    #[allow(clippy::too_many_arguments)]
    pub fn touching_faces(
        &self,
        t: Scalar,
        slack: Scalar,
        faces: &[[u32; 3]],
        edge: Scalar,
        x: &[Vector],
        out: &mut [bool],
    ) {
        if faces.is_empty() || !self.needs_faces(edge) {
            return;
        }
        let pose = self.pose(t);
        let thick = self.material.thickness as Scalar + slack;
        let shape_pose = Pose3::from_parts(pose.origin.to_f32(), pose.rotation);
        let clear = self.face_filter(&pose, &shape_pose, thick, edge);
        let n = x.len().min(out.len());
        for f in faces {
            let [a, b, c] = f.map(|i| i as usize);
            if a.max(b).max(c) >= n || out[a] && out[b] && out[c] {
                continue;
            }
            let tri = [x[a], x[b], x[c]];
            if !clear(tri, 0.0)
                && !self.feature_held(&pose, thick, tri, None)
                && self.face_contact(&pose, &shape_pose, thick, tri).is_some()
            {
                out[a] = true;
                out[b] = true;
                out[c] = true;
            }
        }
    }

    /// Whether feature `tri` (a triangle, or an edge `[a, b, b]`) needs no test because its
    /// corners, held at `thick` or farther by the particles' contact, keep it there (the
    /// per-feature form of [`Collider::needs_faces`]'s bounds, with the feature's own longest
    /// edge `e`):
    ///
    /// - a sphere or a capsule of radius `ρ`: `e² ≤ 3t(ρ + ¾t)`. Over the step too: its
    ///   corners stay out of the shape itself along their paths (the particles' swept test),
    ///   and the feature then dips into it by at most about `t/2`, never through;
    /// - a box: all corners in one face's region (the distance is affine there, least at a
    ///   corner), at the step's start as well when `then` gives it (the region is convex, so
    ///   the corners stay in it along their straight paths); or, at the end only, the
    ///   nearest corner farther than `t + e/√3` (the distance is 1-Lipschitz, and every
    ///   point of the feature lies within `e/√3` of a corner).
    fn feature_held(
        &self,
        pose: &Pose,
        thick: Scalar,
        tri: [Vector; 3],
        then: Option<(&Pose, [Vector; 3])>,
    ) -> bool {
        let e2 = tri[0]
            .distance_squared(tri[1])
            .max(tri[1].distance_squared(tri[2]))
            .max(tri[2].distance_squared(tri[0]));
        let round = |r: Scalar| e2 <= 3.0 * thick * (r + 0.75 * thick);
        match self.fast {
            Fast::Plane(_) => true,
            Fast::Sphere(r) => round(r),
            Fast::Capsule(c) => round(c.radius as Scalar),
            Fast::General { .. } => false,
            Fast::Cuboid(half) => {
                // Each corner's face region (the axis it is out along and on which side), if
                // it is out along one axis only, and its distance from the box.
                let region = |pose: &Pose, p: Vector| {
                    let local = pose.rotation.inverse() * (p - pose.origin).to_f32();
                    let out = local.abs() - half;
                    let outside = out.cmpgt(glam::Vec3::ZERO).bitmask();
                    let side = local.cmpgt(glam::Vec3::ZERO).bitmask() & outside;
                    let face = (outside.count_ones() == 1).then_some((outside, side));
                    (face, out.max(glam::Vec3::ZERO).length() as Scalar)
                };
                let (first, mut nearest) = region(pose, tri[0]);
                let mut one = first.is_some();
                for p in &tri[1..] {
                    let (face, d) = region(pose, *p);
                    one &= face == first;
                    nearest = nearest.min(d);
                }
                match then {
                    Some((before, start)) => {
                        one && start.iter().all(|&p| region(before, p).0 == first)
                    }
                    None => one || nearest > thick + e2.sqrt() / (3.0 as Scalar).sqrt(),
                }
            }
        }
    }

    /// A test that a triangle is certainly farther than `thick` and its second argument from
    /// the collider (at `pose`, edges at most `edge`), told cheaply: a sphere's centre farther
    /// from a corner than the sphere, that distance and the edge bound; any other shape's box
    /// (grown by that distance) missing the triangle's.
    fn face_filter(
        &self,
        pose: &Pose,
        shape_pose: &Pose3,
        thick: Scalar,
        edge: Scalar,
    ) -> impl Fn([Vector; 3], Scalar) -> bool + use<> {
        let aabb = self.shape.compute_aabb(shape_pose);
        let grow = glam::Vec3::splat(thick as f32);
        let (lo, hi) = (
            (aabb.mins - grow).to_scalar(),
            (aabb.maxs + grow).to_scalar(),
        );
        let (centre, reach) = match self.fast {
            Fast::Sphere(r) => (pose.origin, r + thick + edge),
            // Any other shape: its bounding sphere as well as its box (the box alone let a
            // draped cloth's every triangle over a hull's top through to the hull's query).
            Fast::General { centre, radius, .. } => (
                pose.origin + (pose.rotation * centre).to_scalar(),
                radius as Scalar * 1.0001 + 1e-6 + thick + edge,
            ),
            _ => (Vector::ZERO, Scalar::INFINITY),
        };
        // A ball's sphere is the ball itself: no box besides.
        let boxed = !matches!(self.fast, Fast::Sphere(_));
        move |[pa, pb, pc]: [Vector; 3], more: Scalar| {
            let m = Vector::splat(more);
            (reach.is_finite() && (pa - centre).length_squared() > (reach + more) * (reach + more))
                || (boxed
                    && ((pa.min(pb).min(pc) - m).cmpgt(hi).any()
                        || (pa.max(pb).max(pc) + m).cmplt(lo).any()))
        }
    }

    /// The closest point of triangle `tri` to the collider (at `pose`) when nearer than
    /// `reach`: its barycentric weights, the point, the unit normal out of the collider
    /// towards it, and its distance from the collider's surface (negative inside).
    fn face_contact(
        &self,
        pose: &Pose,
        shape_pose: &Pose3,
        reach: Scalar,
        tri: [Vector; 3],
    ) -> Option<([Scalar; 3], Vector, Vector, Scalar)> {
        // parry's queries assert on non-finite input, and in `f32` a corner 10¹⁹ m away
        // squares past the largest float: a triangle reaching 10 km from the collider is a
        // diverging body's, left to the divergence check.
        if !tri
            .iter()
            .all(|&p| p.is_finite() && (p - pose.origin).abs().max_element() < FAR_FEATURE)
        {
            return None;
        }
        let d = |p: Vector| glam::DVec3::from_array(p.to_f64());
        let bary_of = |p: Vector| {
            let b = crate::core::self_contact::closest_on_triangle(
                d(p),
                d(tri[0]),
                d(tri[1]),
                d(tri[2]),
            );
            b.map(|x| x as Scalar)
        };
        match self.fast {
            Fast::Plane(_) => None,
            Fast::Sphere(r) => {
                let bary = bary_of(pose.origin);
                let q = tri[0] * bary[0] + tri[1] * bary[1] + tri[2] * bary[2];
                let off = q - pose.origin;
                let dist = off.length();
                if dist.is_nan() || dist >= r + reach {
                    return None;
                }
                // The centre on the triangle: out along its normal.
                let n = if dist > 0.0 {
                    off / dist
                } else {
                    (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize_or_zero()
                };
                (n != Vector::ZERO).then_some((bary, q, n, dist - r))
            }
            Fast::Cuboid(half) => {
                // In the box's frame, in `f64`: the closest points when apart; parry's
                // penetration query when the feature is in the box.
                let rot = glam::DQuat::from_array(pose.rotation.to_array().map(f64::from));
                let o = d(pose.origin);
                let local = tri.map(|p| rot.inverse() * (d(p) - o));
                let Some((on_tri, on_box)) = triangle_box_closest(local, half.as_dvec3()) else {
                    // Overlapping: the least translation out (what parry's penetration
                    // query, EPA, answers, without its allocations).
                    let Some((p, n, depth)) = triangle_box_penetration(local, half.as_dvec3())
                    else {
                        return self.face_contact_parry(shape_pose, reach, tri, None);
                    };
                    let n = (rot * n).to_array().to_scalar();
                    let point = (rot * p + o).to_array().to_scalar();
                    return Some((bary_of(point), point, n, -depth as Scalar));
                };
                let off = on_tri - on_box;
                let dist = off.length();
                if dist == 0.0 {
                    // Touching: no direction between them; parry's query gives one.
                    return self.face_contact_parry(shape_pose, reach, tri, None);
                }
                if dist.is_nan() || dist >= reach as f64 {
                    return None;
                }
                let n = (rot * (off / dist)).to_array().map(|c| c as Scalar);
                let point = (rot * on_tri + o).to_array().map(|c| c as Scalar);
                let (n, point) = (Vector::from_array(n), Vector::from_array(point));
                Some((bary_of(point), point, n, dist as Scalar))
            }
            Fast::Capsule(cap) => {
                // Apart from the capsule, parry's contact query (GJK). In it, the triangle's
                // closest point to the axis, exactly and without parry's penetration query
                // (EPA), which allocates: implicit steps ask it about every triangle their
                // trial solve takes into a rod. Crossed by the axis, parry's.
                let rot = glam::DQuat::from_array(pose.rotation.to_array().map(f64::from));
                let o = d(pose.origin);
                let [a, b] = [cap.segment.a, cap.segment.b].map(|p| rot * p.as_dvec3() + o);
                let r = cap.radius as f64;
                match triangle_segment_closest(tri.map(d), a, b) {
                    Some((on_tri, on_axis)) if (1e-9..r).contains(&on_tri.distance(on_axis)) => {
                        let off = on_tri - on_axis;
                        let len = off.length();
                        let n = (off / len).to_array().to_scalar();
                        let point = on_tri.to_array().to_scalar();
                        Some((bary_of(point), point, n, (len - r) as Scalar))
                    }
                    _ => self.face_contact_parry(shape_pose, reach, tri, None),
                }
            }
            Fast::General { ref hull, .. } => {
                // A convex polyhedron: first by its own triangles' planes (a separating
                // plane, exact where its nearest corner's foot lies in its triangle), then
                // by exact pairs with its triangles, then (crossing it) parry's query on the
                // hull's own support points. The triangle in the shape's frame, in f64 for
                // exact pairs, and a pair's closest points there as the contact.
                let rot = glam::DQuat::from_array(pose.rotation.to_array().map(f64::from));
                let o = d(pose.origin);
                let local64 = || tri.map(|p| rot.inverse() * (d(p) - o));
                let contact = |(on_tri, on_shape): (glam::DVec3, glam::DVec3)| {
                    let off = on_tri - on_shape;
                    let dist = off.length();
                    let n = (rot * (off / dist)).to_array().to_scalar();
                    let point = (rot * on_tri + o).to_array().to_scalar();
                    Some((bary_of(point), point, n, dist as Scalar))
                };
                if let Some(hull) = hull {
                    let local = tri.map(|p| pose.rotation.inverse() * (p - pose.origin).to_f32());
                    let last = match hull.triangle(local, reach as f32) {
                        Ok(None) => return None,
                        Ok(Some((corner, n, dist))) => {
                            let mut bary = [0.0; 3];
                            bary[corner] = 1.0;
                            if tri[1] == tri[2] && corner == 2 {
                                bary = [0.0, 1.0, 0.0];
                            }
                            let n = (pose.rotation * n).to_scalar();
                            return Some((bary, tri[corner], n, dist as Scalar));
                        }
                        Err(last) => last,
                    };
                    // Unsettled by a plane: the exact pairs with the hull's triangles that can
                    // hold the nearest point (parry's GJK was millimetres off); crossing the
                    // hull or inside it, parry's query for the depth.
                    let near = hull.near_triangles(local, reach as f32, last);
                    let near = near.map(|c| c.map(|p| p.as_dvec3()));
                    match nearest_of_triangles(local64(), near, reach as f64) {
                        Ok(Some(pair)) => return contact(pair),
                        Ok(None) if !hull.contains(local[0]) => return None,
                        _ => {}
                    }
                }
                if let Some(mesh) = self.shape.as_trimesh() {
                    // A triangle mesh: its triangles near this one, each pair's distance
                    // exactly (parry's GJK on two triangles is millimetres off near a
                    // mesh); crossing any, parry's query for the depth.
                    return match mesh_triangle_closest(mesh, local64(), reach as f64) {
                        Err(()) => self.face_contact_parry(shape_pose, reach, tri, None),
                        Ok(None) => None,
                        Ok(Some(pair)) => contact(pair),
                    };
                }
                self.face_contact_parry(shape_pose, reach, tri, hull.as_deref())
            }
        }
    }

    /// [`Collider::face_contact`] by parry's contact query (GJK, and EPA for a feature in the
    /// shape). A convex polyhedron's `hull` gives the query its support points by a walk
    /// ([`HullPlanes::support`]) instead of parry's scan of every vertex: the same GJK and
    /// EPA, the same support points.
    fn face_contact_parry(
        &self,
        shape_pose: &Pose3,
        reach: Scalar,
        tri: [Vector; 3],
        hull: Option<&HullPlanes>,
    ) -> Option<([Scalar; 3], Vector, Vector, Scalar)> {
        let d = |p: Vector| glam::DVec3::from_array(p.to_f64());
        let [a, b, c] = tri.map(|p| p.to_f32());
        // An edge, `[a, b, b]`, is a segment (a flat triangle's penetration is not).
        let (segment, triangle) = (
            parry3d::shape::Segment::new(a, b),
            parry3d::shape::Triangle::new(a, b, c),
        );
        let c = if let Some(hull) = hull {
            // The feature at the origin: `shape_pose` is the hull's pose relative to it, and
            // the contact's point and normal on the feature are as parry's `contact` gives.
            let feature: &dyn parry3d::shape::SupportMap = if tri[1] == tri[2] {
                &segment
            } else {
                &triangle
            };
            parry3d::query::details::contact_support_map_support_map(
                shape_pose,
                feature,
                hull,
                reach as f32,
            )
        } else {
            let feature: &dyn parry3d::shape::Shape = if tri[1] == tri[2] {
                &segment
            } else {
                &triangle
            };
            parry3d::query::contact(
                &Pose3::IDENTITY,
                feature,
                shape_pose,
                &*self.shape,
                reach as f32,
            )
            .ok()
            .flatten()
        }?;
        let dist = c.dist as Scalar;
        let n = (-c.normal1).to_scalar();
        let point = c.point1.to_scalar();
        if dist.is_nan() || dist >= reach || !n.is_finite() || !point.is_finite() {
            return None;
        }
        let b = crate::core::self_contact::closest_on_triangle(
            d(point),
            d(tri[0]),
            d(tri[1]),
            d(tri[2]),
        );
        Some((b.map(|x| x as Scalar), point, n, dist))
    }
}

/// The closest points of triangle `t` (a segment when `t[1] == t[2]`) and the box of half
/// extents `h` centred at the origin, all in the box's frame: `(on the triangle, on the box)`;
/// `None` when they overlap (no separating axis: Akenine-Möller, *Fast 3D triangle-box
/// overlap testing*, 2001). Apart, the nearest points of two convex polyhedra are a vertex of
/// one and its nearest point on the other, or the nearest points of an edge of each: the
/// least of the triangle's corners clamped to the box, the box's eight corners' nearest
/// points on the triangle, and the nearest points of each of the triangle's three edges and
/// the box's twelve (Ericson, *Real-Time Collision Detection*, §5.1).
fn triangle_box_closest(t: [glam::DVec3; 3], h: glam::DVec3) -> Option<(glam::DVec3, glam::DVec3)> {
    use glam::DVec3;
    if triangle_box_overlap(t, h) {
        return None;
    }
    let mut best = (f64::INFINITY, DVec3::ZERO, DVec3::ZERO);
    let take = |best: &mut (f64, DVec3, DVec3), p: DVec3, q: DVec3| {
        let d2 = p.distance_squared(q);
        if d2 < best.0 {
            *best = (d2, p, q);
        }
    };
    for v in t {
        take(&mut best, v, v.clamp(-h, h));
    }
    // A box corner or edge farther from the triangle's bounding box than the nearest pair so
    // far cannot be nearer to the triangle: skipped (most of them, for a triangle small
    // against the box).
    let (lo, hi) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
    let gap2 = |a: DVec3, b: DVec3| {
        (lo - a.max(b))
            .max(a.min(b) - hi)
            .max(DVec3::ZERO)
            .length_squared()
    };
    let corner = |i: usize| {
        let s = |bit: usize, x: f64| if i >> bit & 1 == 1 { x } else { -x };
        DVec3::new(s(0, h.x), s(1, h.y), s(2, h.z))
    };
    for i in 0..8 {
        let c = corner(i);
        if gap2(c, c) >= best.0 {
            continue;
        }
        let b = crate::core::self_contact::closest_on_triangle(c, t[0], t[1], t[2]);
        take(&mut best, t[0] * b[0] + t[1] * b[1] + t[2] * b[2], c);
    }
    let sides: &[(DVec3, DVec3)] = if t[1] == t[2] {
        &[(t[0], t[1])]
    } else {
        &[(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]
    };
    // The twelve edges: from each corner with a coordinate's bit clear, along that axis.
    for i in 0..8 {
        for axis in 0..3 {
            if i >> axis & 1 == 1 {
                continue;
            }
            let (a, b) = (corner(i), corner(i | 1 << axis));
            if gap2(a, b) >= best.0 {
                continue;
            }
            for &(p, q) in sides {
                let (x, y) = closest_on_segments(p, q, a, b);
                take(&mut best, x, y);
            }
        }
    }
    Some((best.1, best.2))
}

/// How triangle `t` (a segment when `t[1] == t[2]`), overlapping the box of half extents `h`
/// centred at the origin, is best pushed out of it, all in the box's frame: `(p, n, δ)`, the
/// point `p` of the triangle that moved by `δ n` touches the box's surface, `δ` the least
/// translation that separates them (the penetration depth) and `n` its unit direction.
/// Between convex polyhedra that depth is the least overlap of their projections on the
/// separating-axis candidates: the box's three axes, the triangle's normal and the nine
/// products of an edge of each (Ericson, *Real-Time Collision Detection*, §5.2.1; the
/// faces of their Minkowski difference have those normals). The point is the middle of
/// where the triangle's deepest feature along `−n` (a corner, an edge or the whole
/// triangle), moved by `δ n`, lies on the box's (clipped to the box, a millionth of its
/// size around it), or that feature's middle should round-off leave nothing. `None` when
/// they do not overlap or the triangle has no extent. This is what parry's penetration
/// query (EPA) answers, without its allocations.
fn triangle_box_penetration(
    t: [glam::DVec3; 3],
    h: glam::DVec3,
) -> Option<(glam::DVec3, glam::DVec3, f64)> {
    use glam::DVec3;
    let e = [t[1] - t[0], t[2] - t[1], t[0] - t[2]];
    let scale = h
        .max_element()
        .max(e.iter().map(|v| v.length()).fold(0.0, f64::max));
    if !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    // The least overlap over the candidates, in a fixed order (the box's faces first).
    let mut best: Option<(f64, DVec3)> = None;
    let mut try_axis = |a: DVec3| -> bool {
        let len = a.length();
        if len <= 1e-9 * scale * scale {
            return true;
        }
        let a = a / len;
        let p = t.map(|v| v.dot(a));
        let r = h.dot(a.abs());
        let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        // Pushed along `a`, the triangle must go `r − lo`; along `−a`, `hi + r`.
        for (depth, dir) in [(r - lo, a), (hi + r, -a)] {
            if depth <= 0.0 {
                return false;
            }
            if best.is_none_or(|(d, _)| depth < d) {
                best = Some((depth, dir));
            }
        }
        true
    };
    let mut overlap = [DVec3::X, DVec3::Y, DVec3::Z]
        .into_iter()
        .all(&mut try_axis);
    overlap = overlap && (t[1] == t[2] || try_axis(e[0].cross(e[1])));
    for a in [DVec3::X, DVec3::Y, DVec3::Z] {
        for side in e {
            overlap = overlap && try_axis(a.cross(side));
        }
    }
    let (depth, n) = best.filter(|_| overlap)?;
    // The triangle's deepest feature along `−n`, moved out by `δ n`, clipped to the box.
    let low = t
        .map(|v| v.dot(n))
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    let tol = 1e-9 * scale;
    let corners = if t[1] == t[2] { 2 } else { 3 };
    let mut poly = [DVec3::ZERO; 9];
    let mut len = 0;
    for &v in &t[..corners] {
        if v.dot(n) <= low + tol {
            poly[len] = v + n * depth;
            len += 1;
        }
    }
    let feature_mid = poly[..len].iter().sum::<DVec3>() / len as f64 - n * depth;
    let grow = 1e-6 * scale;
    for axis in 0..3 {
        for side in [1.0, -1.0] {
            // Keep `side x_axis ≤ h_axis + grow` (Sutherland–Hodgman).
            let inside = |p: DVec3| side * p[axis] - (h[axis] + grow);
            let mut out = [DVec3::ZERO; 9];
            let mut m = 0;
            for k in 0..len {
                let (a, b) = (poly[k], poly[(k + 1) % len]);
                let (da, db) = (inside(a), inside(b));
                if da <= 0.0 {
                    out[m] = a;
                    m += 1;
                }
                // A segment is closed by its way back: its crossing is taken once.
                if (da <= 0.0) != (db <= 0.0) && (len > 2 || k == 0) && m < 9 {
                    out[m] = a + (b - a) * (da / (da - db));
                    m += 1;
                }
            }
            poly = out;
            len = m;
            if len == 0 {
                return Some((feature_mid, n, depth));
            }
        }
    }
    let mid = poly[..len].iter().sum::<DVec3>() / len as f64;
    Some((mid - n * depth, n, depth))
}

/// The point of segment `a b` nearest `p`, the offset from it to `p` and its length, in
/// any of glam's vector types (the collider's precision, or parry's).
macro_rules! segment_nearest {
    ($a:expr, $b:expr, $p:expr) => {{
        let (a, b, p) = ($a, $b, $p);
        let ab = b - a;
        let len2 = ab.length_squared();
        let t = if len2 > 0.0 {
            ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let q = a + ab * t;
        let d = p - q;
        (q, d, d.length())
    }};
}

/// The point of segment `a b` nearest `p`, the offset from it to `p` and its length.
fn segment_nearest(a: Vector, b: Vector, p: Vector) -> (Vector, Vector, Scalar) {
    segment_nearest!(a, b, p)
}

/// The least `t` in `(0, 1]` at which `o + t d` is within `r` of segment `a b` (the capsule
/// round it; a ball when `a = b`), or `None` if none is or `o` is within already. The
/// capsule is the union of the cylinder round the segment and the balls round its ends, so
/// the first time is the least of the first times into each: the cylinder's by the
/// quadratic in `t` for the distance to the axis line (where the foot lies between the
/// ends), each ball's by its own.
fn first_within_capsule(a: Vector, b: Vector, r: Scalar, o: Vector, d: Vector) -> Option<Scalar> {
    if segment_nearest(a, b, o).2 <= r || d == Vector::ZERO {
        return None;
    }
    let ball = |c: Vector| {
        let oc = o - c;
        let (qa, qb, qc) = (d.dot(d), d.dot(oc), oc.dot(oc) - r * r);
        let disc = qb * qb - qa * qc;
        (disc >= 0.0).then(|| (-qb - disc.sqrt()) / qa)
    };
    let mut first = ball(a)
        .into_iter()
        .chain(ball(b))
        .fold(Scalar::INFINITY, Scalar::min);
    let ba = b - a;
    let (baba, bad, oa) = (ba.dot(ba), ba.dot(d), o - a);
    let (baoa, doa) = (ba.dot(oa), d.dot(oa));
    let qa = baba * d.dot(d) - bad * bad;
    if baba > 0.0 && qa > 0.0 {
        let qb = baba * doa - baoa * bad;
        let qc = baba * oa.dot(oa) - baoa * baoa - r * r * baba;
        let disc = qb * qb - qa * qc;
        if disc >= 0.0 {
            let t = (-qb - disc.sqrt()) / qa;
            let y = baoa + t * bad;
            if (0.0..=baba).contains(&y) {
                first = first.min(t);
            }
        }
    }
    (first > 0.0 && first <= 1.0).then_some(first)
}

/// The least `t` in `(0, 1]` at which `o + t d` is within `r` of the box of half extents
/// `half` centred at the origin, or `None` if none is or `o` is within already. The box grown
/// by `r` is the union of the box grown by `r` along one axis (three of them) and the
/// capsules of radius `r` round its twelve edges: the first time is the least of the first
/// times into each, the boxes' by their slabs.
fn first_within_box(half: Vector, r: Scalar, o: Vector, d: Vector) -> Option<Scalar> {
    let q = o.abs() - half;
    if q.max(Vector::ZERO).length() + q.max_element().min(0.0) <= r || d == Vector::ZERO {
        return None;
    }
    let slabs = |h: Vector| {
        let (mut enter, mut exit) = (Scalar::NEG_INFINITY, Scalar::INFINITY);
        for k in 0..3 {
            if d[k] == 0.0 {
                if o[k].abs() > h[k] {
                    return None;
                }
                continue;
            }
            let (t1, t2) = ((-h[k] - o[k]) / d[k], (h[k] - o[k]) / d[k]);
            enter = enter.max(t1.min(t2));
            exit = exit.min(t1.max(t2));
        }
        (enter <= exit).then_some(enter)
    };
    let mut first = Scalar::INFINITY;
    for k in 0..3 {
        let mut h = half;
        h[k] += r;
        if let Some(t) = slabs(h) {
            first = first.min(t);
        }
        // The four edges along axis `k`.
        for (s1, s2) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let mut a = Vector::ZERO;
            a[i] = s1 * half[i];
            a[j] = s2 * half[j];
            let mut b = a;
            a[k] = -half[k];
            b[k] = half[k];
            if let Some(t) = first_within_capsule(a, b, r, o, d) {
                first = first.min(t);
            }
        }
    }
    (first > 0.0 && first <= 1.0).then_some(first)
}

/// The point of capsule `cap`'s axis nearest `p` (in its frame), the offset from it to `p`
/// and its length.
fn capsule_axis_nearest(
    cap: &parry3d::shape::Capsule,
    p: glam::Vec3,
) -> (glam::Vec3, glam::Vec3, f32) {
    segment_nearest!(cap.segment.a, cap.segment.b, p)
}

/// Whether triangle `t` (a segment when two corners coincide) and the box of half extents `h`
/// centred at the origin overlap: no separating axis among the box's three, the triangle's
/// normal and the nine products of one of each's edges. An axis too short to be told apart
/// from round-off is skipped, which can only answer "overlap" for shapes just apart (and the
/// caller then asks parry).
fn triangle_box_overlap(t: [glam::DVec3; 3], h: glam::DVec3) -> bool {
    use glam::DVec3;
    if t[0].min(t[1]).min(t[2]).cmpgt(h).any() || t[0].max(t[1]).max(t[2]).cmplt(-h).any() {
        return false;
    }
    let e = [t[1] - t[0], t[2] - t[1], t[0] - t[2]];
    let apart = |axis: DVec3, scale: f64| {
        if axis.length_squared() <= 1e-20 * scale {
            return false;
        }
        let p = t.map(|v| v.dot(axis));
        let r = h.dot(axis.abs());
        p[0].min(p[1]).min(p[2]) > r || p[0].max(p[1]).max(p[2]) < -r
    };
    if apart(
        e[0].cross(e[1]),
        e[0].length_squared() * e[1].length_squared(),
    ) {
        return false;
    }
    for a in [DVec3::X, DVec3::Y, DVec3::Z] {
        for side in e {
            if apart(a.cross(side), side.length_squared()) {
                return false;
            }
        }
    }
    true
}

/// The nearest points of segments `p1 q1` and `p2 q2` (Ericson, *Real-Time Collision
/// Detection*, §5.1.9), segments of no length included.
fn closest_on_segments(
    p1: glam::DVec3,
    q1: glam::DVec3,
    p2: glam::DVec3,
    q2: glam::DVec3,
) -> (glam::DVec3, glam::DVec3) {
    let (d1, d2, r) = (q1 - p1, q2 - p2, p1 - p2);
    let (a, e, f) = (d1.length_squared(), d2.length_squared(), d2.dot(r));
    let tiny = f64::MIN_POSITIVE;
    let (s, t) = if a <= tiny && e <= tiny {
        (0.0, 0.0)
    } else if a <= tiny {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(r);
        if e <= tiny {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(d2);
            let denom = a * e - b * b;
            let mut s = if denom > 0.0 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    (p1 + d1 * s, p2 + d2 * t)
}

/// The closest points of triangles `a` and `b` (either a segment when its last two corners
/// are one): `(on a, on b)`; `None` when they cross (an edge of one crosses the other).
/// Apart, two triangles' closest pair is a corner of one and its nearest point on the other,
/// or the nearest points of an edge of each (Ericson, *Real-Time Collision Detection*,
/// §5.1.10): six point–triangle and nine segment–segment tests.
fn triangles_closest(
    a: [glam::DVec3; 3],
    b: [glam::DVec3; 3],
) -> Option<(glam::DVec3, glam::DVec3)> {
    let on = |t: [glam::DVec3; 3], x: glam::DVec3| {
        let w = crate::core::self_contact::closest_on_triangle(x, t[0], t[1], t[2]);
        t[0] * w[0] + t[1] * w[1] + t[2] * w[2]
    };
    for e in 0..3 {
        if segment_crosses(b, a[e], a[(e + 1) % 3]) || segment_crosses(a, b[e], b[(e + 1) % 3]) {
            return None;
        }
    }
    let mut best = (a[0], on(b, a[0]));
    let mut keep = |on_a: glam::DVec3, on_b: glam::DVec3| {
        if on_a.distance_squared(on_b) < best.0.distance_squared(best.1) {
            best = (on_a, on_b);
        }
    };
    for k in 0..3 {
        if k > 0 {
            keep(a[k], on(b, a[k]));
        }
        keep(on(a, b[k]), b[k]);
        for l in 0..3 {
            let (on_a, on_b) = closest_on_segments(a[k], a[(k + 1) % 3], b[l], b[(l + 1) % 3]);
            keep(on_a, on_b);
        }
    }
    Some(best)
}

/// The closest points of triangle `t` (in the mesh's frame) and the triangles of `mesh`
/// whose boxes come within `reach` of it: `Ok(Some((on t, on the mesh)))` when nearer than
/// `reach` and apart, `Ok(None)` when no triangle is that near, `Err(())` when `t` crosses
/// one of them, or touches it (no direction between them).
fn mesh_triangle_closest(
    mesh: &parry3d::shape::TriMesh,
    t: [glam::DVec3; 3],
    reach: f64,
) -> Result<Option<(glam::DVec3, glam::DVec3)>, ()> {
    let grow = glam::DVec3::splat(reach);
    let (lo, hi) = (
        (t[0].min(t[1]).min(t[2]) - grow).as_vec3(),
        (t[0].max(t[1]).max(t[2]) + grow).as_vec3(),
    );
    let near = parry3d::bounding_volume::Aabb::new(lo, hi);
    let near = mesh.bvh().intersect_aabb(&near).map(|id| {
        let m = mesh.triangle(id);
        [m.a, m.b, m.c].map(|p| p.as_dvec3())
    });
    nearest_of_triangles(t, near, reach)
}

/// The closest points of triangle `t` and the nearest of triangles `near` (on `t`, on that
/// one) when nearer than `reach`; `Err` when `t` crosses one of them.
fn nearest_of_triangles(
    t: [glam::DVec3; 3],
    near: impl Iterator<Item = [glam::DVec3; 3]>,
    reach: f64,
) -> Result<Option<(glam::DVec3, glam::DVec3)>, ()> {
    let mut best: Option<(glam::DVec3, glam::DVec3, f64)> = None;
    let own = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
    for m in near {
        // Nearer than `limit` or not at all: out of reach, or no nearer than the best yet.
        let limit = best.map_or(reach, |(_, _, b)| b);
        // Either triangle wholly on one side of the other's plane, that far or farther, is
        // no nearer (a plane between them bounds their distance from below).
        let s = m.map(|p| own.dot(p - t[0]));
        if s[0].min(s[1]).min(s[2]) >= limit || s[0].max(s[1]).max(s[2]) <= -limit {
            continue;
        }
        // Then by the other triangle's plane, as a convex hull's walk settles: all on one
        // side, its nearest corner's foot in the triangle is the closest pair exactly (the
        // plane holds the triangle, so no point of `t` is nearer).
        let normal = (m[1] - m[0]).cross(m[2] - m[0]);
        if normal.length_squared() > 0.0 {
            let normal = normal.normalize();
            let s = t.map(|p| normal.dot(p - m[0]));
            let (lo, hi) = (s[0].min(s[1]).min(s[2]), s[0].max(s[1]).max(s[2]));
            if lo >= limit || hi <= -limit {
                continue;
            }
            if lo > 0.0 || hi < 0.0 {
                let k = if lo > 0.0 {
                    (0..3).fold(0, |k, i| if s[i] < s[k] { i } else { k })
                } else {
                    (0..3).fold(0, |k, i| if s[i] > s[k] { i } else { k })
                };
                let foot = t[k] - normal * s[k];
                let left_of =
                    |u: glam::DVec3, v: glam::DVec3| (v - u).cross(foot - u).dot(normal) >= 0.0;
                if left_of(m[0], m[1]) && left_of(m[1], m[2]) && left_of(m[2], m[0]) {
                    let dist = s[k].abs();
                    if dist < reach && best.is_none_or(|(_, _, b)| dist < b) {
                        best = Some((t[k], foot, dist));
                    }
                    continue;
                }
            }
        }
        let (on_t, on_m) = triangles_closest(t, m).ok_or(())?;
        let dist = on_t.distance(on_m);
        if dist == 0.0 {
            return Err(());
        }
        if dist < reach && best.is_none_or(|(_, _, b)| dist < b) {
            best = Some((on_t, on_m, dist));
        }
    }
    Ok(best.map(|(p, q, _)| (p, q)))
}

/// Whether segment `p q` crosses triangle `t` (meets its plane at a point of the
/// triangle, to round-off); never for a triangle of no area.
fn segment_crosses(t: [glam::DVec3; 3], p: glam::DVec3, q: glam::DVec3) -> bool {
    let nrm = (t[1] - t[0]).cross(t[2] - t[0]);
    if nrm.length_squared() == 0.0 {
        return false;
    }
    let (sp, sq) = (nrm.dot(p - t[0]), nrm.dot(q - t[0]));
    if sp * sq > 0.0 || sp == sq {
        return false;
    }
    let x = p + (q - p) * (sp / (sp - sq));
    let w = crate::core::self_contact::closest_on_triangle(x, t[0], t[1], t[2]);
    let on = t[0] * w[0] + t[1] * w[1] + t[2] * w[2];
    on.distance_squared(x) <= 1e-24 * (1.0 + x.length_squared())
}

/// The closest points of triangle `t` (a segment when `t[1] == t[2]`) and segment `p q`:
/// `(on the triangle, on the segment)`; `None` when the segment crosses the triangle (no
/// direction between them). The least of the segment's ends against the triangle and the
/// segment against each edge (Ericson, *Real-Time Collision Detection*, §5.1.10): when the
/// segment does not cross the triangle, its closest pair has a point on the triangle's
/// boundary or an end of the segment.
fn triangle_segment_closest(
    t: [glam::DVec3; 3],
    p: glam::DVec3,
    q: glam::DVec3,
) -> Option<(glam::DVec3, glam::DVec3)> {
    let on_triangle = |x: glam::DVec3| {
        let w = crate::core::self_contact::closest_on_triangle(x, t[0], t[1], t[2]);
        t[0] * w[0] + t[1] * w[1] + t[2] * w[2]
    };
    if segment_crosses(t, p, q) {
        return None;
    }
    let mut best = (on_triangle(p), p);
    let edges = [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])];
    let ends = std::iter::once((on_triangle(q), q));
    let across = edges.into_iter().map(|(u, v)| {
        let (s, e) = closest_on_segments(p, q, u, v);
        (e, s)
    });
    for cand in ends.chain(across) {
        if cand.0.distance_squared(cand.1) < best.0.distance_squared(best.1) {
            best = cand;
        }
    }
    Some(best)
}

/// How far from a collider's origin a feature's corner may be for the feature to be tested
/// against it (m): see [`Collider::resolve_faces`].
const FAR_FEATURE: Scalar = 1e4;

/// 1 µm: how far round-off can leave a particle that the contact put on a collider's surface
/// (positions of metres carry 0.1 µm of it in `f32`), and the least slack of the implicit
/// steps' holds — on a collider without thickness a particle resting on its surface lies on
/// it only to round-off, and would otherwise be missed as often as found.
pub const ROUND_OFF_SLACK: Scalar = 1e-6;

/// How many times as far as a feature's contact point one of its corners may be pushed (see
/// [`Collider::resolve_faces`]).
const LEVER: Scalar = 2.0;

/// Gauss–Seidel sweeps of [`Collider::resolve_faces`] over the triangles it met, at most.
pub const FACE_SWEEPS: u32 = 32;

/// Particles a chunk of [`resolve_all`] holds on the team (about ten microseconds of work
/// against a sphere and the ground; smaller under Miri).
const RESOLVE_CHUNK: usize = crate::core::kernels::chunk_limit(512, 64);

/// A triangle resting on a collider, held at its contact point for one implicit step
/// ([`Collider::hold_faces`] with points, [`NormalHolds::faces`]): the velocity of the point
/// `Σ wⱼ vⱼ` along the normal is prescribed, and the corners are otherwise free, so the
/// triangle can tip about the contact (see [`crate::core::solve::rows`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaceHold {
    /// The corners.
    pub ids: [u32; 3],
    /// The contact point's barycentric weights.
    pub weights: [Scalar; 3],
    /// Which corners are free (not pinned, not prescribed).
    pub free: [bool; 3],
    /// The contact's unit normal.
    pub normal: Vector,
    /// A velocity whose component along the normal is the contact point's prescribed one for
    /// the step, and whose other components are the collider surface's there.
    pub velocity: Vector,
    /// The collider's friction coefficient.
    pub friction: Scalar,
}

/// Particles held along contact normals for one implicit step: Baraff and Witkin's
/// constraint filter (*Large steps in cloth simulation*, 1998, §5.3) with one or two
/// constrained directions per particle, each with its prescribed velocity along it. The raw
/// holds ([`Collider::hold_faces`], [`Collider::hold_faces_trial`]), and the filters the
/// linear solve takes
/// ([`LinearSolver::solve_filtered`](crate::core::solve::LinearSolver::solve_filtered)). Kept
/// by the integrator, so a step allocates nothing once the lists have grown.
#[derive(Clone, Debug, Default)]
pub struct NormalHolds {
    /// Each hold: the particle, the contact's unit normal, a velocity whose component along
    /// the normal is the particle's prescribed velocity along it for the step (and whose
    /// other components are the collider surface's there), and the contact's friction
    /// coefficient.
    pub raw: Vec<(u32, Vector, Vector, Scalar)>,
    /// Each particle held and the projector `S = I − Σ eₖeₖᵀ` onto the directions it stays
    /// free in (zero when it is held along three), by particle.
    pub filters: Vec<(u32, Matrix3)>,
    /// For each of [`NormalHolds::filters`]: the particle's first hold's normal and velocity,
    /// and the largest friction coefficient of its holds.
    pub contact: Vec<(Vector, Vector, Scalar)>,
    /// Friction at the holds found at the step's start, for the implicit solve: each
    /// particle, the hold's normal `n`, the bound `μ N` of its friction force (`N` the force
    /// pressing it on at the start) and the collider surface's velocity `vₚ`
    /// ([`NormalHolds::start_friction`]).
    pub drag: Vec<(u32, Vector, Scalar, Vector)>,
    /// For each of [`NormalHolds::drag`], where a linear step linearized its friction: the
    /// sliding at the step's start, the sliding there, and the force and its Jacobian with
    /// respect to the velocity ([`NormalHolds::linearize_friction`],
    /// [`NormalHolds::relinearize_leavers`]).
    pub linearized: Vec<(Vector, Vector, Vector, Matrix3)>,
    /// The positions a trial solve would end the step at (scratch).
    pub trial: Vec<Vector>,
    /// The last round's answer, kept while the next is solved (scratch).
    pub kept: Vec<Vector>,
    /// Triangles held at their contact points (those spanning a collider:
    /// [`Collider::hold_faces`]); their corners are then not in [`NormalHolds::raw`].
    pub faces: Vec<FaceHold>,
    /// The rows [`NormalHolds::settle`] made of [`NormalHolds::faces`], for the solve.
    pub rows: PointRows,
    /// Scratch of [`NormalHolds::start_friction`]: each particle's force left unbalanced
    /// by the triangles' contact forces, and the triangles' contact forces.
    pub(crate) pressed: Vec<Vector>,
    pub(crate) face_force: Vec<Scalar>,
    /// Whether the triangles' holds carry their collider's friction (one per corner,
    /// [`NormalHolds::one_friction_per_particle`]) or are frictionless; the particles' own
    /// holds carry it either way. Linearly implicit Euler sets it; backward Euler leaves it
    /// off (docs/BENCHMARKS.md, "tet bodies slide on colliders").
    pub face_friction: bool,
}

impl NormalHolds {
    /// Directions of one particle within this of the span of those already held (|sin|
    /// below a quarter, 14.5°) are taken as the same direction.
    const DISTINCT: Scalar = 0.25;

    /// The least room [`NormalHolds::settle`] keeps for rows once a step holds a triangle
    /// at its point (about half a megabyte).
    const MIN_ROWS: usize = 1024;

    /// Room for the holds of `n` particles (two raw holds each), so that steps allocate
    /// nothing as contacts come and go; grows only.
    pub fn reserve_for(&mut self, n: usize) {
        use crate::core::room;
        room(&mut self.raw, 2 * n);
        room(&mut self.drag, 2 * n);
        room(&mut self.linearized, 2 * n);
        room(&mut self.filters, n);
        room(&mut self.contact, n);
        room(&mut self.trial, n);
        room(&mut self.kept, n);
        room(&mut self.faces, 2 * n);
        room(&mut self.face_force, 2 * n);
        room(&mut self.pressed, n);
    }

    /// Forgets the last step's holds.
    pub fn clear(&mut self) {
        self.raw.clear();
        self.filters.clear();
        self.contact.clear();
        self.drag.clear();
        self.linearized.clear();
        self.faces.clear();
        self.rows.clear();
    }

    /// The sliding speed (m/s) below which friction is smoothed to zero at rest (Li et al.
    /// 2020, *Incremental Potential Contact*, §5: `f₁(x) = 2x/ε − x²/ε²` below `ε`, 1 above):
    /// a particle held by static friction creeps slower than this.
    pub const STATIC_SPEED: Scalar = 1e-3;

    /// Friction for the holds in [`NormalHolds::raw`] (those found at the step's start):
    /// a hold of normal `n`, friction coefficient `μ`, on a particle pressed onto the
    /// collider by `N = max(−p · n, 0)` (`p = press(i)`, its force at the step's start),
    /// gets the force `−μ N f₁(|u|) u/|u|` of its sliding `u = (I − n nᵀ)(v − vₚ)` across
    /// the normal (Coulomb's, smoothed below [`NormalHolds::STATIC_SPEED`]; the normal force
    /// and the normal lagged from the start, as Li et al. 2020 lag them).
    ///
    /// A triangle held at its contact point ([`NormalHolds::faces`]) has Coulomb's friction
    /// there, pressed by its contact force `Λ ≥ 0`: the forces that balance its free corners'
    /// pushes onto the collider best (least squares over all the triangles, `Σₖ wₖⱼ Λₖ nₖ`
    /// against `−pⱼ` at each corner `j`, by projected Gauss–Seidel). Each corner gets the
    /// drag of its share, `μ wⱼ Λ` (as one body sliding, the triangle's corners together get
    /// `μ Λ`). A corner with a hold of its own and friction takes that one alone.
    pub fn start_friction(&mut self, press: impl Fn(usize) -> Vector) {
        self.drag.clear();
        for &(i, n, vp, mu) in &self.raw {
            let bound = mu * (-press(i as usize).dot(n)).max(0.0);
            if bound > 0.0 && bound.is_finite() {
                self.drag.push((i, n, bound, vp));
            }
        }
        if !self.faces.iter().any(|f| f.friction > 0.0) {
            return;
        }
        let top = self
            .faces
            .iter()
            .flat_map(|f| f.ids)
            .max()
            .map_or(0, |i| i as usize + 1);
        if self.pressed.len() < top {
            self.pressed.resize(top, Vector::ZERO);
        }
        for f in &self.faces {
            for (k, &i) in f.ids.iter().enumerate() {
                if f.free[k] {
                    self.pressed[i as usize] = press(i as usize);
                }
            }
        }
        self.face_force.clear();
        self.face_force.resize(self.faces.len(), 0.0);
        for _ in 0..Self::FORCE_SWEEPS {
            for (f, lam) in self.faces.iter().zip(&mut self.face_force) {
                let (mut num, mut den) = (0.0, 0.0);
                for k in 0..3 {
                    if f.free[k] {
                        num += f.weights[k] * f.normal.dot(self.pressed[f.ids[k] as usize]);
                        den += f.weights[k] * f.weights[k];
                    }
                }
                if den <= 0.0 {
                    continue;
                }
                let next = (*lam - num / den).max(0.0);
                let d = next - *lam;
                *lam = next;
                for k in 0..3 {
                    if f.free[k] {
                        self.pressed[f.ids[k] as usize] += f.normal * (f.weights[k] * d);
                    }
                }
            }
        }
        // Corners with friction of their own: marked by a non-finite force left.
        let own = Vector::splat(Scalar::INFINITY);
        for d in &self.drag {
            if let Some(p) = self.pressed.get_mut(d.0 as usize) {
                *p = own;
            }
        }
        for (f, &lam) in self.faces.iter().zip(&self.face_force) {
            if !(f.friction > 0.0 && lam > 0.0 && lam.is_finite()) {
                continue;
            }
            for k in 0..3 {
                let i = f.ids[k];
                let bound = f.friction * f.weights[k] * lam;
                if f.free[k] && bound > 0.0 && self.pressed[i as usize] != own {
                    self.drag.push((i, f.normal, bound, f.velocity));
                }
            }
        }
    }

    /// Sweeps of [`NormalHolds::start_friction`]'s fit of the triangles' contact forces.
    const FORCE_SWEEPS: usize = 16;

    /// A hold's sliding at velocity `v`: `u = (I − n nᵀ)(v − vₚ)`, its length, and the
    /// projector `I − n nᵀ`.
    fn sliding(n: Vector, vp: Vector, v: Vector) -> (Vector, Scalar, Matrix3) {
        let p = Matrix3::IDENTITY - Matrix3::from_cols(n * n.x, n * n.y, n * n.z);
        let u = p * (v - vp);
        (u, u.length(), p)
    }

    /// Coulomb's force on a sliding `u` of length `x`, bounded by `bound` and smoothed below
    /// [`NormalHolds::STATIC_SPEED`], and `f₁` and `f₁'` there (`None` at rest, where the
    /// force is `−2 bound u / ε`, the limit of `f₁(x)/x`).
    fn friction_force(u: Vector, x: Scalar, bound: Scalar) -> (Vector, Option<(Scalar, Scalar)>) {
        let eps = Self::STATIC_SPEED;
        if x < eps * 1e-3 {
            return (-u * (2.0 * bound / eps), None);
        }
        let (f1, df1) = if x < eps {
            (
                2.0 * x / eps - x * x / (eps * eps),
                2.0 / eps - 2.0 * x / (eps * eps),
            )
        } else {
            (1.0, 0.0)
        };
        (-(u / x) * (bound * f1), Some((f1, df1)))
    }

    /// One hold's friction at velocity `v`: its force, and its Jacobian with respect to `v`
    /// (symmetric, negative semi-definite), as [`NormalHolds::start_friction`] gives them.
    fn friction_at(n: Vector, bound: Scalar, vp: Vector, v: Vector) -> (Vector, Matrix3) {
        let (u, x, p) = Self::sliding(n, vp, v);
        Self::friction_of(u, x, p, bound)
    }

    /// [`NormalHolds::friction_at`] of a sliding `u` of length `x` already measured, with the
    /// projector `p` across its normal ([`NormalHolds::sliding`]).
    fn friction_of(u: Vector, x: Scalar, p: Matrix3, bound: Scalar) -> (Vector, Matrix3) {
        let (force, slope) = Self::friction_force(u, x, bound);
        let Some((f1, df1)) = slope else {
            return (force, p * (-2.0 * bound / Self::STATIC_SPEED));
        };
        let t = u / x;
        let tt = Matrix3::from_cols(t * t.x, t * t.y, t * t.z);
        (force, (tt * df1 + (p - tt) * (f1 / x)) * -bound)
    }

    /// The holds' friction as backward Euler's dissipation potential, `Σ μ N f₀(|uᵢ|)`
    /// (`f₀' = f₁`, `f₀(0) = ε/3`), its gradient times `scale` added to `g`.
    pub fn friction_potential(&self, v: &[Vector], scale: Scalar, g: Option<&mut [Vector]>) -> f64 {
        let eps = Self::STATIC_SPEED;
        let mut r = 0.0f64;
        let mut g = g;
        for &(i, n, bound, vp) in &self.drag {
            let i = i as usize;
            let (u, x, _) = Self::sliding(n, vp, v[i]);
            let f0 = if x < eps {
                x * x / eps - x * x * x / (3.0 * eps * eps) + eps / 3.0
            } else {
                x
            };
            r += (bound * f0) as f64;
            if let Some(g) = g.as_deref_mut() {
                g[i] -= Self::friction_force(u, x, bound).0 * scale;
            }
        }
        r
    }

    /// The Hessian of [`NormalHolds::friction_potential`] at `v`, times `scale`, onto the
    /// diagonal blocks `diag`.
    pub fn friction_hessian(&self, v: &[Vector], scale: Scalar, diag: &mut [Matrix3]) {
        for &(i, n, bound, vp) in &self.drag {
            let i = i as usize;
            let (_, j) = Self::friction_at(n, bound, vp, v[i]);
            diag[i] -= j * scale;
        }
    }

    /// A linear step's friction: each hold's force `F` of [`NormalHolds::drag`] (the
    /// gradient of [`NormalHolds::friction_potential`]) linearized at the velocities `v0` of
    /// the step's start, as the damping is: `scale F(v₀)` added to the right-hand side `rhs`
    /// of the system in `Δv = v − v₀` and `−scale ∂F/∂v` to its diagonal blocks `diag`
    /// (symmetric positive semi-definite). Remembers where ([`NormalHolds::linearized`]).
    pub fn linearize_friction(
        &mut self,
        v0: &[Vector],
        scale: Scalar,
        diag: &mut [Matrix3],
        rhs: &mut [Vector],
    ) {
        self.linearized.clear();
        for &(i, n, bound, vp) in &self.drag {
            let i = i as usize;
            let (u, x, p) = Self::sliding(n, vp, v0[i]);
            let (force, jacobian) = Self::friction_of(u, x, p, bound);
            rhs[i] += force * scale;
            diag[i] -= jacobian * scale;
            self.linearized.push((u, u, force, jacobian));
        }
    }

    /// After a solve of the system [`NormalHolds::linearize_friction`] made (`vel(i)`:
    /// particle `i`'s velocity at the step's end): linearizes again the friction of each
    /// hold whose solve left the smoothing zone `ε` = [`NormalHolds::STATIC_SPEED`] on the
    /// other side than where it was linearized (one more Newton iteration for those, Li et
    /// al. 2020, §5), replacing its terms in `diag` and `rhs`:
    /// - sliding where it was linearized, and reversed by the solve: along a sliding faster
    ///   than `ε` the linearized friction is Coulomb's constant force, and a reversed sliding
    ///   means it would have stopped the particle within the step. Linearized about rest, as
    ///   the drag `−μ N u / ε` (the secant of the smoothed friction over `ε`, so its force
    ///   stays within `μ N` while `|u| ≤ ε`; a drag cannot reverse a sliding. The tangent
    ///   there, `2 μ N / ε`, held particles against up to twice Coulomb's force: cloths
    ///   draped on a sphere came to rest at 1.03 of the cone);
    /// - within `ε` where it was linearized, and sliding faster than `ε` at the end: the drag
    ///   about rest held it with more than Coulomb's force. Linearized at the end's velocity,
    ///   where the friction is Coulomb's `μ N` against that sliding. (Without it the start of
    ///   every slide was a step late, and in `f64` a cloth draped on a sphere slid in
    ///   stick–slip events for seconds.)
    ///
    /// Returns true when it changed any, for the caller to solve again.
    pub fn relinearize_leavers(
        &mut self,
        vel: impl Fn(usize) -> Vector,
        scale: Scalar,
        diag: &mut [Matrix3],
        rhs: &mut [Vector],
    ) -> bool {
        let mut any = false;
        let eps = Self::STATIC_SPEED;
        for (&(i, n, bound, vp), at) in self.drag.iter().zip(&mut self.linearized) {
            let i = i as usize;
            let (u0, uw, force_w, jacobian_w) = *at;
            let (u, x, p) = Self::sliding(n, vp, vel(i));
            let xw = uw.length();
            let next = if xw >= eps * 1e-3 && u.dot(uw) < 0.0 {
                (u0, Vector::ZERO, Vector::ZERO, p * (-bound / eps))
            } else if xw < eps && x > eps {
                let (force, jacobian) = Self::friction_of(u, x, p, bound);
                (u0, u, force, jacobian)
            } else {
                continue;
            };
            // `F(w) + J_w (v − w)` in `Δv = v − v₀`: `F(w) + J_w (u₀ − u_w) + J_w Δv` (`u₀ −
            // u_w` is `v₀ − w` across the normal; `J_w` sees nothing along it). The last
            // linearization's terms out, the new one's in.
            let old = force_w + jacobian_w * (u0 - uw);
            let new = next.2 + next.3 * (u0 - next.1);
            rhs[i] += (new - old) * scale;
            diag[i] += (jacobian_w - next.3) * scale;
            *at = next;
            any = true;
        }
        any
    }

    /// Coulomb friction of the holds' impacts, on the step's velocities `v` (from `v0` at
    /// the step's start): a held particle whose velocity along its first normal the step
    /// raised towards the prescribed one by `Δvₙ` (it was approaching the collider faster)
    /// loses up to `μ Δvₙ` of its velocity across the normals relative to the collider's
    /// surface, all of it when that is smaller: the rule of the contact after the step
    /// ([`Collider::resolve`]), for the impulse the holds gave in place of its.
    pub fn impact_friction(&self, v0: &[Vector], v: &mut [Vector]) {
        for (&(i, s), &(n, vp, mu)) in self.filters.iter().zip(&self.contact) {
            let i = i as usize;
            let dvn = (vp - v0[i]).dot(n).min((v[i] - v0[i]).dot(n));
            if !(mu > 0.0 && dvn > 0.0) {
                continue;
            }
            let u = s * (v[i] - vp);
            let ul = u.length();
            if ul > 0.0 {
                v[i] -= u * (mu * dvn / ul).min(1.0);
            }
        }
    }

    /// The triangles' holds `raw[from..]` keep their collider's friction only where the step
    /// gives triangles friction ([`NormalHolds::face_friction`]); otherwise it is set to zero
    /// (the triangles held at their contact points' too).
    pub fn face_friction_from(&mut self, from: usize) {
        if self.face_friction {
            return;
        }
        if let Some(raw) = self.raw.get_mut(from..) {
            for h in raw {
                h.3 = 0.0;
            }
        }
        for f in &mut self.faces {
            f.friction = 0.0;
        }
    }

    /// Leaves one friction coefficient per particle among the holds `raw[from..]` (those one
    /// collider pushed): the others' are set to zero. A particle that is the corner of
    /// several triangles resting on the collider, or rests on it itself as well, gets a hold
    /// for each, but touches the collider once, and [`NormalHolds::start_friction`] would
    /// give it Coulomb's force once a hold. The holds are sorted by particle, then by normal
    /// (as [`NormalHolds::settle`] sorts them): the friction is the first normal's, whatever
    /// order the triangles came in.
    pub fn one_friction_per_particle(&mut self, from: usize) {
        let Some(raw) = self.raw.get_mut(from..) else {
            return;
        };
        raw.sort_unstable_by(|a, b| Self::order(a).cmp(&Self::order(b)));
        let mut last = None;
        for h in raw {
            if last == Some(h.0) {
                h.3 = 0.0;
            } else {
                last = Some(h.0);
            }
        }
    }

    /// The order of [`NormalHolds::settle`]: by particle, then by normal (bitwise), then by
    /// friction coefficient.
    fn order(h: &(u32, Vector, Vector, Scalar)) -> (u32, [u64; 3], u64) {
        (
            h.0,
            h.1.to_array().map(|c| c.to_bits() as u64),
            h.3.to_bits() as u64,
        )
    }

    /// Turns [`NormalHolds::raw`] into [`NormalHolds::filters`] and writes each held
    /// particle's prescribed part into a solve's starting guess `x`, which the filtered
    /// solve keeps: each particle's normals made orthonormal (Gram–Schmidt, in a fixed
    /// order), its guess along them `vₚ − base` with `vₚ` its first hold's velocity. `base` is
    /// the particles' velocities when the solve's unknown is a change of velocity (linearly
    /// implicit Euler's `Δv`), `None` when it is the velocity itself.
    pub fn settle(&mut self, base: Option<&[Vector]>, x: &mut [Vector]) {
        self.filters.clear();
        self.contact.clear();
        // By particle, then by normal: the same list gives the same filters, whatever order
        // the colliders and faces pushed them in.
        self.raw
            .sort_unstable_by(|a, b| Self::order(a).cmp(&Self::order(b)));
        let mut k = 0;
        while k < self.raw.len() {
            let (i, first, vp, _) = self.raw[k];
            let mut mu: Scalar = 0.0;
            let mut e: [Vector; 3] = [Vector::ZERO; 3];
            let mut rank = 0;
            while k < self.raw.len() && self.raw[k].0 == i {
                let nrm = self.raw[k].1;
                mu = mu.max(self.raw[k].3);
                k += 1;
                if rank == 3 {
                    continue;
                }
                let u = e[..rank].iter().fold(nrm, |u, ek| u - *ek * ek.dot(nrm));
                let len = u.length();
                if len > Self::DISTINCT {
                    e[rank] = u / len;
                    rank += 1;
                }
            }
            let i = i as usize;
            let outer = |d: Vector| Matrix3::from_cols(d * d.x, d * d.y, d * d.z);
            let held = e[..rank].iter().fold(Matrix3::ZERO, |m, &d| m + outer(d));
            let s = Matrix3::IDENTITY - held;
            let target = vp - base.map_or(Vector::ZERO, |b| b[i]);
            x[i] = s * x[i] + held * target;
            self.filters.push((i as u32, s));
            self.contact.push((first, vp, mu));
        }
        // The triangles held at their contact points: `Σ wⱼ n · vⱼ = n · v_c` at the step's
        // end, on the free corners' unknowns (the others' end velocities known). Room for
        // four times as many rows as there are triangles now, and never less than
        // `MIN_ROWS` once there are any: the rows of a body resting on a collider come and
        // go without allocating, and the room stays a few times its contact, not its size.
        // (Four times alone let a cloth grow the lists long after its landing, when its
        // spanning triangles first outnumbered four times those of any step before: on a
        // rod 90 frames on in `f64`, and 152 triangles on a 2 cm bar in a second drop.)
        self.rows.clear();
        if !self.faces.is_empty() {
            self.rows
                .reserve_for((4 * self.faces.len()).max(Self::MIN_ROWS));
        }
        for f in &self.faces {
            let n = f.normal;
            let mut target = n.dot(f.velocity);
            let mut coef = [Vector::ZERO; 3];
            for (k, c) in coef.iter_mut().enumerate() {
                let (i, w) = (f.ids[k] as usize, f.weights[k]);
                if let Some(b) = base {
                    target -= w * n.dot(b[i]);
                }
                if f.free[k] {
                    *c = n * w;
                } else {
                    target -= w * n.dot(x[i]);
                }
            }
            if coef.iter().any(|c| *c != Vector::ZERO) {
                self.rows.push(f.ids, coef, target);
            }
        }
        self.rows.factor(&self.filters, x);
    }
}

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

    /// The same box collider answered by parry's queries, as any shape without queries of
    /// its own is (its box and bounding sphere kept for the clear test).
    fn as_general(cuboid: &Collider) -> Collider {
        let Fast::Cuboid(half) = cuboid.fast else {
            panic!("a box collider");
        };
        let mut general = cuboid.clone();
        general.fast = Fast::General {
            mins: -half,
            maxs: half,
            centre: glam::Vec3::ZERO,
            radius: half.length(),
            hull: None,
        };
        general
    }

    /// The distance from `p` to a convex hull (parry's `convex_hull` of its points: vertices
    /// and triangles), negative inside, by brute force: the nearest of every hull triangle's
    /// nearest points (parry's point–triangle projection), the sign from the planes of the
    /// triangles. A reference apart from [`HullPlanes::foot`] and from parry's GJK.
    fn hull_distance(hull: &(Vec<glam::Vec3>, Vec<[u32; 3]>), p: glam::Vec3) -> (f32, glam::Vec3) {
        use parry3d::query::PointQuery;
        let (v, tris) = hull;
        let centroid = v.iter().copied().sum::<glam::Vec3>() / v.len() as f32;
        let (mut best, mut foot, mut outside) = (f32::MAX, p, false);
        for t in tris {
            let tri =
                parry3d::shape::Triangle::new(v[t[0] as usize], v[t[1] as usize], v[t[2] as usize]);
            let q = tri.project_local_point(p, false).point;
            if (q - p).length() < best {
                (best, foot) = ((q - p).length(), q);
            }
            let n = (tri.b - tri.a).cross(tri.c - tri.a);
            let n = if n.dot(tri.a - centroid) < 0.0 { -n } else { n };
            outside |= n.dot(p - tri.a) > 0.0;
        }
        (if outside { best } else { -best }, foot)
    }

    /// A random triangle of `mesh` (its corners) and a point uniformly in it, from `rnd`'s
    /// numbers in `[-1, 1]`: the triangle, then the point's two coordinates (folded into the
    /// triangle where they sum past 1).
    fn random_point_on(
        mesh: &(Vec<glam::Vec3>, Vec<[u32; 3]>),
        rnd: &mut impl FnMut() -> f32,
    ) -> ([glam::Vec3; 3], glam::Vec3) {
        let (v, tris) = mesh;
        let pick = ((rnd().abs() * tris.len() as f32) as usize).min(tris.len() - 1);
        let [p0, p1, p2] = tris[pick].map(|i| v[i as usize]);
        let (r0, r1) = (rnd().abs(), rnd().abs());
        let (r0, r1) = if r0 + r1 > 1.0 {
            (1.0 - r0, 1.0 - r1)
        } else {
            (r0, r1)
        };
        ([p0, p1, p2], p0 + (p1 - p0) * r0 + (p2 - p0) * r1)
    }

    /// The distance between triangle `t` and a convex hull (as [`hull_distance`] takes it),
    /// by brute force in `f64`: the least over the hull's triangles of the closest points of
    /// each edge of either triangle against the other (`triangle_segment_closest`: two
    /// disjoint triangles are nearest at a point of an edge of one); zero where an edge
    /// crosses a triangle.
    fn hull_triangle_distance(hull: &(Vec<glam::Vec3>, Vec<[u32; 3]>), t: [glam::Vec3; 3]) -> f64 {
        let (v, tris) = hull;
        let t = t.map(|p| p.as_dvec3());
        let mut best = f64::MAX;
        for h in tris {
            let h = h.map(|i| v[i as usize].as_dvec3());
            for (a, b, other) in (0..3)
                .map(|e| (t[e], t[(e + 1) % 3], h))
                .chain((0..3).map(|e| (h[e], h[(e + 1) % 3], t)))
            {
                best = best.min(match triangle_segment_closest(other, a, b) {
                    Some((p, q)) => p.distance(q),
                    None => 0.0,
                });
            }
        }
        best
    }

    /// A convex polyhedron's distance to a triangle by its own triangles' planes
    /// ([`HullPlanes::triangle`]), on twenty random hulls of 100 points on ellipsoids (a
    /// rounded prop's hull) and random small triangles near them, against the brute-force
    /// distance ([`hull_triangle_distance`]): what it settles is the reference's distance,
    /// at a corner of the triangle that far from the hull; what it calls out of reach is;
    /// it settles at least 30 % of the triangles within reach (43 % here; the others span
    /// an edge of the hull and are nearest there), or it would spare nothing; and its walk
    /// finds at least 99 % of those out of reach (1,941 of 1,954 here, as many as a scan of
    /// every plane found: the rest are nearest at an edge, where no plane is that far out).
    /// Making every triangle's distance its plane's (as if the corner's foot always fell in
    /// that plane's triangle) fails it, and so does a walk that never leaves its start.
    /// Tolerance as in `a_hulls_planes_answer_as_the_brute_force_distance`.
    #[test]
    fn a_hulls_planes_settle_a_triangles_distance_as_brute_force() {
        let mut rng = crate::math::test_rng(0x5851_f42d_4c95_7f2du64);
        let mut rnd = move || rng() as f32;
        let reach = 0.02f32;
        let (mut settled, mut near, mut far, mut beyond) = (0, 0, 0, 0);
        for _ in 0..20 {
            let size = 0.1 + 0.4 * rnd().abs();
            // A rounded prop's hull: points on an ellipsoid.
            let axes = glam::Vec3::new(1.0, 0.4 + 0.6 * rnd().abs(), 0.7 + 0.3 * rnd().abs());
            let points: Vec<glam::Vec3> = (0..100)
                .map(|_| {
                    glam::Vec3::new(rnd(), rnd(), rnd()).normalize_or(glam::Vec3::X) * axes * size
                })
                .collect();
            let shape = SharedShape::convex_hull(&points).expect("random points span a volume");
            let planes = HullPlanes::of(&shape).expect("a hull's triangles");
            let reference = parry3d::transformation::convex_hull(&points);
            let tol = 2e-5 * size;
            for _ in 0..200 {
                // A cell of a cloth lying on or over the hull: a point up to 4 cm out from
                // a random point of one of its triangles, and a small triangle about it
                // along that triangle, tilted by up to a millimetre at its corners.
                let v = &reference.0;
                let ([p0, p1, p2], on) = random_point_on(&reference, &mut rnd);
                let normal = (p1 - p0).cross(p2 - p0).normalize();
                let normal = if normal
                    .dot(p0 - v.iter().copied().sum::<glam::Vec3>() / v.len() as f32)
                    < 0.0
                {
                    -normal
                } else {
                    normal
                };
                let centre = on + normal * (0.04 * rnd().abs());
                let cell = 0.01 + 0.02 * rnd().abs();
                let (u, w) = normal.any_orthonormal_pair();
                let t = [0.0f32, 2.1, 4.2].map(|a| {
                    centre + (u * a.cos() + w * a.sin()) * cell + normal * (0.001 * rnd())
                });
                let dist = hull_triangle_distance(&reference, t) as f32;
                let within = dist > 0.0 && dist < reach;
                near += within as usize;
                beyond += (dist >= reach) as usize;
                match planes.triangle(t, reach) {
                    Ok(None) => {
                        far += 1;
                        assert!(dist >= reach - tol, "{dist} called out of reach");
                    }
                    Ok(Some((corner, normal, g))) => {
                        settled += within as usize;
                        assert!((g - dist).abs() <= tol, "{g} against {dist}");
                        let (d, nearest) = hull_distance(&reference, t[corner]);
                        assert!((d - dist).abs() <= tol, "its corner {d} from the hull");
                        assert!(normal.dot((t[corner] - nearest) / d) > 1.0 - 1e-4);
                    }
                    Err(_) => {}
                }
            }
        }
        println!(
            "settled {settled} of {near} triangles apart within reach; {far} of {beyond} out of \
             reach"
        );
        assert!(
            settled * 10 >= near * 3 && near > 500 && far * 100 >= beyond * 99 && far > 500,
            "{settled} of {near}, {far} of {beyond} far"
        );
    }

    /// A cloth triangle's contact with a triangle mesh (`face_contact` on parry's `TriMesh`),
    /// and with a convex hull of the same points (parry's `ConvexPolyhedron`): on ten random
    /// rough terrains (8 × 8 cells of 5 cm, heights up to ±2 cm) and ten random convex
    /// meshes (hull triangles of 100 points on ellipsoids, each also as a hull), 300
    /// cloth-like cells each (1–3 cm, up to 4 cm from a random point of the mesh, tilted at
    /// random), through a moved, turned collider: the distance is the brute-force distance
    /// over every triangle of the mesh (`hull_triangle_distance`, no hierarchy, no plane
    /// test), the point lies on the cloth triangle that far from the mesh and the normal
    /// points from the mesh's nearest point to it, to 2·10⁻⁵ of a metre (`f32` positions);
    /// out of reach where the reference is. Cells with a corner in a hull (by
    /// `hull_distance`) have a contact at a depth (parry's). On the hulls, the cells
    /// that no plane settles (the walk's `Err`) are counted: they take the exact pairs with
    /// the hull's triangles near them. Parry's GJK on two triangles, and on a triangle and
    /// the polyhedron, which this replaces, are up to millimetres off here (printed).
    #[test]
    fn a_meshs_and_a_hulls_triangles_meet_a_cloths_as_the_brute_force_distance() {
        let mut rng = crate::math::test_rng(0x1405_7b7e_f767_814fu64);
        let mut rnd = move || rng() as f32;
        let reach: Scalar = 0.03;
        // Compared, parry's worst error, and how many by more than 0.1 mm: meshes, hulls.
        let mut seen = [(0, 0.0f64, 0); 2];
        let (mut unsettled, mut met) = (0, 0);
        for case in 0..20 {
            let (v, tris) = if case % 2 == 0 {
                let n = 9;
                let v: Vec<glam::Vec3> = (0..n * n)
                    .map(|k| {
                        glam::Vec3::new((k % n) as f32 * 0.05, 0.02 * rnd(), (k / n) as f32 * 0.05)
                    })
                    .collect();
                let mut tris = vec![];
                for i in 0..n - 1 {
                    for j in 0..n - 1 {
                        let a = (i * n + j) as u32;
                        tris.push([a, a + n as u32, a + 1]);
                        tris.push([a + 1, a + n as u32, a + n as u32 + 1]);
                    }
                }
                (v, tris)
            } else {
                let axes = glam::Vec3::new(1.0, 0.4 + 0.6 * rnd().abs(), 0.7 + 0.3 * rnd().abs());
                let points: Vec<glam::Vec3> = (0..100)
                    .map(|_| {
                        glam::Vec3::new(rnd(), rnd(), rnd()).normalize_or(glam::Vec3::X)
                            * axes
                            * 0.2
                    })
                    .collect();
                parry3d::transformation::convex_hull(&points)
            };
            let rotation = Rot3::from_euler(glam::EulerRot::XYZ, rnd(), rnd(), rnd());
            let origin = Vector::new(0.4, -0.2, 0.1);
            let reference = (v.clone(), tris.clone());
            let cells: Vec<[glam::Vec3; 3]> = (0..300)
                .map(|_| {
                    let ([p0, p1, p2], on) = random_point_on(&reference, &mut rnd);
                    let up = (p1 - p0).cross(p2 - p0).normalize();
                    let centre = on + up * (0.04 * rnd());
                    let cell = 0.01 + 0.02 * rnd().abs();
                    let tilt = glam::Vec3::new(rnd(), rnd(), rnd()) * 0.5;
                    let (u, w) = (up + tilt).normalize().any_orthonormal_pair();
                    [0.0f32, 2.1, 4.2].map(|a| centre + (u * a.cos() + w * a.sin()) * cell)
                })
                .collect();
            let mut shapes = vec![(
                0,
                SharedShape::trimesh(v.clone(), tris.clone()).expect("a mesh"),
            )];
            if case % 2 == 1 {
                shapes.push((1, SharedShape::convex_hull(&v).expect("a hull")));
            }
            for (kind, shape) in shapes {
                let planes = HullPlanes::of(&shape);
                let with = Collider::new(
                    shape,
                    Motion::Fixed {
                        position: origin.to_array().map(|c| c as f64),
                    },
                    rotation,
                    ContactMaterial::default(),
                );
                let pose = with.pose(0.0);
                let shape_pose = Pose3::from_parts(pose.origin.to_f32(), pose.rotation);
                for &local in &cells {
                    let dist_ref = hull_triangle_distance(&reference, local);
                    let tri = local.map(|p| origin + (rotation * p).to_scalar());
                    let got = with.face_contact(&pose, &shape_pose, reach, tri);
                    if kind == 1 && local.iter().any(|p| hull_distance(&reference, *p).0 <= 0.0) {
                        // In the hull: a contact at a depth (parry's).
                        let depth = got.map(|(_, _, _, dist)| dist);
                        assert!(depth.is_some_and(|d| d <= 2e-5), "{depth:?} in the hull");
                        met += 1;
                        continue;
                    }
                    if dist_ref < 1e-4 {
                        continue;
                    }
                    let parry = with.face_contact_parry(&shape_pose, reach, tri, None);
                    match got {
                        None => assert!(dist_ref >= reach as f64 - 2e-5, "missed at {dist_ref}"),
                        Some((bary, point, n, dist)) => {
                            seen[kind].0 += 1;
                            if let Some(planes) = &planes {
                                unsettled +=
                                    usize::from(planes.triangle(local, reach as f32).is_err());
                            }
                            assert!(
                                (dist as f64 - dist_ref).abs() <= 2e-5,
                                "{dist} against {dist_ref}"
                            );
                            let on_tri = tri[0] * bary[0] + tri[1] * bary[1] + tri[2] * bary[2];
                            assert!(
                                (on_tri - point).length() <= 2e-5,
                                "{point} off the triangle"
                            );
                            let local_point = rotation.inverse() * (point - origin).to_f32();
                            // Unsigned: a terrain's sign means nothing.
                            let (d, nearest) = hull_distance(&reference, local_point);
                            let d = d.abs();
                            assert!((d as f64 - dist_ref).abs() <= 2e-5, "{d} from the mesh");
                            let expected = (rotation * ((local_point - nearest) / d)).to_scalar();
                            assert!(n.dot(expected) > 1.0 - 1e-3, "{n} against {expected}");
                            if let Some((_, _, _, pd)) = parry {
                                let off = (pd as f64 - dist_ref).abs();
                                seen[kind].1 = seen[kind].1.max(off);
                                seen[kind].2 += usize::from(off > 1e-4);
                            }
                        }
                    }
                }
            }
        }
        for (what, (compared, worst, off)) in ["meshes", "hulls"].iter().zip(seen) {
            println!(
                "{what}: {compared} compared; parry up to {worst} m off, {off} by more than \
                 0.1 mm"
            );
        }
        println!("hulls: {unsettled} compared that no plane settles; {met} in the hull");
        assert!(
            seen[0].0 >= 2_000 && seen[1].0 >= 1_000 && unsettled >= 200,
            "{seen:?}, {unsettled}"
        );
    }

    /// A convex polyhedron's support point by a walk along its edges ([`HullPlanes::support`])
    /// is its farthest vertex: on twenty random hulls (100 points on ellipsoids, and 40 in
    /// boxes, so that faces of many and of few vertices are both walked), along 500 random
    /// directions each and the cube map's own cell borders, it is as far along the
    /// direction as the farthest of every point (a scan apart from the walk), to `f32`
    /// round-off of the hull's size. And a cloth triangle's contact through the walk's
    /// support points is parry's own query's on the `ConvexPolyhedron` (the same GJK and EPA
    /// on the same support points; triangles as in
    /// `a_hulls_planes_settle_a_triangles_distance_as_brute_force`, within 4 cm, some
    /// crossing the hull), to 10⁻⁵ of the hull's size in distance and a thousandth in the
    /// normal's direction. A walk that stops at its start fails the first part.
    #[test]
    fn a_hulls_support_by_a_walk_is_its_farthest_vertex() {
        let mut rng = crate::math::test_rng(0x2545_f491_4f6c_dd1du64);
        let mut rnd = move || rng() as f32;
        let (mut walked, mut contacts) = (0, 0);
        for hull in 0..20 {
            let size = 0.1 + 0.4 * rnd().abs();
            let axes = glam::Vec3::new(1.0, 0.4 + 0.6 * rnd().abs(), 0.7 + 0.3 * rnd().abs());
            let points: Vec<glam::Vec3> = if hull % 2 == 0 {
                (0..100)
                    .map(|_| {
                        glam::Vec3::new(rnd(), rnd(), rnd()).normalize_or(glam::Vec3::X)
                            * axes
                            * size
                    })
                    .collect()
            } else {
                (0..40)
                    .map(|_| glam::Vec3::new(rnd(), rnd(), rnd()) * axes * size)
                    .collect()
            };
            let shape = SharedShape::convex_hull(&points).expect("random points span a volume");
            let planes = HullPlanes::of(&shape).expect("a hull's triangles");
            let tol = 1e-5 * size;
            let borders = [-1.0f32, -0.5, 0.0, 0.5, 1.0];
            let mut dirs: Vec<glam::Vec3> = (0..500)
                .map(|_| glam::Vec3::new(rnd(), rnd(), rnd()))
                .collect();
            for x in borders {
                for y in borders {
                    dirs.extend([
                        glam::Vec3::new(1.0, x, y),
                        glam::Vec3::new(x, -1.0, y),
                        glam::Vec3::new(x, y, 1.0),
                    ]);
                }
            }
            for d in dirs {
                let farthest = points.iter().map(|p| p.dot(d)).fold(f32::MIN, f32::max);
                let got = planes.support(d).dot(d);
                assert!(
                    (got - farthest).abs() <= tol * d.length(),
                    "{got} against {farthest} along {d}"
                );
                walked += 1;
            }
            let fast = Collider::new(
                shape,
                Motion::Fixed { position: [0.0; 3] },
                Rot3::IDENTITY,
                ContactMaterial::default(),
            );
            let (v, tris) = parry3d::transformation::convex_hull(&points);
            let centroid = v.iter().copied().sum::<glam::Vec3>() / v.len() as f32;
            for _ in 0..100 {
                let pick = ((rnd().abs() * tris.len() as f32) as usize).min(tris.len() - 1);
                let [p0, p1, p2] = tris[pick].map(|i| v[i as usize]);
                let on = (p0 + p1 + p2) / 3.0;
                let normal = (p1 - p0).cross(p2 - p0).normalize();
                let normal = if normal.dot(p0 - centroid) < 0.0 {
                    -normal
                } else {
                    normal
                };
                let centre = on + normal * (0.04 * rnd());
                let cell = 0.01 + 0.02 * rnd().abs();
                let (u, w) = normal.any_orthonormal_pair();
                let tri = [0.0f32, 2.1, 4.2].map(|a| {
                    (centre + (u * a.cos() + w * a.sin()) * cell + normal * (0.01 * rnd()))
                        .to_scalar()
                });
                let pose = Pose3::IDENTITY;
                let by_walk = fast.face_contact_parry(&pose, 0.05, tri, Some(&planes));
                let by_parry = fast.face_contact_parry(&pose, 0.05, tri, None);
                match (by_walk, by_parry) {
                    (Some((_, _, n, dist)), Some((_, _, m, expected))) => {
                        contacts += 1;
                        assert!(
                            (dist - expected).abs() <= tol as Scalar,
                            "{dist} against parry's {expected}"
                        );
                        assert!(n.dot(m) > 1.0 - 1e-3, "{n} against parry's {m}");
                    }
                    (None, None) => {}
                    (walk, parry) => panic!("{walk:?} against parry's {parry:?}"),
                }
            }
        }
        assert!(
            walked >= 10_000 && contacts >= 1_000,
            "{walked}, {contacts}"
        );
    }

    /// A convex polyhedron's queries by its own triangles ([`HullPlanes::foot`]), on twenty
    /// random hulls of 40 points, against the brute-force distance ([`hull_distance`]): for
    /// random points in and around each, the signed distance and the normal are the
    /// reference's, and so is the nearest point (outside near the hull, where it is one;
    /// inside, a point of the boundary). Through a tilted, moved collider, `contact` is the
    /// reference's nearest point pushed out by the thickness, and `swept_contact`'s contact
    /// on a path from outside the thickness (paths up to several thicknesses long) lies at
    /// the thickness, with no sample of the path before it within it. Making every foot
    /// its farthest plane's (as if it always fell in that triangle) fails it.
    ///
    /// Tolerances: 2·10⁻⁵ of the hull's size is `f32` round-off over a few operations on
    /// coordinates of its size. Parry's GJK projection onto a `ConvexPolyhedron`, which the
    /// planes replace, is farther off: up to 3.1 mm within 4 cm of these hulls (printed).
    #[test]
    fn a_hulls_planes_answer_as_the_brute_force_distance() {
        let mut rng = crate::math::test_rng(0x9e37_79b9_7f4a_7c15u64);
        let mut rnd = move || rng() as f32;
        let material = ContactMaterial {
            thickness: 0.02,
            ..Default::default()
        };
        let thick = material.thickness as Scalar;
        let (mut compared, mut grazes) = (0, 0);
        let (mut parry_worst, mut swept_worst): (f32, Scalar) = (0.0, 0.0);
        for _ in 0..20 {
            let size = 0.1 + 0.4 * rnd().abs();
            let squash = glam::Vec3::new(1.0, 0.3 + 0.7 * rnd().abs(), 1.0);
            let points: Vec<glam::Vec3> = (0..40)
                .map(|_| glam::Vec3::new(rnd(), rnd(), rnd()) * squash * size)
                .collect();
            let shape = SharedShape::convex_hull(&points).expect("random points span a volume");
            let planes = HullPlanes::of(&shape).expect("a hull's triangles");
            let reference = parry3d::transformation::convex_hull(&points);
            assert!(planes.len() >= 4);
            let tol = 2e-5 * size;
            for _ in 0..400 {
                let p = glam::Vec3::new(rnd(), rnd(), rnd()) * (size + 0.05);
                let (dist, nearest) = hull_distance(&reference, p);
                if dist.abs() < 0.04 {
                    let proj = shape.project_point(&Pose3::IDENTITY, p, false);
                    parry_worst = parry_worst.max(((proj.point - p).length() - dist.abs()).abs());
                }
                let HullFoot {
                    point,
                    normal,
                    signed,
                } = planes.foot(p, f32::INFINITY).expect("no bound");
                assert!((signed - dist).abs() <= tol, "{signed} against {dist}");
                // Outside, the nearest point is one (though far out it is
                // ill-conditioned: a foot δ aside is only δ²/2d farther, under
                // `f32`'s resolution of the distance); inside, any point of the
                // boundary at that depth is.
                if (0.0..0.04).contains(&dist) {
                    assert!(
                        (point - nearest).length() <= tol,
                        "{point} against {nearest}"
                    );
                } else if dist <= 0.0 {
                    assert!(hull_distance(&reference, point).0.abs() <= tol);
                }
                if dist > 1e-3 * size {
                    let n = (p - nearest) / dist;
                    assert!(normal.dot(n) > 1.0 - 1e-4, "{normal} against {n}");
                }
            }
            let rotation = Rot3::from_scaled_axis(glam::Vec3::new(0.4, -0.2, 0.7));
            let origin = Vector::new(0.3, -0.1, 0.2);
            let with = Collider::new(
                shape,
                Motion::Fixed {
                    position: [0.3, -0.1, 0.2],
                },
                rotation,
                material,
            );
            assert!(matches!(with.fast, Fast::General { hull: Some(_), .. }));
            let pose = with.pose(0.0);
            let h = 0.01;
            for _ in 0..400 {
                let local = glam::Vec3::new(rnd(), rnd(), rnd()) * (size + 0.05);
                let p = origin + (rotation * local).to_scalar();
                let v = Vector::new(rnd() as Scalar, rnd() as Scalar, rnd() as Scalar)
                    * (3.0 * thick / h);
                let (dist, nearest) = hull_distance(&reference, local);
                let dist = dist as Scalar;
                match with.contact(&pose, thick, p) {
                    Some((x, n)) => {
                        assert!(dist < thick + tol as Scalar, "{dist}");
                        if dist > 1e-3 * size as Scalar {
                            let expected_n =
                                (rotation * ((local - nearest) / dist as f32)).to_scalar();
                            let expected =
                                origin + (rotation * nearest).to_scalar() + expected_n * thick;
                            let off = (x - expected).length();
                            assert!(off <= 2.0 * tol as Scalar, "{off}");
                            assert!(n.dot(expected_n) > 1.0 - 1e-4);
                        }
                    }
                    None => assert!(dist > thick - tol as Scalar, "{dist}"),
                }
                // A path from outside the thickness: its first point within it, by the
                // reference's distance along 200 samples.
                let start = p - v * h;
                let local_at = |x: Vector| rotation.inverse() * (x - origin).to_f32();
                let d_start = hull_distance(&reference, local_at(start)).0 as Scalar;
                if d_start > thick {
                    let first = (0..=200).map(|k| k as Scalar / 200.0).find(|&s| {
                        (hull_distance(&reference, local_at(start + v * h * s)).0 as Scalar) < thick
                    });
                    match with.swept_contact(&pose, thick, h, p, v) {
                        Some((x, _)) => {
                            compared += 1;
                            let d = hull_distance(&reference, local_at(x)).0 as Scalar;
                            let s = (x - start).dot(v * h) / (v * h).length_squared();
                            swept_worst = swept_worst.max((d - thick).abs());
                            assert!(
                                (d - thick).abs() <= 2.0 * tol as Scalar,
                                "{d} from {d_start}"
                            );
                            // No sample before it within the thickness.
                            assert!(
                                first.is_none_or(|f| f >= s - 1.0 / 200.0),
                                "{first:?} before {s}"
                            );
                        }
                        None => grazes += first.is_some() as usize,
                    }
                }
            }
        }
        println!(
            "{compared} paths compared, {grazes} grazing; parry's GJK up to {parry_worst:e} off near the hull, \
             the swept contacts' distances up to {swept_worst:e} off the thickness"
        );
        assert!(
            compared > 300 && grazes * 50 <= compared,
            "{grazes} of {compared}"
        );
    }

    /// `Collider::clear` stands for `swept_contact` finding nothing: over random particles
    /// near a sphere (still, and moving), a tilted half-space, a tilted capsule, a tilted
    /// box, and general shapes — a tilted convex hull (still, and moving) and a non-convex
    /// triangle mesh (a tent of two slopes) — with paths up to several thicknesses long, no
    /// particle it calls clear has a contact, and it calls clear most of those far away (so
    /// the response loops skip them).
    #[test]
    fn a_particle_called_clear_has_no_contact() {
        let mut rng = crate::math::test_rng(0x2545_f491_4f6c_dd1du64);
        let mut rnd = move || rng() as Scalar;
        let material = ContactMaterial {
            thickness: 0.02,
            ..Default::default()
        };
        let tilt = Rot3::from_scaled_axis(glam::Vec3::new(0.3, 0.0, 0.2));
        let p3 = glam::Vec3::new;
        let hull = SharedShape::convex_hull(&[
            p3(0.2, 0.0, 0.0),
            p3(-0.1, 0.15, 0.05),
            p3(-0.1, -0.15, 0.1),
            p3(0.0, 0.05, -0.2),
            p3(0.05, -0.1, 0.15),
            p3(-0.15, 0.0, -0.1),
        ])
        .expect("a hull of six points in general position");
        let tent = SharedShape::trimesh(
            vec![
                p3(-0.3, 0.0, -0.2),
                p3(-0.3, 0.0, 0.2),
                p3(0.0, 0.2, -0.2),
                p3(0.0, 0.2, 0.2),
                p3(0.3, 0.0, -0.2),
                p3(0.3, 0.0, 0.2),
            ],
            vec![[0, 1, 3], [0, 3, 2], [2, 3, 5], [2, 5, 4]],
        )
        .expect("a tent of four triangles");
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
            Collider::new(
                SharedShape::capsule_y(0.25, 0.08),
                Motion::Fixed {
                    position: [0.1, 0.0, 0.1],
                },
                tilt,
                material,
            ),
            Collider::new(
                SharedShape::cuboid(0.25, 0.05, 0.15),
                Motion::Fixed {
                    position: [0.0, 0.1, -0.1],
                },
                tilt,
                material,
            ),
            Collider::new(
                hull.clone(),
                Motion::Fixed {
                    position: [-0.1, 0.0, 0.1],
                },
                tilt,
                material,
            ),
            Collider::new(
                hull,
                Motion::Linear {
                    start: [0.0; 3],
                    velocity: [-1.0, 2.0, 0.5],
                    t0: 0.0,
                },
                tilt,
                material,
            ),
            Collider::new(
                tent,
                Motion::Fixed {
                    position: [0.1, -0.1, 0.0],
                },
                tilt,
                material,
            ),
        ];
        assert!(matches!(colliders[5].fast, Fast::General { .. }));
        assert!(matches!(colliders[7].fast, Fast::General { .. }));
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

    /// A particle whose path in a step passes within the thickness of a collider and on
    /// (a cloth's particle falling past a rod's side while its neighbour stops on top) is
    /// stopped where its path first comes within the thickness, on the side it came from:
    /// over random straight paths longer than the thickness near a sphere, a tilted capsule,
    /// a tilted box and the same box as a convex hull (a general shape), each starting
    /// outside the thickness, a contact is found exactly when the path's nearest approach
    /// (sampled at 4,000 points, by each shape's distance written here: centre, axis
    /// segment, box's clamped local coordinates) is within the thickness; it lies on the
    /// path at the thickness from the shape, every sample before it farther, with the
    /// distance's gradient as its normal. Before, a path that missed the shape itself and
    /// ended outside the thickness had no contact (more than half of those found).
    #[test]
    fn a_particle_passing_within_the_thickness_stops_where_its_path_first_comes_that_near() {
        let mut rng = crate::math::test_rng(0x9e37_79b9_7f4a_7c15u64);
        let mut rnd = move || rng() as Scalar;
        let thick: Scalar = 0.02;
        let material = ContactMaterial {
            thickness: thick as f64,
            ..Default::default()
        };
        let tilt = Rot3::from_scaled_axis(glam::Vec3::new(0.3, 0.0, 0.2));
        let at = [0.1, 0.2, -0.1];
        let fixed = Motion::Fixed { position: at };
        let centre = Vector::new(at[0] as Scalar, at[1] as Scalar, at[2] as Scalar);
        let local = move |p: Vector| (tilt.inverse() * (p - centre).to_f32()).to_scalar();
        let box_distance = move |p: Vector| {
            let half = Vector::new(0.01, 0.2, 0.05);
            let q = local(p).abs() - half;
            q.max(Vector::ZERO).length() + q.x.max(q.y).max(q.z).min(0.0)
        };
        type Distance = Box<dyn Fn(Vector) -> Scalar>;
        let shapes: [(SharedShape, Distance); 4] = [
            (
                SharedShape::ball(0.05),
                Box::new(move |p: Vector| (p - centre).length() - 0.05),
            ),
            (
                SharedShape::capsule_y(0.25, 0.01),
                Box::new(move |p: Vector| {
                    let q = local(p);
                    let y = q.y.clamp(-0.25, 0.25);
                    (q - Vector::new(0.0, y, 0.0)).length() - 0.01
                }),
            ),
            (SharedShape::cuboid(0.01, 0.2, 0.05), Box::new(box_distance)),
            // The same box as a convex hull of its corners: a general shape, by conservative
            // advancement.
            (
                SharedShape::convex_hull(
                    &[-1.0f32, 1.0]
                        .into_iter()
                        .flat_map(|x| [-1.0f32, 1.0].into_iter().map(move |y| (x, y)))
                        .flat_map(|(x, y)| {
                            [-1.0f32, 1.0]
                                .into_iter()
                                .map(move |z| glam::Vec3::new(0.01 * x, 0.2 * y, 0.05 * z))
                        })
                        .collect::<Vec<_>>(),
                )
                .unwrap(),
                Box::new(box_distance),
            ),
        ];
        let h = 0.01;
        for (k, (shape, dist)) in shapes.into_iter().enumerate() {
            let rotation = if k == 0 { Rot3::IDENTITY } else { tilt };
            let c = Collider::new(shape, fixed, rotation, material);
            let pose = c.pose(0.0);
            let (mut met, mut passed_by) = (0, 0);
            for _ in 0..4_000 {
                let start = centre + Vector::new(rnd(), rnd(), rnd()) * 0.12;
                let travel = Vector::new(rnd(), rnd(), rnd()) * 0.15;
                if dist(start) <= 1.01 * thick || travel.length() <= thick {
                    continue;
                }
                let end = start + travel;
                let samples = 4_000;
                let path =
                    (0..=samples).map(|j| start + travel * (j as Scalar / samples as Scalar));
                let nearest = path.clone().map(&dist).fold(Scalar::INFINITY, Scalar::min);
                let hit = c.swept_contact(&pose, thick, h, end, travel / h);
                // Marginal paths, within a thousandth of the thickness, either way.
                let tol = 1e-3 * thick;
                if (nearest - thick).abs() < tol {
                    continue;
                }
                if nearest > thick {
                    assert!(
                        hit.is_none(),
                        "{k}: {start:?} by {travel:?}, {nearest} away: {hit:?}"
                    );
                    continue;
                }
                let shape_pose = Pose3::from_parts(pose.origin.to_f32(), pose.rotation);
                // The path as `swept_contact` takes it back from the end (the same bits).
                let back = (travel / h - Collider::surface_velocity(&pose, end)) * h;
                let met_at = c.first_within(&shape_pose, thick, end - back, back);
                // The contact is where the path first comes within the thickness.
                let Some((target, n)) = hit else {
                    panic!("{k}: {start:?} by {travel:?} came {nearest} near: no contact");
                };
                assert_eq!(Some((target, n)), met_at);
                met += 1;
                passed_by += usize::from(dist(end) > thick);
                // On the path, at the thickness (parry's casts against a capsule and a box
                // end within 10⁻⁵ m of it), and every sample of the path before it farther.
                let s = (target - start).dot(travel) / travel.length_squared();
                assert!(
                    (target - (start + travel * s)).length() < 1e-5 && (0.0..=1.0).contains(&s),
                    "{k}: {target:?} is off the path from {start:?} by {travel:?}"
                );
                assert!((dist(target) - thick).abs() < tol, "{k}: {}", dist(target));
                let earlier = path
                    .clone()
                    .take_while(|&q| (q - start).dot(travel) < s * travel.length_squared())
                    .map(&dist)
                    .fold(Scalar::INFINITY, Scalar::min);
                assert!(
                    earlier > thick - tol,
                    "{k}: {start:?} by {travel:?} came {earlier} near before {target:?}"
                );
                let e = 1e-5;
                let grad = Vector::new(
                    dist(target + Vector::X * e) - dist(target - Vector::X * e),
                    dist(target + Vector::Y * e) - dist(target - Vector::Y * e),
                    dist(target + Vector::Z * e) - dist(target - Vector::Z * e),
                ) / (2.0 * e);
                assert!(
                    (n - grad.normalize()).length() < 1e-2,
                    "{k}: normal {n:?}, the distance's gradient {grad:?}"
                );
            }
            println!("{k}: {met} paths met the thickness, {passed_by} ending outside it");
            assert!(
                met > 200 && 3 * passed_by > met,
                "{k}: {met} met, {passed_by} passed by"
            );
        }
    }

    /// [`Collider::needs_faces`]'s bound for a sphere: a triangle with edges at most `e`
    /// whose corners are at least `s = R + t` from the centre comes no nearer than
    /// `√(s² − e²/3)`. Over random triangles around the tight case (an equilateral one
    /// centred over the centre with its corners on the shell), none comes nearer, and some
    /// come within half a millimetre of it (of the 6 cm shell: the bound is nearly attained).
    #[test]
    fn a_triangle_with_its_corners_off_a_sphere_keeps_the_bound_needs_faces_takes() {
        let mut rng = crate::math::test_rng(0x9e37_79b9_7f4a_7c15u64);
        let mut rnd = move || rng();
        let (r, t) = (0.05f64, 0.01f64);
        let s = r + t;
        let mut tightest = f64::INFINITY;
        let mut kept = 0;
        for _ in 0..50_000 {
            let e = 0.02 + 0.08 * rnd().abs();
            let d = (s * s - e * e / 3.0).sqrt() * (1.0 + 0.02 * rnd());
            let n = glam::DVec3::new(rnd(), rnd(), rnd()).normalize();
            let u = n.any_orthonormal_vector();
            let w = n.cross(u);
            let turn = std::f64::consts::PI * rnd();
            let mut corner = |k: f64| {
                let a = turn + k * 2.0 * std::f64::consts::PI / 3.0;
                let jitter = glam::DVec3::new(rnd(), rnd(), rnd()) * (0.05 * e);
                n * d + (u * a.cos() + w * a.sin()) * (e / 3f64.sqrt()) + jitter
            };
            let tri = [corner(0.0), corner(1.0), corner(2.0)];
            let longest = (0..3)
                .map(|k| tri[k].distance(tri[(k + 1) % 3]))
                .fold(0.0, f64::max);
            if tri.iter().any(|c| c.length() < s) {
                continue;
            }
            kept += 1;
            let b = crate::core::self_contact::closest_on_triangle(
                glam::DVec3::ZERO,
                tri[0],
                tri[1],
                tri[2],
            );
            let q = tri[0] * b[0] + tri[1] * b[1] + tri[2] * b[2];
            let bound = (s * s - longest * longest / 3.0).max(0.0).sqrt();
            assert!(q.length() >= bound - 1e-12, "{} under {bound}", q.length());
            tightest = tightest.min(q.length() - bound);
        }
        assert!(
            kept > 1000 && tightest < 5e-4,
            "{kept} kept, tightest {tightest}"
        );
    }

    /// The triangles' impulses against a still collider never add kinetic energy (inelastic,
    /// friction within Coulomb's cone, each of the triangle's effective mass), and against a
    /// dynamic body they conserve momentum: what the particles gain, the body's exchange
    /// records as lost, and the particles' and the body's kinetic energy together never rise.
    /// Random triangles of random masses (some pinned) moving at random into a sphere and a
    /// box.
    #[test]
    fn face_impulses_keep_momentum_and_never_add_kinetic_energy() {
        let mut rng = crate::math::test_rng(0x1234_5678_9abc_def1u64);
        let mut rnd = move || rng() as Scalar;
        let material = ContactMaterial {
            thickness: 0.01,
            friction: 0.6,
            restitution: 0.0,
            ..Default::default()
        };
        let inertia = [Vector::X * 40.0, Vector::Y * 25.0, Vector::Z * 30.0];
        let shapes = [SharedShape::ball(0.1), SharedShape::cuboid(0.1, 0.05, 0.2)];
        let (mut pushed, mut near) = (0, vec![]);
        for shape in &shapes {
            for dynamic in [false, true] {
                for _ in 0..400 {
                    let mut c = Collider::new(
                        shape.clone(),
                        Motion::Fixed { position: [0.0; 3] },
                        Rot3::IDENTITY,
                        material,
                    );
                    if dynamic {
                        c = c.with_response(Response::new(2.0, inertia, 0.0));
                    }
                    // A triangle of 6–20 cm edges whose middle is within 12 cm of the centre.
                    let mid = Vector::new(rnd(), rnd(), rnd()) * 0.12;
                    let mut x: Vec<Vector> = (0..3)
                        .map(|_| mid + Vector::new(rnd(), rnd(), rnd()) * 0.1)
                        .collect();
                    let mut v: Vec<Vector> = x
                        .iter()
                        .map(|p| -*p * (5.0 * rnd().abs()) + Vector::new(rnd(), rnd(), rnd()))
                        .collect();
                    let w: Vec<Scalar> = (0..3)
                        .map(|_| {
                            if rnd() < -0.6 {
                                0.0
                            } else {
                                1.0 / (0.01 + 0.1 * rnd().abs())
                            }
                        })
                        .collect();
                    let ke = |v: &[Vector]| -> f64 {
                        (0..3)
                            .filter(|&i| w[i] > 0.0)
                            .map(|i| 0.5 * (v[i].length_squared() / w[i]) as f64)
                            .sum()
                    };
                    let momentum = |v: &[Vector]| -> Vector {
                        (0..3).filter(|&i| w[i] > 0.0).map(|i| v[i] / w[i]).sum()
                    };
                    // A pinned corner is still (a moving one may drive the others, as a
                    // moving collider does).
                    for i in 0..3 {
                        if w[i] == 0.0 {
                            v[i] = Vector::ZERO;
                        }
                    }
                    let (k0, p0) = (ke(&v), momentum(&v));
                    let x0: Vec<Vector> = x.iter().zip(&v).map(|(&x, &v)| x - v * 0.01).collect();
                    pushed += c.resolve_faces(
                        0.0,
                        0.01,
                        &[[0, 1, 2]],
                        1.0,
                        &x0,
                        &mut x,
                        &mut v,
                        &w,
                        &mut near,
                    );
                    let (k1, p1) = (ke(&v), momentum(&v));
                    assert!(x.iter().chain(&v).all(|p| p.is_finite()));
                    let (body_ke, lost) = match &c.response {
                        Some(r) => {
                            let ex = r.exchange();
                            let l = ex.angular;
                            let ke = 0.5 * (ex.linear.length_squared() * r.inv_mass) as f64
                                + 0.5 * l.dot(r.inv_inertia_mul(l)) as f64;
                            (ke, ex.linear)
                        }
                        None => (0.0, Vector::ZERO),
                    };
                    assert!(
                        k1 + body_ke <= k0 * (1.0 + 1e-5) + 1e-9,
                        "kinetic energy {k0} -> {k1} + body {body_ke}"
                    );
                    // A pinned corner takes its share of the impulse (infinitely heavy).
                    if dynamic && w.iter().all(|&w| w > 0.0) {
                        let gap = (p1 - p0 + lost).length() as f64;
                        assert!(
                            gap <= 1e-4 * (1.0 + p0.length() as f64),
                            "momentum off by {gap}"
                        );
                    }
                }
            }
        }
        assert!(pushed > 400, "only {pushed} triangles met the colliders");
    }

    /// Hostile corners (not finite, or astronomically far) never reach parry's queries, which
    /// assert on them: the triangles are left alone, nothing panics, nothing finite turns NaN.
    #[test]
    fn far_or_non_finite_corners_are_left_alone() {
        let shapes = [
            SharedShape::ball(0.1),
            SharedShape::cuboid(0.1, 0.05, 0.2),
            SharedShape::capsule_y(0.3, 0.01),
        ];
        let bad = [
            Scalar::NAN,
            Scalar::INFINITY,
            -Scalar::INFINITY,
            1e19,
            -3e30,
        ];
        let mut near = vec![];
        for shape in &shapes {
            let c = Collider::new(
                shape.clone(),
                Motion::Fixed { position: [0.0; 3] },
                Rot3::IDENTITY,
                ContactMaterial::default(),
            );
            for &b in &bad {
                for k in 0..3 {
                    let mut x = vec![
                        Vector::new(-0.05, 0.0, -0.05),
                        Vector::new(0.05, 0.0, -0.05),
                        Vector::new(0.0, 0.0, 0.05),
                    ];
                    x[k].y = b;
                    let x0 = x.clone();
                    let mut v = vec![Vector::new(0.0, -1.0, 0.0); 3];
                    let w = [1.0; 3];
                    let faces = [[0, 1, 2], [0, 1, 1], [1, 2, 2], [2, 0, 0]];
                    c.resolve_faces(0.1, 0.01, &faces, 1.0, &x0, &mut x, &mut v, &w, &mut near);
                    for i in (0..3).filter(|&i| i != k) {
                        assert!(x[i].is_finite() && v[i].is_finite(), "{b} at corner {k}");
                    }
                }
            }
        }
    }

    /// The box's own contact (its frame, clamped or to the nearest face) is parry's
    /// projection: over random points around a turned box, in it, near it and on its faces,
    /// the same contact or none, targets and normals within `f32` round-off.
    #[test]
    fn a_box_contact_is_parrys_projection() {
        let mut rng = crate::math::test_rng(0x5151_aaaa_0f0f_1234u64);
        let mut rnd = move || rng() as Scalar;
        let rot = Rot3::from_scaled_axis(glam::Vec3::new(0.4, -0.7, 0.2));
        let material = ContactMaterial {
            thickness: 0.02,
            ..Default::default()
        };
        let fast = Collider::new(
            SharedShape::cuboid(0.3, 0.1, 0.2),
            Motion::Fixed {
                position: [0.5, -0.2, 0.1],
            },
            rot,
            material,
        );
        assert!(matches!(fast.fast, Fast::Cuboid(_)));
        let general = as_general(&fast);
        let pose = fast.pose(0.0);
        let (mut met, mut inside) = (0, 0);
        for k in 0..20_000 {
            let mut p = pose.origin
                + (rot
                    * glam::Vec3::new(
                        0.35 * rnd() as f32,
                        0.15 * rnd() as f32,
                        0.25 * rnd() as f32,
                    ))
                .to_scalar();
            if k % 10 == 0 {
                // On a face.
                let local = rot.inverse() * (p - pose.origin).to_f32();
                let on = glam::Vec3::new(0.3 * local.x.signum(), local.y, local.z);
                p = pose.origin + (rot * on).to_scalar();
            }
            let a = fast.contact(&pose, 0.02, p);
            let b = general.contact(&pose, 0.02, p);
            let shape_pose = Pose3::from_parts(pose.origin.to_f32(), rot);
            let proj = fast.shape.project_point(&shape_pose, p.to_f32(), false);
            if (proj.point - p.to_f32()).length() < 1e-5 {
                // On a face: parry's direction is round-off; the box's is the face's normal,
                // the point pushed the thickness along it.
                let (ta, na) = a.expect("on the surface is in contact");
                assert!(
                    ((ta - p).length() - 0.02).abs() < 1e-5 && (na.length() - 1.0).abs() < 1e-5
                );
                continue;
            }
            match (a, b) {
                (Some((ta, na)), Some((tb, nb))) => {
                    met += 1;
                    inside += usize::from((p - ta).dot(na) < 0.0);
                    // A normal from a point `d` off the surface turns by the round-off over `d`.
                    let d = (proj.point - p.to_f32()).length() as Scalar;
                    let tol = 1e-4 + 2e-6 / d;
                    assert!(
                        (ta - tb).length() < 1e-5 + 0.02 * tol && (na - nb).length() < tol,
                        "{p:?}: {a:?} {b:?}"
                    );
                }
                (None, None) => {}
                // Exactly on the surface parry may call the point either way.
                (Some((ta, _)), None) | (None, Some((ta, _))) => {
                    assert!((ta - p).length() <= 0.02 + 1e-5, "{p:?}: {a:?} {b:?}")
                }
            }
        }
        assert!(
            met > 5000 && inside > 1000,
            "{met} contacts, {inside} from inside"
        );
    }

    /// A capsule's feature contact in it (the triangle's closest points to its axis): over
    /// random triangles (every fifth a segment) and segments, apart, near and crossing, the
    /// pair is `None` only where parry's intersection test says the two meet, never farther
    /// apart than parry's distance, and certified the nearest: along the direction between
    /// the points the triangle lies wholly beyond the one and the segment wholly short of
    /// the other. Through `face_contact`, a turned capsule's answer for triangles in it and
    /// near it: never farther than parry's, its point on the triangle, and `dist` back along
    /// the normal on the capsule's surface.
    #[test]
    fn a_capsule_feature_contact_is_the_nearest_pair() {
        use glam::DVec3;
        let mut rng = crate::math::test_rng(0x5e9_7a1a_bc0d_e123u64);
        let mut rnd = move || rng();
        let (mut apart, mut crossing) = (0, 0);
        for k in 0..20_000 {
            let size = if k % 3 == 0 { 0.05 } else { 0.4 };
            let centre = DVec3::new(0.3 * rnd(), 0.3 * rnd(), 0.3 * rnd());
            let mut t = [0; 3].map(|_| centre + DVec3::new(rnd(), rnd(), rnd()) * size);
            if k % 5 == 0 {
                t[2] = t[1];
            }
            let (a, b) = (
                DVec3::new(rnd(), rnd(), rnd()) * 0.4,
                DVec3::new(rnd(), rnd(), rnd()) * 0.4,
            );
            let f = t.map(|p| p.as_vec3());
            let feature: Box<dyn parry3d::shape::Shape> = if t[1] == t[2] {
                Box::new(parry3d::shape::Segment::new(f[0], f[1]))
            } else {
                Box::new(parry3d::shape::Triangle::new(f[0], f[1], f[2]))
            };
            let axis = parry3d::shape::Segment::new(a.as_vec3(), b.as_vec3());
            let id = Pose3::IDENTITY;
            let hit = parry3d::query::intersection_test(&id, &*feature, &id, &axis).unwrap();
            let dist = parry3d::query::distance(&id, &*feature, &id, &axis).unwrap() as f64;
            match triangle_segment_closest(t, a, b) {
                None => {
                    crossing += 1;
                    assert!(
                        hit || dist < 1e-5,
                        "{t:?}, {a} {b}: crossing against {dist}"
                    );
                }
                Some((p, q)) => {
                    apart += 1;
                    let ours = p.distance(q);
                    assert!(ours <= dist + 1e-6, "{t:?}: {ours} against {dist}");
                    if ours < 1e-9 {
                        continue;
                    }
                    let w = crate::core::self_contact::closest_on_triangle(p, t[0], t[1], t[2]);
                    let on = t[0] * w[0] + t[1] * w[1] + t[2] * w[2];
                    assert!(on.distance(p) < 1e-12, "{p:?} off the feature");
                    let s = (q - a).dot(b - a) / (b - a).length_squared();
                    assert!(
                        (a + (b - a) * s.clamp(0.0, 1.0)).distance(q) < 1e-12,
                        "{q:?} off the segment"
                    );
                    let dir = (p - q) / ours;
                    let feature_min = t.map(|v| v.dot(dir)).into_iter().fold(f64::MAX, f64::min);
                    let axis_max = a.dot(dir).max(b.dot(dir));
                    assert!(
                        feature_min >= p.dot(dir) - 1e-12 && axis_max <= q.dot(dir) + 1e-12,
                        "{t:?}, {a} {b}: {p} and {q} are not the nearest"
                    );
                }
            }
        }
        println!("{apart} apart, {crossing} crossing");
        assert!(
            apart > 10_000 && crossing > 500,
            "{apart} apart, {crossing} crossing"
        );

        let rot = Rot3::from_scaled_axis(glam::Vec3::new(0.4, -0.7, 0.2));
        let fast = Collider::new(
            SharedShape::capsule_y(0.3, 0.05),
            Motion::Fixed {
                position: [0.5, -0.2, 0.1],
            },
            rot,
            ContactMaterial::default(),
        );
        assert!(matches!(fast.fast, Fast::Capsule(_)));
        let pose = fast.pose(0.0);
        let shape_pose = Pose3::from_parts(pose.origin.to_f32(), pose.rotation);
        let (mut met, mut inside) = (0, 0);
        for _ in 0..5_000 {
            let centre = DVec3::new(0.1 * rnd(), 0.4 * rnd(), 0.1 * rnd());
            let tri = [0; 3].map(|_| {
                let local = (centre + DVec3::new(rnd(), rnd(), rnd()) * 0.1).as_vec3();
                pose.origin + (rot * local).to_scalar()
            });
            let ours = fast.face_contact(&pose, &shape_pose, 0.05, tri);
            let parry = fast.face_contact_parry(&shape_pose, 0.05, tri, None);
            match (ours, parry) {
                (Some((ba, pa, na, da)), Some((.., db))) => {
                    met += 1;
                    inside += (da < 0.0) as usize;
                    assert!(da <= db + 2e-5, "{tri:?}: {da} against {db}");
                    let on = tri[0] * ba[0] + tri[1] * ba[1] + tri[2] * ba[2];
                    assert!((on - pa).length() < 1e-5, "{tri:?}: {pa} off the triangle");
                    // In the capsule (ours): the foot on its surface to `f32` round-off of
                    // metres; where the axis crosses the triangle (deeper than the radius)
                    // the answer is parry's penetration query's, whose foot parry's own
                    // projection puts up to 51 µm away. (Apart, the answer is parry's.)
                    if da < 0.0 {
                        let foot = (pa - na * da).to_f32();
                        let proj = fast.shape.project_point(&shape_pose, foot, false);
                        let tol = if da < -0.05 { 2e-4 } else { 1e-5 };
                        assert!(
                            (proj.point - foot).length() < tol,
                            "{tri:?}: {foot} off the capsule"
                        );
                    }
                }
                (None, None) => {}
                (Some((.., d)), None) | (None, Some((.., d))) => {
                    assert!(d > 0.05 - 2e-5, "{tri:?}: one missed {d}")
                }
            }
        }
        println!("{met} contacts, {inside} of them inside");
        assert!(
            met > 1000 && inside > 100,
            "{met} contacts, {inside} inside"
        );
    }

    /// The box's own feature contact (closest points when apart, by vertices and edges) is
    /// parry's: over random triangles and segments around a box, near it, crossing it and
    /// far from it, the overlap test agrees with parry's intersection test and the distance,
    /// the points and the direction between them with parry's distance and closest points,
    /// to `f32` round-off (parry's precision); and through `face_contact`, a turned box's
    /// answer is the general path's.
    #[test]
    fn a_box_feature_contact_is_parrys() {
        use glam::DVec3;
        let mut rng = crate::math::test_rng(0x0bad_cafe_1234_5678u64);
        let mut rnd = move || rng();
        let h = DVec3::new(0.3, 0.1, 0.2);
        let cuboid = parry3d::shape::Cuboid::new(h.as_vec3());
        let (mut apart, mut overlapping, mut worst) = (0, 0, 0.0f64);
        for k in 0..20_000 {
            // Corners around the box, out to twice its size; every third a small triangle
            // (an eighth of the box) so that many lie just off a face, an edge or a corner.
            let size = if k % 3 == 0 { 0.05 } else { 0.4 };
            let centre = DVec3::new(0.5 * rnd(), 0.3 * rnd(), 0.4 * rnd());
            let mut t = [0; 3].map(|_| centre + DVec3::new(rnd(), rnd(), rnd()) * size);
            if k % 5 == 0 {
                // A segment, as an edge is passed.
                t[2] = t[1];
            }
            let f = t.map(|p| p.as_vec3());
            let feature: Box<dyn parry3d::shape::Shape> = if t[1] == t[2] {
                Box::new(parry3d::shape::Segment::new(f[0], f[1]))
            } else {
                Box::new(parry3d::shape::Triangle::new(f[0], f[1], f[2]))
            };
            let id = Pose3::IDENTITY;
            let hit = parry3d::query::intersection_test(&id, &*feature, &id, &cuboid).unwrap();
            let dist = parry3d::query::distance(&id, &*feature, &id, &cuboid).unwrap() as f64;
            match triangle_box_closest(t, h) {
                None => {
                    overlapping += 1;
                    // Told to overlap only where parry says so, or within round-off of it.
                    assert!(hit || dist < 1e-5, "{t:?}: overlap against parry's {dist}");
                }
                Some((p, q)) => {
                    apart += 1;
                    assert!(!hit || dist < 1e-5, "{t:?}: apart where parry overlaps");
                    let ours = p.distance(q);
                    // Never farther than parry's answer. parry's GJK stops within a
                    // tolerance, above the least distance (by 3 % of it at worst here: a
                    // corner 48.49 mm from an edge of the box, 50.01 mm by parry); the
                    // certificate below shows ours is the least.
                    assert!(ours <= dist + 1e-6, "{t:?}: {ours} against {dist}");
                    worst = worst.max((dist - ours) / dist.max(1e-3));
                    // The points: on the box and on the feature.
                    assert!((q.abs() - h).max_element() < 1e-12, "{q:?} off the box");
                    let b = crate::core::self_contact::closest_on_triangle(p, t[0], t[1], t[2]);
                    let on = t[0] * b[0] + t[1] * b[1] + t[2] * b[2];
                    assert!(on.distance(p) < 1e-12, "{p:?} off the feature");
                    // And they are the nearest: along `p − q` the feature lies wholly past
                    // `p` and the box wholly short of `q`, so no two points of them are
                    // nearer than `|p − q|` (the gap along that direction bounds every
                    // distance between them).
                    let dir = (p - q) / ours;
                    let feature_min = t.map(|v| v.dot(dir)).into_iter().fold(f64::MAX, f64::min);
                    let box_max = h.dot(dir.abs());
                    assert!(
                        feature_min >= p.dot(dir) - 1e-12 && box_max <= q.dot(dir) + 1e-12,
                        "{t:?}: {p} and {q} are not the nearest"
                    );
                }
            }
        }
        println!("{apart} apart, {overlapping} overlapping; parry at most {worst:.2e} farther");
        assert!(
            apart > 10_000 && overlapping > 2_000,
            "{apart} apart, {overlapping} overlapping"
        );

        // Through `face_contact`: a turned, moved box against the general path.
        let rot = Rot3::from_scaled_axis(glam::Vec3::new(0.4, -0.7, 0.2));
        let fast = Collider::new(
            SharedShape::cuboid(0.3, 0.1, 0.2),
            Motion::Fixed {
                position: [0.5, -0.2, 0.1],
            },
            rot,
            ContactMaterial::default(),
        );
        assert!(matches!(fast.fast, Fast::Cuboid(_)));
        let general = as_general(&fast);
        let pose = fast.pose(0.0);
        let shape_pose = Pose3::from_parts(pose.origin.to_f32(), pose.rotation);
        let mut met = 0;
        for _ in 0..5_000 {
            let centre = DVec3::new(0.4 * rnd(), 0.2 * rnd(), 0.3 * rnd());
            let tri = [0; 3].map(|_| {
                let local = (centre + DVec3::new(rnd(), rnd(), rnd()) * 0.1).as_vec3();
                pose.origin + (rot * local).to_scalar()
            });
            let a = fast.face_contact(&pose, &shape_pose, 0.05, tri);
            let b = general.face_contact(&pose, &shape_pose, 0.05, tri);
            match (a, b) {
                (Some((ba, pa, na, da)), Some((_, _, _, db))) => {
                    met += 1;
                    // Never farther than parry's; the point on the triangle, by its weights;
                    // the point `dist` back along the normal on the box's surface.
                    assert!(da <= db + 2e-5, "{tri:?}: {da} against {db}");
                    let on = tri[0] * ba[0] + tri[1] * ba[1] + tri[2] * ba[2];
                    assert!((on - pa).length() < 1e-5, "{tri:?}: {pa} off the triangle");
                    let foot = (pa - na * da).to_f32();
                    let proj = fast.shape.project_point(&shape_pose, foot, false);
                    assert!(
                        (proj.point - foot).length() < 1e-5,
                        "{tri:?}: {foot} off the box"
                    );
                }
                (None, None) => {}
                // At the edge of the reach either may call it (parry's distance is a little
                // long).
                (Some((.., d)), None) => assert!(d > 0.048, "{tri:?}: parry missed {d}"),
                (None, Some((.., d))) => assert!(d > 0.05 - 2e-5, "{tri:?}: missed {d}"),
            }
        }
        assert!(met > 1000, "{met} contacts");
    }

    /// The box's own penetration (the least translation out, by separating axes) against
    /// parry's penetration query (EPA) and an independent check: over random triangles and
    /// segments overlapping a box, moved by the depth along the normal (and a millionth
    /// more) the feature no longer overlaps the box, by the separating-axis test; the point
    /// is on the feature and, moved so, on the box's surface; and wherever parry's
    /// translation takes the feature out, the depth is parry's to `f32` round-off (6.5e-8 m
    /// at most), never more (ours is the least). In 27 of 12,204 overlaps parry's
    /// translation left the feature in the box (EPA stopping short: a triangle wholly inside
    /// at 0.0933 m where 0.0994 is the least that takes it out).
    #[test]
    fn a_box_penetration_is_the_least_translation_out() {
        use glam::DVec3;
        let mut rng = crate::math::test_rng(0x005e_ed0f_b0c5_u64);
        let mut rnd = move || rng();
        let h = DVec3::new(0.3, 0.1, 0.2);
        let cuboid = parry3d::shape::Cuboid::new(h.as_vec3());
        let (mut met, mut worst, mut short) = (0, 0.0f64, 0);
        for k in 0..20_000 {
            let size = if k % 3 == 0 { 0.05 } else { 0.4 };
            let centre = DVec3::new(0.35 * rnd(), 0.15 * rnd(), 0.25 * rnd());
            let mut t = [0; 3].map(|_| centre + DVec3::new(rnd(), rnd(), rnd()) * size);
            if k % 5 == 0 {
                t[2] = t[1];
            }
            if !triangle_box_overlap(t, h) {
                continue;
            }
            let Some((p, n, depth)) = triangle_box_penetration(t, h) else {
                panic!("{t:?}: overlapping, but no penetration");
            };
            met += 1;
            assert!(
                (n.length() - 1.0).abs() < 1e-12 && depth > 0.0,
                "{n} {depth}"
            );
            // Out: moved a little past the depth, apart.
            let out = t.map(|v| v + n * (depth * (1.0 + 1e-6) + 1e-9));
            assert!(
                !triangle_box_overlap(out, h),
                "{t:?}: still in after {depth} along {n}"
            );
            // The point: on the feature, and moved out, on the box's surface.
            let b = crate::core::self_contact::closest_on_triangle(p, t[0], t[1], t[2]);
            let on = t[0] * b[0] + t[1] * b[1] + t[2] * b[2];
            assert!(on.distance(p) < 1e-9, "{t:?}: {p} off the feature");
            let foot = p + n * depth;
            let gap = (foot.abs() - h).max_element();
            assert!(
                gap.abs() < 1e-6,
                "{t:?}: {foot} is {gap} off the box's surface"
            );
            // parry's penetration query, in `f32`.
            let f = t.map(|v| v.as_vec3());
            let feature: Box<dyn parry3d::shape::Shape> = if t[1] == t[2] {
                Box::new(parry3d::shape::Segment::new(f[0], f[1]))
            } else {
                Box::new(parry3d::shape::Triangle::new(f[0], f[1], f[2]))
            };
            let id = Pose3::IDENTITY;
            // Where parry's translation takes the feature out, ours is no longer than it.
            // (EPA stops short on some features deep in the box: its translation leaves
            // them in.)
            if let Ok(Some(c)) = parry3d::query::contact(&id, &*feature, &id, &cuboid, 0.0) {
                let (theirs, dir) = (-c.dist as f64, -c.normal1.as_dvec3());
                let moved = t.map(|v| v + dir * (theirs * (1.0 + 1e-5) + 1e-6));
                if triangle_box_overlap(moved, h) {
                    short += 1;
                } else {
                    assert!(
                        depth <= theirs + 1e-5,
                        "{t:?}: {depth} against parry's {theirs}"
                    );
                    worst = worst.max(theirs - depth);
                }
            }
        }
        println!("{met} overlapping; parry's depth at most {worst:.2e} more, short in {short}");
        assert!(met > 5_000, "{met} overlapping");
        // The same depth to `f32` round-off, where parry's is right.
        assert!(worst < 1e-6, "parry's depth {worst} more than ours");
    }

    /// A capsule's own particle contact (the nearest point of its axis) is parry's projection
    /// (the general path): over random points around a turned capsule, in it, near it and far,
    /// the same contact or none, targets and normals within `f32` round-off.
    #[test]
    fn a_capsule_particle_contact_is_parrys_projection() {
        let mut rng = crate::math::test_rng(0x7f4a_7c15_9e37_79b9u64);
        let mut rnd = move || rng() as Scalar;
        let rot = Rot3::from_scaled_axis(glam::Vec3::new(-0.4, 0.2, 0.7));
        let fast = Collider::new(
            SharedShape::capsule_y(0.3, 0.06),
            Motion::Fixed {
                position: [0.5, -0.2, 0.1],
            },
            rot,
            ContactMaterial::default(),
        );
        let pose = fast.pose(0.0);
        let (mut met, mut inside) = (0, 0);
        for _ in 0..20_000 {
            let local =
                glam::Vec3::new(0.12 * rnd() as f32, 0.4 * rnd() as f32, 0.12 * rnd() as f32);
            let p = pose.origin + (rot * local).to_scalar();
            let a = fast.contact(&pose, 0.02, p);
            // The general path, parry's projection, by the same collider's shape.
            let shape_pose = Pose3::from_parts(pose.origin.to_f32(), rot);
            let proj = fast.shape.project_point(&shape_pose, p.to_f32(), false);
            let off = p.to_f32() - proj.point;
            let dist = off.length() * if proj.is_inside { -1.0 } else { 1.0 };
            match a {
                Some((target, n)) => {
                    met += 1;
                    inside += usize::from(proj.is_inside);
                    assert!(
                        dist < 0.02 + 1e-5,
                        "{p:?}: contact at {dist} from the surface"
                    );
                    // The target: the projection, the thickness out along the normal.
                    let want = proj.point.to_scalar() + n * 0.02;
                    assert!(
                        (target - want).length() < 1e-5,
                        "{p:?}: {target} against {want}"
                    );
                    if off.length() > 1e-3 {
                        let theirs = (off / off.length()).to_scalar()
                            * if proj.is_inside { -1.0 } else { 1.0 };
                        assert!((n - theirs).length() < 1e-3, "{p:?}: {n} against {theirs}");
                    }
                }
                None => assert!(dist > 0.02 - 1e-5, "{p:?}: none at {dist}"),
            }
        }
        assert!(
            met > 5_000 && inside > 1_000,
            "{met} contacts, {inside} inside"
        );
    }
}
