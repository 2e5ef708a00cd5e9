//! Where pins and colliders are over the coming frame: scripted motion of kinematic entities,
//! particles following their pin targets, colliders' paths.

use super::*;
use crate::core::collide::{Collider, ContactMaterial};
use crate::core::motion::Motion;

type ScriptedItem<'a> = (
    &'a ScriptedMotion,
    &'a mut Transform,
    &'a mut GlobalTransform,
    Option<&'a mut ColliderTrack>,
);

pub(super) fn scripted_motion(
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
        tf.translation = m.0.position(t).to_f32();
        // Top-level entity: its global transform is its transform; set it now so this fixed
        // step sees the new pose (propagation runs later, in PostUpdate).
        *gt = GlobalTransform::from(*tf);
    }
}

pub(super) fn v3(v: Vec3) -> [f64; 3] {
    v.to_array().map(|c| c as f64)
}

/// A linear path from `from` (at `t0`) to `to` (at `t0 + dt`).
pub(super) fn linear(from: Vec3, to: Vec3, t0: Scalar, dt: f64) -> Motion {
    Motion::Linear {
        start: v3(from),
        velocity: v3((to - from) / dt as f32),
        t0: t0 as f64,
    }
}

/// Moves the particles that follow a target along the target's path over the coming frame.
pub(super) fn update_follow(bs: &mut BodySim, targets: &Query<&GlobalTransform>) {
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

/// Colliders, as this body sees them over the coming frame: each moves linearly from its last
/// pose to its current one (its velocity is the transform's change over the fixed step).
pub(super) fn update_colliders(
    bs: &mut BodySim,
    colliders: &Query<(&SoftBodyCollider, &GlobalTransform, &ColliderTrack)>,
    frame_dt: f64,
) {
    if let Some(sim) = bs.sim.as_mut() {
        sim.system.colliders.clear();
        let t0 = sim.time;
        for (c, gt, track) in colliders {
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
