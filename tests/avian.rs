//! Soft bodies and avian3d rigid bodies in one headless app (feature `avian`): momentum
//! exchanged in a collision, a crate carried by a trampoline and by a rope, turntables, layers,
//! a kinematic body seen without lag, hostile rigid bodies, bitwise determinism.
#![cfg(feature = "avian")]
// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

mod common;
use avian3d::prelude::*;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_soft_body::avian::{SoftBodyAvianSettings, SoftBodyImpulse};
use bevy_soft_body::core::build;
use bevy_soft_body::core::driver::StepPolicy;
use bevy_soft_body::core::integrate::IntegratorKind;
use bevy_soft_body::core::scene::{ParticleDesc, Scene};
use bevy_soft_body::ecs::*;
use common::spawn;
use glam::DVec3;

const HZ: f64 = 60.0;

/// Soft bodies (everything but the panel) and avian, one fixed
/// frame of 1/60 s per update.
fn app() -> App {
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        TransformPlugin,
        common::headless_plugins(),
        PhysicsPlugins::default(),
    ))
    .insert_resource(Time::<Fixed>::from_hz(HZ))
    .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
    // avian finishes its set-up (diagnostics resources) in `Plugin::finish`, which `App::run`
    // calls and a test's `update` does not.
    app.finish();
    app.cleanup();
    app.update();
    app
}

fn explicit(h: f64) -> SoftBody {
    SoftBody {
        integrator: IntegratorKind::SymplecticEuler,
        step: StepPolicy::Fixed { h },
        energy_guard: None,
        ..Default::default()
    }
}

fn particles(app: &App, body: Entity) -> Vec<Particle> {
    let w = app.world();
    w.get::<BodyParticles>(body)
        .unwrap()
        .entities()
        .iter()
        .map(|e| *w.get::<Particle>(*e).unwrap())
        .collect()
}

fn running(app: &App, body: Entity) {
    let st = app.world().get::<SoftBodyStatus>(body).unwrap();
    assert_eq!(st.state, BodyState::Running, "{:?}", st.state);
}

/// The world inertia tensor of a rigid body times `w`.
fn inertia_times(app: &App, rb: Entity, w: Vec3) -> DVec3 {
    let world = app.world();
    let rot = world.get::<Rotation>(rb).unwrap().0;
    let i = world
        .get::<ComputedAngularInertia>(rb)
        .unwrap()
        .rotated(rot)
        .tensor()
        .to_mat3();
    (i * w).as_dvec3()
}

fn momenta(app: &App, body: Entity, rb: Entity) -> (DVec3, DVec3) {
    let w = app.world();
    let ps = particles(app, body);
    let m_rb = w.get::<ComputedMass>(rb).unwrap().value() as f64;
    let c_rb = w.get::<Position>(rb).unwrap().0.as_dvec3();
    let v_rb = w.get::<LinearVelocity>(rb).unwrap().0.as_dvec3();
    let w_rb = w.get::<AngularVelocity>(rb).unwrap().0;
    let total: f64 = m_rb + ps.iter().map(|p| p.mass as f64).sum::<f64>();
    let com = (c_rb * m_rb
        + ps.iter()
            .map(|p| p.position.as_dvec3() * p.mass as f64)
            .sum::<DVec3>())
        / total;
    let mut p = v_rb * m_rb;
    let mut l = (c_rb - com).cross(v_rb * m_rb) + inertia_times(app, rb, w_rb);
    for q in &ps {
        let (x, v, m) = (q.position.as_dvec3(), q.velocity.as_dvec3(), q.mass as f64);
        p += v * m;
        l += (x - com).cross(v * m);
    }
    (p, l)
}

