//! The interactive face (feature `egui`): [`SoftBodyUiPlugin`] adds an egui panel to tune and
//! inspect bodies live, the keys every example shares (switchable: [`SoftBodyUi::keys`]) and
//! grabbing particles with the mouse ([`SoftBodyUi::grab_button`]). Cameras are the app's own
//! (the examples bring an orbit camera).
//!
//! Panel: body, integrator (every kind), step `h` (log slider), stiffness, damping and drag
//! applied live, wind on/off, pause / step / reset, a live plot of kinetic, potential and
//! total energy, ms per fixed step (the body's, and every body's with Newton and CG iterations
//! from Bevy's `DiagnosticsStore`), and a particle inspector (pick particle `i`, list and
//! highlight the springs attached to it).
//!
//! Keys: Space pause/resume, N single step while paused, R reset, W wind on/off, G wireframe,
//! E/S/T/M/K/A/I/D/B/X/P integrator (forward Euler, symplectic Euler, trapezoid, midpoint, RK4,
//! RK45, linearly implicit Euler, implicit-damping trapezoid, backward Euler, XPBD, projective
//! dynamics). Mouse: left button (by default) drags the particle nearest the cursor ray with a
//! spring.

use crate::core::driver::StepPolicy;
use crate::core::integrate::IntegratorKind;
use crate::core::ode::OdeSystem;
use crate::ecs::*;
use crate::math::VectorExt;
use crate::render::{SoftBodyDebug, SoftBodyGizmos};
use bevy::prelude::*;
use bevy_egui::{EguiContexts, EguiPlugin, EguiPrimaryContextPass, egui};
use egui_plot::{Legend, Line, Plot, PlotPoints};
use std::collections::{HashMap, VecDeque};

/// The egui panel, shared keys and mouse grabbing (see the module docs).
/// Add after `DefaultPlugins` and [`SoftBodyPlugin`].
#[derive(Default)]
pub struct SoftBodyUiPlugin;

impl Plugin for SoftBodyUiPlugin {
    fn build(&self, app: &mut App) {
        if !app.is_plugin_added::<EguiPlugin>() {
            app.add_plugins(EguiPlugin::default());
        }
        app.register_type::<SoftBodyUi>()
            .init_resource::<SoftBodyUi>()
            .add_systems(Update, (keys, grab, record_energy, highlight))
            .add_systems(EguiPrimaryContextPass, panel);
    }
}

/// A particle held by the mouse.
#[derive(Clone, Copy, Debug, Reflect)]
struct Grab {
    body: Entity,
    particle: Entity,
    handle: Entity,
    anchor: Entity,
    spring: Entity,
    depth: f32,
}

/// State of the panel.
#[derive(Resource, Reflect, Clone, Debug)]
#[reflect(Resource)]
pub struct SoftBodyUi {
    /// The body the panel shows (`None`: the first one).
    pub selected: Option<Entity>,
    /// The particle the inspector shows.
    pub inspect: usize,
    /// Show the inspector's highlight.
    pub highlight: bool,
    /// Stiffness multiplier applied to every spring of the selected body.
    pub stiffness_scale: f32,
    /// Damping multiplier applied to every spring of the selected body.
    pub damping_scale: f32,
    /// Stiffness of the mouse spring relative to the body's stiffest spring.
    pub grab_stiffness: f32,
    /// The mouse button that grabs particles.
    pub grab_button: MouseButton,
    /// The shared keys (pause, step, reset, wind, wireframe, integrator letters) on; off
    /// leaves the keyboard to the app.
    pub keys: bool,
    #[reflect(ignore)]
    history: VecDeque<[f64; 4]>,
    #[reflect(ignore)]
    base: HashMap<Entity, (f32, f32)>,
    #[reflect(ignore)]
    grab: Option<Grab>,
}

impl Default for SoftBodyUi {
    fn default() -> Self {
        Self {
            selected: None,
            inspect: 0,
            highlight: true,
            stiffness_scale: 1.0,
            damping_scale: 1.0,
            grab_stiffness: 0.5,
            grab_button: MouseButton::Left,
            keys: true,
            history: VecDeque::new(),
            base: HashMap::new(),
            grab: None,
        }
    }
}

