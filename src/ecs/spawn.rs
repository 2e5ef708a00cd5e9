//! Spawning whole bodies from the core's scene layouts (builders or JSON files).

use super::components::*;
use crate::core::scene::{Scene, SceneError};
use crate::math::VectorExt;
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

    /// Spawns a tet mesh as one elastic body of `material` (particle masses `Σ ρV/4`), with its
    /// boundary as the drawn surface and, when `display` gives a triangle mesh (vertices at
    /// rest, triangles), a [`SkinnedSurface`](crate::render::SkinnedSurface) embedding it
    /// (shown; S in the examples toggles). Pin or move particles afterwards through
    /// [`SoftBodyInitial`]'s entity list.
    fn spawn_tet_body(
        &mut self,
        mesh: &crate::core::fem::mesh::TetMesh,
        material: crate::core::fem::NeoHookean,
        body: SoftBody,
        display: Option<DisplayMesh>,
    ) -> Result<Entity, SceneError>;

    /// Spawns a triangle mesh of the game's own as a cloth body
    /// ([`build::surface_cloth`](crate::core::build::surface_cloth): vertices split by UV seams
    /// welded, stretch and bending springs, masses from areas), pinned as `params` says and
    /// drawn with the mesh itself ([`SoftBodyMeshSurface`](super::SoftBodyMeshSurface): UVs,
    /// colours and material kept). A mesh that is no triangle list, or that the builder
    /// refuses, is an error saying why.
    fn spawn_mesh_body(
        &mut self,
        mesh: &Mesh,
        params: &super::MeshBody,
        body: SoftBody,
    ) -> Result<Entity, SceneError>;

    /// Spawns a collider described as in scenes (a ground plane from
    /// [`build::ground`](crate::core::build::ground), a moving ball...).
    fn spawn_collider(&mut self, collider: &crate::core::collide::ColliderDesc) -> Entity;

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
    fn spawn_collider(&mut self, collider: &crate::core::collide::ColliderDesc) -> Entity {
        spawn_collider(self, collider)
    }

    fn spawn_mesh_body(
        &mut self,
        mesh: &Mesh,
        params: &super::MeshBody,
        body: SoftBody,
    ) -> Result<Entity, SceneError> {
        super::mesh_body::spawn_mesh_body(self, mesh, params, body)
    }

    fn spawn_tet_body(
        &mut self,
        mesh: &crate::core::fem::mesh::TetMesh,
        material: crate::core::fem::NeoHookean,
        body: SoftBody,
        display: Option<DisplayMesh>,
    ) -> Result<Entity, SceneError> {
        let scene = mesh.to_scene("elastic body", material);
        let (root, ids) = spawn_scene(self, &scene, body)?;
        if let Some((points, tris)) = display {
            let skinning = crate::core::fem::skin::Skinning::new(mesh, points);
            self.entity(root).insert(crate::render::SkinnedSurface {
                show: true,
                color: Color::srgb(0.78, 0.72, 0.62),
                skinning: std::sync::Arc::new(skinning),
                triangles: std::sync::Arc::new(tris.to_vec()),
                vertices: ids,
            });
        }
        Ok(root)
    }

    fn spawn_soft_body(&mut self, scene: &Scene, body: SoftBody) -> Result<Entity, SceneError> {
        spawn_scene(self, scene, body).map(|(root, _)| root)
    }
}

/// A display mesh to skin onto a tet body: vertices at rest and triangles.
pub type DisplayMesh<'a> = (&'a [[f32; 3]], &'a [[u32; 3]]);

/// Spawns a scene; returns the root and the particle entities in scene order.
pub(crate) fn spawn_scene(
    commands: &mut Commands,
    scene: &Scene,
    mut body: SoftBody,
) -> Result<(Entity, Vec<Entity>), SceneError> {
    {
        let this = commands;
        scene.validate()?;
        body.gravity = Some(v(scene.gravity));
        body.drag = scene.drag as f32;
        let name = if scene.name.is_empty() {
            "soft body".to_string()
        } else {
            scene.name.clone()
        };
        let root = this
            .spawn((
                body,
                Name::new(name),
                Transform::IDENTITY,
                Visibility::default(),
            ))
            .id();
        if let Some(w) = scene.wind {
            this.entity(root).insert(SoftBodyWind::from(w));
        }
        if let Some(sc) = scene.self_collision {
            this.entity(root).insert(SelfCollision::from(sc));
        }
        if let Some(t) = scene.tearing {
            this.entity(root).insert(Tearable::from(t));
        }
        if let Some(s) = &scene.surface {
            this.entity(root).insert(SoftBodySurface {
                triangles: s.triangles.clone(),
                uvs: s.uvs.clone(),
                torn_from: s.torn_from.clone(),
                ..Default::default()
            });
        }
        let ids: Vec<Entity> = scene
            .particles
            .iter()
            .map(|p| {
                let mut e = this.spawn((
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
        this.entity(root).insert(SoftBodyInitial {
            particles: ids
                .iter()
                .zip(&scene.particles)
                .map(|(e, p)| (*e, v(p.position), v(p.velocity)))
                .collect(),
        });
        for (k, s) in scene.springs.iter().enumerate() {
            this.spawn((
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
        if let Some(m) = scene.material {
            this.entity(root).insert(ElasticMaterial(m));
        }
        for t in &scene.tets {
            this.spawn((
                Tet {
                    particles: t.vertices.map(|i| ids[i]),
                    rest: t.vertices.map(|i| v(scene.particles[i].position)),
                    material: t.material,
                },
                TetOf(root),
            ));
        }
        for m in &scene.motions {
            let start = m.motion.position(0.0).to_f32();
            let target = this
                .spawn((
                    Name::new("prescribed path"),
                    ScriptedMotion(m.motion),
                    Transform::from_translation(start),
                    GlobalTransform::from_translation(start),
                ))
                .id();
            this.entity(ids[m.particle])
                .insert(Pinned::to(target, Vec3::ZERO));
        }
        for f in &scene.forces {
            this.entity(ids[f.particle])
                .insert(ExternalForce(v(f.force)));
        }
        for c in &scene.colliders {
            spawn_collider(this, c);
        }
        Ok((root, ids))
    }
}

/// Spawns one collider of a scene (with its scripted motion when it moves).
fn spawn_collider(commands: &mut Commands, c: &crate::core::collide::ColliderDesc) -> Entity {
    let q = c.rotation;
    let tf = Transform::from_translation(c.motion.position(0.0).to_f32()).with_rotation(
        Quat::from_xyzw(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32).normalize(),
    );
    let mut e = commands.spawn((
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
    e.id()
}
