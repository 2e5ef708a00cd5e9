//! [`SoftBodyPlugin`]: gathers each body's components into the core's packed model (only when
//! something changed), advances every body in parallel with the core driver — substeps that
//! land exactly on the fixed frame's end, collisions every substep, the divergence guard — and
//! writes the state back to the components.

use super::components::*;
use crate::core::collide::{Collider, ContactMaterial};
use crate::core::driver::{Divergence, DriverConfig, Simulation, StepPolicy};
use crate::core::motion::Motion;
use crate::core::ode::{OdeState, ParticleState};
use crate::core::particles::{ModelError, ParticleModel};
use crate::math::{Scalar, from_f32, to_f32};
use bevy::ecs::schedule::{InternedScheduleLabel, ScheduleLabel};
use bevy::prelude::*;
use std::collections::HashMap;

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

/// The thread pool large bodies' force kernels share (see
/// [`SoftBodyPlugin::with_kernel_threads`]); `None`: one thread per body.
#[derive(Resource, Clone, Default)]
pub struct SoftBodyKernelPool {
    #[cfg(feature = "parallel")]
    pool: Option<std::sync::Arc<rayon::ThreadPool>>,
}

impl SoftBodyKernelPool {
    /// A pool of `threads` threads (`0`: every core; `1`: none).
    pub fn new(threads: usize) -> Self {
        #[cfg(feature = "parallel")]
        {
            let threads = if threads == 0 {
                std::thread::available_parallelism().map_or(1, |n| n.get())
            } else {
                threads
            };
            let pool = (threads > 1)
                .then(|| {
                    rayon::ThreadPoolBuilder::new()
                        .num_threads(threads)
                        .thread_name(|i| format!("soft-body kernels {i}"))
                        .build()
                        .ok()
                })
                .flatten()
                .map(std::sync::Arc::new);
            Self { pool }
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
            self.pool.as_ref().map_or(1, |p| p.current_num_threads())
        }
        #[cfg(not(feature = "parallel"))]
        {
            1
        }
    }

