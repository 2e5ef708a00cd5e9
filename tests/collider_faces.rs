//! Colliders against a surface's triangles, not its particles alone: a rod or a small sphere
//! between a cloth's particles is met by the triangles around it. Checked by distances written
//! apart from the collision code (`common::intersect`'s point–triangle distance; a rod's
//! axis against the triangles projected across it), against the same scene with the particles alone (which lets the collider
//! through, so the tests can fail), and by the impulses' momentum and kinetic energy.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

mod common;

use bevy_soft_body::core::build::{ClothParams, ClothPins, JellyParams, cloth, jelly};
use bevy_soft_body::core::collide::{Collider, Exchange, Response, Spin};
use bevy_soft_body::math::{ToScalar, VectorExt};
use bevy_soft_body::prelude::*;
use common::intersect::point_triangle_distance;
use glam::{DMat3, DQuat, DVec3};
use parry3d::math::Rot3;
use parry3d::shape::SharedShape;

type P = [f64; 3];

fn positions(s: &ParticleState) -> Vec<P> {
    s.x.iter()
        .map(|p| [p.x as f64, p.y as f64, p.z as f64])
        .collect()
}

/// The nearest any of `tris` (at positions `x`) comes to the surface of a rod of radius `r`
/// along `a b`, a segment along z that outreaches them: the distance from a point to the
/// rod's axis then depends on its x and y alone, so a triangle's is the 2D distance from the
/// axis' point to the triangle projected onto the xy-plane (zero when the projection holds
/// the point: the axis crosses the triangle).
fn rod_distance(x: &[P], tris: &[[u32; 3]], a: P, b: P, r: f64) -> f64 {
    assert!(a[0] == b[0] && a[1] == b[1], "the rod lies along z");
    let (lo, hi) = (a[2].min(b[2]), a[2].max(b[2]));
    assert!(
        tris.iter()
            .flatten()
            .all(|&i| (lo..=hi).contains(&x[i as usize][2])),
        "the rod outreaches the cloth"
    );
    let o = [a[0], a[1]];
    let seg = |a: [f64; 2], b: [f64; 2]| {
        let (ab, ao) = ([b[0] - a[0], b[1] - a[1]], [o[0] - a[0], o[1] - a[1]]);
        let l = ab[0] * ab[0] + ab[1] * ab[1];
        let t = if l > 0.0 {
            ((ao[0] * ab[0] + ao[1] * ab[1]) / l).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (a[0] + ab[0] * t - o[0]).hypot(a[1] + ab[1] * t - o[1])
    };
    let side =
        |a: [f64; 2], b: [f64; 2]| (b[0] - a[0]) * (o[1] - a[1]) - (b[1] - a[1]) * (o[0] - a[0]);
    tris.iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| [x[i as usize][0], x[i as usize][1]]);
            let s = [side(a, b), side(b, c), side(c, a)];
            let inside = s.iter().all(|&v| v >= 0.0) || s.iter().all(|&v| v <= 0.0);
            let d = if inside {
                0.0
            } else {
                seg(a, b).min(seg(b, c)).min(seg(c, a))
            };
            d - r
        })
        .fold(f64::INFINITY, f64::min)
}

/// Thickness of the colliders' contact (m).
const THICK: f64 = 0.005;

/// A 16 × 16 cloth, 0.75 m square (edges of 5 cm, diagonals of 7.1 cm; its particles at
/// x, z = −0.375 + 0.05 k, so the middle of a cell at x = z = 0), 10 g particles, structural
/// springs of 200 N/m, lying at height `y`.
fn cloth_at(y: f64) -> Scene {
    let mut s = cloth(&ClothParams {
        rows: 16,
        cols: 16,
        width: 0.75,
        height: 0.75,
        mass: 0.01,
        k_structural: 200.0,
        k_shear: 80.0,
        k_flex: 2.0,
        damping: 0.02,
        drag: 0.01,
        pins: ClothPins::None,
        hanging: false,
        origin: [0.0, y, 0.0],
    })
    .unwrap();
    s.gravity = [0.0, -9.81, 0.0];
    s
}

fn material() -> ContactMaterial {
    ContactMaterial {
        friction: 0.5,
        thickness: THICK,
        ..Default::default()
    }
}

/// Symplectic Euler at h = 1/1200 s (h·2√(k/m) = 0.24).
fn run(scene: Scene, faces: bool, frames: u64, each: impl FnMut(&[P])) -> Vec<P> {
    run_with(
        scene,
        faces,
        frames,
        IntegratorKind::SymplecticEuler,
        1.0 / 1200.0,
        each,
    )
}

fn run_with(
    scene: Scene,
    faces: bool,
    frames: u64,
    integrator: IntegratorKind,
    h: f64,
    mut each: impl FnMut(&[P]),
) -> Vec<P> {
    let (mut model, state) = scene.build().unwrap();
    assert!(
        !model.contact_faces.is_empty(),
        "the cloth's surface reaches the model"
    );
    if !faces {
        model.contact_faces.clear();
    }
    let mut sim = stepped(model, state, integrator, h, SolverChoice::Auto);
    for _ in 0..frames {
        sim.advance_frame().unwrap();
        each(&positions(&sim.state));
    }
    positions(&sim.state)
}

