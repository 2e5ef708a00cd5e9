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
            bs.idle = false;
            let Some(sim) = bs.sim.as_mut() else { return };
            if bs.diverged.is_some() {
                return;
            }
            if body.paused {
                status.state = BodyState::Paused;
                return;
            }
            let start = bevy::platform::time::Instant::now();
            if sim.system.self_contact.is_some() {
                // The frame's start, for contact with other bodies after every body has moved.
                bs.frame_start.clear();
                bs.frame_start.extend_from_slice(&sim.state.x);
            }
            let before = sim.stats();
            let contact_before = sim.system.self_contact.as_ref().map(|c| c.total);
            let was_asleep = sim.is_asleep();
            let result = pool.advance(sim);
            bs.idle = was_asleep && sim.is_asleep();
            let after = sim.stats();
            if let (Some(b), Some(a)) = (
                contact_before,
                sim.system.self_contact.as_ref().map(|c| c.total),
            ) {
                status.contact_passes = a.passes_run - b.passes_run;
                status.contact_searches = a.searches - b.searches;
                status.contact_candidates = a.candidates;
                status.contact_broad_ms = ms(a.broad.saturating_sub(b.broad));
                status.contact_narrow_ms = ms(a.narrow.saturating_sub(b.narrow));
                // The totals keep the last particle that made a pass due: this step's only if
                // a pass of this step was made due by one.
                let by_particle = a.due_budget + a.due_tube > b.due_budget + b.due_tube;
                status.contact_due_particle = if by_particle { a.due_particle } else { None };
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
                    status.state = if sim.is_asleep() {
                        BodyState::Sleeping
                    } else {
                        BodyState::Running
                    };
                    status.substeps = rep.substeps;
                    status.method = sim.method();
                    // Compared first: a frame that keeps the choice allocates nothing.
                    let reason = sim.auto_choice().map_or("", |c| c.reason.as_str());
                    if status.auto_reason != reason {
                        status.auto_reason = reason.to_string();
                    }
                }
                Err(d) => {
                    status.state = BodyState::Diverged(d.to_string());
                    bs.diverged = Some(d);
                    bs.report = true;
                }
            }
            status.time = sim.time as f32;
            status.step_ms = ms(start.elapsed());
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
        // A body that slept through the step has nothing new.
        if !sim.state.is_finite() || bs.idle {
            continue;
        }
        bs.version += 1;
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

