//! Sleeping: a body at rest stops stepping, and wakes on everything that can move it. The rule
//! is the core driver's (`Simulation::set_sleep`); the plugin adds the wake causes of a game
//! world. Work is counted in substeps (speed itself lives in the benchmarks).

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

mod common;

use bevy_soft_body::core::build::{ClothParams, ClothPins, cloth};
use bevy_soft_body::prelude::*;

/// A 10×10 flag, 0.5 m square, hanging from its top edge: 5 g per particle, 50 N/m, drag
/// 0.05 N·s/m per particle (a 0.1 s time constant, so it comes to rest within a second or two).
fn flag(origin: [f64; 3]) -> Scene {
    cloth(&ClothParams {
        rows: 10,
        cols: 10,
        width: 0.5,
        height: 0.5,
        mass: 0.005,
        k_structural: 50.0,
        k_shear: 20.0,
        k_flex: 2.0,
        damping: 0.02,
        drag: 0.05,
        pins: ClothPins::TopEdge,
        hanging: true,
        origin,
    })
    .unwrap()
}

/// Symplectic Euler at 1/1024 s: h·2√(k/m) = 2√(50/0.005)/1024 = 0.2, well inside its bound 2.
const H: f64 = 1.0 / 1024.0;
/// 1/64 s frames: exactly representable, so the plugin and the core driver agree.
const FRAME: f64 = 1.0 / 64.0;

fn config() -> DriverConfig {
    DriverConfig {
        integrator: IntegratorKind::SymplecticEuler,
        policy: StepPolicy::Fixed { h: H },
        frame_dt: FRAME,
        ..Default::default()
    }
}

/// The flag with its numbers rounded to `f32` (what the plugin's components hold), so the core
/// and the plugin start from the same values in either precision.
fn core_flag() -> Simulation<ParticleState, ParticleModel> {
    let mut scene = flag([0.0, 1.0, 0.0]);
    common::f32_exact(&mut scene);
    let (model, state) = scene.build().unwrap();
    Simulation::new(model, state, config())
}

/// The fastest free particle's speed over a frame `frame` long that took it from `before` to
/// where it is: the farthest one went, over the frame's length.
fn frame_speed(
    sim: &Simulation<ParticleState, ParticleModel>,
    before: &[Vector],
    frame: f64,
) -> f64 {
    sim.state
        .x
        .iter()
        .zip(before)
        .zip(sim.system.inv_mass())
        .filter(|(_, w)| **w > 0.0)
        .map(|((a, b), _)| (*a - *b).length() as f64)
        .fold(0.0, f64::max)
        / frame
}

/// The fastest free particle's velocity at the frame's end.
fn end_speed(sim: &Simulation<ParticleState, ParticleModel>) -> f64 {
    sim.state
        .v
        .iter()
        .zip(sim.system.inv_mass())
        .filter(|(_, w)| **w > 0.0)
        .map(|(v, _)| v.length() as f64)
        .fold(0.0, f64::max)
}

