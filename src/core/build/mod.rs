//! Scene generators: pendulum, chain, cloth, the PhysBAM wire, the particle-system assignment's pyramid, a jelly
//! block and the cloth-and-sphere scene. Each returns a [`Scene`] (layout as data), so what a
//! generator makes can be saved, edited and loaded back.

use crate::core::collide::{ColliderDesc, ContactMaterial, ShapeDesc};
use crate::core::forces::SpringLaw;
use crate::core::motion::Motion;
use crate::core::scene::{
    MAX_PARTICLES, MotionDesc, ParticleDesc, Scene, SpringDesc, SpringKind, Surface,
};
use serde::{Deserialize, Serialize};

mod surface;
pub use surface::{SurfaceBody, SurfaceParams, SurfaceStiffness, surface_cloth};

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

/// Which cloth particles are held.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClothPins {
    /// The two corners of the first row.
    #[default]
    TwoCorners,
    /// The whole first row.
    TopEdge,
    /// The four corners.
    FourCorners,
    /// Nothing (the cloth falls).
    None,
}

/// A rectangular cloth of `rows × cols` particles with structural, shear and flex springs.
/// Row 0 is at the top (`+y`) when hanging, and at `-z` when lying flat.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ClothParams {
    /// Particles along a column (i index).
    pub rows: usize,
    /// Particles along a row (j index).
    pub cols: usize,
    /// Extent along rows (m).
    pub width: f64,
    /// Extent along columns (m).
    pub height: f64,
    /// Mass per particle (kg).
    pub mass: f64,
    /// Structural spring stiffness (N/m).
    pub k_structural: f64,
    /// Shear spring stiffness (N/m).
    pub k_shear: f64,
    /// Flex spring stiffness (N/m).
    pub k_flex: f64,
    /// Damper on every spring (N·s/m).
    pub damping: f64,
    /// Viscous drag (N·s/m).
    pub drag: f64,
    /// Held particles.
    pub pins: ClothPins,
    /// Hanging in the x–y plane (true) or lying in the x–z plane (false).
    pub hanging: bool,
    /// Centre of the top edge (hanging) or of the cloth (lying).
    pub origin: [f64; 3],
}

impl Default for ClothParams {
    /// The 16×16 cloth of the cloth assignment's claims: 1 m square, 10 g per particle.
    fn default() -> Self {
        Self {
            rows: 16,
            cols: 16,
            width: 1.0,
            height: 1.0,
            mass: 0.01,
            k_structural: 100.0,
            k_shear: 50.0,
            k_flex: 20.0,
            damping: 0.05,
            drag: 0.01,
            pins: ClothPins::TwoCorners,
            hanging: true,
            origin: [0.0, 1.0, 0.0],
        }
    }
}

impl ClothParams {
    /// Index of particle `(i, j)`: row `i`, column `j`.
    pub fn index_of(&self, i: usize, j: usize) -> usize {
        i * self.cols + j
    }

    /// Structural, shear and flex spring counts: `(N−1)M + N(M−1)`, `2(N−1)(M−1)`,
    /// `(N−2)M + N(M−2)`.
    pub fn spring_counts(&self) -> (usize, usize, usize) {
        let (n, m) = (self.rows, self.cols);
        (
            (n - 1) * m + n * (m - 1),
            2 * (n - 1) * (m - 1),
            (n - 2) * m + n * (m - 2),
        )
    }

    /// The same cloth material at another resolution: mass per particle scales with the area
    /// a particle covers and spring stiffness so that the sheet's stretch under a given load
    /// stays the same (springs in series), from this cloth as the reference.
    pub fn resized(&self, rows: usize, cols: usize) -> Self {
        let area = (self.rows * self.cols) as f64 / (rows * cols) as f64;
        let stretch = ((rows - 1) as f64 / (self.rows - 1) as f64
            + (cols - 1) as f64 / (self.cols - 1) as f64)
            / 2.0;
        // k per spring ∝ length⁻¹ for a fixed sheet stiffness; forces per row ∝ 1/count.
        let k = stretch * (self.rows + self.cols) as f64 / (rows + cols) as f64;
        Self {
            rows,
            cols,
            mass: self.mass * area,
            k_structural: self.k_structural * k,
            k_shear: self.k_shear * k,
            k_flex: self.k_flex * k,
            damping: self.damping * k,
            drag: self.drag * area,
            ..*self
        }
    }
}

