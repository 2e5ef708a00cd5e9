//! Soft bodies in avian3d's world (feature `avian`): a curtain that balls are thrown into, a
//! trampoline that a crate drops onto, a lamp hanging from a rope of springs, a jelly that a
//! ball hits, a flag on a turning kinematic pole. Every avian collider is a soft-body collider;
//! contacts and the rope's pull act back on the rigid bodies.
//!
//! `cargo run --release --example avian_playground --features avian`
//! `-- --bench [FRAMES]`: headless, prints ms per fixed frame for the coupled scene, the soft
//! bodies alone and the rigid bodies alone (the table in docs/BENCHMARKS.md).
//!
//! The jelly floats in a pool (a `Buoyancy` force field), and F sets off a `RadialBlast` in
//! front of the curtain.
//!
//! Keys: O throws a ball at the curtain, C drops a crate on the trampoline, F blast, Space pause, N step,
//! G wireframe; left drag pulls cloth, right drag or arrows orbit, wheel zoom. The "coupling"
//! panel lists what the soft bodies gave each rigid body in the last frame and the momenta.

#[path = "common/mod.rs"]
mod common;

use avian3d::prelude::*;
use bevy::ecs::system::RunSystemOnce;
use bevy::prelude::*;
use bevy_soft_body::core::build;
use bevy_soft_body::prelude::*;

/// What to put in the world.
#[derive(Clone, Copy, PartialEq)]
enum Part {
    Both,
    SoftOnly,
    RigidOnly,
}

fn main() {
    if std::env::args().nth(1).as_deref() == Some("--bench") {
        let frames = std::env::args()
            .nth(2)
            .and_then(|s| s.parse().ok())
            .unwrap_or(600);
        bench(frames);
        return;
    }
    let args = common::args("avian_playground");
    let body = args.body(IntegratorKind::SymplecticEuler, 1.0 / 1200.0);
    let mut app = common::app("avian playground", &args);
    app.add_plugins(PhysicsPlugins::default())
        .add_systems(
            Startup,
            move |mut c: Commands,
                  mut meshes: ResMut<Assets<Mesh>>,
                  mut materials: ResMut<Assets<StandardMaterial>>| {
                common::stage(&mut c, Vec3::new(0.0, 0.8, 0.0), 7.5);
                let mut looks = Looks {
                    meshes: &mut meshes,
                    materials: &mut materials,
                };
                spawn_world(&mut c, Some(&mut looks), &body, Part::Both);
            },
        )
        .add_systems(FixedUpdate, throw_balls)
        .add_systems(Update, (attach, keys))
        .add_systems(bevy_egui::EguiPrimaryContextPass, coupling_panel);
    app.run();
}

/// Meshes and materials for the rigid bodies (absent in headless runs).
struct Looks<'a> {
    meshes: &'a mut Assets<Mesh>,
    materials: &'a mut Assets<StandardMaterial>,
}

impl Looks<'_> {
    fn add(
        &mut self,
        mesh: impl Into<Mesh>,
        color: Color,
    ) -> (Mesh3d, MeshMaterial3d<StandardMaterial>) {
        (
            Mesh3d(self.meshes.add(mesh)),
            MeshMaterial3d(self.materials.add(StandardMaterial {
                base_color: color,
                perceptual_roughness: 0.6,
                ..default()
            })),
        )
    }
}

/// Where balls are thrown from, and at what (one every three seconds, alternating).
#[derive(Component)]
struct Thrower {
    targets: [(Vec3, Vec3); 2],
    next: f32,
    count: usize,
}