    /// Advances `sim` one frame, on the pool when the body is large enough to be cut into
    /// chunks.
    fn advance(
        &self,
        sim: &mut Simulation<ParticleState, ParticleModel>,
    ) -> Result<crate::core::driver::FrameReport, Divergence> {
        #[cfg(feature = "parallel")]
        if let Some(pool) = &self.pool
            && sim.system.is_chunked()
        {
            return pool.install(|| sim.advance_frame());
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
    /// substeps.
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
            .register_type::<SpringOf>()
            .register_type::<BodySprings>()
            .register_type::<Pinned>()
            .register_type::<ExternalForce>()
            .register_type::<SoftBodyWind>()
            .register_type::<GlobalWind>()
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
                    (reset, scripted_motion, prepare)
                        .chain()
                        .in_set(SoftBodySystems::Prepare),
                    step.in_set(SoftBodySystems::Step),
                    (writeback, super::diagnostics::measure, tick)
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
    /// Tet entities in the body's relationship order.
    pub(crate) tets: Vec<Entity>,
    /// Positions and velocities as last written to the components (to tell user edits apart).
    written: Vec<(Vec3, Vec3)>,
    /// Particles following a target: index, target, offset, target's last position.
    follow: Vec<(u32, Entity, Vec3, Vec3)>,
    /// Pinned-in-place particle indices (editing their position moves the pin).
    fixed_pins: Vec<u32>,
    problem: Option<String>,
    diverged: Option<Divergence>,
    report: bool,
    frame_dt: f64,
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

    /// The packed index of a particle entity of this body.
    pub fn index_of(&self, particle: Entity) -> Option<usize> {
        self.index.get(&particle).map(|i| *i as usize)
    }
}

/// A collider's pose at the previous fixed step (internal: its velocity comes from the
/// change).
#[derive(Component, Default)]
pub struct ColliderTrack {
    prev: Option<(Vec3, Quat)>,
}

/// Puts bodies back to their spawn state on [`ResetSoftBodies`].
fn reset(
    mut msgs: MessageReader<ResetSoftBodies>,
    mut clock: ResMut<SoftBodyClock>,
    mut bodies: Query<(&mut SoftBody, &SoftBodyInitial)>,
    mut particles: Query<&mut Particle>,
) {
    if msgs.read().count() == 0 {
        return;
    }
    clock.elapsed = 0.0;
    for (mut body, init) in &mut bodies {
        body.set_changed(); // rebuild: time, integrator history and divergence start afresh
        for (e, x, v) in &init.particles {
            if let Ok(mut p) = particles.get_mut(*e) {
                p.position = *x;
                p.velocity = *v;
            }
        }
    }
}

/// Advances the plugin's clock after a step.
fn tick(mut clock: ResMut<SoftBodyClock>, fixed: Res<Time<Fixed>>) {
    if clock.running() {
        clock.elapsed += fixed.timestep().as_secs_f64();
        clock.step_once = false;
    }
}

type ScriptedItem<'a> = (
    &'a ScriptedMotion,
    &'a mut Transform,
    &'a mut GlobalTransform,
    Option<&'a mut ColliderTrack>,
);

fn scripted_motion(
    clock: Res<SoftBodyClock>,
    fixed: Res<Time<Fixed>>,
    mut q: Query<ScriptedItem, Without<ChildOf>>,
) {
    if !clock.running() {
        return;
    }
    // Poses at the end of the step about to be taken.
    let t = (clock.elapsed + fixed.timestep().as_secs_f64()) as Scalar;
    for (m, mut tf, mut gt, track) in &mut q {
        // A new collider's first frame starts where it was spawned.
        if let Some(mut track) = track
            && track.prev.is_none()
        {
            track.prev = Some((tf.translation, tf.rotation));
        }
        tf.translation = to_f32(m.0.position(t));
        // Top-level entity: its global transform is its transform; set it now so this fixed
        // step sees the new pose (propagation runs later, in PostUpdate).
        *gt = GlobalTransform::from(*tf);
    }
}

fn v3(v: Vec3) -> [f64; 3] {
    v.to_array().map(|c| c as f64)
}

/// A linear path from `from` (at `t0`) to `to` (at `t0 + dt`).
fn linear(from: Vec3, to: Vec3, t0: Scalar, dt: f64) -> Motion {
    Motion::Linear {
        start: v3(from),
        velocity: v3((to - from) / dt as f32),
        t0: t0 as f64,
    }
}

type ParticleItem<'a> = (
    Ref<'a, Particle>,
    Option<Ref<'a, Pinned>>,
    Option<Ref<'a, ExternalForce>>,
);

/// A body's finite elements, for a rebuild.
struct FemInput<'a, 'w, 's> {
    list: &'a [Entity],
    tets: &'a Query<'w, 's, Ref<'static, Tet>>,
    material: Option<NeoHookean>,
    solver: SolverChoice,
}

/// Tets, tets edited this frame, tets and materials removed.
type TetParams<'w, 's> = (
    Query<'w, 's, Ref<'static, Tet>>,
    Query<'w, 's, &'static TetOf, Changed<Tet>>,
    RemovedComponents<'w, 's, Tet>,
    RemovedComponents<'w, 's, ElasticMaterial>,
);

/// What a rebuild produced.
struct Built {
    sim: Simulation<ParticleState, ParticleModel>,
    particles: Vec<Entity>,
    index: HashMap<Entity, u32>,
    follow: Vec<(u32, Entity, Vec3, Vec3)>,
    fixed_pins: Vec<u32>,
}