/// A cloth grid.
pub fn cloth(p: &ClothParams) -> Result<Scene, BuildError> {
    if p.rows < 3 || p.cols < 3 {
        return Err(BuildError(format!(
            "cloth: needs at least 3×3 particles, got {}×{}",
            p.rows, p.cols
        )));
    }
    check_count("cloth", p.rows.saturating_mul(p.cols), 9)?;
    let (n, m) = (p.rows, p.cols);
    let mut s = Scene {
        name: "cloth".into(),
        gravity: [0.0, -G, 0.0],
        drag: p.drag,
        ..Default::default()
    };
    let o = p.origin;
    let mut uvs = Vec::with_capacity(n * m);
    for i in 0..n {
        for j in 0..m {
            let u = j as f64 / (m - 1) as f64;
            let v = i as f64 / (n - 1) as f64;
            let x = o[0] + (u - 0.5) * p.width;
            let pos = if p.hanging {
                [x, o[1] - v * p.height, o[2]]
            } else {
                [x, o[1], o[2] + (v - 0.5) * p.height]
            };
            s.particles.push(particle(pos, p.mass));
            uvs.push([u as f32, v as f32]);
        }
    }
    let idx = |i, j| p.index_of(i, j);
    let pin = |s: &mut Scene, i, j| s.particles[idx(i, j)].pinned = true;
    match p.pins {
        ClothPins::TwoCorners => {
            pin(&mut s, 0, 0);
            pin(&mut s, 0, m - 1);
        }
        ClothPins::TopEdge => (0..m).for_each(|j| pin(&mut s, 0, j)),
        ClothPins::FourCorners => {
            for (i, j) in [(0, 0), (0, m - 1), (n - 1, 0), (n - 1, m - 1)] {
                pin(&mut s, i, j);
            }
        }
        ClothPins::None => {}
    }
    let b = p.damping;
    for i in 0..n {
        for j in 0..m {
            if i + 1 < n {
                s.springs.push(spring(
                    idx(i, j),
                    idx(i + 1, j),
                    p.k_structural,
                    b,
                    SpringKind::Structural,
                ));
            }
            if j + 1 < m {
                s.springs.push(spring(
                    idx(i, j),
                    idx(i, j + 1),
                    p.k_structural,
                    b,
                    SpringKind::Structural,
                ));
            }
        }
    }
    for i in 0..n - 1 {
        for j in 0..m - 1 {
            s.springs.push(spring(
                idx(i, j),
                idx(i + 1, j + 1),
                p.k_shear,
                b,
                SpringKind::Shear,
            ));
            s.springs.push(spring(
                idx(i, j + 1),
                idx(i + 1, j),
                p.k_shear,
                b,
                SpringKind::Shear,
            ));
        }
    }
    for i in 0..n {
        for j in 0..m {
            if i + 2 < n {
                s.springs.push(spring(
                    idx(i, j),
                    idx(i + 2, j),
                    p.k_flex,
                    b,
                    SpringKind::Flex,
                ));
            }
            if j + 2 < m {
                s.springs.push(spring(
                    idx(i, j),
                    idx(i, j + 2),
                    p.k_flex,
                    b,
                    SpringKind::Flex,
                ));
            }
        }
    }
    let mut tris = Vec::with_capacity(2 * (n - 1) * (m - 1));
    for i in 0..n - 1 {
        for j in 0..m - 1 {
            let (a, b, c, d) = (
                idx(i, j) as u32,
                idx(i, j + 1) as u32,
                idx(i + 1, j) as u32,
                idx(i + 1, j + 1) as u32,
            );
            // Counter-clockwise seen from +z (hanging) and from +y (lying).
            tris.push([a, c, b]);
            tris.push([b, c, d]);
        }
    }
    s.surface = Some(Surface {
        triangles: tris,
        uvs,
    });
    Ok(s)
}

/// The cloth-and-sphere scene: a hanging cloth held by its top corners and a sphere swinging
/// back and forth through it along z, starting at rest behind it (`z = −amplitude`: the scene
/// begins with nothing in contact, so every method and driver sees the same first impact).
pub fn cloth_sphere(
    p: &ClothParams,
    radius: f64,
    amplitude: f64,
    period: f64,
) -> Result<Scene, BuildError> {
    let mut s = cloth(p)?;
    s.name = "cloth_sphere".into();
    let center = [p.origin[0], p.origin[1] - 0.55 * p.height, p.origin[2]];
    s.colliders.push(ColliderDesc {
        shape: ShapeDesc::Sphere { radius },
        motion: Motion::Oscillate {
            center,
            amplitude: [0.0, 0.0, amplitude],
            omega: std::f64::consts::TAU / period,
            phase: -std::f64::consts::FRAC_PI_2,
        },
        rotation: [0.0, 0.0, 0.0, 1.0],
        material: ContactMaterial {
            friction: 0.2,
            restitution: 0.0,
            thickness: 0.02,
            bounce_threshold: 0.05,
        },
    });
    Ok(s)
}

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
        uvs: Vec::new(),
    });
    s.colliders.push(ground(0.0, p.restitution, p.friction));
    Ok(s)
}

/// Distance between two particles of a scene (used by tests and tools).
pub fn particle_distance(s: &Scene, a: usize, b: usize) -> f64 {
    dist(s.particles[a].position, s.particles[b].position)
}

/// A tet mesh as an elastic body hung by its top: vertices above 95 % of the mesh's highest
/// y are pinned, every other one moves sideways at `kick · y` m/s (y the height above y = 0,
/// where the shipped meshes stand): the swinging armadillo of the FEM bench, the yank of the
/// stiff-armadillo test and `fem_study`.
pub fn hung_tet_body(
    mesh: &crate::core::fem::mesh::TetMesh,
    material: crate::core::fem::NeoHookean,
    kick: f64,
) -> Scene {
    let mut scene = mesh.to_scene("hung body", material);
    let top = mesh.bounds().1[1];
    for p in &mut scene.particles {
        if p.position[1] > 0.95 * top {
            p.pinned = true;
        } else {
            p.velocity = [kick * p.position[1], 0.0, 0.0];
        }
    }
    scene
}