/// A free cloth (no gravity, no pins) in the plane z = 0, and a 0.5 kg ball of radius 0.1 m
/// thrown at it at 4 m/s, 0.2 m off centre, frictionless and without bounce.
fn ball_and_cloth(app: &mut App) -> (Entity, Entity) {
    app.insert_resource(Gravity(Vec3::ZERO));
    let mut scene = build::cloth(&build::ClothParams {
        rows: 12,
        cols: 12,
        pins: build::ClothPins::None,
        hanging: true,
        origin: [0.0, 0.5, 0.0],
        // No air drag: it takes momentum out of the system.
        drag: 0.0,
        ..Default::default()
    })
    .unwrap();
    scene.gravity = [0.0; 3];
    scene.colliders.clear();
    let cloth = spawn(app, &scene, explicit(1.0 / 600.0));
    let ball = app
        .world_mut()
        .spawn((
            RigidBody::Dynamic,
            Collider::sphere(0.1),
            Mass(0.5),
            Friction::new(0.0),
            Restitution::new(0.0),
            Transform::from_xyz(0.2, 0.1, -0.4),
            LinearVelocity(Vec3::new(0.0, 0.0, 4.0)),
        ))
        .id();
    (cloth, ball)
}

#[test]
fn a_ball_thrown_into_a_free_cloth_keeps_the_momentum_of_both() {
    let mut app = app();
    let (cloth, ball) = ball_and_cloth(&mut app);
    app.update();
    let (p0, l0) = momenta(&app, cloth, ball);
    let mut contacts = 0;
    for _ in 0..45 {
        app.update();
        contacts += app
            .world()
            .get::<SoftBodyImpulse>(ball)
            .map_or(0, |i| i.contacts);
    }
    running(&app, cloth);
    let (p1, l1) = momenta(&app, cloth, ball);
    let v = app.world().get::<LinearVelocity>(ball).unwrap().0;
    println!("contacts {contacts}; ball v {v}; p {p0} → {p1}; L {l0} → {l1}");
    assert!(contacts > 100, "the ball hit the cloth");
    assert!(v.z > 0.0 && v.z < 3.0, "the ball slowed down: {v}");
    let cloth_v: DVec3 = particles(&app, cloth)
        .iter()
        .map(|p| p.velocity.as_dvec3())
        .sum::<DVec3>()
        / 144.0;
    assert!(cloth_v.z > 0.1, "the cloth was pushed: {cloth_v}");
    let dp = (p1 - p0).length() / p0.length();
    assert!(
        dp < 0.01,
        "linear momentum off by {:.3} % (limit 1 %)",
        dp * 100.0
    );
    let dl = (l1 - l0).length() / l0.length();
    assert!(
        dl < 0.02,
        "angular momentum off by {:.3} % (limit 2 %)",
        dl * 100.0
    );
}

/// A 10 kg crate dropped on the trampoline bounces and comes to rest on it (the last of twenty
/// seconds is measured); at rest the cloth's contact impulse per second on it is its weight,
/// and it does not jitter. The cloth holds the crate's lower edges at the thickness (its
/// triangles meet them, wrapped round each edge) and its bounce dies out by about 30 % a
/// second: 6.4 cm/s over the tenth second, under 1 cm/s by the twentieth. Held by the
/// particles alone it sat 4 cm deeper and stilled in ten.
#[test]
fn a_crate_comes_to_rest_on_a_trampoline_held_by_its_weight() {
    let mut app = app();
    let cloth = spawn(&mut app, &common::trampoline(), explicit(1.0 / 1200.0));
    let mass = 10.0;
    let g = 9.81;
    let krate = app
        .world_mut()
        .spawn((
            RigidBody::Dynamic,
            Collider::cuboid(0.4, 0.4, 0.4),
            Mass(mass),
            Friction::new(0.5),
            Restitution::new(0.0),
            Transform::from_xyz(0.0, 0.5, 0.0),
        ))
        .id();
    let frames = (20.0 * HZ) as usize;
    let last_second = HZ as usize;
    let (mut impulse, mut ys, mut speed) = (0.0f64, vec![], 0.0f32);
    for f in 0..frames {
        app.update();
        if f >= frames - last_second {
            impulse += app
                .world()
                .get::<SoftBodyImpulse>(krate)
                .map_or(0.0, |i| i.linear.y as f64);
            ys.push(app.world().get::<Position>(krate).unwrap().0.y);
            speed = speed.max(app.world().get::<LinearVelocity>(krate).unwrap().0.y.abs());
        }
    }
    running(&app, cloth);
    let spread =
        ys.iter().cloned().fold(f32::MIN, f32::max) - ys.iter().cloned().fold(f32::MAX, f32::min);
    println!(
        "crate at y = {:.4} m; impulse over the last second {impulse:.3} N·s (weight {:.3} N); spread {spread:e} m; max |v_y| {speed:e} m/s",
        ys.last().unwrap(),
        mass * g
    );
    assert!(*ys.last().unwrap() < 0.2, "the crate sank into the cloth");
    assert!(*ys.last().unwrap() > -0.5, "the crate did not fall through");
    assert!(
        speed < 0.01,
        "at rest: vertical speed {speed} (limit 1 cm/s)"
    );
    let weight = mass as f64 * g as f64;
    assert!(
        (impulse - weight).abs() < 0.03 * weight,
        "contact impulse per second {impulse} vs weight {weight} (3 %)"
    );
    assert!(
        spread < 1e-3,
        "jitter: position spread {spread} m (limit 1 mm)"
    );
}

