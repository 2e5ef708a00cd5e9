//! Level of detail for surfaces: a fine display mesh carried by a coarse simulated one.
//!
//! A cloth simulated at 24² and drawn at 24² shows its facets; simulated at 96² it costs
//! about 16 times the particles at a quarter of the stable step. A [`Tessellation`] draws the
//! coarse surface finely instead: every coarse triangle is cut into `level²` triangles whose
//! vertices are points of that triangle, given by barycentric coordinates (the skinning of a
//! display mesh on triangles, as [`fem::skin`](super::fem::skin) does on tets). Vertices on a
//! coarse edge or corner are shared by every triangle that meets there, so the fine mesh is
//! exactly as connected as the coarse one; its first vertices are the coarse vertices
//! themselves, in their order.
//!
//! Flat interpolation would only make the facets smoother-shaded. The fine vertices are lifted
//! off the flat triangles by **Phong tessellation** (Boubekeur and Alexa, *Phong
//! Tessellation*, SIGGRAPH Asia 2008): with `p = Σ bᵢ xᵢ` the flat point and
//! `πᵢ(p) = p − ((p − xᵢ)·nᵢ) nᵢ` its projection onto the tangent plane at corner `i`,
//!
//! ```text
//! p*  = Σ bᵢ πᵢ(p)                  (a quadratic patch through the corners)
//! out = p + α (p* − p),   |α (p* − p)| clamped to max_offset
//! ```
//!
//! where `nᵢ` are the coarse surface's vertex normals: the area-weighted mean of the unit
//! normals of the triangles around vertex `i`, whose length — the normals' coherence — is 1
//! on a flat or smooth surface (to `O(h²)`) and falls towards 0 where the surface folds back
//! on itself, so the rounding fades out at a crease instead of pushing the display along the
//! ill-defined average of nearly opposite normals. The offset on a coarse
//! edge depends only on the edge's two corners, so neighbouring triangles agree there and the
//! fine mesh has no cracks; at the corners it is zero, so the coarse vertices are drawn
//! exactly where they are. `α = ½` (the default [`Rounding`]) reproduces a sphere to second
//! order: the fine mesh's distance to a sphere falls with the fourth power of the coarse
//! edge, against the square for flat triangles (measured in this module's tests).
//! Boubekeur and Alexa suggest `¾` for silhouettes; it overshoots a sphere by half the flat
//! error.
//!
//! The clamp keeps the display inside a shell around the simulated surface: every fine
//! triangle lies within one coarse triangle's shell (its points are convex combinations of
//! points of that triangle plus offsets no longer than the clamp). With self-collision of
//! thickness `t`, the simulated surface keeps every vertex at least `t/2` from the triangles
//! it is not a corner of (the self-collision tests' bound), so shells of `t/4` do not meet
//! there. That is not a proof for every pair of parts: at a sharp crease, edges on the two
//! sides of the fold that share no vertex have been measured 0.36 `t` apart at a frame's end
//! while every vertex stayed a whole `t` from the triangles. There the normals' coherence
//! (above) takes the rounding away; the draping test checks the display for intersections
//! with the exact test, frame by frame.

use glam::Vec3;

/// Most subdivisions of a coarse edge (a level of 16 draws 256 triangles per simulated one).
pub const MAX_LEVEL: u32 = 16;

/// How the fine vertices leave the flat coarse triangles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rounding {
    /// Phong tessellation's shape factor α: 0 keeps the flat triangles, ½ reproduces a
    /// sphere to second order, ¾ is Boubekeur and Alexa's choice for silhouettes, 1 the full
    /// quadratic patch.
    pub alpha: f32,
    /// Longest offset from the flat triangle (m); `f32::INFINITY` for none.
    pub max_offset: f32,
}

impl Default for Rounding {
    fn default() -> Self {
        Self {
            alpha: 0.5,
            max_offset: f32::INFINITY,
        }
    }
}

/// Why a tessellation cannot be made.
#[derive(Clone, Debug, PartialEq)]
pub enum DetailError {
    /// The level is 0 or above [`MAX_LEVEL`].
    Level(u32),
    /// A triangle repeats a vertex.
    Degenerate(usize),
}

impl std::fmt::Display for DetailError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Level(l) => write!(f, "level of detail must be 1 to {MAX_LEVEL}, got {l}"),
            Self::Degenerate(k) => write!(f, "triangle {k} repeats a vertex"),
        }
    }
}

