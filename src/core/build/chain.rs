//! The circle's start, pendulum chains and the single pendulum.

use super::{BuildError, G, check_count, particle, spring};
use crate::core::scene::{ParticleDesc, Scene, SpringKind};
use serde::{Deserialize, Serialize};

/// The circle system's usual start, `(1, 0, 0)`.
pub fn circle_start() -> [f64; 3] {
    [1.0, 0.0, 0.0]
}

/// A chain of particles hanging from a fixed first particle.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ChainParams {
    /// Particles including the fixed one (4 in the cloth assignment).
    pub particles: usize,
    /// Link length (m).
    pub link: f64,
    /// Mass per free particle (kg).
    pub mass: f64,
    /// Spring stiffness (N/m).
    pub stiffness: f64,
    /// Spring damping (N·s/m).
    pub damping: f64,
    /// Viscous drag (N·s/m).
    pub drag: f64,
    /// Initial direction of the chain from the fixed particle (normalised); horizontal makes
    /// it swing.
    pub direction: [f64; 3],
    /// Gravity on.
    pub gravity: bool,
}

impl Default for ChainParams {
    fn default() -> Self {
        Self {
            particles: 4,
            link: 0.25,
            mass: 0.1,
            stiffness: 200.0,
            damping: 0.0,
            drag: 0.01,
            direction: [1.0, 0.0, 0.0],
            gravity: true,
        }
    }
}

/// A pendulum chain: particle 0 fixed at the origin, the others along `direction`.
pub fn chain(p: &ChainParams) -> Result<Scene, BuildError> {
    check_count("chain", p.particles, 2)?;
    let d = p.direction;
    let dn = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let d = if dn > 0.0 {
        [d[0] / dn, d[1] / dn, d[2] / dn]
    } else {
        [0.0, -1.0, 0.0]
    };
    let mut s = Scene {
        name: "pendulum".into(),
        drag: p.drag,
        ..Default::default()
    };
    if p.gravity {
        s.gravity = [0.0, -G, 0.0];
    }
    for i in 0..p.particles {
        let r = p.link * i as f64;
        let mut q = particle([d[0] * r, d[1] * r, d[2] * r], p.mass);
        q.pinned = i == 0;
        s.particles.push(q);
        if i > 0 {
            s.springs.push(spring(
                i - 1,
                i,
                p.stiffness,
                p.damping,
                SpringKind::Structural,
            ));
        }
    }
    Ok(s)
}

/// A single pendulum: one particle on a stiff spring of length `length` from a fixed point,
/// started at angle `angle` (rad) from the vertical, in the x–y plane.
pub fn pendulum(length: f64, mass: f64, stiffness: f64, angle: f64) -> Scene {
    let mut s = Scene {
        name: "single_pendulum".into(),
        gravity: [0.0, -G, 0.0],
        ..Default::default()
    };
    s.particles.push(ParticleDesc {
        position: [0.0; 3],
        velocity: [0.0; 3],
        mass,
        pinned: true,
    });
    // Start at the static stretch so that the spring does not bounce: L_rest = L − m g / k.
    let rest = length - mass * G / stiffness;
    s.particles.push(particle(
        [length * angle.sin(), -length * angle.cos(), 0.0],
        mass,
    ));
    let mut sp = spring(0, 1, stiffness, 0.0, SpringKind::Structural);
    sp.rest_length = Some(rest);
    s.springs.push(sp);
    s
}