#[test]
fn a_flag_at_rest_sleeps_after_the_sleep_time_and_its_frames_cost_nothing() {
    let p = SleepParams::default();
    let mut sim = core_flag();
    sim.set_sleep(Some(p));
    // The frame at which it falls asleep, and how long its speed had been below the
    // threshold then (measured here, apart from the driver's timer).
    let (mut below, mut slept_at) = (0u32, None);
    for f in 0..400 {
        let before = sim.state.x.clone();
        let rep = sim.advance_frame().unwrap();
        assert!(rep.substeps > 0, "frame {f} stepped no substep while awake");
        below = if frame_speed(&sim, &before, FRAME) < p.speed {
            below + 1
        } else {
            0
        };
        if sim.is_asleep() {
            slept_at = Some(f);
            break;
        }
    }
    let f = slept_at.expect("the flag never fell asleep");
    // Half a second is 32 frames of 1/64 s: exactly that many still frames.
    assert_eq!(below, 32, "asleep after {below} still frames (frame {f})");
    println!("flag asleep at frame {f} ({:.2} s)", (f + 1) as f64 * FRAME);
    // Asleep: no substep, the state bit for bit the same, the clock going on.
    let (x, v, t) = (sim.state.x.clone(), sim.state.v.clone(), sim.time);
    for k in 1..=64 {
        let rep = sim.advance_frame().unwrap();
        assert_eq!(rep.substeps, 0);
        assert!(sim.is_asleep());
        assert_eq!(sim.state.x, x);
        assert_eq!(sim.state.v, v);
        assert!((sim.time as f64 - (t as f64 + k as f64 * FRAME)).abs() < 1e-4);
    }
    // Woken with nothing changed, it goes on from where it lay: no pop (it moves less per
    // frame than the sleep speed allows, 0.01 m/s × 1/64 s = 0.16 mm).
    sim.wake();
    sim.advance_frame().unwrap();
    assert!(!sim.is_asleep());
    let moved = sim
        .state
        .x
        .iter()
        .zip(&x)
        .map(|(a, b)| (*a - *b).length() as f64)
        .fold(0.0, f64::max);
    assert!(moved < p.speed * FRAME, "moved {moved} m on waking");
    // Without sleep settings, never.
    let mut awake = core_flag();
    for _ in 0..200 {
        assert!(awake.advance_frame().unwrap().substeps > 0);
    }
    assert!(!awake.is_asleep());
}

#[test]
fn a_coarse_cloth_held_up_by_a_ball_between_its_particles_sleeps() {
    // The pile's 12² cloth (11 cm cells) dropped onto a 7 cm ball on the ground: the ball
    // meets it inside its triangles and holds it up as a tent. Each step the tension pulls the
    // tent onto the ball and the contact's impulse stops the point of contact; the triangle's
    // corners share that impulse by their weights, so the corners pulled hardest end every
    // step with a step's acceleration (h·a, here 4 cm/s) while they stay where they
    // are. The sleep speed is read from how far the particles go in a frame, so it sleeps;
    // by the particles' velocities at the frames' ends it never would.
    let r = 0.07;
    let mut sim = common::tent(r, FRAME);
    let sp = SleepParams::default();
    sim.set_sleep(Some(sp));
    // Per frame: the speed over the frame (positions) and the fastest end velocity.
    let mut frames: Vec<(f64, f64)> = vec![];
    for _ in 0..(10.0 / FRAME) as usize {
        let before = sim.state.x.clone();
        sim.advance_frame().unwrap();
        frames.push((frame_speed(&sim, &before, FRAME), end_speed(&sim)));
        if sim.is_asleep() {
            break;
        }
    }
    assert!(sim.is_asleep(), "never slept in 10 s");
    let still = (sp.time / FRAME).round() as usize;
    let last = &frames[frames.len() - still..];
    println!(
        "asleep after {:.2} s; over its last {still} frames: frame speeds up to {:.4} m/s, end velocities {:.4} to {:.4} m/s",
        frames.len() as f64 * FRAME,
        last.iter().map(|f| f.0).fold(0.0, f64::max),
        last.iter().map(|f| f.1).fold(f64::INFINITY, f64::min),
        last.iter().map(|f| f.1).fold(0.0, f64::max)
    );
    // Still by its frames (measured here, apart from the driver) for exactly the sleep time,
    // with end velocities that never fell below the sleep speed.
    assert!(last.iter().all(|f| f.0 < sp.speed));
    assert!(frames[frames.len() - still - 1].0 >= sp.speed);
    assert!(last.iter().all(|f| f.1 > 2.0 * sp.speed), "{last:?}");
    // A tent: its highest particle above the ball's top (the ball rests on the ground).
    let top = sim
        .state
        .x
        .iter()
        .map(|x| x.y as f64)
        .fold(f64::MIN, f64::max);
    assert!(
        top > 2.0 * r,
        "the cloth's top at {top} m, the ball's at {}",
        2.0 * r
    );
}

