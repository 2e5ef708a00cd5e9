//! Drawing soft bodies: a body with a [`SoftBodySurface`] gets a triangle mesh whose vertices
//! are its particles (positions written once per frame after the fixed step, smooth
//! area-weighted normals recomputed in place, UVs kept, double-sided material); bodies without
//! a surface (chains, wires, jelly lattices) and, in wireframe mode, every body are drawn with
//! gizmos: springs as lines, particles as small spheres.

use crate::core::ode::OdeState;
use crate::ecs::plugin::BodySim;
use crate::math::VectorExt;
use bevy::asset::RenderAssetUsages;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;

mod debug;
pub use debug::{SoftBodyDebugPlugin, SoftBodyDebugRender, SoftBodyGizmos};

/// Triangles over a body's particles (indices into its particle list, counter-clockwise), with
/// optional per-particle texture coordinates: the body is drawn as a deforming mesh.
#[derive(Component, Reflect, Clone, Debug, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct SoftBodySurface {
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Texture coordinates, one per particle (empty: none).
    pub uvs: Vec<[f32; 2]>,
    /// For each particle, the particle it was split from by tearing (itself if never split;
    /// empty: nothing torn). Kept by the plugin as the surface tears; self-collision's broad
    /// phase never culls a patch that reaches a cut.
    pub torn_from: Vec<u32>,
    /// Colour of the default material (used when the body has no `MeshMaterial3d`).
    pub color: Color,
}

impl Default for SoftBodySurface {
    fn default() -> Self {
        Self {
            triangles: vec![],
            uvs: vec![],
            torn_from: vec![],
            color: Color::srgb(0.85, 0.25, 0.22),
        }
    }
}

/// Level of detail for a body drawn through its [`SoftBodySurface`]: each simulated triangle
/// is drawn as `level²` triangles, lifted off the flat triangle by Phong tessellation
/// (Boubekeur and Alexa 2008) so a coarse cloth looks like a fine one (see
/// [`core::detail`](crate::core::detail)). The simulation is untouched: a 24² cloth drawn at
/// level 4 costs a 24² cloth's step and shows about a 93² mesh. Texture coordinates are
/// interpolated, and so are the simulated surface's smooth normals (Phong shading).
///
/// With [`SelfCollision`](crate::ecs::SelfCollision), offsets are clamped to a quarter of its
/// thickness (or `max_offset`, if smaller), so parts the simulation keeps half a thickness
/// apart stay apart on screen, and the rounding fades out where the surface folds back on
/// itself (see [`core::detail`](crate::core::detail)). With `far`, a body farther than that from every 3D camera is drawn as
/// simulated (level 1), with 10 % hysteresis so it does not flicker at the boundary.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct SurfaceDetail {
    /// Subdivisions of each simulated edge, 1 to [`MAX_LEVEL`](crate::core::detail::MAX_LEVEL)
    /// (1: the simulated surface as it is).
    pub level: u32,
    /// Phong tessellation's shape factor, 0 to 1: 0 flat, ½ (the default) reproduces a sphere
    /// to second order, ¾ rounder silhouettes.
    pub roundness: f32,
    /// Longest offset from the simulated surface (m); `None`: a quarter of the body's
    /// self-collision thickness, or no limit without self-collision.
    pub max_offset: Option<f32>,
    /// Camera distance (m) beyond which the body is drawn as simulated; `None`: always fine.
    pub far: Option<f32>,
}

impl Default for SurfaceDetail {
    fn default() -> Self {
        Self {
            level: 4,
            roundness: 0.5,
            max_offset: None,
            far: None,
        }
    }
}

impl SurfaceDetail {
    /// `level` subdivisions, the other settings by default.
    pub fn level(level: u32) -> Self {
        Self {
            level,
            ..Default::default()
        }
    }