/// A 10 kg crate hanging from a rope of springs: at rest the top spring holds the crate's
/// weight and the rope's.
#[test]
fn a_crate_hangs_from_a_rope_and_the_rope_holds_both_weights() {
    let mut app = app();
    let links = 10;
    let link = 0.1;
    let m_particle = 0.05;
    let k = 20000.0;
    let mut scene = build::chain(&build::ChainParams {
        particles: links + 1,
        link,
        mass: m_particle,
        stiffness: k,
        damping: 5.0,
        drag: 0.01,
        direction: [0.0, -1.0, 0.0],
        ..Default::default()
    })
    .unwrap();
    scene.gravity = [0.0, -9.81, 0.0];
    let top = scene.particles[0].position;
    let bottom = Vec3::new(
        top[0] as f32,
        (top[1] - links as f64 * link) as f32,
        top[2] as f32,
    );
    let mass = 10.0;
    let half = 0.2;
    let krate = app
        .world_mut()
        .spawn((
            RigidBody::Dynamic,
            Collider::cuboid(2.0 * half, 2.0 * half, 2.0 * half),
            Mass(mass),
            Transform::from_translation(bottom - Vec3::Y * half),
        ))
        .id();
    app.update();
    let rope = spawn(&mut app, &scene, explicit(1.0 / 2400.0));
    app.update();
    let last = app.world().get::<BodyParticles>(rope).unwrap().entities()[links];
    app.world_mut()
        .entity_mut(last)
        .insert(Pinned::to(krate, Vec3::Y * half));
    for _ in 0..(5.0 * HZ) as usize {
        app.update();
    }
    running(&app, rope);
    let ps = particles(&app, rope);
    let stretch = (ps[1].position - ps[0].position).length() as f64 - link;
    let tension = k * stretch;
    // Every particle but the pinned top one hangs from the top spring, with the crate.
    let weight = (mass as f64 + links as f64 * m_particle) * 9.81;
    let v = app.world().get::<LinearVelocity>(krate).unwrap().0;
    println!("top tension {tension:.3} N vs weights {weight:.3} N; crate v {v}");
    assert!(v.length() < 0.01, "the crate is at rest: {v}");
    assert!(
        (tension - weight).abs() < 0.02 * weight,
        "tension {tension} vs weight {weight} (2 %)"
    );
}

/// One particle on a box turning about +y at 1 rad/s, friction 0.5: after 3 s it moves with
/// the table's surface velocity `ω × r` at its radius.
fn check_carried(app: &App, body: Entity, omega: f32, radius: f32) {
    let p = particles(app, body)[0];
    let expect = Vec3::Y.cross(p.position) * omega;
    let r = Vec3::new(p.position.x, 0.0, p.position.z).length();
    println!(
        "x {} v {} expected {expect} radius {r}",
        p.position, p.velocity
    );
    assert!(
        (p.velocity - expect).length() < 0.02 * expect.length(),
        "{} vs {expect}",
        p.velocity
    );
    assert!((r - radius).abs() < 0.02 * radius, "radius {r}");
}

