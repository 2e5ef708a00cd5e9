//! The Bevy face of the core (feature `plugin`): components that are the layout,
//! [`SoftBodyPlugin`] that gathers them into the core's packed model, steps every body with the
//! core driver and writes the state back, and [`SpawnSoftBody`] to spawn whole bodies from the
//! core's scene builders or JSON files.

mod components;
mod diagnostics;
pub(crate) mod mesh_body;
pub(crate) mod plugin;
mod spawn;

pub use components::*;
pub use diagnostics::SoftBodyDiagnostics;
pub use mesh_body::{
    MeshBody, MeshPins, SoftBodyGltf, SoftBodyGltfSpawned, SoftBodyMeshSurface, triangle_mesh,
};
#[allow(deprecated)]
pub use plugin::SoftBodySet;
pub use plugin::{BodySim, SoftBodyKernelPool, SoftBodyPlugin, SoftBodySchedule, SoftBodySystems};
pub use spawn::{DisplayMesh, SpawnSoftBody};