/// A simulation of `model` in frames of 1/60 s, taken in fixed steps of `h` by
/// `integrator`, its linear solves by `solver`.
fn stepped(
    model: ParticleModel,
    state: ParticleState,
    integrator: IntegratorKind,
    h: f64,
    solver: SolverChoice,
) -> Simulation<ParticleState, ParticleModel> {
    Simulation::new(
        model,
        state,
        DriverConfig {
            integrator,
            policy: StepPolicy::Fixed { h },
            frame_dt: 1.0 / 60.0,
            solver,
            ..Default::default()
        },
    )
}

/// A rod of radius 1 cm (a capsule along z) under the cloth, its axis midway between two
/// columns of particles (2.5 cm from each: farther than the radius and the thickness, so no
/// particle ever meets it).
fn rod() -> (ColliderDesc, P, P, f64) {
    let (r, half, x, y) = (0.01, 0.6, 0.0, 0.3);
    let rod = ColliderDesc {
        shape: ShapeDesc::Capsule {
            half_height: half,
            radius: r,
        },
        motion: Motion::Fixed {
            position: [x, y, 0.0],
        },
        // The capsule's axis (y) turned onto z.
        rotation: [
            std::f64::consts::FRAC_1_SQRT_2,
            0.0,
            0.0,
            std::f64::consts::FRAC_1_SQRT_2,
        ],
        material: material(),
    };
    (rod, [x, y, -half], [x, y, half], r)
}

#[test]
fn a_cloth_drops_onto_a_rod_thinner_than_its_cells_and_hangs_over_it() {
    let (collider, a, b, r) = rod();
    let mut scene = cloth_at(0.4);
    let tris = scene.surface.as_ref().unwrap().triangles.clone();
    scene.colliders = vec![collider];
    // 2 s: the fall (10 cm, 0.14 s), the drape and the sides' swing.
    let mut nearest = f64::INFINITY;
    let end = run(scene.clone(), true, 120, |x| {
        nearest = nearest.min(rod_distance(x, &tris, a, b, r))
    });
    let centre_y = end.iter().map(|p| p[1]).sum::<f64>() / end.len() as f64;
    let lowest = end.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
    println!(
        "on the triangles: nearest {:.2} mm from the rod (thickness {:.1} mm), mean height {centre_y:.3} m, lowest {lowest:.3} m",
        nearest * 1e3,
        THICK * 1e3
    );
    // Held at the thickness at every frame's end, less the half the contract allows.
    assert!(
        nearest >= 0.5 * THICK,
        "the rod came {nearest} m from the cloth"
    );
    // Hanging over the rod (at 0.3 m): its middle on it, its sides below.
    assert!(
        centre_y < 0.3 && lowest < 0.0,
        "the cloth hangs: mean {centre_y}, lowest {lowest}"
    );
    let on_rod = end
        .iter()
        .filter(|p| p[0].abs() < 0.05 && p[1] > 0.29)
        .count();
    assert!(
        on_rod >= 16,
        "the cloth's middle lies on the rod ({on_rod} particles)"
    );

    // The particles alone let it through: every particle falls past the rod.
    let (collider, _, _, _) = rod();
    let mut scene = cloth_at(0.4);
    scene.colliders = vec![collider];
    let end = run(scene, false, 60, |_| {});
    let highest = end.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    println!("on the particles alone: highest particle at {highest:.3} m after 1 s");
    assert!(
        highest < 0.3 - r,
        "the particles alone held the cloth at {highest}"
    );
}

/// A sphere of radius 2 cm under the centre of a cell (3.5 cm from its corners).
fn small_sphere() -> (ColliderDesc, P, f64) {
    let (r, c) = (0.02, [0.0, 0.3, 0.0]);
    (
        ColliderDesc {
            shape: ShapeDesc::Sphere { radius: r },
            motion: Motion::Fixed { position: c },
            rotation: [0.0, 0.0, 0.0, 1.0],
            material: material(),
        },
        c,
        r,
    )
}

#[test]
fn a_cloth_drops_onto_a_sphere_smaller_than_its_cells_and_rests_on_it() {
    let (collider, c, r) = small_sphere();
    let mut scene = cloth_at(0.4);
    let tris = scene.surface.as_ref().unwrap().triangles.clone();
    scene.colliders = vec![collider];
    let mut nearest = f64::INFINITY;
    let end = run(scene, true, 60, |x| {
        for t in &tris {
            let tri = t.map(|i| x[i as usize]);
            nearest = nearest.min(point_triangle_distance(c, &tri) - r);
        }
    });
    let highest = end.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    println!(
        "small sphere: nearest {:.2} mm (thickness {:.1} mm), highest particle {highest:.3} m",
        nearest * 1e3,
        THICK * 1e3
    );
    assert!(
        nearest >= 0.5 * THICK,
        "the sphere came {nearest} m from the cloth"
    );
    assert!(highest > c[1], "the cloth rests on the sphere ({highest})");

    let (collider, _, _) = small_sphere();
    let mut scene = cloth_at(0.4);
    scene.colliders = vec![collider];
    let end = run(scene, false, 60, |_| {});
    let highest = end.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    println!("small sphere, particles alone: highest particle {highest:.3} m");
    assert!(
        highest < c[1] - r,
        "the particles alone held the cloth at {highest}"
    );
}

