//! Rebuild detection and user changes: a body whose topology or parameters changed is
//! gathered again from its components into a packed core model; otherwise particles the user
//! moved are teleported; then pins and colliders are placed for the coming frame.

use super::motion::{update_colliders, update_follow, v3};
use super::*;
use crate::core::driver::DriverConfig;
use crate::core::layout::{
    Anchor, BodyLayout, LayoutItem, LayoutParticle, LayoutSpring, LayoutTet,
};
use crate::render::SoftBodySurface;

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
    /// What the automatic method aims for.
    auto: AutoConfig,
    /// Self-collision, the surface's triangles (empty: the tets' boundary) and which particles
    /// were torn from which (empty: from the body's own record, `torn_origin`).
    self_collision: Option<(SelfCollision, Vec<[u32; 3]>, Vec<u32>)>,
    /// The surface's triangles, for colliders to touch between the particles (empty: the
    /// tets' boundary, or none).
    surface: Vec<[u32; 3]>,
    /// Each particle split off by tearing → the one it was split from, for bodies with no
    /// surface to keep that record.
    torn_origin: &'a HashMap<Entity, Entity>,
    /// Tearing (checked here, applied after each step).
    tearable: Option<Tearable>,
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
    packed_springs: Vec<Entity>,
    packed_tets: Vec<Entity>,
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
    // The body as a core layout: the same `BodyLayout::build` the core driver's scenes go
    // through, so the plugin steps exactly the model `Scene::build` would make.
    let mut layout = BodyLayout {
        gravity: body
            .gravity
            .unwrap_or(Vec3::new(0.0, -9.81, 0.0))
            .to_array()
            .map(f64::from),
        drag: body.drag as f64,
        wind: wind.map(Into::into),
        material: fem.material,
        ..Default::default()
    };
    let (mut follow, mut fixed_pins) = (vec![], vec![]);
    for (i, &e) in ents.iter().enumerate() {
        let (p, pin, force) = particles.get(e).expect("checked above");
        let mut particle = LayoutParticle {
            position: p.position.to_array().map(f64::from),
            velocity: p.velocity.to_array().map(f64::from),
            mass: p.mass as f64,
            anchor: Anchor::Free,
        };
        if let Some(pin) = pin {
            match pin.target.map(|t| (t, targets.get(t))) {
                None => {
                    particle.anchor = Anchor::Pinned;
                    fixed_pins.push(i as u32);
                }
                Some((t, Ok(gt))) => {
                    let at = gt.transform_point(pin.offset);
                    particle.anchor = Anchor::Moving(Motion::Fixed { position: v3(at) });
                    particle.position = at.to_array().map(f64::from);
                    follow.push((i as u32, t, pin.offset, at));
                }
                Some((t, Err(_))) => {
                    warn!("particle {e}: pin target {t} has no GlobalTransform; pinned in place");
                    particle.anchor = Anchor::Pinned;
                    fixed_pins.push(i as u32);
                }
            }
        }
        layout.particles.push(particle);
        if let Some(f) = force {
            layout.forces.push((i, f.0.to_array().map(f64::from)));
        }
    }
    // The entity behind each packed spring and tet, to name it in errors.
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
                layout.springs.push(LayoutSpring {
                    a: a as usize,
                    b: b as usize,
                    rest_length: Some(s.rest_length as f64),
                    stiffness: s.stiffness as f64,
                    damping: s.damping as f64,
                    law: s.law,
                });
                packed_springs.push(se);
            }
            _ => warn!(
                "soft body {body_e}: spring {se} joins {} and {}, which are not both particles of this body; the spring is left out",
                s.a, s.b
            ),
        }
    }
    let mut packed_tets = Vec::with_capacity(fem.list.len());
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
        layout.tets.push(LayoutTet {
            vertices: v,
            rest: Some(t.rest.map(|p| p.as_dvec3())),
            material: t.material,
        });
        packed_tets.push(te);
    }
    if let Some(t) = fem.tearable
        && let Err((field, message)) = t.params().validate()
    {
        return Err(format!("soft body {body_e}: Tearable {field} {message}"));
    }
    layout.surface = fem.surface;
    if let Some((sc, triangles, torn_from)) = fem.self_collision {
        layout.self_collision = Some(sc.params());
        layout.surface = triangles;
        layout.torn_from = if torn_from.is_empty() {
            torn_origins(&ents, &index, fem.torn_origin)
        } else {
            torn_from
        };
    }
    let (mut model, state) = layout.build().map_err(|errs| {
        // The first problem, named by the entity behind the packed index.
        let e = &errs[0];
        let what = match e.item {
            LayoutItem::Particle(i) => format!("particle {}", ents[i]),
            LayoutItem::Spring(k) => format!("spring {}", packed_springs[k]),
            LayoutItem::Tet(k) => format!("tet {}", packed_tets[k]),
            LayoutItem::Force(k) => format!("particle {}", ents[layout.forces[k].0]),
            LayoutItem::Body => format!("soft body {body_e}"),
        };
        let field = match (e.item, e.field) {
            (LayoutItem::Tet(_), "material") if fem.material.is_none() => {
                return format!(
                    "{what}: no material (give the tet one, or the body an ElasticMaterial)"
                );
            }
            (LayoutItem::Force(_), _) => "external force",
            (LayoutItem::Body, "surface") => "SoftBodySurface",
            (LayoutItem::Body, "self_collision.thickness") => "SelfCollision thickness",
            (LayoutItem::Body, "self_collision.friction") => "SelfCollision friction",
            (_, "") => "",
            (_, f) => f,
        };
        let more = match errs.len() {
            1 => String::new(),
            n => format!(" (and {} more problems)", n - 1),
        };
        if field.is_empty() {
            format!("{what}: {}{more}", e.message)
        } else {
            format!("{what}: {field} {}{more}", e.message)
        }
    })?;
    model.hold_faces = body.hold_faces;
    let config = DriverConfig {
        integrator: body.integrator,
        policy: body.step,
        frame_dt,
        energy_guard: body.energy_guard.map(|g| g as f64),
        solver: fem.solver,
        auto: fem.auto,
        ..Default::default()
    };
    config
        .validate()
        .map_err(|e| format!("soft body {body_e}: {e}"))?;
    Ok(Built {
        sim: Simulation::new(model, state, config),
        packed_springs,
        packed_tets,
        particles: ents,
        index,
        follow,
        fixed_pins,
    })
}

