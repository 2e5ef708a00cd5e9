//! Tet meshes: Gmsh `.msh` (v2 ASCII and v4 ASCII), Medit `.mesh` and TetGen `.node`/`.ele`
//! readers, boundary extraction with outward orientation, procedural boxes and beams, and the
//! conversion to a [`Scene`] (lumped masses from the density).
//!
//! Readers never panic: a malformed file (truncated, wrong counts, indices out of range,
//! non-finite or huge coordinates, flat or inverted tets) gives a [`MeshError`] naming the file
//! and line.

use super::NeoHookean;
use super::element::signed_volume;
use crate::core::scene::{ParticleDesc, Scene, Surface, TetDesc};
use glam::DVec3;
use std::collections::HashMap;
use std::fmt;

/// Coordinates above this magnitude (m) are refused: squared and cubed in volumes and
/// energies, they would overflow or swamp every other digit.
pub const MAX_COORDINATE: f64 = 1e6;

/// Vertex or tet counts above this are refused before anything is allocated (a header that
/// claims 10⁹ tets must not exhaust memory).
pub const MAX_COUNT: usize = 10_000_000;

/// A tetrahedral mesh: vertices, positively oriented tets, and the boundary surface.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TetMesh {
    /// Vertex positions (m).
    pub vertices: Vec<[f64; 3]>,
    /// Tets as four vertex indices, each with positive volume
    /// (`dot(b − a, (c − a) × (d − a)) > 0`).
    pub tets: Vec<[u32; 4]>,
}

/// What is wrong with a mesh file, and where.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshError {
    /// The file (or a name given by the caller).
    pub file: String,
    /// 1-based line (0 when the problem is not on one line).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for MeshError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line > 0 {
            write!(f, "{}:{}: {}", self.file, self.line, self.message)
        } else {
            write!(f, "{}: {}", self.file, self.message)
        }
    }
}

impl std::error::Error for MeshError {}

mod gmsh;
mod medit;
mod tetgen;
mod tokens;

/// Checks index ranges, orientation and volume; flips every tet of a file whose tets are all
/// negatively oriented (a whole-file convention); rejects flat tets and mixed orientation.
fn finish(
    file: &str,
    vertices: Vec<[f64; 3]>,
    tets: Vec<([i64; 4], usize)>,
    base: i64,
) -> Result<TetMesh, MeshError> {
    let err = |line: usize, message: String| MeshError {
        file: file.to_string(),
        line,
        message,
    };
    if tets.is_empty() {
        return Err(err(0, "the mesh has no tetrahedra".into()));
    }
    let n = vertices.len() as i64;
    let mut out = Vec::with_capacity(tets.len());
    let mut vols = Vec::with_capacity(tets.len());
    for (k, (t, line)) in tets.iter().enumerate() {
        let mut v = [0u32; 4];
        for (o, &i) in v.iter_mut().zip(t) {
            let i0 = i - base;
            if i0 < 0 || i0 >= n {
                return Err(err(
                    *line,
                    format!(
                        "tet {k}: vertex index {i} is out of range ({} vertices, first index {base})",
                        vertices.len()
                    ),
                ));
            }
            *o = i0 as u32;
        }
        for a in 0..4 {
            for b in a + 1..4 {
                if v[a] == v[b] {
                    return Err(err(*line, format!("tet {k}: vertex {} repeats", t[a])));
                }
            }
        }
        let x = v.map(|i| DVec3::from_array(vertices[i as usize]));
        vols.push(signed_volume(x));
        out.push(v);
    }
    let negative = vols.iter().filter(|v| **v < 0.0).count();
    let flip = negative == vols.len();
    for (k, vol) in vols.iter().enumerate() {
        let vol = if flip { -vol } else { *vol };
        let x = out[k].map(|i| DVec3::from_array(vertices[i as usize]));
        let scale = (x[1] - x[0])
            .length()
            .max((x[2] - x[0]).length())
            .max((x[3] - x[0]).length());
        if vol.is_nan() || vol <= 1e-12 * scale.powi(3) {
            return Err(err(
                tets[k].1,
                format!(
                    "tet {k}: rest volume {vol:e} is not positive ({} of {} tets are negatively oriented)",
                    negative,
                    vols.len()
                ),
            ));
        }
    }
    if flip {
        for t in &mut out {
            t.swap(2, 3);
        }
    }
    Ok(TetMesh {
        vertices,
        tets: out,
    })
}

