//! What the finite-element examples share: loading a tet mesh and a display mesh through the
//! asset server, spawning the elastic body once both are loaded. Not an example itself.

#![allow(dead_code)]

use bevy::prelude::*;
use bevy_soft_body::prelude::*;

/// What to spawn once the tet mesh asset is loaded.
#[derive(Resource, Clone)]
pub struct FemSpec {
    /// The tet mesh handle.
    pub mesh: Handle<TetMeshAsset>,
    /// The material.
    pub material: NeoHookean,
    /// Body settings.
    pub body: SoftBody,
    /// `x ↦ scale x + offset` applied to the mesh.
    pub scale: f64,
    /// Offset (m).
    pub offset: [f64; 3],
    /// A high-resolution mesh under `assets/` (any format Bevy loads as a `Mesh`: `.obj`
    /// through the crate's loader, a glTF primitive...) to skin onto it.
    pub display: Option<&'static str>,
    /// Pin the vertices whose height is above this fraction of the mesh's height.
    pub pin_above: Option<f64>,
    /// An initial sideways velocity per metre of height (m/s per m).
    pub kick: f64,
    /// Colour of the simulation mesh's surface.
    pub color: Color,
}

/// Spawns the body from [`FemSpec`] when its mesh has loaded (once).
#[allow(clippy::too_many_arguments)]
pub fn spawn_when_loaded(
    mut commands: Commands,
    spec: Option<Res<FemSpec>>,
    assets: Res<Assets<TetMeshAsset>>,
    server: Res<AssetServer>,
    mut done: Local<bool>,
    mut particles: Query<&mut Particle>,
    mut pending: Local<Option<Entity>>,
    mut initial: Query<&mut SoftBodyInitial>,
    (meshes, mut display_handle): (Res<Assets<Mesh>>, Local<Option<Handle<Mesh>>>),
) {
    // A frame after spawning: pin and kick through the spawned particle entities.
    if let Some(root) = *pending
        && let Ok(mut init) = initial.get_mut(root)
        && let Some(spec) = &spec
    {
        let top = init
            .particles
            .iter()
            .map(|p| p.1.y)
            .fold(f32::MIN, f32::max);
        let bottom = init
            .particles
            .iter()
            .map(|p| p.1.y)
            .fold(f32::MAX, f32::min);
        for (e, x, v) in &mut init.particles {
            let above = (x.y - bottom) / (top - bottom).max(1e-6);
            if spec.pin_above.is_some_and(|f| above as f64 > f) {
                commands.entity(*e).insert(Pinned::here());
            } else if spec.kick != 0.0
                && let Ok(mut p) = particles.get_mut(*e)
            {
                // Kept in the spawn state, so R resets to the kicked start.
                p.velocity.x = spec.kick as f32 * (x.y - bottom);
                v.x = p.velocity.x;
            }
        }
        *pending = None;
    }
    let Some(spec) = spec else { return };
    if *done {
        return;
    }
    if let bevy::asset::LoadState::Failed(e) = server.load_state(&spec.mesh) {
        error!("tet mesh failed to load: {e}");
        *done = true;
        return;
    }
    let Some(asset) = assets.get(&spec.mesh) else {
        return;
    };
    // The display mesh, as a Bevy mesh asset.
    if let Some(name) = spec.display
        && display_handle.is_none()
    {
        *display_handle = Some(server.load(name));
    }
    if let Some(h) = display_handle.as_ref() {
        if let bevy::asset::LoadState::Failed(e) = server.load_state(h) {
            error!("display mesh failed to load: {e}");
            *display_handle = None;
        } else if !meshes.contains(h) {
            return;
        }
    }
    *done = true;
    // Renumbered along a Morton curve: the generator's numbers follow no spatial order, and
    // the force kernels share a body among threads by ranges of particles (nothing here uses
    // the file's numbers: the pins go by height).
    let mesh = asset
        .0
        .clone()
        .transformed(spec.scale, spec.offset)
        .spatially_ordered()
        .0;
    let display = display_handle.as_ref().and_then(|h| {
        let (mut v, f) = triangle_mesh(meshes.get(h)?)
            .map_err(|e| error!("display mesh: {e}"))
            .ok()?;
        for p in &mut v {
            for (c, o) in p.iter_mut().zip(spec.offset) {
                *c = *c * spec.scale as f32 + o as f32;
            }
        }
        Some((v, f))
    });
    match commands.spawn_tet_body(
        &mesh,
        spec.material,
        spec.body.clone(),
        display.as_ref().map(|(v, f)| (v.as_slice(), f.as_slice())),
    ) {
        Ok(root) => {
            commands.entity(root).insert(SoftBodySurface {
                triangles: mesh.boundary(),
                color: spec.color,
                ..default()
            });
            *pending = Some(root);
        }
        Err(e) => error!("{e}"),
    }
}