fn one_particle(radius: f32, y: f32) -> Scene {
    Scene {
        gravity: [0.0, -9.81, 0.0],
        particles: vec![ParticleDesc {
            position: [radius as f64, y as f64, 0.0],
            velocity: [0.0; 3],
            mass: 0.1,
            pinned: false,
        }],
        ..Default::default()
    }
}

#[test]
fn an_avian_turntable_carries_a_particle_at_its_surface_velocity() {
    let mut app = app();
    app.world_mut().spawn((
        RigidBody::Kinematic,
        Collider::cuboid(4.0, 0.2, 4.0),
        Friction::new(0.5),
        Transform::default(),
        AngularVelocity(Vec3::Y),
    ));
    app.update();
    let body = spawn(&mut app, &one_particle(0.8, 0.11), explicit(1.0 / 600.0));
    for _ in 0..(3.0 * HZ) as usize {
        app.update();
    }
    running(&app, body);
    check_carried(&app, body, 1.0, 0.8);
}

/// The same with a plain `SoftBodyCollider` turned by its transform each fixed frame (its pose
/// at the end of the frame to come, as for any plain collider).
#[test]
fn a_plain_collider_turned_by_its_transform_carries_a_particle_too() {
    let mut app = app();
    let mut table = SoftBodyCollider::new(parry3d::shape::SharedShape::cuboid(2.0, 0.1, 2.0));
    table.friction = 0.5;
    let table = app.world_mut().spawn((table, Transform::default())).id();
    app.add_systems(
        FixedUpdate,
        (move |clock: Res<SoftBodyClock>,
               fixed: Res<Time<Fixed>>,
               mut q: Query<(&mut Transform, &mut GlobalTransform)>| {
            let t = (clock.elapsed + fixed.timestep().as_secs_f64()) as f32;
            let (mut tf, mut gt) = q.get_mut(table).unwrap();
            tf.rotation = Quat::from_rotation_y(t);
            *gt = GlobalTransform::from(*tf);
        })
        .in_set(SoftBodySystems::First),
    );
    let body = spawn(&mut app, &one_particle(0.8, 0.11), explicit(1.0 / 600.0));
    for _ in 0..(3.0 * HZ) as usize {
        app.update();
    }
    running(&app, body);
    check_carried(&app, body, 1.0, 0.8);
}

/// A body on a layer a collider filters out falls through it; the same body without layers is
/// caught.
#[test]
fn collision_layers_are_respected() {
    let mut app = app();
    app.world_mut().spawn((
        RigidBody::Static,
        Collider::cuboid(4.0, 0.2, 4.0),
        CollisionLayers::new(0b01, 0b01),
        Transform::default(),
    ));
    app.update();
    let filtered = spawn(&mut app, &one_particle(0.5, 0.2), explicit(1.0 / 600.0));
    app.world_mut()
        .entity_mut(filtered)
        .insert(CollisionLayers::new(0b10, 0b10));
    let caught = spawn(&mut app, &one_particle(-0.5, 0.2), explicit(1.0 / 600.0));
    for _ in 0..60 {
        app.update();
    }
    let yf = particles(&app, filtered)[0].position.y;
    let yc = particles(&app, caught)[0].position.y;
    println!("filtered y {yf}, caught y {yc}");
    assert!(yf < -1.0, "fell through: {yf}");
    assert!(
        (yc - 0.11).abs() < 1e-3,
        "rests on the top face + thickness: {yc}"
    );
}

