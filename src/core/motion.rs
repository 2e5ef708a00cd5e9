//! Prescribed motion: positions given as functions of time, for kinematic particles (the
//! rotating wire endpoint of the PhysBAM slides, a cloth corner held by a hand) and moving
//! colliders (the swinging sphere). Position, velocity and acceleration are exact.

use crate::math::{Scalar, ToScalar, Vector};
use serde::{Deserialize, Serialize};

/// A trajectory `p(t)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Motion {
    /// At rest at `position`.
    Fixed {
        /// Where.
        position: [f64; 3],
    },
    /// `p(t) = start + velocity·(t − t0)`.
    Linear {
        /// Position at `t0`.
        start: [f64; 3],
        /// Constant velocity.
        velocity: [f64; 3],
        /// Reference time.
        t0: f64,
    },
    /// `p(t) = center + radius·(sin θ·a + cos θ·b)`, `θ = ω t + φ`: the PhysBAM wire's endpoint
    /// is `center = 0, radius = 0.5, a = x̂, b = ẑ`.
    Circle {
        /// Centre of the circle.
        center: [f64; 3],
        /// Radius.
        radius: f64,
        /// Angular velocity ω (rad/s).
        omega: f64,
        /// Phase φ (rad).
        phase: f64,
        /// Unit axis multiplying `sin θ`.
        a: [f64; 3],
        /// Unit axis multiplying `cos θ`.
        b: [f64; 3],
    },
    /// `p(t) = center + amplitude·sin(ω t + φ)`: a swing back and forth.
    Oscillate {
        /// Centre of the swing.
        center: [f64; 3],
        /// Displacement at the swing's extreme.
        amplitude: [f64; 3],
        /// Angular frequency ω (rad/s).
        omega: f64,
        /// Phase φ (rad).
        phase: f64,
    },
}

impl Motion {
    /// True when the path stays where it is for all time (fixed, or linear at zero
    /// velocity, or a circle or swing of zero size or frequency).
    pub fn is_still(&self) -> bool {
        match self {
            Motion::Fixed { .. } => true,
            Motion::Linear { velocity, .. } => velocity.iter().all(|&c| c == 0.0),
            Motion::Circle { radius, omega, .. } => *radius == 0.0 || *omega == 0.0,
            Motion::Oscillate {
                amplitude, omega, ..
            } => amplitude.iter().all(|&c| c == 0.0) || *omega == 0.0,
        }
    }

    /// The PhysBAM slides' wire endpoint: radius 0.5 in the x–z plane, one revolution in
    /// `period` seconds, starting at `(0, 0, 0.5)`.
    pub fn physbam_wire_endpoint(period: f64) -> Self {
        Motion::Circle {
            center: [0.0; 3],
            radius: 0.5,
            omega: std::f64::consts::TAU / period,
            phase: 0.0,
            a: [1.0, 0.0, 0.0],
            b: [0.0, 0.0, 1.0],
        }
    }

    /// Position, velocity and acceleration at time `t`.
    pub fn eval(&self, t: Scalar) -> (Vector, Vector, Vector) {
        match *self {
            Motion::Fixed { position } => (position.to_scalar(), Vector::ZERO, Vector::ZERO),
            Motion::Linear {
                start,
                velocity,
                t0,
            } => {
                let v = velocity.to_scalar();
                (start.to_scalar() + v * (t - t0 as Scalar), v, Vector::ZERO)
            }
            Motion::Circle {
                center,
                radius,
                omega,
                phase,
                a,
                b,
            } => {
                let (r, w) = (radius as Scalar, omega as Scalar);
                let (s, c) = (w * t + phase as Scalar).sin_cos();
                let (a, b) = (a.to_scalar(), b.to_scalar());
                let p = (a * s + b * c) * r;
                (
                    center.to_scalar() + p,
                    (a * c - b * s) * (r * w),
                    -p * (w * w),
                )
            }
            Motion::Oscillate {
                center,
                amplitude,
                omega,
                phase,
            } => {
                let w = omega as Scalar;
                let (s, c) = (w * t + phase as Scalar).sin_cos();
                let amp = amplitude.to_scalar();
                (
                    center.to_scalar() + amp * s,
                    amp * (w * c),
                    -amp * (w * w * s),
                )
            }
        }
    }

    /// The same path shifted by `offset`.
    pub fn translated(mut self, offset: [f64; 3]) -> Self {
        let add = |p: &mut [f64; 3]| {
            for (c, o) in p.iter_mut().zip(offset) {
                *c += o;
            }
        };
        match &mut self {
            Motion::Fixed { position } => add(position),
            Motion::Linear { start, .. } => add(start),
            Motion::Circle { center, .. } | Motion::Oscillate { center, .. } => add(center),
        }
        self
    }

    /// Position at time `t`.
    pub fn position(&self, t: Scalar) -> Vector {
        self.eval(t).0
    }

    /// Velocity at time `t`.
    pub fn velocity(&self, t: Scalar) -> Vector {
        self.eval(t).1
    }

    /// True when every number is finite.
    pub fn is_finite(&self) -> bool {
        let f = |a: &[f64]| a.iter().all(|x| x.is_finite());
        match self {
            Motion::Fixed { position } => f(position),
            Motion::Linear {
                start,
                velocity,
                t0,
            } => f(start) && f(velocity) && t0.is_finite(),
            Motion::Circle {
                center,
                radius,
                omega,
                phase,
                a,
                b,
            } => f(center) && f(a) && f(b) && f(&[*radius, *omega, *phase]),
            Motion::Oscillate {
                center,
                amplitude,
                omega,
                phase,
            } => f(center) && f(amplitude) && f(&[*omega, *phase]),
        }
    }
}