#[allow(clippy::too_many_arguments)]
fn build_body(
    body_e: Entity,
    body: &SoftBody,
    wind: Option<SoftBodyWind>,
    list: &[Entity],
    spring_list: &[Entity],
    particles: &Query<ParticleItem>,
    springs: &Query<Ref<Spring>>,
    targets: &Query<&GlobalTransform>,
    frame_dt: f64,
    fem: FemInput,
) -> Result<Built, String> {
    let mut ents = Vec::with_capacity(list.len());
    let mut index = HashMap::with_capacity(list.len());
    for &e in list {
        if particles.contains(e) {
            index.insert(e, ents.len() as u32);
            ents.push(e);
        }
    }
    if ents.is_empty() {
        return Err(format!("soft body {body_e} has no particles"));
    }
    let mut state = ParticleState::zeros(ents.len());
    let mut masses = Vec::with_capacity(ents.len());
    for (i, &e) in ents.iter().enumerate() {
        let (p, _, _) = particles.get(e).expect("checked above");
        if !p.position.is_finite() || !p.velocity.is_finite() {
            return Err(format!(
                "particle {e}: position {} or velocity {} is not finite",
                p.position, p.velocity
            ));
        }
        state.x[i] = from_f32(p.position);
        state.v[i] = from_f32(p.velocity);
        masses.push(p.mass as Scalar);
    }
    let mut model = ParticleModel::new(masses);
    let (mut follow, mut fixed_pins) = (vec![], vec![]);
    for (i, &e) in ents.iter().enumerate() {
        let (p, pin, force) = particles.get(e).expect("checked above");
        if let Some(pin) = pin {
            match pin.target {
                None => {
                    model.pin(i, state.x[i]);
                    fixed_pins.push(i as u32);
                }
                Some(t) => match targets.get(t) {
                    Ok(gt) => {
                        let at = gt.transform_point(pin.offset);
                        model.prescribe(i, Motion::Fixed { position: v3(at) });
                        state.x[i] = from_f32(at);
                        follow.push((i as u32, t, pin.offset, at));
                    }
                    Err(_) => {
                        warn!(
                            "particle {e}: pin target {t} has no GlobalTransform; pinned in place"
                        );
                        model.pin(i, from_f32(p.position));
                        fixed_pins.push(i as u32);
                    }
                },
            }
        }
        if let Some(f) = force {
            model.set_external_force(i, from_f32(f.0));
        }
    }
    // The entity behind each packed spring, to name it in errors.
    let mut packed_springs = Vec::with_capacity(spring_list.len());
    for &se in spring_list {
        let Ok(s) = springs.get(se) else {
            continue;
        };
        match (index.get(&s.a), index.get(&s.b)) {
            (Some(&a), Some(&b)) if a == b => warn!(
                "soft body {body_e}: spring {se} joins particle {} to itself; the spring is left out",
                s.a
            ),
            (Some(&a), Some(&b)) => {
                model.springs.push(
                    a as usize,
                    b as usize,
                    s.rest_length as Scalar,
                    s.stiffness as Scalar,
                    s.damping as Scalar,
                    s.law,
                );
                packed_springs.push(se);
            }
            _ => warn!(
                "soft body {body_e}: spring {se} joins {} and {}, which are not both particles of this body; the spring is left out",
                s.a, s.b
            ),
        }
    }
    for &te in fem.list {
        let Ok(t) = fem.tets.get(te) else {
            continue;
        };
        let idx = t.particles.map(|p| index.get(&p).copied());
        let Some(v) = (idx[0].zip(idx[1]).zip(idx[2]).zip(idx[3]))
            .map(|(((a, b), c), d)| [a as usize, b as usize, c as usize, d as usize])
        else {
            warn!(
                "soft body {body_e}: tet {te} uses an entity that is not a particle of this body; the tet is left out"
            );
            continue;
        };
        let material = match t.material.or(fem.material) {
            Some(m) => m,
            None => {
                return Err(format!(
                    "tet {te}: no material (give the tet one, or the body an ElasticMaterial)"
                ));
            }
        };
        let rest = t
            .rest
            .map(|p| glam::DVec3::new(p.x as f64, p.y as f64, p.z as f64));
        if let Err(e) = model.tets.push(v, rest, &material) {
            return Err(format!("tet {te}: {e}"));
        }
    }
    model.gravity = from_f32(body.gravity.unwrap_or(Vec3::new(0.0, -9.81, 0.0)));
    model.drag = body.drag as Scalar;
    model.set_wind(wind.map(Into::into));
    if let Err(e) = model.validate() {
        // Name the entity behind the packed index.
        let spring_entity = |k: usize| packed_springs.get(k).copied();
        return Err(match e {
            ModelError::BadMass { particle, mass } => format!(
                "particle {}: mass {mass} must be positive and finite unless the particle is pinned",
                ents[particle]
            ),
            ModelError::BadSpring { spring, reason } => match spring_entity(spring) {
                Some(se) => format!("spring {se}: {reason}"),
                None => format!("soft body {body_e}: spring {spring}: {reason}"),
            },
            other => format!("soft body {body_e}: {other}"),
        });
    }
    match body.step {
        StepPolicy::Fixed { h } if !(h.is_finite() && h > 0.0) => {
            return Err(format!(
                "soft body {body_e}: step h = {h} must be a positive number"
            ));
        }
        StepPolicy::Cfl { number, max, .. }
            if !(number.is_finite() && number > 0.0 && max.is_finite() && max > 0.0) =>
        {
            return Err(format!(
                "soft body {body_e}: CFL number {number} and cap {max} must be positive numbers"
            ));
        }
        _ => {}
    }
    if let Some(g) = body.energy_guard
        && !(g.is_finite() && g > 0.0)
    {
        return Err(format!(
            "soft body {body_e}: energy guard {g} must be a positive number"
        ));
    }
    let config = DriverConfig {
        integrator: body.integrator,
        policy: body.step,
        frame_dt,
        energy_guard: body.energy_guard.map(|g| g as f64),
        solver: fem.solver,
        ..Default::default()
    };
    Ok(Built {
        sim: Simulation::new(model, state, config),
        particles: ents,
        index,
        follow,
        fixed_pins,
    })
}