#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub(crate) fn prepare(
    fixed: Res<Time<Fixed>>,
    (global_wind, global_fields, sleep, mut wakes): (
        Res<GlobalWind>,
        Res<GlobalForceFields>,
        Res<SoftBodySleep>,
        MessageReader<WakeSoftBody>,
    ),
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
            Option<&SoftBodyForceFields>,
            Option<Ref<SelfCollision>>,
            Option<Mut<SoftBodySurface>>,
            Option<Ref<Tearable>>,
            Has<SoftBodySleepingDisabled>,
            Option<Ref<AutoSettings>>,
            Option<Ref<crate::ecs::SoftBodyMeshSurface>>,
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
    (mut removed_winds, mut removed_self): (
        RemovedComponents<SoftBodyWind>,
        RemovedComponents<SelfCollision>,
    ),
    (mut invalid, mut commands): (MessageWriter<SoftBodyInvalid>, Commands),
) {
    let frame_dt = fixed.timestep().as_secs_f64();
    // Removals cannot be traced to their body once despawned: every body re-checks.
    let removed = removed_particles.read().count()
        + removed_springs.read().count()
        + removed_pins.read().count()
        + removed_forces.read().count()
        + removed_winds.read().count()
        + removed_self.read().count()
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
    let mut woken: Vec<Entity> = wakes.read().map(|w| w.0).collect();
    woken.sort_unstable();
    for (
        body_e,
        body,
        mut bs,
        mut status,
        plist,
        slist,
        wind,
        (
            tlist,
            material,
            solver,
            fields,
            self_collision,
            mut surface,
            tearable,
            no_sleep,
            auto_settings,
            mesh_surface,
        ),
    ) in &mut bodies
    {
        let plist = plist.map_or(no_list, |p| p.entities());
        // A body drawn with the game's own mesh: its triangles, on the particles, are the
        // surface (for colliders between the particles, and self-collision), unless the body
        // has a surface of its own.
        let mesh_surface = mesh_surface.filter(|_| surface.is_none());
        // Its triangles when the mesh surface changed (a tear), for the check below and the
        // rebuild.
        let mut mesh_tris = mesh_surface
            .as_ref()
            .filter(|m| m.is_changed())
            .map(|m| mesh_triangles(m, plist));
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
            || auto_settings.as_ref().is_some_and(|a| a.is_changed())
            || self_collision.as_ref().is_some_and(|c| c.is_changed())
            || tearable.as_ref().is_some_and(|t| t.is_changed())
            || surface.as_ref().is_some_and(|s| {
                // Its triangles are self-collision's, and colliders' between the particles.
                s.is_changed()
                    && (self_collision.is_some()
                        || bs
                            .sim
                            .as_ref()
                            .is_some_and(|sim| sim.system.contact_faces != s.triangles))
            })
            || mesh_tris.as_ref().is_some_and(|tris| {
                bs.sim
                    .as_ref()
                    .is_some_and(|sim| sim.system.contact_faces != *tris)
            })
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
            let mut teleported = false;
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
                        sim.state.x[i] = p.position.to_scalar();
                        sim.state.v[i] = p.velocity.to_scalar();
                        bs.written[i] = (p.position, p.velocity);
                        teleported = true;
                    } else {
                        warn!("particle {e}: non-finite position or velocity ignored (kept {wx})");
                    }
                }
            }
            if teleported {
                sim.wake();
            }
        }
        if dirty
            && let Some(surf) = surface.as_mut()
            && !surf.is_changed()
            && !bs.particles.is_empty()
            && bs.particles.as_slice() != plist
        {
            follow_removed_particles(body_e, &bs.particles, plist, surf, &mut commands);
        }
        if dirty {
            bs.diverged = None;
            bs.torn = false;
            bs.report = false;
            bs.frame_dt = frame_dt;
            bs.springs = slist.to_vec();
            bs.tets = tlist.to_vec();
            let wind = wind.map(|w| *w).or(global_wind.0);
            let (tris, from) = match (&surface, &mesh_surface) {
                (Some(s), _) => (s.triangles.clone(), s.torn_from.clone()),
                (None, Some(m)) => (
                    mesh_tris.take().unwrap_or_else(|| mesh_triangles(m, plist)),
                    vec![],
                ),
                (None, None) => (vec![], vec![]),
            };
            let fem = FemInput {
                list: tlist,
                tets: &tets,
                material: material.map(|m| m.0),
                solver: solver.map_or(SolverChoice::Auto, |s| s.0),
                auto: auto_settings.map_or(AutoConfig::default(), |a| a.0),
                self_collision: self_collision.map(|c| (*c, tris.clone(), from)),
                surface: tris,
                torn_origin: &bs.torn_origin,
                tearable: tearable.map(|t| *t),
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
                    bs.packed_springs = b.packed_springs;
                    bs.packed_tets = b.packed_tets;
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
        update_colliders(bs, &colliders, frame_dt);
        // Force fields: the body's, then everyone's (a list of shared handles, set every frame,
        // so edits need no rebuild).
        if let Some(sim) = bs.sim.as_mut() {
            let own = fields.map_or(&[][..], |f| &f.0[..]);
            if sim.system.fields.len() != own.len() + global_fields.0.len()
                || !sim
                    .system
                    .fields
                    .iter()
                    .zip(own.iter().chain(&global_fields.0))
                    .all(|(a, b)| std::sync::Arc::ptr_eq(a, b))
            {
                sim.system.fields = own.iter().chain(&global_fields.0).cloned().collect();
                sim.wake();
            }
            // Sleeping: the settings as they are now; a wake asked for by message.
            let want = if no_sleep { None } else { sleep.params() };
            if sim.sleep() != want {
                sim.set_sleep(want);
            }
            if woken.binary_search(&body_e).is_ok() {
                sim.wake();
            }
        }
    }
}

