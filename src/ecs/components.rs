//! Components and messages of the ECS face. Components are the layout: a [`SoftBody`] root,
//! [`Particle`]s and [`Spring`]s that belong to it through Bevy relationships ([`ParticleOf`],
//! [`SpringOf`]), [`Pinned`] particles, [`ExternalForce`]s, [`SoftBodyWind`], and
//! [`SoftBodyCollider`]s anywhere in the world.

use crate::core::driver::{CflLimit, Divergence, StepPolicy};
pub use crate::core::fem::NeoHookean;
use crate::core::forces::SpringLaw;
use crate::core::integrate::IntegratorKind;
pub use crate::core::integrate::SolverChoice;
use crate::core::motion::Motion;
use crate::core::self_contact::SelfContactParams;
use bevy::prelude::*;
use bevy::reflect::{impl_reflect, impl_reflect_opaque};
use parry3d::shape::SharedShape;

impl_reflect_opaque!((in bevy_soft_body::core::integrate) IntegratorKind(
    Clone,
    Debug,
    Default,
    PartialEq,
    Hash,
    Serialize,
    Deserialize
));
// Internally tagged in serde (`{"type": "fixed", "h": …}` in scene files), which RON cannot
// read back: reflected field by field instead, so saved worlds round-trip.
impl_reflect!(
    #[reflect(Clone, Debug, Default, PartialEq)]
    #[type_path = "bevy_soft_body::core::driver"]
    enum StepPolicy {
        Fixed {
            h: f64,
        },
        Cfl {
            number: f64,
            max: f64,
            limit: CflLimit,
        },
    }
);
impl_reflect_opaque!((in bevy_soft_body::core::driver) CflLimit(
    Clone,
    Debug,
    Default,
    PartialEq,
    Serialize,
    Deserialize
));
impl_reflect_opaque!((in bevy_soft_body::core::forces) SpringLaw(
    Clone,
    Debug,
    Default,
    PartialEq,
    Hash,
    Serialize,
    Deserialize
));
impl_reflect_opaque!((in bevy_soft_body::core::fem) NeoHookean(
    Clone,
    Debug,
    Default,
    PartialEq,
    Serialize,
    Deserialize
));
pub use crate::core::auto::AutoConfig;
impl_reflect_opaque!((in bevy_soft_body::core::auto) AutoConfig(
    Clone,
    Debug,
    Default,
    PartialEq,
    Serialize,
    Deserialize
));
impl_reflect_opaque!((in bevy_soft_body::core::integrate) SolverChoice(
    Clone,
    Debug,
    Default,
    PartialEq,
    Hash,
    Serialize,
    Deserialize
));
impl_reflect!(
    #[reflect(Clone, Debug, PartialEq)]
    #[type_path = "bevy_soft_body::core::motion"]
    enum Motion {
        Fixed {
            position: [f64; 3],
        },
        Linear {
            start: [f64; 3],
            velocity: [f64; 3],
            t0: f64,
        },
        Circle {
            center: [f64; 3],
            radius: f64,
            omega: f64,
            phase: f64,
            a: [f64; 3],
            b: [f64; 3],
        },
        Oscillate {
            center: [f64; 3],
            amplitude: [f64; 3],
            omega: f64,
            phase: f64,
        },
    }
);

