//! Springs and spring dampers, packed for a tight force kernel.
//!
//! Two laws are offered per spring:
//! - Hooke, `f_i = −k (|d| − L) d/|d|` with `d = x_i − x_j` and `k` in N/m (the seed
//!   assignment's law);
//! - strain, `f_i = −k (l/L − 1) n` with `k` in N (Young's modulus times area, the PhysBAM
//!   slides' law).
//!
//! The strain law is Hooke's law with stiffness `k/L`, so both are stored as an effective
//! Hooke stiffness and share one kernel (and one Jacobian). A damper along the spring adds
//! `f_i = −b (n·(v_i − v_j)) n`.

use crate::math::{Scalar, Vector};
use serde::{Deserialize, Serialize};

/// How a spring's stiffness is given.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "plugin", derive(bevy::reflect::Reflect))]
#[serde(rename_all = "snake_case")]
pub enum SpringLaw {
    /// `f = −k (l − L) n`, `k` in N/m.
    #[default]
    Hooke,
    /// `f = −k (l/L − 1) n`, `k` in N (the PhysBAM slides' "Young's modulus").
    Strain,
}

impl SpringLaw {
    /// The Hooke stiffness (N/m) equivalent to stiffness `k` under this law at rest length `rest`.
    pub fn effective_stiffness(self, k: Scalar, rest: Scalar) -> Scalar {
        match self {
            SpringLaw::Hooke => k,
            SpringLaw::Strain => k / rest,
        }
    }
}

/// One spring as the kernel reads it: 20 bytes in f32, so a cache line holds three.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct PackedSpring {
    /// First particle.
    pub i: u32,
    /// Second particle.
    pub j: u32,
    /// Rest length `L`.
    pub rest: Scalar,
    /// Effective Hooke stiffness (N/m).
    pub k: Scalar,
    /// Damping along the spring (N·s/m).
    pub damping: Scalar,
}

/// All springs of a model.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Springs {
    springs: Vec<PackedSpring>,
    damped: usize,
}

impl Springs {
    /// No springs.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a spring. Indices must be valid for the model that uses it (the model checks).
    pub fn push(
        &mut self,
        i: usize,
        j: usize,
        rest: Scalar,
        k: Scalar,
        damping: Scalar,
        law: SpringLaw,
    ) {
        self.springs.push(PackedSpring {
            i: i as u32,
            j: j as u32,
            rest,
            k: law.effective_stiffness(k, rest),
            damping,
        });
        if damping != 0.0 {
            self.damped += 1;
        }
    }

    /// Number of springs.
    pub fn len(&self) -> usize {
        self.springs.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.springs.is_empty()
    }

    /// The packed springs.
    pub fn as_slice(&self) -> &[PackedSpring] {
        &self.springs
    }

    /// Mutable access (stiffness changes at run time). Call [`Springs::refresh`] after
    /// changing damping.
    pub fn as_mut_slice(&mut self) -> &mut [PackedSpring] {
        &mut self.springs
    }

    /// Recounts damped springs after edits.
    pub fn refresh(&mut self) {
        self.damped = self.springs.iter().filter(|s| s.damping != 0.0).count();
    }

    /// Removes the spring at `index` (order of the others is kept).
    pub fn remove(&mut self, index: usize) -> PackedSpring {
        let s = self.springs.remove(index);
        if s.damping != 0.0 {
            self.damped -= 1;
        }
        s
    }

    /// True when any spring has a damper.
    pub fn has_damping(&self) -> bool {
        self.damped > 0
    }

    /// Adds spring (and damper) forces into `f`. `x`, `v` and `f` have one entry per particle
    /// and every spring index is below their length (checked by the model at build time).
    pub fn accumulate(&self, x: &[Vector], v: &[Vector], f: &mut [Vector]) {
        let n = x.len();
        assert!(v.len() == n && f.len() == n);
        if self.damped > 0 {
            for s in &self.springs {
                let (i, j) = (s.i as usize, s.j as usize);
                let d = x[i] - x[j];
                let l = d.length();
                let inv = if l > 0.0 { 1.0 / l } else { 0.0 };
                let nrm = d * inv;
                let mag = -s.k * (l - s.rest) - s.damping * nrm.dot(v[i] - v[j]);
                let fi = nrm * mag;
                f[i] += fi;
                f[j] -= fi;
            }
        } else {
            for s in &self.springs {
                let (i, j) = (s.i as usize, s.j as usize);
                let d = x[i] - x[j];
                let l = d.length();
                // −k (l − L) d/l = d·(k (L/l − 1)); zero-length springs exert nothing.
                let c = if l > 0.0 {
                    s.k * (s.rest / l - 1.0)
                } else {
                    0.0
                };
                let fi = d * c;
                f[i] += fi;
                f[j] -= fi;
            }
        }
    }

    /// Elastic energy `Σ ½ k (l − L)²`.
    pub fn energy(&self, x: &[Vector]) -> Scalar {
        self.springs
            .iter()
            .map(|s| {
                let e = (x[s.i as usize] - x[s.j as usize]).length() - s.rest;
                0.5 * s.k * e * e
            })
            .sum()
    }

    /// Largest index referenced plus one (0 when empty).
    pub fn max_index(&self) -> usize {
        self.springs
            .iter()
            .map(|s| s.i.max(s.j) as usize + 1)
            .max()
            .unwrap_or(0)
    }
}
