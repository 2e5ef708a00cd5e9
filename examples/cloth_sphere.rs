//! The main job: a 32×32 cloth held by its two top corners, and a sphere swinging back and
//! forth through it, smooth shaded. Like the classic sample solution, the integrator letter
//! and step size come from the command line:
//!
//! ```text
//! cargo run --release --example cloth_sphere              # RK4, h = 0.0025
//! cargo run --release --example cloth_sphere -- r 0.005   # RK4 at twice the step: diverges, and says so
//! cargo run --release --example cloth_sphere -- s 0.001   # symplectic Euler
//! cargo run --release --example cloth_sphere -- t 0.001 --size 24
//! ```
//!
//! Letters: e forward Euler, s symplectic Euler, t trapezoid, m midpoint, r RK4, a RK45,
//! i linearly implicit Euler (`cloth_sphere -- i 0.0167`: h above the 1/60 s frame, so each frame is one step),
//! d trapezoid with implicit damping, b backward Euler (Newton).
//!
//! Keys: Space pause/resume, R reset, E/S/T/M/K/A/I/D/B switch integrator (K = RK4),
//! Left/Right orbit the camera, Up/Down zoom.
//!
//! `--screenshot FILE [--frames N]` renders N frames of exactly 1/60 s each (default 270, the
//! sphere swinging out through the cloth at t = 4.5 s), saves a PNG and exits.
//!
//! This example drives the core's headless [`Simulation`] from a Bevy system and draws its
//! state; it shows what the numerics do before the ECS plugin (components per particle and
//! spring) exists.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, save_to_disk};
use bevy_egui::{EguiContexts, EguiPlugin, EguiPrimaryContextPass, egui};
use bevy_soft_body::core::collide::ShapeDesc;
use bevy_soft_body::core::motion::Motion;
use bevy_soft_body::math::to_f32;
use bevy_soft_body::prelude::*;

/// The simulation and how to rebuild it.
#[derive(Resource)]
struct ClothSim {
    sim: Simulation<ParticleState, ParticleModel>,
    scene: Scene,
    config: DriverConfig,
    paused: bool,
    status: String,
}

impl ClothSim {
    fn reset(&mut self) {
        let (model, state) = self.scene.build().expect("built-in scene is valid");
        self.sim = Simulation::new(model, state, self.config);
        self.paused = false;
        self.status.clear();
    }
}

#[derive(Component)]
struct ClothMesh(Handle<Mesh>);

#[derive(Component)]
struct Ball {
    motion: Motion,
}

#[derive(Resource)]
struct Orbit {
    yaw: f32,
    distance: f32,
}

#[derive(Resource)]
struct ShotPlan {
    path: String,
    frames: u32,
    seen: u32,
    taken: bool,
    wait: u32,
}

struct Args {
    integrator: IntegratorKind,
    h: f64,
    size: usize,
    screenshot: Option<String>,
    frames: u32,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        integrator: IntegratorKind::Rk4,
        h: 0.0025,
        size: 32,
        screenshot: None,
        frames: 270,
    };
    let mut positional = 0;
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--size" => {
                a.size = it
                    .next()
                    .and_then(|s| s.parse().ok())
                    .ok_or("--size needs a count")?
            }
            "--screenshot" => a.screenshot = Some(it.next().ok_or("--screenshot needs a file")?),
            "--frames" => {
                a.frames = it
                    .next()
                    .and_then(|s| s.parse().ok())
                    .ok_or("--frames needs a count")?
            }
            _ if positional == 0 => {
                a.integrator = arg.parse().map_err(|e| format!("{e}"))?;
                positional += 1;
            }
            _ if positional == 1 => {
                a.h = arg
                    .parse()
                    .map_err(|_| format!("step size '{arg}' is not a number"))?;
                if !(a.h.is_finite() && a.h > 0.0) {
                    return Err(format!("step size must be positive, got {arg}"));
                }
                positional += 1;
            }
            _ => return Err(format!("unexpected argument '{arg}'")),
        }
    }
    if !(3..=256).contains(&a.size) {
        return Err(format!("--size must be between 3 and 256, got {}", a.size));
    }
    Ok(a)
}