impl std::error::Error for DetailError {}

/// A fine mesh over a coarse triangle surface: for each fine vertex, the coarse triangle
/// corners and barycentric weights it is made from, and the fine triangles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tessellation {
    level: u32,
    coarse: Vec<[u32; 3]>,
    coarse_vertices: usize,
    corners: Vec<[u32; 3]>,
    weights: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
}

impl Tessellation {
    /// Cuts every triangle of `triangles` (over `vertices` coarse vertices; more than the
    /// triangles name is allowed: the extra ones become isolated fine vertices) into
    /// `level²`. Level 1 is the coarse mesh itself.
    pub fn new(triangles: &[[u32; 3]], vertices: usize, level: u32) -> Result<Self, DetailError> {
        if level == 0 || level > MAX_LEVEL {
            return Err(DetailError::Level(level));
        }
        let vertices = triangles
            .iter()
            .flatten()
            .map(|&i| i as usize + 1)
            .max()
            .unwrap_or(0)
            .max(vertices);
        if let Some(k) = triangles
            .iter()
            .position(|&[a, b, c]| a == b || b == c || a == c)
        {
            return Err(DetailError::Degenerate(k));
        }
        let n = level;
        let nf = n as f32;
        let mut t = Self {
            level,
            coarse: triangles.to_vec(),
            coarse_vertices: vertices,
            corners: (0..vertices as u32).map(|i| [i, i, i]).collect(),
            weights: vec![[1.0, 0.0, 0.0]; vertices],
            triangles: Vec::with_capacity(triangles.len() * (n * n) as usize),
        };
        // Edge vertices: `n − 1` per coarse edge, numbered from its lower corner.
        let mut edges: std::collections::HashMap<(u32, u32), u32> = Default::default();
        let mut edge = |t: &mut Self, p: u32, q: u32, step: u32| -> u32 {
            let (lo, hi, s) = if p < q {
                (p, q, step)
            } else {
                (q, p, n - step)
            };
            let base = *edges.entry((lo, hi)).or_insert_with(|| {
                let base = t.corners.len() as u32;
                for s in 1..n {
                    t.corners.push([lo, hi, lo]);
                    t.weights.push([(n - s) as f32 / nf, s as f32 / nf, 0.0]);
                }
                base
            });
            base + s - 1
        };
        let mut grid = vec![0u32; ((n + 1) * (n + 2) / 2) as usize];
        let at = |r: u32, s: u32| (r * (2 * n + 3 - r) / 2 + s) as usize;
        for &[a, b, c] in triangles {
            // Grid point (r, s): weights (n − r − s, r, s) / n over (a, b, c).
            for r in 0..=n {
                for s in 0..=n - r {
                    let id = match (r, s) {
                        (0, 0) => a,
                        (r, 0) if r == n => b,
                        (0, s) if s == n => c,
                        (r, 0) => edge(&mut t, a, b, r),
                        (0, s) => edge(&mut t, a, c, s),
                        (r, s) if r + s == n => edge(&mut t, b, c, s),
                        (r, s) => {
                            t.corners.push([a, b, c]);
                            t.weights
                                .push([(n - r - s) as f32 / nf, r as f32 / nf, s as f32 / nf]);
                            t.corners.len() as u32 - 1
                        }
                    };
                    grid[at(r, s)] = id;
                }
            }
            for r in 0..n {
                for s in 0..n - r {
                    t.triangles
                        .push([grid[at(r, s)], grid[at(r + 1, s)], grid[at(r, s + 1)]]);
                    if r + s + 2 <= n {
                        t.triangles.push([
                            grid[at(r + 1, s)],
                            grid[at(r + 1, s + 1)],
                            grid[at(r, s + 1)],
                        ]);
                    }
                }
            }
        }
        Ok(t)
    }

    /// Subdivisions of a coarse edge.
    pub fn level(&self) -> u32 {
        self.level
    }

    /// Number of coarse vertices (the fine mesh's first vertices are they).
    pub fn coarse_vertices(&self) -> usize {
        self.coarse_vertices
    }

    /// The coarse triangles.
    pub fn coarse_triangles(&self) -> &[[u32; 3]] {
        &self.coarse
    }

    /// Number of fine vertices: the coarse ones, `level − 1` per coarse edge and
    /// `(level − 1)(level − 2)/2` inside each coarse triangle.
    pub fn len(&self) -> usize {
        self.corners.len()
    }