impl TetMesh {
    /// Reads a file by its extension: `.msh`, `.mesh`, or `.node`/`.ele` (either name; the
    /// other is found beside it).
    pub fn load(path: &std::path::Path) -> Result<Self, MeshError> {
        let name = path.display().to_string();
        let read = |p: &std::path::Path| {
            std::fs::read_to_string(p).map_err(|e| MeshError {
                file: p.display().to_string(),
                line: 0,
                message: e.to_string(),
            })
        };
        match path.extension().and_then(|e| e.to_str()) {
            Some("msh") => Self::from_gmsh(&name, &read(path)?),
            Some("mesh") => Self::from_medit(&name, &read(path)?),
            Some("node") | Some("ele") => {
                let node = path.with_extension("node");
                let ele = path.with_extension("ele");
                Self::from_tetgen(
                    &node.display().to_string(),
                    &read(&node)?,
                    &ele.display().to_string(),
                    &read(&ele)?,
                )
            }
            _ => Err(MeshError {
                file: name,
                line: 0,
                message: "unknown tet-mesh extension (expected .msh, .mesh, .node or .ele)".into(),
            }),
        }
    }

    /// Faces that belong to exactly one tet, wound counter-clockwise seen from outside.
    pub fn boundary(&self) -> Vec<[u32; 3]> {
        boundary_faces(&self.tets)
    }

    /// Total volume (m³).
    pub fn volume(&self) -> f64 {
        self.tets
            .iter()
            .map(|t| signed_volume(t.map(|i| DVec3::from_array(self.vertices[i as usize]))))
            .sum()
    }