#[test]
fn what_keeps_moving_it_keeps_it_awake() {
    // Each of these makes the forces unsteady: the flag never sleeps, though each drive is
    // gentle. A gusting breeze; one corner on a slow circle; a ball collider swinging far
    // from the flag (in the core every collider of the model counts); a blast still to come.
    let mut cases: Vec<(&str, Scene)> = vec![];
    let mut s = flag([0.0, 1.0, 0.0]);
    s.wind = Some(Wind {
        velocity: [0.0; 3],
        gust: 0.05,
        ..Default::default()
    });
    cases.push(("gusting wind", s));
    let mut s = flag([0.0, 1.0, 0.0]);
    s.motions.push(bevy_soft_body::core::scene::MotionDesc {
        particle: 0,
        motion: Motion::Circle {
            center: [-0.25, 1.0, 0.0],
            radius: 0.001,
            omega: 1.0,
            phase: 0.0,
            a: [1.0, 0.0, 0.0],
            b: [0.0, 0.0, 1.0],
        },
    });
    cases.push(("a corner on a path", s));
    let mut s = flag([0.0, 1.0, 0.0]);
    s.colliders.push(ColliderDesc {
        shape: ShapeDesc::Sphere { radius: 0.1 },
        motion: Motion::Oscillate {
            center: [5.0, 0.0, 0.0],
            amplitude: [0.1, 0.0, 0.0],
            omega: 1.0,
            phase: 0.0,
        },
        rotation: [0.0, 0.0, 0.0, 1.0],
        material: ContactMaterial::default(),
    });
    cases.push(("a moving collider", s));
    for (what, scene) in cases {
        let (model, state) = scene.build().unwrap();
        let mut sim = Simulation::new(model, state, config());
        sim.set_sleep(Some(SleepParams::default()));
        for _ in 0..200 {
            sim.advance_frame().unwrap();
        }
        assert!(!sim.is_asleep(), "{what}: asleep");
    }
    // A blast at 5 s: awake until it has pushed, then free to sleep.
    let mut sim = core_flag();
    sim.system.fields.push(std::sync::Arc::new(RadialBlast {
        center: [0.0, 0.5, 0.3],
        strength: 20.0,
        radius: 0.5,
        start: 5.0,
        duration: 0.1,
    }));
    sim.set_sleep(Some(SleepParams::default()));
    let mut slept_before_blast = false;
    for _ in 0..(5.0 / FRAME) as u32 {
        sim.advance_frame().unwrap();
        slept_before_blast |= sim.is_asleep();
    }
    assert!(!slept_before_blast);
    for _ in 0..400 {
        sim.advance_frame().unwrap();
    }
    assert!(
        sim.is_asleep(),
        "after the blast the flag settles and sleeps"
    );
}

#[test]
fn bad_sleep_numbers_are_refused() {
    for (speed, time, field) in [
        (-1.0, 0.5, "speed"),
        (f64::NAN, 0.5, "speed"),
        (0.01, f64::INFINITY, "time"),
        (0.01, -0.1, "time"),
    ] {
        let p = SleepParams { speed, time };
        assert_eq!(p.validate().unwrap_err().0, field);
        let mut sim = core_flag();
        sim.set_sleep(Some(p));
        assert_eq!(sim.sleep(), None, "bad numbers count as no sleeping");
    }
}

#[cfg(feature = "plugin")]
mod plugin {
    use super::*;
    use bevy::prelude::*;
    use bevy_soft_body::ecs::BodySim;
    use common::spawn;

    fn body() -> SoftBody {
        SoftBody {
            integrator: IntegratorKind::SymplecticEuler,
            step: StepPolicy::Fixed { h: H },
            ..Default::default()
        }
    }

