//! Builders, the JSON layout format, the driver's frame bookkeeping and divergence detection,
//! and the cloth assignment's claims about the cloth.

// Casts to and from `Scalar` are no-ops in one precision and needed in the other.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::motion::Motion;
use bevy_soft_body::core::ode::OdeSystem;
use bevy_soft_body::core::scene::{ForceDesc, MotionDesc, SpringKind};
use bevy_soft_body::prelude::*;

const F64: bool = cfg!(feature = "f64");

#[test]
fn cloth_spring_counts_and_rest_lengths() {
    for (n, m) in [(8, 8), (16, 16), (5, 9), (32, 20)] {
        let p = build::ClothParams {
            rows: n,
            cols: m,
            ..Default::default()
        };
        let s = build::cloth(&p).unwrap();
        let count = |k| s.springs.iter().filter(|sp| sp.kind == k).count();
        assert_eq!(
            count(SpringKind::Structural),
            (n - 1) * m + n * (m - 1),
            "{n}x{m}"
        );
        assert_eq!(count(SpringKind::Shear), 2 * (n - 1) * (m - 1));
        assert_eq!(count(SpringKind::Flex), (n - 2) * m + n * (m - 2));
        assert_eq!(
            p.spring_counts(),
            (
                count(SpringKind::Structural),
                count(SpringKind::Shear),
                count(SpringKind::Flex)
            )
        );
        // Every spring starts at rest, and joins the particles index_of says.
        let (model, state) = s.build().unwrap();
        for sp in model.springs.as_slice() {
            let d = (state.x[sp.i as usize] - state.x[sp.j as usize]).length();
            assert!((d - sp.rest).abs() <= 1e-6 * sp.rest.max(1.0));
        }
        let dx = p.width / (m - 1) as f64;
        let a = s.particles[p.index_of(2, 3)].position;
        let b = s.particles[p.index_of(2, 4)].position;
        assert!((b[0] - a[0] - dx).abs() < 1e-12 && a[1] == b[1]);
        assert!(s.surface.as_ref().unwrap().triangles.len() == 2 * (n - 1) * (m - 1));
    }
    assert!(
        build::cloth(&build::ClothParams {
            rows: 2,
            ..Default::default()
        })
        .is_err()
    );
    assert!(
        build::cloth(&build::ClothParams {
            rows: 10_000,
            cols: 10_000,
            ..Default::default()
        })
        .is_err(),
        "10⁸ particles refused"
    );
}

#[test]
fn pyramid_and_jelly_layouts() {
    let s = build::pyramid(4, 0.2, 0.05, 500.0, 0.5, 0.5).unwrap();
    assert_eq!(s.particles.len(), 1 + 4 + 9 + 16);
    // Every spring at rest, none degenerate, none duplicated.
    let mut seen = std::collections::HashSet::new();
    for (k, sp) in s.springs.iter().enumerate() {
        assert!(sp.a != sp.b);
        assert!(
            seen.insert((sp.a.min(sp.b), sp.a.max(sp.b))),
            "duplicate spring {k}"
        );
        assert!(build::particle_distance(&s, sp.a, sp.b) > 0.0);
    }
    // Cross-layer springs from the apex reach the four corners of each lower layer at the
    // slides' geometry: layer spacing s/√2 makes apex-to-layer-2 springs exactly s long.
    assert!((build::particle_distance(&s, 0, 1) - 0.2).abs() < 1e-12);
    s.build().unwrap();

    let j = build::jelly(&build::JellyParams::default()).unwrap();
    assert_eq!(j.particles.len(), 216);
    // 3D grid n³: structural 3n²(n−1), face diagonals 6n(n−1)², body diagonals 4(n−1)³, flex 3n²(n−2).
    let n = 6;
    let structural = j
        .springs
        .iter()
        .filter(|s| s.kind == SpringKind::Structural)
        .count();
    let shear = j
        .springs
        .iter()
        .filter(|s| s.kind == SpringKind::Shear)
        .count();
    let flex = j
        .springs
        .iter()
        .filter(|s| s.kind == SpringKind::Flex)
        .count();
    assert_eq!(structural, 3 * n * n * (n - 1));
    assert_eq!(shear, 6 * n * (n - 1) * (n - 1) + 4 * (n - 1).pow(3));
    assert_eq!(flex, 3 * n * n * (n - 2));
    // Boundary: 6 faces of (n−1)² quads, two triangles each.
    assert_eq!(
        j.surface.as_ref().unwrap().triangles.len(),
        12 * (n - 1) * (n - 1)
    );
    j.build().unwrap();
}

