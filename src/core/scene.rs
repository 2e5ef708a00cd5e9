//! Scenes as data: everything a simulation starts from (particles, masses, pins, springs,
//! forces, colliders, initial state), readable from and writable to JSON. Numbers are stored
//! as `f64` whatever the crate's precision, so a JSON round trip is exact.

use crate::core::collide::{Collider, ColliderDesc};
use crate::core::fem::NeoHookean;
use crate::core::forces::{SpringLaw, Wind};
use crate::core::layout::{
    Anchor, BodyLayout, LayoutItem, LayoutParticle, LayoutSpring, LayoutTet,
};
use crate::core::motion::Motion;
use crate::core::ode::ParticleState;
use crate::core::particles::ParticleModel;
use crate::core::self_contact::SelfContactParams;
use serde::{Deserialize, Serialize};
use std::fmt;

/// One particle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParticleDesc {
    /// Initial position (m).
    pub position: [f64; 3],
    /// Initial velocity (m/s).
    #[serde(default)]
    pub velocity: [f64; 3],
    /// Mass (kg); may be zero for pinned or prescribed particles.
    pub mass: f64,
    /// Held fixed at its initial position.
    #[serde(default)]
    pub pinned: bool,
}

/// What a spring is for (builders tag them; the physics does not care).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpringKind {
    /// Grid neighbours.
    #[default]
    Structural,
    /// Diagonals.
    Shear,
    /// Skip-one neighbours (bending).
    Flex,
}

/// One spring.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpringDesc {
    /// First particle index.
    pub a: usize,
    /// Second particle index.
    pub b: usize,
    /// Stiffness: N/m for Hooke, N for strain.
    pub stiffness: f64,
    /// Damper along the spring (N·s/m).
    #[serde(default)]
    pub damping: f64,
    /// Rest length; the initial distance when absent.
    #[serde(default)]
    pub rest_length: Option<f64>,
    /// Force law.
    #[serde(default)]
    pub law: SpringLaw,
    /// Role in the layout.
    #[serde(default)]
    pub kind: SpringKind,
}

/// A particle moved along a prescribed path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionDesc {
    /// Particle index.
    pub particle: usize,
    /// Its path.
    pub motion: Motion,
}

/// A constant force on one particle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceDesc {
    /// Particle index.
    pub particle: usize,
    /// Force (N).
    pub force: [f64; 3],
}

/// One linear tetrahedron of neo-Hookean material. Its rest shape (`rest`, or else the initial
/// positions of its four particles) must have positive volume
/// (`dot(b − a, (c − a) × (d − a)) > 0`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TetDesc {
    /// Particle indices.
    pub vertices: [usize; 4],
    /// Its own material; the scene's `material` when absent.
    #[serde(default)]
    pub material: Option<NeoHookean>,
    /// Its rest shape (the four corners' rest positions, m); the particles' initial positions
    /// when absent. Tearing sets it, so that a torn body rebuilt from its current state keeps
    /// its tets' rest shapes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rest: Option<[[f64; 3]; 4]>,
}

/// A surface to draw: triangles over particle indices, with optional texture coordinates
/// (one per particle).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Surface {
    /// Counter-clockwise triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Texture coordinates per particle (empty: none).
    #[serde(default)]
    pub uvs: Vec<[f32; 2]>,
    /// For each particle, the particle it was split from by tearing (itself if never split;
    /// empty: nothing torn). Self-collision's broad phase never culls a patch that reaches a
    /// cut ([`ContactSurface`](crate::core::self_contact::ContactSurface)).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub torn_from: Vec<u32>,
}

impl Surface {
    /// `torn_from` for `n` particles, filled in as "never split" if it was empty.
    pub fn torn_from_mut(&mut self, n: usize) -> &mut Vec<u32> {
        if self.torn_from.len() < n {
            let from = self.torn_from.len() as u32;
            self.torn_from.extend(from..n as u32);
        }
        &mut self.torn_from
    }
}

