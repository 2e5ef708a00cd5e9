//! Skinned display meshes (as in CSC417 assignment 3): a high-resolution triangle mesh embedded in a tet mesh
//! follows it through the sparse skinning matrix `W`, `x_display = W q`.
//!
//! Each display vertex gets the barycentric coordinates of the tet that contains it at rest;
//! a vertex outside every tet (a fine surface bulging past the coarse tet boundary) takes the
//! nearest tet — the one owning the boundary triangle closest to it — and its (partly
//! negative) coordinates extrapolate that tet's linear map, so rigid and affine motion are
//! still reproduced exactly.

use super::mesh::TetMesh;
use crate::math::Vector;
use crate::math::VectorExt;
use glam::{DMat3, DVec3};

/// The skinning matrix: four (tet vertex, weight) pairs per display vertex.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Skinning {
    /// Tet-mesh vertex indices of each display vertex.
    pub indices: Vec<[u32; 4]>,
    /// Barycentric weights (sum 1).
    pub weights: Vec<[f32; 4]>,
    /// Distance (m) from each vertex to the tet mesh at rest (0 inside).
    pub outside: Vec<f32>,
}

fn barycentric(inv: &DMat3, x0: DVec3, p: DVec3) -> [f64; 4] {
    let l = *inv * (p - x0);
    [1.0 - l.x - l.y - l.z, l.x, l.y, l.z]
}

/// Squared distance from `p` to the triangle `t` (Ericson, Real-Time Collision Detection 5.1.5).
fn point_triangle_distance2(p: DVec3, t: [DVec3; 3]) -> f64 {
    let [a, b, c] = t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.length_squared();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.length_squared();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let w = d1 / (d1 - d3);
        return (p - (a + ab * w)).length_squared();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.length_squared();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (p - (a + ac * w)).length_squared();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (p - (b + (c - b) * w)).length_squared();
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (p - (a + ab * v + ac * w)).length_squared()
}

impl Skinning {
    /// Computes `W` for `points` (display-mesh vertices at rest) in `mesh` (at rest).
    pub fn new(mesh: &TetMesh, points: &[[f32; 3]]) -> Self {
        let v = |i: u32| DVec3::from_array(mesh.vertices[i as usize]);
        // Per tet: inverse of [x1−x0, x2−x0, x3−x0] and its bounds.
        let tets: Vec<(DMat3, DVec3, DVec3, DVec3)> = mesh
            .tets
            .iter()
            .map(|t| {
                let x = t.map(v);
                let m = DMat3::from_cols(x[1] - x[0], x[2] - x[0], x[3] - x[0]);
                let lo = x[0].min(x[1]).min(x[2]).min(x[3]);
                let hi = x[0].max(x[1]).max(x[2]).max(x[3]);
                (m.inverse(), x[0], lo, hi)
            })
            .collect();
        // A uniform grid over the mesh bounds; each cell lists the tets whose box meets it.
        let (lo, hi) = mesh.bounds();
        let (lo, hi) = (DVec3::from_array(lo), DVec3::from_array(hi));
        let cells = ((mesh.tets.len() as f64).cbrt().ceil() as usize).clamp(1, 64);
        let size = ((hi - lo) / cells as f64).max(DVec3::splat(1e-12));
        let cell_of = |p: DVec3| {
            let c = ((p - lo) / size).floor();
            c.clamp(DVec3::ZERO, DVec3::splat(cells as f64 - 1.0))
                .as_uvec3()
        };
        let flat = |c: glam::UVec3| (c.x as usize * cells + c.y as usize) * cells + c.z as usize;
        let mut grid: Vec<Vec<u32>> = vec![Vec::new(); cells * cells * cells];
        for (k, t) in tets.iter().enumerate() {
            let (a, b) = (cell_of(t.2), cell_of(t.3));
            for x in a.x..=b.x {
                for y in a.y..=b.y {
                    for z in a.z..=b.z {
                        grid[flat(glam::UVec3::new(x, y, z))].push(k as u32);
                    }
                }
            }
        }
        // Boundary faces and the tet each belongs to.
        let mut face_tet: std::collections::HashMap<[u32; 3], usize> = Default::default();
        for (k, t) in mesh.tets.iter().enumerate() {
            let [a, b, c, d] = *t;
            for f in [[a, c, b], [a, b, d], [a, d, c], [b, c, d]] {
                let mut key = f;
                key.sort_unstable();
                face_tet.insert(key, k);
            }
        }
        let faces: Vec<([u32; 3], usize)> = mesh
            .boundary()
            .into_iter()
            .map(|f| {
                let mut key = f;
                key.sort_unstable();
                (f, face_tet[&key])
            })
            .collect();
        let mut out = Self::default();
        for p in points {
            let p = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let best_in = |list: &mut dyn Iterator<Item = usize>| {
                let mut best = (f64::NEG_INFINITY, 0usize, [0.0; 4]);
                for k in list {
                    let b = barycentric(&tets[k].0, tets[k].1, p);
                    let m = b.iter().copied().fold(f64::INFINITY, f64::min);
                    if m > best.0 {
                        best = (m, k, b);
                        if m >= 0.0 {
                            break;
                        }
                    }
                }
                best
            };
            let inside = (p.cmpge(lo) & p.cmple(hi)).all();
            let best = if inside {
                best_in(&mut grid[flat(cell_of(p))].iter().map(|k| *k as usize))
            } else {
                (f64::NEG_INFINITY, 0, [0.0; 4])
            };
            let (k, b, dist) = if best.0 >= -1e-9 {
                (best.1, best.2, 0.0)
            } else {
                // Outside: the tet of the nearest boundary face.
                let mut near = (f64::INFINITY, 0usize);
                for (f, tet) in &faces {
                    let d2 = point_triangle_distance2(p, f.map(v));
                    if d2 < near.0 {
                        near = (d2, *tet);
                    }
                }
                let k = near.1;
                (k, barycentric(&tets[k].0, tets[k].1, p), near.0.sqrt())
            };
            out.indices.push(mesh.tets[k]);
            out.weights.push(b.map(|w| w as f32));
            out.outside.push(dist as f32);
        }
        out
    }