/// Contact between separate bodies that have [`SelfCollision`]: after every body has advanced
/// the frame, the bodies whose swept boxes (grown by their thickness) overlap are grouped, and
/// each group's surfaces go through one contact pass over the frame as a single surface
/// ([`crate::core::body_contact`]); bodies that are paused, diverged or not yet built take no
/// part. A group's handler is kept while its members stay the same.
pub(super) fn contact_between(
    clock: Res<SoftBodyClock>,
    mut cache: Local<Vec<crate::core::body_contact::ContactGroup>>,
    mut supports: Local<Vec<Vec<bool>>>,
    mut bodies: Query<(Entity, &SoftBody, &mut BodySim, &mut SoftBodyStatus)>,
) {
    use crate::core::body_contact::{ContactGroup, GroupMember, overlapping_groups, swept_box};
    if !clock.running() {
        return;
    }
    let colliding = bodies
        .iter()
        .filter(|(_, _, bs, _)| {
            bs.sim
                .as_ref()
                .is_some_and(|s| s.system.self_contact.is_some())
        })
        .count();
    if colliding < 2 {
        cache.clear(); // nothing to pair: no work, no allocation
        return;
    }
    let mut all: Vec<_> = bodies.iter_mut().collect();
    let boxes: Vec<_> = all
        .iter()
        .map(|(_, body, bs, _)| {
            let sim = bs.sim.as_ref()?;
            let sc = sim.system.self_contact.as_ref()?;
            if body.paused || bs.diverged.is_some() || bs.frame_start.len() != sim.state.x.len() {
                return None;
            }
            swept_box(
                &sc.surface,
                &bs.frame_start,
                &sim.state.x,
                sc.params.thickness as Scalar,
            )
        })
        .collect();
    let groups = overlapping_groups(&boxes);
    if groups.is_empty() {
        cache.clear();
        return;
    }
    let mut used = vec![false; cache.len()];
    for group in groups {
        let key: Vec<u64> = group
            .iter()
            .flat_map(|&k| [all[k].0.to_bits(), all[k].3.rebuilds as u64])
            .collect();
        let cached = cache.iter().position(|g| g.key() == key.as_slice());
        // Bodies that all slept through the step did not move: nothing to resolve (their
        // handler is kept). An awake body touching sleeping ones wakes them (they take part
        // as they lie).
        if group.iter().all(|&k| all[k].2.idle) {
            if let Some(slot) = cached {
                used[slot] = true;
            }
            continue;
        }
        for &k in &group {
            let bs = &mut *all[k].2;
            if bs.idle {
                bs.idle = false;
                if let Some(sim) = bs.sim.as_mut() {
                    sim.wake();
                }
                all[k].3.state = BodyState::Running;
            }
        }
        let slot = match cached {
            Some(i) => i,
            None => {
                cache.push(ContactGroup::default());
                used.push(false);
                cache.len() - 1
            }
        };
        used[slot] = true;
        // Particles resting on a collider count heavier, as in a body's own passes.
        supports.resize_with(group.len(), Vec::new);
        for (m, &k) in group.iter().enumerate() {
            let sim = all[k].2.sim.as_ref().expect("grouped bodies are built");
            let sc = sim
                .system
                .self_contact
                .as_ref()
                .expect("grouped bodies collide");
            let slack = 0.5 * sc.params.thickness as Scalar;
            let support = &mut supports[m];
            support.clear();
            support.resize(sim.state.x.len(), false);
            for c in &sim.system.colliders {
                c.touching(sim.time, slack, &sim.state.x, support);
            }
        }
        let h = all[group[0]].2.frame_dt as Scalar;
        let mut members: Vec<GroupMember> = Vec::with_capacity(group.len());
        let mut entities = Vec::with_capacity(group.len());
        for (k, (e, _, bs, _)) in all.iter_mut().enumerate() {
            let Ok(m) = group.binary_search(&k) else {
                continue;
            };
            entities.push(*e);
            let bs = &mut **bs;
            let sim = bs.sim.as_mut().expect("grouped bodies are built");
            let (system, state) = (&sim.system, &mut sim.state);
            let sc = system
                .self_contact
                .as_ref()
                .expect("grouped bodies collide");
            members.push(GroupMember {
                surface: &sc.surface,
                params: sc.params,
                x0: &bs.frame_start,
                x: &mut state.x,
                v: &mut state.v,
                inv_mass: system.inv_mass(),
                support: &supports[m],
            });
        }
        let rep = cache[slot].resolve(&key, h, &mut members);
        drop(members);
        // The group's time shared evenly among its bodies (the sum over bodies is the wall time).
        let share = 1.0 / group.len() as f32;
        for &k in &group {
            let status = &mut all[k].3;
            status.contact_passes += 1;
            status.contact_searches += rep.searches;
            status.contact_broad_ms += ms(rep.broad) * share;
            status.contact_narrow_ms += ms(rep.narrow) * share;
            if rep.failed {
                status.contact_failed = true;
            }
        }
        if rep.failed {
            warn!(
                "soft bodies {entities:?}: contact between them could not be separated within {} impact-zone iterations; their free surface particles were held where the frame began (free of intersections)",
                crate::core::self_contact::ZONE_ITERATIONS
            );
        }
    }
    let mut i = 0;
    cache.retain(|_| {
        i += 1;
        used[i - 1]
    });
}