    /// True when there are no vertices.
    pub fn is_empty(&self) -> bool {
        self.corners.is_empty()
    }

    /// The fine triangles (counter-clockwise like the coarse ones).
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Each fine vertex's coarse corners and barycentric weights (a corner with weight 0 is a
    /// repeat and plays no part).
    pub fn skin(&self) -> impl Iterator<Item = ([u32; 3], [f32; 3])> + '_ {
        self.corners
            .iter()
            .copied()
            .zip(self.weights.iter().copied())
    }

    /// Per-vertex attributes (texture coordinates, colours) interpolated to the fine vertices.
    pub fn interpolate<const D: usize>(&self, coarse: &[[f32; D]]) -> Vec<[f32; D]> {
        self.skin()
            .map(|(c, w)| {
                let mut out = [0.0; D];
                for k in 0..3 {
                    if w[k] != 0.0 {
                        for (o, v) in out.iter_mut().zip(coarse[c[k] as usize]) {
                            *o += w[k] * v;
                        }
                    }
                }
                out
            })
            .collect()
    }

    /// Fine vertex positions from the coarse ones (`x`, at least
    /// [`coarse_vertices`](Self::coarse_vertices) long), with the coarse surface's smooth
    /// normals.
    pub fn apply(&self, x: &[Vec3], rounding: Rounding, out: &mut [[f32; 3]]) {
        self.apply_with_normals(x, &self.coarse_normals(x), rounding, out);
    }

    /// What a renderer needs each frame: fine positions from the coarse ones (`x`) and their
    /// shading normals, both from one computation of the coarse normals.
    pub fn draw(
        &self,
        x: &[Vec3],
        rounding: Rounding,
        positions: &mut [[f32; 3]],
        normals: &mut [[f32; 3]],
    ) {
        let coarse = self.coarse_normals(x);
        self.apply_with_normals(x, &coarse, rounding, positions);
        self.shade(&coarse, normals);
    }

    /// The coarse surface's vertex normals at positions `x`: the area-weighted mean of the
    /// unit normals of the triangles around each vertex, `Σ A_f n_f / Σ A_f`. Its length is
    /// the normals' coherence — 1 where the surface is flat around the vertex, `1 − O(h²)`
    /// where it is smooth, near 0 where it folds back on itself — so the rounding fades out
    /// at a crease, where a unit normal would be the average of nearly opposite ones and
    /// point anywhere (`+Y` where no triangle with area touches a vertex).
    pub fn coarse_normals(&self, x: &[Vec3]) -> Vec<Vec3> {
        let mut normals = vec![Vec3::ZERO; x.len()];
        let mut area = vec![0.0f32; x.len()];
        for_each_face_normal(x, &self.coarse, |t, n| {
            let len = n.length();
            for &i in t {
                normals[i as usize] += n;
                area[i as usize] += len;
            }
        });
        for (n, a) in normals.iter_mut().zip(area) {
            *n = if a > 0.0 && a.is_finite() {
                *n / a
            } else {
                Vec3::Y
            };
        }
        normals
    }

    /// Shading normals of the fine vertices: the coarse vertex normals interpolated and
    /// normalized (Phong shading, as Boubekeur and Alexa pair with the tessellation). They
    /// vary smoothly across coarse edges, where the fine mesh's own face normals turn
    /// (the quadratic patches meet with a crease), which shading would show as a faint grid.
    pub fn shade(&self, coarse_normals: &[Vec3], out: &mut [[f32; 3]]) {
        for ((o, c), w) in out.iter_mut().zip(&self.corners).zip(&self.weights) {
            let n = c
                .iter()
                .zip(w)
                .filter(|(_, w)| **w != 0.0)
                .fold(Vec3::ZERO, |n, (&c, &w)| n + coarse_normals[c as usize] * w);
            *o = n.try_normalize().unwrap_or(Vec3::Y).to_array();
        }
    }

    /// [`apply`](Self::apply) with given vertex normals (unit, or shorter where the rounding
    /// should be weaker: it scales with the square of their lengths).
    pub fn apply_with_normals(
        &self,
        x: &[Vec3],
        normals: &[Vec3],
        rounding: Rounding,
        out: &mut [[f32; 3]],
    ) {
        let Rounding { alpha, max_offset } = rounding;
        for ((o, c), w) in out.iter_mut().zip(&self.corners).zip(&self.weights) {
            if w[0] == 1.0 {
                *o = x[c[0] as usize].to_array(); // a coarse vertex: exactly itself
                continue;
            }
            let [xa, xb, xc] = c.map(|i| x[i as usize]);
            let p = xa * w[0] + xb * w[1] + xc * w[2];
            let mut d = Vec3::ZERO;
            for k in 0..3 {
                if w[k] != 0.0 {
                    let (xi, ni) = (x[c[k] as usize], normals[c[k] as usize]);
                    d -= ni * (w[k] * (p - xi).dot(ni));
                }
            }
            d *= alpha;
            let len2 = d.length_squared();
            if len2 > max_offset * max_offset {
                d *= max_offset / len2.sqrt();
            }
            *o = (p + d).to_array();
        }
    }
}