/// A kinematic platform rising at constant speed with a particle resting on it: after every
/// frame the particle sits exactly on the platform's top face as avian placed it (a one-frame
/// lag would leave it 0.5 m/s × 1/60 s = 8 mm behind).
#[test]
fn a_kinematic_body_and_the_particles_on_it_agree_every_frame() {
    let mut app = app();
    let platform = app
        .world_mut()
        .spawn((
            RigidBody::Kinematic,
            Collider::cuboid(2.0, 0.2, 2.0),
            Transform::default(),
            LinearVelocity(Vec3::Y * 0.5),
        ))
        .id();
    app.update();
    let body = spawn(&mut app, &one_particle(0.3, 0.11), explicit(1.0 / 600.0));
    let mut worst = 0.0f32;
    for f in 0..60 {
        app.update();
        let top = app.world().get::<Position>(platform).unwrap().0.y + 0.1 + 0.01;
        let y = particles(&app, body)[0].position.y;
        if f > 2 {
            worst = worst.max((y - top).abs());
        }
    }
    println!("largest gap between particle and platform top: {worst:e} m");
    assert!(worst < 1e-4, "lag: {worst} m");
}

/// A pose that is NaN while the soft bodies read it (set in `SoftBodySystems::First`, put back
/// in `SoftBodySystems::Last`, so avian itself, which asserts finite poses in debug builds,
/// never sees it).
#[derive(Resource)]
struct Poison(Entity, Option<Vec3>, bool);

/// Hostile rigid bodies: despawned mid-contact, a NaN pose, a massless dynamic body. Each is a
/// warning at most; the soft bodies go on and no particle becomes non-finite.
#[test]
fn hostile_rigid_bodies_never_break_the_soft_bodies() {
    let mut app = app();
    let (cloth, ball) = ball_and_cloth(&mut app);
    let nan = app
        .world_mut()
        .spawn((
            RigidBody::Kinematic,
            Collider::sphere(0.2),
            Transform::from_xyz(-0.3, 0.2, 0.0),
        ))
        .id();
    app.world_mut().spawn((
        RigidBody::Dynamic,
        Collider::sphere(0.1),
        Mass(0.0),
        Transform::from_xyz(-0.2, 0.3, 0.05),
        LinearVelocity(Vec3::new(0.0, 0.0, -1.0)),
    ));
    app.insert_resource(Poison(nan, None, false));
    app.add_systems(
        FixedUpdate,
        (
            (|mut p: ResMut<Poison>, mut q: Query<&mut Position>| {
                if p.2 {
                    let mut pos = q.get_mut(p.0).unwrap();
                    p.1 = Some(pos.0);
                    pos.0 = Vec3::NAN;
                }
            })
            .in_set(SoftBodySystems::First),
            (|mut p: ResMut<Poison>, mut q: Query<&mut Position>| {
                if let Some(x) = p.1.take() {
                    q.get_mut(p.0).unwrap().0 = x;
                }
            })
            .in_set(SoftBodySystems::Last),
        ),
    );
    for f in 0..40 {
        app.world_mut().resource_mut::<Poison>().2 = (5..15).contains(&f);
        if f == 12 {
            app.world_mut().entity_mut(ball).despawn();
        }
        app.update();
        running(&app, cloth);
        assert!(
            particles(&app, cloth)
                .iter()
                .all(|p| p.position.is_finite() && p.velocity.is_finite()),
            "frame {f}"
        );
    }
}

/// Same scene, same thread count: the same bits, soft and rigid.
#[test]
fn a_coupled_scene_is_bitwise_deterministic() {
    let run = || {
        let mut app = app();
        let (cloth, ball) = ball_and_cloth(&mut app);
        for _ in 0..30 {
            app.update();
        }
        let mut bits: Vec<u32> = particles(&app, cloth)
            .iter()
            .flat_map(|p| {
                p.position
                    .to_array()
                    .into_iter()
                    .chain(p.velocity.to_array())
            })
            .map(f32::to_bits)
            .collect();
        let w = app.world();
        bits.extend(
            w.get::<Position>(ball)
                .unwrap()
                .0
                .to_array()
                .map(f32::to_bits),
        );
        bits.extend(
            w.get::<LinearVelocity>(ball)
                .unwrap()
                .0
                .to_array()
                .map(f32::to_bits),
        );
        bits
    };
    let a = run();
    let b = run();
    assert_eq!(a, b);
}

