//! [`SoftBodyPlugin`]: gathers each body's components into the core's packed model (only when
//! something changed), advances every body in parallel with the core driver — substeps of one
//! size that land exactly on the fixed frame's end, collisions every substep, the divergence
//! guard — and
//! writes the state back to the components.

use super::components::*;
use crate::core::driver::{Divergence, Simulation};
use crate::core::motion::Motion;
use crate::core::ode::{OdeState, ParticleState};
use crate::core::particles::ParticleModel;
use crate::math::{Scalar, ToScalar, VectorExt};
use bevy::ecs::schedule::{InternedScheduleLabel, ScheduleLabel};
use bevy::prelude::*;
use std::collections::HashMap;

mod motion;
mod rebuild;
mod step;
use motion::scripted_motion;
pub(crate) use rebuild::prepare;
use step::{contact_between, reset, step, tear, tick, writeback};

/// Soft-body physics. Runs in `FixedUpdate` by default ([`SoftBodyPlugin::new`] picks another
/// schedule), in the chained sets [`SoftBodySystems`]; meshes and debug drawing follow in
/// `PostUpdate`, once per frame.
#[derive(Debug, Clone)]
pub struct SoftBodyPlugin {
    schedule: InternedScheduleLabel,
    kernel_threads: usize,
}

impl Default for SoftBodyPlugin {
    fn default() -> Self {
        Self::new(FixedUpdate)
    }
}

impl SoftBodyPlugin {
    /// Runs the simulation in `schedule` (the frame length is still `Time<Fixed>`'s timestep).
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        Self {
            schedule: schedule.intern(),
            kernel_threads: 0,
        }
    }

    /// Threads that share the force evaluation of one large body (a cloth of thousands of
    /// springs, a body of thousands of tets; small bodies always run on one thread): `0`, the
    /// default, uses every core; `1` steps each body on one thread. Bodies are stepped in
    /// parallel with each other either way, and the results are the same bits for any count.
    /// Needs the `parallel` feature (on by default); without it every body uses one thread.
    pub fn with_kernel_threads(mut self, threads: usize) -> Self {
        self.kernel_threads = threads;
        self
    }
}

/// The threads large bodies' force kernels share (see
/// [`SoftBodyPlugin::with_kernel_threads`]): a `core::kernels::team::Team` (feature
/// `parallel`) whose helpers spin between the passes of a step and sleep when the simulation is idle;
/// `None`: one thread per body. One body at a time steps on the team; a large body stepped
/// beside it (bodies are stepped in parallel) runs on its own thread, with the same bits.
#[derive(Resource, Clone, Default)]
pub struct SoftBodyKernelPool {
    #[cfg(feature = "parallel")]
    team: Option<std::sync::Arc<crate::core::kernels::team::Team>>,
}

impl SoftBodyKernelPool {
    /// A team of `threads` threads (`0`: every core; `1`: none).
    pub fn new(threads: usize) -> Self {
        #[cfg(feature = "parallel")]
        {
            let team = crate::core::kernels::team::Team::new(threads);
            Self {
                team: (team.threads() > 1).then(|| std::sync::Arc::new(team)),
            }
        }
        #[cfg(not(feature = "parallel"))]
        {
            let _ = threads;
            Self {}
        }
    }

    /// Number of threads a large body's kernels use.
    pub fn threads(&self) -> usize {
        #[cfg(feature = "parallel")]
        {
            self.team.as_ref().map_or(1, |t| t.threads())
        }
        #[cfg(not(feature = "parallel"))]
        {
            1
        }
    }

    /// Advances `sim` one frame, on the team when the body is large enough to be cut into
    /// chunks.
    fn advance(
        &self,
        sim: &mut Simulation<ParticleState, ParticleModel>,
    ) -> Result<crate::core::driver::FrameReport, Divergence> {
        #[cfg(feature = "parallel")]
        if let Some(team) = &self.team
            && sim.system.is_chunked()
        {
            return team.run(|| sim.advance_frame());
        }
        sim.advance_frame()
    }
}

impl std::fmt::Debug for SoftBodyKernelPool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SoftBodyKernelPool")
            .field("threads", &self.threads())
            .finish()
    }
}

