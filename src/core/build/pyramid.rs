//! The particle-system assignment's pyramid and the ground plane.

use super::{BuildError, G, check_count, particle, spring};
use crate::core::collide::{ColliderDesc, ContactMaterial, ShapeDesc};
use crate::core::motion::Motion;
use crate::core::scene::{Scene, SpringKind};

/// The particle-system assignment's pyramid: layer `k` (1 at the apex) holds `k×k` particles; springs join every
/// pair of particles on a common row, column or diagonal of a layer, and each particle to the
/// four corners of the square below it in every lower layer. Dropped from `drop_height` onto
/// a ground plane with restitution 0.8 and friction 0.3.
pub fn pyramid(
    layers: usize,
    spacing: f64,
    mass: f64,
    stiffness: f64,
    damping: f64,
    drop_height: f64,
) -> Result<Scene, BuildError> {
    let count: usize = (1..=layers).map(|k| k * k).sum();
    check_count("pyramid", count, 1)?;
    let mut s = Scene {
        name: "pyramid".into(),
        gravity: [0.0, -G, 0.0],
        ..Default::default()
    };
    let layer_h = spacing / std::f64::consts::SQRT_2;
    let mut start = Vec::with_capacity(layers + 1);
    for k in 1..=layers {
        start.push(s.particles.len());
        let y = drop_height + (layers - k) as f64 * layer_h;
        for i in 0..k {
            for j in 0..k {
                let x = (i as f64 - (k - 1) as f64 / 2.0) * spacing;
                let z = (j as f64 - (k - 1) as f64 / 2.0) * spacing;
                s.particles.push(particle([x, y, z], mass));
            }
        }
    }
    let id = |k: usize, i: usize, j: usize| start[k - 1] + i * k + j;
    for k in 1..=layers {
        for i in 0..k {
            for j in 0..k {
                let a = id(k, i, j);
                // Same layer: all further particles along the row, column and diagonals.
                for d in 1..k {
                    if i + d < k {
                        s.springs.push(spring(
                            a,
                            id(k, i + d, j),
                            stiffness,
                            damping,
                            SpringKind::Structural,
                        ));
                    }
                    if j + d < k {
                        s.springs.push(spring(
                            a,
                            id(k, i, j + d),
                            stiffness,
                            damping,
                            SpringKind::Structural,
                        ));
                    }
                    if i + d < k && j + d < k {
                        s.springs.push(spring(
                            a,
                            id(k, i + d, j + d),
                            stiffness,
                            damping,
                            SpringKind::Shear,
                        ));
                    }
                    if i + d < k && j >= d {
                        s.springs.push(spring(
                            a,
                            id(k, i + d, j - d),
                            stiffness,
                            damping,
                            SpringKind::Shear,
                        ));
                    }
                }
                // Lower layers: the corners of the square of side d below.
                for d in 1..=layers - k {
                    let kk = k + d;
                    for (di, dj) in [(0, 0), (d, 0), (0, d), (d, d)] {
                        s.springs.push(spring(
                            a,
                            id(kk, i + di, j + dj),
                            stiffness,
                            damping,
                            SpringKind::Structural,
                        ));
                    }
                }
            }
        }
    }
    s.colliders.push(ground(0.0, 0.8, 0.3));
    Ok(s)
}

/// A ground plane `y = height`.
pub fn ground(height: f64, restitution: f64, friction: f64) -> ColliderDesc {
    ColliderDesc {
        shape: ShapeDesc::Plane {
            normal: [0.0, 1.0, 0.0],
        },
        motion: Motion::Fixed {
            position: [0.0, height, 0.0],
        },
        rotation: [0.0, 0.0, 0.0, 1.0],
        material: ContactMaterial {
            friction,
            restitution,
            thickness: 0.0,
            bounce_threshold: 0.05,
        },
    }
}
