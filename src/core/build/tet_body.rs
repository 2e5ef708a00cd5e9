//! Tet meshes as hung elastic bodies.

use crate::core::scene::Scene;

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
