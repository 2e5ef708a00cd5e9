//! Soft bodies in avian3d's world (feature `avian`): every avian [`Collider`] is a soft-body
//! collider, what the particles do to a dynamic rigid body acts back on it, and particles can
//! hang from rigid bodies.
//!
//! # Who steps first
//!
//! Both engines step once per fixed frame: the soft bodies in `FixedUpdate` (the
//! [`SoftBodySystems`] sets), avian in `FixedPostUpdate` (its `PhysicsSystems`). So within one
//! frame `[t, t + Δ]`:
//!
//! 1. [`SoftBodySystems::Prepare`]: each avian collider is read at its pose at `t` (avian's
//!    result of the previous frame) with its body's velocities. A static or kinematic body
//!    moves through the soft step as avian will move it: its centre of mass along `v`,
//!    turning at `ω` about it. A kinematic body is therefore where the particles see it at
//!    every substep and at the end of the frame — no lag.
//! 2. [`SoftBodySystems::Step`]: a dynamic body is stepped with the particles, substep by
//!    substep: it falls under avian's gravity, and each particle contact is an impulse computed
//!    with the pair's effective mass that changes the body's velocity at once and its path
//!    from then on (see [`crate::core::collide::Response`]).
//! 3. [`SoftBodySystems::Writeback`]: what the particles gave each dynamic body is applied to
//!    it through [`Forces`] (which wakes a sleeping body) as an impulse at the start of avian's
//!    step plus a constant force over it, chosen so that avian's step ends at the velocity
//!    *and* position the body reached in the soft step ([`Exchange::split`]); resting contact
//!    is then a steady force, felt in every avian substep as gravity is. The pull of particles
//!    hanging from a dynamic body is added as a force. The impulse is recorded in
//!    [`SoftBodyImpulse`].
//! 4. avian steps the rigid bodies `t → t + Δ` with those velocities and forces, and its own
//!    contacts and joints.
//!
//! Soft first is the order that lets a kinematic body and the particles agree on its pose
//! every frame, and makes the contact impulses reach the rigid body within the frame they
//! happen. The coupling is staggered, not a joint solve: momentum is exchanged exactly (what
//! the particles gain the body loses, linear and angular), but within a frame the soft step
//! does not see what avian's own contacts and joints will do to the body (they act from the
//! next frame on), the body's inertia tensor is held at its frame-start orientation, and a
//! hanging attachment's force is the pull at the end of the soft step, held over avian's
//! step. A rigid body touched by several soft bodies in one frame gets each one's impulses
//! computed as if the others were not there (they are summed).
//!
//! # Stability in both mass regimes
//!
//! Contacts are computed with the pair's effective mass and change the body's velocity within
//! the soft step, so neither a light cloth on a heavy crate (20 g particles under 10 kg) nor a
//! light ball on a heavy jelly (50 g on 10.8 kg) needs anything special: both rest without
//! jitter (`tests/avian.rs`). Attachments are the staggered part: the pull of particles
//! hanging from a body reaches it as a force held over avian's step, an explicit coupling
//! that is stable while `Δ·√(k/M) < 2`, with `k` the stiffness of the springs at the
//! attachment, `M` the body's mass and `Δ` the fixed frame. Measured with a ball on a rope of
//! 12 springs of 8000 N/m at 60 Hz, swinging from 20°: at 4 and 2 kg (Δ√(k/M) = 0.75, 1.05)
//! its top speed is the pendulum's 1.4 m/s; at 1 kg (1.49) it stays bounded but gains energy
//! (2.6 m/s); at 0.5 kg (2.11) and below it runs away. Keep `Δ√(k/M)` below about 1. Past the
//! limit the push is capped at [`SoftBodyAvianSettings::max_velocity_change`] and reported
//! (the bodies stay finite); raise the fixed rate, soften the last springs or make the body
//! heavier.
//!
//! # Filtering
//!
//! A soft body may carry avian [`CollisionLayers`]; it touches a collider when the two layers
//! interact. [`NoSoftBodyContact`] on a collider hides it from soft bodies. Sensors and
//! disabled colliders and bodies are skipped. A collider is handed to a body only when their
//! bounding boxes, each grown by what it can travel in the frame, overlap.
//!
//! # Contact material
//!
//! Friction is avian's [`Friction`] dynamic coefficient and restitution avian's
//! [`Restitution`] coefficient, looked up on the collider, then its body, then avian's
//! defaults; the contact thickness and bounce threshold are [`SoftBodyAvianSettings`]'s.

