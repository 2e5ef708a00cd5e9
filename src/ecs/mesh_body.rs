//! Soft bodies from the game's own meshes: any triangle [`Mesh`] (made in code, or a glTF
//! primitive) becomes a cloth ([`build::surface_cloth`](crate::core::build::surface_cloth):
//! seams welded, stretch and bending springs, masses from areas), drawn with the mesh itself —
//! its UVs, vertex colours and (from glTF) material kept, positions and normals (and tangents, when it has
//! them) rewritten every frame ([`SoftBodyMeshSurface`]).
//!
//! Two ways in: [`SpawnSoftBody::spawn_mesh_body`] with a `Mesh` in hand, or a
//! [`SoftBodyGltf`] component naming a mesh of a glTF asset, which spawns the body once the
//! asset has loaded, with pins picked by vertex colour or by named nodes of the file.

use super::components::*;
#[allow(unused_imports)] // for docs
use super::spawn::SpawnSoftBody;
use super::spawn::spawn_scene;
use crate::core::build::{SurfaceParams, surface_cloth};
use crate::core::forces::Wind;
use crate::core::scene::{FieldError, SceneError};
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;
use std::sync::Arc;

/// Which vertices of a mesh hold the cloth.
#[derive(Clone, Default)]
pub enum MeshPins {
    /// None: the cloth falls freely.
    #[default]
    None,
    /// Vertices whose colour (`Mesh::ATTRIBUTE_COLOR`, linear RGBA) is within `tolerance` of
    /// `color` in every channel: an artist paints the pinned rim red.
    VertexColor {
        /// The colour that marks a pinned vertex.
        color: LinearRgba,
        /// Largest difference per channel.
        tolerance: f32,
    },
    /// Vertices within `radius` of any of `points` (in the mesh's own frame); a glTF's named
    /// pin nodes become such points.
    Near {
        /// Centres.
        points: Vec<Vec3>,
        /// Radius (m, in the mesh's frame).
        radius: f32,
    },
    /// Vertices the predicate picks, given the vertex index and its position in the mesh's
    /// frame.
    Predicate(Arc<dyn Fn(usize, Vec3) -> bool + Send + Sync>),
}

impl std::fmt::Debug for MeshPins {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MeshPins::None => f.write_str("None"),
            MeshPins::VertexColor { color, tolerance } => f
                .debug_struct("VertexColor")
                .field("color", color)
                .field("tolerance", tolerance)
                .finish(),
            MeshPins::Near { points, radius } => f
                .debug_struct("Near")
                .field("points", points)
                .field("radius", radius)
                .finish(),
            MeshPins::Predicate(_) => f.write_str("Predicate(..)"),
        }
    }
}

/// How to turn a mesh into a cloth body.
#[derive(Clone, Debug, Default)]
pub struct MeshBody {
    /// Material and welding.
    pub cloth: SurfaceParams,
    /// Pinned vertices.
    pub pins: MeshPins,
    /// Where the mesh is placed in the world (its vertices are in its own frame).
    pub transform: Transform,
    /// Pinned particles follow this entity, whose pose at spawn is given, at their offsets in
    /// its frame (a pole, a character's shoulders); `None`: pinned in place.
    pub attach: Option<(Entity, GlobalTransform)>,
    /// Wind on this body.
    pub wind: Option<Wind>,
    /// Tearing ([`Tearable`]): springs strained past the limit break, and the mesh opens
    /// along the cut (vertices split, their attributes kept). A limit that is not positive
    /// is an error naming `tearing.max_strain`.
    pub tearing: Option<Tearable>,
    /// Self-collision ([`SelfCollision`]) of the mesh's surface, checked against its welded
    /// triangles (a thickness too large for its shortest edge is an error naming
    /// `self_collision.thickness`). Colliders meet the mesh's triangles between its particles
    /// with or without it.
    pub self_collision: Option<SelfCollision>,
    /// Colour of the default material when the body has no `MeshMaterial3d`.
    pub color: Option<Color>,
}