#[test]
fn json_round_trip_is_exact_for_every_builder() {
    let scenes = vec![
        build::chain(&build::ChainParams::default()).unwrap(),
        build::pendulum(1.0, 0.3, 1234.5, 0.1),
        build::cloth_sphere(&build::ClothParams::default(), 0.25, 0.6, 4.0).unwrap(),
        build::wire(11, 0.05, 100).unwrap(),
        build::pyramid(3, 0.2, 0.05, 500.0, 0.5, 0.5).unwrap(),
        build::jelly(&build::JellyParams {
            size: [3, 4, 3],
            ..Default::default()
        })
        .unwrap(),
        {
            let mut s = build::chain(&build::ChainParams::default()).unwrap();
            s.wind = Some(Wind::default());
            s.forces.push(bevy_soft_body::core::scene::ForceDesc {
                particle: 2,
                force: [0.1, 1.0 / 3.0, -7e-9],
            });
            s.particles[1].velocity = [std::f64::consts::PI, -0.1, 1e-300];
            s
        },
    ];
    for s in scenes {
        let text = s.to_json();
        let back = Scene::from_json(&text).unwrap_or_else(|e| panic!("{}: {e}", s.name));
        assert_eq!(back.particles, s.particles, "{}: particles", s.name);
        assert_eq!(back.springs, s.springs, "{}: springs", s.name);
        assert_eq!(back.colliders, s.colliders, "{}: colliders", s.name);
        if let (Some(a), Some(b)) = (&back.surface, &s.surface) {
            assert_eq!(a.triangles, b.triangles, "{}: triangles", s.name);
            for (k, (u, v)) in a.uvs.iter().zip(&b.uvs).enumerate() {
                assert_eq!(u, v, "{}: uv {k}", s.name);
            }
        }
        assert!(back == s, "{}: other fields differ", s.name);
        assert_eq!(back.to_json(), text);
    }
}

fn base() -> Scene {
    build::chain(&build::ChainParams::default()).unwrap()
}

#[test]
fn invalid_scenes_are_rejected_with_their_field_paths() {
    // Each mutation, and the path the error must name.
    type Mutate = fn(&mut Scene);
    let cases: Vec<(Mutate, &str)> = vec![
        (|s| s.particles[2].mass = 0.0, "particles[2].mass"),
        (|s| s.particles[1].mass = -1.0, "particles[1].mass"),
        (|s| s.particles[3].mass = f64::NAN, "particles[3].mass"),
        (
            |s| s.particles[1].position[1] = f64::INFINITY,
            "particles[1].position",
        ),
        (
            |s| s.particles[1].velocity[0] = f64::NAN,
            "particles[1].velocity",
        ),
        (|s| s.springs[1].b = 99, "springs[1].b"),
        (|s| s.springs[0].a = 17, "springs[0].a"),
        (|s| s.springs[2].b = s.springs[2].a, "springs[2].b"),
        (|s| s.springs[0].stiffness = -5.0, "springs[0].stiffness"),
        (
            |s| s.springs[0].stiffness = f64::NAN,
            "springs[0].stiffness",
        ),
        (|s| s.springs[1].damping = -0.1, "springs[1].damping"),
        (
            |s| s.springs[1].rest_length = Some(f64::NAN),
            "springs[1].rest_length",
        ),
        (|s| s.gravity[2] = f64::NAN, "gravity"),
        (|s| s.drag = -1.0, "drag"),
        (
            |s| {
                s.motions.push(MotionDesc {
                    particle: 2,
                    motion: Motion::Fixed {
                        position: [0.0, f64::NAN, 0.0],
                    },
                })
            },
            "motions[0].motion",
        ),
        (
            |s| {
                s.motions.push(MotionDesc {
                    particle: 40,
                    motion: Motion::Fixed { position: [0.0; 3] },
                })
            },
            "motions[0].particle",
        ),
        (
            |s| {
                s.forces.push(ForceDesc {
                    particle: 1,
                    force: [f64::INFINITY, 0.0, 0.0],
                })
            },
            "forces[0].force",
        ),
    ];
    for (mutate, path) in cases {
        let mut s = base();
        mutate(&mut s);
        let err = s.validate().expect_err(path);
        assert!(err.has(path), "expected an error at {path}, got: {err}");
        assert!(s.build().is_err());
    }
    // A pinned particle may have zero mass, and so may a moved one.
    let mut s = base();
    s.particles[0].mass = 0.0;
    s.validate().unwrap();
    s.particles[2].mass = 0.0;
    s.motions.push(MotionDesc {
        particle: 2,
        motion: Motion::Fixed {
            position: s.particles[2].position,
        },
    });
    s.validate().unwrap();
    // All problems are reported at once.
    let mut s = base();
    s.particles[2].mass = 0.0;
    s.springs[1].b = 99;
    let err = s.validate().unwrap_err();
    assert!(
        err.has("particles[2].mass") && err.has("springs[1].b"),
        "{err}"
    );
}