/// A whole layout.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Name, for logs and file names.
    #[serde(default)]
    pub name: String,
    /// Gravitational acceleration (m/s²).
    #[serde(default)]
    pub gravity: [f64; 3],
    /// Viscous drag coefficient (N·s/m) on every particle.
    #[serde(default)]
    pub drag: f64,
    /// Particles.
    pub particles: Vec<ParticleDesc>,
    /// Springs.
    #[serde(default)]
    pub springs: Vec<SpringDesc>,
    /// Linear tetrahedra (volumetric finite elements).
    #[serde(default)]
    pub tets: Vec<TetDesc>,
    /// Material of tets without their own.
    #[serde(default)]
    pub material: Option<NeoHookean>,
    /// Particles with prescribed motion.
    #[serde(default)]
    pub motions: Vec<MotionDesc>,
    /// Constant external forces.
    #[serde(default)]
    pub forces: Vec<ForceDesc>,
    /// Wind.
    #[serde(default)]
    pub wind: Option<Wind>,
    /// Colliders.
    #[serde(default)]
    pub colliders: Vec<ColliderDesc>,
    /// Surface to draw.
    #[serde(default)]
    pub surface: Option<Surface>,
    /// Contact of the surface with itself (and, in one scene, of its parts with each other).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub self_collision: Option<SelfContactParams>,
    /// Springs break past this strain and the surface tears along them
    /// ([`crate::core::tear`]; `None`: nothing breaks).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tearing: Option<crate::core::tear::TearParams>,
}

/// One problem found in a scene, with the path of the field (`springs[3].b`).
#[derive(Clone, Debug, PartialEq)]
pub struct FieldError {
    /// Where.
    pub path: String,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for FieldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path, self.message)
    }
}

/// Every problem found in a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneError {
    /// The problems, in document order.
    pub errors: Vec<FieldError>,
}

impl SceneError {
    /// True when some error's path is `path`.
    pub fn has(&self, path: &str) -> bool {
        self.errors.iter().any(|e| e.path == path)
    }
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "invalid scene ({} problem{})",
            self.errors.len(),
            if self.errors.len() == 1 { "" } else { "s" }
        )?;
        for e in &self.errors {
            write!(f, "\n  {e}")?;
        }
        Ok(())
    }
}

impl std::error::Error for SceneError {}

/// Largest scene the builders and the reader accept (particles), so that a typo cannot ask
/// for all the machine's memory.
pub const MAX_PARTICLES: usize = 4_000_000;
/// Largest number of springs accepted.
pub const MAX_SPRINGS: usize = 40_000_000;

impl Scene {
    /// Reads a scene from JSON and validates it. Syntax errors report line and column; every
    /// invalid field is reported with its path.
    pub fn from_json(text: &str) -> Result<Scene, SceneError> {
        let scene: Scene = serde_json::from_str(text).map_err(|e| SceneError {
            errors: vec![FieldError {
                path: format!("line {}, column {}", e.line(), e.column()),
                message: e.to_string(),
            }],
        })?;
        scene.validate()?;
        Ok(scene)
    }

