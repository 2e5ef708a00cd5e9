//! Tet meshes as Bevy assets: `asset_server.load::<TetMeshAsset>("meshes/bunny_coarse.mesh")`
//! reads Gmsh `.msh` (2.2 and 4.1 ASCII), Medit `.mesh` and TetGen `.node` (with the `.ele`
//! beside it). A malformed file fails the load with the file and line in the error (Bevy logs
//! it; the handle's load state says `Failed`), never a panic.

use crate::core::fem::mesh::{MeshError, TetMesh};
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
        let mut bytes = Vec::new();
        reader
            .read_to_end(&mut bytes)
            .await
            .map_err(|e| io_error(&name, e))?;
        let text = String::from_utf8(bytes).map_err(|_| io_error(&name, "not UTF-8 text"))?;
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

/// Loads tet meshes as [`TetMeshAsset`]s (part of [`SoftBodyPlugins`](crate::SoftBodyPlugins)).
/// Needs Bevy's `AssetPlugin`; without it it does nothing.
#[derive(Default, Debug, Clone, Copy)]
pub struct SoftBodyAssetPlugin;

impl Plugin for SoftBodyAssetPlugin {
    fn build(&self, _app: &mut App) {}

    fn finish(&self, app: &mut App) {
        if app.world().contains_resource::<AssetServer>() {
            app.init_asset::<TetMeshAsset>()
                .init_asset_loader::<TetMeshLoader>();
        }
    }
}
