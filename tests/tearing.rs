//! Tearing: springs break past their strain limit and the surface splits along the cut. The
//! strains are recomputed here from the positions and the rest lengths, apart from the code
//! that tears; the pieces are found by a union–find over the springs and the triangles.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

mod common;

use bevy_soft_body::core::build::{ClothParams, ClothPins, cloth};
use bevy_soft_body::core::fem::mesh::TetMesh;
use bevy_soft_body::core::scene::MotionDesc;
use bevy_soft_body::core::tear::{TearParams, tear_scene};
use bevy_soft_body::prelude::*;

const ROWS: usize = 4;
const COLS: usize = 25;
/// The column whose lengthwise springs (to the next column) are half as stiff: in series with
/// the others they take twice the strain, so the strip must tear there.
const WEAK: usize = 12;
const LIMIT: f64 = 0.3;

/// A 4 × 25 strip, 2.4 m long (10 cm cells), lying flat without gravity; its end columns are
/// pulled apart at 0.5 m/s each. Lengthwise springs from column 12 to 13 are half as stiff.
fn strip() -> (Scene, ClothParams) {
    let p = ClothParams {
        rows: ROWS,
        cols: COLS,
        width: 2.4,
        height: 0.3,
        mass: 0.01,
        k_structural: 200.0,
        k_shear: 80.0,
        k_flex: 2.0,
        damping: 0.05,
        drag: 0.0,
        pins: ClothPins::None,
        hanging: false,
        origin: [0.0, 1.0, 0.0],
    };
    let mut s = cloth(&p).unwrap();
    s.gravity = [0.0; 3];
    for sp in &mut s.springs {
        let (a, b) = (sp.a.min(sp.b), sp.a.max(sp.b));
        if a % COLS == WEAK && b == a + 1 {
            sp.stiffness *= 0.5;
        }
    }
    for i in 0..ROWS {
        for (j, vx) in [(0, -0.5), (COLS - 1, 0.5)] {
            let k = p.index_of(i, j);
            s.motions.push(MotionDesc {
                particle: k,
                motion: Motion::Linear {
                    start: s.particles[k].position,
                    velocity: [vx, 0.0, 0.0],
                    t0: 0.0,
                },
            });
        }
    }
    s.tearing = Some(TearParams { max_strain: LIMIT });
    (s, p)
}

/// The scene under symplectic Euler at step `h`, 1/60 s frames.
fn simulation(scene: &Scene, h: f64) -> Simulation<ParticleState, ParticleModel> {
    let (model, state) = scene.build().unwrap();
    Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: IntegratorKind::SymplecticEuler,
            policy: StepPolicy::Fixed { h },
            frame_dt: 1.0 / 60.0,
            ..Default::default()
        },
    )
}

fn strains(scene: &Scene, x: &[Vector]) -> Vec<f64> {
    (0..scene.springs.len())
        .map(|k| {
            let s = &scene.springs[k];
            let d = x[s.a] - x[s.b];
            (d.length() as f64) / scene.rest_length(k) - 1.0
        })
        .collect()
}

fn momentum(mass: &[f64], v: &[Vector]) -> [f64; 3] {
    let mut p = [0.0; 3];
    for (m, v) in mass.iter().zip(v) {
        for c in 0..3 {
            p[c] += m * v[c] as f64;
        }
    }
    p
}

/// Union–find roots of the particles joined by `links`.
fn pieces(n: usize, links: impl Iterator<Item = (usize, usize)>) -> Vec<usize> {
    let mut p: Vec<usize> = (0..n).collect();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    for (a, b) in links {
        let (ra, rb) = (root(&mut p, a), root(&mut p, b));
        p[ra.max(rb)] = ra.min(rb);
    }
    (0..n).map(|i| root(&mut p, i)).collect()
}