/// The root of a soft body: how it is advanced. Particles join it with [`ParticleOf`] and
/// springs with [`SpringOf`]. Editing this component (another integrator, step, drag...)
/// rebuilds the body's packed model on the next step and clears a reported divergence.
#[derive(Component, Reflect, Clone, Debug, PartialEq)]
#[reflect(Component, Default, Debug)]
#[require(SoftBodyStatus, crate::ecs::plugin::BodySim)]
pub struct SoftBody {
    /// The time integrator. Default: [`IntegratorKind::Auto`], which picks the cheapest
    /// method and substep count that are stable for this body at the frame's length (and
    /// meet [`AutoSettings`]' tolerance, when one is set), and says why in [`SoftBodyStatus`].
    pub integrator: IntegratorKind,
    /// How the substep `h` is chosen; the fixed frame is cut into substeps of one size, at most
    /// `h`, that land exactly on its end (`core::driver::equal_substep`). Ignored
    /// under [`IntegratorKind::Auto`], which chooses the substeps itself.
    pub step: StepPolicy,
    /// Viscous drag `−c v` on every free particle (N·s/m).
    pub drag: f32,
    /// Gravitational acceleration; `None`: `(0, −9.81, 0)`.
    pub gravity: Option<Vec3>,
    /// Stop stepping (the state is kept).
    pub paused: bool,
    /// Stop the body when its internal energy exceeds this multiple of its energy scale
    /// (`None`: only non-finite states stop it).
    pub energy_guard: Option<f32>,
    /// Implicit methods hold the corners of the body's triangles resting on
    /// colliders that need its triangles (rods, small balls, box edges) along the contact
    /// normals inside the solve, so a cloth on a rod about as wide as its cells hangs on it
    /// instead of wedging ([`ParticleModel::hold_faces`](crate::core::particles::ParticleModel::hold_faces)).
    /// Backward Euler and linearly implicit Euler also hold the particles resting on
    /// colliders, with Coulomb friction inside the solve, so that a body at rest on colliders
    /// is in static equilibrium.
    /// Default: on. Off, the triangles are left to the contact after the step alone, which
    /// costs less (the 64² cloth on a rod 1.0–1.6 times less) but may wedge the cloth.
    /// Explicit methods never hold them.
    pub hold_faces: bool,
}

impl Default for SoftBody {
    fn default() -> Self {
        Self {
            integrator: IntegratorKind::Auto,
            step: StepPolicy::Fixed { h: 1.0 / 240.0 },
            drag: 0.0,
            gravity: None,
            paused: false,
            energy_guard: Some(100.0),
            hold_faces: true,
        }
    }
}

/// What a body is doing, written by the plugin every fixed step.
#[derive(Component, Reflect, Clone, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct SoftBodyStatus {
    /// Running, paused, left out (invalid input) or stopped by a divergence.
    pub state: BodyState,
    /// Simulated time since the body's model was last (re)built (s).
    pub time: f32,
    /// Substeps in the last fixed step.
    pub substeps: u32,
    /// The method stepping the body: the [`SoftBody`]'s, or [`IntegratorKind::Auto`]'s
    /// choice.
    pub method: IntegratorKind,
    /// Under [`IntegratorKind::Auto`]: what it chose and why (empty otherwise).
    pub auto_reason: String,
    /// Wall time of the last fixed step of this body (ms).
    pub step_ms: f32,
    /// Linear-solver (conjugate-gradient) iterations in the last fixed step.
    pub linear_iterations: u32,
    /// Newton iterations in the last fixed step (backward Euler).
    pub newton_iterations: u32,
    /// Particles and springs in the packed model.
    pub particles: u32,
    /// Springs in the packed model.
    pub springs: u32,
    /// Tets in the packed model.
    pub tets: u32,
    /// Times the packed model was rebuilt (topology or parameter changes).
    pub rebuilds: u32,
    /// Self-collision passes in the last fixed step (zero without [`SelfCollision`]), with
    /// those of the contact between bodies it took part in.
    pub contact_passes: u32,
    /// Broad-phase searches of the surface's candidate pairs in the last fixed step, with
    /// those of the contact between bodies it took part in (a search runs when a vertex has
    /// left the tube around its motion at the last one, or that search's horizon passed).
    pub contact_searches: u32,
    /// Candidate pairs the body's self-collision holds after the last fixed step (what every
    /// pass looks at).
    pub contact_candidates: u32,
    /// Wall time of self-collision's broad phase in the last fixed step (ms): the searches and
    /// the checks that keep their candidates. Contact between bodies adds its time shared
    /// evenly among the bodies in it, so the sum over bodies is the wall time.
    pub contact_broad_ms: f32,
    /// Wall time of self-collision's narrow phase and responses in the last fixed step (ms),
    /// shared as [`SoftBodyStatus::contact_broad_ms`] is.
    pub contact_narrow_ms: f32,
    /// The particle that last made a self-collision pass due in the last fixed step, by
    /// straying past what its nearest pair allows or by leaving the search's tube (none when
    /// every pass ran at the frame's end or at the search's horizon). The same particle
    /// step after step is typically a crease that its springs press against the thickness:
    /// the whole surface's passes then run at its rate.
    pub contact_due_particle: Option<u32>,
    /// In the last fixed step, self-collision met a configuration its fail-safe could not
    /// separate: the surface's free particles were held where that pass began (free of
    /// intersections), and a warning names the body.
    pub contact_failed: bool,
}