use crate::core::collide::{
    Collider as SoftCollider, ContactMaterial, Exchange, Response, Spin, reach_bounds,
};
use crate::core::jacobian::Linearization;
use crate::core::motion::Motion;
use crate::ecs::SoftBody;
use crate::ecs::plugin::{BodySim, SoftBodySchedule, SoftBodySystems};
use crate::math::{Scalar, ToScalar, Vector, VectorExt};
use avian3d::prelude::*;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::prelude::*;
use std::collections::{HashMap, HashSet};

/// Soft bodies meet avian3d's rigid bodies (part of [`SoftBodyPlugins`](crate::SoftBodyPlugins)
/// with the `avian` feature). Needs avian's `PhysicsPlugins` and [`SoftBodyPlugin`](crate::ecs::SoftBodyPlugin).
#[derive(Default)]
pub struct SoftBodyAvianPlugin;

/// On an avian collider: soft bodies do not see it.
#[derive(Component, Reflect, Clone, Copy, Debug, Default)]
#[reflect(Component, Default, Debug)]
pub struct NoSoftBodyContact;

/// The soft side of contacts with avian colliders.
#[derive(Resource, Reflect, Clone, Debug)]
#[reflect(Resource, Default, Debug)]
pub struct SoftBodyAvianSettings {
    /// Particles closer than this to a collider's surface are pushed out to it (m).
    pub thickness: f32,
    /// Normal approach speeds below this do not bounce (m/s).
    pub bounce_threshold: f32,
    /// Contacts and attachments act back on dynamic bodies (`false`: avian bodies are moving
    /// obstacles the soft bodies cannot push).
    pub two_way: bool,
    /// The most the soft bodies may change a rigid body's velocity in one frame (m/s); a
    /// larger push is scaled down to it, with a warning. Only a runaway coupling reaches it
    /// (an attachment past its stability limit, see the module documentation): the default,
    /// 50 m/s in 1/60 s, is 300 g.
    pub max_velocity_change: f32,
}

impl Default for SoftBodyAvianSettings {
    fn default() -> Self {
        Self {
            thickness: 0.01,
            bounce_threshold: 0.05,
            two_way: true,
            max_velocity_change: 50.0,
        }
    }
}

/// What soft bodies gave this dynamic rigid body in the last fixed frame (kept up to date on
/// every dynamic body a soft body touched or hangs from; zero once they part).
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct SoftBodyImpulse {
    /// Linear impulse (N·s) of contacts and attachments.
    pub linear: Vec3,
    /// Angular impulse about the body's centre of mass (N·m·s).
    pub angular: Vec3,
    /// Particle contacts that exchanged an impulse.
    pub contacts: u32,
}

/// Which soft-body colliders came from which avian entities, per soft body (internal).
#[derive(Resource, Default)]
struct Links {
    bodies: HashMap<Entity, BodyLinks>,
}

#[derive(Default)]
struct BodyLinks {
    /// Index in the body's collider list of the first avian collider.
    first: usize,
    /// Per avian collider: its dynamic body (receiving the exchange), if two-way.
    dynamic: Vec<Option<Entity>>,
    /// Particles hanging from a dynamic avian body: packed index, body.
    hanging: Vec<(u32, Entity)>,
}

/// Entities already warned about (one warning each).
#[derive(Resource, Default)]
struct Warned(HashSet<Entity>);

