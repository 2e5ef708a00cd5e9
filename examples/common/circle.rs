//! The cloth assignment's first system, `dx/dt = (−y, x, 0)` from (1, 0, 0): the exact solution is the unit
//! circle, so the drift of |x| from 1 shows each method's character at a glance (forward Euler
//! spirals out, the trapezoid and RK4 hold it). A first-order system of one vector: it runs
//! through the core's integrators directly, with no particles, springs or ECS machinery.

use bevy::prelude::*;
use bevy_egui::{EguiContexts, EguiPrimaryContextPass, egui};
use bevy_soft_body::math::VectorExt;
use bevy_soft_body::prelude::*;

/// The circle's simulation, drawn at `origin` with radius `scale`.
#[derive(Resource)]
pub struct CircleSim {
    sim: Simulation<Vector, CircleSystem>,
    trail: Vec<Vec3>,
    origin: Vec3,
    scale: f32,
    h: f64,
}

fn new_sim(kind: IntegratorKind, h: f64) -> Simulation<Vector, CircleSystem> {
    Simulation::new(
        CircleSystem,
        Vector::X,
        DriverConfig {
            integrator: kind,
            policy: StepPolicy::Fixed { h },
            frame_dt: 1.0 / 60.0,
            energy_guard: None,
            ..Default::default()
        },
    )
}

/// Adds the circle to the app: stepping with the plugin's clock (Space, N, R apply), the
/// integrator letters, gizmo drawing and a small egui window.
pub fn add(app: &mut App, kind: IntegratorKind, h: f64, origin: Vec3, scale: f32) {
    app.insert_resource(CircleSim {
        sim: new_sim(kind, h),
        trail: vec![],
        origin,
        scale,
        h,
    })
    .add_systems(FixedUpdate, step.after(SoftBodySystems::Writeback))
    .add_systems(Update, (keys, draw))
    .add_systems(EguiPrimaryContextPass, window);
}

fn step(
    clock: Res<SoftBodyClock>,
    mut c: ResMut<CircleSim>,
    mut reset: MessageReader<ResetSoftBodies>,
) {
    if reset.read().count() > 0 {
        let (kind, h) = (c.sim.config().integrator, c.h);
        c.sim = new_sim(kind, h);
        c.trail.clear();
    }
    // `tick` has already advanced the clock when it ran this step; the circle follows it.
    if clock.paused && clock.elapsed <= c.sim.time as f64 {
        return;
    }
    if c.sim.advance_frame().is_ok() {
        let p = c.origin + c.sim.state.to_f32() * c.scale;
        c.trail.push(p);
        if c.trail.len() > 2000 {
            c.trail.remove(0);
        }
    }
}

fn keys(input: Res<ButtonInput<KeyCode>>, mut c: ResMut<CircleSim>) {
    for kind in IntegratorKind::EXPLICIT {
        let key = match kind.letter() {
            'e' => KeyCode::KeyE,
            's' => KeyCode::KeyS,
            't' => KeyCode::KeyT,
            'm' => KeyCode::KeyM,
            'r' => KeyCode::KeyK,
            'a' => KeyCode::KeyA,
            _ => continue,
        };
        if input.just_pressed(key) {
            let h = c.h;
            c.sim = new_sim(kind, h);
            c.trail.clear();
        }
    }
}

fn draw(c: Res<CircleSim>, mut gizmos: Gizmos) {
    let iso = Isometry3d::new(c.origin, Quat::from_rotation_arc(Vec3::Z, Vec3::Z));
    gizmos.circle(iso, c.scale, Color::srgb(0.5, 0.5, 0.55));
    gizmos.linestrip(c.trail.iter().copied(), Color::srgb(0.3, 0.8, 1.0));
    if let Some(p) = c.trail.last() {
        gizmos.sphere(
            Isometry3d::from_translation(*p),
            0.03 * c.scale.max(0.5),
            Color::srgb(1.0, 0.6, 0.1),
        );
    }
}

fn window(c: Res<CircleSim>, mut contexts: EguiContexts) -> Result {
    let x = c.sim.state;
    let t = c.sim.time;
    let exact = CircleSystem::exact(Vector::X, t);
    egui::Window::new("circle  dx/dt = (−y, x, 0)")
        .anchor(egui::Align2::RIGHT_TOP, [-8.0, 8.0])
        .resizable(false)
        .show(contexts.ctx_mut()?, |ui| {
            ui.label(format!(
                "{}  h = {:.4} s\nt = {:.2} s  |x| − 1 = {:+.3e}\nerror vs exact = {:.3e}",
                c.sim.config().integrator.label(),
                c.h.min(1.0 / 60.0),
                t,
                x.length() - 1.0,
                (x - exact).length()
            ));
            ui.small("E S T M K A switch method (circle)");
        });
    Ok(())
}