#[test]
fn malformed_json_is_an_error_with_a_position() {
    let good = base().to_json();
    let cases = [
        &good[..good.len() / 2],                                         // truncated
        "{\"particles\": [{\"position\": [0, 0], \"mass\": 1}]}",        // short vector
        "{\"particles\": [{\"position\": [0, 0, 0], \"mass\": 1e999}]}", // overflows to infinity
        "{\"particles\": [{\"position\": [0, 0, 0], \"mass\": \"heavy\"}]}", // wrong type
        "{\"particles\": [], \"sprongs\": []}",                          // unknown field
        "",
        "null",
    ];
    for text in cases {
        let err = Scene::from_json(text).expect_err(text);
        assert!(!err.errors.is_empty());
        assert!(err.errors[0].path.starts_with("line"), "{err}");
    }
    // Valid syntax, invalid content: field paths.
    let text = good.replace("\"mass\": 0.1", "\"mass\": -0.1");
    let err = Scene::from_json(&text).unwrap_err();
    assert!(err.has("particles[1].mass"), "{err}");
}

#[test]
fn substeps_land_exactly_on_frame_ends() {
    // h = 0.007 does not divide 1/60; RK45 chooses its own steps. Either way every frame ends
    // exactly at k/60 (computed from the frame index, no drift).
    for (kind, h) in [
        (IntegratorKind::Rk4, 0.007),
        (IntegratorKind::Rk45, 0.05),
        (IntegratorKind::Trapezoid, 1.0 / 600.0),
    ] {
        let (model, state) = base().build().unwrap();
        let cfg = DriverConfig {
            integrator: kind,
            policy: StepPolicy::Fixed { h },
            frame_dt: 1.0 / 60.0,
            ..Default::default()
        };
        let mut sim = Simulation::new(model, state, cfg);
        sim.run(120, |s, rep| {
            assert_eq!(s.time, (s.frame as f64 * (1.0 / 60.0)) as Scalar, "{kind}");
            assert!(rep.h_max as f64 <= h * 1.001 + 1e-12);
        })
        .unwrap();
    }
    // With h = 0.007 each 1/60 frame is 2 full steps and a remainder of 0.00267: 3 substeps.
    let (model, state) = base().build().unwrap();
    let cfg = DriverConfig {
        policy: StepPolicy::Fixed { h: 0.007 },
        frame_dt: 1.0 / 60.0,
        ..Default::default()
    };
    let mut sim = Simulation::new(model, state, cfg);
    let rep = sim.advance_frame().unwrap();
    assert_eq!(rep.substeps, 3);
}

#[test]
fn cfl_policy_follows_the_springs() {
    // Chain: μ = m/2 for the link between two free particles, √(μ/k) = √(0.05/200) = 0.0158 s;
    // the first link has one fixed end, μ = m: √(0.1/200) = 0.0224 s. CFL 0.5 → 0.0079 s.
    let (model, state) = base().build().unwrap();
    let cfg = DriverConfig {
        policy: StepPolicy::Cfl {
            number: 0.5,
            max: 1.0,
            limit: CflLimit::Oscillation,
        },
        ..Default::default()
    };
    let sim = Simulation::new(model, state, cfg);
    let expected = 0.5 * (0.05f64 / 200.0).sqrt();
    assert!(
        (sim.step_size() as f64 - expected).abs() < 1e-6,
        "{}",
        sim.step_size()
    );
}