/// A body drawn with a mesh of the game's own (from [`SpawnSoftBody::spawn_mesh_body`]): every
/// frame each vertex takes its particle's position, normals are recomputed over the welded
/// surface (no shading crease along UV seams) and tangents regenerated when the mesh has them.
#[derive(Component, Reflect, Clone, Debug, Default)]
#[reflect(Component, Default, Debug)]
pub struct SoftBodyMeshSurface {
    /// The particle each vertex of the mesh shows.
    #[entities]
    pub vertices: Vec<Entity>,
    /// The mesh's triangles (indices of its vertices): what its index buffer holds, kept here
    /// so that a tear ([`Tearable`]) splits them as it splits a [`SoftBodySurface`]'s
    /// (empty: the mesh is drawn whole).
    ///
    /// [`SoftBodySurface`]: crate::render::SoftBodySurface
    pub triangles: Vec<[u32; 3]>,
    /// For each vertex a tear added, in order after the mesh's own, the vertex it copies
    /// (texture coordinates, colours, every attribute but position and normal).
    pub split_from: Vec<u32>,
    /// True while a tear's new vertices and triangles are not yet in the mesh asset.
    #[reflect(ignore)]
    pub torn: bool,
    /// Colour of the default material (when the body has no `MeshMaterial3d`).
    pub color: Color,
    /// The mesh to deform (taken when its asset is made).
    #[reflect(ignore)]
    pub source: Option<Arc<Mesh>>,
}

fn mesh_error(message: String) -> SceneError {
    SceneError {
        errors: vec![FieldError {
            path: "mesh".into(),
            message,
        }],
    }
}

/// Positions, triangles and (when present) vertex colours.
type MeshData = (Vec<[f32; 3]>, Vec<[u32; 3]>, Option<Vec<[f32; 4]>>);

/// A triangle mesh's positions, triangles and vertex colours.
fn read_mesh(mesh: &Mesh) -> Result<MeshData, String> {
    if mesh.primitive_topology() != PrimitiveTopology::TriangleList {
        return Err(format!(
            "a cloth needs a triangle list, this mesh is {:?}",
            mesh.primitive_topology()
        ));
    }
    let Some(VertexAttributeValues::Float32x3(pos)) = mesh.attribute(Mesh::ATTRIBUTE_POSITION)
    else {
        return Err("the mesh has no Float32x3 positions".into());
    };
    let flat: Vec<u32> = match mesh.indices() {
        Some(Indices::U16(i)) => i.iter().map(|i| *i as u32).collect(),
        Some(Indices::U32(i)) => i.clone(),
        None => (0..pos.len() as u32).collect(),
    };
    if !flat.len().is_multiple_of(3) {
        return Err(format!(
            "{} indices do not make whole triangles",
            flat.len()
        ));
    }
    let tris = flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let colors = match mesh.attribute(Mesh::ATTRIBUTE_COLOR) {
        Some(VertexAttributeValues::Float32x4(c)) => Some(c.clone()),
        Some(VertexAttributeValues::Unorm8x4(c)) => {
            Some(c.iter().map(|c| c.map(|x| x as f32 / 255.0)).collect())
        }
        _ => None,
    };
    Ok((pos.clone(), tris, colors))
}

/// The positions and triangles of a triangle-list `Mesh` (a display mesh to skin onto a tet
/// body with [`SpawnSoftBody::spawn_tet_body`], from any mesh asset), or why it has none.
pub fn triangle_mesh(mesh: &Mesh) -> Result<crate::core::fem::skin::TriangleMesh, String> {
    read_mesh(mesh).map(|(p, t, _)| (p, t))
}

