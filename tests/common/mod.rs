//! Helpers the integration tests share (not a test itself).
#![allow(dead_code)]

#[cfg(feature = "plugin")]
pub use plugin::*;

#[cfg(feature = "plugin")]
mod plugin {
    use bevy::app::{PluginGroup, PluginGroupBuilder};

    /// `SoftBodyPlugins` for a headless app: everything but the egui panel (which needs a
    /// window).
    pub fn headless_plugins() -> PluginGroupBuilder {
        let group = bevy_soft_body::SoftBodyPlugins::default().build();
        #[cfg(feature = "egui")]
        let group = group.disable::<bevy_soft_body::ui::SoftBodyUiPlugin>();
        group
    }
}
