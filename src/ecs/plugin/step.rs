//! Stepping and writing back: every body advanced one fixed frame (in parallel), the state
//! written to the components, messages and events sent; reset and the plugin's clock.

use super::*;

/// Puts bodies back to their spawn state on [`ResetSoftBodies`].
pub(super) fn reset(
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
pub(super) fn tick(mut clock: ResMut<SoftBodyClock>, fixed: Res<Time<Fixed>>) {
    if clock.running() {
        clock.elapsed += fixed.timestep().as_secs_f64();
        clock.step_once = false;
    }
}

pub(super) fn step(
    clock: Res<SoftBodyClock>,
    pool: Res<SoftBodyKernelPool>,
    mut timing: ResMut<crate::ecs::diagnostics::StepTiming>,
    mut bodies: Query<(Entity, &SoftBody, &mut BodySim, &mut SoftBodyStatus)>,
) {
    if !clock.running() {
        return;
    }
    let start = bevy::platform::time::Instant::now();
    bodies
        .par_iter_mut()
        .for_each(|(entity, body, mut bs, mut status)| {
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
            let contact_before = sim.system.self_contact.as_ref().map(|c| c.total);
            let result = pool.advance(sim);
            let after = sim.stats();
            if let (Some(b), Some(a)) = (
                contact_before,
                sim.system.self_contact.as_ref().map(|c| c.total),
            ) {
                status.contact_passes = a.passes_run - b.passes_run;
                status.contact_failed = a.failures > b.failures;
                if status.contact_failed {
                    warn!(
                        "soft body {entity}: self-collision could not separate its surface within {} impact-zone iterations; its free particles were held where the pass began (free of intersections)",
                        crate::core::self_contact::ZONE_ITERATIONS
                    );
                }
            }
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
                        sim.state.x[*i as usize] = at.to_scalar();
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

pub(super) fn writeback(
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
            let (x, v) = (sim.state.x[i].to_f32(), sim.state.v[i].to_f32());
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