impl Plugin for SoftBodyAvianPlugin {
    fn build(&self, app: &mut App) {
        // The soft bodies' schedule (SoftBodyPlugin, added before this plugin in
        // SoftBodyPlugins, records it).
        let schedule = app
            .world()
            .get_resource::<SoftBodySchedule>()
            .map_or_else(|| FixedUpdate.intern(), |s| s.0);
        app.register_type::<NoSoftBodyContact>()
            .register_type::<SoftBodyAvianSettings>()
            .register_type::<SoftBodyImpulse>()
            .init_resource::<SoftBodyAvianSettings>()
            .init_resource::<Links>()
            .init_resource::<Warned>()
            .add_systems(
                schedule,
                (
                    (follow_rigid_bodies, gather_colliders)
                        .chain()
                        .in_set(SoftBodySystems::Prepare)
                        .after(crate::ecs::plugin::prepare),
                    apply_to_rigid_bodies.in_set(SoftBodySystems::Writeback),
                ),
            );
    }
}

/// A rigid body's pose and velocities as the soft step sees them.
#[derive(Clone, Copy)]
struct RigidState {
    position: Vec3,
    rotation: Quat,
    linear: Vec3,
    angular: Vec3,
    /// Centre of mass in world space.
    com: Vec3,
}

type RigidItem<'a> = (
    &'a RigidBody,
    &'a Position,
    &'a Rotation,
    &'a LinearVelocity,
    &'a AngularVelocity,
    &'a ComputedMass,
    &'a ComputedAngularInertia,
    &'a ComputedCenterOfMass,
    (Option<&'a Friction>, Option<&'a Restitution>),
    Option<&'a GravityScale>,
);

/// Not yet placed by avian (its pose is set from the transform when avian first prepares it).
fn unplaced(pos: &Position, rot: &Rotation) -> bool {
    *pos == Position::PLACEHOLDER || *rot == Rotation::PLACEHOLDER
}

fn rigid_state(item: &RigidItem) -> Option<RigidState> {
    let (_, pos, rot, lin, ang, _, _, com, _, _) = item;
    let s = RigidState {
        position: pos.0,
        rotation: rot.0,
        linear: lin.0,
        angular: ang.0,
        com: pos.0 + rot.0 * com.0,
    };
    (s.position.is_finite()
        && s.rotation.is_finite()
        && s.linear.is_finite()
        && s.angular.is_finite()
        && s.com.is_finite())
    .then_some(s)
}

/// Where a point fixed to the body at `local` (in its frame) is at `t0 + dt`, moving as the
/// body would without new forces.
fn predicted_point(s: &RigidState, local: Vec3, dt: f32) -> Vec3 {
    let turn = Quat::from_scaled_axis(s.angular * dt);
    let r = s.rotation * local + s.position - s.com;
    s.com + s.linear * dt + turn * r
}

type ColliderItem<'a> = (
    Entity,
    &'a Collider,
    &'a Position,
    &'a Rotation,
    Option<&'a ColliderOf>,
    Option<&'a CollisionLayers>,
    &'a ColliderAabb,
    (Option<&'a Friction>, Option<&'a Restitution>),
);

type ColliderFilter = (
    Without<NoSoftBodyContact>,
    Without<Sensor>,
    Without<ColliderDisabled>,
);

/// Particles pinned to an avian rigid body follow its predicted path over the frame (instead
/// of the `GlobalTransform`, which avian's fixed step does not propagate).
fn follow_rigid_bodies(
    mut bodies: Query<(Entity, &mut BodySim)>,
    rigid: Query<RigidItem, Without<RigidBodyDisabled>>,
    settings: Res<SoftBodyAvianSettings>,
    mut links: ResMut<Links>,
    mut warned: ResMut<Warned>,
) {
    for (body_e, mut bs) in &mut bodies {
        let bs = &mut *bs;
        let dt = bs.frame_dt() as f32;
        let entry = links.bodies.entry(body_e).or_default();
        entry.hanging.clear();
        let Some(sim) = bs.sim.as_mut() else { continue };
        let t0 = sim.time;
        for (i, target, offset, last) in &mut bs.follow {
            let Ok(item) = rigid.get(*target) else {
                continue;
            };
            if unplaced(item.1, item.2) {
                continue;
            }
            let Some(s) = rigid_state(&item) else {
                if warned.0.insert(*target) {
                    warn!(
                        "rigid body {target}: non-finite pose or velocity; particles hanging from it stay where they are"
                    );
                }
                continue;
            };
            let from = s.position + s.rotation * *offset;
            let to = predicted_point(&s, *offset, dt);
            sim.system.prescribe(
                *i as usize,
                Motion::Linear {
                    start: from.to_array().map(f64::from),
                    velocity: ((to - from) / dt).to_array().map(f64::from),
                    t0: t0 as f64,
                },
            );
            *last = to;
            if settings.two_way && item.0.is_dynamic() {
                entry.hanging.push((*i, *target));
            }
        }
    }
}

