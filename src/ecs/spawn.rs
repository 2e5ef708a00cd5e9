//! Spawning whole bodies from the core's scene layouts (builders or JSON files).

use super::components::*;
use crate::core::scene::{Scene, SceneError};
use crate::render::SoftBodySurface;
use bevy::prelude::*;

fn v(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0] as f32, a[1] as f32, a[2] as f32)
}

/// Spawns soft bodies from [`Scene`] layouts.
pub trait SpawnSoftBody {
    /// Spawns the scene as one body: a root with `body` (its gravity and drag taken from the
    /// scene), a [`Particle`] entity per particle (pinned ones [`Pinned`]), a [`Spring`] entity
    /// per spring, [`ExternalForce`]s, [`SoftBodyWind`], a [`SoftBodySurface`] when the scene
    /// has one, and a [`SoftBodyCollider`] entity per collider (moved by [`ScriptedMotion`]).
    /// Particles on a prescribed path follow a target entity moved by [`ScriptedMotion`].
    /// Returns the root, or the scene's validation errors (every bad field, with its path).
    fn spawn_soft_body(&mut self, scene: &Scene, body: SoftBody) -> Result<Entity, SceneError>;

    /// Reads a scene JSON file and spawns it (see [`SpawnSoftBody::spawn_soft_body`]). An
    /// unreadable file or invalid JSON is an error naming the file (and the field or line).
    fn spawn_soft_body_file(
        &mut self,
        path: impl AsRef<std::path::Path>,
        body: SoftBody,
    ) -> Result<Entity, SceneError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| SceneError {
            errors: vec![crate::core::scene::FieldError {
                path: path.display().to_string(),
                message: e.to_string(),
            }],
        })?;
        let scene = Scene::from_json(&text).map_err(|mut e| {
            for f in &mut e.errors {
                f.path = format!("{}: {}", path.display(), f.path);
            }
            e
        })?;
        self.spawn_soft_body(&scene, body)
    }
}

impl SpawnSoftBody for Commands<'_, '_> {
    fn spawn_soft_body(&mut self, scene: &Scene, mut body: SoftBody) -> Result<Entity, SceneError> {
        scene.validate()?;
        body.gravity = Some(v(scene.gravity));
        body.drag = scene.drag as f32;
        let name = if scene.name.is_empty() {
            "soft body".to_string()
        } else {
            scene.name.clone()
        };
        let root = self
            .spawn((
                body,
                Name::new(name),
                Transform::IDENTITY,
                Visibility::default(),
            ))
            .id();
        if let Some(w) = scene.wind {
            self.entity(root).insert(SoftBodyWind::from(w));
        }
        if let Some(s) = &scene.surface {
            self.entity(root).insert(SoftBodySurface {
                triangles: s.triangles.clone(),
                uvs: s.uvs.clone(),
                ..Default::default()
            });
        }
        let ids: Vec<Entity> = scene
            .particles
            .iter()
            .map(|p| {
                let mut e = self.spawn((
                    Particle {
                        position: v(p.position),
                        velocity: v(p.velocity),
                        mass: p.mass as f32,
                    },
                    ParticleOf(root),
                ));
                if p.pinned {
                    e.insert(Pinned::here());
                }
                e.id()
            })
            .collect();
        self.entity(root).insert(SoftBodyInitial {
            particles: ids
                .iter()
                .zip(&scene.particles)
                .map(|(e, p)| (*e, v(p.position), v(p.velocity)))
                .collect(),
        });
        for (k, s) in scene.springs.iter().enumerate() {
            self.spawn((
                Spring {
                    a: ids[s.a],
                    b: ids[s.b],
                    rest_length: scene.rest_length(k) as f32,
                    stiffness: s.stiffness as f32,
                    damping: s.damping as f32,
                    law: s.law,
                },
                SpringOf(root),
            ));
        }
        for m in &scene.motions {
            let start = crate::math::to_f32(m.motion.position(0.0));
            let target = self
                .spawn((
                    Name::new("prescribed path"),
                    ScriptedMotion(m.motion),
                    Transform::from_translation(start),
                    GlobalTransform::from_translation(start),
                ))
                .id();
            self.entity(ids[m.particle])
                .insert(Pinned::to(target, Vec3::ZERO));
        }
        for f in &scene.forces {
            self.entity(ids[f.particle])
                .insert(ExternalForce(v(f.force)));
        }
        for c in &scene.colliders {
            let q = c.rotation;
            let tf = Transform::from_translation(crate::math::to_f32(c.motion.position(0.0)))
                .with_rotation(
                    Quat::from_xyzw(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32).normalize(),
                );
            let mut e = self.spawn((
                SoftBodyCollider {
                    shape: ColliderShape(c.shape.to_shared()),
                    friction: c.material.friction as f32,
                    restitution: c.material.restitution as f32,
                    thickness: c.material.thickness as f32,
                    bounce_threshold: c.material.bounce_threshold as f32,
                },
                tf,
                GlobalTransform::from(tf),
            ));
            if !matches!(c.motion, crate::core::motion::Motion::Fixed { .. }) {
                e.insert(ScriptedMotion(c.motion));
            }
        }
        Ok(root)
    }
}