/// The state a [`SoftBodyStatus`] reports.
#[derive(Reflect, Clone, Debug, Default, PartialEq)]
pub enum BodyState {
    /// Not built yet.
    #[default]
    Pending,
    /// Stepping.
    Running,
    /// [`SoftBody::paused`] is set.
    Paused,
    /// At rest: its fixed steps cost nothing until something wakes it (see
    /// [`SoftBodySleep`]).
    Sleeping,
    /// Left out of stepping because its input is invalid (the message names the culprit).
    Invalid(String),
    /// Stopped by a divergence; the last good state is kept (the message says what happened
    /// and what to try).
    Diverged(String),
}

/// A point mass of a soft body, in world space. Editing `position` or `velocity` teleports
/// the particle on the next step.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct Particle {
    /// Position (m).
    pub position: Vec3,
    /// Velocity (m/s).
    pub velocity: Vec3,
    /// Mass (kg); must be positive unless the particle is [`Pinned`].
    pub mass: f32,
}

impl Default for Particle {
    fn default() -> Self {
        Self {
            position: Vec3::ZERO,
            velocity: Vec3::ZERO,
            mass: 1.0,
        }
    }
}

impl Particle {
    /// A particle at rest.
    pub fn at(position: Vec3, mass: f32) -> Self {
        Self {
            position,
            velocity: Vec3::ZERO,
            mass,
        }
    }
}

/// The body a [`Particle`] belongs to.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq, Eq)]
#[reflect(Component, Debug)]
#[relationship(relationship_target = BodyParticles)]
pub struct ParticleOf(pub Entity);

/// The particles of a body, in the order of its packed arrays (maintained by Bevy; despawning
/// the body despawns them).
#[derive(Component, Reflect, Clone, Debug, Default, PartialEq, Eq)]
#[reflect(Component, Debug)]
#[relationship_target(relationship = ParticleOf, linked_spawn)]
pub struct BodyParticles(Vec<Entity>);

impl BodyParticles {
    /// The particle entities.
    pub fn entities(&self) -> &[Entity] {
        &self.0
    }
}

/// A spring (and optional damper) between two particle entities of the same body.
/// Despawning it cuts the spring; a spring whose particle is gone is left out with a warning.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Debug)]
pub struct Spring {
    /// First particle.
    #[entities]
    pub a: Entity,
    /// Second particle.
    #[entities]
    pub b: Entity,
    /// Rest length (m).
    pub rest_length: f32,
    /// Stiffness: N/m for [`SpringLaw::Hooke`], N for [`SpringLaw::Strain`].
    pub stiffness: f32,
    /// Damping along the spring (N·s/m).
    pub damping: f32,
    /// How stiffness is given.
    pub law: SpringLaw,
}

/// A linear tetrahedron of neo-Hookean material over four particle entities of the same body
/// (a volumetric finite element). Its rest shape is kept here, so the particles may start
/// deformed; it must have positive volume (`dot(b − a, (c − a) × (d − a)) > 0`), or the body
/// reports the tet and does not run. Its material is its own, else the body's
/// [`ElasticMaterial`].
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Debug)]
pub struct Tet {
    /// The four particles.
    #[entities]
    pub particles: [Entity; 4],
    /// Their rest positions (m).
    pub rest: [Vec3; 4],
    /// This tet's material (`None`: the body's).
    pub material: Option<NeoHookean>,
}

/// The body a [`Tet`] belongs to.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq, Eq)]
#[reflect(Component, Debug)]
#[relationship(relationship_target = BodyTets)]
pub struct TetOf(pub Entity);

/// The tets of a body (maintained by Bevy; despawning the body despawns them).
#[derive(Component, Reflect, Clone, Debug, Default, PartialEq, Eq)]
#[reflect(Component, Debug)]
#[relationship_target(relationship = TetOf, linked_spawn)]
pub struct BodyTets(Vec<Entity>);