    fn state(app: &App, e: Entity) -> BodyState {
        app.world().get::<SoftBodyStatus>(e).unwrap().state.clone()
    }

    fn positions(app: &App, e: Entity) -> Vec<Vec3> {
        let world = app.world();
        world
            .get::<BodyParticles>(e)
            .unwrap()
            .iter()
            .map(|p| world.get::<Particle>(p).unwrap().position)
            .collect()
    }

    /// A flag spawned in a headless app and run until it sleeps (at most 6 s).
    fn sleeping_flag() -> (App, Entity) {
        let mut app = common::headless_app(FRAME);
        let e = spawn(&mut app, &flag([0.0, 1.0, 0.0]), body());
        for _ in 0..384 {
            app.update();
            if state(&app, e) == BodyState::Sleeping {
                return (app, e);
            }
        }
        panic!("the flag never fell asleep: {:?}", state(&app, e));
    }

    #[test]
    fn the_plugin_sleeps_as_the_core_does() {
        // Same flag, same settings: the plugin's body falls asleep on the same frame as the
        // core driver with the default sleep settings, and lies in the same bits.
        let mut app = common::headless_app(FRAME);
        let mut scene = flag([0.0, 1.0, 0.0]);
        common::f32_exact(&mut scene);
        let e = spawn(&mut app, &scene, body());
        let mut sim = core_flag();
        sim.set_sleep(Some(SleepParams::default()));
        for f in 0..300 {
            app.update();
            sim.advance_frame().unwrap();
            let asleep = state(&app, e) == BodyState::Sleeping;
            assert_eq!(asleep, sim.is_asleep(), "frame {f}");
        }
        assert!(sim.is_asleep());
        let bs = app.world().get::<BodySim>(e).unwrap();
        assert_eq!(bs.simulation().unwrap().state.x, sim.state.x);
        assert_eq!(bs.simulation().unwrap().state.v, sim.state.v);
    }

    /// 50 flags side by side, of which `gusty` hang in a gusting breeze (they never rest):
    /// the substeps every body took over 64 frames once the others have settled, the states
    /// at the end, the bodies' step time and the whole App's wall time over those frames (ms).
    fn fifty_flags(gusty: usize, sleeping: bool) -> (u64, Vec<BodyState>, f32, f64) {
        let mut app = common::headless_app(FRAME);
        app.insert_resource(SoftBodySleep {
            enabled: sleeping,
            ..Default::default()
        });
        let flags: Vec<Entity> = (0..50)
            .map(|k| {
                let e = spawn(
                    &mut app,
                    &flag([(k % 10) as f64 * 0.7, 1.0 + (k / 10) as f64 * 0.7, 0.0]),
                    body(),
                );
                if k < gusty {
                    app.world_mut().entity_mut(e).insert(SoftBodyWind {
                        velocity: Vec3::new(0.0, 0.0, 0.5),
                        gust: 0.5,
                        frequency: 0.5,
                        coefficient: 0.005,
                        seed: k as u64,
                        enabled: true,
                    });
                }
                e
            })
            .collect();
        for _ in 0..192 {
            app.update();
        }
        let (mut substeps, mut ms) = (0u64, 0.0f32);
        let mut wall = std::time::Duration::ZERO;
        for _ in 0..64 {
            let t = std::time::Instant::now();
            app.update();
            wall += t.elapsed();
            for &e in &flags {
                let s = app.world().get::<SoftBodyStatus>(e).unwrap();
                substeps += s.substeps as u64;
                ms += s.step_ms;
            }
        }
        let states = flags.iter().map(|&e| state(&app, e)).collect();
        (substeps, states, ms, wall.as_secs_f64() * 1e3)
    }

