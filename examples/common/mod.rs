//! What every windowed example shares: the App (window, `SoftBodyPlugins` with the
//! `SoftBodyUiPlugin` panel and keys, 60 Hz fixed step), lights, an orbit camera, the
//! `LETTER H` arguments of the classic sample solution, `--size N` for the cloth examples and
//! `--screenshot FILE [--frames N]` (N frames of exactly 1/60 s, default 150, then a PNG,
//! then exit). Not an example itself.

#![allow(dead_code)]
// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy::input::mouse::{AccumulatedMouseMotion, AccumulatedMouseScroll};
use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, save_to_disk};
use bevy_soft_body::prelude::*;

/// Command line: `[LETTER [H]] [--size N] [--detail L] [--screenshot FILE] [--frames N]`.
pub struct Args {
    /// Integrator, when given.
    pub integrator: Option<IntegratorKind>,
    /// Step size, when given.
    pub h: Option<f64>,
    /// Cloth resolution, when given (3 to 256).
    pub size: Option<usize>,
    /// Level of detail to draw cloth surfaces at (`SurfaceDetail`), when given.
    pub detail: Option<u32>,
    screenshot: Option<String>,
    frames: u32,
}

/// Parses the arguments, or prints `usage` and exits.
pub fn args(usage: &str) -> Args {
    args_with(usage, &[])
}

/// [`args`], with the example's own switches `flags` (read by the example) let through.
pub fn args_with(usage: &str, flags: &[&str]) -> Args {
    let mut a = Args {
        integrator: None,
        h: None,
        size: None,
        detail: None,
        screenshot: None,
        frames: 150,
    };
    let mut it = std::env::args().skip(1);
    let fail = |e: String| -> ! {
        eprintln!(
            "error: {e}\nusage: {usage} {} [LETTER [H]] [--size N] [--detail L] [--screenshot FILE [--frames N]]",
            flags
                .iter()
                .map(|f| format!("[{f}]"))
                .collect::<Vec<_>>()
                .join(" ")
        );
        std::process::exit(1)
    };
    while let Some(arg) = it.next() {
        match arg.as_str() {
            f if flags.contains(&f) => {}
            "--screenshot" => {
                a.screenshot = Some(
                    it.next()
                        .unwrap_or_else(|| fail("--screenshot needs a file".into())),
                )
            }
            "--size" => {
                let n = it
                    .next()
                    .and_then(|s| s.parse().ok())
                    .unwrap_or_else(|| fail("--size needs a count".into()));
                if !(3..=256).contains(&n) {
                    fail(format!("--size must be between 3 and 256, got {n}"));
                }
                a.size = Some(n);
            }
            "--detail" => {
                let l = it
                    .next()
                    .and_then(|s| s.parse().ok())
                    .unwrap_or_else(|| fail("--detail needs a level".into()));
                if let Err(why) = SurfaceDetail::level(l).validate() {
                    fail(format!("--detail: {why}"));
                }
                a.detail = Some(l);
            }
            "--frames" => {
                a.frames = it
                    .next()
                    .and_then(|s| s.parse().ok())
                    .unwrap_or_else(|| fail("--frames needs a count".into()))
            }
            _ if a.integrator.is_none() => {
                a.integrator = Some(arg.parse().unwrap_or_else(|e| fail(format!("{e}"))))
            }
            _ if a.h.is_none() => {
                let h: f64 = arg
                    .parse()
                    .unwrap_or_else(|_| fail(format!("step size '{arg}' is not a number")));
                if !(h.is_finite() && h > 0.0) {
                    fail(format!("step size must be positive, got {arg}"));
                }
                a.h = Some(h);
            }
            _ => fail(format!("unexpected argument '{arg}'")),
        }
    }
    a
}

impl Args {
    /// The body settings: the arguments over the example's defaults.
    pub fn body(&self, integrator: IntegratorKind, h: f64) -> SoftBody {
        SoftBody {
            integrator: self.integrator.unwrap_or(integrator),
            step: StepPolicy::Fixed {
                h: self.h.unwrap_or(h),
            },
            ..Default::default()
        }
    }
}

#[derive(Resource)]
struct ShotPlan {
    path: String,
    frames: u32,
    seen: u32,
    taken: bool,
    wait: u32,
}

