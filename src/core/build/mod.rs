//! Scene generators: pendulum, chain, cloth, the PhysBAM wire, the particle-system assignment's pyramid, a jelly
//! block and the cloth-and-sphere scene. Each returns a [`Scene`] (layout as data), so what a
//! generator makes can be saved, edited and loaded back.

use crate::core::forces::SpringLaw;
use crate::core::scene::{MAX_PARTICLES, ParticleDesc, Scene, SpringDesc, SpringKind};

mod chain;
mod cloth;
mod jelly;
mod pile;
mod pyramid;
mod surface;
mod tet_body;
mod wire;
pub use chain::*;
pub use cloth::*;
pub use jelly::*;
pub use pile::*;
pub use pyramid::*;
pub use surface::{SurfaceBody, SurfaceParams, SurfaceStiffness, surface_cloth};
pub use tet_body::*;
pub use wire::*;

/// Standard gravity (m/s²), along −y.
pub const G: f64 = 9.81;

/// A builder asked for more than [`MAX_PARTICLES`] particles or for a degenerate size.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildError(pub String);

impl std::fmt::Display for BuildError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BuildError {}

fn check_count(what: &str, n: usize, min: usize) -> Result<(), BuildError> {
    if n > MAX_PARTICLES {
        return Err(BuildError(format!(
            "{what}: {n} particles is more than the limit of {MAX_PARTICLES}"
        )));
    }
    if n < min {
        return Err(BuildError(format!(
            "{what}: needs at least {min} particles, got {n}"
        )));
    }
    Ok(())
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn particle(position: [f64; 3], mass: f64) -> ParticleDesc {
    ParticleDesc {
        position,
        velocity: [0.0; 3],
        mass,
        pinned: false,
    }
}

fn spring(a: usize, b: usize, stiffness: f64, damping: f64, kind: SpringKind) -> SpringDesc {
    SpringDesc {
        a,
        b,
        stiffness,
        damping,
        rest_length: None,
        law: SpringLaw::Hooke,
        kind,
    }
}

/// Distance between two particles of a scene (used by tests and tools).
pub fn particle_distance(s: &Scene, a: usize, b: usize) -> f64 {
    dist(s.particles[a].position, s.particles[b].position)
}