/// The other mass regime: a light ball (50 g, radius 0.15 m) dropped on a heavy jelly
/// (216 particles of 50 g: 10.8 kg) standing on avian's ground. It lands and lies on the top
/// face, held the thickness off its triangles (not sunk 12 mm into a cell between four
/// particles, as it was when the particles alone met it: `tests/collider_faces.rs`), without
/// blowing up. On the flat face nothing holds it where it landed: it keeps the few cm/s of
/// sideways motion the landing on the faces' diagonals gave it, rolling as a ball on a floor
/// does, the point touching the face at rest, and it rides the face's own vibration (1–2 cm/s)
/// up and down.
#[test]
fn a_light_ball_lands_on_a_heavy_jelly_and_lies_on_its_top_face() {
    let mut app = app();
    app.world_mut().spawn((
        RigidBody::Static,
        Collider::half_space(Vec3::Y),
        Transform::default(),
    ));
    let mut scene = build::jelly(&build::JellyParams {
        size: [6, 6, 6],
        spacing: 0.1,
        mass: 0.05,
        stiffness: [400.0, 200.0, 100.0],
        damping: 0.2,
        drop_height: 0.0,
        ..Default::default()
    })
    .unwrap();
    scene.colliders.clear();
    let jelly = spawn(&mut app, &scene, explicit(1.0 / 1200.0));
    let (r, thickness) = (
        0.15,
        app.world().resource::<SoftBodyAvianSettings>().thickness,
    );
    let ball = app
        .world_mut()
        .spawn((
            RigidBody::Dynamic,
            Collider::sphere(r),
            Mass(0.05),
            Transform::from_xyz(0.0, 1.0, 0.0),
        ))
        .id();
    let top = |app: &App| {
        particles(app, jelly)
            .iter()
            .map(|p| p.position.y)
            .fold(f32::MIN, f32::max)
    };
    // Over the last second: how far the ball's centre strays from the radius and the
    // thickness above the top face (which sags a little under it), and the largest vertical
    // speeds of the ball and of the face's particles.
    let (mut lowest, mut off, mut vertical, mut face) = (f32::MAX, 0.0f32, 0.0f32, 0.0f32);
    let frames = (3.0 * HZ) as usize;
    for f in 0..frames {
        app.update();
        let y = app.world().get::<Position>(ball).unwrap().0.y;
        lowest = lowest.min(y);
        if f + HZ as usize >= frames {
            off = off.max((y - (top(&app) + r + thickness)).abs());
            let v = app.world().get::<LinearVelocity>(ball).unwrap().0;
            vertical = vertical.max(v.y.abs());
            face = particles(&app, jelly)
                .iter()
                .filter(|p| p.position.y > 0.45)
                .map(|p| p.velocity.y.abs())
                .fold(face, f32::max);
        }
    }
    running(&app, jelly);
    let top = top(&app);
    let y = app.world().get::<Position>(ball).unwrap().0.y;
    let v = app.world().get::<LinearVelocity>(ball).unwrap().0;
    let w = app.world().get::<AngularVelocity>(ball).unwrap().0;
    // The point of the ball touching the face: its velocity is the ball's plus ω × (−r ŷ).
    let slip = v + w.cross(Vec3::new(0.0, -r, 0.0));
    let sideways = Vec3::new(v.x, 0.0, v.z).length();
    println!(
        "jelly top {top}; ball at {y} (lowest {lowest}), v {v}, ω {w}; slip {slip}; over the last second: {off} m off the face at most, |v_y| up to {vertical} (the face's particles' up to {face})"
    );
    // On the top face in every frame of the last second: its centre the radius and the
    // thickness above it, within a few millimetres (the face is not quite flat where it
    // rolls).
    assert!(off < 0.005, "the ball left the face by {off} m");
    assert!(
        lowest > top - 0.05,
        "the ball went into the jelly: {lowest}"
    );
    // Riding the face, not bouncing on it: as fast up and down as the face under it.
    assert!(
        vertical <= face + 0.005,
        "the ball bounces: |v_y| up to {vertical} against the face's {face}"
    );
    // Rolling, not sliding: the touching point still within a tenth of the ball's speed.
    assert!(
        Vec3::new(slip.x, 0.0, slip.z).length() <= 0.1 * sideways.max(0.01),
        "the ball slides: slip {slip} at {sideways} m/s"
    );
}