/// Spawns `mesh` as a cloth body (see [`SpawnSoftBody::spawn_mesh_body`]).
pub(crate) fn spawn_mesh_body(
    commands: &mut Commands,
    mesh: &Mesh,
    params: &MeshBody,
    body: SoftBody,
) -> Result<Entity, SceneError> {
    let (local, tris, colors) = read_mesh(mesh).map_err(mesh_error)?;
    let world: Vec<[f32; 3]> = local
        .iter()
        .map(|p| {
            params
                .transform
                .transform_point(Vec3::from_array(*p))
                .to_array()
        })
        .collect();
    if let MeshPins::VertexColor { .. } = params.pins
        && colors.is_none()
    {
        return Err(mesh_error(
            "pins by vertex colour, but the mesh has no vertex colours".into(),
        ));
    }
    let pinned = |v: usize, _: [f32; 3]| {
        let p = Vec3::from_array(local[v]);
        match &params.pins {
            MeshPins::None => false,
            MeshPins::VertexColor { color, tolerance } => colors.as_ref().is_some_and(|c| {
                let c = c[v];
                let want = color.to_f32_array();
                (0..4).all(|k| (c[k] - want[k]).abs() <= *tolerance)
            }),
            MeshPins::Near { points, radius } => points.iter().any(|q| q.distance(p) <= *radius),
            MeshPins::Predicate(f) => f(v, p),
        }
    };
    let built = surface_cloth(&world, &tris, &params.cloth, pinned).map_err(|e| mesh_error(e.0))?;
    let mut scene = built.scene;
    scene.wind = params.wind;
    scene.tearing = params.tearing.map(|t| t.params());
    // Self-collision checked against the welded surface; the body is spawned without a
    // surface of its own (drawn with the mesh itself, whose triangles stand for it).
    scene.self_collision = params.self_collision.map(|c| c.params());
    scene.validate()?;
    let self_collision = scene.self_collision.take();
    scene.surface = None;
    let (root, particles) = spawn_scene(commands, &scene, body)?;
    if let Some(sc) = self_collision {
        commands.entity(root).insert(SelfCollision::from(sc));
    }
    if let Some((target, at)) = params.attach {
        let inv = at.affine().inverse();
        for (p, e) in scene.particles.iter().zip(&particles) {
            if p.pinned {
                let x = Vec3::new(
                    p.position[0] as f32,
                    p.position[1] as f32,
                    p.position[2] as f32,
                );
                commands
                    .entity(*e)
                    .insert(Pinned::to(target, inv.transform_point3(x)));
            }
        }
    }
    // Vertices in no triangle show the first particle (they draw nothing).
    let vertices = built
        .vertex_particle
        .iter()
        .map(|q| particles[q.unwrap_or(0) as usize])
        .collect();
    commands.entity(root).insert(SoftBodyMeshSurface {
        vertices,
        triangles: tris,
        split_from: vec![],
        torn: false,
        color: params.color.unwrap_or(Color::srgb(0.8, 0.75, 0.7)),
        source: Some(Arc::new(mesh.clone())),
    });
    Ok(root)
}

/// Spawns a cloth body from a mesh of a glTF asset once it has loaded, on the entity that
/// carries this component (its `Transform` places the mesh); then the component is removed
/// and [`SoftBodyGltfSpawned`] names the body. Needs Bevy's `GltfPlugin` (in `DefaultPlugins`).
#[derive(Component, Clone, Debug)]
pub struct SoftBodyGltf {
    /// The glTF file.
    pub gltf: Handle<bevy::gltf::Gltf>,
    /// The name of the mesh in the file (its first primitive is used).
    pub mesh: String,
    /// How to build the cloth; its `transform` is replaced by this entity's, and for
    /// [`MeshPins::Near`] with no points, the positions of [`SoftBodyGltf::pin_nodes`] are used.
    pub params: MeshBody,
    /// Named nodes whose positions pin the vertices near them.
    pub pin_nodes: Vec<String>,
    /// Pinned particles follow this entity (its `GlobalTransform` at spawn gives the offsets).
    pub attach: Option<Entity>,
    /// The body's settings.
    pub body: SoftBody,
}

/// The body a [`SoftBodyGltf`] spawned (on the entity that carried it).
#[derive(Component, Reflect, Clone, Copy, Debug)]
#[reflect(Component, Debug)]
pub struct SoftBodyGltfSpawned(#[entities] pub Entity);

type GltfItem<'a> = (
    Entity,
    &'a SoftBodyGltf,
    Option<&'a GlobalTransform>,
    Option<&'a Transform>,
    Has<ChildOf>,
);

