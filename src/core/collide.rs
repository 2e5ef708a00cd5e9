//! Particles against collider shapes: project a particle that is inside (closer than the
//! collider's thickness) back to the surface, reflect its normal velocity relative to the
//! collider with restitution, and reduce its tangential velocity by Coulomb friction.
//!
//! Spheres and planes are handled analytically (in the crate's precision); every other
//! shape goes through parry3d's point projection (in `f32`, parry's precision).

use crate::core::motion::Motion;
use crate::math::{Scalar, ToScalar, Vector, VectorExt};
use parry3d::math::{Pose3, Rot3};
use parry3d::shape::SharedShape;
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
    Plane(Vector),
    General,
}

/// A collider ready for queries.
pub struct Collider {
    /// The parry3d shape.
    pub shape: SharedShape,
    /// Where its origin is over time.
    pub motion: Motion,
    /// Orientation.
    pub rotation: Rot3,
    /// Contact material.
    pub material: ContactMaterial,
    fast: Fast,
}

impl Clone for Collider {
    fn clone(&self) -> Self {
        Self::new(
            self.shape.clone(),
            self.motion,
            self.rotation,
            self.material,
        )
    }
}

impl std::fmt::Debug for Collider {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Collider")
            .field("shape", &self.shape.shape_type())
            .field("motion", &self.motion)
            .field("material", &self.material)
            .finish()
    }
}

impl Collider {
    /// A collider from any parry3d shape.
    pub fn new(
        shape: SharedShape,
        motion: Motion,
        rotation: Rot3,
        material: ContactMaterial,
    ) -> Self {
        let fast = if let Some(b) = shape.as_ball() {
            Fast::Sphere(b.radius as Scalar)
        } else if let Some(h) = shape.as_halfspace() {
            Fast::Plane((rotation * h.normal).to_scalar())
        } else {
            Fast::General
        };
        Self {
            shape,
            motion,
            rotation,
            material,
            fast,
        }
    }

    /// From a layout description.
    pub fn from_desc(d: &ColliderDesc) -> Self {
        let q = d.rotation;
        let rot = Rot3::from_xyzw(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32).normalize();
        Self::new(d.shape.to_shared(), d.motion, rot, d.material)
    }

    /// Where particle position `p` should be and the contact normal, when it is inside the
    /// collider (centred at `c`) or closer to its surface than `thick`.
    fn contact(&self, c: Vector, thick: Scalar, p: Vector) -> Option<(Vector, Vector)> {
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
            Fast::Plane(n) => {
                let s = (p - c).dot(n);
                if s < thick {
                    Some((p + n * (thick - s), n))
                } else {
                    None
                }
            }
            Fast::General => {
                let pose = Pose3::from_parts(c.to_f32(), self.rotation);
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

    /// Particles resting on or pressed into this collider at time `t`: touching (within the
    /// thickness plus `slack`), not moving away, and pushed into it by `f` (their total force).
    /// Implicit steps hold them still (Baraff & Witkin's constraint filter: sticking contact)
    /// instead of letting the step drive them in and projecting them out afterwards, which
    /// pumps energy into stiff elements. Marks them in `held` and sets their velocity to the
    /// collider's.
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
        let (c, vc, _) = self.motion.eval(t);
        let thick = self.material.thickness as Scalar + slack;
        for i in 0..x.len() {
            if inv_mass[i] == 0.0 || held[i] {
                continue;
            }
            if let Some((_, n)) = self.contact(c, thick, x[i])
                && (v[i] - vc).dot(n) <= 0.0
                && f[i].dot(n) <= 0.0
            {
                held[i] = true;
                v[i] = vc;
            }
        }
    }

    /// Pushes particles out of the collider at time `t` and applies restitution and friction.
    /// `inv_mass` selects the particles that respond (zero: pinned or prescribed). Returns the
    /// number of particles in contact.
    pub fn resolve(
        &self,
        t: Scalar,
        x: &mut [Vector],
        v: &mut [Vector],
        inv_mass: &[Scalar],
    ) -> usize {
        let (c, vc, _) = self.motion.eval(t);
        let m = &self.material;
        let thick = m.thickness as Scalar;
        let mut contacts = 0;
        for i in 0..x.len() {
            if inv_mass[i] == 0.0 {
                continue;
            }
            let hit = self.contact(c, thick, x[i]);
            if let Some((target, n)) = hit {
                contacts += 1;
                x[i] = target;
                let rel = v[i] - vc;
                let vn = rel.dot(n);
                if vn < 0.0 {
                    let vt = rel - n * vn;
                    let e = if -vn > m.bounce_threshold as Scalar {
                        m.restitution as Scalar
                    } else {
                        0.0
                    };
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
}