/// Every avian collider a body may touch this frame, appended to its colliders.
#[allow(clippy::too_many_arguments)]
fn gather_colliders(
    mut bodies: Query<(Entity, &mut BodySim, Option<&CollisionLayers>), With<SoftBody>>,
    colliders: Query<ColliderItem, ColliderFilter>,
    rigid: Query<RigidItem, Without<RigidBodyDisabled>>,
    settings: Res<SoftBodyAvianSettings>,
    default_friction: Option<Res<DefaultFriction>>,
    default_restitution: Option<Res<DefaultRestitution>>,
    gravity: Option<Res<Gravity>>,
    mut links: ResMut<Links>,
    mut warned: ResMut<Warned>,
) {
    let friction0 = default_friction.map_or(0.5, |f| f.0.dynamic_coefficient);
    let restitution0 = default_restitution.map_or(0.0, |r| r.0.coefficient);
    links.bodies.retain(|e, _| bodies.contains(*e));
    for (body_e, mut bs, layers) in &mut bodies {
        let bs = &mut *bs;
        let dt = bs.frame_dt() as f32;
        let entry = links.bodies.entry(body_e).or_default();
        entry.dynamic.clear();
        let Some(sim) = bs.sim.as_mut() else { continue };
        entry.first = sim.system.colliders.len();
        let layers = layers.copied().unwrap_or_default();
        // The box the body's particles can reach in the frame.
        let Some((lo, hi)) = reach_bounds(
            &sim.state.x,
            &sim.state.v,
            dt as Scalar,
            settings.thickness as Scalar + sim.system.gravity.length() * (dt * dt) as Scalar,
        ) else {
            continue;
        };
        let (lo, hi) = (lo.to_f32(), hi.to_f32());
        let t0 = sim.time;
        for (e, collider, pos, rot, of, c_layers, aabb, (c_friction, c_restitution)) in &colliders {
            if !layers.interacts_with(c_layers.copied().unwrap_or_default()) || unplaced(pos, rot) {
                continue;
            }
            if !(pos.0.is_finite() && rot.0.is_finite()) {
                if warned.0.insert(e) {
                    warn!(
                        "collider {e}: non-finite pose; soft bodies ignore it until it is finite"
                    );
                }
                continue;
            }
            let body = of
                .and_then(|of| rigid.get(of.body).ok())
                .filter(|b| !unplaced(b.1, b.2));
            let state = match &body {
                Some(item) => match rigid_state(item) {
                    Some(s) if !item.0.is_static() => Some(s),
                    Some(_) => None,
                    None => {
                        if warned.0.insert(e) {
                            warn!(
                                "collider {e}: its rigid body has a non-finite pose or velocity; soft bodies ignore it until it is finite"
                            );
                        }
                        continue;
                    }
                },
                None => None,
            };
            // The collider's box grown by what its body can travel in the frame.
            let reach = state.map_or(0.0, |s| {
                let half = (aabb.max - aabb.min).length() * 0.5;
                (s.linear.length() + s.angular.length() * (half + (aabb.center() - s.com).length()))
                    * dt
            });
            if aabb.min.cmpgt(hi + reach).any() || aabb.max.cmplt(lo - reach).any() {
                continue;
            }
            let friction = c_friction
                .or(body.as_ref().and_then(|b| b.8.0))
                .map_or(friction0, |f| f.dynamic_coefficient);
            let restitution = c_restitution
                .or(body.as_ref().and_then(|b| b.8.1))
                .map_or(restitution0, |r| r.coefficient);
            let material = ContactMaterial {
                friction: friction as f64,
                restitution: restitution as f64,
                thickness: settings.thickness as f64,
                bounce_threshold: settings.bounce_threshold as f64,
            };
            let shape = collider.shape_scaled().clone();
            let mut dynamic = None;
            let soft = match (state, &body) {
                (Some(s), Some(item)) => {
                    let motion = Motion::Linear {
                        start: s.com.to_array().map(f64::from),
                        velocity: s.linear.to_array().map(f64::from),
                        t0: t0 as f64,
                    };
                    let spin = Spin {
                        angular_velocity: s.angular.to_scalar(),
                        t0,
                        center: (rot.0.inverse() * (s.com - pos.0)).to_scalar(),
                    };
                    let mut c = SoftCollider::new(shape, motion, rot.0, material).with_spin(spin);
                    if settings.two_way && item.0.is_dynamic() {
                        let inv_mass = item.5.inverse();
                        let inv_inertia = item.6.rotated(s.rotation).inverse_tensor().to_mat3();
                        if inv_mass.is_finite() && inv_mass > 0.0 && inv_inertia.is_finite() {
                            let rows = [0, 1, 2].map(|k| inv_inertia.row(k).to_scalar());
                            let g = gravity.as_ref().map_or(Vec3::ZERO, |g| g.0)
                                * item.9.map_or(1.0, |s| s.0);
                            c = c.with_response(
                                Response::new(inv_mass as Scalar, rows, t0)
                                    .with_gravity(g.to_scalar()),
                            );
                            dynamic = of.map(|of| of.body);
                        } else if warned.0.insert(e) {
                            warn!(
                                "collider {e}: its dynamic body has no usable mass (inverse mass {inv_mass}); soft bodies treat it as kinematic"
                            );
                        }
                    }
                    c
                }
                _ => SoftCollider::new(
                    shape,
                    Motion::Fixed {
                        position: pos.0.to_array().map(f64::from),
                    },
                    rot.0,
                    material,
                ),
            };
            sim.system.colliders.push(soft);
            entry.dynamic.push(dynamic);
        }
    }
}