/// Moves the particles that follow a target along the target's path over the coming frame.
fn update_follow(bs: &mut BodySim, targets: &Query<&GlobalTransform>) {
    let dt = bs.frame_dt;
    let Some(sim) = bs.sim.as_mut() else { return };
    let t0 = sim.time;
    for (i, target, offset, last) in &mut bs.follow {
        let to = match targets.get(*target) {
            Ok(gt) => gt.transform_point(*offset),
            Err(_) => *last, // target gone: stay where it was
        };
        sim.system.prescribe(*i as usize, linear(*last, to, t0, dt));
        *last = to;
    }
}

#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn prepare(
    fixed: Res<Time<Fixed>>,
    global_wind: Res<GlobalWind>,
    mut bodies: Query<(
        Entity,
        Ref<SoftBody>,
        &mut BodySim,
        &mut SoftBodyStatus,
        Option<&BodyParticles>,
        Option<&BodySprings>,
        Option<Ref<SoftBodyWind>>,
        (
            Option<&BodyTets>,
            Option<Ref<ElasticMaterial>>,
            Option<Ref<LinearSolverChoice>>,
        ),
    )>,
    (tets, changed_tets, mut removed_tets, mut removed_materials): TetParams,
    particles: Query<ParticleItem>,
    springs: Query<Ref<Spring>>,
    changed_springs: Query<&SpringOf, Changed<Spring>>,
    changed_setup: Query<&ParticleOf, Or<(Changed<Pinned>, Changed<ExternalForce>)>>,
    targets: Query<&GlobalTransform>,
    colliders: Query<(&SoftBodyCollider, &GlobalTransform, &ColliderTrack)>,
    mut removed_particles: RemovedComponents<Particle>,
    mut removed_springs: RemovedComponents<Spring>,
    mut removed_pins: RemovedComponents<Pinned>,
    mut removed_forces: RemovedComponents<ExternalForce>,
    mut removed_winds: RemovedComponents<SoftBodyWind>,
    (mut invalid, mut commands): (MessageWriter<SoftBodyInvalid>, Commands),
) {
    let frame_dt = fixed.timestep().as_secs_f64();
    // Removals cannot be traced to their body once despawned: every body re-checks.
    let removed = removed_particles.read().count()
        + removed_springs.read().count()
        + removed_pins.read().count()
        + removed_forces.read().count()
        + removed_winds.read().count()
        + removed_tets.read().count()
        + removed_materials.read().count()
        > 0;
    // Bodies whose springs, pins or forces were edited (one pass over the changed ones, not a
    // lookup per spring of every body).
    let mut edited: Vec<Entity> = changed_springs.iter().map(|s| s.0).collect();
    edited.extend(changed_setup.iter().map(|p| p.0));
    edited.extend(changed_tets.iter().map(|t| t.0));
    edited.sort_unstable();
    edited.dedup();
    let no_list: &[Entity] = &[];
    for (body_e, body, mut bs, mut status, plist, slist, wind, (tlist, material, solver)) in
        &mut bodies
    {
        let plist = plist.map_or(no_list, |p| p.entities());
        let slist = slist.map_or(no_list, |s| s.entities());
        let tlist = tlist.map_or(no_list, |t| t.entities());
        let bs = &mut *bs;
        let mut dirty = bs.sim.is_none() && bs.problem.is_none()
            || body.is_changed()
            || removed
            || global_wind.is_changed()
            || wind.as_ref().is_some_and(|w| w.is_changed())
            || bs.frame_dt != frame_dt
            || bs.springs.as_slice() != slist
            || bs.tets.as_slice() != tlist
            || material.as_ref().is_some_and(|m| m.is_changed())
            || solver.as_ref().is_some_and(|m| m.is_changed())
            || bs.particles.len() != plist.len()
            || bs.particles.as_slice() != plist;
        dirty |= edited.binary_search(&body_e).is_ok();
        if !dirty && bs.problem.is_some() {
            // Left out for bad input: retry when any of its particles is edited.
            dirty = plist.iter().any(|e| {
                particles.get(*e).is_ok_and(|(p, pin, f)| {
                    p.is_changed()
                        || pin.is_some_and(|p| p.is_changed())
                        || f.is_some_and(|f| f.is_changed())
                })
            });
        }
        if !dirty && let Some(sim) = bs.sim.as_mut() {
            // Per particle: pins, forces and masses changed → rebuild; position or velocity
            // edited (not by our writeback) → teleport.
            let masses = sim.system.mass();
            for (i, &e) in bs.particles.iter().enumerate() {
                let Ok((p, _, _)) = particles.get(e) else {
                    dirty = true;
                    break;
                };
                if p.mass as Scalar != masses[i] {
                    dirty = true;
                    break;
                }
                let (wx, wv) = bs.written[i];
                if p.position != wx || p.velocity != wv {
                    if bs.fixed_pins.contains(&(i as u32)) {
                        dirty = true;
                        break;
                    }
                    if p.position.is_finite() && p.velocity.is_finite() {
                        sim.state.x[i] = from_f32(p.position);
                        sim.state.v[i] = from_f32(p.velocity);
                        bs.written[i] = (p.position, p.velocity);
                    } else {
                        warn!("particle {e}: non-finite position or velocity ignored (kept {wx})");
                    }
                }
            }
        }
        if dirty {
            bs.diverged = None;
            bs.report = false;
            bs.frame_dt = frame_dt;
            bs.springs = slist.to_vec();
            bs.tets = tlist.to_vec();
            let wind = wind.map(|w| *w).or(global_wind.0);
            let fem = FemInput {
                list: tlist,
                tets: &tets,
                material: material.map(|m| m.0),
                solver: solver.map_or(SolverChoice::Auto, |s| s.0),
            };
            match build_body(
                body_e, &body, wind, plist, slist, &particles, &springs, &targets, frame_dt, fem,
            ) {
                Ok(b) => {
                    bs.written = b
                        .particles
                        .iter()
                        .map(|e| {
                            let (p, _, _) = particles.get(*e).expect("built from these");
                            (p.position, p.velocity)
                        })
                        .collect();
                    status.particles = b.particles.len() as u32;
                    status.rebuilds += 1;
                    status.springs = b.sim.system.springs.len() as u32;
                    status.tets = b.sim.system.tets.len() as u32;
                    bs.sim = Some(b.sim);
                    bs.particles = b.particles;
                    bs.index = b.index;
                    bs.follow = b.follow;
                    bs.fixed_pins = b.fixed_pins;
                    bs.problem = None;
                    status.state = BodyState::Running;
                }
                Err(msg) => {
                    warn!("{msg}; the body is left out of stepping");
                    let event = SoftBodyInvalid {
                        body: body_e,
                        message: msg.clone(),
                    };
                    commands.trigger(event.clone());
                    invalid.write(event);
                    bs.sim = None;
                    bs.particles = plist.to_vec();
                    bs.problem = Some(msg.clone());
                    status.state = BodyState::Invalid(msg);
                }
            }
        } else {
            update_follow(bs, &targets);
        }
        // Colliders: each moves linearly from its last pose to its current one over the
        // frame (its velocity is the transform's change over the fixed step).
        if let Some(sim) = bs.sim.as_mut() {
            sim.system.colliders.clear();
            let t0 = sim.time;
            for (c, gt, track) in &colliders {
                let (_, rot, pos) = gt.to_scale_rotation_translation();
                let from = track.prev.map_or(pos, |p| p.0);
                sim.system.colliders.push(Collider::new(
                    c.shape.0.clone(),
                    linear(from, pos, t0, frame_dt),
                    rot,
                    ContactMaterial {
                        friction: c.friction as f64,
                        restitution: c.restitution as f64,
                        thickness: c.thickness as f64,
                        bounce_threshold: c.bounce_threshold as f64,
                    },
                ));
            }
        }
    }
}

