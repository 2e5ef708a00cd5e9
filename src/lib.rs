//! # bevy_soft_body
//!
//! Soft-body physics for Bevy: cloth, ropes, jelly and elastic solids advanced by
//! interchangeable, measured time integrators.
//!
//! The crate has two layers:
//! - [`core`]: the numerics, without Bevy — the ODE abstraction ([`core::ode`]), the
//!   integrators ([`core::integrate`]), the particle model and its forces, collisions, scene
//!   layouts ([`core::scene`], [`core::build`]) and the headless driver ([`core::driver`]).
//! - the Bevy face (feature `plugin`, on by default): `ecs` (components, `SoftBodyPlugin`,
//!   spawning scenes), `render` (deforming meshes, gizmos) and, with feature `egui`, `ui`
//!   (panel, keys, mouse grab).
//!
//! Layout is not driver: what a scene contains is described apart from how it is advanced,
//! so switching from RK4 to symplectic Euler is one [`IntegratorKind`] value.
//!
//! ```
//! use bevy_soft_body::prelude::*;
//!
//! let scene = build::chain(&build::ChainParams::default()).unwrap();
//! let (model, state) = scene.build().unwrap();
//! let config = DriverConfig { integrator: "r".parse().unwrap(), ..Default::default() };
//! let mut sim = Simulation::new(model, state, config);
//! sim.run_until(1.0).unwrap();
//! assert!(sim.state.x[3].y < 0.0); // the chain swung down
//! ```

// `Scalar` is f32 or f64 by feature, so a cast to or from it is a no-op in one build and
// needed in the other.
#![allow(clippy::unnecessary_cast)]
#![warn(missing_docs)]

#[cfg(feature = "plugin")]
pub mod assets;
#[cfg(feature = "avian")]
pub mod avian;
pub mod core;
#[cfg(feature = "plugin")]
pub mod ecs;
pub mod math;
#[cfg(feature = "plugin")]
mod plugins;
#[cfg(feature = "plugin")]
pub mod render;
#[cfg(feature = "egui")]
pub mod ui;

/// The names most programs need.
pub mod prelude {
    pub use crate::core::build;
    pub use crate::core::build::{SurfaceParams, SurfaceStiffness};
    pub use crate::core::collide::{ColliderDesc, ContactMaterial, ShapeDesc};
    pub use crate::core::driver::{
        CflLimit, Divergence, DivergenceReason, DriverConfig, Simulation, SleepParams, StepPolicy,
    };
    pub use crate::core::fem::NeoHookean;
    pub use crate::core::fem::mesh::TetMesh;
    pub use crate::core::forces::{Buoyancy, ForceField, RadialBlast, SpringLaw, Wind};
    pub use crate::core::integrate::SolverChoice;
    pub use crate::core::integrate::{AdaptiveConfig, Integrator, IntegratorKind, StepError};
    pub use crate::core::motion::Motion;
    pub use crate::core::ode::{CircleSystem, Energy, OdeState, OdeSystem, ParticleState};
    pub use crate::core::particles::ParticleModel;
    pub use crate::core::scene::{Scene, SceneError};
    pub use crate::core::self_contact::SelfContactParams;
    pub use crate::math::{PRECISION, Scalar, Vector};

    #[cfg(feature = "plugin")]
    pub use crate::SoftBodyPlugins;
    #[cfg(feature = "plugin")]
    pub use crate::assets::{
        SoftBodyAssetPlugin, SoftBodySceneAsset, SoftBodySceneRoot, SoftBodySceneSpawned,
        TetMeshAsset,
    };
    #[cfg(feature = "avian")]
    pub use crate::avian::{
        NoSoftBodyContact, SoftBodyAvianPlugin, SoftBodyAvianSettings, SoftBodyImpulse,
    };
    #[cfg(feature = "plugin")]
    pub use crate::ecs::{
        AutoSettings, BodyParticles, BodySprings, BodyState, BodyTets, ElasticMaterial,
        ExternalForce, GlobalForceFields, GlobalWind, LinearSolverChoice, MeshBody, MeshPins,
        Particle, ParticleOf, Pinned, ResetSoftBodies, ScriptedMotion, SelfCollision, SoftBody,
        SoftBodyClock, SoftBodyCollider, SoftBodyDiagnostics, SoftBodyDiverged,
        SoftBodyForceFields, SoftBodyGltf, SoftBodyGltfSpawned, SoftBodyInitial, SoftBodyInvalid,
        SoftBodyMeshSurface, SoftBodyPlugin, SoftBodySleep, SoftBodySleepingDisabled,
        SoftBodyStatus, SoftBodySystems, SoftBodyTorn, SoftBodyWind, SpawnSoftBody, Spring,
        SpringOf, Tearable, Tet, TetOf, WakeSoftBody, triangle_mesh,
    };
    #[cfg(feature = "plugin")]
    pub use crate::render::{
        SkinnedSurface, SoftBodyDebug, SoftBodyDebugPlugin, SoftBodyDebugRender, SoftBodyGizmos,
        SoftBodyRenderPlugin, SoftBodySurface, SurfaceDetail,
    };
    #[cfg(feature = "egui")]
    pub use crate::ui::{SoftBodyUi, SoftBodyUiPlugin};
}

pub use crate::core::integrate::IntegratorKind;
#[cfg(feature = "plugin")]
pub use crate::plugins::SoftBodyPlugins;