#[test]
fn a_strip_pulled_at_both_ends_tears_where_the_strain_first_exceeds_the_limit() {
    let (mut scene, p) = strip();
    // h·2√(k/m) = 1e-3 · 2√(200 / 0.01) = 0.28.
    let mut sim = simulation(&scene, 1e-3);
    let n0 = scene.particles.len();
    let mut first: Option<(u64, Vec<usize>)> = None;
    let mut separated_at = None;
    for _ in 0..240 {
        sim.advance_frame().unwrap();
        assert!(sim.state.is_finite(), "NaN at frame {}", sim.frame);
        let over: Vec<usize> = strains(&scene, &sim.state.x)
            .iter()
            .enumerate()
            .filter(|(_, s)| **s > LIMIT)
            .map(|(k, _)| k)
            .collect();
        let before = scene.clone();
        let mass_before: Vec<f64> = scene.particles.iter().map(|q| q.mass).collect();
        let p_before = momentum(&mass_before, &sim.state.v);
        let e_before = sim.system.elastic_energy(&sim.state.x) as f64;
        let torn = tear_scene(&mut scene, &mut sim).unwrap();
        assert_eq!(torn.over, over, "frame {}", sim.frame);
        if !over.is_empty() {
            // No energy made: a spring on the cut and its copy for the other side share the
            // edge's stiffness (each side keeps one of its two triangles), so a split keeps
            // the elastic energy and a broken spring takes its own away. (Giving the copy the
            // whole stiffness added 0.008 J of 3.65 J at the first tear.) The tolerance is
            // the f32 sum's round-off over the strip's springs.
            let e_after = sim.system.elastic_energy(&sim.state.x) as f64;
            let tol = 1e-5 * e_before;
            if torn.broken.is_empty() {
                assert!(
                    (e_after - e_before).abs() <= tol,
                    "frame {}: elastic energy {e_before} → {e_after} across a split",
                    sim.frame
                );
            } else {
                assert!(
                    e_after <= e_before + tol,
                    "frame {}: elastic energy {e_before} → {e_after} across a tear",
                    sim.frame
                );
            }
            // Momentum kept: the copies share their originals' mass and velocity.
            let mass: Vec<f64> = scene.particles.iter().map(|q| q.mass).collect();
            let p_after = momentum(&mass, &sim.state.v);
            for c in 0..3 {
                assert!(
                    (p_after[c] - p_before[c]).abs() <= 1e-6 * (1.0 + p_before[c].abs()),
                    "momentum {p_before:?} → {p_after:?}"
                );
            }
            if first.is_none() {
                // The first springs to go are the weak column's lengthwise ones.
                for &k in &over {
                    let s = &before.springs[k];
                    let (a, b) = (s.a.min(s.b), s.a.max(s.b));
                    assert!(
                        a % COLS == WEAK && b == a + 1,
                        "spring {k} ({a}–{b}) broke first, not one of the weak column's"
                    );
                }
                first = Some((sim.frame, over.clone()));
            }
        }
        // Separated: the ends' particles in different pieces, by springs and by triangles.
        let n = scene.particles.len();
        let by_springs = pieces(n, scene.springs.iter().map(|s| (s.a, s.b)));
        let tris = &scene.surface.as_ref().unwrap().triangles;
        let by_tris = pieces(
            n,
            tris.iter()
                .flat_map(|t| [(t[0], t[1]), (t[1], t[2])])
                .map(|(a, b)| (a as usize, b as usize)),
        );
        let (l, r) = (p.index_of(0, 0), p.index_of(0, COLS - 1));
        if by_tris[l] != by_tris[r] && separated_at.is_none() {
            separated_at = Some(sim.frame);
            // The surface tore along one column: one new vertex per row it crossed.
            assert_eq!(n - n0, ROWS, "particles {n0} → {n}");
            assert_eq!(scene.surface.as_ref().unwrap().uvs.len(), n);
        }
        if by_springs[l] != by_springs[r] {
            break;
        }
    }
    let (frame, over) = first.expect("the strip never tore");
    let cut_frame = separated_at.expect("the surface never came apart");
    println!(
        "first break at frame {frame} ({} springs), surface apart at frame {cut_frame}, springs apart at frame {}; {} particles (was {n0})",
        over.len(),
        sim.frame,
        scene.particles.len()
    );
    // The body goes on: the two halves fly apart with their pulled ends.
    for _ in 0..60 {
        sim.advance_frame().unwrap();
        tear_scene(&mut scene, &mut sim).unwrap();
        assert!(sim.state.is_finite());
    }
    let n = scene.particles.len();
    let by_springs = pieces(n, scene.springs.iter().map(|s| (s.a, s.b)));
    assert_ne!(
        by_springs[p.index_of(0, 0)],
        by_springs[p.index_of(0, COLS - 1)]
    );
}