    /// Why these settings cannot be used, if they cannot.
    pub fn validate(&self) -> Result<(), String> {
        use crate::core::detail::MAX_LEVEL;
        if self.level == 0 || self.level > MAX_LEVEL {
            return Err(format!(
                "level must be 1 to {MAX_LEVEL}, got {}",
                self.level
            ));
        }
        if !(0.0..=1.0).contains(&self.roundness) {
            return Err(format!("roundness must be 0 to 1, got {}", self.roundness));
        }
        if let Some(m) = self.max_offset
            && !(m >= 0.0 && m.is_finite())
        {
            return Err(format!("max_offset must be ≥ 0 and finite, got {m}"));
        }
        if let Some(f) = self.far
            && (f.is_nan() || f <= 0.0)
        {
            return Err(format!("far must be positive, got {f}"));
        }
        Ok(())
    }
}

/// Rendering settings shared by every body (a resource).
#[derive(Resource, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Resource, Default, Debug)]
pub struct SoftBodyDebug {
    /// Give colliders without a mesh one of their shape (balls, ground planes, cuboids,
    /// capsules), when the app renders.
    pub show_colliders: bool,
    /// Draw meshes and gizmos between the last two fixed steps, by the fixed clock's overstep
    /// (smooth motion at any frame rate, one fixed step behind). Off: the last step exactly.
    /// Particle components and `Transform`s always hold the exact last step.
    pub interpolate: bool,
}

impl Default for SoftBodyDebug {
    fn default() -> Self {
        Self {
            show_colliders: true,
            interpolate: false,
        }
    }
}

/// Deforming meshes for bodies with a [`SoftBodySurface`] or a [`SkinnedSurface`], and meshes
/// for colliders that have none (part of [`SoftBodyPlugins`](crate::SoftBodyPlugins)). Needs
/// an app that renders (`Assets<Mesh>`); without one it does nothing.
#[derive(Default, Debug, Clone, Copy)]
pub struct SoftBodyRenderPlugin;

impl Plugin for SoftBodyRenderPlugin {
    fn build(&self, app: &mut App) {
        build(app);
    }
}

/// A high-resolution display mesh embedded in a tet body's rest shape and carried by it
/// (the skinning of CSC417 assignment 3): every frame `x_display = W q` and smooth normals. With `show`, the
/// display mesh is drawn and the body's own surface hidden; without, the reverse.
#[derive(Component, Reflect, Clone, Debug, Default)]
#[reflect(Component, Default, Debug)]
pub struct SkinnedSurface {
    /// Draw the skinned mesh (else the simulation mesh's surface).
    pub show: bool,
    /// Colour of its material.
    pub color: Color,
    /// The skinning matrix, from the tet mesh's vertices.
    #[reflect(ignore)]
    pub skinning: std::sync::Arc<crate::core::fem::skin::Skinning>,
    /// Display triangles.
    #[reflect(ignore)]
    pub triangles: std::sync::Arc<Vec<[u32; 3]>>,
    /// The particle entity of each tet-mesh vertex.
    #[reflect(ignore)]
    pub vertices: Vec<Entity>,
}

/// The entity showing a body's [`SkinnedSurface`] (set by the plugin).
#[derive(Component, Reflect, Clone, Copy, Debug)]
#[reflect(Component, Debug)]
pub struct SkinnedDisplay(pub Entity);

fn build(app: &mut App) {
    let schedule = app
        .world()
        .get_resource::<crate::ecs::SoftBodySchedule>()
        .map_or(FixedUpdate.intern(), |s| s.0);
    app.add_systems(
        schedule,
        snapshot_previous
            .after(crate::ecs::SoftBodySystems::Prepare)
            .before(crate::ecs::SoftBodySystems::Step),
    );
    app.register_type::<SkinnedSurface>()
        .register_type::<SoftBodySurface>()
        .register_type::<SurfaceDetail>()
        .register_type::<SoftBodyDebug>()
        .init_resource::<SoftBodyDebug>()
        .register_type::<SkinnedDisplay>()
        .register_type::<SurfaceVertices>()
        .register_type::<crate::ecs::SoftBodyMeshSurface>()
        .add_systems(
            PostUpdate,
            (
                sync_surfaces,
                sync_mesh_surfaces,
                collider_meshes,
                sync_skinned,
            ),
        );
}

type SkinnedItem<'a> = (
    Entity,
    &'a SkinnedSurface,
    &'a BodySim,
    Option<&'a SkinnedDisplay>,
    Option<&'a mut Visibility>,
);