fn throw_balls(
    time: Res<Time<Fixed>>,
    mut throwers: Query<&mut Thrower>,
    mut commands: Commands,
    mut meshes: Option<ResMut<Assets<Mesh>>>,
    mut materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    for mut t in &mut throwers {
        if time.elapsed_secs() < t.next {
            continue;
        }
        t.next += 3.0;
        let (from, velocity) = t.targets[t.count % 2];
        t.count += 1;
        let mut ball = commands.spawn((
            Name::new("thrown ball"),
            RigidBody::Dynamic,
            Collider::sphere(0.12),
            Mass(0.6),
            Restitution::new(0.3),
            Transform::from_translation(from),
            LinearVelocity(velocity),
        ));
        if let (Some(meshes), Some(materials)) = (meshes.as_mut(), materials.as_mut()) {
            ball.insert((
                Mesh3d(meshes.add(Sphere::new(0.12))),
                MeshMaterial3d(materials.add(Color::srgb(0.9, 0.35, 0.2))),
            ));
        }
    }
}

/// The playground: ground, curtain, trampoline with a crate, lamp on a rope, jelly, flag on a
/// turning pole, and the ball thrower.
fn spawn_world(c: &mut Commands, mut looks: Option<&mut Looks>, body: &SoftBody, part: Part) {
    let soft = part != Part::RigidOnly;
    let rigid = part != Part::SoftOnly;
    fn with_look(
        looks: &mut Option<&mut Looks>,
        c: &mut Commands,
        e: Entity,
        mesh: Mesh,
        color: Color,
    ) {
        if let Some(l) = looks.as_mut() {
            c.entity(e).insert(l.add(mesh, color));
        }
    }
    if rigid {
        let ground = c
            .spawn((
                Name::new("ground"),
                RigidBody::Static,
                Collider::half_space(Vec3::Y),
                Transform::default(),
            ))
            .id();
        with_look(
            &mut looks,
            c,
            ground,
            Plane3d::default().mesh().size(14.0, 14.0).into(),
            Color::srgb(0.3, 0.32, 0.3),
        );
    }
    // A curtain hanging from a rail at x = −2.5.
    if soft {
        let scene = build::cloth(&build::ClothParams {
            rows: 20,
            cols: 20,
            width: 1.6,
            height: 1.6,
            mass: 0.01,
            k_structural: 400.0,
            k_shear: 200.0,
            k_flex: 40.0,
            damping: 0.1,
            drag: 0.01,
            pins: build::ClothPins::TopEdge,
            hanging: true,
            origin: [-2.5, 2.0, 0.0],
        })
        .unwrap();
        let mut scene = scene;
        scene.colliders.clear();
        c.spawn_soft_body(&scene, body.clone()).unwrap();
    }
    // A trampoline at x = 0.3, 0.8 m up, and a 10 kg crate dropped on it.
    if soft {
        let n = 17;
        let mut scene = build::cloth(&build::ClothParams {
            rows: n,
            cols: n,
            width: 1.6,
            height: 1.6,
            mass: 0.02,
            k_structural: 3000.0,
            k_shear: 500.0,
            k_flex: 100.0,
            damping: 2.0,
            drag: 0.05,
            pins: build::ClothPins::Border,
            hanging: false,
            origin: [0.3, 0.8, 0.0],
        })
        .unwrap();
        scene.colliders.clear();
        c.spawn_soft_body(&scene, body.clone()).unwrap();
    }
    if rigid {
        let krate = c
            .spawn((
                Name::new("crate"),
                RigidBody::Dynamic,
                Collider::cuboid(0.4, 0.4, 0.4),
                Mass(10.0),
                Friction::new(0.5),
                Transform::from_xyz(0.3, 1.8, 0.0).with_rotation(Quat::from_rotation_y(0.4)),
            ))
            .id();
        with_look(
            &mut looks,
            c,
            krate,
            Cuboid::new(0.4, 0.4, 0.4).into(),
            Color::srgb(0.6, 0.45, 0.25),
        );
    }
    // A lamp (2 kg) hanging from a rope of 12 springs fixed at (2.6, 2.6, −0.8), swinging.
    let lamp = rigid.then(|| {
        let lamp = c
            .spawn((
                Name::new("lamp"),
                RigidBody::Dynamic,
                Collider::sphere(0.15),
                Mass(2.0),
                Transform::from_xyz(3.71, 2.0, -0.8),
            ))
            .id();
        with_look(
            &mut looks,
            c,
            lamp,
            Sphere::new(0.15).into(),
            Color::srgb(0.95, 0.85, 0.4),
        );
        lamp
    });
    if soft {
        let mut scene = build::chain(&build::ChainParams {
            particles: 13,
            link: 0.1,
            mass: 0.02,
            stiffness: 8000.0,
            damping: 0.5,
            drag: 0.005,
            direction: [1.0, -0.4, 0.0],
            ..Default::default()
        })
        .unwrap()
        .translated([2.6, 2.6, -0.8]);
        scene.gravity = [0.0, -9.81, 0.0];
        // The rope's end is hung on the lamp in `hang_lamp` once both exist.
        let rope = c.spawn_soft_body(&scene, body.clone()).unwrap();
        if let Some(lamp) = lamp {
            c.spawn(HangLamp { rope, lamp });
        }
    }
    // A pool at x = 2.3: water (a buoyancy field on the jelly, region and level as drawn) that
    // a jelly floats in, half under (its particles, 20 g on a 0.1 m grid, stand for 20 kg/m³;
    // the "water" is 40 kg/m³), and balls are thrown at.
    if let Some(l) = looks.as_mut() {
        let water = l.materials.add(StandardMaterial {
            base_color: Color::srgba(0.2, 0.45, 0.8, 0.45),
            alpha_mode: AlphaMode::Blend,
            ..default()
        });
        c.spawn((
            Name::new("water"),
            Mesh3d(l.meshes.add(Cuboid::new(1.4, 0.3, 1.4))),
            MeshMaterial3d(water),
            Transform::from_xyz(2.3, 0.15, 0.9),
        ));
    }
    if soft {
        let mut scene = build::jelly(&build::JellyParams {
            size: [5, 5, 5],
            spacing: 0.1,
            mass: 0.02,
            stiffness: [200.0, 100.0, 50.0],
            damping: 0.1,
            drop_height: 0.0,
            ..Default::default()
        })
        .unwrap()
        .translated([2.3, 0.1, 0.9]);
        scene.colliders.clear();
        let jelly = c.spawn_soft_body(&scene, body.clone()).unwrap();
        c.entity(jelly)
            .insert(SoftBodyForceFields(vec![std::sync::Arc::new(Buoyancy {
                level: 0.3,
                fluid_density: 40.0,
                body_density: 20.0,
                gravity: 9.81,
                layer: 0.1,
                drag: 2.0,
                region: Some(([1.6, 0.2], [3.0, 1.6])),
            })]));
    }
    // A flag on a kinematic pole turning about its axis at 0.8 rad/s.
    let pole = rigid.then(|| {
        let pole = c
            .spawn((
                Name::new("flag pole"),
                RigidBody::Kinematic,
                Collider::cylinder(0.03, 2.4),
                Transform::from_xyz(-0.6, 1.2, -1.6),
                AngularVelocity(Vec3::Y * 0.8),
            ))
            .id();
        with_look(
            &mut looks,
            c,
            pole,
            Cylinder::new(0.03, 2.4).into(),
            Color::srgb(0.6, 0.6, 0.65),
        );
        pole
    });
    if soft {
        let mut scene = build::cloth(&build::ClothParams {
            rows: 10,
            cols: 14,
            width: 0.9,
            height: 0.6,
            mass: 0.005,
            k_structural: 300.0,
            k_shear: 150.0,
            k_flex: 20.0,
            damping: 0.05,
            drag: 0.01,
            pins: build::ClothPins::None,
            hanging: true,
            origin: [-0.6 + 0.45 + 0.04, 2.35, -1.6],
        })
        .unwrap();
        scene.colliders.clear();
        let flag = c.spawn_soft_body(&scene, body.clone()).unwrap();
        if let Some(pole) = pole {
            c.spawn(PinFlag {
                flag,
                pole,
                cols: 14,
            });
        }
    }
    if rigid {
        c.spawn(Thrower {
            targets: [
                (Vec3::new(-2.3, 1.3, 3.0), Vec3::new(0.0, 1.5, -7.0)),
                (Vec3::new(2.5, 0.8, 4.0), Vec3::new(0.0, 0.5, -6.0)),
            ],
            next: 1.0,
            count: 0,
        });
    }
}

