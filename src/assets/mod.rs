//! The crate's files as Bevy assets. A malformed file fails its load with the file and line
//! (or field) in the error — Bevy logs it and the handle's load state says `Failed` — never a
//! panic.
//!
//! - Tet meshes: `asset_server.load::<TetMeshAsset>("meshes/bunny_coarse.mesh")` reads Gmsh
//!   `.msh` (2.2 and 4.1 ASCII), Medit `.mesh` and TetGen `.node` (with the `.ele` beside it).
//! - Scene files (`*.softbody.json`, the JSON of [`Scene`]) as [`SoftBodySceneAsset`]s; a
//!   [`SoftBodySceneRoot`] component spawns one as a body once loaded.
//! - Wavefront `.obj` triangle meshes as Bevy `Mesh`es (positions, smooth normals; for
//!   display meshes skinned onto tet bodies). An app with another `.obj` loader for `Mesh`
//!   (bevy_obj) should disable this one: `SoftBodyAssetPlugin { obj: false }`.

use crate::core::fem::mesh::{MeshError, TetMesh};
use crate::core::scene::{Scene, SceneError};
use crate::ecs::{SoftBody, SpawnSoftBody};
use bevy::asset::io::Reader;
use bevy::asset::{AssetLoader, LoadContext};
use bevy::prelude::*;

/// A loaded tet mesh.
#[derive(Asset, TypePath, Clone, Debug, PartialEq)]
pub struct TetMeshAsset(pub TetMesh);

/// Loads [`TetMeshAsset`]s from `.msh`, `.mesh` and `.node` files.
#[derive(Default, TypePath)]
pub struct TetMeshLoader;

fn io_error(file: &str, e: impl std::fmt::Display) -> MeshError {
    MeshError {
        file: file.to_string(),
        line: 0,
        message: e.to_string(),
    }
}

/// A whole asset file as UTF-8 text, or what went wrong (the I/O error, or "not UTF-8 text").
async fn read_text(reader: &mut dyn Reader) -> Result<String, String> {
    let mut bytes = Vec::new();
    reader
        .read_to_end(&mut bytes)
        .await
        .map_err(|e| e.to_string())?;
    String::from_utf8(bytes).map_err(|_| "not UTF-8 text".to_string())
}

impl AssetLoader for TetMeshLoader {
    type Asset = TetMeshAsset;
    type Settings = ();
    type Error = MeshError;

    async fn load(
        &self,
        reader: &mut dyn Reader,
        _settings: &(),
        ctx: &mut LoadContext<'_>,
    ) -> Result<TetMeshAsset, MeshError> {
        let path = ctx.path().path().to_path_buf();
        let name = path.display().to_string();
        let text = read_text(reader).await.map_err(|e| io_error(&name, e))?;
        let mesh = match path.extension().and_then(|e| e.to_str()) {
            Some("msh") => TetMesh::from_gmsh(&name, &text)?,
            Some("node") => {
                let ele = path.with_extension("ele");
                let ele_name = ele.display().to_string();
                let bytes = ctx
                    .read_asset_bytes(ele)
                    .await
                    .map_err(|e| io_error(&ele_name, e))?;
                let ele_text =
                    String::from_utf8(bytes).map_err(|_| io_error(&ele_name, "not UTF-8 text"))?;
                TetMesh::from_tetgen(&name, &text, &ele_name, &ele_text)?
            }
            _ => TetMesh::from_medit(&name, &text)?,
        };
        Ok(TetMeshAsset(mesh))
    }

    fn extensions(&self) -> &[&str] {
        &["msh", "mesh", "node"]
    }
}

/// A scene file (the JSON of [`Scene`]) loaded as an asset.
#[derive(Asset, TypePath, Clone, Debug, PartialEq)]
pub struct SoftBodySceneAsset(pub Scene);

/// Loads [`SoftBodySceneAsset`]s from `.softbody.json` files.
#[derive(Default, TypePath)]
pub struct SoftBodySceneLoader;

/// A scene file that failed to load: the file and every problem found.
#[derive(Debug)]
pub struct SceneFileError {
    /// The file.
    pub file: String,
    /// What is wrong.
    pub error: SceneError,
}

impl std::fmt::Display for SceneFileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.file, self.error)
    }
}

impl std::error::Error for SceneFileError {}

impl AssetLoader for SoftBodySceneLoader {
    type Asset = SoftBodySceneAsset;
    type Settings = ();
    type Error = SceneFileError;

    async fn load(
        &self,
        reader: &mut dyn Reader,
        _settings: &(),
        ctx: &mut LoadContext<'_>,
    ) -> Result<SoftBodySceneAsset, SceneFileError> {
        let file = ctx.path().path().display().to_string();
        let fail = |message: String| SceneFileError {
            file: file.clone(),
            error: SceneError {
                errors: vec![crate::core::scene::FieldError {
                    path: String::new(),
                    message,
                }],
            },
        };
        let text = read_text(reader).await.map_err(fail)?;
        let scene = Scene::from_json(&text).map_err(|error| SceneFileError {
            file: file.clone(),
            error,
        })?;
        scene.validate().map_err(|error| SceneFileError {
            file: file.clone(),
            error,
        })?;
        Ok(SoftBodySceneAsset(scene))
    }

