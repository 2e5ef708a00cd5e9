//! Cloth built from arbitrary triangle meshes (`build::surface_cloth`), checked against
//! counts and sums computed apart from the builder: a grid split along a UV seam welds back to
//! the grid's particles; masses add up to density × area; edges and interior edges give the
//! stretch and bending springs Euler's formula predicts; per-area stiffness gives the same
//! energy `½ s ε² A` under a uniform stretch on a coarse and a fine mesh; bad input is an error.
#![allow(clippy::unnecessary_cast)]

use bevy_soft_body::core::build::{SurfaceParams, SurfaceStiffness, surface_cloth};
use bevy_soft_body::core::ode::OdeSystem;

/// An `nx × ny`-cell grid in the x–y plane, `w × h` metres, split into two UV islands along
/// column `seam` (its vertices duplicated: the right island has its own copies), triangles
/// counter-clockwise seen from +z.
fn seamed_grid(
    nx: usize,
    ny: usize,
    w: f32,
    h: f32,
    seam: usize,
) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut pos = vec![];
    let mut left = vec![vec![0u32; ny + 1]; nx + 1];
    let mut right = left.clone();
    for i in 0..=nx {
        for j in 0..=ny {
            let p = [w * i as f32 / nx as f32, h * j as f32 / ny as f32, 0.0];
            left[i][j] = pos.len() as u32;
            pos.push(p);
            right[i][j] = left[i][j];
            if i == seam {
                right[i][j] = pos.len() as u32;
                pos.push(p); // the seam's duplicate
            }
        }
    }
    let mut tris = vec![];
    for i in 0..nx {
        for j in 0..ny {
            // Cells right of the seam use the right island's copies of the seam column.
            let v = |a: usize, b: usize| if i >= seam { right[a][b] } else { left[a][b] };
            let (a, b, c, d) = (v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1));
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    (pos, tris)
}

#[test]
fn a_seamed_grid_welds_to_the_grid_with_its_mass_and_springs() {
    let (nx, ny, w, h) = (8, 6, 1.2f32, 0.9f32);
    let (pos, tris) = seamed_grid(nx, ny, w, h, 3);
    assert_eq!(pos.len(), (nx + 1) * (ny + 1) + (ny + 1));
    let p = SurfaceParams::default();
    let body = surface_cloth(&pos, &tris, &p, |_, x| x[1] > h - 1e-5).unwrap();
    let s = &body.scene;
    // The seam's ny + 1 duplicates are welded: the grid's particles remain.
    assert_eq!(body.welded, ny + 1);
    assert_eq!(s.particles.len(), (nx + 1) * (ny + 1));
    // Both copies of a seam vertex are the same particle.
    for j in 0..=ny {
        let x = [w * 3.0 / nx as f32, h * j as f32 / ny as f32, 0.0];
        let copies: Vec<_> = pos
            .iter()
            .enumerate()
            .filter(|(_, q)| **q == x)
            .map(|(v, _)| body.vertex_particle[v])
            .collect();
        assert_eq!(copies.len(), 2);
        assert_eq!(copies[0], copies[1]);
    }
    // Mass: density × area, to rounding.
    let m: f64 = s.particles.iter().map(|p| p.mass).sum();
    let expect = p.areal_density * (w as f64) * (h as f64);
    assert!((m - expect).abs() < 1e-6 * expect, "{m} {expect}");
    // Edges of a triangulated nx × ny grid: horizontal nx(ny+1), vertical (nx+1)ny, diagonals
    // nx·ny; interior edges are all edges but the 2(nx + ny) on the boundary.
    let edges = nx * (ny + 1) + (nx + 1) * ny + nx * ny;
    assert_eq!(body.stretch_springs(), edges);
    assert_eq!(body.bending_springs(), edges - 2 * (nx + ny));
    assert_eq!(body.degenerate, 0);
    assert_eq!(body.nonmanifold_edges, 0);
    // Pins: the top row.
    assert_eq!(s.particles.iter().filter(|p| p.pinned).count(), nx + 1);
    // It builds into a valid model.
    s.build().unwrap();
}