/// The schedule [`SoftBodyPlugin`] steps in (a resource, for plugins that add systems beside
/// its sets).
#[derive(Resource, Debug, Clone, Copy, PartialEq, Eq)]
pub struct SoftBodySchedule(pub InternedScheduleLabel);

/// The phases of a soft-body step, chained in this order in the plugin's schedule
/// (`FixedUpdate` by default); order your systems against them, as with avian's
/// `PhysicsSystems`.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SoftBodySystems {
    /// Before anything the plugin does in the frame (empty: for the app's own systems, e.g.
    /// moving pin targets or colliders that the step should see this frame).
    First,
    /// Topology and parameter changes → packed core model (rebuilt only when something
    /// changed); teleports, pin targets and collider poses applied.
    Prepare,
    /// Every body advanced by one fixed frame in substeps (forces, integration, collisions),
    /// bodies in parallel. Forces, integration and collision run inside this one set rather
    /// than as systems of their own: a multi-stage method (RK4, the implicit methods' Newton
    /// iterations) evaluates the forces several times per substep, and a frame has many
    /// substeps. Then contact between bodies with [`SelfCollision`] whose frames' boxes
    /// overlap (one pass per group of touching bodies over the frame).
    Step,
    /// Core state → [`Particle`] components (and their `Transform`s), messages, events and
    /// diagnostics sent.
    Writeback,
    /// After everything the plugin does in the frame (empty: for the app's own systems that
    /// read this frame's result).
    Last,
}

/// The former name of [`SoftBodySystems`].
#[deprecated(
    since = "0.1.0",
    note = "renamed `SoftBodySystems`, as avian's `PhysicsSystems`"
)]
pub type SoftBodySet = SoftBodySystems;

impl Plugin for SoftBodyPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<SoftBody>()
            .register_type::<SoftBodyStatus>()
            .register_type::<Particle>()
            .register_type::<ParticleOf>()
            .register_type::<BodyParticles>()
            .register_type::<Spring>()
            .register_type::<Tet>()
            .register_type::<TetOf>()
            .register_type::<BodyTets>()
            .register_type::<ElasticMaterial>()
            .register_type::<LinearSolverChoice>()
            .register_type::<AutoSettings>()
            .register_type::<SpringOf>()
            .register_type::<BodySprings>()
            .register_type::<Pinned>()
            .register_type::<ExternalForce>()
            .register_type::<SoftBodyWind>()
            .register_type::<SelfCollision>()
            .register_type::<Tearable>()
            .add_message::<SoftBodyTorn>()
            .register_type::<SoftBodySleep>()
            .init_resource::<SoftBodySleep>()
            .register_type::<SoftBodySleepingDisabled>()
            .add_message::<WakeSoftBody>()
            .register_type::<GlobalWind>()
            .register_type::<SoftBodyForceFields>()
            .register_type::<GlobalForceFields>()
            .init_resource::<GlobalForceFields>()
            .register_type::<SoftBodyCollider>()
            .register_type::<ScriptedMotion>()
            .register_type::<SoftBodyClock>()
            .register_type::<SoftBodyInitial>()
            .init_resource::<SoftBodyClock>()
            .insert_resource(SoftBodyKernelPool::new(self.kernel_threads))
            .add_message::<ResetSoftBodies>()
            .init_resource::<GlobalWind>()
            .insert_resource(SoftBodySchedule(self.schedule))
            .add_message::<SoftBodyDiverged>()
            .add_message::<SoftBodyInvalid>()
            .configure_sets(
                self.schedule,
                (
                    SoftBodySystems::First,
                    SoftBodySystems::Prepare,
                    SoftBodySystems::Step,
                    SoftBodySystems::Writeback,
                    SoftBodySystems::Last,
                )
                    .chain(),
            )
            .add_systems(
                self.schedule,
                (
                    (reset, scripted_motion, motion::scale_colliders, prepare)
                        .chain()
                        .in_set(SoftBodySystems::Prepare),
                    (step, contact_between)
                        .chain()
                        .in_set(SoftBodySystems::Step),
                    (writeback, tear, super::diagnostics::measure, tick)
                        .chain()
                        .in_set(SoftBodySystems::Writeback),
                ),
            );
        super::diagnostics::register(app);
    }
}