impl BodyTets {
    /// The tet entities.
    pub fn entities(&self) -> &[Entity] {
        &self.0
    }
}

/// The material of a body's tets (those without their own): Young's modulus, Poisson ratio
/// and density. Particle masses are set from the density when a tet mesh is spawned; editing
/// `young` or `poisson` here takes effect on the next step.
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct ElasticMaterial(pub NeoHookean);

/// Which linear solver a body's implicit methods use (default: Cholesky for bodies with tets,
/// PCG otherwise).
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct LinearSolverChoice(pub SolverChoice);

/// What [`IntegratorKind::Auto`] aims for on this body (default: the cheapest stable method,
/// at most 64 substeps per frame; see [`AutoConfig`]). Editing it makes Auto decide again.
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct AutoSettings(pub AutoConfig);

/// The body a [`Spring`] belongs to.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq, Eq)]
#[reflect(Component, Debug)]
#[relationship(relationship_target = BodySprings)]
pub struct SpringOf(pub Entity);

/// The springs of a body (maintained by Bevy; despawning the body despawns them).
#[derive(Component, Reflect, Clone, Debug, Default, PartialEq, Eq)]
#[reflect(Component, Debug)]
#[relationship_target(relationship = SpringOf, linked_spawn)]
pub struct BodySprings(Vec<Entity>);

impl BodySprings {
    /// The spring entities.
    pub fn entities(&self) -> &[Entity] {
        &self.0
    }
}

/// Holds a particle: in place (no target), or at `target`'s `GlobalTransform` applied to
/// `offset`, moving with the target's velocity (prescribed motion: the particle follows the
/// target's path, linearly between fixed steps, landing on it at every step's end).
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct Pinned {
    /// The entity to follow (`None`: fixed where the particle is when pinned).
    #[entities]
    pub target: Option<Entity>,
    /// Offset in the target's local frame.
    pub offset: Vec3,
}

impl Pinned {
    /// Fixed in place.
    pub fn here() -> Self {
        Self::default()
    }

    /// Following `target` at `offset` in its frame.
    pub fn to(target: Entity, offset: Vec3) -> Self {
        Self {
            target: Some(target),
            offset,
        }
    }
}

/// A constant force on one particle (N).
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct ExternalForce(pub Vec3);

/// Contact of a body's surface with itself (on the body root): a cloth folding onto itself,
/// a jelly squeezed against itself, never pass through. The surface is the body's
/// [`SoftBodySurface`](crate::render::SoftBodySurface) triangles, or the boundary of its tets
/// when it has none. Proximity impulses with Coulomb friction, continuous collision detection
/// and rigid impact zones (Bridson, Fedkiw and Anderson 2002; see
/// [`crate::core::self_contact`]); every state a fixed step delivers is free of
/// self-intersections. Bodies without it pay nothing.
///
/// Two bodies that both have it also collide with each other: after every body has
/// stepped the frame, bodies whose swept boxes overlap go through one pass over the frame
/// as a single surface (their smallest thickness, their mean friction; see
/// [`crate::core::body_contact`]), so the frame also ends free of intersections between
/// them. (A body without it is not seen by the others: one component is the switch for
/// soft–soft contact, at no cost to bodies that do not ask for it.)
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct SelfCollision {
    /// Thickness (m): parts of the surface closer than this repel. Positive and less than
    /// half the surface's shortest edge.
    pub thickness: f32,
    /// Coulomb friction coefficient between touching parts.
    pub friction: f32,
}

impl Default for SelfCollision {
    fn default() -> Self {
        let p = SelfContactParams::default();
        Self {
            thickness: p.thickness as f32,
            friction: p.friction as f32,
        }
    }
}

impl SelfCollision {
    /// The core's settings.
    pub fn params(&self) -> SelfContactParams {
        SelfContactParams {
            thickness: self.thickness as f64,
            friction: self.friction as f64,
        }
    }
}

impl From<SelfContactParams> for SelfCollision {
    fn from(p: SelfContactParams) -> Self {
        Self {
            thickness: p.thickness as f32,
            friction: p.friction as f32,
        }
    }
}