const LETTERS: [(KeyCode, IntegratorKind); 12] = [
    (KeyCode::KeyE, IntegratorKind::ForwardEuler),
    (KeyCode::KeyS, IntegratorKind::SymplecticEuler),
    (KeyCode::KeyT, IntegratorKind::Trapezoid),
    (KeyCode::KeyM, IntegratorKind::Midpoint),
    (KeyCode::KeyK, IntegratorKind::Rk4),
    (KeyCode::KeyA, IntegratorKind::Rk45),
    (KeyCode::KeyI, IntegratorKind::LinearlyImplicitEuler),
    (KeyCode::KeyD, IntegratorKind::ImplicitDampingTrapezoid),
    (KeyCode::KeyB, IntegratorKind::BackwardEuler),
    (KeyCode::KeyX, IntegratorKind::Xpbd),
    (KeyCode::KeyP, IntegratorKind::ProjectiveDynamics),
    (KeyCode::KeyU, IntegratorKind::Auto),
];

/// Whether egui is using the keyboard (`keyboard`) or the pointer: an app's own controls
/// (a camera) should then leave the input alone.
pub fn egui_wants(contexts: &mut EguiContexts, keyboard: bool) -> bool {
    contexts.ctx_mut().is_ok_and(|c| {
        if keyboard {
            c.egui_wants_keyboard_input()
        } else {
            c.egui_wants_pointer_input() || c.is_pointer_over_egui()
        }
    })
}

#[allow(clippy::too_many_arguments)]
fn keys(
    input: Res<ButtonInput<KeyCode>>,
    mut contexts: EguiContexts,
    mut clock: ResMut<SoftBodyClock>,
    mut gizmo_store: Option<ResMut<GizmoConfigStore>>,
    mut reset: MessageWriter<ResetSoftBodies>,
    mut bodies: Query<(Entity, &mut SoftBody, Option<&mut SoftBodyWind>)>,
    mut global_wind: ResMut<GlobalWind>,
    mut ui: ResMut<SoftBodyUi>,
    mut skins: Query<&mut crate::render::SkinnedSurface>,
    tet_bodies: Query<(), With<BodyTets>>,
) {
    if !ui.keys {
        return;
    }
    // Elastic-body scenes: S toggles the skinned display mesh, N (while running) toggles
    // linearly implicit ↔ backward Euler.
    let fem = !tet_bodies.is_empty();
    if fem && input.just_pressed(KeyCode::KeyS) {
        for mut s in &mut skins {
            s.show = !s.show;
        }
    }
    if fem && input.just_pressed(KeyCode::KeyN) && !clock.paused {
        for (_, mut b, _) in &mut bodies {
            b.integrator = if b.integrator == IntegratorKind::LinearlyImplicitEuler {
                IntegratorKind::BackwardEuler
            } else {
                IntegratorKind::LinearlyImplicitEuler
            };
        }
    }
    if egui_wants(&mut contexts, true) {
        return;
    }
    if input.just_pressed(KeyCode::Space) {
        clock.paused = !clock.paused;
    }
    if input.just_pressed(KeyCode::KeyN) && clock.paused {
        clock.step_once = true;
    }
    if input.just_pressed(KeyCode::KeyR) {
        reset.write(ResetSoftBodies);
        ui.history.clear();
    }
    if input.just_pressed(KeyCode::KeyG)
        && let Some(store) = gizmo_store.as_mut()
    {
        let (_, g) = store.config_mut::<SoftBodyGizmos>();
        g.wireframe = !g.wireframe;
    }
    if input.just_pressed(KeyCode::KeyW) {
        let mut any = false;
        for (_, _, w) in &mut bodies {
            if let Some(mut w) = w {
                w.enabled = !w.enabled;
                any = true;
            }
        }
        if !any {
            global_wind.0 = match global_wind.0 {
                Some(_) => None,
                None => Some(SoftBodyWind {
                    velocity: Vec3::new(0.0, 0.0, 2.0),
                    gust: 1.0,
                    frequency: 0.5,
                    coefficient: 0.002,
                    seed: 1,
                    enabled: true,
                }),
            };
        }
    }
    for (key, kind) in LETTERS {
        if fem && key == KeyCode::KeyS && !skins.is_empty() {
            continue;
        }
        if input.just_pressed(key) {
            for (_, mut b, _) in &mut bodies {
                b.integrator = kind;
            }
        }
    }
}

