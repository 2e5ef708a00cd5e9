//! The PhysBAM slides' wire.

use super::{BuildError, G, check_count, particle};
use crate::core::forces::SpringLaw;
use crate::core::motion::Motion;
use crate::core::scene::{MotionDesc, Scene, SpringDesc, SpringKind};

/// The PhysBAM slides' wire: `n` particles (11), total mass 1, length 1, strain-law springs of
/// "Young's modulus" 10 N with dampers of 10 N·s/m, hanging from an endpoint that moves on a
/// circle of radius 0.5 with angular velocity `2π / (frame_time · frames)`.
pub fn wire(n: usize, frame_time: f64, frames: u32) -> Result<Scene, BuildError> {
    check_count("wire", n, 2)?;
    let mass = 1.0 / n as f64;
    let rest = 1.0 / (n - 1) as f64;
    let mut s = Scene {
        name: "wire".into(),
        gravity: [0.0, -G, 0.0],
        ..Default::default()
    };
    for p in 0..n {
        s.particles
            .push(particle([0.0, -(p as f64) * rest, 0.5], mass));
        if p > 0 {
            s.springs.push(SpringDesc {
                a: p - 1,
                b: p,
                stiffness: 10.0,
                damping: 10.0,
                rest_length: Some(rest),
                law: SpringLaw::Strain,
                kind: SpringKind::Structural,
            });
        }
    }
    s.motions.push(MotionDesc {
        particle: 0,
        motion: Motion::physbam_wire_endpoint(frame_time * frames as f64),
    });
    Ok(s)
}
