//! Debug drawing with Bevy gizmos, in a gizmo config group of its own ([`SoftBodyGizmos`]):
//! springs as lines, particles as small spheres. Bodies without a surface (chains, wires, jelly
//! lattices) are always drawn this way; with [`SoftBodyGizmos::wireframe`] every body is
//! (bodies with a [`SoftBodySurface`] or a mesh of the game's are drawn as meshes otherwise). A
//! [`SoftBodyDebugRender`] on a body overrides the colours or hides it.

use super::{PreviousPositions, SoftBodyDebug, SoftBodySurface, alpha, drawn_positions};
use crate::core::ode::OdeState;
use crate::ecs::plugin::BodySim;
use bevy::prelude::*;

/// The soft-body gizmo config group: `GizmoConfig` (enabled, line width, depth bias, render
/// layers) through `GizmoConfigStore::config_mut::<SoftBodyGizmos>()`, and these settings.
#[derive(Reflect, GizmoConfigGroup, Clone, Copy, Debug, PartialEq)]
#[reflect(Default, Debug)]
pub struct SoftBodyGizmos {
    /// Draw every body's springs as lines, bodies with a surface mesh included.
    pub wireframe: bool,
    /// Radius of the particle spheres drawn for bodies without a surface (m).
    pub particle_radius: f32,
    /// Colour of spring lines (a body's [`SoftBodyDebugRender`] may override it).
    pub spring_color: Color,
    /// Colour of particle spheres (a body's [`SoftBodyDebugRender`] may override it).
    pub particle_color: Color,
}

impl Default for SoftBodyGizmos {
    fn default() -> Self {
        Self {
            wireframe: false,
            particle_radius: 0.02,
            spring_color: Color::srgb(0.9, 0.9, 0.5),
            particle_color: Color::srgb(0.3, 0.7, 1.0),
        }
    }
}

/// Per-body debug drawing (as avian's `DebugRender`): colours of this body's springs and
/// particles, `None` to leave them out. A body without one uses [`SoftBodyGizmos`]' colours.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct SoftBodyDebugRender {
    /// Spring lines (`None`: not drawn).
    pub springs: Option<Color>,
    /// Particle spheres (`None`: not drawn).
    pub particles: Option<Color>,
    /// Draw this body even when it has a surface mesh and wireframe mode is off.
    pub always: bool,
}

impl Default for SoftBodyDebugRender {
    fn default() -> Self {
        let g = SoftBodyGizmos::default();
        Self {
            springs: Some(g.spring_color),
            particles: Some(g.particle_color),
            always: false,
        }
    }
}

impl SoftBodyDebugRender {
    /// Draws nothing for this body.
    pub fn none() -> Self {
        Self {
            springs: None,
            particles: None,
            always: false,
        }
    }

    /// Draws this body's springs and particles even under its surface mesh.
    pub fn always() -> Self {
        Self {
            always: true,
            ..default()
        }
    }
}

/// Gizmo drawing of soft bodies (part of [`SoftBodyPlugins`](crate::SoftBodyPlugins)). Needs
/// Bevy's gizmos (`GizmoPlugin`, in `DefaultPlugins`); without them it does nothing.
#[derive(Default, Debug, Clone, Copy)]
pub struct SoftBodyDebugPlugin;

impl Plugin for SoftBodyDebugPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<SoftBodyGizmos>()
            .register_type::<SoftBodyDebugRender>();
    }

    fn finish(&self, app: &mut App) {
        // Gizmo groups need the gizmo plugin's store (absent in headless apps).
        if app.world().contains_resource::<GizmoConfigStore>() {
            app.init_gizmo_group::<SoftBodyGizmos>()
                .add_systems(PostUpdate, draw_gizmos);
        }
    }
}

type GizmoItem<'a> = (
    &'a BodySim,
    (Has<SoftBodySurface>, Has<crate::ecs::SoftBodyMeshSurface>),
    Option<&'a SoftBodyDebugRender>,
    Option<&'a PreviousPositions>,
);

fn draw_gizmos(
    debug: Option<Res<SoftBodyDebug>>,
    fixed: Res<Time<Fixed>>,
    mut gizmos: Gizmos<SoftBodyGizmos>,
    q: Query<GizmoItem>,
) {
    let group = *gizmos.config_ext;
    let a = debug.and_then(|d| alpha(&d, &fixed));
    for (bs, (surface, mesh_surface), render, prev) in &q {
        // Drawn as a mesh: its own surface, or a mesh of the game's.
        let has_surface = surface || mesh_surface;
        let Some(sim) = bs.simulation() else { continue };
        let always = render.is_some_and(|r| r.always);
        if has_surface && !group.wireframe && !always {
            continue;
        }
        if !sim.state.is_finite() {
            continue;
        }
        let (springs, particles) = match render {
            Some(r) => (r.springs, r.particles),
            None => (Some(group.spring_color), Some(group.particle_color)),
        };
        let x = drawn_positions(bs, prev, a);
        if let Some(c) = springs {
            for s in sim.system.springs.as_slice() {
                gizmos.line(x[s.i as usize], x[s.j as usize], c);
            }
        }
        if let Some(c) = particles
            && (!has_surface || always)
        {
            for p in &x {
                gizmos.sphere(Isometry3d::from_translation(*p), group.particle_radius, c);
            }
        }
    }
}