    /// Number of display vertices.
    pub fn len(&self) -> usize {
        self.indices.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.indices.is_empty()
    }

    /// `out = W q`: display positions from tet-mesh positions.
    pub fn apply(&self, q: &[Vector], out: &mut [[f32; 3]]) {
        for ((o, idx), w) in out.iter_mut().zip(&self.indices).zip(&self.weights) {
            let mut p = glam::Vec3::ZERO;
            for k in 0..4 {
                p += (q[idx[k] as usize]).to_f32() * w[k];
            }
            *o = p.to_array();
        }
    }
}

/// Vertices and counter-clockwise triangles of a display mesh.
pub type TriangleMesh = (Vec<[f32; 3]>, Vec<[u32; 3]>);

/// Reads the vertices and triangles of a Wavefront `.obj` (`v` and `f` lines; polygons are
/// fanned into triangles; texture and normal indices are ignored). Errors name the line.
pub fn read_obj(file: &str, text: &str) -> Result<TriangleMesh, super::mesh::MeshError> {
    let err = |line: usize, message: String| super::mesh::MeshError {
        file: file.to_string(),
        line,
        message,
    };
    let mut v = Vec::new();
    let mut f = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let mut p = [0f32; 3];
                for c in &mut p {
                    let t = it
                        .next()
                        .ok_or_else(|| err(n + 1, "vertex needs 3 coordinates".into()))?;
                    *c = t
                        .parse::<f32>()
                        .ok()
                        .filter(|x| x.is_finite() && x.abs() <= super::mesh::MAX_COORDINATE as f32)
                        .ok_or_else(|| err(n + 1, format!("`{t}` is not a usable coordinate")))?;
                }
                v.push(p);
            }
            Some("f") => {
                let mut idx = Vec::with_capacity(4);
                for t in it {
                    let first = t.split('/').next().unwrap_or("");
                    let i: i64 = first
                        .parse()
                        .map_err(|_| err(n + 1, format!("`{t}` is not a vertex index")))?;
                    // 1-based; negative counts back from the last vertex read.
                    let i = if i < 0 { v.len() as i64 + i } else { i - 1 };
                    if i < 0 || i >= v.len() as i64 {
                        return Err(err(n + 1, format!("vertex index {first} is out of range")));
                    }
                    idx.push(i as u32);
                }
                if idx.len() < 3 {
                    return Err(err(n + 1, "a face needs at least 3 vertices".into()));
                }
                for k in 1..idx.len() - 1 {
                    f.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if v.is_empty() || f.is_empty() {
        return Err(err(0, "no vertices or faces".into()));
    }
    Ok((v, f))
}