fn sync_skinned(
    mut commands: Commands,
    meshes: Option<ResMut<Assets<Mesh>>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
    mut bodies: Query<SkinnedItem>,
    mut displays: Query<(&Mesh3d, &mut Visibility), Without<SkinnedSurface>>,
    mut shown: Local<Drawn>,
) {
    let (Some(mut meshes), Some(mut materials)) = (meshes, materials) else {
        return;
    };
    shown.prune(bodies.iter().len(), |e| bodies.contains(e));
    for (e, skin, bs, display, vis) in &mut bodies {
        let Some(sim) = bs.simulation() else { continue };
        if !sim.state.is_finite() {
            continue;
        }
        let skinned = || {
            // q: the tet-mesh vertices' current positions (a vertex whose particle is gone
            // stays at the origin of the map: it no longer moves).
            let q: Vec<crate::math::Vector> = skin
                .vertices
                .iter()
                .map(|v| {
                    bs.index_of(*v)
                        .map_or(crate::math::Vector::ZERO, |i| sim.state.x[i])
                })
                .collect();
            let mut positions = vec![[0f32; 3]; skin.skinning.len()];
            skin.skinning.apply(&q, &mut positions);
            positions
        };
        if let Some(mut vis) = vis {
            let want = if skin.show {
                Visibility::Hidden
            } else {
                Visibility::Inherited
            };
            if *vis != want {
                *vis = want;
            }
        }
        match display.and_then(|d| displays.get_mut(d.0).ok()) {
            Some((m, mut dvis)) => {
                let want = if skin.show {
                    Visibility::Inherited
                } else {
                    Visibility::Hidden
                };
                if *dvis != want {
                    *dvis = want;
                }
                if !skin.show || shown.current(e, bs, false) {
                    continue; // hidden, or asleep and already shown
                }
                let Some(mut mesh) = meshes.get_mut(&m.0) else {
                    continue;
                };
                let positions = skinned();
                if let Some(VertexAttributeValues::Float32x3(p)) =
                    mesh.attribute_mut(Mesh::ATTRIBUTE_POSITION)
                {
                    p.copy_from_slice(&positions);
                }
                if let Some(VertexAttributeValues::Float32x3(nrm)) =
                    mesh.attribute_mut(Mesh::ATTRIBUTE_NORMAL)
                    && nrm.len() == positions.len()
                {
                    smooth_normals(&positions, &skin.triangles, nrm);
                }
            }
            None => {
                let positions = skinned();
                let n = positions.len();
                if skin.triangles.iter().flatten().any(|&i| i as usize >= n) {
                    warn!(
                        "soft body {e}: a skinned triangle names a vertex beyond its {n}; not drawn"
                    );
                    commands.entity(e).remove::<SkinnedSurface>();
                    continue;
                }
                let mut mesh = Mesh::new(
                    PrimitiveTopology::TriangleList,
                    RenderAssetUsages::MAIN_WORLD | RenderAssetUsages::RENDER_WORLD,
                );
                let mut normals = vec![[0.0; 3]; n];
                smooth_normals(&positions, &skin.triangles, &mut normals);
                mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
                mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
                mesh.insert_indices(Indices::U32(
                    skin.triangles.iter().flatten().copied().collect(),
                ));
                let d = commands
                    .spawn((
                        Name::new("skinned display mesh"),
                        Mesh3d(meshes.add(mesh)),
                        MeshMaterial3d(materials.add(StandardMaterial {
                            base_color: skin.color,
                            perceptual_roughness: 0.6,
                            ..default()
                        })),
                        Transform::IDENTITY,
                        if skin.show {
                            Visibility::Inherited
                        } else {
                            Visibility::Hidden
                        },
                    ))
                    .id();
                commands.entity(e).insert(SkinnedDisplay(d));
            }
        }
    }
}

/// Area-weighted vertex normals of a triangle mesh, written into `normals` (one per vertex,
/// unit length; `+Y` where no triangle with area touches a vertex).
pub fn smooth_normals(positions: &[[f32; 3]], triangles: &[[u32; 3]], normals: &mut [[f32; 3]]) {
    let x: Vec<Vec3> = positions.iter().map(|p| Vec3::from_array(*p)).collect();
    let mut acc = vec![Vec3::ZERO; x.len()];
    crate::core::detail::vertex_normals(&x, triangles, &mut acc);
    for (out, n) in normals.iter_mut().zip(acc) {
        *out = n.to_array();
    }
}