#[test]
fn a_tearing_limit_that_is_not_positive_names_the_field() {
    for bad in [0.0, -0.5, f64::NAN, f64::INFINITY] {
        let (mut scene, _) = strip();
        scene.tearing = Some(TearParams { max_strain: bad });
        let err = scene.build().unwrap_err();
        assert!(
            err.errors.iter().any(|e| e.path == "tearing.max_strain"),
            "{bad}: {err:?}"
        );
    }
    // And from a file: the key is `tearing`.
    let (scene, _) = strip();
    let json = serde_json::to_string(&scene).unwrap();
    assert!(json.contains("\"tearing\":{\"max_strain\":0.3}"));
    let bad = json.replace("\"max_strain\":0.3", "\"max_strain\":-1.0");
    let parsed: Scene = serde_json::from_str(&bad).unwrap();
    assert!(parsed.build().is_err());
}

/// A bar of tets, 1.2 m × 0.1 m × 0.1 m in 12 cubes of six tets, lying without gravity; its
/// end faces are pulled apart at 0.5 m/s each. The tets of the seventh cube (x from 0.6 to
/// 0.7 m) have a quarter of the Young's modulus: in series with the rest they take about four
/// times the strain, so the bar must break there — and the rest, released at a quarter of the
/// limit, rings below it (a released bar's strain waves at most double).
fn bar() -> Scene {
    let mesh = TetMesh::tet_box([1.2, 0.1, 0.1], [BAR_CELLS, 1, 1]).unwrap();
    let material = NeoHookean {
        young: 1e5,
        poisson: 0.3,
        density: 1000.0,
    };
    let mut s = mesh.to_scene("bar", material);
    s.gravity = [0.0; 3];
    for t in &mut s.tets {
        if weak_tet(&t.vertices.map(|i| s.particles[i].position)) {
            t.material = Some(NeoHookean {
                young: 0.25 * material.young,
                ..material
            });
        }
    }
    for (k, p) in s.particles.iter().enumerate() {
        let x = p.position[0];
        if x == 0.0 || x == 1.2 {
            s.motions.push(MotionDesc {
                particle: k,
                motion: Motion::Linear {
                    start: p.position,
                    velocity: [if x == 0.0 { -0.5 } else { 0.5 }, 0.0, 0.0],
                    t0: 0.0,
                },
            });
        }
    }
    s.tearing = Some(TearParams { max_strain: LIMIT });
    s
}

const BAR_CELLS: usize = 12;

/// True for a tet (rest corners) of the weak cube.
fn weak_tet(corners: &[[f64; 3]; 4]) -> bool {
    let cx = corners.iter().map(|c| c[0]).sum::<f64>() / 4.0;
    (0.6..0.7).contains(&cx)
}

/// The largest principal stretch minus one of each tet, from its rest corners and the
/// positions, by power iteration on `FᵀF` (apart from the closed form the code uses).
fn tet_strains(scene: &Scene, x: &[Vector]) -> Vec<f64> {
    use glam::{DMat3, DVec3};
    (0..scene.tets.len())
        .map(|k| {
            let t = &scene.tets[k];
            let rest = t
                .rest
                .unwrap_or_else(|| t.vertices.map(|i| scene.particles[i].position))
                .map(DVec3::from_array);
            let p = t
                .vertices
                .map(|i| DVec3::new(x[i][0] as f64, x[i][1] as f64, x[i][2] as f64));
            let dm = DMat3::from_cols(rest[1] - rest[0], rest[2] - rest[0], rest[3] - rest[0]);
            let ds = DMat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0]);
            let f = ds * dm.inverse();
            let c = f.transpose() * f;
            let mut v = DVec3::new(1.0, 0.7, 0.3).normalize();
            let mut lambda = 0.0;
            for _ in 0..500 {
                let w = c * v;
                lambda = w.length();
                v = w / lambda;
            }
            lambda.sqrt() - 1.0
        })
        .collect()
}