/// The App every example starts from.
pub fn app(title: &str, args: &Args) -> App {
    let mut app = App::new();
    app.add_plugins(DefaultPlugins.set(WindowPlugin {
        primary_window: Some(Window {
            title: format!("bevy_soft_body: {title}"),
            ..default()
        }),
        ..default()
    }))
    .add_plugins(SoftBodyPlugins::default())
    .register_type::<OrbitCamera>()
    .add_systems(Update, orbit)
    .insert_resource(Time::<Fixed>::from_hz(60.0))
    .insert_resource(ClearColor(Color::srgb(0.09, 0.10, 0.12)));
    if let Some(path) = &args.screenshot {
        app.insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            std::time::Duration::from_secs_f64(1.0 / 60.0),
        ))
        .insert_resource(ShotPlan {
            path: path.clone(),
            frames: args.frames,
            seen: 0,
            taken: false,
            wait: 0,
        })
        .add_systems(Update, screenshot);
    }
    app
}

/// A key light with shadows, a fill light and an orbit camera looking at `target`.
pub fn stage(commands: &mut Commands, target: Vec3, distance: f32) {
    stage_with(
        commands,
        OrbitCamera {
            target,
            yaw: 0.5,
            pitch: 0.25,
            distance,
        },
    );
}

/// The cloth of `cloth_sphere` and `three_systems`: 4× stiffer than the 16×16 reference, so
/// it stretches little when held by two corners; at 32×32 its fastest mode has h ω ≈ 2.4 at
/// h = 0.0025 (RK4's bound is 2.83).
pub fn stiff_cloth(size: usize) -> build::ClothParams {
    build::ClothParams {
        k_structural: 400.0,
        k_shear: 200.0,
        k_flex: 80.0,
        damping: 0.1,
        ..Default::default()
    }
    .resized(size, size)
}

/// The lights and the given orbit camera.
pub fn stage_with(commands: &mut Commands, camera: OrbitCamera) {
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
            range: 30.0,
            ..default()
        },
        Transform::from_xyz(-2.5, 2.5, -2.0),
    ));
    commands.spawn(camera);
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

pub mod circle;

/// A camera that orbits `target` (right-drag or arrows; wheel or Up/Down zoom).
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug)]
#[require(Camera3d)]
pub struct OrbitCamera {
    /// The point looked at.
    pub target: Vec3,
    /// Angle about +Y (rad).
    pub yaw: f32,
    /// Angle above the horizon (rad).
    pub pitch: f32,
    /// Distance to the target (m).
    pub distance: f32,
}

impl Default for OrbitCamera {
    fn default() -> Self {
        Self {
            target: Vec3::ZERO,
            yaw: 0.0,
            pitch: 0.2,
            distance: 3.0,
        }
    }
}

fn orbit(
    input: Res<ButtonInput<KeyCode>>,
    buttons: Res<ButtonInput<MouseButton>>,
    motion: Res<AccumulatedMouseMotion>,
    scroll: Res<AccumulatedMouseScroll>,
    time: Res<Time>,
    mut contexts: bevy_egui::EguiContexts,
    mut q: Query<(&mut OrbitCamera, &mut Transform)>,
) {
    let over_ui = bevy_soft_body::ui::egui_wants(&mut contexts, false);
    let dt = time.delta_secs();
    for (mut o, mut tf) in &mut q {
        if input.pressed(KeyCode::ArrowLeft) {
            o.yaw -= 1.5 * dt;
        }
        if input.pressed(KeyCode::ArrowRight) {
            o.yaw += 1.5 * dt;
        }
        if input.pressed(KeyCode::ArrowUp) {
            o.distance *= 1.0 - 1.2 * dt;
        }
        if input.pressed(KeyCode::ArrowDown) {
            o.distance *= 1.0 + 1.2 * dt;
        }
        if !over_ui {
            if buttons.pressed(MouseButton::Right) {
                o.yaw -= motion.delta.x * 0.005;
                o.pitch = (o.pitch + motion.delta.y * 0.005).clamp(-1.4, 1.4);
            }
            o.distance *= (1.0 - 0.1 * scroll.delta.y).clamp(0.5, 1.5);
        }
        o.distance = o.distance.clamp(0.2, 100.0);
        let dir = Vec3::new(
            o.yaw.sin() * o.pitch.cos(),
            o.pitch.sin(),
            o.yaw.cos() * o.pitch.cos(),
        );
        *tf =
            Transform::from_translation(o.target + dir * o.distance).looking_at(o.target, Vec3::Y);
    }
}