/// The body the panel shows.
fn selected(ui: &SoftBodyUi, bodies: impl Iterator<Item = Entity>) -> Option<Entity> {
    let mut first = None;
    for e in bodies {
        if Some(e) == ui.selected {
            return Some(e);
        }
        first = first.or(Some(e));
    }
    first
}

fn record_energy(
    mut ui: ResMut<SoftBodyUi>,
    clock: Res<SoftBodyClock>,
    bodies: Query<(Entity, &BodySim)>,
) {
    let Some(sel) = selected(&ui, bodies.iter().map(|(e, _)| e)) else {
        return;
    };
    let Ok((_, bs)) = bodies.get(sel) else { return };
    let Some(sim) = bs.simulation() else { return };
    let Some(e) = sim.system.energy(sim.time, &sim.state) else {
        return;
    };
    let t = clock.elapsed;
    if ui.history.back().is_some_and(|h| h[0] >= t) {
        if ui.history.back().is_some_and(|h| h[0] > t) {
            ui.history.clear(); // reset
        } else {
            return;
        }
    }
    ui.history
        .push_back([t, e.kinetic as f64, e.potential as f64, e.total() as f64]);
    while ui.history.front().is_some_and(|h| h[0] < t - 10.0) {
        ui.history.pop_front();
    }
}

type PanelItem<'a> = (
    Entity,
    &'a mut SoftBody,
    &'a SoftBodyStatus,
    &'a BodySim,
    Option<&'a Name>,
    Option<&'a BodySprings>,
    Option<&'a mut SoftBodyWind>,
    (
        Option<&'a mut ElasticMaterial>,
        Option<&'a mut crate::render::SkinnedSurface>,
        Option<&'a BodyParticles>,
    ),
);

