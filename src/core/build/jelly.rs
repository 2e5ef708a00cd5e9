//! Jelly blocks.

use super::{BuildError, G, check_count, ground, particle, spring};
use crate::core::scene::{Scene, SpringKind, Surface};
use serde::{Deserialize, Serialize};

/// A jelly block: a 3D grid with structural (axis), shear (face and body diagonals) and flex
/// (skip-one) springs, its boundary drawn as a surface, above a ground plane.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct JellyParams {
    /// Particles along x, y, z.
    pub size: [usize; 3],
    /// Grid spacing (m).
    pub spacing: f64,
    /// Mass per particle (kg).
    pub mass: f64,
    /// Stiffness of structural, shear and flex springs (N/m).
    pub stiffness: [f64; 3],
    /// Damper on every spring (N·s/m).
    pub damping: f64,
    /// Height of the block's bottom above the ground (m).
    pub drop_height: f64,
    /// Ground restitution.
    pub restitution: f64,
    /// Ground friction.
    pub friction: f64,
}

impl Default for JellyParams {
    fn default() -> Self {
        Self {
            size: [6, 6, 6],
            spacing: 0.1,
            mass: 0.01,
            stiffness: [60.0, 30.0, 15.0],
            damping: 0.05,
            drop_height: 0.8,
            restitution: 0.5,
            friction: 0.5,
        }
    }
}

/// A jelly block.
pub fn jelly(p: &JellyParams) -> Result<Scene, BuildError> {
    let [nx, ny, nz] = p.size;
    if nx < 2 || ny < 2 || nz < 2 {
        return Err(BuildError(
            "jelly: needs at least 2 particles along each axis".into(),
        ));
    }
    check_count("jelly", nx.saturating_mul(ny).saturating_mul(nz), 8)?;
    let mut s = Scene {
        name: "jelly".into(),
        gravity: [0.0, -G, 0.0],
        ..Default::default()
    };
    let id = |x: usize, y: usize, z: usize| (x * ny + y) * nz + z;
    let h = p.spacing;
    let half = [(nx - 1) as f64 * h / 2.0, 0.0, (nz - 1) as f64 * h / 2.0];
    for x in 0..nx {
        for y in 0..ny {
            for z in 0..nz {
                s.particles.push(particle(
                    [
                        x as f64 * h - half[0],
                        p.drop_height + y as f64 * h,
                        z as f64 * h - half[2],
                    ],
                    p.mass,
                ));
            }
        }
    }
    let dims = [nx as isize, ny as isize, nz as isize];
    let inside = |c: [isize; 3]| (0..3).all(|k| c[k] >= 0 && c[k] < dims[k]);
    for x in 0..nx {
        for y in 0..ny {
            for z in 0..nz {
                let a = id(x, y, z);
                let c = [x as isize, y as isize, z as isize];
                // The 13 "forward" neighbour offsets of the 26-neighbourhood.
                for dx in -1isize..=1 {
                    for dy in -1isize..=1 {
                        for dz in -1isize..=1 {
                            let o = [dx, dy, dz];
                            if o.iter().map(|v| v.abs()).sum::<isize>() == 0 || o <= [0, 0, 0] {
                                continue;
                            }
                            let q = [c[0] + dx, c[1] + dy, c[2] + dz];
                            if !inside(q) {
                                continue;
                            }
                            let nonzero = o.iter().filter(|v| **v != 0).count();
                            let (k, kind) = if nonzero == 1 {
                                (p.stiffness[0], SpringKind::Structural)
                            } else {
                                (p.stiffness[1], SpringKind::Shear)
                            };
                            s.springs.push(spring(
                                a,
                                id(q[0] as usize, q[1] as usize, q[2] as usize),
                                k,
                                p.damping,
                                kind,
                            ));
                        }
                    }
                }
                for axis in 0..3 {
                    let mut q = c;
                    q[axis] += 2;
                    if inside(q) {
                        s.springs.push(spring(
                            a,
                            id(q[0] as usize, q[1] as usize, q[2] as usize),
                            p.stiffness[2],
                            p.damping,
                            SpringKind::Flex,
                        ));
                    }
                }
            }
        }
    }
    // Boundary faces, outward and counter-clockwise.
    let mut tris = Vec::new();
    let mut quad = |a: usize, b: usize, c: usize, d: usize| {
        tris.push([a as u32, b as u32, c as u32]);
        tris.push([a as u32, c as u32, d as u32]);
    };
    for y in 0..ny - 1 {
        for z in 0..nz - 1 {
            quad(
                id(0, y, z),
                id(0, y, z + 1),
                id(0, y + 1, z + 1),
                id(0, y + 1, z),
            );
            let x = nx - 1;
            quad(
                id(x, y, z),
                id(x, y + 1, z),
                id(x, y + 1, z + 1),
                id(x, y, z + 1),
            );
        }
    }
    for x in 0..nx - 1 {
        for z in 0..nz - 1 {
            quad(
                id(x, 0, z),
                id(x + 1, 0, z),
                id(x + 1, 0, z + 1),
                id(x, 0, z + 1),
            );
            let y = ny - 1;
            quad(
                id(x, y, z),
                id(x, y, z + 1),
                id(x + 1, y, z + 1),
                id(x + 1, y, z),
            );
        }
    }
    for x in 0..nx - 1 {
        for y in 0..ny - 1 {
            quad(
                id(x, y, 0),
                id(x, y + 1, 0),
                id(x + 1, y + 1, 0),
                id(x + 1, y, 0),
            );
            let z = nz - 1;
            quad(
                id(x, y, z),
                id(x + 1, y, z),
                id(x + 1, y + 1, z),
                id(x, y + 1, z),
            );
        }
    }
    s.surface = Some(Surface {
        triangles: tris,
        ..Default::default()
    });
    s.colliders.push(ground(0.0, p.restitution, p.friction));
    Ok(s)
}