/// The pile's 12² cloth (11 cm cells) dropped onto a 5 cm ball on the ground: the ball meets
/// it inside its triangles and holds it up as a tent, symplectic Euler at the pile's stable
/// step (frames of 1/64 s in four steps of 1/256 s). Once the cloth lies still, contact with
/// a static collider must add no energy: over 20–25 s its total energy does not rise (to
/// round-off), and no particle moves more than 10 µm in a frame. When each triangle's contact
/// stopped its point whole in the step it arrived, two contacts sharing a corner pumped
/// energy in (one took the velocity that had brought the shared corners in, the other then
/// pushed them out with no impulse to match): the tent quivered 0.3–1.3 mm a frame for good,
/// its energy rising 0.3 mJ over those 5 s.
#[test]
fn a_cloth_tented_on_a_ball_smaller_than_its_cells_comes_to_rest() {
    let r = 0.05;
    let frame = 1.0 / 64.0;
    let mut sim = common::tent(r, frame);
    let energy = |sim: &Simulation<ParticleState, ParticleModel>| {
        let e = sim.system.energy(sim.time, &sim.state).unwrap();
        (e.kinetic + e.potential) as f64
    };
    for _ in 0..(20.0 / frame) as usize {
        sim.advance_frame().unwrap();
    }
    let e20 = energy(&sim);
    let mut moved = 0.0f64;
    for _ in 0..(5.0 / frame) as usize {
        let before = positions(&sim.state);
        sim.advance_frame().unwrap();
        let after = positions(&sim.state);
        for (a, b) in before.iter().zip(&after) {
            let d = (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
            moved = moved.max(d);
        }
    }
    let e25 = energy(&sim);
    let top = positions(&sim.state)
        .iter()
        .map(|p| p[1])
        .fold(f64::NEG_INFINITY, f64::max);
    println!(
        "tent: total energy {e20:.6} J at 20 s, {e25:.6} J at 25 s; largest move in a frame {:.4} mm; top at {top:.4} m",
        moved * 1e3
    );
    // A tent: its top above the ball's (the ball rests on the ground).
    assert!(top > 2.0 * r, "the cloth's top at {top} m");
    // Round-off of the energy sum in f32: about 1e-7 of its 0.24 J.
    assert!(e25 <= e20 + 1e-6, "the energy rose from {e20} to {e25} J");
    assert!(moved < 1e-5, "a particle moved {moved} m in a frame");
}

/// Steps a frame long (1/60 s) carry a falling cloth past the rod's whole width in one step
/// (at 10 m/s, 17 cm a step against the rod's 2 cm and the thickness on each side): the
/// triangles and edges that moved more than the thickness are tested at the step's start as
/// well, and one that went through goes back to the side it came from. Linearly implicit and
/// backward Euler, dropped from rest and thrown at 5 and 10 m/s: at every frame's end over 1
/// s no triangle comes nearer the rod than half the thickness, and the cloth hangs on it.
#[test]
fn frame_long_steps_keep_a_cloth_on_a_rod_thinner_than_its_cells() {
    for (speed, integrator) in [
        (0.0, IntegratorKind::LinearlyImplicitEuler),
        (0.0, IntegratorKind::BackwardEuler),
        (5.0, IntegratorKind::LinearlyImplicitEuler),
        (10.0, IntegratorKind::LinearlyImplicitEuler),
    ] {
        let (collider, a, b, r) = rod();
        let mut scene = cloth_at(0.45);
        for p in &mut scene.particles {
            p.velocity = [0.0, -speed, 0.0];
        }
        let tris = scene.surface.as_ref().unwrap().triangles.clone();
        scene.colliders = vec![collider];
        let mut nearest = f64::INFINITY;
        let end = run_with(scene, true, 60, integrator, 1.0 / 60.0, |x| {
            nearest = nearest.min(rod_distance(x, &tris, a, b, r))
        });
        let mean = end.iter().map(|p| p[1]).sum::<f64>() / end.len() as f64;
        println!(
            "{integrator:?} at {speed} m/s: nearest {:.2} mm, mean height after 1 s {mean:.3} m",
            nearest * 1e3
        );
        assert!(
            nearest >= 0.5 * THICK,
            "{integrator:?} at {speed} m/s: the rod came {nearest} m from the cloth"
        );
        // Its half-width is 0.375 m: hanging from the rod at 0.3 m, its mean is above
        // −0.075 m, and one that fell would be far below.
        assert!(
            mean > -0.075,
            "{integrator:?} at {speed} m/s: fell to {mean}"
        );
    }
}

/// A strip of cloth across the rod, off its middle: 3 × 19 particles over 0.9 × 0.1 m (cells
/// of 5 cm, 2.5 times the rod's diameter), 0.8 m of it on one side and 0.1 m on the other,
/// dropped from just above the rod, no friction. Nothing holds it: it slides off towards its
/// long side and falls. Linearly implicit Euler and backward Euler in steps of 1/600 s with
/// PCG hold each triangle spanning the rod at its contact point, so the triangle tips about
/// it: the strip is off the rod within 3 s (its highest particle 18 m below the rod at 3 s
/// with either), and no triangle comes within half the thickness of the rod while it
/// slides. Held at their corners along the normal instead (the solves' only holds before),
/// the triangles over the rod could not tip and the strip hung there, its highest particle
/// on top of the rod at 3 s.
/// (Symplectic Euler at 1/2400 s, which needs no holds, lets the same strip slide off too.
/// At 1/240 s the strip slides until its last cell lies over the rod, its end on it: a
/// triangle with a corner on the rod is held at its corners.)
#[test]
fn a_strip_hung_off_centre_on_a_thin_rod_slides_off_with_implicit_steps() {
    let (mut collider, a, b, r) = rod();
    collider.material.friction = 0.0;
    let (len, left) = (0.9, 0.8);
    let mut scene = cloth(&ClothParams {
        rows: 3,
        cols: 19,
        width: len,
        height: 0.1,
        mass: 0.01,
        k_structural: 200.0,
        k_shear: 80.0,
        k_flex: 2.0,
        damping: 0.05,
        drag: 0.01,
        pins: ClothPins::None,
        hanging: false,
        origin: [len / 2.0 - left, a[1] + r + THICK + 0.002, 0.0],
    })
    .unwrap();
    scene.gravity = [0.0, -9.81, 0.0];
    scene.colliders = vec![collider];
    let tris = scene.surface.as_ref().unwrap().triangles.clone();
    for integrator in [
        IntegratorKind::LinearlyImplicitEuler,
        IntegratorKind::BackwardEuler,
    ] {
        let mut nearest = f64::INFINITY;
        let end = run_with(scene.clone(), true, 180, integrator, 1.0 / 600.0, |x| {
            nearest = nearest.min(rod_distance(x, &tris, a, b, r))
        });
        let highest = end.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
        println!(
            "{integrator:?}: nearest {:.2} mm (thickness {:.1} mm); at 3 s the highest \
             particle {:.2} m below the rod",
            nearest * 1e3,
            THICK * 1e3,
            a[1] - highest
        );
        assert!(
            nearest >= 0.5 * THICK,
            "{integrator:?}: the rod came {nearest} m from the strip"
        );
        assert!(
            highest < a[1] - 2.0,
            "{integrator:?}: the strip is still on the rod, its highest particle at {highest} m"
        );
    }
}

/// Implicit steps as long as a frame or half of one, on a rod as wide as the cloth's cells:
/// the pile's cloth, 32² particles over 0.6 m (cells of 1.94 cm), dropped from 0.75 m onto a
/// rod of 1 cm radius at 0.3 m. Each step's springs pull the triangles over the rod round it;
/// pushed back out after the step, they stretched the springs again, and the cloth stayed
/// wedged on the rod, stretched 2 to 5 times and still moving after 3 s, the rod through it
/// at some frames (or the energy guard stopped it); backward Euler's Newton iteration, in
/// frame-long steps, left it wedged too (stretched 3.8 times, 62 J of elastic energy). With
/// the triangles' corners held along the contact normals inside the solve
/// ([`ParticleModel::hold_faces`]): linearly implicit Euler in steps of a frame and of half
/// one, backward Euler in steps of a frame, with PCG, and linearly implicit Euler in steps of
/// a frame with the sparse Cholesky (without the holds: stretched 8.2 times, the rod through
/// it); over 3 s the rod never comes within a quarter of
/// the thickness of a triangle; at the end the cloth rests (kinetic energy below 5 mJ, where
/// wedged it kept 23–49 mJ), and its structural springs are stretched by its weight alone:
/// half the cloth (1 kg) hanging from a 0.6 m width pulls each 1.94 cm spring of 500 N/m by
/// 0.32 N, a strain of 3 %, to which bending over the rod adds a little (below 15 % in all).
#[test]
fn implicit_steps_hang_a_cloth_on_a_rod_as_wide_as_its_cells_without_wedging() {
    for (integrator, h, solver) in [
        (
            IntegratorKind::LinearlyImplicitEuler,
            1.0 / 60.0,
            SolverChoice::Auto,
        ),
        (
            IntegratorKind::LinearlyImplicitEuler,
            1.0 / 120.0,
            SolverChoice::Auto,
        ),
        (
            IntegratorKind::BackwardEuler,
            1.0 / 60.0,
            SolverChoice::Auto,
        ),
        (
            IntegratorKind::LinearlyImplicitEuler,
            1.0 / 60.0,
            SolverChoice::Cholesky,
        ),
    ] {
        hangs_on_a_rod_at_rest(integrator, h, solver, 0.01);
    }
}

/// The same cloth on thinner rods in frame-long steps: radii of 5 and 2.5 mm, so the rod and
/// its contact thickness on either side (2 and 1.5 cm across) are narrower than the 4.4 cm
/// the cloth falls in its last frame before it meets the rod (at 2.6 m/s). A step's trial
/// solve took the triangles over the rod through it; the contact after the step put them
/// back on the side they came from, and with the cloth's sides still falling, the cells
/// over the rod stretched frame after frame until the rod passed through one (a spring
/// stretched 9.6 times at 2.5 mm and 10.4 times at 5 mm with linearly implicit Euler, 13.9
/// times with backward Euler; the rod through a triangle at 3 s). Now a triangle the trial
/// takes through the collider is held as one it takes into it is
/// ([`Collider::hold_faces_trial`](bevy_soft_body::core::collide::Collider::hold_faces_trial)):
/// the cloth rests on the rod as on the 1 cm one above.
#[test]
fn frame_long_implicit_steps_hang_a_cloth_on_a_rod_thinner_than_a_frames_fall() {
    for (integrator, r) in [
        (IntegratorKind::LinearlyImplicitEuler, 0.005),
        (IntegratorKind::LinearlyImplicitEuler, 0.0025),
        (IntegratorKind::BackwardEuler, 0.005),
    ] {
        hangs_on_a_rod_at_rest(integrator, 1.0 / 60.0, SolverChoice::Auto, r);
    }
}

/// `common::cloth_on_a_rod` with a rod of radius `r`, 3 s in steps of `h` holding triangles
/// on it: the rod never within a quarter of the thickness of a triangle, and at the end the
/// structural springs stretched by less than 15 % and the kinetic energy below 5 mJ.
fn hangs_on_a_rod_at_rest(integrator: IntegratorKind, h: f64, solver: SolverChoice, r: f64) {
    let y = 0.3;
    let scene = common::cloth_on_a_rod(r, y);
    let thick = scene.colliders[1].material.thickness;
    let tris = scene.surface.as_ref().unwrap().triangles.clone();
    let masses: Vec<f64> = scene.particles.iter().map(|q| q.mass).collect();
    let edge = 0.6 / 31.0;
    let (mut model, state) = scene.build().unwrap();
    model.hold_faces = true;
    let mut sim = stepped(model, state, integrator, h, solver);
    let mut nearest = f64::INFINITY;
    for _ in 0..180 {
        sim.advance_frame().unwrap();
        nearest = nearest.min(rod_distance(
            &positions(&sim.state),
            &tris,
            [0.0, y, -0.8],
            [0.0, y, 0.8],
            r,
        ));
    }
    let end = positions(&sim.state);
    let n = 32;
    let mut strain: f64 = 0.0;
    for row in 0..n {
        for c in 0..n {
            let i = row * n + c;
            let len = |j: usize| {
                let (a, b) = (end[i], end[j]);
                ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
            };
            if c + 1 < n {
                strain = strain.max(len(i + 1) / edge);
            }
            if row + 1 < n {
                strain = strain.max(len(i + n) / edge);
            }
        }
    }
    let kinetic: f64 = sim
        .state
        .v
        .iter()
        .zip(&masses)
        .map(|(v, m)| 0.5 * m * (v.length_squared() as f64))
        .sum();
    println!(
        "{integrator:?}, h = 1/{:.0}, {solver:?}: nearest {:.2} mm; at 3 s largest strain \
         {strain:.3}, kinetic energy {:.2} mJ",
        1.0 / h,
        nearest * 1e3,
        kinetic * 1e3
    );
    assert!(
        nearest >= 0.25 * thick,
        "{integrator:?}, h = {h}, {solver:?}: the rod came {nearest} m from the cloth"
    );
    assert!(
        strain < 1.15,
        "{integrator:?}, h = {h}, {solver:?}: a spring stretched {strain} times"
    );
    assert!(
        kinetic < 5e-3,
        "{integrator:?}, h = {h}, {solver:?}: still moving, {kinetic} J"
    );
}

/// A slab of soft rubber (neo-Hookean tets, E = 100 kPa, ν = 0.4, 200 kg/m³: 1.08 kg),
/// 60 × 30 × 3 cm in cells of 5 cm, dropped from 10 cm above onto a rod of radius 1 cm
/// (`rod()`; its axis between two columns of particles, 2 and 3 cm from them) and the
/// ground, with frame-long implicit steps and either solver (the sparse Cholesky is a tet
/// body's default). The rod is kept outside the slab's surface (its boundary triangles) by
/// every frame's exact rod distance, and at 4 s the slab hangs over the rod at rest, holding
/// 10–31 mJ of elastic energy. Backward Euler holds the particles on the ground still and the
/// triangles on the rod without friction: the slab (its sides 0.32 and 0.28 m) slides 9–10 cm
/// over the rod and rests by 2 s (13–31 mJ). Linearly implicit Euler holds the slab's
/// particles on the ground with Coulomb friction and the triangles spanning the rod at their
/// contact points with its friction (μ = 0.5): the slab slides 3–15 cm and rests by 3.5 s
/// (10–29 mJ; in `f64` with the Cholesky still sliding at 3 s, 7 mJ). With those triangles
/// held at their corners it could not tip, and stayed nearly where it fell, bent (69–71 mJ);
/// with the corner holds frictionless, it slid over the rod, still moving at 3 s (38 mJ),
/// and off it by 5 s.
/// Without the holds in the Cholesky's solves, the rod went
/// through the slab with linearly implicit Euler (138 J of elastic energy at 3 s) and wedged
/// in it with backward Euler (66 J, still moving); with the holds dropped for a step whenever
/// a filtered solve of the exact element Hessians failed (before the projected ones were
/// tried), backward Euler with PCG slid the slab off the rod.
#[test]
fn a_tet_slab_hangs_on_a_rod_thinner_than_its_cells_with_either_solver() {
    use bevy_soft_body::core::fem::NeoHookean;
    use bevy_soft_body::core::fem::mesh::TetMesh;
    let (rod, a, b, r) = rod();
    let mesh = TetMesh::tet_box([0.6, 0.03, 0.3], [12, 1, 6])
        .unwrap()
        .transformed(1.0, [-0.32, 0.4, -0.15]);
    let mut scene = mesh.to_scene(
        "slab",
        NeoHookean {
            young: 1e5,
            poisson: 0.4,
            density: 200.0,
        },
    );
    let ground = ColliderDesc {
        shape: ShapeDesc::Plane {
            normal: [0.0, 1.0, 0.0],
        },
        motion: Motion::Fixed { position: [0.0; 3] },
        rotation: [0.0, 0.0, 0.0, 1.0],
        material: material(),
    };
    scene.colliders = vec![rod, ground];
    let tris = scene.surface.as_ref().unwrap().triangles.clone();
    // The slab falls 0.4 m onto the ground at its ends: m g h = 4.2 J. Hanging over the rod it
    // holds 0.01–0.07 J; wedged, tens of joules and more.
    let mass: f64 = scene.particles.iter().map(|p| p.mass).sum();
    let fall = mass * 9.81 * 0.4;
    for (integrator, solver) in [
        (
            IntegratorKind::LinearlyImplicitEuler,
            SolverChoice::Cholesky,
        ),
        (IntegratorKind::BackwardEuler, SolverChoice::Cholesky),
        (IntegratorKind::LinearlyImplicitEuler, SolverChoice::Pcg),
        (IntegratorKind::BackwardEuler, SolverChoice::Pcg),
    ] {
        let (mut model, state) = scene.clone().build().unwrap();
        model.hold_faces = true;
        let mut sim = stepped(model, state, integrator, 1.0 / 60.0, solver);
        let mut nearest = f64::INFINITY;
        for f in 0..240 {
            if let Err(e) = sim.advance_frame() {
                panic!("{integrator:?}, {solver:?}: frame {f}: {e}");
            }
            nearest = nearest.min(rod_distance(&positions(&sim.state), &tris, a, b, r));
        }
        let end = rod_distance(&positions(&sim.state), &tris, a, b, r);
        let elastic = sim.system.elastic_energy(&sim.state.x) as f64;
        let kinetic: f64 = sim
            .state
            .v
            .iter()
            .zip(sim.system.mass())
            .map(|(v, m)| 0.5 * *m as f64 * v.length_squared() as f64)
            .sum();
        println!(
            "{integrator:?}, {solver:?}: nearest {:.2} mm, at 4 s {:.2} mm from the rod, \
             elastic {:.1} mJ, kinetic {:.3} mJ",
            nearest * 1e3,
            end * 1e3,
            elastic * 1e3,
            kinetic * 1e3
        );
        let what = format!("{integrator:?}, {solver:?}");
        assert!(
            nearest >= 0.25 * THICK,
            "{what}: the rod came {nearest} m from the surface"
        );
        assert!(
            end <= 2.0 * THICK,
            "{what}: the slab left the rod ({end} m from it)"
        );
        assert!(
            elastic < 0.05 * fall,
            "{what}: wedged, {elastic} J of elastic energy"
        );
        // At rest: a thousandth of the fall's energy (4 mJ; wedged and still moving, 0.1 J).
        assert!(kinetic < 1e-3 * fall, "{what}: still moving, {kinetic} J");
    }
}

/// A free rigid body moved as a rigid-body engine moves it between frames (as in
/// `tests/coupling.rs`): the soft step gives it impulses through its collider's [`Response`],
/// and after each frame it is put where they moved it, with gravity.
struct Rigid {
    m: f64,
    /// Principal moments of inertia, in the body's frame.
    inertia: DVec3,
    c: DVec3,
    v: DVec3,
    w: DVec3,
    q: DQuat,
    shape: SharedShape,
}

/// Gravity on the rigid bodies, as on the cloth (m/s²).
const G: DVec3 = DVec3::new(0.0, -9.81, 0.0);

impl Rigid {
    /// A solid ball of mass `m`, radius `r`, at `c`: `I = 2/5 m r²`.
    fn ball(m: f64, r: f64, c: DVec3) -> Self {
        Self::new(
            m,
            DVec3::splat(0.4 * m * r * r),
            c,
            SharedShape::ball(r as f32),
        )
    }

    /// A solid cube of mass `m`, half-side `a`, at `c`: `I = m (2a)²/6`.
    fn cube(m: f64, a: f64, c: DVec3) -> Self {
        let s = a as f32;
        Self::new(
            m,
            DVec3::splat(m * 4.0 * a * a / 6.0),
            c,
            SharedShape::cuboid(s, s, s),
        )
    }

    fn new(m: f64, inertia: DVec3, c: DVec3, shape: SharedShape) -> Self {
        Self {
            m,
            inertia,
            c,
            v: DVec3::ZERO,
            w: DVec3::ZERO,
            q: DQuat::IDENTITY,
            shape,
        }
    }

    /// World-frame `I⁻¹`.
    fn inv_inertia(&self) -> DMat3 {
        let r = DMat3::from_quat(self.q);
        r * DMat3::from_diagonal(DVec3::ONE / self.inertia) * r.transpose()
    }

    /// Its collider over the frame starting at `t`.
    fn collider(&self, t: f64) -> Collider {
        let ii = self.inv_inertia();
        let rows = [ii.row(0), ii.row(1), ii.row(2)].map(|r| r.as_vec3().to_scalar());
        let q = self.q.as_quat();
        Collider::new(
            self.shape.clone(),
            Motion::Linear {
                start: self.c.to_array(),
                velocity: self.v.to_array(),
                t0: t,
            },
            Rot3::from_xyzw(q.x, q.y, q.z, q.w),
            material(),
        )
        .with_spin(Spin {
            angular_velocity: self.w.as_vec3().to_scalar(),
            t0: t as Scalar,
            center: Vector::ZERO,
        })
        .with_response(
            Response::new((1.0 / self.m) as Scalar, rows, t as Scalar)
                .with_gravity(G.as_vec3().to_scalar()),
        )
    }

    /// Puts the body where the frame's impulses `ex` and gravity moved it over `dt`: an
    /// impulse `J` at `τ` moves it by `J (dt − τ)/M`, and turns it likewise.
    fn advance(&mut self, ex: &Exchange, dt: f64) {
        let d = |v: Vector| DVec3::from(v.to_f64());
        let ii = self.inv_inertia();
        let (j, jt) = (d(ex.linear), d(ex.linear_moment));
        self.c += self.v * dt + 0.5 * G * dt * dt + (j * dt - jt) / self.m;
        self.v += G * dt + j / self.m;
        let turn = self.w * dt + ii * (d(ex.angular) * dt - d(ex.angular_moment));
        self.w += ii * d(ex.angular);
        self.q = (DQuat::from_scaled_axis(turn) * self.q).normalize();
    }

    /// The least distance from the body to the triangles `tris` at positions `x`, by
    /// `common::intersect`'s point–triangle distance: for a ball, from its centre less its
    /// radius; for a cube, from 101 points along each edge of its lower face.
    fn distance(&self, x: &[P], tris: &[[u32; 3]]) -> f64 {
        let points: Vec<(DVec3, f64)> = if let Some(b) = self.shape.as_ball() {
            vec![(self.c, b.radius as f64)]
        } else {
            let a = self.shape.as_cuboid().unwrap().half_extents.as_dvec3();
            let r = DMat3::from_quat(self.q);
            let corner = |sx: f64, sz: f64| self.c + r * DVec3::new(sx * a.x, -a.y, sz * a.z);
            let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
            (0..4)
                .flat_map(|k| {
                    let (p, q) = (corners[k], corners[(k + 1) % 4]);
                    let (p, q) = (corner(p.0, p.1), corner(q.0, q.1));
                    (0..=100).map(move |s| (p + (q - p) * (s as f64 / 100.0), 0.0))
                })
                .collect()
        };
        tris.iter()
            .flat_map(|t| {
                let tri = t.map(|i| x[i as usize]);
                points
                    .iter()
                    .map(move |&(p, r)| point_triangle_distance(p.to_array(), &tri) - r)
            })
            .fold(f64::INFINITY, f64::min)
    }
}

/// What a rigid body dropped onto a soft one did.
struct Landing {
    body: Rigid,
    /// The least distance from the body to the surface over the frames `from` on, and at the
    /// end.
    nearest: f64,
    end: f64,
    /// The vertical impulse the soft body gave it over the last second (N·s), and its
    /// largest speed then.
    impulse: f64,
    speed: f64,
}

/// Drops `body` onto `scene` (its own colliders kept) for `frames` frames, symplectic Euler at
/// h = 1/1200 s, with the surface's triangles or its particles alone; distances from frame
/// `from` on.
fn land(scene: Scene, mut body: Rigid, faces: bool, frames: usize, from: usize) -> Landing {
    let tris = scene.surface.as_ref().unwrap().triangles.clone();
    let (mut model, state) = scene.build().unwrap();
    if !faces {
        model.contact_faces.clear();
    }
    let fixed = model.colliders.clone();
    let mut sim = stepped(
        model,
        state,
        IntegratorKind::SymplecticEuler,
        1.0 / 1200.0,
        SolverChoice::Auto,
    );
    let (mut nearest, mut end, mut impulse, mut speed) = (f64::INFINITY, 0.0, 0.0, 0.0f64);
    for f in 0..frames {
        sim.system.colliders = fixed.clone();
        sim.system.colliders.push(body.collider(sim.time as f64));
        sim.advance_frame().unwrap();
        let ex = sim
            .system
            .colliders
            .last()
            .unwrap()
            .response
            .as_ref()
            .unwrap()
            .take();
        body.advance(&ex, 1.0 / 60.0);
        if f >= from {
            end = body.distance(&positions(&sim.state), &tris);
            nearest = nearest.min(end);
        }
        if f + 60 >= frames {
            impulse += ex.linear.y as f64;
            speed = speed.max(body.v.length());
        }
    }
    Landing {
        body,
        nearest,
        end,
        impulse,
        speed,
    }
}

/// A 0.2 kg ball of radius 3 cm dropped from 0.5 m over the middle of a trampoline's cell
/// (7 cm from its corners): the particles alone let it through; the triangles catch it and
/// hold it at the thickness in every frame (10 s: the bounce, then rest), and at rest the
/// trampoline's impulse over a second is the ball's weight.
#[test]
fn a_small_rigid_ball_rests_on_a_trampoline_between_its_particles() {
    falls_through_alone_and_rests_on_the_triangles("ball", || {
        Rigid::ball(0.2, 0.03, DVec3::new(0.05, 0.5, 0.05))
    });
}

/// A 0.3 kg cube of side 10 cm dropped from 0.5 m onto the trampoline, its edges over the
/// middles of cells (its lower face 10 cm square, as a cell is): with the particles alone it
/// falls through the cloth; with the triangles it rests on it, its edges at the thickness.
#[test]
fn a_rigid_cube_rests_on_a_trampoline_with_its_edges_off_the_cloth() {
    falls_through_alone_and_rests_on_the_triangles("cube", || {
        Rigid::cube(0.3, 0.05, DVec3::new(0.05, 0.5, 0.05))
    });
}

/// The body `make` gives, dropped on the trampoline: with the particles alone it is below
/// −1 m after 2 s (fallen through); with the triangles, over 10 s, it rests on them: at the
/// thickness in every frame (less the half the contract allows) and at the end (to
/// round-off: 1 %), still (1 cm/s), and the trampoline's impulse over the last second its
/// weight (3 %, as `tests/avian.rs` asks of a crate).
fn falls_through_alone_and_rests_on_the_triangles(name: &str, make: impl Fn() -> Rigid) {
    let through = land(common::trampoline(), make(), false, 120, 0);
    println!(
        "{name}, particles alone: at {:.3} m after 2 s",
        through.body.c.y
    );
    assert!(
        through.body.c.y < -1.0,
        "the particles alone held the {name} at {}",
        through.body.c.y
    );
    let on = land(common::trampoline(), make(), true, 600, 0);
    let weight = on.body.m * 9.81;
    println!(
        "{name}, triangles: nearest {:.2} mm, at the end {:.2} mm (thickness {:.1} mm); impulse over the last second {:.4} N·s (weight {weight:.4} N); largest speed then {:.2e} m/s",
        on.nearest * 1e3,
        on.end * 1e3,
        THICK * 1e3,
        on.impulse,
        on.speed
    );
    assert!(
        on.nearest >= 0.5 * THICK,
        "the {name} came {} m from the surface",
        on.nearest
    );
    assert!(
        on.end >= 0.99 * THICK,
        "the {name} rests {} m from the surface",
        on.end
    );
    assert!(on.speed < 0.01, "the {name} moves at {} m/s", on.speed);
    assert!(
        (on.impulse - weight).abs() < 0.03 * weight,
        "impulse per second {} against the {name}'s weight {weight}",
        on.impulse
    );
}

/// A 50 g ball of radius 15 cm dropped from 1 m onto a jelly block (6³ particles 10 cm
/// apart, on the ground). Held at the thickness `t` from the four particles of a top cell, a
/// half-diagonal `d` = 7.07 cm from the cell's middle, its centre would stand
/// `√((r + t)² − d²)` = 13.79 cm above their plane and its lowest point 12.07 mm below it:
/// in the cell, through the surface. The particles alone leave it so; with the triangles it
/// lies on the top face at the thickness. Over the second after its fall (1–2 s): on the flat
/// face it rolls, as a ball on a flat floor does, where in the cell it was held.
#[test]
fn a_rigid_ball_on_a_jelly_rests_on_its_faces_not_in_its_cells() {
    let block = || {
        jelly(&JellyParams {
            size: [6, 6, 6],
            spacing: 0.1,
            mass: 0.05,
            stiffness: [400.0, 200.0, 100.0],
            damping: 0.2,
            drop_height: 0.0,
            ..Default::default()
        })
        .unwrap()
    };
    let ball = || Rigid::ball(0.05, 0.15, DVec3::new(0.0, 1.0, 0.0));
    let alone = land(block(), ball(), false, 120, 60);
    let on = land(block(), ball(), true, 120, 60);
    let (r, t, d) = (0.15f64, THICK, 0.05 * 2f64.sqrt());
    let dip = r - ((r + t).powi(2) - d * d).sqrt();
    println!(
        "particles alone: {:.2} mm from the faces at the end (−{:.2} mm computed); triangles: nearest {:.2} mm, at the end {:.2} mm (thickness {:.1} mm)",
        alone.end * 1e3,
        dip * 1e3,
        on.nearest * 1e3,
        on.end * 1e3,
        t * 1e3
    );
    // The jelly under the ball sags a little: within a tenth of a millimetre of the figure.
    assert!(
        (alone.end + dip).abs() < 1e-4,
        "the particles alone held the ball {} m from the faces, not −{dip}",
        alone.end
    );
    assert!(
        on.nearest >= 0.99 * t,
        "the ball came {} m from the faces",
        on.nearest
    );
}