#[allow(clippy::too_many_arguments)]
fn panel(
    mut contexts: EguiContexts,
    mut ui_state: ResMut<SoftBodyUi>,
    mut clock: ResMut<SoftBodyClock>,
    (mut debug, mut gizmo_store): (ResMut<SoftBodyDebug>, Option<ResMut<GizmoConfigStore>>),
    mut global_wind: ResMut<GlobalWind>,
    mut reset: MessageWriter<ResetSoftBodies>,
    mut bodies: Query<PanelItem>,
    mut springs: Query<&mut Spring>,
    mut particles: Query<&mut Particle>,
    diagnostics: Option<Res<bevy::diagnostic::DiagnosticsStore>>,
) -> Result {
    let ctx = contexts.ctx_mut()?;
    // The whole step's cost, smoothed, from Bevy's diagnostics store.
    let smoothed = |path: &bevy::diagnostic::DiagnosticPath| {
        diagnostics
            .as_ref()
            .and_then(|d| d.get(path))
            .and_then(|d| d.smoothed())
    };
    let all_ms = smoothed(&SoftBodyDiagnostics::STEP_TIME);
    let (newton, cg) = (
        smoothed(&SoftBodyDiagnostics::NEWTON_ITERATIONS),
        smoothed(&SoftBodyDiagnostics::LINEAR_ITERATIONS),
    );
    let sel = selected(&ui_state, bodies.iter().map(|b| b.0));
    let names: Vec<(Entity, String)> = bodies
        .iter()
        .map(|b| (b.0, b.4.map_or(format!("{}", b.0), |n| n.to_string())))
        .collect();
    egui::Window::new("soft bodies")
        .anchor(egui::Align2::LEFT_TOP, [8.0, 8.0])
        .default_width(330.0)
        .show(ctx, |ui| {
            ui.horizontal(|ui| {
                let label = if clock.paused { "▶ resume" } else { "⏸ pause" };
                if ui.button(label).clicked() {
                    clock.paused = !clock.paused;
                }
                if ui
                    .add_enabled(clock.paused, egui::Button::new("step"))
                    .clicked()
                {
                    clock.step_once = true;
                }
                if ui.button("reset").clicked() {
                    reset.write(ResetSoftBodies);
                    ui_state.history.clear();
                }
                if let Some(store) = gizmo_store.as_mut() {
                    let (_, g) = store.config_mut::<SoftBodyGizmos>();
                    ui.checkbox(&mut g.wireframe, "wireframe");
                }
                ui.checkbox(&mut debug.interpolate, "interpolate");
            });
            ui.label(format!(
                "t = {:.2} s   precision {}",
                clock.elapsed,
                crate::math::PRECISION
            ));
            let Some(sel) = sel else {
                ui.label("no soft body");
                return;
            };
            if names.len() > 1 {
                egui::ComboBox::from_label("body")
                    .selected_text(
                        names
                            .iter()
                            .find(|n| n.0 == sel)
                            .map_or("?", |n| n.1.as_str()),
                    )
                    .show_ui(ui, |ui| {
                        for (e, n) in &names {
                            if ui.selectable_label(*e == sel, n).clicked() {
                                ui_state.selected = Some(*e);
                                ui_state.history.clear();
                            }
                        }
                    });
            }
            let Ok((_, mut body, status, bs, _, spring_list, wind, (material, skin, plist))) =
                bodies.get_mut(sel)
            else {
                return;
            };
            ui.label(format!(
                "{} particles, {} springs, {} substeps, {:.2} ms per fixed step",
                status.particles, status.springs, status.substeps, status.step_ms
            ));
            if let Some(ms) = all_ms {
                ui.label(format!(
                    "all bodies: {ms:.2} ms per fixed step · Newton {:.1} · CG {:.0} per step",
                    newton.unwrap_or(0.0),
                    cg.unwrap_or(0.0)
                ));
            }
            if status.contact_passes > 0 || status.contact_candidates > 0 {
                let due = status
                    .contact_due_particle
                    .map_or(String::new(), |i| format!(" · due by particle {i}"));
                ui.label(format!(
                    "self-collision: {} passes, {} searches, {} candidates · broad {:.2} ms, narrow {:.2} ms{due}",
                    status.contact_passes,
                    status.contact_searches,
                    status.contact_candidates,
                    status.contact_broad_ms,
                    status.contact_narrow_ms
                ));
            }
            if !status.auto_reason.is_empty() {
                ui.label(format!("auto: {}", status.auto_reason));
            }
            match &status.state {
                BodyState::Diverged(m) | BodyState::Invalid(m) => {
                    ui.colored_label(egui::Color32::from_rgb(255, 110, 90), m);
                    ui.small("R resets; pick another method or a smaller h.");
                }
                s => {
                    ui.label(format!("{s:?}"));
                }
            }
            let mut kind = body.integrator;
            egui::ComboBox::from_label("integrator")
                .selected_text(kind.label())
                .show_ui(ui, |ui| {
                    for k in IntegratorKind::ALL.into_iter().chain([IntegratorKind::Auto]) {
                        ui.selectable_value(&mut kind, k, format!("{} ({})", k.label(), k.letter()));
                    }
                });
            if kind != body.integrator {
                body.integrator = kind;
            }
            // Under Auto the step is Auto's (the reason above says which).
            if let StepPolicy::Fixed { h } = body.step
                && body.integrator != IntegratorKind::Auto
            {
                let mut hv = h;
                ui.add(
                    egui::Slider::new(&mut hv, 1e-5..=0.1)
                        .logarithmic(true)
                        .text("h (s)"),
                );
                if hv != h {
                    body.step = StepPolicy::Fixed { h: hv };
                }
            }
            let mut drag = body.drag;
            ui.add(egui::Slider::new(&mut drag, 0.0..=1.0).text("drag (N·s/m)"));
            if drag != body.drag {
                body.drag = drag;
            }
            let (mut ks, mut ds) = (ui_state.stiffness_scale, ui_state.damping_scale);
            ui.add(
                egui::Slider::new(&mut ks, 0.1..=10.0)
                    .logarithmic(true)
                    .text("stiffness ×"),
            );
            ui.add(
                egui::Slider::new(&mut ds, 0.0..=10.0)
                    .text("damping ×"),
            );
            if (ks != ui_state.stiffness_scale || ds != ui_state.damping_scale)
                && let Some(list) = spring_list
            {
                for e in list.entities() {
                    if let Ok(mut s) = springs.get_mut(*e) {
                        let base = *ui_state.base.entry(*e).or_insert((s.stiffness, s.damping));
                        s.stiffness = base.0 * ks;
                        s.damping = base.1 * ds;
                    }
                }
                ui_state.stiffness_scale = ks;
                ui_state.damping_scale = ds;
            }
            if let Some(mut mat) = material {
                ui.separator();
                let m = mat.0;
                let (mut e, mut nu, mut rho) = (m.young, m.poisson, m.density);
                ui.add(
                    egui::Slider::new(&mut e, 1e3..=1e9)
                        .logarithmic(true)
                        .text("Young's modulus (Pa)"),
                );
                ui.add(egui::Slider::new(&mut nu, -0.5..=0.49).text("Poisson ratio"));
                ui.add(
                    egui::Slider::new(&mut rho, 10.0..=20000.0)
                        .logarithmic(true)
                        .text("density (kg/m³)"),
                );
                if rho != m.density && let Some(list) = plist {
                    // Masses are ρ V / 4 sums: scale them with the density.
                    let r = (rho / m.density) as f32;
                    for e in list.entities() {
                        if let Ok(mut p) = particles.get_mut(*e) {
                            p.mass *= r;
                        }
                    }
                }
                if (e, nu, rho) != (m.young, m.poisson, m.density) {
                    mat.0 = crate::core::fem::NeoHookean {
                        young: e,
                        poisson: nu,
                        density: rho,
                    };
                }
                if let Some(sim) = bs.simulation() {
                    let st = sim.stats();
                    let steps = st.steps.max(1) as f64;
                    ui.label(format!(
                        "{} tets · {} inverted · Newton {:.2} it./step · residual {:.2e} m/s",
                        sim.system.tets.len(),
                        sim.system.tets.inverted(&sim.state.x),
                        st.newton_iterations as f64 / steps,
                        st.newton_residual,
                    ));
                }
                if let Some(mut sk) = skin {
                    let mut show = sk.show;
                    ui.checkbox(&mut show, "skinned display mesh (S)");
                    if show != sk.show {
                        sk.show = show;
                    }
                }
            }
            match wind {
                Some(mut w) => {
                    let mut on = w.enabled;
                    ui.checkbox(&mut on, "wind (W)");
                    if on != w.enabled {
                        w.enabled = on;
                    }
                }
                None => {
                    let mut on = global_wind.0.is_some();
                    ui.checkbox(&mut on, "wind (W)");
                    if on != global_wind.0.is_some() {
                        global_wind.0 = on.then(|| SoftBodyWind {
                            velocity: Vec3::new(0.0, 0.0, 2.0),
                            gust: 1.0,
                            frequency: 0.5,
                            coefficient: 0.002,
                            seed: 1,
                            enabled: true,
                        });
                    }
                }
            }
            // Energy drift per simulated second over the plotted window (total energy: constant
            // for a conservative system with an exact integrator; negative when damping or the
            // method dissipates, positive when the method injects energy or something drives it).
            if let (Some(a), Some(b)) = (ui_state.history.front(), ui_state.history.back())
                && b[0] > a[0]
            {
                ui.label(format!(
                    "energy drift {:+.3e} J/s over the last {:.1} s",
                    (b[3] - a[3]) / (b[0] - a[0]),
                    b[0] - a[0]
                ));
            }
            let series = |k: usize| -> PlotPoints<'static> {
                ui_state.history.iter().map(|h| [h[0], h[k]]).collect()
            };
            Plot::new("energy")
                .height(140.0)
                .legend(Legend::default())
                .show(ui, |p| {
                    p.line(Line::new("kinetic", series(1)));
                    p.line(Line::new("potential", series(2)));
                    p.line(Line::new("total", series(3)));
                });
            if let Some(sim) = bs.simulation() {
                ui.separator();
                let n = sim.state.x.len();
                ui.horizontal(|ui| {
                    ui.label("particle");
                    ui.add(egui::DragValue::new(&mut ui_state.inspect).range(0..=n.saturating_sub(1)));
                    ui.checkbox(&mut ui_state.highlight, "highlight");
                });
                let i = ui_state.inspect.min(n.saturating_sub(1));
                if n > 0 {
                    ui.small(format!(
                        "x = {:.3}  v = {:.3}  m = {}",
                        sim.state.x[i].to_f32(),
                        sim.state.v[i].to_f32(),
                        sim.system.mass()[i]
                    ));
                    egui::ScrollArea::vertical().max_height(120.0).show(ui, |ui| {
                        for s in sim.system.springs.as_slice() {
                            let (a, b) = (s.i as usize, s.j as usize);
                            if a != i && b != i {
                                continue;
                            }
                            let other = if a == i { b } else { a };
                            let l = (sim.state.x[a] - sim.state.x[b]).length();
                            ui.small(format!(
                                "→ {other}: L = {:.4}, l = {:.4} ({:+.1} %), k = {:.1} N/m, b = {:.3}",
                                s.rest,
                                l,
                                100.0 * (l / s.rest - 1.0),
                                s.k,
                                s.damping
                            ));
                        }
                    });
                }
            }
            ui.small("Space pause · N step · R reset · W wind · G wireframe · E S T M K A I D B X P U method · mouse: drag particles, right-drag orbit, wheel zoom");
        });
    Ok(())
}