    fn extensions(&self) -> &[&str] {
        &["softbody.json"]
    }
}

/// Spawns the scene file once it has loaded, as one body with these settings (see
/// [`SpawnSoftBody::spawn_soft_body`]); then this component is replaced by
/// [`SoftBodySceneSpawned`] naming the body's root. A file that fails to load or to validate
/// is logged with its errors, and nothing is spawned.
#[derive(Component, Clone, Debug)]
pub struct SoftBodySceneRoot {
    /// The scene file.
    pub scene: Handle<SoftBodySceneAsset>,
    /// The body's settings.
    pub body: SoftBody,
}

/// The body a [`SoftBodySceneRoot`] spawned.
#[derive(Component, Reflect, Clone, Copy, Debug)]
#[reflect(Component, Debug)]
pub struct SoftBodySceneSpawned(#[entities] pub Entity);

fn spawn_scene_assets(
    mut commands: Commands,
    q: Query<(Entity, &SoftBodySceneRoot)>,
    scenes: Res<Assets<SoftBodySceneAsset>>,
    server: Res<AssetServer>,
) {
    for (e, root) in &q {
        if let bevy::asset::LoadState::Failed(err) = server.load_state(&root.scene) {
            warn!("soft body scene on {e}: {err}; no body spawned");
            commands.entity(e).remove::<SoftBodySceneRoot>();
            continue;
        }
        let Some(scene) = scenes.get(&root.scene) else {
            continue;
        };
        match commands.spawn_soft_body(&scene.0, root.body.clone()) {
            Ok(body) => {
                commands
                    .entity(e)
                    .remove::<SoftBodySceneRoot>()
                    .insert(SoftBodySceneSpawned(body));
            }
            Err(err) => {
                warn!("soft body scene on {e}: {err}; no body spawned");
                commands.entity(e).remove::<SoftBodySceneRoot>();
            }
        }
    }
}

/// Loads Wavefront `.obj` triangle meshes as Bevy `Mesh`es (see the module docs).
#[derive(Default, TypePath)]
pub struct ObjMeshLoader;

impl AssetLoader for ObjMeshLoader {
    type Asset = Mesh;
    type Settings = ();
    type Error = MeshError;

    async fn load(
        &self,
        reader: &mut dyn Reader,
        _settings: &(),
        ctx: &mut LoadContext<'_>,
    ) -> Result<Mesh, MeshError> {
        let name = ctx.path().path().display().to_string();
        let text = read_text(reader).await.map_err(|e| io_error(&name, e))?;
        let (v, f) = crate::core::fem::skin::read_obj(&name, &text)?;
        let mut normals = vec![[0.0; 3]; v.len()];
        crate::render::smooth_normals(&v, &f, &mut normals);
        let mut mesh = Mesh::new(
            bevy::mesh::PrimitiveTopology::TriangleList,
            bevy::asset::RenderAssetUsages::default(),
        );
        mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, v);
        mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
        mesh.insert_indices(bevy::mesh::Indices::U32(f.into_iter().flatten().collect()));
        Ok(mesh)
    }

    fn extensions(&self) -> &[&str] {
        &["obj"]
    }
}

/// The crate's asset loaders (part of [`SoftBodyPlugins`](crate::SoftBodyPlugins)): tet
/// meshes, scene files and (unless `obj` is off) `.obj` meshes. Needs Bevy's `AssetPlugin`;
/// without it it does nothing.
#[derive(Debug, Clone, Copy)]
pub struct SoftBodyAssetPlugin {
    /// Register the `.obj` loader for `Mesh` (off when the app has another).
    pub obj: bool,
}

impl Default for SoftBodyAssetPlugin {
    fn default() -> Self {
        Self { obj: true }
    }
}

impl Plugin for SoftBodyAssetPlugin {
    fn build(&self, _app: &mut App) {}

    fn finish(&self, app: &mut App) {
        if app.world().contains_resource::<AssetServer>() {
            app.init_asset::<TetMeshAsset>()
                .init_asset_loader::<TetMeshLoader>()
                .init_asset::<SoftBodySceneAsset>()
                .init_asset_loader::<SoftBodySceneLoader>()
                .register_type::<SoftBodySceneSpawned>()
                .add_systems(Update, spawn_scene_assets);
            if self.obj && app.world().contains_resource::<Assets<Mesh>>() {
                app.init_asset_loader::<ObjMeshLoader>();
            }
        }
        // Cloth from glTF meshes, when the app loads glTF (`GltfPlugin`).
        if app.world().contains_resource::<Assets<bevy::gltf::Gltf>>()
            && app.world().contains_resource::<Assets<Mesh>>()
        {
            app.register_type::<crate::ecs::SoftBodyGltfSpawned>()
                .add_systems(Update, crate::ecs::mesh_body::spawn_gltf_bodies);
        }
    }
}