/// Hangs the rope's last particle on the lamp (one-shot, once the rope's particles exist).
#[derive(Component)]
struct HangLamp {
    rope: Entity,
    lamp: Entity,
}

/// Pins the flag's first column to the pole (one-shot).
#[derive(Component)]
struct PinFlag {
    flag: Entity,
    pole: Entity,
    cols: usize,
}

fn attach(
    hang: Query<(Entity, &HangLamp)>,
    flags: Query<(Entity, &PinFlag)>,
    bodies: Query<&BodyParticles>,
    particles: Query<&Particle>,
    transforms: Query<&GlobalTransform>,
    mut commands: Commands,
) {
    for (e, h) in &hang {
        if let Ok(ps) = bodies.get(h.rope)
            && let Some(&last) = ps.entities().last()
        {
            commands
                .entity(last)
                .insert(Pinned::to(h.lamp, Vec3::Y * 0.15));
            commands.entity(e).despawn();
        }
    }
    for (e, f) in &flags {
        let (Ok(ps), Ok(pole)) = (bodies.get(f.flag), transforms.get(f.pole)) else {
            continue;
        };
        // Row-major: column 0 of every row is the edge at the pole.
        for (k, &p) in ps.entities().iter().enumerate() {
            if k % f.cols == 0
                && let Ok(q) = particles.get(p)
            {
                let offset = pole.affine().inverse().transform_point3(q.position);
                commands.entity(p).insert(Pinned::to(f.pole, offset));
            }
        }
        commands.entity(e).despawn();
    }
}