#[test]
fn physbam_cfl_forms_reproduce_the_slides_maximum_dt() {
    // The slides' wire: 11 particles of 1/11 kg, l₀ = 0.1 m, E = 10 N (k = E/l₀ = 100 N/m),
    // b = 10 N·s/m. Between two free particles μ = m/2 = 1/22 kg (the link to the moving
    // endpoint has μ = m). Maximum_Dt = CFL · min(μ l₀/b, b l₀/E) = 0.5 · min(4.545e-4, 0.1);
    // the later form's elastic term 2 b l₀/E = 0.2 s does not change the minimum; the
    // oscillation form takes √(μ/k) = 0.0213 s and μ/b = 4.545e-3 s.
    let (model, state) = build::wire(11, 0.05, 100).unwrap().build().unwrap();
    let mu: f64 = 1.0 / 22.0;
    for (limit, expected) in [
        (CflLimit::PhysBam, 0.5 * mu * 0.1 / 10.0),
        (CflLimit::PhysBamLater, 0.5 * mu * 0.1 / 10.0),
        (CflLimit::Oscillation, 0.5 * mu / 10.0),
    ] {
        let cfg = DriverConfig {
            policy: StepPolicy::Cfl {
                number: 0.5,
                max: 1.0,
                limit,
            },
            ..Default::default()
        };
        let sim = Simulation::new(model.clone(), state.clone(), cfg);
        let h = sim.step_size() as f64;
        println!("{limit:?}: h = {h:.4e} s (expected {expected:.4e})");
        assert!(
            (h - expected).abs() < 1e-6 * expected,
            "{limit:?}: {h} vs {expected}"
        );
    }
    // Weak dampers (b = 0.01 N·s/m): μ l₀/b = 0.45 s, and the elastic terms decide:
    // b/k = 1e-4 s in the first form, 2b/k = 2e-4 s in the later one.
    let mut weak = model.clone();
    for s in weak.springs.as_mut_slice() {
        s.damping = 0.01;
    }
    weak.springs.refresh();
    let first = weak.spring_bound(CflLimit::PhysBam).unwrap() as f64;
    let later = weak.spring_bound(CflLimit::PhysBamLater).unwrap() as f64;
    assert!((first - 1e-4).abs() < 1e-6 * 1e-4 * 10.0, "{first}");
    assert!((later - 2e-4).abs() < 1e-6 * 2e-4 * 10.0, "{later}");
}

fn seed_cloth() -> (ParticleModel, ParticleState) {
    build::cloth(&build::ClothParams::default())
        .unwrap()
        .build()
        .unwrap()
}

fn run_cloth(
    kind: IntegratorKind,
    h: f64,
    seconds: f64,
) -> Result<Simulation<ParticleState, ParticleModel>, Divergence> {
    let (model, state) = seed_cloth();
    let cfg = DriverConfig {
        integrator: kind,
        policy: StepPolicy::Fixed { h },
        frame_dt: 1.0 / 60.0,
        ..Default::default()
    };
    let mut sim = Simulation::new(model, state, cfg);
    sim.run_until(seconds)?;
    Ok(sim)
}

#[test]
fn seed_cloth_claims_euler_diverges_trapezoid_and_rk4_hold() {
    // The cloth assignment: "Cloth simulation will quickly blow up when using the Euler
    // integrator. Trapezoidal integrator is okay with small-enough steps (h = 0.001), and RK4
    // allows you to take larger steps (h = 0.005)." On the default 16×16 cloth (1 m, 10 g per
    // particle, k = 100/50/20 N/m, dampers 0.05 N·s/m, drag 0.01 N·s/m) the stiffest mode has
    // ω ≈ 2√((k_struct + k_shear)/m) ≈ 245 rad/s, so h = 0.005 gives hω ≈ 1.2: outside forward
    // Euler's region for a lightly damped oscillation, inside RK4's (|hω| < 2.83).
    let err = run_cloth(IntegratorKind::ForwardEuler, 0.005, 3.0)
        .err()
        .expect("forward Euler at h = 0.005 must diverge");
    println!("{err}");
    assert!(err.time < 3.0);
    assert!(matches!(
        err.reason,
        DivergenceReason::NonFinite | DivergenceReason::EnergyBlowup { .. }
    ));

    for (kind, h) in [
        (IntegratorKind::Trapezoid, 0.001),
        (IntegratorKind::Rk4, 0.005),
    ] {
        let sim = run_cloth(kind, h, 3.0).unwrap_or_else(|e| panic!("{kind} at h = {h}: {e}"));
        // Physically sane after 3 s: the cloth hangs below its pins, no faster than free fall.
        let vmax = sim
            .state
            .v
            .iter()
            .map(|v| v.length())
            .fold(0.0, Scalar::max);
        assert!(vmax < 3.0 * 9.81, "{kind}: max speed {vmax}");
        let lowest = sim
            .state
            .x
            .iter()
            .map(|x| x.y)
            .fold(Scalar::INFINITY, Scalar::min);
        assert!(
            lowest > -1.0 && lowest < 0.1,
            "{kind}: lowest point {lowest}"
        );
    }
}