/// The triangles of a body drawn with the game's own mesh, on the body's particles (their
/// indices in `list`): each mesh vertex shows a particle, and vertices split along a UV seam
/// show the same one. A triangle with a vertex showing no particle of the body, or with two
/// corners on one particle, is left out.
fn mesh_triangles(mesh: &crate::ecs::SoftBodyMeshSurface, list: &[Entity]) -> Vec<[u32; 3]> {
    let index: HashMap<Entity, u32> = list
        .iter()
        .enumerate()
        .map(|(i, &e)| (e, i as u32))
        .collect();
    let particle = |v: u32| {
        mesh.vertices
            .get(v as usize)
            .and_then(|e| index.get(e))
            .copied()
    };
    mesh.triangles
        .iter()
        .filter_map(|t| {
            let [a, b, c] = t.map(particle);
            let t = [a?, b?, c?];
            (t[0] != t[1] && t[1] != t[2] && t[2] != t[0]).then_some(t)
        })
        .collect()
}

/// A body's particles were removed or reordered (a mouse grab's handle let go after a tear
/// appended particles behind it) while its surface was left as it was: the surface's
/// triangles and texture coordinates follow their particles to their new indices (triangles
/// with a particle gone are dropped), and the drawn mesh is made afresh.
fn follow_removed_particles(
    body_e: Entity,
    old: &[Entity],
    new: &[Entity],
    surf: &mut Mut<SoftBodySurface>,
    commands: &mut Commands,
) {
    let at: HashMap<Entity, u32> = new
        .iter()
        .enumerate()
        .map(|(i, e)| (*e, i as u32))
        .collect();
    let map: Vec<Option<u32>> = old.iter().map(|e| at.get(e).copied()).collect();
    if map.iter().enumerate().all(|(i, m)| *m == Some(i as u32)) {
        return; // only appended
    }
    let tris: Vec<[u32; 3]> = surf
        .triangles
        .iter()
        .filter_map(|t| {
            let m = t.map(|i| map.get(i as usize).copied().flatten());
            Some([m[0]?, m[1]?, m[2]?])
        })
        .collect();
    let uvs = (surf.uvs.len() == old.len()).then(|| {
        let mut uvs = vec![[0.0; 2]; new.len()];
        for (i, m) in map.iter().enumerate() {
            if let Some(j) = m {
                uvs[*j as usize] = surf.uvs[i];
            }
        }
        uvs
    });
    // Torn from a particle that is gone: its own.
    let torn_from = (surf.torn_from.len() == old.len()).then(|| {
        let mut from: Vec<u32> = (0..new.len() as u32).collect();
        for (i, m) in map.iter().enumerate() {
            let o = map.get(surf.torn_from[i] as usize).copied().flatten();
            if let (Some(j), Some(o)) = (m, o) {
                from[*j as usize] = o;
            }
        }
        from
    });
    let surf = &mut **surf;
    surf.triangles = tris;
    if let Some(uvs) = uvs {
        surf.uvs = uvs;
    }
    if let Some(from) = torn_from {
        surf.torn_from = from;
    }
    commands
        .entity(body_e)
        .remove::<crate::render::SurfaceVertices>();
}

/// The packed index (`index`) each packed particle (`ents`) was torn from: its own when not
/// torn, or when the one it was torn from is gone; from a body's record by entity; empty
/// when nothing was torn.
fn torn_origins(
    ents: &[Entity],
    index: &HashMap<Entity, u32>,
    origin: &HashMap<Entity, Entity>,
) -> Vec<u32> {
    if origin.is_empty() {
        return vec![];
    }
    ents.iter()
        .enumerate()
        .map(|(i, e)| {
            origin
                .get(e)
                .and_then(|o| index.get(o))
                .copied()
                .unwrap_or(i as u32)
        })
        .collect()
}
