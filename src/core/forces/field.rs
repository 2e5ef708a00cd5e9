//! Force fields: a game's own law, evaluated at every force evaluation, for each particle
//! from its position, velocity, mass and the time — buoyancy below a water surface, a blast,
//! a magnet, a character's push. Two built-ins: [`Buoyancy`] and [`RadialBlast`].
//!
//! Explicit methods use [`ForceField::force`] at every stage. Linearly implicit Euler uses
//! the force and, where a field gives one, its [`ForceField::jacobian`]: the diagonal of
//! `−∂f/∂x` and `−∂f/∂v` where it is positive (where the field stiffens or damps, which keeps
//! the method's matrix symmetric positive definite), the rest explicitly. The implicit-damping
//! trapezoid takes a field explicitly, and Newton's backward Euler as a force constant over
//! the step, evaluated at its start (a field has no potential in general, and the
//! minimization needs one).

use crate::math::{Scalar, Vector};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Derivatives of a field's force on one particle, as rows: `dx[i]` is `∂f_i/∂x`, `dv[i]` is
/// `∂f_i/∂v`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FieldJacobian {
    /// `∂f/∂x` (N/m).
    pub dx: [Vector; 3],
    /// `∂f/∂v` (N·s/m).
    pub dv: [Vector; 3],
}

/// A force law on particles.
pub trait ForceField: Send + Sync + std::fmt::Debug {
    /// The force (N) on a particle of `mass` at `x` moving at `v`, at time `t`.
    fn force(&self, t: Scalar, x: Vector, v: Vector, mass: Scalar) -> Vector;

    /// Its derivatives at the same arguments; `None` (the default) when the field does not
    /// say, and implicit methods take it explicitly.
    fn jacobian(&self, t: Scalar, x: Vector, v: Vector, mass: Scalar) -> Option<FieldJacobian> {
        let _ = (t, x, v, mass);
        None
    }

    /// True when the field no longer changes with time from `t` on (its force depends on
    /// position and velocity alone): a body at rest in it may sleep. The default, `false`,
    /// keeps bodies in the field awake.
    fn steady_from(&self, t: Scalar) -> bool {
        let _ = t;
        false
    }
}

/// A field shared by the bodies it acts on.
pub type SharedField = Arc<dyn ForceField>;

/// A still fluid below the horizontal surface `y = level`: Archimedes' push and a linear drag
/// on the part of each particle under the surface. A particle of mass `m` stands for a slab
/// of volume `m / body_density` and thickness `layer` centred on it, so its submerged fraction
/// `s = clamp((level − y)/layer + ½, 0, 1)` grows linearly as it goes under; the force is
/// `s (ρ_f/ρ_b) m g ŷ − s c m v`. A body of such slabs stacked `layer` apart floats with the
/// fraction `ρ_b/ρ_f` of its height under the surface, as Archimedes says.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Buoyancy {
    /// Height of the surface (m).
    pub level: f64,
    /// Density of the fluid (kg/m³; water 1000).
    pub fluid_density: f64,
    /// Density the particles stand for (kg/m³).
    pub body_density: f64,
    /// Gravitational acceleration (m/s², downwards).
    pub gravity: f64,
    /// Thickness of a particle's slab (m): the grid spacing of a lattice body.
    pub layer: f64,
    /// Linear drag per unit mass under the surface, `c` (1/s).
    pub drag: f64,
    /// The x–z rectangle the fluid fills (`[x_min, z_min]`, `[x_max, z_max]`); everywhere when
    /// absent.
    pub region: Option<([f64; 2], [f64; 2])>,
}

impl Default for Buoyancy {
    fn default() -> Self {
        Self {
            level: 0.0,
            fluid_density: 1000.0,
            body_density: 500.0,
            gravity: 9.81,
            layer: 0.1,
            drag: 2.0,
            region: None,
        }
    }
}

impl Buoyancy {
    /// Submerged fraction and its derivative along y.
    fn fraction(&self, x: Vector) -> (Scalar, Scalar) {
        if let Some((lo, hi)) = self.region {
            let (px, pz) = (x.x as f64, x.z as f64);
            if px < lo[0] || px > hi[0] || pz < lo[1] || pz > hi[1] {
                return (0.0, 0.0);
            }
        }
        let s = (self.level - x.y as f64) / self.layer + 0.5;
        if s <= 0.0 {
            (0.0, 0.0)
        } else if s >= 1.0 {
            (1.0, 0.0)
        } else {
            (s as Scalar, (-1.0 / self.layer) as Scalar)
        }
    }