/// The impulses the particles gave dynamic bodies, and the pull of hanging particles, applied
/// to the bodies before avian steps them.
#[allow(clippy::too_many_arguments)]
fn apply_to_rigid_bodies(
    bodies: Query<(Entity, &BodySim)>,
    links: Res<Links>,
    mut forces: Query<(
        Forces,
        &ComputedCenterOfMass,
        &ComputedMass,
        Option<&mut SoftBodyImpulse>,
    )>,
    settings: Res<SoftBodyAvianSettings>,
    mut touched: Local<HashSet<Entity>>,
    fixed: Res<Time<Fixed>>,
    mut commands: Commands,
    mut warned: ResMut<Warned>,
) {
    // Per rigid body: the contact exchange, the attachments' force and its moment about the
    // origin.
    let mut total: HashMap<Entity, (Exchange, Vec3, Vec3)> = HashMap::new();
    for (body_e, bs) in &bodies {
        let (Some(sim), Some(entry)) = (bs.sim.as_ref(), links.bodies.get(&body_e)) else {
            continue;
        };
        if bs.is_diverged() {
            continue;
        }
        for (k, dynamic) in entry.dynamic.iter().enumerate() {
            let (Some(rb), Some(c)) = (dynamic, sim.system.colliders.get(entry.first + k)) else {
                continue;
            };
            let Some(r) = &c.response else { continue };
            let ex = r.take();
            let t = &mut total.entry(*rb).or_default().0;
            t.linear += ex.linear;
            t.angular += ex.angular;
            t.linear_moment += ex.linear_moment;
            t.angular_moment += ex.angular_moment;
            t.contacts += ex.contacts;
        }
        if !entry.hanging.is_empty() {
            // The pull of the rest of the body on each hanging particle at the end of the
            // step (springs, elements, its weight): what the rigid body must bear.
            let n = sim.state.x.len();
            let mut f = vec![Vector::ZERO; n];
            sim.system.total_forces(sim.time, &sim.state, &mut f);
            for &(i, rb) in &entry.hanging {
                let fi = f[i as usize].to_f32();
                let t = total.entry(rb).or_default();
                t.1 += fi;
                let x = sim.state.x[i as usize].to_f32();
                t.2 += x.cross(fi); // about the origin; shifted to the centre of mass below
            }
        }
    }
    let frame = fixed.timestep().as_secs_f32();
    let mut now = HashSet::with_capacity(total.len());
    for (rb, (ex, force, moment)) in total {
        let (j, l, contacts) = (ex.linear.to_f32(), ex.angular.to_f32(), ex.contacts);
        let Ok((mut f, local_com, mass, record)) = forces.get_mut(rb) else {
            if warned.0.insert(rb) {
                warn!(
                    "rigid body {rb} is gone or has no mass properties; its soft-body impulse is dropped"
                );
            }
            continue;
        };
        let moments = (ex.linear_moment.to_f32(), ex.angular_moment.to_f32());
        if !(j.is_finite()
            && l.is_finite()
            && moments.0.is_finite()
            && moments.1.is_finite()
            && force.is_finite()
            && moment.is_finite())
        {
            if warned.0.insert(rb) {
                warn!("rigid body {rb}: a non-finite soft-body impulse was dropped");
            }
            continue;
        }
        // The exchange as an impulse at the start of avian's step and a constant force over
        // it, which give the body the end velocity and position it had in the soft step
        // (`Exchange::split`); resting contact is a steady force, felt in every substep as
        // gravity is. The attachments' pull is a force over the step as it is.
        let (ja, fa, aa, ta) = ex.split(frame as Scalar);
        let com = f.position().0 + f.rotation().0 * local_com.0;
        let (mut ja, mut aa) = (ja.to_f32(), aa.to_f32());
        let mut force_total = fa.to_f32() + force;
        let mut torque = ta.to_f32() + moment - com.cross(force);
        // A safety valve for a runaway coupling: never more than `max_velocity_change` in a
        // frame (scaled down, reported once).
        let dv = (ja + force_total * frame).length() * mass.inverse();
        if dv > settings.max_velocity_change {
            let k = settings.max_velocity_change / dv;
            (ja, aa, force_total, torque) = (ja * k, aa * k, force_total * k, torque * k);
            if warned.0.insert(rb) {
                warn!(
                    "rigid body {rb}: the soft bodies' push would change its velocity by {dv:.1} m/s in one frame; scaled down to {} m/s. An attachment is unstable when Δ·√(k/M) > 2 (a light body on a stiff spring): raise the fixed rate, soften the spring or make the body heavier",
                    settings.max_velocity_change
                );
            }
        }
        if ja.is_finite() && ja != Vec3::ZERO {
            f.apply_linear_impulse(ja);
        }
        if aa.is_finite() && aa != Vec3::ZERO {
            f.apply_angular_impulse(aa);
        }
        if force_total.is_finite() && force_total != Vec3::ZERO {
            f.apply_force(force_total);
        }
        if torque.is_finite() && torque != Vec3::ZERO {
            f.apply_torque(torque);
        }
        let value = SoftBodyImpulse {
            linear: j + force * frame,
            angular: l + (moment - com.cross(force)) * frame,
            contacts,
        };
        match record {
            Some(mut r) => *r = value,
            None => {
                commands.entity(rb).insert(value);
            }
        }
        now.insert(rb);
    }
    for rb in touched.drain() {
        if !now.contains(&rb)
            && let Ok((_, _, _, Some(mut r))) = forces.get_mut(rb)
        {
            *r = SoftBodyImpulse::default();
        }
    }
    *touched = now;
}