/// Wind on a body: air drag `c (w(t) − v)` toward a constant velocity plus a seeded breeze of
/// three sines. On the body root; the [`GlobalWind`] resource applies where a body has none.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct SoftBodyWind {
    /// Mean air velocity (m/s).
    pub velocity: Vec3,
    /// Breeze amplitude (m/s).
    pub gust: f32,
    /// Breeze base frequency (Hz).
    pub frequency: f32,
    /// Air-drag coefficient per particle (N·s/m).
    pub coefficient: f32,
    /// Seed of the breeze.
    pub seed: u64,
    /// On or off (the W key of the examples toggles it).
    pub enabled: bool,
}

impl Default for SoftBodyWind {
    fn default() -> Self {
        Self::from(crate::core::forces::Wind::default())
    }
}

impl From<crate::core::forces::Wind> for SoftBodyWind {
    fn from(w: crate::core::forces::Wind) -> Self {
        Self {
            velocity: Vec3::from_array(w.velocity.map(|c| c as f32)),
            gust: w.gust as f32,
            frequency: w.frequency as f32,
            coefficient: w.coefficient as f32,
            seed: w.seed,
            enabled: w.enabled,
        }
    }
}

impl From<SoftBodyWind> for crate::core::forces::Wind {
    fn from(w: SoftBodyWind) -> Self {
        Self {
            velocity: w.velocity.to_array().map(|c| c as f64),
            gust: w.gust as f64,
            frequency: w.frequency as f64,
            coefficient: w.coefficient as f64,
            seed: w.seed,
            enabled: w.enabled,
        }
    }
}

/// When bodies at rest sleep (a resource): once every free particle of a body has stayed
/// slower than `speed` for `time` under steady forces, its fixed steps, write-back and mesh
/// updates cost nothing ([`BodyState::Sleeping`]) until something wakes it:
///
/// - a collider near it that moves or turns (a [`SoftBodyCollider`] whose transform changed,
///   an avian body in motion) — in the same fixed step;
/// - a pin whose target moves, or a particle following a path;
/// - an edit: a particle's position or velocity set, a spring, tet, pin, force, wind,
///   material or setting changed, particles or springs added or removed (a mouse grab);
/// - a change of its force fields, or a field that changes with time
///   ([`ForceField::steady_from`](crate::core::forces::ForceField::steady_from)), and gusting
///   wind (a body in a gusting breeze never sleeps);
/// - contact with another body with [`SelfCollision`] that is awake;
/// - a [`WakeSoftBody`] message.
///
/// A woken body must be still for `time` again before it sleeps, so nothing flickers; while
/// it sleeps its state does not change, so its own jitter cannot wake it. A body with
/// [`SoftBodySleepingDisabled`] never sleeps (as avian's `SleepingDisabled`). The core's
/// rule is [`SleepParams`](crate::core::driver::SleepParams).
#[derive(Resource, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Resource, Default, Debug)]
pub struct SoftBodySleep {
    /// Off: no body sleeps.
    pub enabled: bool,
    /// Speed (m/s) every free particle must stay below: how far it goes in a frame, over the
    /// frame's length.
    pub speed: f32,
    /// For this long (s).
    pub time: f32,
}

impl Default for SoftBodySleep {
    fn default() -> Self {
        let p = crate::core::driver::SleepParams::default();
        Self {
            enabled: true,
            speed: p.speed as f32,
            time: p.time as f32,
        }
    }
}

impl SoftBodySleep {
    /// The core's settings (`None` when off or when a number is bad).
    pub fn params(&self) -> Option<crate::core::driver::SleepParams> {
        let p = crate::core::driver::SleepParams {
            speed: self.speed as f64,
            time: self.time as f64,
        };
        (self.enabled && p.validate().is_ok()).then_some(p)
    }
}

/// On a body root: the body never sleeps.
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct SoftBodySleepingDisabled;

/// Wakes a sleeping body (a message): it steps from the next fixed step on.
#[derive(Message, Clone, Copy, Debug, PartialEq)]
pub struct WakeSoftBody(pub Entity);