/// A body's particle positions before its last fixed step, kept by the render plugin while
/// [`SoftBodyDebug::interpolate`] is on (the step itself keeps no render state).
#[derive(Component, Clone, Debug, Default)]
pub struct PreviousPositions(Vec<Vec3>);

impl PreviousPositions {
    /// The positions (empty until the first step with interpolation on).
    pub fn positions(&self) -> &[Vec3] {
        &self.0
    }
}

/// Before each fixed step (after the model is prepared), keeps the positions the step starts
/// from, for bodies that are about to step.
fn snapshot_previous(
    mut commands: Commands,
    debug: Res<SoftBodyDebug>,
    clock: Res<crate::ecs::SoftBodyClock>,
    mut q: Query<(
        Entity,
        &crate::ecs::SoftBody,
        &BodySim,
        Option<&mut PreviousPositions>,
    )>,
) {
    if !debug.interpolate || !clock.running() {
        return;
    }
    for (e, body, bs, prev) in &mut q {
        let Some(sim) = bs.simulation() else { continue };
        if body.paused || bs.is_diverged() {
            continue;
        }
        let x = sim.state.x.iter().map(|x| x.to_f32());
        match prev {
            Some(mut p) => {
                p.0.clear();
                p.0.extend(x);
            }
            None => {
                commands.entity(e).insert(PreviousPositions(x.collect()));
            }
        }
    }
}

/// The positions to draw: the last fixed step's, or (interpolating) between the last two.
fn drawn_positions(
    bs: &BodySim,
    prev: Option<&PreviousPositions>,
    alpha: Option<f32>,
) -> Vec<Vec3> {
    let Some(sim) = bs.simulation() else {
        return vec![];
    };
    let cur = sim.state.x.iter().map(|x| x.to_f32());
    match (alpha, prev) {
        (Some(a), Some(p)) if p.0.len() == sim.state.x.len() => {
            cur.zip(&p.0).map(|(c, p)| p.lerp(c, a)).collect()
        }
        _ => cur.collect(),
    }
}

/// The state version each body's mesh was last updated at (bodies that sleep keep theirs, and
/// their meshes are left alone).
#[derive(Default)]
struct Drawn(bevy::platform::collections::HashMap<Entity, u64>);

impl Drawn {
    /// True when body `e`'s mesh already shows its state (not interpolating); otherwise
    /// records that it is about to.
    fn current(&mut self, e: Entity, bs: &BodySim, interpolating: bool) -> bool {
        if !interpolating && self.0.get(&e) == Some(&bs.version()) {
            return true;
        }
        self.0.insert(e, bs.version());
        false
    }

    /// Forgets despawned bodies now and then.
    fn prune(&mut self, live: usize, alive: impl Fn(Entity) -> bool) {
        if self.0.len() > 2 * live + 16 {
            self.0.retain(|e, _| alive(*e));
        }
    }
}

fn alpha(debug: &SoftBodyDebug, fixed: &Time<Fixed>) -> Option<f32> {
    debug.interpolate.then(|| fixed.overstep_fraction())
}

/// Which particle entity each vertex of a body's surface mesh shows, fixed when the mesh is
/// made, so particles added later (a mouse grab's handle) or despawned do not shift the
/// surface: a vertex whose particle is gone keeps its last position.
#[derive(Component, Reflect, Clone, Debug)]
#[reflect(Component, Debug)]
pub struct SurfaceVertices(pub Vec<Entity>);

type SurfaceItem<'a> = (
    Entity,
    (&'a SoftBodySurface, Option<&'a SurfaceDetail>),
    (&'a BodySim, Option<&'a PreviousPositions>),
    Option<&'a Mesh3d>,
    Option<&'a SurfaceVertices>,
    Option<&'a mut Detailed>,
    Option<&'a crate::ecs::SelfCollision>,
    Has<MeshMaterial3d<StandardMaterial>>,
);