#[test]
fn divergence_keeps_the_last_good_state() {
    let (model, state) = seed_cloth();
    let cfg = DriverConfig {
        integrator: IntegratorKind::ForwardEuler,
        policy: StepPolicy::Fixed { h: 0.01 },
        ..Default::default()
    };
    let mut sim = Simulation::new(model, state, cfg);
    // The last good state is the last one delivered: the end of the last completed frame.
    let mut last = (sim.state.clone(), sim.time);
    let err = loop {
        match sim.advance_frame() {
            Ok(_) => last = (sim.state.clone(), sim.time),
            Err(e) => break e,
        }
    };
    assert_eq!(sim.state, last.0, "restored to the last delivered state");
    assert_eq!(sim.time, last.1);
    // Every delivered state passed the guard: its internal energy is within the bound
    // (100 × the energy scale by default; how far past physical that is depends on how fast
    // the method blows up within one frame — here ×7 per substep).
    let DivergenceReason::EnergyBlowup { bound, .. } = err.reason else {
        panic!("{err}")
    };
    assert!((sim.system.guard_energy(&sim.state) as f64) <= bound);
    assert!(
        sim.state
            .x
            .iter()
            .chain(&sim.state.v)
            .all(|v| v.is_finite())
    );
    let msg = err.to_string();
    assert!(
        msg.contains("forward Euler") && msg.contains("smaller h") && msg.contains("implicit"),
        "{msg}"
    );
    // Without the energy guard, f32 overflows to non-finite and is caught as such; f64 keeps
    // growing finite numbers for a long time, which is why the guard exists.
    if !F64 {
        let (model, state) = seed_cloth();
        let cfg = DriverConfig {
            energy_guard: None,
            ..cfg
        };
        let mut sim = Simulation::new(model, state, cfg);
        let err = sim.run_until(30.0).unwrap_err();
        assert_eq!(err.reason, DivergenceReason::NonFinite);
        assert!(sim.state.x.iter().all(|v| v.is_finite()));
    }
}

#[test]
fn free_fall_is_not_divergence() {
    // An unpinned cloth falling for 10 s (≈ 490 m, kinetic energy ≈ 10⁴ × its initial energy
    // scale) is physical: the guard watches internal energy (elastic plus kinetic relative to
    // the centre of mass), which free fall leaves unchanged.
    let p = build::ClothParams {
        pins: build::ClothPins::None,
        ..Default::default()
    };
    let (model, state) = build::cloth(&p).unwrap().build().unwrap();
    let cfg = DriverConfig {
        integrator: IntegratorKind::Rk4,
        policy: StepPolicy::Fixed { h: 0.005 },
        ..Default::default()
    };
    let mut sim = Simulation::new(model, state, cfg);
    sim.run_until(10.0).unwrap_or_else(|e| panic!("{e}"));
    // Drag 0.01 N·s/m on 10 g particles: terminal speed m g / c = 9.81 m/s… reached.
    let vy = sim.state.v[0].y as f64;
    assert!(vy < -9.0, "falling at {vy} m/s");
}

/// `ClothPins::Border` holds exactly the border: 4 (n − 1) particles of an n × n cloth.
#[test]
fn a_border_pinned_cloth_holds_its_border() {
    let n = 9;
    let s = build::cloth(&build::ClothParams {
        pins: build::ClothPins::Border,
        ..build::ClothParams::default().resized(n, n)
    })
    .unwrap();
    let pinned: Vec<usize> = (0..n * n).filter(|&k| s.particles[k].pinned).collect();
    assert_eq!(pinned.len(), 4 * (n - 1));
    assert!(pinned.iter().all(|&k| {
        let (i, j) = (k / n, k % n);
        i == 0 || j == 0 || i == n - 1 || j == n - 1
    }));
}