#[test]
fn a_bar_of_tets_pulled_at_both_ends_breaks_at_its_weak_section() {
    let mut scene = bar();
    // h ω = 2e-4 · 363 = 0.07, a 27th of symplectic Euler's bound 2/ω (ω = 363 rad/s from
    // `auto::spectrum` on the uniform bar; the soft cube only lowers it, and a split's
    // quarter-mass copy at most doubles it): the strain waves a tear sets off are resolved.
    let mut sim = simulation(&scene, 2e-4);
    let n0 = scene.particles.len();
    let faces0 = scene.surface.as_ref().unwrap().triangles.len();
    let (left, right) = (0, n0 - 1);
    let mut first = None;
    let mut apart = None;
    let mut removed = 0;
    for _ in 0..120 {
        sim.advance_frame().unwrap();
        assert!(sim.state.is_finite(), "NaN at frame {}", sim.frame);
        let strains = tet_strains(&scene, &sim.state.x);
        let before = scene.clone();
        let mass_before: Vec<f64> = scene.particles.iter().map(|q| q.mass).collect();
        let p_before = momentum(&mass_before, &sim.state.v);
        let e_before = sim.system.elastic_energy(&sim.state.x) as f64;
        let torn = tear_scene(&mut scene, &mut sim).unwrap();
        // The same tets past the limit as the independent strains say (those within round-off
        // of it either way).
        for (k, &e) in strains.iter().enumerate() {
            if (e - LIMIT).abs() > 1e-9 {
                assert_eq!(
                    torn.tets_over.contains(&k),
                    e > LIMIT,
                    "frame {}: tet {k} at strain {e}",
                    sim.frame
                );
            }
        }
        if torn.tets_over.is_empty() {
            continue;
        }
        // A split changes no tet's shape (copies start where their originals are) and keeps
        // momentum (copies take their share of the mass at the same velocity).
        let mass: Vec<f64> = scene.particles.iter().map(|q| q.mass).collect();
        let p_after = momentum(&mass, &sim.state.v);
        for c in 0..3 {
            assert!(
                (p_after[c] - p_before[c]).abs() <= 1e-9 * (1.0 + p_before[c].abs()),
                "momentum {p_before:?} → {p_after:?}"
            );
        }
        let e_after = sim.system.elastic_energy(&sim.state.x) as f64;
        // A tet removed takes its (non-negative) energy with it.
        if torn.tets_removed.is_empty() {
            assert!(
                (e_after - e_before).abs() <= 1e-6 * e_before,
                "elastic energy {e_before} → {e_after} across a tear"
            );
        } else {
            assert!(e_after <= e_before * (1.0 + 1e-6), "{e_before} → {e_after}");
        }
        // Only the weak cube's tets ever break: first, as the bar is pulled, and after, as
        // the soft cube rings at the end of its piece.
        for &k in &torn.tets_over {
            let t = &before.tets[k];
            let rest = t
                .rest
                .unwrap_or_else(|| t.vertices.map(|i| before.particles[i].position));
            assert!(
                weak_tet(&rest),
                "frame {}: tet {k} broke outside the weak cube",
                sim.frame
            );
        }
        removed += torn.tets_removed.len();
        first.get_or_insert((sim.frame, torn.tets_over.len()));
        // The drawn surface is the boundary of the tets left.
        let tets: Vec<[u32; 4]> = scene
            .tets
            .iter()
            .map(|t| t.vertices.map(|i| i as u32))
            .collect();
        assert!(bevy_soft_body::core::tear::is_boundary_of(
            &scene.surface.as_ref().unwrap().triangles,
            &tets
        ));
        // Apart: the ends in different pieces of tets.
        let n = scene.particles.len();
        let by_tets = pieces(
            n,
            scene.tets.iter().flat_map(|t| {
                let v = t.vertices;
                [(v[0], v[1]), (v[0], v[2]), (v[0], v[3])]
            }),
        );
        if apart.is_none() && by_tets[left] != by_tets[right] {
            apart = Some((
                sim.frame,
                n - n0,
                scene.surface.as_ref().unwrap().triangles.len(),
            ));
        }
    }
    let (frame, count) = first.expect("the bar never tore");
    let (at, added, faces) = apart.expect("the bar never came apart");
    println!(
        "first break at frame {frame} ({count} tets), apart at frame {at}: {added} particles added, {faces0} → {faces} surface triangles; by frame {}: {} particles, {} tets removed",
        sim.frame,
        scene.particles.len(),
        removed
    );
    // A crack across the bar in one plane of corners: each of the section's 2 × 2 corners
    // split once, and the section's two triangles exposed on each side.
    assert_eq!((added, faces), (4, faces0 + 4));
    // The two pieces fly apart with their pulled ends and stay whole.
    for _ in 0..60 {
        sim.advance_frame().unwrap();
        tear_scene(&mut scene, &mut sim).unwrap();
        assert!(sim.state.is_finite());
    }
}