fn highlight(ui: Res<SoftBodyUi>, mut gizmos: Gizmos, bodies: Query<(Entity, &BodySim)>) {
    if !ui.highlight {
        return;
    }
    let Some(sel) = selected(&ui, bodies.iter().map(|b| b.0)) else {
        return;
    };
    let Ok((_, bs)) = bodies.get(sel) else { return };
    let Some(sim) = bs.simulation() else { return };
    let x = &sim.state.x;
    let i = ui.inspect;
    if i >= x.len() {
        return;
    }
    let orange = Color::srgb(1.0, 0.55, 0.1);
    gizmos.sphere(Isometry3d::from_translation(x[i].to_f32()), 0.015, orange);
    for s in sim.system.springs.as_slice() {
        let (a, b) = (s.i as usize, s.j as usize);
        if a == i || b == i {
            gizmos.line(x[a].to_f32(), x[b].to_f32(), orange);
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn grab(
    mut commands: Commands,
    mut contexts: EguiContexts,
    buttons: Res<ButtonInput<MouseButton>>,
    windows: Query<&Window>,
    cameras: Query<(&Camera, &GlobalTransform), With<Camera3d>>,
    bodies: Query<(Entity, &BodySim)>,
    mut anchors: Query<&mut Transform>,
    mut ui: ResMut<SoftBodyUi>,
) {
    // The first active 3D camera (the one the cursor is over, for the usual single view).
    let Some((camera, cam_tf)) = cameras.iter().find(|(c, _)| c.is_active) else {
        return;
    };
    let ray = windows
        .iter()
        .find_map(|w| w.cursor_position())
        .and_then(|c| camera.viewport_to_world(cam_tf, c).ok());
    if buttons.just_released(ui.grab_button)
        && let Some(g) = ui.grab.take()
    {
        for e in [g.spring, g.handle, g.anchor] {
            commands.entity(e).despawn();
        }
        let _ = (g.body, g.particle);
        return;
    }
    let Some(ray) = ray else { return };
    if let Some(g) = ui.grab {
        if let Ok(mut tf) = anchors.get_mut(g.anchor) {
            tf.translation = ray.get_point(g.depth);
        }
        return;
    }
    if !buttons.just_pressed(ui.grab_button) || egui_wants(&mut contexts, false) {
        return;
    }
    // The particle nearest the ray, over every body.
    let mut best: Option<(f32, Entity, Entity, f32, f32)> = None;
    for (be, bs) in &bodies {
        let Some(sim) = bs.simulation() else { continue };
        let kmax = sim
            .system
            .springs
            .as_slice()
            .iter()
            .map(|s| s.k as f32)
            .fold(0.0, f32::max);
        for (i, x) in sim.state.x.iter().enumerate() {
            let p = x.to_f32();
            let along = (p - ray.origin).dot(*ray.direction);
            if along <= 0.0 {
                continue;
            }
            let d = (p - ray.get_point(along)).length() / along; // angular distance
            if best.is_none_or(|b| d < b.0) {
                best = Some((d, be, bs.particle_entities()[i], along, kmax));
            }
        }
    }
    let Some((d, body, particle, depth, kmax)) = best else {
        return;
    };
    if d > 0.05 {
        return; // nothing within about 3° of the cursor
    }
    let at = ray.get_point(depth);
    let anchor = commands
        .spawn((
            Transform::from_translation(at),
            GlobalTransform::from_translation(at),
        ))
        .id();
    let handle = commands
        .spawn((
            Particle::at(at, 1.0),
            ParticleOf(body),
            Pinned::to(anchor, Vec3::ZERO),
        ))
        .id();
    let k = (kmax * ui.grab_stiffness).max(1.0);
    let spring = commands
        .spawn((
            Spring {
                a: particle,
                b: handle,
                rest_length: 0.0,
                stiffness: k,
                damping: 0.0,
                law: Default::default(),
            },
            SpringOf(body),
        ))
        .id();
    ui.grab = Some(Grab {
        body,
        particle,
        handle,
        anchor,
        spring,
        depth,
    });
}