fn main() {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!(
                "error: {e}\nusage: cloth_sphere [LETTER [H]] [--size N] [--screenshot FILE [--frames N]]"
            );
            std::process::exit(1);
        }
    };
    // A 4× stiffer cloth than the 16×16 reference, so it stretches little when held by two
    // corners; its fastest mode then has h ω ≈ 2.4 at h = 0.0025 (RK4's bound is 2.83).
    let base = build::ClothParams {
        k_structural: 400.0,
        k_shear: 200.0,
        k_flex: 80.0,
        damping: 0.1,
        ..Default::default()
    };
    let params = base.resized(args.size, args.size);
    let scene = build::cloth_sphere(&params, 0.25, 0.6, 4.0).expect("valid cloth size");
    let config = DriverConfig {
        integrator: args.integrator,
        policy: StepPolicy::Fixed { h: args.h },
        frame_dt: 1.0 / 60.0,
        // This scene's internal energy stays far below its energy scale (the cloth swings under
        // gravity, the sphere moves at ~1 m/s), so a guard of 10× stops a diverging method
        // while the last good frame still looks like a cloth.
        energy_guard: Some(10.0),
        ..Default::default()
    };
    let (model, state) = scene.build().expect("built-in scene is valid");
    let sim = ClothSim {
        sim: Simulation::new(model, state, config),
        scene,
        config,
        paused: false,
        status: String::new(),
    };

    let mut app = App::new();
    app.add_plugins(DefaultPlugins.set(WindowPlugin {
        primary_window: Some(Window {
            title: "bevy_soft_body: cloth and sphere".into(),
            ..default()
        }),
        ..default()
    }))
    .insert_resource(Time::<Fixed>::from_hz(60.0))
    .insert_resource(ClearColor(Color::srgb(0.09, 0.10, 0.12)))
    .insert_resource(sim)
    .insert_resource(Orbit {
        yaw: 0.5,
        distance: 2.4,
    })
    .add_systems(Startup, setup)
    .add_systems(FixedUpdate, step)
    .add_plugins(EguiPlugin::default())
    .add_systems(Update, (keys, sync_cloth, sync_ball, camera))
    .add_systems(EguiPrimaryContextPass, hud);
    if let Some(path) = args.screenshot {
        // Deterministic: every rendered frame advances exactly one 1/60 s fixed step, however
        // slow the renderer, so frame N shows t = N/60.
        app.insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            std::time::Duration::from_secs_f64(1.0 / 60.0),
        ))
        .insert_resource(ShotPlan {
            path,
            frames: args.frames,
            seen: 0,
            taken: false,
            wait: 0,
        })
        .add_systems(Update, screenshot);
    }
    app.run();
}

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    sim: Res<ClothSim>,
) {
    let surface = sim.scene.surface.clone().unwrap_or_default();
    let positions = mesh_positions(&sim.sim.state);
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::MAIN_WORLD | RenderAssetUsages::RENDER_WORLD,
    );
    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_0, surface.uvs.clone());
    mesh.insert_indices(Indices::U32(
        surface.triangles.iter().flatten().copied().collect(),
    ));
    mesh.compute_smooth_normals();
    let handle = meshes.add(mesh);
    commands.spawn((
        Mesh3d(handle.clone()),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.85, 0.25, 0.22),
            perceptual_roughness: 0.8,
            double_sided: true,
            cull_mode: None,
            ..default()
        })),
        Transform::IDENTITY,
        ClothMesh(handle),
    ));
    for c in &sim.scene.colliders {
        if let ShapeDesc::Sphere { radius } = c.shape {
            commands.spawn((
                // Drawn slightly smaller than the collider plus its contact thickness, so the
                // cloth rests visibly on the surface rather than inside it.
                Mesh3d(meshes.add(Sphere::new(radius as f32).mesh().uv(48, 24))),
                MeshMaterial3d(materials.add(StandardMaterial {
                    base_color: Color::srgb(0.75, 0.78, 0.82),
                    metallic: 0.2,
                    perceptual_roughness: 0.4,
                    ..default()
                })),
                Transform::from_translation(to_f32(c.motion.position(0.0))),
                Ball { motion: c.motion },
            ));
        }
    }
    commands.spawn((
        DirectionalLight {
            illuminance: 9000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(2.0, 4.0, 3.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    commands.spawn((
        PointLight {
            intensity: 400_000.0,
            range: 20.0,
            ..default()
        },
        Transform::from_xyz(-2.5, 2.0, -2.0),
    ));
    commands.spawn((
        Camera3d::default(),
        Transform::from_xyz(0.0, 0.6, 3.2).looking_at(Vec3::new(0.0, 0.45, 0.0), Vec3::Y),
    ));
}

/// Particle positions as Bevy mesh vertex positions.
fn mesh_positions(state: &ParticleState) -> Vec<[f32; 3]> {
    state.x.iter().map(|x| to_f32(*x).to_array()).collect()
}

fn step(mut sim: ResMut<ClothSim>) {
    if sim.paused {
        return;
    }
    if let Err(d) = sim.sim.advance_frame() {
        warn!("{d}");
        sim.status = format!("DIVERGED: {d}\nPress R to reset, or pick another method.");
        sim.paused = true;
    }
}

fn keys(
    input: Res<ButtonInput<KeyCode>>,
    mut sim: ResMut<ClothSim>,
    mut orbit: ResMut<Orbit>,
    time: Res<Time>,
) {
    if input.just_pressed(KeyCode::Space) {
        sim.paused = !sim.paused;
    }
    if input.just_pressed(KeyCode::KeyR) {
        sim.reset();
    }
    for (key, kind) in [
        (KeyCode::KeyE, IntegratorKind::ForwardEuler),
        (KeyCode::KeyS, IntegratorKind::SymplecticEuler),
        (KeyCode::KeyT, IntegratorKind::Trapezoid),
        (KeyCode::KeyM, IntegratorKind::Midpoint),
        (KeyCode::KeyK, IntegratorKind::Rk4),
        (KeyCode::KeyA, IntegratorKind::Rk45),
        (KeyCode::KeyI, IntegratorKind::LinearlyImplicitEuler),
        (KeyCode::KeyD, IntegratorKind::ImplicitDampingTrapezoid),
        (KeyCode::KeyB, IntegratorKind::BackwardEuler),
    ] {
        if input.just_pressed(key) {
            sim.config.integrator = kind;
            sim.sim.set_integrator(kind);
        }
    }
    let dt = time.delta_secs();
    if input.pressed(KeyCode::ArrowLeft) {
        orbit.yaw -= dt;
    }
    if input.pressed(KeyCode::ArrowRight) {
        orbit.yaw += dt;
    }
    if input.pressed(KeyCode::ArrowUp) {
        orbit.distance = (orbit.distance - 2.0 * dt).max(1.0);
    }
    if input.pressed(KeyCode::ArrowDown) {
        orbit.distance = (orbit.distance + 2.0 * dt).min(10.0);
    }
}

fn sync_cloth(sim: Res<ClothSim>, q: Query<&ClothMesh>, mut meshes: ResMut<Assets<Mesh>>) {
    if !sim.is_changed() {
        return;
    }
    for cm in &q {
        let Some(mut mesh) = meshes.get_mut(&cm.0) else {
            continue;
        };
        // The driver restores the last good state on divergence, so this is always finite.
        let positions = mesh_positions(&sim.sim.state);
        mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
        mesh.compute_smooth_normals();
    }
}

fn sync_ball(sim: Res<ClothSim>, mut q: Query<(&Ball, &mut Transform)>) {
    for (b, mut t) in &mut q {
        t.translation = to_f32(b.motion.position(sim.sim.time));
    }
}

fn camera(orbit: Res<Orbit>, mut q: Query<&mut Transform, With<Camera3d>>) {
    let target = Vec3::new(0.0, 0.45, 0.0);
    for mut t in &mut q {
        let eye = target
            + Vec3::new(
                orbit.distance * orbit.yaw.sin(),
                0.3,
                orbit.distance * orbit.yaw.cos(),
            );
        *t = Transform::from_translation(eye).looking_at(target, Vec3::Y);
    }
}

fn hud(sim: Res<ClothSim>, mut contexts: EguiContexts) -> Result {
    let st = sim.sim.stats();
    let n = sim.sim.system.len();
    let text = format!(
        "{} particles, {} springs  [{}]\n{}  h = {}  t = {:.2} s  steps {}  evaluations {}  CG iterations {}{}\n{}",
        n,
        sim.sim.system.springs.len(),
        bevy_soft_body::math::PRECISION,
        sim.config.integrator.label(),
        match sim.config.policy {
            StepPolicy::Fixed { h } => h,
            StepPolicy::Cfl { max, .. } => max,
        },
        sim.sim.time,
        st.steps,
        st.evaluations,
        st.linear_iterations,
        if sim.paused && sim.status.is_empty() {
            "  (paused)"
        } else {
            ""
        },
        sim.status
    );
    egui::Window::new("cloth_sphere")
        .anchor(egui::Align2::LEFT_TOP, [8.0, 8.0])
        .resizable(false)
        .show(contexts.ctx_mut()?, |ui| {
            ui.label(text);
            ui.small("Space pause · R reset · E S T M K A I method · arrows orbit/zoom");
        });
    Ok(())
}

fn screenshot(
    mut commands: Commands,
    mut plan: ResMut<ShotPlan>,
    mut exit: MessageWriter<AppExit>,
) {
    plan.seen += 1;
    if !plan.taken && plan.seen >= plan.frames {
        commands
            .spawn(Screenshot::primary_window())
            .observe(save_to_disk(plan.path.clone()));
        plan.taken = true;
    }
    if plan.taken {
        plan.wait += 1;
        if plan.wait > 30 && std::path::Path::new(&plan.path).exists() {
            exit.write(AppExit::Success);
        }
        if plan.wait > 600 {
            error!("screenshot was not written");
            exit.write(AppExit::error());
        }
    }
}