fn step(
    clock: Res<SoftBodyClock>,
    pool: Res<SoftBodyKernelPool>,
    mut timing: ResMut<super::diagnostics::StepTiming>,
    mut bodies: Query<(&SoftBody, &mut BodySim, &mut SoftBodyStatus)>,
) {
    if !clock.running() {
        return;
    }
    let start = bevy::platform::time::Instant::now();
    bodies
        .par_iter_mut()
        .for_each(|(body, mut bs, mut status)| {
            let bs = &mut *bs;
            let Some(sim) = bs.sim.as_mut() else { return };
            if bs.diverged.is_some() {
                return;
            }
            if body.paused {
                status.state = BodyState::Paused;
                return;
            }
            let start = bevy::platform::time::Instant::now();
            let before = sim.stats();
            let result = pool.advance(sim);
            let after = sim.stats();
            status.linear_iterations = after
                .linear_iterations
                .saturating_sub(before.linear_iterations)
                as u32;
            status.newton_iterations = after
                .newton_iterations
                .saturating_sub(before.newton_iterations)
                as u32;
            match result {
                Ok(rep) => {
                    // Followers end the frame exactly on their target (the linear path's end,
                    // recomputed in floating point, can be off by an ulp).
                    for (i, _, _, at) in &bs.follow {
                        sim.state.x[*i as usize] = from_f32(*at);
                    }
                    status.state = BodyState::Running;
                    status.substeps = rep.substeps;
                }
                Err(d) => {
                    status.state = BodyState::Diverged(d.to_string());
                    bs.diverged = Some(d);
                    bs.report = true;
                }
            }
            status.time = sim.time as f32;
            status.step_ms = start.elapsed().as_secs_f32() * 1e3;
        });
    timing.ms = Some(start.elapsed().as_secs_f64() * 1e3);
}