#[cfg(feature = "plugin")]
mod plugin {
    use super::*;
    use bevy::prelude::*;
    use bevy_soft_body::ecs::BodySim;
    use common::spawn;

    /// A headless app at 1/64 s frames with `scene` (a bar) as one body, stepped by
    /// symplectic Euler at the core test's step.
    fn bar_app(scene: &Scene) -> (App, Entity) {
        let mut app = common::headless_app(1.0 / 64.0);
        let body = spawn(
            &mut app,
            scene,
            SoftBody {
                integrator: IntegratorKind::SymplecticEuler,
                step: StepPolicy::Fixed { h: 2e-4 },
                ..Default::default()
            },
        );
        (app, body)
    }

    /// The bar of tets as one body in a headless app: it breaks at its weak cube, the tets
    /// that broke are named (split off at a corner, or despawned), the drawn surface is the
    /// boundary of the tets left, the two ends end up in separate pieces, and the body goes on.
    #[test]
    fn a_tearable_body_of_tets_breaks_in_the_plugin() {
        use bevy_soft_body::core::tear::is_boundary_of;
        let scene = bar();
        let (mut app, body) = bar_app(&scene);
        let n0 = scene.particles.len();
        let mut torn: Vec<SoftBodyTorn> = vec![];
        // 40 frames, and on until one that does not tear (a torn body's model is rebuilt at
        // its next step).
        for frame in 0..80 {
            app.update();
            let msgs = app.world().resource::<Messages<SoftBodyTorn>>();
            let now: Vec<SoftBodyTorn> = msgs.iter_current_update_messages().cloned().collect();
            let world = app.world();
            for p in world.get::<BodyParticles>(body).unwrap().iter() {
                let p = world.get::<Particle>(p).unwrap();
                assert!(p.position.is_finite() && p.velocity.is_finite());
            }
            if frame >= 40 && now.is_empty() {
                break;
            }
            torn.extend(now);
        }
        let world = app.world();
        assert!(!torn.is_empty(), "never tore");
        // The first tets to break are the weak cube's (by their rest corners).
        for &te in &torn[0].tets {
            let t = world
                .get::<Tet>(te)
                .expect("the first tear split, not removed");
            assert!(weak_tet(&t.rest.map(|p| p.as_dvec3().to_array())));
        }
        let bs = world.get::<BodySim>(body).unwrap();
        let sim = bs.simulation().unwrap();
        let particles = world.get::<BodyParticles>(body).unwrap().len();
        assert_eq!(sim.state.x.len(), particles);
        assert!(particles > n0);
        assert_eq!(
            sim.system.tets.len(),
            world.get::<BodyTets>(body).unwrap().len()
        );
        let corners: Vec<[u32; 4]> = sim.system.tets.as_slice().iter().map(|t| t.v).collect();
        let surf = world.get::<SoftBodySurface>(body).unwrap();
        assert!(is_boundary_of(&surf.triangles, &corners));
        let by_tets = pieces(
            particles,
            corners.iter().flat_map(|v| {
                [(v[0], v[1]), (v[0], v[2]), (v[0], v[3])].map(|(a, b)| (a as usize, b as usize))
            }),
        );
        assert_ne!(by_tets[0], by_tets[n0 - 1], "the ends are still joined");
        let status = world.get::<SoftBodyStatus>(body).unwrap();
        assert_eq!(status.state, BodyState::Running);
        println!(
            "plugin: {} tears, {} tets past the limit, {} particles added",
            torn.len(),
            torn.iter().map(|t| t.tets.len()).sum::<usize>(),
            particles - n0
        );
    }