/// Tearing, after the frame is written back: the springs of [`Tearable`] bodies stretched
/// past their limit break (their entities despawned), and the surface tears along them
/// ([`crate::core::tear`]): each split particle gets a copy entity (same position and
/// velocity, its share of the mass, the same pin), springs on the copy's side are moved to
/// it, and the surface's triangles and texture coordinates follow (a game's mesh,
/// [`crate::ecs::SoftBodyMeshSurface`], gets a vertex of its own for each corner moved to a
/// copy). The body is rebuilt at the next step; a [`SoftBodyTorn`] names what broke.
#[allow(clippy::type_complexity)]
pub(super) fn tear(
    mut bodies: Query<(
        Entity,
        &Tearable,
        &mut BodySim,
        Option<&mut crate::render::SoftBodySurface>,
        Option<&mut crate::ecs::SoftBodyMeshSurface>,
    )>,
    mut particles: Query<(&mut Particle, Option<&Pinned>)>,
    mut springs: Query<&mut Spring>,
    mut tets: Query<&mut Tet>,
    mut torn_msgs: MessageWriter<SoftBodyTorn>,
    mut commands: Commands,
) {
    use crate::core::tear::{
        TearMesh, by_strain, overstrained_tets, overstretched, part_copies, tets_by_strain,
    };
    for (body_e, tearable, mut bs, surface, mesh_surface) in &mut bodies {
        let bs = &mut *bs;
        let params = tearable.params();
        if bs.torn || bs.diverged.is_some() || params.validate().is_err() {
            continue;
        }
        let Some(sim) = bs.sim.as_ref() else { continue };
        if !sim.state.is_finite() {
            continue;
        }
        let thickness = sim.system.self_contact.as_ref().map(|c| c.params.thickness);
        let packed = sim.system.springs.as_slice();
        let over = overstretched(
            packed.iter().map(|s| ([s.i, s.j], s.rest)),
            &sim.state.x,
            params.max_strain,
        );
        let packed_tets = sim.system.tets.as_slice();
        let over_tets = overstrained_tets(
            packed_tets.iter().map(|t| (t.v, &t.rest)),
            &sim.state.x,
            params.max_strain,
        );
        if over.is_empty() && over_tets.is_empty() {
            continue;
        }
        let corners: Vec<[u32; 4]> = packed_tets.iter().map(|t| t.v).collect();
        // The game's mesh: its triangles between distinct particles, in particle indices (the
        // mesh's own, and which of them they are), so the tear splits them too.
        let game_mesh: Option<(Vec<usize>, Vec<[u32; 3]>)> = match (&surface, &mesh_surface) {
            (None, Some(ms)) if !ms.triangles.is_empty() => mesh_triangles(ms, bs),
            _ => None,
        };
        let mut mesh = TearMesh::new(
            packed.iter().map(|s| [s.i, s.j]).collect(),
            match (&surface, &game_mesh) {
                (Some(s), _) => s.triangles.clone(),
                (None, Some((_, t))) => t.clone(),
                _ => vec![],
            },
        )
        .with_tets(corners);
        let triangles_before = mesh.triangles.len();
        let mut mass: Vec<f64> = sim.system.mass().iter().map(|&m| m as f64).collect();
        let torn = mesh.tear_with_tets(
            &by_strain(&over),
            &tets_by_strain(&over_tets),
            &sim.state.x,
            &mut mass,
        );
        let n = bs.particles.len();
        // Positions after the tear: copies where their originals are, and with self-collision
        // each side of a cut moved half the thickness into its own side.
        let mut x = sim.state.x.clone();
        for &(p, _) in &torn.copies {
            let xp = x[p as usize];
            x.push(xp);
        }
        if let Some(gap) = thickness {
            // Pinned particles (and their copies, which keep the pin) stay where they are.
            let held = |i: usize| {
                let mut root = i;
                while root >= n {
                    root = torn.copies[root - n].0 as usize;
                }
                particles
                    .get(bs.particles[root])
                    .is_ok_and(|(_, pin)| pin.is_some())
            };
            part_copies(&torn, &mut x, gap, held);
        }
        // The particle each index copies, back to one the model has.
        let mut origin: Vec<usize> = (0..n).collect();
        let mut entity = bs.particles.clone();
        let mut split = Vec::with_capacity(torn.copies.len());
        for (k, &(parent, m)) in torn.copies.iter().enumerate() {
            let root = origin[parent as usize];
            let (x, v) = (x[n + k].to_f32(), sim.state.v[root].to_f32());
            let pin = particles
                .get(entity[parent as usize])
                .ok()
                .and_then(|(_, pin)| pin.cloned());
            let mut ec = commands.spawn((
                Particle {
                    position: x,
                    velocity: v,
                    mass: m as f32,
                },
                ParticleOf(body_e),
            ));
            if let Some(pin) = pin {
                ec.insert(pin);
            }
            let copy = ec.id();
            split.push((entity[parent as usize], copy));
            origin.push(root);
            entity.push(copy);
        }
        for (i, &e) in bs.particles.iter().enumerate() {
            if let Ok((mut p, _)) = particles.get_mut(e) {
                if (mass[i] as f32) != p.mass {
                    p.mass = mass[i] as f32;
                }
                let xi = x[i].to_f32();
                if xi != p.position {
                    p.position = xi;
                }
            }
        }
        for &(k, [a, b]) in &torn.moved {
            if let Some(&se) = bs.packed_springs.get(k)
                && let Ok(mut s) = springs.get_mut(se)
            {
                s.a = entity[a as usize];
                s.b = entity[b as usize];
            }
        }
        // The split-off side's own springs along edges on the cut: each side keeps one of
        // the edge's two triangles, so the original and its copy take half of its stiffness
        // and damping each (the split stores no energy the edge did not).
        for &(k, [a, b]) in &torn.added {
            if let Some(&se) = bs.packed_springs.get(k)
                && let Ok(mut s) = springs.get_mut(se)
            {
                s.stiffness *= 0.5;
                s.damping *= 0.5;
                let mut copy = *s;
                copy.a = entity[a as usize];
                copy.b = entity[b as usize];
                commands.spawn((copy, SpringOf(body_e)));
            }
        }
        let broken: Vec<Entity> = torn
            .broken
            .iter()
            .filter_map(|&k| bs.packed_springs.get(k).copied())
            .collect();
        for &se in &broken {
            commands.entity(se).despawn();
        }
        // Tets split off at a corner take the copy; those that could not be are removed.
        for &(k, c) in &torn.tets_moved {
            if let Some(&te) = bs.packed_tets.get(k)
                && let Ok(mut t) = tets.get_mut(te)
            {
                t.particles = c.map(|i| entity[i as usize]);
            }
        }
        let tets_over: Vec<Entity> = torn
            .tets_over
            .iter()
            .filter_map(|&k| bs.packed_tets.get(k).copied())
            .collect();
        for &k in &torn.tets_removed {
            if let Some(&te) = bs.packed_tets.get(k) {
                commands.entity(te).despawn();
            }
        }
        // The surface changed: split, or triangles gone (a hole where a surface spring broke
        // with neither end splittable, or tets removed).
        let reshaped = !torn.copies.is_empty()
            || !torn.tets_removed.is_empty()
            || mesh.triangles.len() != triangles_before;
        let has_surface = surface.is_some();
        if let Some(mut surf) = surface
            && reshaped
        {
            let surf = &mut *surf;
            surf.triangles = std::mem::take(&mut mesh.triangles);
            if !surf.uvs.is_empty() && surf.uvs.len() <= n {
                // Particles the surface does not show (a mouse grab's handle) have none.
                surf.uvs.resize(n, [0.0; 2]);
                for &(parent, _) in &torn.copies {
                    let uv = surf.uvs[parent as usize];
                    surf.uvs.push(uv);
                }
            }
            crate::core::tear::record_copies(&mut surf.torn_from, n, &torn.copies);
            commands
                .entity(body_e)
                .remove::<crate::render::SurfaceVertices>();
        }
        if !has_surface {
            for &(parent, copy) in &split {
                bs.torn_origin.insert(copy, parent);
            }
        }
        if let Some(mut ms) = mesh_surface
            && reshaped
        {
            match &game_mesh {
                Some((which, before)) => {
                    split_mesh_surface(&mut ms, which, before, &mesh.triangles, &origin, &entity)
                }
                None => warn_once!(
                    "soft body {body_e}: Tearable with a SoftBodyMeshSurface that lists no triangles, or shows something other than the body's particles: the physics tears, but the game's mesh is drawn whole"
                ),
            }
        }
        bs.torn = true;
        let event = SoftBodyTorn {
            body: body_e,
            springs: broken,
            split,
            tets: tets_over,
        };
        commands.trigger(event.clone());
        torn_msgs.write(event);
    }
}