/// How a body with a [`SurfaceDetail`] is drawn now: its tessellation, and the simulated
/// surface's positions it was last given (a vertex whose particle is gone keeps its last) with
/// their bounding sphere (for the camera distance).
#[derive(Component)]
struct Detailed {
    tessellation: crate::core::detail::Tessellation,
    rounding: crate::core::detail::Rounding,
    coarse: Vec<Vec3>,
    centre: Vec3,
    radius: f32,
}

impl Detailed {
    fn bound(&mut self) {
        let (lo, hi) = self.coarse.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        self.centre = (lo + hi) * 0.5;
        self.radius = (hi - lo).length() * 0.5;
    }
}

/// The level a detailed body should be drawn at: its own, or 1 beyond `far` (leaving the
/// current level alone within 10 % of it).
fn wanted_level(detail: &SurfaceDetail, now: Option<&Detailed>, cameras: &[Vec3]) -> u32 {
    let (Some(far), Some(now)) = (detail.far, now) else {
        return detail.level;
    };
    let Some(dist) = cameras
        .iter()
        .map(|c| (c.distance(now.centre) - now.radius).max(0.0))
        .reduce(f32::min)
    else {
        return detail.level;
    };
    let coarse = now.tessellation.level() == 1 && detail.level != 1;
    let limit = if coarse { 0.9 * far } else { 1.1 * far };
    if dist > limit { 1 } else { detail.level }
}

