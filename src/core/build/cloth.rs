//! Rectangular cloth grids and the cloth-and-sphere scene.

use super::{BuildError, G, check_count, particle, spring};
use crate::core::collide::{ColliderDesc, ContactMaterial, ShapeDesc};
use crate::core::motion::Motion;
use crate::core::scene::{Scene, SpringKind, Surface};
use serde::{Deserialize, Serialize};

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
    /// Every particle of the border (a trampoline, a drum skin).
    Border,
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
        ClothPins::Border => {
            for i in 0..n {
                for j in 0..m {
                    if i == 0 || j == 0 || i == n - 1 || j == m - 1 {
                        pin(&mut s, i, j);
                    }
                }
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
        ..Default::default()
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
