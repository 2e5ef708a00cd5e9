//! [`SoftBodyPlugins`]: every part of the Bevy face in one group, each replaceable or
//! disabled, as avian's `PhysicsPlugins`.

use crate::assets::SoftBodyAssetPlugin;
use crate::ecs::SoftBodyPlugin;
use crate::render::{SoftBodyDebugPlugin, SoftBodyRenderPlugin};
use bevy::app::{PluginGroup, PluginGroupBuilder};
use bevy::ecs::schedule::{InternedScheduleLabel, ScheduleLabel};
use bevy::prelude::*;

/// Soft-body physics and everything around it, in this order:
///
/// | plugin | does |
/// | --- | --- |
/// | [`SoftBodyPlugin`] | the physics: components → core model → fixed steps → components |
/// | [`SoftBodyRenderPlugin`] | deforming surface and skinned meshes, collider meshes |
/// | [`SoftBodyAssetPlugin`] | tet meshes (`.msh`, `.mesh`, `.node`) as assets |
/// | [`SoftBodyDebugPlugin`] | gizmos ([`SoftBodyGizmos`](crate::render::SoftBodyGizmos)) |
/// | `SoftBodyAvianPlugin` (feature `avian`) | coupling with avian3d's rigid bodies |
/// | `SoftBodyUiPlugin` (feature `egui`) | the live-tuning panel, keys, mouse grab |
///
/// ```no_run
/// use bevy::prelude::*;
/// use bevy_soft_body::prelude::*;
///
/// App::new()
///     .add_plugins((DefaultPlugins, SoftBodyPlugins::default()))
///     .run();
/// ```
///
/// A game that draws bodies itself and has no use for the panel:
///
/// ```no_run
/// # use bevy::prelude::*;
/// # use bevy_soft_body::prelude::*;
/// # #[cfg(feature = "egui")]
/// App::new().add_plugins((
///     DefaultPlugins,
///     SoftBodyPlugins::default()
///         .build()
///         .disable::<SoftBodyRenderPlugin>()
///         .disable::<SoftBodyUiPlugin>(),
/// ));
/// ```
#[derive(Debug, Clone, Copy)]
pub struct SoftBodyPlugins {
    schedule: InternedScheduleLabel,
}

impl Default for SoftBodyPlugins {
    fn default() -> Self {
        Self::new(FixedUpdate)
    }
}

impl SoftBodyPlugins {
    /// The group with the physics stepping in `schedule` (`FixedUpdate` by default).
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        Self {
            schedule: schedule.intern(),
        }
    }
}

impl PluginGroup for SoftBodyPlugins {
    fn build(self) -> PluginGroupBuilder {
        let group = PluginGroupBuilder::start::<Self>()
            .add(SoftBodyPlugin::new(self.schedule))
            .add(SoftBodyRenderPlugin)
            .add(SoftBodyAssetPlugin::default())
            .add(SoftBodyDebugPlugin);
        #[cfg(feature = "avian")]
        let group = group.add(crate::avian::SoftBodyAvianPlugin);
        #[cfg(feature = "egui")]
        let group = group.add(crate::ui::SoftBodyUiPlugin);
        group
    }
}
