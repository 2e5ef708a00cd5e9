//! Cloth from any triangle mesh — an artist's cape or flag, not a grid. Vertices that share a
//! position (split by UV seams or hard normals in the file) are welded into one particle; every
//! edge becomes a stretch spring and every interior edge a bending spring between the two
//! vertices opposite it (the common "crossed spring" bending of mass-spring cloth, as in the
//! flex springs of a grid); masses come from the triangles' areas.

use super::{BuildError, G, check_count};
use crate::core::forces::SpringLaw;
use crate::core::scene::{ParticleDesc, Scene, SpringDesc, SpringKind, Surface};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// How a mesh edge's spring stiffness follows from the mesh, so that the same material gives
/// the same cloth however finely the artist meshed it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SurfaceStiffness {
    /// Per unit length: `k = s / L` (s in N), as a bar of fixed cross-section (`s = E A`):
    /// every spring stretched by the same strain pulls with the same force.
    PerLength(f64),
    /// Per area: `k = s A_e / L²` (s in N/m, a membrane's `E × thickness`), with `A_e` the
    /// area the edge stands for (a third of each triangle beside it). Under a uniform
    /// stretch by strain `ε` the elastic energy is `½ s ε² A`, `A` the mesh's area, on any
    /// mesh of it.
    PerArea(f64),
}

impl SurfaceStiffness {
    fn stiffness(self, length: f64, area: f64) -> f64 {
        match self {
            SurfaceStiffness::PerLength(s) => s / length,
            SurfaceStiffness::PerArea(s) => s * area / (length * length),
        }
    }

    fn value(self) -> f64 {
        match self {
            SurfaceStiffness::PerLength(s) | SurfaceStiffness::PerArea(s) => s,
        }
    }
}

/// Material and welding of a cloth built from a triangle mesh.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SurfaceParams {
    /// Mass per area (kg/m²): each triangle gives a third of its mass to each corner.
    pub areal_density: f64,
    /// Stretch springs along every edge.
    pub stretch: SurfaceStiffness,
    /// Bending springs across every interior edge (`None`: no bending resistance).
    pub bend: Option<SurfaceStiffness>,
    /// Damper along every spring (N·s/m).
    pub damping: f64,
    /// Vertices closer than this are one particle (m): a UV seam's split vertices are welded.
    pub weld_distance: f64,
}

impl Default for SurfaceParams {
    fn default() -> Self {
        Self {
            // A light cotton: 0.2 kg/m²; a membrane stiffness of 200 N/m.
            areal_density: 0.2,
            stretch: SurfaceStiffness::PerArea(200.0),
            bend: Some(SurfaceStiffness::PerArea(2.0)),
            damping: 0.01,
            weld_distance: 1e-5,
        }
    }
}

/// A cloth built from a triangle mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceBody {
    /// The layout: particles (pinned where asked), stretch springs ([`SpringKind::Structural`])
    /// and bending springs ([`SpringKind::Flex`]), the welded triangles as its surface, and
    /// gravity.
    pub scene: Scene,
    /// For every vertex of the input, the particle it became (`None`: in no triangle).
    pub vertex_particle: Vec<Option<u32>>,
    /// Vertices welded into another one (a UV seam's duplicates, split normals).
    pub welded: usize,
    /// Triangles left out because welding or their input made them degenerate (zero area).
    pub degenerate: usize,
    /// Edges shared by more than two triangles (non-manifold): stretch springs, no bending.
    pub nonmanifold_edges: usize,
}

impl SurfaceBody {
    /// Number of stretch springs (one per mesh edge).
    pub fn stretch_springs(&self) -> usize {
        self.scene
            .springs
            .iter()
            .filter(|s| s.kind == SpringKind::Structural)
            .count()
    }