    #[test]
    fn forty_flags_at_rest_out_of_fifty_cost_a_fifth() {
        let (asleep_work, states, asleep_ms, asleep_wall) = fifty_flags(10, true);
        let (awake_work, awake_states, awake_ms, awake_wall) = fifty_flags(10, false);
        // Per body the same step (1/1024 s): 16 substeps a frame awake, none asleep.
        let sleeping = states.iter().filter(|s| **s == BodyState::Sleeping).count();
        println!(
            "50 flags, 10 in a gusting breeze, 64 frames: {asleep_work} substeps ({sleeping} asleep) against {awake_work} with sleeping off; body step time {asleep_ms:.1} ms against {awake_ms:.1} ms, App updates {asleep_wall:.1} ms against {awake_wall:.1} ms (debug build, for information)"
        );
        assert_eq!(sleeping, 40, "{states:?}");
        assert!(states[..10].iter().all(|s| *s == BodyState::Running));
        assert!(awake_states.iter().all(|s| *s == BodyState::Running));
        assert_eq!(awake_work, 50 * 64 * 16);
        // The bound: at most a quarter of the work; exactly the ten gusty flags'.
        assert_eq!(asleep_work, 10 * 64 * 16);
        assert!(asleep_work * 4 <= awake_work);
    }

    #[test]
    fn a_ball_hitting_a_sleeping_flag_wakes_it_in_the_same_frame() {
        let (mut app, e) = sleeping_flag();
        let triangles = flag([0.0, 1.0, 0.0]).surface.unwrap().triangles;
        // A 10 cm ball flying at the flag's middle at 2 m/s from 1 m in front of it: while
        // it is far the flag sleeps on; the frame its box first reaches the flag, the flag
        // steps and is pushed. (A collider spawned with a bare `Transform` sits at the
        // origin until its transform is propagated, then jumps: a move past the flag that
        // wakes it. So the ball appears first, and the flag settles again.)
        let ball = app
            .world_mut()
            .spawn((
                SoftBodyCollider::ball(0.1),
                Transform::from_xyz(0.0, 0.75, 1.0),
            ))
            .id();
        for _ in 0..64 {
            app.update();
        }
        assert_eq!(state(&app, e), BodyState::Sleeping);
        let lying = positions(&app, e);
        let (mut woke, mut touched) = (None, None);
        for f in 0..40 {
            // The transform and its propagated form together, so the physics sees the ball
            // where this test does (a `Transform` alone reaches colliders a frame later).
            let mut tf = *app.world().get::<Transform>(ball).unwrap();
            tf.translation.z -= (2.0 * FRAME) as f32;
            app.world_mut()
                .entity_mut(ball)
                .insert((tf, GlobalTransform::from(tf)));
            app.update();
            let z = app.world().get::<Transform>(ball).unwrap().translation.z;
            let now = positions(&app, e);
            let moved = now.iter().zip(&lying).any(|(a, b)| a != b);
            let awake = state(&app, e) == BodyState::Running;
            if awake && woke.is_none() {
                woke = Some((f, z));
            }
            // Touching: a surface triangle within the ball's radius and the contact thickness
            // (the ball meets the flag's triangles between its particles: 7.9 cm diagonals
            // against a 10 cm ball and 1 cm, see `Collider::needs_faces`).
            let centre = [0.0, 0.75, z as f64];
            let near = triangles.iter().any(|t| {
                let tri = t.map(|i| now[i as usize].as_dvec3().to_array());
                common::intersect::point_triangle_distance(centre, &tri) < 0.1 + 0.01
            });
            if near && touched.is_none() {
                touched = Some(f);
                assert!(awake && moved, "touched at frame {f} while asleep");
            }
            if z > 0.5 {
                assert!(!awake, "woken with the ball still {z} m away");
            }
        }
        println!("flag woken at frame {woke:?} (ball z), first touched at frame {touched:?}");
        assert!(woke.is_some() && touched.is_some());
        assert!(woke.unwrap().0 <= touched.unwrap());
    }