    /// The bar of tets with `SelfCollision` and no `SoftBodySurface` (self-collision then takes
    /// the tets' boundary): the body keeps its own record of which particle each copy was
    /// split from, so the rebuilt contact surface knows the crack's two sides apart (its
    /// broad phase never takes them for one flat patch). Checked against the record rebuilt
    /// independently from the `SoftBodyTorn` messages (each copy's parent, chains followed).
    #[test]
    fn a_torn_body_of_tets_without_a_surface_keeps_its_split_record() {
        use bevy::platform::collections::HashMap;
        let mut scene = bar();
        scene.surface = None;
        // Thickness: a tenth of the bar's 0.1 m cube edges, under the half-edge limit.
        scene.self_collision = Some(SelfContactParams {
            thickness: 0.01,
            friction: 0.0,
        });
        let (mut app, body) = bar_app(&scene);
        assert!(app.world().get::<SoftBodySurface>(body).is_none());
        assert!(app.world().get::<SelfCollision>(body).is_some());
        let mut root: HashMap<Entity, Entity> = HashMap::default();
        let mut checked = 0;
        for frame in 0..80 {
            app.update();
            let msgs = app.world().resource::<Messages<SoftBodyTorn>>();
            let now: Vec<SoftBodyTorn> = msgs.iter_current_update_messages().cloned().collect();
            for t in &now {
                for &(parent, copy) in &t.split {
                    let r = root.get(&parent).copied().unwrap_or(parent);
                    root.insert(copy, r);
                }
            }
            let world = app.world();
            let bs = world.get::<BodySim>(body).unwrap();
            // The record is read at the rebuild after a tear: compare once the model has the
            // components' particles.
            let list: Vec<Entity> = world.get::<BodyParticles>(body).unwrap().iter().collect();
            let sim = bs.simulation().unwrap();
            if sim.state.x.len() == list.len() && !root.is_empty() {
                let index: HashMap<Entity, u32> = list
                    .iter()
                    .enumerate()
                    .map(|(i, &p)| (p, i as u32))
                    .collect();
                let expect: Vec<u32> = list
                    .iter()
                    .map(|p| index[root.get(p).unwrap_or(p)])
                    .collect();
                let surf = &sim.system.self_contact.as_ref().unwrap().surface;
                assert!(surf.is_torn());
                // The surface's record runs to its highest vertex (a copy inside the body,
                // on no boundary face, may lie past it).
                let o = surf.origins();
                assert_eq!(o, &expect[..o.len()], "frame {frame}");
                checked += 1;
            }
            if frame >= 40 && now.is_empty() && checked > 0 {
                break;
            }
        }
        assert!(checked > 0, "never tore");
        println!(
            "split record checked in {checked} frames, {} copies",
            root.len()
        );
    }