    /// Axis-aligned bounds `(min, max)`.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for v in &self.vertices {
            for c in 0..3 {
                lo[c] = lo[c].min(v[c]);
                hi[c] = hi[c].max(v[c]);
            }
        }
        (lo, hi)
    }

    /// The same mesh with its vertices in the order of a Morton (Z-order) curve through its
    /// bounds, the tets as they were; and for each new vertex the index it had
    /// (`ordered.vertices[k] == self.vertices[old[k]]`).
    ///
    /// The force kernels cut a body into chunks of consecutive particles, one thread's work
    /// each; a tet spanning two chunks is the thread's reading what another wrote. Mesh
    /// generators number vertices in no spatial order: the armadillo and bunny in
    /// `assets/meshes` have a median tet spanning 982 and 1054 indices of their 2290 and 2411,
    /// so nearly every tet spans chunks. In this order the armadillo's median tet spans 54,
    /// and a symplectic Euler step took 57.7 µs on two threads against 71.2 (1.23× as fast;
    /// 100.0 against 108.9 µs on one; best runs, `docs/BENCHMARKS.md`). Use it before
    /// [`TetMesh::to_scene`] or `SpawnSoftBody::spawn_tet_body` when nothing refers to the
    /// file's vertex numbers, or map them through `old`. The same forces, particle for particle
    /// (the same bits).
    pub fn spatially_ordered(&self) -> (Self, Vec<u32>) {
        let (lo, hi) = self.bounds();
        // 21 bits an axis, interleaved into a 63-bit key; a flat axis (or no vertex) is 0.
        let key = |p: &[f64; 3]| {
            let q = std::array::from_fn::<u64, 3, _>(|c| {
                let extent = hi[c] - lo[c];
                if extent > 0.0 && extent.is_finite() {
                    ((p[c] - lo[c]) / extent * ((1u64 << 21) - 1) as f64) as u64
                } else {
                    0
                }
            });
            let mut k = 0u64;
            for b in (0..21).rev() {
                for qc in q {
                    k = k << 1 | (qc >> b & 1);
                }
            }
            k
        };
        let mut old: Vec<u32> = (0..self.vertices.len() as u32).collect();
        old.sort_by_cached_key(|&i| key(&self.vertices[i as usize]));
        let mut new_of = vec![0u32; old.len()];
        for (k, &i) in old.iter().enumerate() {
            new_of[i as usize] = k as u32;
        }
        let ordered = TetMesh {
            vertices: old.iter().map(|&i| self.vertices[i as usize]).collect(),
            tets: self
                .tets
                .iter()
                .map(|t| t.map(|i| new_of[i as usize]))
                .collect(),
        };
        (ordered, old)
    }

    /// The mesh scaled by `s` and moved by `offset` (`x ↦ s x + offset`).
    pub fn transformed(mut self, s: f64, offset: [f64; 3]) -> Self {
        for v in &mut self.vertices {
            for c in 0..3 {
                v[c] = v[c] * s + offset[c];
            }
        }
        self
    }

    /// A box `[0, size]` of `cells` cubes per axis, each split into six tets around its main
    /// diagonal (Kuhn/Freudenthal: conforming across cubes). More vertices than
    /// [`MAX_PARTICLES`](crate::core::scene::MAX_PARTICLES), or a size that is not positive and
    /// finite, is refused before anything is allocated.
    pub fn tet_box(
        size: [f64; 3],
        cells: [usize; 3],
    ) -> Result<Self, crate::core::build::BuildError> {
        let [nx, ny, nz] = cells.map(|c| c.max(1));
        let limit = crate::core::scene::MAX_PARTICLES;
        let count = (nx as u128 + 1)
            .saturating_mul(ny as u128 + 1)
            .saturating_mul(nz as u128 + 1);
        if count > limit as u128 {
            return Err(crate::core::build::BuildError(format!(
                "tet box: {nx}×{ny}×{nz} cells need {count} vertices, more than the limit of {limit}"
            )));
        }
        if !size.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(crate::core::build::BuildError(format!(
                "tet box: size {size:?} must be positive and finite"
            )));
        }
        let idx = |i: usize, j: usize, k: usize| ((i * (ny + 1) + j) * (nz + 1) + k) as u32;
        let mut vertices = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
        for i in 0..=nx {
            for j in 0..=ny {
                for k in 0..=nz {
                    vertices.push([
                        size[0] * i as f64 / nx as f64,
                        size[1] * j as f64 / ny as f64,
                        size[2] * k as f64 / nz as f64,
                    ]);
                }
            }
        }
        let perms = [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ];
        let mut tets = Vec::with_capacity(6 * nx * ny * nz);
        for i in 0..nx {
            for j in 0..ny {
                for k in 0..nz {
                    for p in perms {
                        let mut c = [i, j, k];
                        let mut t = [idx(c[0], c[1], c[2]); 4];
                        for (s, &axis) in p.iter().enumerate() {
                            c[axis] += 1;
                            t[s + 1] = idx(c[0], c[1], c[2]);
                        }
                        let x = t.map(|v| DVec3::from_array(vertices[v as usize]));
                        if signed_volume(x) < 0.0 {
                            t.swap(2, 3);
                        }
                        tets.push(t);
                    }
                }
            }
        }
        Ok(Self { vertices, tets })
    }

    /// A beam along x: length `length`, square section of side `side`, `n` cells along its
    /// length and `m` across each side, with its clamped end at x = 0 and its section centred
    /// on the x axis.
    pub fn beam(
        length: f64,
        side: f64,
        n: usize,
        m: usize,
    ) -> Result<Self, crate::core::build::BuildError> {
        Ok(Self::tet_box([length, side, side], [n, m, m])?
            .transformed(1.0, [0.0, -side / 2.0, -side / 2.0]))
    }

    /// The mesh as a scene of one elastic body: one particle per vertex with its lumped mass
    /// `Σ ρ V / 4`, the tets with the body's material, and the boundary as the surface.
    pub fn to_scene(&self, name: &str, material: NeoHookean) -> Scene {
        let mut mass = vec![0.0; self.vertices.len()];
        for t in &self.tets {
            let x = t.map(|i| DVec3::from_array(self.vertices[i as usize]));
            let m = super::element::lumped_mass(material.density, signed_volume(x));
            for &i in t {
                mass[i as usize] += m;
            }
        }
        Scene {
            name: name.into(),
            gravity: [0.0, -9.81, 0.0],
            particles: self
                .vertices
                .iter()
                .zip(&mass)
                .map(|(p, m)| ParticleDesc {
                    position: *p,
                    velocity: [0.0; 3],
                    mass: *m,
                    // A vertex no tet uses has no mass: hold it still.
                    pinned: *m == 0.0,
                })
                .collect(),
            tets: self
                .tets
                .iter()
                .map(|t| TetDesc {
                    vertices: t.map(|i| i as usize),
                    material: None,
                    rest: None,
                })
                .collect(),
            material: Some(material),
            surface: Some(Surface {
                triangles: self.boundary(),
                ..Default::default()
            }),
            ..Default::default()
        }
    }
}

/// The faces of positively oriented tets that belong to one tet only (the boundary), oriented
/// outward, sorted.
pub fn boundary_faces(tets: &[[u32; 4]]) -> Vec<[u32; 3]> {
    let mut faces: HashMap<[u32; 3], ([u32; 3], u32)> = HashMap::new();
    for t in tets {
        let [a, b, c, d] = *t;
        for f in [[a, c, b], [a, b, d], [a, d, c], [b, c, d]] {
            let mut key = f;
            key.sort_unstable();
            faces.entry(key).or_insert((f, 0)).1 += 1;
        }
    }
    let mut out: Vec<[u32; 3]> = faces
        .into_values()
        .filter(|(_, n)| *n == 1)
        .map(|(f, _)| f)
        .collect();
    out.sort_unstable();
    out
}