/// The coupled scene, the soft bodies alone and the rigid bodies alone, headless: ms per fixed
/// frame after a second of warm-up.
fn bench(frames: usize) {
    println!("| world | frames | ms per fixed frame |");
    println!("| --- | ---: | ---: |");
    for (name, part) in [
        ("soft bodies and rigid bodies, coupled", Part::Both),
        ("soft bodies alone", Part::SoftOnly),
        ("rigid bodies alone (avian)", Part::RigidOnly),
    ] {
        let mut app = App::new();
        app.add_plugins((
            MinimalPlugins,
            TransformPlugin,
            SoftBodyPlugins::default()
                .build()
                .disable::<SoftBodyUiPlugin>(),
        ))
        .insert_resource(Time::<Fixed>::from_hz(60.0))
        .insert_resource(bevy::time::TimeUpdateStrategy::FixedTimesteps(1))
        .add_systems(FixedUpdate, throw_balls)
        .add_systems(Update, attach);
        if part != Part::SoftOnly {
            app.add_plugins(PhysicsPlugins::default());
        }
        app.finish();
        app.cleanup();
        let body = SoftBody {
            integrator: IntegratorKind::SymplecticEuler,
            step: StepPolicy::Fixed { h: 1.0 / 1200.0 },
            ..default()
        };
        app.world_mut()
            .run_system_once(move |mut c: Commands| spawn_world(&mut c, None, &body, part))
            .expect("spawns");
        for _ in 0..60 {
            app.update();
        }
        let start = std::time::Instant::now();
        for _ in 0..frames {
            app.update();
        }
        let ms = start.elapsed().as_secs_f64() * 1e3 / frames as f64;
        println!("| {name} | {frames} | {ms:.3} |");
    }
}