    /// The strip as one body in a headless app at 1/64 s frames: it tears where the core's
    /// strip tears, the components follow (particles added, broken springs despawned, the
    /// surface renumbered), a `SoftBodyTorn` names what broke, and the body goes on.
    #[test]
    fn a_tearable_body_tears_in_the_plugin() {
        let (scene, _) = strip();
        let mut app = common::headless_app(1.0 / 64.0);
        let body = spawn(
            &mut app,
            &scene,
            SoftBody {
                integrator: IntegratorKind::SymplecticEuler,
                step: StepPolicy::Fixed { h: 1e-3 },
                ..Default::default()
            },
        );
        assert_eq!(
            app.world().get::<Tearable>(body).map(|t| t.max_strain),
            Some(LIMIT as f32)
        );
        let n0 = scene.particles.len();
        let springs0 = scene.springs.len();
        let mut torn: Vec<SoftBodyTorn> = vec![];
        for _ in 0..240 {
            app.update();
            let msgs = app.world().resource::<Messages<SoftBodyTorn>>();
            torn.extend(msgs.iter_current_update_messages().cloned());
            let world = app.world();
            for p in world.get::<BodyParticles>(body).unwrap().iter() {
                let p = world.get::<Particle>(p).unwrap();
                assert!(p.position.is_finite() && p.velocity.is_finite());
            }
        }
        let world = app.world();
        assert!(!torn.is_empty(), "never tore");
        let first = &torn[0];
        assert_eq!(first.body, body);
        // The first tear splits particles (a surface edge past the limit) or removes springs
        // (whose entities are then gone).
        assert!(!first.springs.is_empty() || !first.split.is_empty());
        for e in &first.springs {
            assert!(
                world.get_entity(*e).is_err(),
                "broken spring {e} still there"
            );
        }
        let split: usize = torn.iter().map(|t| t.split.len()).sum();
        let particles = world.get::<BodyParticles>(body).unwrap().len();
        assert_eq!(split, ROWS, "one new particle per row the cut crossed");
        assert_eq!(particles, n0 + ROWS);
        let broken: usize = torn.iter().map(|t| t.springs.len()).sum();
        // Springs: the original ones less the broken, plus the split-off sides' own springs
        // along edges on the cut; the model has exactly the body's spring entities.
        let now = world.get::<BodySprings>(body).unwrap().len();
        assert!(
            now >= springs0 - broken,
            "{now} springs, {springs0} − {broken} broken"
        );
        let model_springs = world
            .get::<BodySim>(body)
            .unwrap()
            .simulation()
            .unwrap()
            .system
            .springs
            .len();
        assert_eq!(model_springs, now);
        let surf = world.get::<SoftBodySurface>(body).unwrap();
        assert!(
            surf.triangles
                .iter()
                .flatten()
                .all(|&i| (i as usize) < particles)
        );
        assert_eq!(surf.uvs.len(), particles);
        let bs = world.get::<BodySim>(body).unwrap();
        assert_eq!(bs.simulation().unwrap().state.x.len(), particles);
        let status = world.get::<SoftBodyStatus>(body).unwrap();
        assert_eq!(status.state, BodyState::Running);
        println!(
            "plugin: {} tears, {broken} springs broken, {split} particles split",
            torn.len()
        );
    }