fn sync_surfaces(
    mut commands: Commands,
    (debug, fixed): (Res<SoftBodyDebug>, Res<Time<Fixed>>),
    meshes: Option<ResMut<Assets<Mesh>>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
    mut q: Query<SurfaceItem>,
    cameras: Query<&GlobalTransform, With<Camera3d>>,
    (mut drawn, mut warned): (
        Local<Drawn>,
        Local<bevy::platform::collections::HashSet<Entity>>,
    ),
) {
    use crate::core::detail::{Rounding, Tessellation};
    let Some(mut meshes) = meshes else { return };
    let mut materials = materials;
    let cameras: Vec<Vec3> = cameras.iter().map(|c| c.translation()).collect();
    drawn.prune(q.iter().len(), |e| q.contains(e));
    for (e, (surface, detail), (bs, prev), mesh3d, vertices, mut detailed, sc, has_material) in
        &mut q
    {
        let Some(sim) = bs.simulation() else { continue };
        if bs.awaiting_rebuild() {
            continue; // torn: the surface names particles the model takes in at its next step
        }
        if !sim.state.is_finite() {
            continue;
        }
        let detail = detail.filter(|d| match d.validate() {
            Ok(()) => true,
            Err(why) => {
                if warned.insert(e) {
                    warn!("soft body {e}: SurfaceDetail: {why}; drawn as simulated");
                }
                false
            }
        });
        // The level to draw at, and whether the mesh must be made (again) for it.
        let level = detail.map(|d| wanted_level(d, detailed.as_deref(), &cameras));
        let remake = mesh3d.is_none()
            || vertices.is_none()
            || level != detailed.as_ref().map(|d| d.tessellation.level());
        if !remake && drawn.current(e, bs, debug.interpolate) {
            continue; // asleep: the mesh already shows it
        }
        let drawn = drawn_positions(bs, prev, alpha(&debug, &fixed));
        if !remake && let (Some(m), Some(vertices)) = (mesh3d, vertices) {
            let Some(mut mesh) = meshes.get_mut(&m.0) else {
                continue;
            };
            let Some(VertexAttributeValues::Float32x3(p)) =
                mesh.attribute_mut(Mesh::ATTRIBUTE_POSITION)
            else {
                continue;
            };
            match detailed.as_deref_mut() {
                Some(d) => {
                    for (out, v) in d.coarse.iter_mut().zip(&vertices.0) {
                        if let Some(i) = bs.index_of(*v) {
                            *out = drawn[i];
                        }
                    }
                    d.bound();
                    // Both attributes at once: taken out of the mesh and put back.
                    let mut positions = std::mem::take(p);
                    let mut normals = match mesh.attribute_mut(Mesh::ATTRIBUTE_NORMAL) {
                        Some(VertexAttributeValues::Float32x3(n)) => std::mem::take(n),
                        _ => vec![],
                    };
                    normals.resize(positions.len(), [0.0; 3]);
                    d.tessellation
                        .draw(&d.coarse, d.rounding, &mut positions, &mut normals);
                    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
                    mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
                    continue;
                }
                None => {
                    for (out, v) in p.iter_mut().zip(&vertices.0) {
                        if let Some(i) = bs.index_of(*v) {
                            *out = drawn[i].to_array();
                        }
                    }
                }
            };
            let positions = p.clone();
            if let Some(VertexAttributeValues::Float32x3(nrm)) =
                mesh.attribute_mut(Mesh::ATTRIBUTE_NORMAL)
                && nrm.len() == positions.len()
            {
                smooth_normals(&positions, &surface.triangles, nrm);
            }
            continue;
        }
        // A new mesh: its first vertices are the body's particles as they are now.
        let n = drawn.len();
        if surface.triangles.iter().flatten().any(|&i| i as usize >= n) {
            warn!(
                "soft body {e}: a surface triangle names a particle index beyond its {n} particles; not drawn"
            );
            commands.entity(e).remove::<SoftBodySurface>();
            continue;
        }
        let mut ec = commands.entity(e);
        let (positions, normals, triangles, uvs) = match (detail, level) {
            (Some(d), Some(level)) => {
                let tessellation = match Tessellation::new(&surface.triangles, n, level) {
                    Ok(t) => t,
                    Err(why) => {
                        warn!("soft body {e}: SurfaceDetail: {why}; not drawn");
                        ec.remove::<SoftBodySurface>();
                        continue;
                    }
                };
                let quarter = sc.map_or(f32::INFINITY, |s| 0.25 * s.thickness);
                let rounding = Rounding {
                    alpha: d.roundness,
                    max_offset: d.max_offset.map_or(quarter, |m| m.min(quarter)),
                };
                let mut positions = vec![[0.0; 3]; tessellation.len()];
                let mut normals = vec![[0.0; 3]; tessellation.len()];
                tessellation.draw(&drawn, rounding, &mut positions, &mut normals);
                let uvs = (surface.uvs.len() == n).then(|| tessellation.interpolate(&surface.uvs));
                let triangles = tessellation.triangles().to_vec();
                let mut state = Detailed {
                    tessellation,
                    rounding,
                    coarse: drawn,
                    centre: Vec3::ZERO,
                    radius: 0.0,
                };
                state.bound();
                ec.insert(state);
                (positions, normals, triangles, uvs)
            }
            _ => {
                if detailed.is_some() {
                    ec.remove::<Detailed>();
                }
                let positions: Vec<[f32; 3]> = drawn.iter().map(|p| p.to_array()).collect();
                let uvs = (surface.uvs.len() == n).then(|| surface.uvs.clone());
                let mut normals = vec![[0.0; 3]; n];
                smooth_normals(&positions, &surface.triangles, &mut normals);
                (positions, normals, surface.triangles.clone(), uvs)
            }
        };
        let mut mesh = Mesh::new(
            PrimitiveTopology::TriangleList,
            RenderAssetUsages::MAIN_WORLD | RenderAssetUsages::RENDER_WORLD,
        );
        mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
        mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
        if let Some(uvs) = uvs {
            mesh.insert_attribute(Mesh::ATTRIBUTE_UV_0, uvs);
        }
        mesh.insert_indices(Indices::U32(triangles.into_iter().flatten().collect()));
        let handle = meshes.add(mesh);
        ec.insert((
            Mesh3d(handle),
            SurfaceVertices(bs.particle_entities().to_vec()),
        ));
        if !has_material && let Some(materials) = materials.as_mut() {
            ec.insert(MeshMaterial3d(materials.add(StandardMaterial {
                base_color: surface.color,
                perceptual_roughness: 0.8,
                double_sided: true,
                cull_mode: None,
                ..default()
            })));
        }
    }
}

/// Buffers reused every frame: particle positions, welded triangles, normals, vertex → particle.
type MeshScratch = (Vec<[f32; 3]>, Vec<[u32; 3]>, Vec<[f32; 3]>, Vec<u32>);

type MeshSurfaceItem<'a> = (
    Entity,
    &'a mut crate::ecs::SoftBodyMeshSurface,
    (&'a BodySim, Option<&'a PreviousPositions>),
    Option<&'a Mesh3d>,
    Has<MeshMaterial3d<StandardMaterial>>,
);

