//! Helpers the integration tests share (not a test itself).
#![allow(dead_code)]

#[cfg(feature = "plugin")]
pub use plugin::*;

#[cfg(feature = "plugin")]
mod plugin {
    use bevy::app::{PluginGroup, PluginGroupBuilder};
    use bevy::prelude::*;
    use bevy::time::TimeUpdateStrategy;

    /// `SoftBodyPlugins` for a headless app: everything but the egui panel (which needs a
    /// window).
    pub fn headless_plugins() -> PluginGroupBuilder {
        let group = bevy_soft_body::SoftBodyPlugins::default().build();
        #[cfg(feature = "egui")]
        let group = group.disable::<bevy_soft_body::ui::SoftBodyUiPlugin>();
        group
    }

    /// A headless app (`MinimalPlugins`, transforms, [`headless_plugins`]) whose every
    /// `update` runs exactly one fixed step of `frame` seconds, past its first update (which
    /// has zero delta and steps nothing).
    pub fn headless_app(frame: f64) -> App {
        let mut app = App::new();
        app.add_plugins((MinimalPlugins, TransformPlugin, headless_plugins()))
            .insert_resource(Time::<Fixed>::from_seconds(frame))
            .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
        app.update();
        app
    }
}