/// Area-weighted unit vertex normals of a triangle mesh (`+Y` where no triangle with area
/// touches a vertex). `normals` is as long as `x`.
pub fn vertex_normals(x: &[Vec3], triangles: &[[u32; 3]], normals: &mut [Vec3]) {
    normals.fill(Vec3::ZERO);
    for_each_face_normal(x, triangles, |t, n| {
        for &i in t {
            normals[i as usize] += n;
        }
    });
    for n in normals.iter_mut() {
        *n = n.try_normalize().unwrap_or(Vec3::Y);
    }
}

/// Calls `f(triangle, n)` for every triangle, `n` its normal with twice its area as length (so
/// that sums over the triangles at a vertex weigh larger ones more).
fn for_each_face_normal(x: &[Vec3], triangles: &[[u32; 3]], mut f: impl FnMut(&[u32; 3], Vec3)) {
    for t in triangles {
        let [a, b, c] = t.map(|i| x[i as usize]);
        f(t, (b - a).cross(c - a));
    }
}

/// A sphere of triangles: the icosahedron cut `k` times by a [`Tessellation`] of level 2
/// (each triangle into four at its edges' midpoints), every vertex pushed onto the unit
/// sphere: `10·4ᵏ + 2` vertices, `20·4ᵏ` triangles.
pub fn icosphere(k: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let g = (1.0 + 5f32.sqrt()) / 2.0;
    let mut x: Vec<Vec3> = [
        [-1.0, g, 0.0],
        [1.0, g, 0.0],
        [-1.0, -g, 0.0],
        [1.0, -g, 0.0],
        [0.0, -1.0, g],
        [0.0, 1.0, g],
        [0.0, -1.0, -g],
        [0.0, 1.0, -g],
        [g, 0.0, -1.0],
        [g, 0.0, 1.0],
        [-g, 0.0, -1.0],
        [-g, 0.0, 1.0],
    ]
    .map(|p| Vec3::from_array(p).normalize())
    .to_vec();
    let mut t: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..k {
        let fine = Tessellation::new(&t, x.len(), 2).expect("an icosphere's triangles");
        let mut y = vec![[0.0; 3]; fine.len()];
        fine.apply(
            &x,
            Rounding {
                alpha: 0.0,
                ..Default::default()
            },
            &mut y,
        );
        x = y.iter().map(|p| Vec3::from_array(*p).normalize()).collect();
        t = fine.triangles().to_vec();
    }
    (x, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Largest distance of the fine vertices from the unit sphere, and the longest coarse edge.
    fn sphere_error(k: u32, alpha: f32) -> (f64, f64) {
        let (x, t) = icosphere(k);
        let normals: Vec<Vec3> = x.clone(); // exact: the sphere's own normals
        let fine = Tessellation::new(&t, x.len(), 8).unwrap();
        let mut y = vec![[0.0; 3]; fine.len()];
        let r = Rounding {
            alpha,
            ..Default::default()
        };
        fine.apply_with_normals(&x, &normals, r, &mut y);
        let err = y
            .iter()
            .map(|p| {
                let p = p.map(|c| c as f64);
                ((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 1.0).abs()
            })
            .fold(0.0, f64::max);
        let edge = t
            .iter()
            .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
            .map(|(a, b)| x[a as usize].distance(x[b as usize]) as f64)
            .fold(0.0, f64::max);
        (err, edge)
    }

    #[test]
    fn counts_and_sharing_follow_the_subdivision() {
        // Two triangles sharing the edge 1–2, and a fifth vertex no triangle names.
        let tris = [[0, 1, 2], [2, 1, 3]];
        for n in 1..=6u32 {
            let t = Tessellation::new(&tris, 5, n).unwrap();
            // V + E (n − 1) + F (n − 1)(n − 2)/2 with V = 5, E = 5, F = 2.
            let expect = 5 + 5 * (n - 1) + 2 * (n - 1) * n.saturating_sub(2) / 2;
            assert_eq!(t.len() as u32, expect, "level {n}");
            assert_eq!(t.triangles().len() as u32, 2 * n * n);
            // Every fine edge is used by one or two fine triangles, and by two exactly when it
            // is inside the coarse surface: the shared coarse edge leaves no crack.
            let mut uses: std::collections::HashMap<(u32, u32), u32> = Default::default();
            for &[a, b, c] in t.triangles() {
                for (p, q) in [(a, b), (b, c), (c, a)] {
                    *uses.entry((p.min(q), p.max(q))).or_default() += 1;
                }
            }
            let boundary = uses.values().filter(|&&u| u == 1).count() as u32;
            assert!(uses.values().all(|&u| u <= 2));
            assert_eq!(
                boundary,
                4 * n,
                "the coarse boundary's four edges, cut in {n}"
            );
        }
        assert_eq!(Tessellation::new(&tris, 4, 0), Err(DetailError::Level(0)));
        assert_eq!(
            Tessellation::new(&tris, 4, MAX_LEVEL + 1),
            Err(DetailError::Level(MAX_LEVEL + 1))
        );
        assert_eq!(
            Tessellation::new(&[[0, 1, 1]], 2, 2),
            Err(DetailError::Degenerate(0))
        );
    }

    #[test]
    fn fine_triangles_turn_the_way_the_coarse_ones_do_and_cover_them() {
        // A bent pair of triangles, drawn flat (α = 0): the fine triangles' areas sum to each
        // coarse triangle's, and each fine normal points along its coarse triangle's.
        let x = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.7),
        ];
        let tris = [[0, 1, 2], [2, 1, 3]];
        let t = Tessellation::new(&tris, 4, 5).unwrap();
        let mut y = vec![[0.0; 3]; t.len()];
        let flat = Rounding {
            alpha: 0.0,
            ..Default::default()
        };
        t.apply(&x, flat, &mut y);
        let y: Vec<Vec3> = y.into_iter().map(Vec3::from_array).collect();
        let area = |p: [Vec3; 3]| (p[1] - p[0]).cross(p[2] - p[0]);
        let mut sums = [Vec3::ZERO; 2];
        for (k, f) in t.triangles().iter().enumerate() {
            let coarse = k / 25;
            let a = area(f.map(|i| y[i as usize]));
            let c = area(tris[coarse].map(|i| x[i as usize]));
            assert!(a.dot(c) > 0.0, "fine triangle {k} turned over");
            sums[coarse] += a;
        }
        for (s, tri) in sums.iter().zip(tris) {
            let c = area(tri.map(|i| x[i as usize]));
            assert!((*s - c).length() < 1e-5 * c.length(), "{s} against {c}");
        }
    }

    #[test]
    fn coarse_vertices_are_drawn_exactly_and_a_plane_stays_flat() {
        // A rigidly moved flat sheet: every normal is the plane's, every offset zero, so the
        // fine vertices are the flat barycentric points; the coarse vertices are themselves.
        let rot = glam::Quat::from_axis_angle(Vec3::new(1.0, 2.0, 0.5).normalize(), 0.8);
        let mut x = Vec::new();
        for j in 0..4 {
            for i in 0..4 {
                x.push(rot * Vec3::new(i as f32 * 0.1, j as f32 * 0.1, 0.0) + Vec3::splat(0.3));
            }
        }
        let mut tris = Vec::new();
        for j in 0..3u32 {
            for i in 0..3u32 {
                let a = j * 4 + i;
                tris.push([a, a + 1, a + 5]);
                tris.push([a, a + 5, a + 4]);
            }
        }
        let t = Tessellation::new(&tris, x.len(), 4).unwrap();
        let mut y = vec![[0.0; 3]; t.len()];
        t.apply(&x, Rounding::default(), &mut y);
        for (p, q) in x.iter().zip(&y) {
            assert_eq!(p.to_array(), *q);
        }
        let normal = rot * Vec3::Z;
        for (q, (c, w)) in y.iter().zip(t.skin()) {
            let flat = x[c[0] as usize] * w[0] + x[c[1] as usize] * w[1] + x[c[2] as usize] * w[2];
            assert!(Vec3::from_array(*q).distance(flat) < 1e-6);
            assert!((Vec3::from_array(*q) - x[0]).dot(normal).abs() < 1e-6);
        }
    }

    #[test]
    fn phong_tessellation_at_one_half_reproduces_a_sphere_to_second_order() {
        // Icospheres of 80, 320 and 1280 triangles with their exact normals, each cut 8 ways.
        // Flat triangles miss the sphere by about e²/8 (e the edge): halving e quarters it.
        // Phong tessellation with α = ½ matches the sphere's second fundamental form, so its
        // error is fourth order: halving e divides it by about 16. α = ¾ overshoots: at an edge's
        // middle the flat error is e²/8 and the offset (3/4)(e²/4), at a centre e²/6 and
        // (3/4)(e²/3): half the flat error either way, second order again.
        let flat: Vec<_> = (1..4).map(|k| sphere_error(k, 0.0)).collect();
        let half: Vec<_> = (1..4).map(|k| sphere_error(k, 0.5)).collect();
        let three: Vec<_> = (1..4).map(|k| sphere_error(k, 0.75)).collect();
        let order =
            |e: &[(f64, f64)], i: usize| (e[i].0 / e[i + 1].0).ln() / (e[i].1 / e[i + 1].1).ln();
        println!("flat {flat:?}\nα=½ {half:?}\nα=¾ {three:?}");
        for i in 0..2 {
            let (f, h, t) = (order(&flat, i), order(&half, i), order(&three, i));
            println!("orders: flat {f:.2}, α=½ {h:.2}, α=¾ {t:.2}");
            assert!((f - 2.0).abs() < 0.2, "flat: {f}");
            assert!(h > 3.6, "α = ½: {h}");
            assert!(t > 1.5 && t < 2.3, "α = ¾: {t}");
        }
        let ratio = three[2].0 / flat[2].0;
        assert!((ratio - 0.5).abs() < 0.1, "α = ¾ against flat: {ratio}");
        // And at the coarsest mesh α = ½ is already far closer than flat.
        assert!(half[0].0 < 0.1 * flat[0].0);
    }

    #[test]
    fn the_offset_is_clamped_and_the_mesh_stays_closed() {
        // A coarse icosphere drawn with a tight clamp: no vertex leaves the flat triangles by
        // more than it, and vertices on shared edges are shared (the fine mesh is closed: every
        // fine edge is used twice).
        let (x, t) = icosphere(0);
        let fine = Tessellation::new(&t, x.len(), 6).unwrap();
        let r = Rounding {
            alpha: 1.0,
            max_offset: 0.01,
        };
        let mut y = vec![[0.0; 3]; fine.len()];
        fine.apply(&x, r, &mut y);
        let mut clamped = 0;
        for (q, (c, w)) in y.iter().zip(fine.skin()) {
            let flat = x[c[0] as usize] * w[0] + x[c[1] as usize] * w[1] + x[c[2] as usize] * w[2];
            let d = Vec3::from_array(*q).distance(flat);
            assert!(d <= 0.01 * (1.0 + 1e-5), "{d}");
            clamped += (d > 0.0099) as usize;
        }
        assert!(clamped > fine.len() / 2, "the clamp must bite: {clamped}");
        let mut uses: std::collections::HashMap<(u32, u32), u32> = Default::default();
        for &[a, b, c] in fine.triangles() {
            for (p, q) in [(a, b), (b, c), (c, a)] {
                *uses.entry((p.min(q), p.max(q))).or_default() += 1;
            }
        }
        assert!(uses.values().all(|&u| u == 2));
        // Attributes interpolate: the coarse positions as a 3-vector attribute give the flat
        // points.
        let attr: Vec<[f32; 3]> = x.iter().map(|p| p.to_array()).collect();
        let lerp = fine.interpolate(&attr);
        for (l, (c, w)) in lerp.iter().zip(fine.skin()) {
            let flat = x[c[0] as usize] * w[0] + x[c[1] as usize] * w[1] + x[c[2] as usize] * w[2];
            assert!(Vec3::from_array(*l).distance(flat) < 1e-6);
        }
    }
}
