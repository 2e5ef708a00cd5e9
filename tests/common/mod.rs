//! Helpers the integration tests share (not a test itself).
#![allow(dead_code)]

pub mod intersect;

#[cfg(feature = "plugin")]
#[allow(unused_imports)] // not every test file uses the app helpers
pub use plugin::*;

/// The cloth pile's single 32² cloth over 0.6 m (cells of 1.94 cm, self-collision off),
/// dropped from 0.75 m with the sphere replaced by a rod: a capsule of radius `radius`
/// (1.6 m long) lying along z at height `y`, with the pile's contact material. Its cell size
/// is `0.6 / 31` m.
pub fn cloth_on_a_rod(radius: f64, y: f64) -> bevy_soft_body::core::scene::Scene {
    use bevy_soft_body::core::build::{ClothPileParams, cloth_pile};
    use bevy_soft_body::core::collide::{ColliderDesc, ShapeDesc};
    use bevy_soft_body::core::motion::Motion;
    let p = ClothPileParams {
        cloths: 1,
        size: 0.6,
        self_collision: None,
        ..Default::default()
    }
    .with_resolution(32);
    let mut scene = cloth_pile(&p).unwrap();
    let material = scene.colliders[1].material;
    scene.colliders[1] = ColliderDesc {
        shape: ShapeDesc::Capsule {
            half_height: 0.8,
            radius,
        },
        motion: Motion::Fixed {
            position: [0.0, y, 0.0],
        },
        // The capsule's axis (y) turned onto z.
        rotation: [
            std::f64::consts::FRAC_1_SQRT_2,
            0.0,
            0.0,
            std::f64::consts::FRAC_1_SQRT_2,
        ],
        material,
    };
    scene
}

/// A lying cloth whose border is pinned, a trampoline: 21 × 21 particles of 20 g, 2 m square
/// (cells of 10 cm, diagonals of 14 cm), at height 0, with no collider.
pub fn trampoline() -> bevy_soft_body::core::scene::Scene {
    use bevy_soft_body::core::build::{ClothParams, ClothPins, cloth};
    let mut scene = cloth(&ClothParams {
        rows: 21,
        cols: 21,
        width: 2.0,
        height: 2.0,
        mass: 0.02,
        k_structural: 3000.0,
        k_shear: 500.0,
        k_flex: 100.0,
        damping: 2.0,
        drag: 0.05,
        pins: ClothPins::Border,
        hanging: false,
        origin: [0.0, 0.0, 0.0],
    })
    .unwrap();
    scene.colliders.clear();
    scene
}

/// A small deterministic generator (xorshift 13/7/17), so the tests need no crate and every
/// run draws the same numbers.
pub struct Rng(pub u64);

impl Rng {
    /// The next raw state.
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// Uniform in [0, 1) (53 bits).
    pub fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [−1, 1).
    pub fn signed(&mut self) -> f64 {
        self.unit() * 2.0 - 1.0
    }

    /// An index below `n` (from `unit`).
    pub fn below(&mut self, n: usize) -> usize {
        (self.unit() * n as f64) as usize % n
    }