    /// Runs a sleeping flag one frame after `poke` and says whether it was awake in that frame
    /// (or, for causes the transforms carry a frame late, the next).
    fn wakes(poke: impl FnOnce(&mut App, Entity), frames: u32) -> bool {
        let (mut app, e) = sleeping_flag();
        poke(&mut app, e);
        (0..frames).any(|_| {
            app.update();
            state(&app, e) == BodyState::Running
        })
    }

    fn particle(app: &App, e: Entity, k: usize) -> Entity {
        app.world()
            .get::<BodyParticles>(e)
            .unwrap()
            .iter()
            .nth(k)
            .unwrap()
    }

    #[test]
    fn an_edit_wakes_it() {
        assert!(wakes(
            |app, e| {
                let p = particle(app, e, 55);
                app.world_mut().get_mut::<Particle>(p).unwrap().velocity = Vec3::Z;
            },
            1
        ));
    }

    #[test]
    fn a_moving_pin_target_wakes_it() {
        // A corner pinned to an entity; the entity moved. Pins read the propagated
        // `GlobalTransform`, one frame behind a `Transform` set between updates.
        assert!(wakes(
            |app, e| {
                let target = app
                    .world_mut()
                    .spawn(Transform::from_xyz(0.0, 0.0, 0.0))
                    .id();
                let p = particle(app, e, 99);
                let at = app.world().get::<Particle>(p).unwrap().position;
                app.world_mut().entity_mut(p).insert(Pinned::to(target, at));
                // Pinning is an edit: let it settle asleep again, then move the target.
                for _ in 0..64 {
                    app.update();
                }
                assert_eq!(state(app, e), BodyState::Sleeping);
                app.world_mut()
                    .get_mut::<Transform>(target)
                    .unwrap()
                    .translation
                    .x += 0.05;
            },
            2
        ));
    }

    #[test]
    fn a_force_wakes_it() {
        assert!(wakes(
            |app, e| {
                let p = particle(app, e, 95);
                app.world_mut()
                    .entity_mut(p)
                    .insert(ExternalForce(Vec3::new(0.0, 0.0, 0.05)));
            },
            1
        ));
    }

    #[test]
    fn wind_wakes_it() {
        assert!(wakes(
            |app, e| {
                app.world_mut().entity_mut(e).insert(SoftBodyWind {
                    velocity: Vec3::new(0.0, 0.0, 1.0),
                    gust: 0.0,
                    ..Default::default()
                });
            },
            1
        ));
    }

    #[test]
    fn a_force_field_wakes_it() {
        assert!(wakes(
            |app, _| {
                app.world_mut()
                    .resource_mut::<GlobalForceFields>()
                    .0
                    .push(std::sync::Arc::new(Buoyancy::default()));
            },
            1
        ));
    }

    #[test]
    fn a_grab_wakes_it() {
        // What the panel's mouse grab does: a handle particle, pinned, joined to the grabbed
        // particle by a spring.
        assert!(wakes(
            |app, e| {
                let p = particle(app, e, 55);
                let at = app.world().get::<Particle>(p).unwrap().position;
                let world = app.world_mut();
                let handle = world
                    .spawn((
                        Particle {
                            position: at + Vec3::Z * 0.05,
                            velocity: Vec3::ZERO,
                            mass: 0.0,
                        },
                        Pinned::default(),
                        ParticleOf(e),
                    ))
                    .id();
                world.spawn((
                    Spring {
                        a: handle,
                        b: p,
                        rest_length: 0.0,
                        stiffness: 20.0,
                        damping: 0.1,
                        law: SpringLaw::Hooke,
                    },
                    SpringOf(e),
                ));
            },
            1
        ));
    }

    #[test]
    fn a_wake_message_wakes_it() {
        assert!(wakes(
            |app, e| {
                app.world_mut().write_message(WakeSoftBody(e));
            },
            1
        ));
    }