    /// Writes pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a scene always serializes")
    }

    /// Checks every field; returns all problems at once.
    pub fn validate(&self) -> Result<(), SceneError> {
        let mut errs = Vec::new();
        let mut err = |path: String, message: &str| {
            errs.push(FieldError {
                path,
                message: message.to_string(),
            })
        };
        let n = self.particles.len();
        if n > MAX_PARTICLES {
            err(
                "particles".into(),
                &format!("{n} particles is more than the limit of {MAX_PARTICLES}"),
            );
        }
        if self.springs.len() > MAX_SPRINGS {
            err(
                "springs".into(),
                &format!("more than the limit of {MAX_SPRINGS} springs"),
            );
        }
        for (k, m) in self.motions.iter().enumerate() {
            if m.particle >= n {
                err(format!("motions[{k}].particle"), "index out of range");
            }
        }
        // The body's own rules live in one place, shared with the plugin.
        for e in self.layout().validate() {
            let path = match e.item {
                LayoutItem::Body => e.field.to_string(),
                LayoutItem::Particle(i) if e.field == "motion" => {
                    match self.motions.iter().rposition(|m| m.particle == i) {
                        Some(k) => format!("motions[{k}].motion"),
                        None => format!("particles[{i}]"),
                    }
                }
                LayoutItem::Particle(i) => format!("particles[{i}].{}", e.field),
                LayoutItem::Spring(k) => format!("springs[{k}].{}", e.field),
                LayoutItem::Tet(k) if e.field.is_empty() => format!("tets[{k}]"),
                LayoutItem::Tet(k) => format!("tets[{k}].{}", e.field),
                LayoutItem::Force(k) => format!("forces[{k}].{}", e.field),
            };
            err(path, &e.message);
        }
        if let Some(t) = &self.tearing
            && let Err((field, message)) = t.validate()
        {
            err(format!("tearing.{field}"), &message);
        }
        for (k, c) in self.colliders.iter().enumerate() {
            if !c.shape.is_valid() {
                err(
                    format!("colliders[{k}].shape"),
                    "dimensions must be finite and positive",
                );
            }
            if !c.motion.is_finite() {
                err(format!("colliders[{k}].motion"), "must be finite");
            }
            let q = c.rotation;
            let qn: f64 = q.iter().map(|x| x * x).sum();
            if !(qn.is_finite() && qn > 1e-12) {
                err(
                    format!("colliders[{k}].rotation"),
                    "must be a finite non-zero quaternion",
                );
            }
            let m = &c.material;
            for (name, v) in [
                ("friction", m.friction),
                ("restitution", m.restitution),
                ("thickness", m.thickness),
                ("bounce_threshold", m.bounce_threshold),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    err(
                        format!("colliders[{k}].material.{name}"),
                        "must be finite and non-negative",
                    );
                }
            }
        }
        if let Some(s) = &self.surface {
            for (k, t) in s.triangles.iter().enumerate() {
                if t.iter().any(|&i| i as usize >= n) {
                    err(format!("surface.triangles[{k}]"), "index out of range");
                }
            }
            if !s.uvs.is_empty() && s.uvs.len() != n {
                err("surface.uvs".into(), "needs one entry per particle");
            }
            if !s.torn_from.is_empty() && s.torn_from.len() != n {
                err("surface.torn_from".into(), "needs one entry per particle");
            }
            if let Some(k) = s.torn_from.iter().position(|&i| i as usize >= n) {
                err(format!("surface.torn_from[{k}]"), "index out of range");
            }
        }
        if errs.is_empty() {
            Ok(())
        } else {
            Err(SceneError { errors: errs })
        }
    }

    /// Rest length of spring `k` (given, or the initial distance).
    pub fn rest_length(&self, k: usize) -> f64 {
        let s = &self.springs[k];
        s.rest_length.unwrap_or_else(|| {
            let (a, b) = (self.particles[s.a].position, self.particles[s.b].position);
            (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt()
        })
    }

    /// Rest shape of tet `k` (given, or its particles' initial positions).
    pub fn tet_rest(&self, k: usize) -> [glam::DVec3; 4] {
        let t = &self.tets[k];
        t.rest
            .unwrap_or_else(|| t.vertices.map(|i| self.particles[i].position))
            .map(glam::DVec3::from_array)
    }

    /// The scene's body as a [`BodyLayout`] (motions with an out-of-range particle are left
    /// out: [`Scene::validate`] reports them). A particle with a motion is moved by it, pinned
    /// or not.
    pub fn layout(&self) -> BodyLayout {
        let mut particles: Vec<LayoutParticle> = self
            .particles
            .iter()
            .map(|p| LayoutParticle {
                position: p.position,
                velocity: p.velocity,
                mass: p.mass,
                anchor: if p.pinned {
                    Anchor::Pinned
                } else {
                    Anchor::Free
                },
            })
            .collect();
        for m in &self.motions {
            if let Some(p) = particles.get_mut(m.particle) {
                p.anchor = Anchor::Moving(m.motion);
            }
        }
        BodyLayout {
            particles,
            springs: self
                .springs
                .iter()
                .map(|s| LayoutSpring {
                    a: s.a,
                    b: s.b,
                    rest_length: s.rest_length,
                    stiffness: s.stiffness,
                    damping: s.damping,
                    law: s.law,
                })
                .collect(),
            tets: self
                .tets
                .iter()
                .map(|t| LayoutTet {
                    vertices: t.vertices,
                    rest: t.rest.map(|r| r.map(glam::DVec3::from_array)),
                    material: t.material,
                })
                .collect(),
            material: self.material,
            forces: self.forces.iter().map(|f| (f.particle, f.force)).collect(),
            gravity: self.gravity,
            drag: self.drag,
            wind: self.wind,
            // Without a surface, contact takes the tets' boundary.
            surface: self
                .surface
                .as_ref()
                .map_or(vec![], |s| s.triangles.clone()),
            self_collision: self.self_collision,
            torn_from: self
                .surface
                .as_ref()
                .map_or(vec![], |s| s.torn_from.clone()),
        }
    }

    /// The initial state, as [`Scene::build`] makes it (pinned particles at rest).
    pub fn initial_state(&self) -> ParticleState {
        self.layout().initial_state()
    }

    /// The same scene moved by `offset`: particles, prescribed paths and colliders (to place
    /// several scenes side by side).
    pub fn translated(mut self, offset: [f64; 3]) -> Self {
        for p in &mut self.particles {
            for (c, o) in p.position.iter_mut().zip(offset) {
                *c += o;
            }
        }
        for r in self.tets.iter_mut().filter_map(|t| t.rest.as_mut()) {
            for p in r {
                for (c, o) in p.iter_mut().zip(offset) {
                    *c += o;
                }
            }
        }
        for m in &mut self.motions {
            m.motion = m.motion.translated(offset);
        }
        for c in &mut self.colliders {
            c.motion = c.motion.translated(offset);
        }
        self
    }

    /// This scene with `other`'s parts added after its own (particle indices of `other`
    /// shifted): several bodies stepped as one model, so that with `self_collision` their
    /// surfaces collide with each other as well as with themselves. Gravity, drag, wind,
    /// material and self-collision settings are this scene's (`other`'s self-collision when
    /// this one has none).
    pub fn append(mut self, other: Scene) -> Self {
        let off = self.particles.len();
        let had_uvs = self.surface.as_ref().is_some_and(|s| !s.uvs.is_empty());
        self.particles.extend(other.particles);
        self.springs.extend(other.springs.into_iter().map(|mut s| {
            s.a += off;
            s.b += off;
            s
        }));
        self.tets.extend(other.tets.into_iter().map(|mut t| {
            t.vertices = t.vertices.map(|v| v + off);
            t
        }));
        self.motions.extend(other.motions.into_iter().map(|mut m| {
            m.particle += off;
            m
        }));
        self.forces.extend(other.forces.into_iter().map(|mut f| {
            f.particle += off;
            f
        }));
        self.colliders.extend(other.colliders);
        if let Some(o) = other.surface {
            let mine = self.surface.get_or_insert_with(Surface::default);
            let other_uvs = !o.uvs.is_empty();
            if had_uvs || other_uvs {
                // One texture coordinate per particle: fill what a part lacks with zeros.
                mine.uvs.resize(off, [0.0; 2]);
                mine.uvs.extend(o.uvs);
                mine.uvs.resize(self.particles.len(), [0.0; 2]);
            }
            let o32 = off as u32;
            mine.triangles
                .extend(o.triangles.into_iter().map(|t| t.map(|i| i + o32)));
            if !(mine.torn_from.is_empty() && o.torn_from.is_empty()) {
                mine.torn_from_mut(off).truncate(off);
                mine.torn_from
                    .extend(o.torn_from.into_iter().map(|i| i + o32));
                let n = self.particles.len();
                mine.torn_from_mut(n);
            }
        }
        self.self_collision = self.self_collision.or(other.self_collision);
        self.tearing = self.tearing.or(other.tearing);
        self
    }

    /// The part of this scene made of the particles in `range` (what [`Scene::append`] put
    /// together, taken apart): those particles, and the springs, tets, motions, forces and
    /// surface triangles among them alone, renumbered from zero; everything else (gravity,
    /// colliders, settings) as in this scene.
    pub fn part(&self, range: std::ops::Range<usize>) -> Scene {
        let lo = range.start;
        let inside = |i: usize| range.contains(&i);
        let mut s = self.clone();
        s.particles = self.particles[range.clone()].to_vec();
        s.springs = self
            .springs
            .iter()
            .filter(|sp| inside(sp.a) && inside(sp.b))
            .map(|sp| SpringDesc {
                a: sp.a - lo,
                b: sp.b - lo,
                ..sp.clone()
            })
            .collect();
        s.tets = self
            .tets
            .iter()
            .filter(|t| t.vertices.iter().all(|&v| inside(v)))
            .map(|t| TetDesc {
                vertices: t.vertices.map(|v| v - lo),
                ..t.clone()
            })
            .collect();
        s.motions.retain(|m| inside(m.particle));
        s.motions.iter_mut().for_each(|m| m.particle -= lo);
        s.forces.retain(|f| inside(f.particle));
        s.forces.iter_mut().for_each(|f| f.particle -= lo);
        if let Some(surf) = &mut s.surface {
            surf.triangles
                .retain(|t| t.iter().all(|&i| inside(i as usize)));
            for t in &mut surf.triangles {
                *t = t.map(|i| i - lo as u32);
            }
            if !surf.uvs.is_empty() {
                surf.uvs = surf.uvs[range.clone()].to_vec();
            }
            if !surf.torn_from.is_empty() {
                // A particle torn from one outside the part is its own.
                surf.torn_from = range
                    .clone()
                    .map(|i| match surf.torn_from[i] as usize {
                        o if inside(o) => (o - lo) as u32,
                        _ => (i - lo) as u32,
                    })
                    .collect();
            }
        }
        s
    }

    /// Validates and builds the model and its initial state, through the same
    /// [`BodyLayout::build`] the plugin uses; then adds the scene's colliders.
    pub fn build(&self) -> Result<(ParticleModel, ParticleState), SceneError> {
        self.validate()?;
        let (mut model, state) = self.layout().build().map_err(|errs| SceneError {
            errors: errs
                .into_iter()
                .map(|e| FieldError {
                    path: "model".into(),
                    message: e.to_string(),
                })
                .collect(),
        })?;
        model.colliders = self.colliders.iter().map(Collider::from_desc).collect();
        Ok((model, state))
    }
}
