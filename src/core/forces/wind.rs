//! Wind: a constant air velocity plus a gentle breeze, deterministic given a seed.
//!
//! A particle feels air drag towards the air's velocity, `f = c (w(t) − v)`, so wind is
//! well-posed at any strength (it never pumps energy without bound) and its Jacobian is the
//! constant `−c I` in velocity. The breeze is a sum of three sines per axis whose frequencies
//! and phases come from the seed.

use crate::math::{Scalar, ToScalar, Vector};
use serde::{Deserialize, Serialize};

/// Wind settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Wind {
    /// Mean air velocity (m/s).
    pub velocity: [f64; 3],
    /// Amplitude of the breeze's gusts (m/s).
    pub gust: f64,
    /// Typical gust frequency (Hz).
    pub frequency: f64,
    /// Air-drag coefficient `c` (N·s/m per particle).
    pub coefficient: f64,
    /// Seed of the breeze's frequencies and phases.
    pub seed: u64,
    /// Off: no force, no cost.
    pub enabled: bool,
}

impl Default for Wind {
    fn default() -> Self {
        Self {
            velocity: [1.0, 0.0, 0.5],
            gust: 1.0,
            frequency: 0.5,
            coefficient: 0.01,
            seed: 1,
            enabled: true,
        }
    }
}

/// SplitMix64: a tiny, well-mixed, portable generator (deterministic across platforms).
pub(crate) fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Uniform in [0, 1).
pub(crate) fn unit(state: &mut u64) -> f64 {
    (splitmix64(state) >> 11) as f64 / (1u64 << 53) as f64
}

/// Precomputed breeze: frequencies and phases per axis.
#[derive(Clone, Debug, PartialEq)]
pub struct WindField {
    mean: Vector,
    coefficient: Scalar,
    gust: Scalar,
    omega: [[Scalar; 3]; 3],
    phase: [[Scalar; 3]; 3],
}

impl Wind {
    /// Precomputes the breeze.
    pub fn field(&self) -> WindField {
        let mut st = self.seed;
        let mut omega = [[0.0; 3]; 3];
        let mut phase = [[0.0; 3]; 3];
        for a in 0..3 {
            for k in 0..3 {
                // Frequencies spread over [0.5, 1.5] × the typical one, phases uniform.
                omega[a][k] =
                    (std::f64::consts::TAU * self.frequency * (0.5 + unit(&mut st))) as Scalar;
                phase[a][k] = (std::f64::consts::TAU * unit(&mut st)) as Scalar;
            }
        }
        WindField {
            mean: self.velocity.to_scalar(),
            coefficient: self.coefficient as Scalar,
            gust: self.gust as Scalar,
            omega,
            phase,
        }
    }
}

impl WindField {
    /// Air velocity at time `t`.
    pub fn velocity(&self, t: Scalar) -> Vector {
        let mut g = [0.0 as Scalar; 3];
        for (a, ga) in g.iter_mut().enumerate() {
            for k in 0..3 {
                *ga += (self.omega[a][k] * t + self.phase[a][k]).sin();
            }
        }
        // Three unit sines have RMS √1.5; normalise so `gust` is the RMS gust speed.
        let s = self.gust / (1.5 as Scalar).sqrt();
        self.mean + Vector::new(g[0], g[1], g[2]) * s
    }

    /// Drag coefficient towards the air velocity.
    pub fn coefficient(&self) -> Scalar {
        self.coefficient
    }
}