    fn lift(&self, mass: Scalar) -> Scalar {
        (self.fluid_density / self.body_density * self.gravity) as Scalar * mass
    }
}

impl ForceField for Buoyancy {
    fn steady_from(&self, _t: Scalar) -> bool {
        true
    }

    fn force(&self, _t: Scalar, x: Vector, v: Vector, mass: Scalar) -> Vector {
        let (s, _) = self.fraction(x);
        if s == 0.0 {
            return Vector::ZERO;
        }
        Vector::Y * (s * self.lift(mass)) - v * (s * self.drag as Scalar * mass)
    }

    fn jacobian(&self, _t: Scalar, x: Vector, v: Vector, mass: Scalar) -> Option<FieldJacobian> {
        let (s, ds) = self.fraction(x);
        // f = s(y) (a ŷ − b v): ∂f/∂x = (a ŷ − b v) ⊗ (0, ds, 0), ∂f/∂v = −s b I.
        let (a, b) = (self.lift(mass), self.drag as Scalar * mass);
        let col = (Vector::Y * a - v * b) * ds;
        let dx = [
            Vector::new(0.0, col.x, 0.0),
            Vector::new(0.0, col.y, 0.0),
            Vector::new(0.0, col.z, 0.0),
        ];
        let d = -s * b;
        Some(FieldJacobian {
            dx,
            dv: [Vector::X * d, Vector::Y * d, Vector::Z * d],
        })
    }
}

/// A blast: an outward push from `center` of acceleration `strength · exp(−r²/radius²)`
/// (m/s², so light and heavy particles fly alike), from `start` for `duration` seconds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RadialBlast {
    /// Where (m).
    pub center: [f64; 3],
    /// Acceleration at the centre (m/s²).
    pub strength: f64,
    /// Fall-off radius (m).
    pub radius: f64,
    /// When it starts (s, the simulation's time).
    pub start: f64,
    /// How long it pushes (s).
    pub duration: f64,
}

impl Default for RadialBlast {
    fn default() -> Self {
        Self {
            center: [0.0; 3],
            strength: 200.0,
            radius: 0.5,
            start: 0.0,
            duration: 0.1,
        }
    }
}

impl RadialBlast {
    fn active(&self, t: Scalar) -> bool {
        let t = t as f64;
        t >= self.start && t < self.start + self.duration
    }

    /// Arm from the centre, its length, and `g(d)`.
    fn arm(&self, x: Vector) -> (Vector, Scalar, Scalar) {
        let c = Vector::new(
            self.center[0] as Scalar,
            self.center[1] as Scalar,
            self.center[2] as Scalar,
        );
        let r = x - c;
        let d = r.length();
        let q = (d as f64 / self.radius).powi(2);
        (r, d, (self.strength * (-q).exp()) as Scalar)
    }
}

impl ForceField for RadialBlast {
    /// Over once its push has ended.
    fn steady_from(&self, t: Scalar) -> bool {
        t as f64 >= self.start + self.duration
    }

    fn force(&self, t: Scalar, x: Vector, _v: Vector, mass: Scalar) -> Vector {
        if !self.active(t) {
            return Vector::ZERO;
        }
        let (r, d, g) = self.arm(x);
        if d == 0.0 {
            return Vector::ZERO;
        }
        r * (mass * g / d)
    }

    fn jacobian(&self, t: Scalar, x: Vector, _v: Vector, mass: Scalar) -> Option<FieldJacobian> {
        let mut j = FieldJacobian::default();
        if !self.active(t) {
            return Some(j);
        }
        let (r, d, g) = self.arm(x);
        if d == 0.0 {
            return Some(j);
        }
        // f = m g(d) r̂: ∂f/∂x = m (g'(d) r̂r̂ᵀ + g(d)/d (I − r̂r̂ᵀ)), g' = −2d/R² g.
        let n = r / d;
        let gp = -2.0 * d / (self.radius * self.radius) as Scalar * g;
        for (i, row) in j.dx.iter_mut().enumerate() {
            let mut e = Vector::ZERO;
            e[i] = 1.0;
            *row = (n * (n[i] * gp) + (e - n * n[i]) * (g / d)) * mass;
        }
        Some(j)
    }
}