/// Where a staggered attachment stops being stable, and what happens past it: a rigid ball
/// hanging from the end of a rope of 12 springs (k = 8000 N/m, 20 g particles), let go 20° off
/// the vertical, for ball masses from 4 kg down to 20 g. The rope's pull reaches the ball as a
/// force held over avian's step, an explicit coupling, stable while `Δ·√(k/M)` stays below
/// about 2. Below 1.1 the ball swings as a pendulum (top speed √(2gL(1 − cos 20°)) ≈ 1.3 m/s
/// for L ≈ 1.45 m); past the limit the push is capped at `max_velocity_change` (50 m/s a
/// frame) and everything stays finite, the rope still running. Prints the table in the README
/// (`--nocapture`).
#[test]
fn attachment_stability_against_the_mass_of_the_body() {
    println!("| ball mass (kg) | Δ·√(k/M) | largest ball speed in 3 s (m/s) | rope |");
    println!("| ---: | ---: | ---: | --- |");
    for mass in [4.0f32, 2.0, 1.0, 0.5, 0.3, 0.2, 0.1, 0.05, 0.02] {
        let mut app = app();
        let links = 12;
        let mut scene = build::chain(&build::ChainParams {
            particles: links + 1,
            link: 0.1,
            mass: 0.02,
            stiffness: 8000.0,
            damping: 0.5,
            drag: 0.005,
            direction: [0.34, -0.94, 0.0],
            ..Default::default()
        })
        .unwrap()
        .translated([0.0, 2.0, 0.0]);
        scene.gravity = [0.0, -9.81, 0.0];
        let end = scene.particles[links].position;
        let ball = app
            .world_mut()
            .spawn((
                RigidBody::Dynamic,
                Collider::sphere(0.1),
                Mass(mass),
                Transform::from_xyz(end[0] as f32, end[1] as f32 - 0.1, end[2] as f32),
            ))
            .id();
        app.update();
        let rope = spawn(&mut app, &scene, explicit(1.0 / 1200.0));
        app.update();
        let last = app.world().get::<BodyParticles>(rope).unwrap().entities()[links];
        app.world_mut()
            .entity_mut(last)
            .insert(Pinned::to(ball, Vec3::Y * 0.1));
        let mut fastest = 0.0f32;
        for _ in 0..(3.0 * HZ) as usize {
            app.update();
            let v = app.world().get::<LinearVelocity>(ball).unwrap().0.length();
            fastest = fastest.max(if v.is_finite() { v } else { f32::INFINITY });
        }
        let state = app
            .world()
            .get::<SoftBodyStatus>(rope)
            .unwrap()
            .state
            .clone();
        let rope_state = match state {
            BodyState::Running => "running".to_string(),
            other => format!("{other:?}").chars().take(40).collect(),
        };
        let wd = (8000.0 / mass as f64).sqrt() / HZ;
        println!("| {mass} | {wd:.2} | {fastest:.2} | {rope_state} |");
        if wd < 1.1 {
            // The pendulum's speed (1.3 m/s) with 20 % for the rope's stretch and swing.
            assert!(fastest < 1.6, "{mass} kg: top speed {fastest} m/s");
        }
        assert!(
            fastest.is_finite(),
            "{mass} kg: the ball's velocity is not finite"
        );
        assert_eq!(rope_state, "running", "{mass} kg");
    }
}