#[test]
fn per_length_stiffness_is_force_per_strain_on_every_spring() {
    let (pos, tris) = seamed_grid(5, 5, 1.0, 1.0, 2);
    let p = SurfaceParams {
        stretch: SurfaceStiffness::PerLength(40.0),
        bend: Some(SurfaceStiffness::PerLength(0.5)),
        ..Default::default()
    };
    let body = surface_cloth(&pos, &tris, &p, |_, _| false).unwrap();
    let x = |i: usize| body.scene.particles[i].position;
    for s in &body.scene.springs {
        let (a, b) = (x(s.a), x(s.b));
        let l = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
        let want = if s.kind == bevy_soft_body::core::scene::SpringKind::Flex {
            0.5
        } else {
            40.0
        };
        assert!(
            (s.stiffness * l - want).abs() < 1e-9 * want,
            "{} {l}",
            s.stiffness
        );
    }
}

/// Elastic energy of the stretch springs after scaling every position by `1 + ε` about the
/// origin (each spring stretched by ε of its rest length).
fn stretched_energy(nx: usize, eps: f64, s: f64) -> (f64, f64) {
    let (pos, tris) = seamed_grid(nx, nx, 1.0, 0.8, nx / 2);
    let p = SurfaceParams {
        stretch: SurfaceStiffness::PerArea(s),
        bend: None,
        ..Default::default()
    };
    let body = surface_cloth(&pos, &tris, &p, |_, _| false).unwrap();
    let (model, mut state) = body.scene.build().unwrap();
    for x in &mut state.x {
        *x *= (1.0 + eps) as bevy_soft_body::math::Scalar;
    }
    (model.energy(0.0, &state).unwrap().potential as f64, 0.8)
}

#[test]
fn per_area_stiffness_gives_the_membrane_energy_on_any_mesh() {
    // Every spring stretched by ε stores ½ k (εL)² = ½ s A_e ε², and the A_e add up to the
    // area (each triangle gives a third of its area to each of its three edges): the energy
    // is ½ s ε² A on a 4×4 and a 16×16 mesh of the same 1 × 0.8 m sheet. No gravity term
    // changes it: the sheet lies in z = 0 and gravity is along y, so the potential also holds
    // m g y — removed by comparing with the unstretched energy.
    let (s, eps) = (300.0, 0.01);
    for nx in [4, 16] {
        let (e1, area) = stretched_energy(nx, eps, s);
        let (e0, _) = stretched_energy(nx, 0.0, s);
        // Gravity's part m g y also scales by (1 + ε): remove it exactly.
        let gravity_part = e0 * (1.0 + eps);
        let elastic = e1 - gravity_part;
        let want = 0.5 * s * eps * eps * area;
        println!("{nx}×{nx}: elastic {elastic:e} J, ½ s ε² A = {want:e} J");
        assert!(
            (elastic - want).abs() < 2e-3 * want,
            "{nx}: {elastic} vs {want}"
        );
    }
}

#[test]
fn bad_meshes_and_parameters_are_errors_naming_the_cause() {
    let (pos, tris) = seamed_grid(2, 2, 1.0, 1.0, 1);
    let ok = SurfaceParams::default();
    let err = |p: &[[f32; 3]], t: &[[u32; 3]], sp: &SurfaceParams| {
        surface_cloth(p, t, sp, |_, _| false).unwrap_err().0
    };
    assert!(err(&pos, &[[0, 1, 99]], &ok).contains("vertex 99"));
    assert!(err(&pos, &[], &ok).contains("no triangles"));
    let mut nan = pos.clone();
    nan[4] = [f32::NAN, 0.0, 0.0];
    assert!(err(&nan, &tris, &ok).contains("vertex 4"));
    let bad = SurfaceParams {
        areal_density: 0.0,
        ..ok
    };
    assert!(err(&pos, &tris, &bad).contains("areal density"));
    let bad = SurfaceParams {
        stretch: SurfaceStiffness::PerArea(f64::NAN),
        ..ok
    };
    assert!(err(&pos, &tris, &bad).contains("stretch"));
    // A triangle whose corners weld together is left out and counted, not a panic.
    let mut close = pos.clone();
    close[1] = [close[0][0] + 1e-7, close[0][1], 0.0];
    let body = surface_cloth(&close, &tris, &ok, |_, _| false).unwrap();
    assert!(body.degenerate >= 1);
}