/// Spawns the bodies of loaded glTF assets.
#[allow(clippy::too_many_arguments)]
pub(crate) fn spawn_gltf_bodies(
    mut commands: Commands,
    q: Query<GltfItem>,
    targets: Query<(&GlobalTransform, Option<&Transform>, Has<ChildOf>)>,
    gltfs: Res<Assets<bevy::gltf::Gltf>>,
    gltf_meshes: Res<Assets<bevy::gltf::GltfMesh>>,
    nodes: Res<Assets<bevy::gltf::GltfNode>>,
    meshes: Res<Assets<Mesh>>,
    server: Res<AssetServer>,
    std_materials: Option<Res<Assets<StandardMaterial>>>,
) {
    for (e, src, gt, tf, has_parent) in &q {
        if let bevy::asset::LoadState::Failed(err) = server.load_state(&src.gltf) {
            warn!("soft body glTF on {e}: {err}; no body spawned");
            commands.entity(e).remove::<SoftBodyGltf>();
            continue;
        }
        let Some(gltf) = gltfs.get(&src.gltf) else {
            continue; // still loading
        };
        let fail = |commands: &mut Commands, msg: String| {
            warn!("soft body glTF on {e}: {msg}; no body spawned");
            commands.entity(e).remove::<SoftBodyGltf>();
        };
        let Some(gm) = gltf
            .named_meshes
            .get(src.mesh.as_str())
            .and_then(|h| gltf_meshes.get(h))
        else {
            let names: Vec<_> = gltf.named_meshes.keys().collect();
            fail(
                &mut commands,
                format!("no mesh named {:?} (the file has {names:?})", src.mesh),
            );
            continue;
        };
        let Some(mesh) = gm.primitives.first().and_then(|p| meshes.get(&p.mesh)) else {
            continue; // the primitive's mesh is still loading
        };
        let mut params = src.params.clone();
        // A top-level entity's pose is its `Transform` (its `GlobalTransform` is propagated
        // later in the frame, and may not be yet on the frame it was spawned).
        params.transform = match (tf, gt) {
            (Some(tf), _) if !has_parent => *tf,
            (_, Some(g)) => g.compute_transform(),
            _ => Transform::IDENTITY,
        };
        if !src.pin_nodes.is_empty() {
            let mut points = vec![];
            for name in &src.pin_nodes {
                match gltf
                    .named_nodes
                    .get(name.as_str())
                    .and_then(|h| nodes.get(h))
                {
                    Some(n) => points.push(n.transform.translation),
                    None => {
                        fail(&mut commands, format!("no node named {name:?}"));
                        points.clear();
                        break;
                    }
                }
            }
            if points.is_empty() {
                continue;
            }
            let radius = match params.pins {
                MeshPins::Near { radius, .. } => radius,
                _ => 0.05,
            };
            params.pins = MeshPins::Near { points, radius };
        }
        if let Some(t) = src.attach {
            match targets.get(t) {
                Ok((gt, tf, has_parent)) => {
                    let at = match tf {
                        Some(tf) if !has_parent => GlobalTransform::from(*tf),
                        _ => *gt,
                    };
                    params.attach = Some((t, at));
                }
                Err(_) => {
                    fail(
                        &mut commands,
                        format!("attach target {t} has no GlobalTransform"),
                    );
                    continue;
                }
            }
        }
        match spawn_mesh_body(&mut commands, mesh, &params, src.body.clone()) {
            Ok(body) => {
                // The file's material, as Bevy's PBR plugin made it (`Material<i>/std`).
                if std_materials.is_some()
                    && let Some(path) = gm
                        .primitives
                        .first()
                        .and_then(|p| p.material.as_ref())
                        .and_then(|m| m.path())
                    && let Some(label) = path.label()
                {
                    let std: Handle<StandardMaterial> =
                        server.load(path.clone().with_label(format!("{label}/std")));
                    commands.entity(body).insert(MeshMaterial3d(std));
                }
                commands
                    .entity(e)
                    .remove::<SoftBodyGltf>()
                    .insert(SoftBodyGltfSpawned(body));
            }
            Err(err) => fail(&mut commands, err.to_string()),
        }
    }
}