/// Wind for every body without its own [`SoftBodyWind`] (`None`: no wind).
#[derive(Resource, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Resource, Default, Debug)]
pub struct GlobalWind(pub Option<SoftBodyWind>);

/// Force fields on one body (on its root): laws of the game's own, evaluated at every force
/// evaluation ([`ForceField`](crate::core::forces::ForceField); built-ins
/// [`Buoyancy`](crate::core::forces::Buoyancy) and
/// [`RadialBlast`](crate::core::forces::RadialBlast)). Editing the list takes effect on the
/// next fixed step.
#[derive(Component, Reflect, Clone, Debug, Default)]
#[reflect(Component, Default, Debug)]
pub struct SoftBodyForceFields(#[reflect(ignore)] pub Vec<crate::core::forces::SharedField>);

/// Force fields on every body, after each body's own [`SoftBodyForceFields`].
#[derive(Resource, Reflect, Clone, Debug, Default)]
#[reflect(Resource, Default, Debug)]
pub struct GlobalForceFields(#[reflect(ignore)] pub Vec<crate::core::forces::SharedField>);

/// A parry3d shape (reflected as an opaque value).
#[derive(Clone, Deref)]
pub struct ColliderShape(pub SharedShape);

impl Default for ColliderShape {
    fn default() -> Self {
        Self(SharedShape::ball(0.5))
    }
}

impl std::fmt::Debug for ColliderShape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ColliderShape({:?})", self.0.shape_type())
    }
}

/// Something particles collide with: any parry3d shape at the entity's `GlobalTransform`,
/// static or moving (its velocity is taken from its transform change between fixed steps).
/// Every substep, a particle closer than `thickness` is projected to the surface, its normal
/// velocity relative to the collider reflected with `restitution` and its tangential relative
/// velocity reduced by Coulomb friction.
#[derive(Component, Reflect, Clone, Debug)]
#[reflect(Component, Default, Debug)]
#[require(Transform, crate::ecs::plugin::ColliderTrack)]
pub struct SoftBodyCollider {
    /// The shape (ball, half-space, cuboid, capsule, trimesh...).
    #[reflect(ignore)]
    pub shape: ColliderShape,
    /// Coulomb friction coefficient.
    pub friction: f32,
    /// Restitution of the normal relative velocity.
    pub restitution: f32,
    /// Contact distance (m): particles closer than this are pushed out to it.
    pub thickness: f32,
    /// Normal speeds below this do not bounce (m/s).
    pub bounce_threshold: f32,
}

impl Default for SoftBodyCollider {
    fn default() -> Self {
        Self {
            shape: ColliderShape::default(),
            friction: 0.3,
            restitution: 0.0,
            thickness: 0.01,
            bounce_threshold: 0.05,
        }
    }
}

impl SoftBodyCollider {
    /// A collider of `shape` with the default material.
    pub fn new(shape: SharedShape) -> Self {
        Self {
            shape: ColliderShape(shape),
            ..Default::default()
        }
    }

    /// A ball of `radius`.
    pub fn ball(radius: f32) -> Self {
        Self::new(SharedShape::ball(radius))
    }

    /// A ground plane through the entity's origin with normal `+Y` (rotate the entity to tilt
    /// it).
    pub fn ground() -> Self {
        Self::new(SharedShape::halfspace(parry3d::math::Vector::Y))
    }

    /// The same collider with another material.
    pub fn with_material(mut self, friction: f32, restitution: f32, thickness: f32) -> Self {
        self.friction = friction;
        self.restitution = restitution;
        self.thickness = thickness;
        self
    }
}

/// Moves an entity's `Transform` along a closed-form path each fixed step (scene colliders and
/// the prescribed endpoints of scene files).
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Debug)]
pub struct ScriptedMotion(pub Motion);

/// The plugin's own clock: pause, single step and the time [`ScriptedMotion`] follows.
#[derive(Resource, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Resource, Default, Debug)]
pub struct SoftBodyClock {
    /// Simulated time since start or the last reset (s).
    pub elapsed: f64,
    /// Stop every body and scripted motion.
    pub paused: bool,
    /// While paused: advance one fixed step, then stay paused.
    pub step_once: bool,
}

