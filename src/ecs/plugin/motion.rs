//! Where pins and colliders are over the coming frame: scripted motion of kinematic entities,
//! particles following their pin targets, colliders' paths.

use super::*;
use crate::core::collide::{
    Collider, ContactMaterial, Spin, boxes_overlap, reach_bounds, scale_shape,
};
use crate::core::motion::Motion;
use crate::math::Vector;
use parry3d::math::Pose3;

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

/// Once a frame per collider, what every body then reads: its shape at its transform's scale
/// (rescaled only when the scale or the shape changes: a triangle mesh costs a copy), its box
/// over the frame (last and current pose, grown by its thickness) and its turn over the frame.
pub(super) fn scale_colliders(
    mut colliders: Query<(
        Entity,
        Ref<SoftBodyCollider>,
        &GlobalTransform,
        &mut ColliderTrack,
    )>,
) {
    for (e, c, gt, mut track) in &mut colliders {
        let (scale, rot, pos) = gt.to_scale_rotation_translation();
        let current = track.scaled.as_ref().map_or(Vec3::ONE, |s| s.0);
        if scale != current || c.is_changed() {
            track.scaled = if scale == Vec3::ONE {
                None
            } else {
                match scale_shape(&c.shape.0, scale, 16) {
                    Some(shape) => Some((scale, shape)),
                    None => {
                        warn!(
                            "collider {e}: its shape cannot take the scale {scale}; the unscaled shape is used"
                        );
                        None
                    }
                }
            };
        }
        let (from, from_rot) = track.prev.unwrap_or((pos, rot));
        let shape = track.scaled.as_ref().map_or(&c.shape.0, |s| &s.1);
        track.frame_box = shape.as_halfspace().is_none().then(|| {
            let a = shape.compute_aabb(&Pose3::from_parts(from, from_rot));
            let b = shape.compute_aabb(&Pose3::from_parts(pos, rot));
            let grow = Vec3::splat(c.thickness.max(0.0));
            (
                (a.mins.min(b.mins) - grow).to_scalar(),
                (a.maxs.max(b.maxs) + grow).to_scalar(),
            )
        });
        // The shortest turn from the last orientation to this one.
        let mut turn = rot * from_rot.inverse();
        if turn.w < 0.0 {
            turn = -turn;
        }
        let axis_angle = turn.to_scaled_axis();
        track.turn = if axis_angle.is_finite() {
            axis_angle
        } else {
            Vec3::ZERO
        };
    }
}

/// Colliders, as this body sees them over the coming frame: each moves linearly from its last
/// pose to its current one, and turns at the constant angular velocity that takes its last
/// orientation to its current one (both velocities are the transform's change over the fixed
/// step), with the shape at the transform's scale.
pub(super) fn update_colliders(
    bs: &mut BodySim,
    colliders: &Query<(&SoftBodyCollider, &GlobalTransform, &ColliderTrack)>,
    frame_dt: f64,
) {
    if let Some(sim) = bs.sim.as_mut() {
        sim.system.colliders.clear();
        let t0 = sim.time;
        // Broad phase: the box the particles can reach this frame against each collider's box
        // over the frame (its last and current poses); a body far from a collider never tests
        // its particles against it.
        let dt = frame_dt as Scalar;
        let fall = sim.system.gravity.length() * dt * dt;
        let Some(reach) = reach_bounds(&sim.state.x, &sim.state.v, dt, fall) else {
            return;
        };
        for (c, gt, track) in colliders {
            if track
                .frame_box
                .is_some_and(|bounds| !boxes_overlap(reach, bounds))
            {
                continue;
            }
            let (_, rot, pos) = gt.to_scale_rotation_translation();
            let (from, from_rot) = track.prev.unwrap_or((pos, rot));
            let shape = track
                .scaled
                .as_ref()
                .map_or_else(|| c.shape.0.clone(), |s| s.1.clone());
            let material = ContactMaterial {
                friction: c.friction as f64,
                restitution: c.restitution as f64,
                thickness: c.thickness as f64,
                bounce_threshold: c.bounce_threshold as f64,
            };
            let mut collider = Collider::new(shape, linear(from, pos, t0, frame_dt), rot, material);
            // The turn from the last orientation to this one, spread over the step.
            if track.turn != Vec3::ZERO {
                collider.rotation = from_rot;
                collider = collider.with_spin(Spin {
                    angular_velocity: (track.turn / frame_dt as f32).to_scalar(),
                    t0,
                    center: Vector::ZERO,
                });
            }
            sim.system.colliders.push(collider);
        }
    }
}