/// Bodies drawn with a mesh of the game's own: the mesh asset is made on the first frame (a
/// copy of the source, so the source asset stays as loaded); then every frame its vertices
/// take their particles' positions, normals are recomputed per particle over the welded
/// triangles and shared by every copy of a seam vertex, and tangents are regenerated when the
/// mesh has them.
fn sync_mesh_surfaces(
    mut commands: Commands,
    debug: Res<SoftBodyDebug>,
    fixed: Res<Time<Fixed>>,
    meshes: Option<ResMut<Assets<Mesh>>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
    mut q: Query<MeshSurfaceItem>,
    (mut scratch, mut shown): (Local<MeshScratch>, Local<Drawn>),
) {
    let Some(mut meshes) = meshes else { return };
    let mut materials = materials;
    shown.prune(q.iter().len(), |e| q.contains(e));
    for (e, mut surface, (bs, prev), mesh3d, has_material) in &mut q {
        let Some(sim) = bs.simulation() else { continue };
        if !sim.state.is_finite() {
            continue;
        }
        let Some(m) = mesh3d else {
            let Some(source) = surface.source.take() else {
                continue;
            };
            let mut mesh = (*source).clone();
            mesh.asset_usage = RenderAssetUsages::MAIN_WORLD | RenderAssetUsages::RENDER_WORLD;
            if mesh.attribute(Mesh::ATTRIBUTE_NORMAL).is_none() {
                let n = mesh.count_vertices();
                mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, vec![[0.0f32, 1.0, 0.0]; n]);
            }
            let mut ec = commands.entity(e);
            ec.insert(Mesh3d(meshes.add(mesh)));
            if !has_material && let Some(materials) = materials.as_mut() {
                ec.insert(MeshMaterial3d(materials.add(StandardMaterial {
                    base_color: surface.color,
                    perceptual_roughness: 0.85,
                    double_sided: true,
                    cull_mode: None,
                    ..default()
                })));
            }
            continue;
        };
        if surface.torn
            && let Some(mut mesh) = meshes.get_mut(&m.0)
        {
            follow_tear(&mut mesh, &surface);
            surface.torn = false;
        }
        if shown.current(e, bs, debug.interpolate) {
            continue; // asleep: the mesh already shows it
        }
        let Some(mut mesh) = meshes.get_mut(&m.0) else {
            continue;
        };
        let drawn = drawn_positions(bs, prev, alpha(&debug, &fixed));
        let (particle_pos, tris, normals, index) = &mut *scratch;
        // Each vertex's packed particle index (a vertex whose particle is gone keeps its
        // position and shows the first particle's normal).
        index.clear();
        index.extend(
            surface
                .vertices
                .iter()
                .map(|p| bs.index_of(*p).map_or(u32::MAX, |i| i as u32)),
        );
        particle_pos.clear();
        particle_pos.extend(drawn.iter().map(|p| p.to_array()));
        tris.clear();
        if let Some(ix) = mesh.indices() {
            let mut ix = ix.iter();
            while let (Some(a), Some(b), Some(c)) = (ix.next(), ix.next(), ix.next()) {
                let t = [a, b, c].map(|v| index.get(v).copied().unwrap_or(u32::MAX));
                if t.iter().all(|i| (*i as usize) < particle_pos.len()) {
                    tris.push(t);
                }
            }
        }
        normals.clear();
        normals.resize(particle_pos.len(), [0.0; 3]);
        smooth_normals(particle_pos, tris, normals);
        if let Some(VertexAttributeValues::Float32x3(p)) =
            mesh.attribute_mut(Mesh::ATTRIBUTE_POSITION)
        {
            for (out, i) in p.iter_mut().zip(index.iter()) {
                if let Some(x) = particle_pos.get(*i as usize) {
                    *out = *x;
                }
            }
        }
        if let Some(VertexAttributeValues::Float32x3(nrm)) =
            mesh.attribute_mut(Mesh::ATTRIBUTE_NORMAL)
        {
            for (out, i) in nrm.iter_mut().zip(index.iter()) {
                if let Some(n) = normals.get(*i as usize) {
                    *out = *n;
                }
            }
        }
        if mesh.attribute(Mesh::ATTRIBUTE_TANGENT).is_some()
            && mesh.attribute(Mesh::ATTRIBUTE_UV_0).is_some()
            && let Err(err) = mesh.generate_tangents()
        {
            warn!("soft body {e}: tangents not regenerated: {err}");
        }
    }
}