impl SoftBodyClock {
    /// True when this fixed step advances the world.
    pub fn running(&self) -> bool {
        !self.paused || self.step_once
    }
}

/// The particles' states when the body was spawned, for [`ResetSoftBodies`].
#[derive(Component, Reflect, Clone, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug)]
#[component(map_entities)]
pub struct SoftBodyInitial {
    /// Particle entity, position and velocity at spawn.
    pub particles: Vec<(Entity, Vec3, Vec3)>,
}

impl bevy::ecs::entity::MapEntities for SoftBodyInitial {
    fn map_entities<M: bevy::ecs::entity::EntityMapper>(&mut self, mapper: &mut M) {
        for (e, _, _) in &mut self.particles {
            *e = mapper.get_mapped(*e);
        }
    }
}

/// Springs of the body break when stretched past `max_strain` (on the body root), and its
/// [`SoftBodySurface`](crate::render::SoftBodySurface) tears along them: the particle at a
/// broken surface edge is split square to the edge, and the drawn mesh follows. Tets break
/// when their largest principal stretch passes `1 + max_strain`: a corner is split by the
/// plane square to the stretch, and a surface that is the tets' boundary is recomputed,
/// showing the crack's faces (see [`crate::core::tear`]). Checked at every fixed step's end;
/// each tear sends a [`SoftBodyTorn`] and rebuilds the body's model the next step. Scene key
/// `"tearing": { "max_strain": … }`.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct Tearable {
    /// Strain at which a spring breaks (`0.5`: at 1.5 times its rest length). Positive.
    pub max_strain: f32,
}

impl Default for Tearable {
    fn default() -> Self {
        Self {
            max_strain: crate::core::tear::TearParams::default().max_strain as f32,
        }
    }
}

impl Tearable {
    /// The core's settings.
    pub fn params(&self) -> crate::core::tear::TearParams {
        crate::core::tear::TearParams {
            max_strain: self.max_strain as f64,
        }
    }
}

impl From<crate::core::tear::TearParams> for Tearable {
    fn from(p: crate::core::tear::TearParams) -> Self {
        Self {
            max_strain: p.max_strain as f32,
        }
    }
}

/// Sent when a [`Tearable`] body tears (a message, and an entity event triggered on the body).
#[derive(Message, EntityEvent, Clone, Debug)]
pub struct SoftBodyTorn {
    /// The body's root entity.
    #[event_target]
    pub body: Entity,
    /// The springs that broke and were removed (already despawned): those past the limit off
    /// the surface, or on an edge that could not be split. (A spring past the limit along a
    /// surface edge stays, moved to the split-off particle, and relaxes.)
    pub springs: Vec<Entity>,
    /// The particles split: (the original, its new copy).
    pub split: Vec<(Entity, Entity)>,
    /// The tets strained past the limit: each split off at one of its corners (it now holds
    /// the copy), or, when none of its corners could be split, removed (despawned).
    pub tets: Vec<Entity>,
}

/// Send to put every body with a [`SoftBodyInitial`] back to it and the clock back to zero.
#[derive(Message, Clone, Copy, Debug, Default)]
pub struct ResetSoftBodies;

/// Sent when a body diverges: it stops, keeps its last good state, and the others go on.
/// Both a message (read with `MessageReader`) and an entity event triggered on the body
/// (caught by an observer on it: `commands.entity(body).observe(|d: On<SoftBodyDiverged>| …)`).
#[derive(Message, EntityEvent, Clone, Debug)]
pub struct SoftBodyDiverged {
    /// The body's root entity.
    #[event_target]
    pub body: Entity,
    /// What happened (frame, time, method, cause).
    pub divergence: Divergence,
    /// The message with a suggested fix.
    pub message: String,
}

/// Sent when a body is left out of stepping because of invalid input. Both a message and an
/// entity event triggered on the body, as [`SoftBodyDiverged`].
#[derive(Message, EntityEvent, Clone, Debug)]
pub struct SoftBodyInvalid {
    /// The body's root entity.
    #[event_target]
    pub body: Entity,
    /// What is wrong, naming the entity.
    pub message: String,
}