/// A game's mesh's triangles in packed particle indices: the indices of the mesh triangles
/// whose corners are three distinct particles of the body, and those triangles. `None` when
/// a vertex shows no particle of the body.
fn mesh_triangles(
    ms: &crate::ecs::SoftBodyMeshSurface,
    bs: &BodySim,
) -> Option<(Vec<usize>, Vec<[u32; 3]>)> {
    let mut which = Vec::with_capacity(ms.triangles.len());
    let mut tris = Vec::with_capacity(ms.triangles.len());
    for (t, tri) in ms.triangles.iter().enumerate() {
        let mut p = [0u32; 3];
        for c in 0..3 {
            p[c] = bs.index_of(*ms.vertices.get(tri[c] as usize)?)? as u32;
        }
        if p[0] != p[1] && p[1] != p[2] && p[0] != p[2] {
            which.push(t);
            tris.push(p);
        }
    }
    Some((which, tris))
}

/// Follows a tear on a game's mesh: `before` are its triangles `which` in particle indices as
/// the tear got them, `after` what the tear made of them (the same order, less those it
/// removed; `origin` maps every particle index, copies included, to the one it was split
/// from). A corner moved to a copy gets a vertex of its own for that copy (one per mesh
/// vertex and copy: triangles that keep a seam keep it), copying the vertex it split from.
fn split_mesh_surface(
    ms: &mut crate::ecs::SoftBodyMeshSurface,
    which: &[usize],
    before: &[[u32; 3]],
    after: &[[u32; 3]],
    origin: &[usize],
    entity: &[Entity],
) {
    let own = ms.vertices.len() - ms.split_from.len();
    let mut added: HashMap<(u32, u32), u32> = HashMap::new();
    let mut removed = vec![false; ms.triangles.len()];
    let mut k = 0;
    for (&t, b) in which.iter().zip(before) {
        let Some(&a) = after
            .get(k)
            .filter(|a| (0..3).all(|c| origin[a[c] as usize] == b[c] as usize))
        else {
            removed[t] = true;
            continue;
        };
        k += 1;
        for c in 0..3 {
            if a[c] == b[c] {
                continue;
            }
            let v = ms.triangles[t][c];
            let nv = *added.entry((v, a[c])).or_insert_with(|| {
                let source = if (v as usize) < own {
                    v
                } else {
                    ms.split_from[v as usize - own]
                };
                ms.vertices.push(entity[a[c] as usize]);
                ms.split_from.push(source);
                (ms.vertices.len() - 1) as u32
            });
            ms.triangles[t][c] = nv;
        }
    }
    let mut t = 0;
    ms.triangles.retain(|_| {
        t += 1;
        !removed[t - 1]
    });
    ms.torn = true;
}

/// A duration in milliseconds, as the status reports times.
fn ms(d: std::time::Duration) -> f32 {
    d.as_secs_f32() * 1e3
}