/// O: a ball at the curtain; C: a crate over the trampoline; F: a blast in front of the
/// curtain (the panel's integrator keys keep their letters).
fn keys(
    input: Res<ButtonInput<KeyCode>>,
    clock: Res<SoftBodyClock>,
    mut fields: ResMut<GlobalForceFields>,
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut count: Local<u32>,
) {
    // A little spread so that repeated drops do not stack exactly.
    let jitter = |k: u32| ((k * 7919 % 13) as f32 / 13.0 - 0.5) * 0.4;
    if input.just_pressed(KeyCode::KeyO) {
        *count += 1;
        commands.spawn((
            Name::new("thrown ball"),
            RigidBody::Dynamic,
            Collider::sphere(0.12),
            Mass(0.6),
            Restitution::new(0.3),
            Transform::from_xyz(-2.5 + jitter(*count), 1.3, 3.0),
            LinearVelocity(Vec3::new(0.0, 1.5, -7.0)),
            Mesh3d(meshes.add(Sphere::new(0.12))),
            MeshMaterial3d(materials.add(Color::srgb(0.9, 0.35, 0.2))),
        ));
    }
    if input.just_pressed(KeyCode::KeyF) {
        // A blast of 0.15 s, 0.4 m in front of the curtain: every soft body near it is pushed
        // (the field acts on all bodies; far away its push is nil).
        fields.0 = vec![std::sync::Arc::new(RadialBlast {
            center: [-2.5, 1.2, 0.4],
            strength: 80.0,
            radius: 0.8,
            start: clock.elapsed,
            duration: 0.15,
        })];
    }
    if input.just_pressed(KeyCode::KeyC) {
        *count += 1;
        commands.spawn((
            Name::new("crate"),
            RigidBody::Dynamic,
            Collider::cuboid(0.3, 0.3, 0.3),
            Mass(4.0),
            Friction::new(0.5),
            Transform::from_xyz(0.3 + jitter(*count), 2.2, jitter(*count + 5))
                .with_rotation(Quat::from_rotation_y(jitter(*count) * 3.0)),
            Mesh3d(meshes.add(Cuboid::new(0.3, 0.3, 0.3))),
            MeshMaterial3d(materials.add(Color::srgb(0.55, 0.4, 0.22))),
        ));
    }
}

/// What the soft bodies gave each rigid body last frame, and the momenta of the coupled
/// bodies: the rigid bodies touched, the soft bodies, and their sum.
fn coupling_panel(
    mut contexts: bevy_egui::EguiContexts,
    rigid: Query<(
        Entity,
        Option<&Name>,
        &SoftBodyImpulse,
        &ComputedMass,
        &LinearVelocity,
    )>,
    particles: Query<&Particle>,
) -> Result {
    use bevy_egui::egui;
    let ctx = contexts.ctx_mut()?;
    let mut p_rigid = Vec3::ZERO;
    egui::Window::new("coupling")
        .anchor(egui::Align2::RIGHT_TOP, [-8.0, 8.0])
        .default_width(300.0)
        .show(ctx, |ui| {
            egui::Grid::new("impulses").striped(true).show(ui, |ui| {
                ui.label("rigid body");
                ui.label("impulse (N·s)");
                ui.label("contacts");
                ui.end_row();
                for (e, name, imp, mass, v) in &rigid {
                    if imp.contacts == 0 && imp.linear == Vec3::ZERO {
                        continue;
                    }
                    p_rigid += v.0 * mass.value();
                    ui.label(name.map_or(format!("{e}"), |n| n.to_string()));
                    ui.label(format!(
                        "{:+.3} {:+.3} {:+.3}",
                        imp.linear.x, imp.linear.y, imp.linear.z
                    ));
                    ui.label(format!("{}", imp.contacts));
                    ui.end_row();
                }
            });
            let p_soft: Vec3 = particles.iter().map(|p| p.velocity * p.mass).sum();
            ui.separator();
            ui.label(format!(
                "momentum of the rigid bodies touched: {p_rigid:.3} kg·m/s"
            ));
            ui.label(format!("momentum of the soft bodies: {p_soft:.3} kg·m/s"));
            ui.label(format!("sum: {:.3} kg·m/s", p_rigid + p_soft));
        });
    Ok(())
}