/// A game's mesh after a tear: the vertices the tear added (each a copy of the vertex it
/// split from, every attribute) and the torn triangles as its index buffer.
fn follow_tear(mesh: &mut Mesh, surface: &crate::ecs::SoftBodyMeshSurface) {
    let own = surface.vertices.len() - surface.split_from.len();
    let have = mesh.count_vertices();
    if have >= own && have < surface.vertices.len() {
        let from = &surface.split_from[have - own..];
        for (_, values) in mesh.attributes_mut() {
            push_vertex_copies(values, from);
        }
    }
    mesh.insert_indices(Indices::U32(
        surface.triangles.iter().flatten().copied().collect(),
    ));
}

/// Appends to an attribute's values a copy of the value at each of `from`.
fn push_vertex_copies(values: &mut VertexAttributeValues, from: &[u32]) {
    macro_rules! copies {
        ($($v:ident),*) => {
            match values {
                $(VertexAttributeValues::$v(a) => {
                    for &i in from {
                        let x = a[i as usize];
                        a.push(x);
                    }
                })*
            }
        };
    }
    copies!(
        Uint8,
        Uint8x2,
        Uint8x4,
        Sint8,
        Sint8x2,
        Sint8x4,
        Unorm8,
        Unorm8x2,
        Unorm8x4,
        Snorm8,
        Snorm8x2,
        Snorm8x4,
        Uint16,
        Uint16x2,
        Uint16x4,
        Sint16,
        Sint16x2,
        Sint16x4,
        Unorm16,
        Unorm16x2,
        Unorm16x4,
        Snorm16,
        Snorm16x2,
        Snorm16x4,
        Float16,
        Float16x2,
        Float16x4,
        Float32,
        Float32x2,
        Float32x3,
        Float32x4,
        Uint32,
        Uint32x2,
        Uint32x3,
        Uint32x4,
        Sint32,
        Sint32x2,
        Sint32x3,
        Sint32x4,
        Float64,
        Float64x2,
        Float64x3,
        Float64x4,
        Unorm8x4Bgra,
        Unorm10_10_10_2
    );
}

fn collider_meshes(
    mut commands: Commands,
    debug: Res<SoftBodyDebug>,
    meshes: Option<ResMut<Assets<Mesh>>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
    q: Query<(Entity, &crate::ecs::SoftBodyCollider), Without<Mesh3d>>,
) {
    let (Some(mut meshes), Some(mut materials)) = (meshes, materials) else {
        return;
    };
    if !debug.show_colliders {
        return;
    }
    for (e, c) in &q {
        let shape = &c.shape.0;
        let (mesh, color) = if let Some(b) = shape.as_ball() {
            (
                Sphere::new(b.radius).mesh().uv(48, 24),
                Color::srgb(0.75, 0.78, 0.82),
            )
        } else if shape.as_halfspace().is_some() {
            (
                Plane3d::new(Vec3::Y, Vec2::splat(5.0)).mesh().build(),
                Color::srgb(0.25, 0.27, 0.3),
            )
        } else if let Some(cu) = shape.as_cuboid() {
            let h = cu.half_extents;
            (
                Cuboid::new(2.0 * h.x, 2.0 * h.y, 2.0 * h.z).mesh().build(),
                Color::srgb(0.6, 0.62, 0.66),
            )
        } else if let Some(cap) = shape.as_capsule() {
            let half = (cap.segment.b - cap.segment.a).length() * 0.5;
            (
                Capsule3d::new(cap.radius, 2.0 * half).mesh().build(),
                Color::srgb(0.6, 0.62, 0.66),
            )
        } else {
            continue;
        };
        commands.entity(e).insert((
            Mesh3d(meshes.add(mesh)),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color: color,
                metallic: 0.2,
                perceptual_roughness: 0.5,
                ..default()
            })),
        ));
    }
}