    /// An index below `n` (from the raw state; `n = 0` gives 0).
    pub fn below_raw(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// The cloth pile's 12² cloth (1.2 m, cells of 11 cm) dropped from 0.75 m onto a ball of
/// `radius` resting on the ground, self-collision off: a ball smaller than the cells meets it
/// inside its triangles and holds it up as a tent. Symplectic Euler at the pile's stable step,
/// in frames of `frame`.
pub fn tent(
    radius: f64,
    frame: f64,
) -> bevy_soft_body::core::driver::Simulation<
    bevy_soft_body::core::ode::ParticleState,
    bevy_soft_body::core::particles::ParticleModel,
> {
    use bevy_soft_body::core::build::{ClothPileParams, cloth_pile};
    use bevy_soft_body::prelude::*;
    let mut p = ClothPileParams {
        cloths: 1,
        radius,
        ..Default::default()
    }
    .with_resolution(12);
    p.self_collision = None;
    let (model, state) = cloth_pile(&p).unwrap().build().unwrap();
    Simulation::new(
        model,
        state,
        DriverConfig {
            integrator: IntegratorKind::SymplecticEuler,
            policy: StepPolicy::Fixed { h: p.stable_step() },
            frame_dt: frame,
            ..Default::default()
        },
    )
}

/// Every number of a scene rounded to `f32`, which the plugin's components hold: the core
/// then starts from the same values in either precision.
pub fn f32_exact(s: &mut bevy_soft_body::core::scene::Scene) {
    let r = |x: &mut f64| *x = *x as f32 as f64;
    for p in &mut s.particles {
        p.position.iter_mut().chain(&mut p.velocity).for_each(r);
        r(&mut p.mass);
    }
    // Rest lengths explicit (the plugin's springs carry them as f32).
    let rest: Vec<f64> = (0..s.springs.len()).map(|k| s.rest_length(k)).collect();
    for (sp, l) in s.springs.iter_mut().zip(rest) {
        r(&mut sp.stiffness);
        r(&mut sp.damping);
        sp.rest_length = Some(l as f32 as f64);
    }
    s.gravity.iter_mut().for_each(r);
    r(&mut s.drag);
    for c in &mut s.colliders {
        if let bevy_soft_body::core::collide::ShapeDesc::Sphere { radius } = &mut c.shape {
            r(radius);
        }
        if let bevy_soft_body::core::motion::Motion::Fixed { position } = &mut c.motion {
            position.iter_mut().for_each(r);
        }
        let m = &mut c.material;
        for x in [
            &mut m.friction,
            &mut m.restitution,
            &mut m.thickness,
            &mut m.bounce_threshold,
        ] {
            r(x);
        }
    }
}

#[cfg(feature = "plugin")]
mod plugin {
    use bevy::app::{PluginGroup, PluginGroupBuilder};
    use bevy::prelude::*;
    use bevy::time::TimeUpdateStrategy;

    /// `SoftBodyPlugins` for a headless app: everything but the egui panel (which needs a
    /// window).
    pub fn headless_plugins() -> PluginGroupBuilder {
        let group = bevy_soft_body::SoftBodyPlugins::default().build();
        #[cfg(feature = "egui")]
        let group = group.disable::<bevy_soft_body::ui::SoftBodyUiPlugin>();
        group
    }

    /// A headless app (`MinimalPlugins`, transforms, [`headless_plugins`]) whose every
    /// `update` runs exactly one fixed step of `frame` seconds, past its first update (which
    /// has zero delta and steps nothing).
    pub fn headless_app(frame: f64) -> App {
        let mut app = App::new();
        app.add_plugins((MinimalPlugins, TransformPlugin, headless_plugins()))
            .insert_resource(Time::<Fixed>::from_seconds(frame))
            .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
        app.update();
        app
    }

    /// The latest value of the diagnostic at `path` in the app's `DiagnosticsStore`.
    pub fn latest(app: &App, path: &bevy::diagnostic::DiagnosticPath) -> f64 {
        app.world()
            .resource::<bevy::diagnostic::DiagnosticsStore>()
            .get(path)
            .unwrap_or_else(|| panic!("{path} registered"))
            .value()
            .unwrap_or_else(|| panic!("{path} measured"))
    }

    /// Spawns `scene` as one body with `body`'s settings (through `spawn_soft_body`, as a
    /// game would) and returns its root.
    pub fn spawn(
        app: &mut App,
        scene: &bevy_soft_body::core::scene::Scene,
        body: bevy_soft_body::ecs::SoftBody,
    ) -> Entity {
        use bevy::ecs::system::RunSystemOnce;
        use bevy_soft_body::ecs::SpawnSoftBody;
        let scene = scene.clone();
        app.world_mut()
            .run_system_once(move |mut c: Commands| {
                c.spawn_soft_body(&scene, body.clone()).unwrap()
            })
            .unwrap()
    }
}

/// Coulomb's law for a body let go at rest on an incline of angle `theta` (radians) with
/// friction `mu`: how far it slides in `t` seconds, `½ g (sin θ − μ cos θ) t²` (none where
/// `μ ≥ tan θ`), and how close frame-long steps of `h` should come: within `2 a h t` (the
/// step's first-order error and the smoothed start from rest), or, resting, the creep of
/// `NormalHolds::STATIC_SPEED` (1 mm/s) times `t`.
// The cast is a no-op in the `f64` build and needed in the `f32` one.
#[allow(clippy::unnecessary_cast)]
pub fn coulomb_slide(theta: f64, mu: f64, t: f64, h: f64) -> (f64, f64) {
    let a = bevy_soft_body::core::build::G * (theta.sin() - mu * theta.cos());
    if a > 0.0 {
        (0.5 * a * t * t, 2.0 * a * h * t)
    } else {
        let creep = bevy_soft_body::core::collide::NormalHolds::STATIC_SPEED as f64;
        (0.0, creep * t)
    }
}