fn writeback(
    mut bodies: Query<(Entity, &mut BodySim)>,
    mut particles: Query<(&mut Particle, Option<&mut Transform>)>,
    mut colliders: Query<(&GlobalTransform, &mut ColliderTrack)>,
    mut diverged: MessageWriter<SoftBodyDiverged>,
    mut commands: Commands,
) {
    for (body_e, mut bs) in &mut bodies {
        let bs = &mut *bs;
        if bs.report
            && let Some(d) = &bs.diverged
        {
            bs.report = false;
            let message = format!("soft body {body_e}: {d}");
            warn!("{message}");
            let event = SoftBodyDiverged {
                body: body_e,
                divergence: d.clone(),
                message,
            };
            commands.trigger(event.clone());
            diverged.write(event);
        }
        let Some(sim) = bs.sim.as_ref() else { continue };
        // The driver restores the last good state on divergence; never write anything else.
        if !sim.state.is_finite() {
            continue;
        }
        for (i, &e) in bs.particles.iter().enumerate() {
            let Ok((mut p, tf)) = particles.get_mut(e) else {
                continue;
            };
            let (x, v) = (to_f32(sim.state.x[i]), to_f32(sim.state.v[i]));
            if p.position != x || p.velocity != v {
                p.position = x;
                p.velocity = v;
            }
            bs.written[i] = (x, v);
            if let Some(mut tf) = tf
                && tf.translation != x
            {
                tf.translation = x;
            }
        }
    }
    for (gt, mut track) in &mut colliders {
        let (_, rot, pos) = gt.to_scale_rotation_translation();
        track.prev = Some((pos, rot));
    }
}