    /// Number of bending springs (one per interior edge).
    pub fn bending_springs(&self) -> usize {
        self.scene
            .springs
            .iter()
            .filter(|s| s.kind == SpringKind::Flex)
            .count()
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Welds vertices closer than `tol` (the first of a cluster is its representative): returns
/// each used vertex's particle and the particles' positions.
fn weld(positions: &[[f64; 3]], used: &[bool], tol: f64) -> (Vec<Option<u32>>, Vec<[f64; 3]>) {
    let cell = tol.max(1e-12);
    let key = |p: [f64; 3]| p.map(|c| (c / cell).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    let mut map = vec![None; positions.len()];
    let mut out: Vec<[f64; 3]> = vec![];
    for (v, p) in positions.iter().enumerate() {
        if !used[v] {
            continue;
        }
        let k = key(*p);
        let mut found = None;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(list) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                        for &q in list {
                            if norm(sub(out[q as usize], *p)) <= tol {
                                found = Some(q);
                                break 'search;
                            }
                        }
                    }
                }
            }
        }
        let q = found.unwrap_or_else(|| {
            let q = out.len() as u32;
            out.push(*p);
            grid.entry(k).or_default().push(q);
            q
        });
        map[v] = Some(q);
    }
    (map, out)
}

/// Builds a cloth from a triangle mesh (`positions` in metres, counter-clockwise
/// `triangles` of vertex indices); `pinned(vertex, position)` picks the vertices held in
/// place (a particle is pinned when any vertex welded into it is). Errors name the first bad
/// index, position or parameter.
pub fn surface_cloth(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    params: &SurfaceParams,
    pinned: impl Fn(usize, [f32; 3]) -> bool,
) -> Result<SurfaceBody, BuildError> {
    let p = params;
    let positive = |what: &str, x: f64| {
        if x.is_finite() && x > 0.0 {
            Ok(())
        } else {
            Err(BuildError(format!(
                "surface cloth: {what} {x} must be a positive number"
            )))
        }
    };
    positive("areal density", p.areal_density)?;
    positive("stretch stiffness", p.stretch.value())?;
    if let Some(b) = p.bend {
        positive("bending stiffness", b.value())?;
    }
    if !(p.damping.is_finite() && p.damping >= 0.0) {
        return Err(BuildError(format!(
            "surface cloth: damping {} must be a non-negative number",
            p.damping
        )));
    }
    if !(p.weld_distance.is_finite() && p.weld_distance >= 0.0) {
        return Err(BuildError(format!(
            "surface cloth: weld distance {} must be a non-negative number",
            p.weld_distance
        )));
    }
    if triangles.is_empty() {
        return Err(BuildError(
            "surface cloth: the mesh has no triangles".into(),
        ));
    }
    let n = positions.len();
    let mut used = vec![false; n];
    for (t, tri) in triangles.iter().enumerate() {
        for &v in tri {
            if v as usize >= n {
                return Err(BuildError(format!(
                    "surface cloth: triangle {t} names vertex {v}, but the mesh has {n}"
                )));
            }
            used[v as usize] = true;
        }
    }
    for (v, x) in positions.iter().enumerate() {
        if used[v] && !x.iter().all(|c| c.is_finite()) {
            return Err(BuildError(format!(
                "surface cloth: vertex {v} is at {x:?}, not a finite position"
            )));
        }
    }
    let pos64: Vec<[f64; 3]> = positions.iter().map(|x| x.map(|c| c as f64)).collect();
    let (vertex_particle, xs) = weld(&pos64, &used, p.weld_distance);
    check_count("surface cloth", xs.len(), 3)?;
    let welded = used.iter().filter(|u| **u).count() - xs.len();

    // Welded triangles, their areas; masses.
    let mut tris: Vec<[u32; 3]> = Vec::with_capacity(triangles.len());
    let mut areas = vec![];
    let mut mass = vec![0.0; xs.len()];
    let mut degenerate = 0;
    for tri in triangles {
        let t = tri.map(|v| vertex_particle[v as usize].expect("used"));
        let area = 0.5
            * norm(cross(
                sub(xs[t[1] as usize], xs[t[0] as usize]),
                sub(xs[t[2] as usize], xs[t[0] as usize]),
            ));
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || area.is_nan() || area <= 0.0 {
            degenerate += 1;
            continue;
        }
        for &i in &t {
            mass[i as usize] += p.areal_density * area / 3.0;
        }
        tris.push(t);
        areas.push(area);
    }
    if let Some(i) = mass.iter().position(|m| *m <= 0.0) {
        let v = vertex_particle
            .iter()
            .position(|q| *q == Some(i as u32))
            .unwrap_or(0);
        return Err(BuildError(format!(
            "surface cloth: vertex {v} lies only on triangles of zero area"
        )));
    }

    // Edges: the area each stands for and the corners opposite it.
    struct Edge {
        area: f64,
        opposite: Vec<u32>,
    }
    let mut edges: HashMap<(u32, u32), Edge> = HashMap::new();
    let mut order: Vec<(u32, u32)> = vec![];
    for (t, area) in tris.iter().zip(&areas) {
        for k in 0..3 {
            let (a, b, o) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let key = (a.min(b), a.max(b));
            let e = edges.entry(key).or_insert_with(|| {
                order.push(key);
                Edge {
                    area: 0.0,
                    opposite: vec![],
                }
            });
            e.area += area / 3.0;
            e.opposite.push(o);
        }
    }
    let mut springs = Vec::with_capacity(order.len() * 2);
    let spring = |a: u32, b: u32, k: f64, kind: SpringKind| SpringDesc {
        a: a as usize,
        b: b as usize,
        stiffness: k,
        damping: p.damping,
        rest_length: None,
        law: SpringLaw::Hooke,
        kind,
    };
    for key in &order {
        let e = &edges[key];
        let l = norm(sub(xs[key.0 as usize], xs[key.1 as usize]));
        springs.push(spring(
            key.0,
            key.1,
            p.stretch.stiffness(l, e.area),
            SpringKind::Structural,
        ));
    }
    let mut nonmanifold_edges = 0;
    if let Some(bend) = p.bend {
        let mut seen: std::collections::HashSet<(u32, u32)> = order.iter().copied().collect();
        for key in &order {
            let e = &edges[key];
            match e.opposite.as_slice() {
                [o1, o2] if o1 != o2 => {
                    let pair = ((*o1).min(*o2), (*o1).max(*o2));
                    if !seen.insert(pair) {
                        continue; // already joined (an edge, or another bending spring)
                    }
                    let l = norm(sub(xs[*o1 as usize], xs[*o2 as usize]));
                    springs.push(spring(
                        pair.0,
                        pair.1,
                        bend.stiffness(l, e.area),
                        SpringKind::Flex,
                    ));
                }
                [_] | [_, _] => {}
                _ => nonmanifold_edges += 1,
            }
        }
    } else {
        nonmanifold_edges = edges.values().filter(|e| e.opposite.len() > 2).count();
    }

    let mut pin = vec![false; xs.len()];
    for (v, q) in vertex_particle.iter().enumerate() {
        if let Some(q) = q
            && pinned(v, positions[v])
        {
            pin[*q as usize] = true;
        }
    }
    let particles = xs
        .iter()
        .zip(&mass)
        .zip(&pin)
        .map(|((x, m), pinned)| ParticleDesc {
            position: *x,
            velocity: [0.0; 3],
            mass: *m,
            pinned: *pinned,
        })
        .collect();
    Ok(SurfaceBody {
        scene: Scene {
            name: "surface cloth".into(),
            gravity: [0.0, -G, 0.0],
            particles,
            springs,
            surface: Some(Surface {
                triangles: tris,
                ..Default::default()
            }),
            ..Default::default()
        },
        vertex_particle,
        welded,
        degenerate,
        nonmanifold_edges,
    })
}
