use super::{BuildError, ClothParams, ClothPins, G, cloth};
use crate::core::collide::{ColliderDesc, ContactMaterial, ShapeDesc};
use crate::core::motion::Motion;
use crate::core::scene::Scene;
use crate::core::self_contact::SelfContactParams;
use serde::{Deserialize, Serialize};

/// Cloths dropped one above the other onto a sphere resting on the ground.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ClothPileParams {
    /// How many cloths.
    pub cloths: usize,
    /// Particles along each side of a cloth.
    pub resolution: usize,
    /// Side of a cloth (m).
    pub size: f64,
    /// Mass of a cloth (kg).
    pub mass: f64,
    /// Contact of the surfaces with themselves and each other (`None`: they pass through).
    pub self_collision: Option<SelfContactParams>,
    /// Sphere radius (m); it rests on the ground at the origin.
    pub radius: f64,
}

impl Default for ClothPileParams {
    fn default() -> Self {
        Self {
            cloths: 3,
            resolution: 32,
            size: 1.2,
            mass: 2.0,
            self_collision: Some(SelfContactParams {
                thickness: 0.008,
                friction: 0.3,
            }),
            radius: 0.3,
        }
    }
}

impl ClothPileParams {
    /// The same pile with `n × n` cloths and a thickness of a fifth of their edge.
    pub fn with_resolution(mut self, n: usize) -> Self {
        self.resolution = n;
        let edge = self.size / (n.max(2) - 1) as f64;
        if let Some(sc) = &mut self.self_collision {
            sc.thickness = 0.2 * edge;
        }
        self
    }

    /// A symplectic Euler step that is stable for these cloths: 1/1200 s for the 32² cloth
    /// (`h·2√(k/m) = 0.83`), shrinking as `(31/(n−1))^1.5` because `k ∝ n − 1` and `m ∝ 1/n²`.
    pub fn stable_step(&self) -> f64 {
        let scale = (self.resolution.max(2) - 1) as f64 / 31.0;
        1.0 / 1200.0 / scale.powf(1.5)
    }
}

/// The cloth pile: `cloths` lying cloths, the first 0.45 m above the sphere's top and each
/// next 0.12 m higher, off-centre by a quarter of a side (alternately in x and z) and turned
/// by 35° each, so they drape, fold onto themselves and onto each other, and pile on the
/// ground. Stretch springs `k = 500 N/m` at `m = 2 kg / 1024` per particle for the 32² cloth
/// (scaled with the resolution so the cloth's stiffness per metre stays the same), weak flex
/// springs, a little damping; gravity.
pub fn cloth_pile(p: &ClothPileParams) -> Result<Scene, BuildError> {
    if p.cloths == 0 {
        return Err(BuildError("cloth pile: needs at least one cloth".into()));
    }
    let n = p.resolution;
    let scale = (n.max(2) - 1) as f64 / 31.0;
    let particle_mass = p.mass / (n * n) as f64;
    let top = 2.0 * p.radius;
    let mut pile: Option<Scene> = None;
    for k in 0..p.cloths {
        let (dx, dz) = if k % 2 == 0 {
            (0.25 * p.size * 0.83, 0.04)
        } else {
            (-0.04, 0.25 * p.size * 0.83)
        };
        let y = top + 0.15 + 0.12 * k as f64;
        let mut c = cloth(&ClothParams {
            rows: n,
            cols: n,
            width: p.size,
            height: p.size,
            mass: particle_mass,
            // Stiffness of a chain of springs in series scales with the count: k·(n−1) fixed.
            k_structural: 500.0 * scale,
            k_shear: 200.0 * scale,
            k_flex: 5.0 * scale,
            damping: 0.02 * scale,
            drag: 0.002 / (scale * scale),
            pins: ClothPins::None,
            hanging: false,
            origin: [0.0, 0.0, 0.0],
        })?;
        let (s, co) = (35f64.to_radians() * k as f64).sin_cos();
        for q in &mut c.particles {
            let [x, _, z] = q.position;
            q.position = [co * x + s * z + dx, y, -s * x + co * z + dz];
        }
        pile = Some(match pile {
            None => c,
            Some(acc) => acc.append(c),
        });
    }
    let mut s = pile.expect("at least one cloth");
    s.name = "cloth_pile".into();
    s.gravity = [0.0, -G, 0.0];
    s.self_collision = p.self_collision;
    s.colliders = vec![
        ColliderDesc {
            shape: ShapeDesc::Plane {
                normal: [0.0, 1.0, 0.0],
            },
            motion: Motion::Fixed { position: [0.0; 3] },
            rotation: [0.0, 0.0, 0.0, 1.0],
            material: ContactMaterial {
                friction: 0.5,
                thickness: 0.005,
                ..Default::default()
            },
        },
        ColliderDesc {
            shape: ShapeDesc::Sphere { radius: p.radius },
            motion: Motion::Fixed {
                position: [0.0, p.radius, 0.0],
            },
            rotation: [0.0, 0.0, 0.0, 1.0],
            material: ContactMaterial {
                friction: 0.3,
                thickness: 0.005,
                ..Default::default()
            },
        },
    ];
    Ok(s)
}