/// The packed core simulation of one body (internal).
#[derive(Component, Default)]
pub struct BodySim {
    pub(crate) sim: Option<Simulation<ParticleState, ParticleModel>>,
    /// Particle entity of each packed index.
    pub(crate) particles: Vec<Entity>,
    /// Packed index of each particle entity.
    index: HashMap<Entity, u32>,
    /// Spring entities in the body's relationship order (the packed list may skip some).
    pub(crate) springs: Vec<Entity>,
    /// The spring entity of each packed spring.
    pub(crate) packed_springs: Vec<Entity>,
    /// The tet entity of each packed tet.
    pub(crate) packed_tets: Vec<Entity>,
    /// Torn this frame: its components changed, its model is rebuilt at the next step (until
    /// then its surface may name particles the model does not have yet).
    pub(crate) torn: bool,
    /// Tet entities in the body's relationship order.
    pub(crate) tets: Vec<Entity>,
    /// Each particle split off by tearing → the particle it was split from, for bodies with
    /// no `SoftBodySurface` to keep that record (self-collision needs it: the two sides of a
    /// crack are not one flat patch).
    pub(crate) torn_origin: HashMap<Entity, Entity>,
    /// Positions and velocities as last written to the components (to tell user edits apart).
    written: Vec<(Vec3, Vec3)>,
    /// Particles following a target: index, target, offset, target's last position.
    pub(crate) follow: Vec<(u32, Entity, Vec3, Vec3)>,
    /// Pinned-in-place particle indices (editing their position moves the pin).
    fixed_pins: Vec<u32>,
    /// Positions at the start of the last frame (bodies with self-collision: for contact
    /// with other bodies after the step).
    frame_start: Vec<crate::math::Vector>,
    problem: Option<String>,
    diverged: Option<Divergence>,
    report: bool,
    frame_dt: f64,
    /// Slept through the last fixed step: its state did not change.
    idle: bool,
    /// Counts the fixed steps that wrote a changed state (a drawn mesh made at one count
    /// needs no update until it moves on).
    version: u64,
}

impl BodySim {
    /// The core simulation, once built.
    pub fn simulation(&self) -> Option<&Simulation<ParticleState, ParticleModel>> {
        self.sim.as_ref()
    }

    /// Stopped by a divergence (kept at its last good state until rebuilt or reset).
    pub fn is_diverged(&self) -> bool {
        self.diverged.is_some()
    }

    /// The particle entity of each packed index.
    pub fn particle_entities(&self) -> &[Entity] {
        &self.particles
    }

    /// Length of the fixed frame the body was built for (s).
    #[cfg_attr(not(feature = "avian"), allow(dead_code))]
    pub(crate) fn frame_dt(&self) -> f64 {
        self.frame_dt
    }

    /// True between a tear and the rebuild that takes it in (the surface may then name
    /// particles the model does not have yet).
    pub fn awaiting_rebuild(&self) -> bool {
        self.torn
    }

    /// The packed index of a particle entity of this body.
    pub fn index_of(&self, particle: Entity) -> Option<usize> {
        self.index.get(&particle).map(|i| *i as usize)
    }

    /// How many fixed steps have written a changed state: what is drawn at one count needs no
    /// update while the count stays.
    pub fn version(&self) -> u64 {
        self.version
    }
}

/// A collider's pose at the previous fixed step (internal: its linear and angular velocity
/// come from the change) and its shape at its transform's scale.
#[derive(Component, Default)]
pub struct ColliderTrack {
    prev: Option<(Vec3, Quat)>,
    /// The shape scaled by this scale (absent: scale one, or a shape that cannot be scaled).
    scaled: Option<(Vec3, crate::core::collide::SharedShape)>,
    /// Its box over the coming frame, grown by its thickness (absent: unbounded, a half-space).
    frame_box: Option<(crate::math::Vector, crate::math::Vector)>,
    /// Its turn (axis × angle) from the last orientation to the current one.
    turn: Vec3,
}