    #[test]
    fn a_sleeping_flag_that_keeps_being_woken_does_not_flicker() {
        // Woken every 10 frames: it must stay awake the sleep time (32 frames) after each
        // wake, so it never sleeps; woken every 48 frames it sleeps between wakes, once per
        // wake, each time 32 frames after it.
        for (every, expect) in [(10u32, 0usize), (48, 4)] {
            let (mut app, e) = sleeping_flag();
            let (mut sleeps, mut since_wake, mut last) = (0, 0u32, BodyState::Sleeping);
            for f in 0..(every * 4) {
                if f % every == 0 {
                    app.world_mut().write_message(WakeSoftBody(e));
                    since_wake = 0;
                }
                app.update();
                since_wake += 1;
                let now = state(&app, e);
                if now == BodyState::Sleeping && last == BodyState::Running {
                    sleeps += 1;
                    assert_eq!(since_wake, 32, "asleep {since_wake} frames after a wake");
                }
                last = now;
            }
            assert_eq!(sleeps, expect, "woken every {every} frames");
        }
    }

    #[test]
    fn a_flag_with_sleeping_disabled_never_sleeps() {
        let mut app = common::headless_app(FRAME);
        let e = spawn(&mut app, &flag([0.0, 1.0, 0.0]), body());
        app.world_mut()
            .entity_mut(e)
            .insert(SoftBodySleepingDisabled);
        for _ in 0..300 {
            app.update();
            assert_eq!(state(&app, e), BodyState::Running);
        }
    }

    #[test]
    fn an_awake_body_landing_on_a_sleeping_one_wakes_it() {
        use bevy_soft_body::core::build::{ClothPileParams, cloth_pile};
        // Two 12² cloths of the pile as two bodies with self-collision: the first lies asleep
        // on the ground, the second falls onto it from 0.5 m.
        let mut p = ClothPileParams {
            cloths: 1,
            radius: 0.05,
            ..Default::default()
        }
        .with_resolution(12);
        p.self_collision = Some(SelfContactParams {
            thickness: 1.0 / 64.0,
            friction: 0.25,
        });
        let mut ground = cloth_pile(&p).unwrap();
        // The ground alone: the pile's 10 cm ball would hold this coarse cloth up as a tent
        // (its 11 cm cells meet the ball between the particles), which does not come to rest.
        ground.colliders.truncate(1);
        let h = p.stable_step();
        let mut app = common::headless_app(FRAME);
        let body = SoftBody {
            integrator: IntegratorKind::SymplecticEuler,
            step: StepPolicy::Fixed { h },
            ..Default::default()
        };
        let a = spawn(&mut app, &ground, body.clone());
        let mut slept = false;
        for _ in 0..640 {
            app.update();
            if state(&app, a) == BodyState::Sleeping {
                slept = true;
                break;
            }
        }
        assert!(slept, "the lower cloth never slept: {:?}", state(&app, a));
        let mut top = ground.clone().translated([0.0, 0.5, 0.0]);
        top.colliders.clear();
        let b = spawn(&mut app, &top, body);
        let (mut woke, mut landed) = (None, None);
        for f in 0..90 {
            app.update();
            if woke.is_none() && state(&app, a) == BodyState::Running {
                woke = Some(f);
            }
            let lowest = positions(&app, b)
                .iter()
                .map(|p| p.y)
                .fold(f32::INFINITY, f32::min);
            let highest = positions(&app, a)
                .iter()
                .map(|p| p.y)
                .fold(f32::NEG_INFINITY, f32::max);
            // In contact: within the proximity band of 1.5 thicknesses, where the impulses
            // act (a cloth lying on the other rests at the thickness, to round-off).
            if landed.is_none() && lowest < highest + 1.5 / 64.0 {
                landed = Some(f);
            }
        }
        println!("lower cloth woken at frame {woke:?}; upper in contact at {landed:?}");
        let (woke, landed) = (woke.expect("never woken"), landed.expect("never landed"));
        assert!(woke <= landed);
    }
}