    /// What the panel's mouse grab does (a handle particle pinned to an anchor the cursor
    /// moves, joined to the grabbed particle by a zero-length spring), here without a
    /// window: a hanging 12² cloth pinned along its top, grabbed at its bottom middle and
    /// pulled down and away. The cloth tears near the grab; letting go (the handle, its
    /// spring and the anchor despawned, so the particles after the handle move down one
    /// index) leaves a surface whose triangles and texture coordinates follow the particles,
    /// and the body goes on.
    #[test]
    fn a_mouse_grab_pulling_hard_tears_the_cloth_and_letting_go_keeps_the_surface() {
        let p = ClothParams {
            rows: 12,
            cols: 12,
            width: 0.6,
            height: 0.6,
            mass: 0.002,
            k_structural: 100.0,
            k_shear: 40.0,
            k_flex: 1.0,
            damping: 0.02,
            drag: 0.0,
            pins: ClothPins::TopEdge,
            hanging: true,
            origin: [0.0, 1.0, 0.0],
        };
        let mut scene = cloth(&p).unwrap();
        scene.tearing = Some(TearParams { max_strain: 0.4 });
        let mut app = common::headless_app(1.0 / 64.0);
        let body = spawn(
            &mut app,
            &scene,
            SoftBody {
                integrator: IntegratorKind::SymplecticEuler,
                step: StepPolicy::Fixed { h: 1e-3 },
                ..Default::default()
            },
        );
        app.update();
        let grabbed = app
            .world()
            .get::<BodyParticles>(body)
            .unwrap()
            .iter()
            .nth(p.index_of(11, 6))
            .unwrap();
        let at = app.world().get::<Particle>(grabbed).unwrap().position;
        let world = app.world_mut();
        let anchor = world
            .spawn((
                Transform::from_translation(at),
                GlobalTransform::from_translation(at),
            ))
            .id();
        let handle = world
            .spawn((
                Particle::at(at, 1.0),
                ParticleOf(body),
                Pinned::to(anchor, Vec3::ZERO),
            ))
            .id();
        let spring = world
            .spawn((
                Spring {
                    a: grabbed,
                    b: handle,
                    rest_length: 0.0,
                    stiffness: 50.0,
                    damping: 0.0,
                    law: Default::default(),
                },
                SpringOf(body),
            ))
            .id();
        // Pull down and towards the camera at 2 m/s for 0.5 s.
        let mut split = 0;
        for k in 1..=32 {
            let to = at + Vec3::new(0.0, -1.0, 1.0).normalize() * (2.0 * k as f32 / 64.0);
            let world = app.world_mut();
            *world.get_mut::<Transform>(anchor).unwrap() = Transform::from_translation(to);
            *world.get_mut::<GlobalTransform>(anchor).unwrap() =
                GlobalTransform::from_translation(to);
            app.update();
            let msgs = app.world().resource::<Messages<SoftBodyTorn>>();
            split += msgs
                .iter_current_update_messages()
                .map(|t| t.split.len())
                .sum::<usize>();
        }
        assert!(split > 0, "pulling hard did not tear the cloth");
        // Let go.
        for e in [spring, handle, anchor] {
            app.world_mut().entity_mut(e).despawn();
        }
        for _ in 0..30 {
            app.update();
        }
        let world = app.world();
        let particles: Vec<Entity> = world.get::<BodyParticles>(body).unwrap().iter().collect();
        assert_eq!(
            particles.len(),
            144 + split,
            "the handle is gone, the copies stay"
        );
        let surf = world.get::<SoftBodySurface>(body).unwrap();
        assert_eq!(surf.uvs.len(), particles.len());
        // The triangles name the right particles after the renumbering, and every drawn edge
        // is held by a spring: none longer than twice the longest rest edge (0.6 m / 11 · √2
        // = 7.7 cm; a spring tears at 1.4 times its rest length, and may overshoot that
        // within a frame). Before the split-off side got its own springs along the cut's
        // edges, an unheld edge there stretched to 1.35 m.
        assert!(
            surf.triangles
                .iter()
                .flatten()
                .all(|&i| (i as usize) < particles.len())
        );
        let bs = world.get::<BodySim>(body).unwrap();
        let x = &bs.simulation().unwrap().state.x;
        assert_eq!(x.len(), particles.len());
        let longest = surf
            .triangles
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .map(|(a, b)| (x[a as usize] - x[b as usize]).length() as f64)
            .fold(0.0, f64::max);
        assert!(
            longest < 2.0 * 0.6 / 11.0 * 2f64.sqrt(),
            "longest edge {longest} m"
        );
        assert!(x.iter().all(|p| p.is_finite()));
        assert_eq!(
            world.get::<SoftBodyStatus>(body).unwrap().state,
            BodyState::Running
        );
        println!(
            "grab: {split} particles split; longest drawn edge after letting go {longest:.3} m (rest ≤ 0.077 m)"
        );
    }

    #[test]
    fn a_bad_tearing_limit_names_the_body() {
        let (scene, _) = strip();
        let mut app = common::headless_app(1.0 / 64.0);
        let body = spawn(&mut app, &scene, SoftBody::default());
        app.world_mut()
            .entity_mut(body)
            .insert(Tearable { max_strain: 0.0 });
        app.update();
        let status = app.world().get::<SoftBodyStatus>(body).unwrap();
        let BodyState::Invalid(msg) = &status.state else {
            panic!("not refused: {:?}", status.state);
        };
        assert!(
            msg.contains(&format!("{body}")) && msg.contains("Tearable max_strain"),
            "{msg}"
        );
    }
}
