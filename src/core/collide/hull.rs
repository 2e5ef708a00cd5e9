//! A convex polyhedron's boundary as the planes of its own triangles, for point and
//! triangle queries without GJK.
//!
//! Parry projects a point onto a convex polyhedron by GJK, each support point a scan of
//! every vertex: 2.6 µs a point on a 162-vertex hull, 10 µs on a 642-vertex one. The planes
//! of a triangulation of the hull's boundary answer a point's query exactly:
//!
//! - Each triangle's plane is a supporting plane (its offset is the hull's support value
//!   along the normal), so the distance of a point outside is at least the largest signed
//!   distance `s` to the planes: a point with `s` beyond a thickness is not within it.
//! - A point outside whose foot on that plane lies in the triangle has the foot as its
//!   nearest point: the foot belongs to the hull and is `s` away.
//! - A point inside (every `s ≤ 0`) is nearest the boundary on the plane it is least inside
//!   of: the ball of that radius about it lies in the hull, and touches the plane within
//!   the hull.
//! - What is left (a point outside whose foot falls beside its triangle: near an edge or a
//!   corner) takes the nearest of the nearest points of the triangles it is in front of.
//!
//! Parry's GJK projection onto a `ConvexPolyhedron` is less exact: within 4 cm of twenty
//! random hulls its distance came out up to 3.1 mm off a brute-force distance over the
//! triangles (the unit test that checks these answers against it prints the figure).
//!
//! The planes are not scanned one by one where a walk will do. Each triangle knows its
//! three neighbours, and a cube map of directions about the hull's centre knows where to
//! start: a walk from there to the neighbour farther out, while there is one, ends at a
//! plane that settles most queries (any plane that settles one settles it exactly; a point
//! the walk leaves unsettled is scanned). A cloth's triangle the walk leaves unsettled takes
//! the exact closest points against each hull triangle that can hold its nearest point
//! ([`HullPlanes::near_triangles`]: those near it in a hierarchy of boxes that it is not
//! wholly behind); parry's GJK on a triangle and the polyhedron was up to 7 mm off. One that
//! crosses the hull goes to parry's contact query for its depth, whose support points come
//! by the same kind of walk along the hull's edges, which for a support function on a convex
//! polyhedron ends at the farthest vertex.
//!
//! The triangles are parry's convex hull of the polyhedron's vertices (parry's own
//! `ConvexPolyhedron` merges triangles within about 1.5° into one face, with the first one's
//! normal, so its faces' planes are not the hull's). Computing them costs about 100 µs for
//! 162 vertices; colliders are made afresh every frame from the same shapes, so the planes
//! are kept per shape (by the address of its shared allocation, while it lives).

use crate::core::self_contact::closest_on_triangle;
use parry3d::shape::{Shape, SharedShape};
use std::sync::{Arc, Mutex, Weak};

/// Planes a pass of the scans takes at once (padded to whole lanes).
const LANES: usize = 8;

/// A convex polyhedron's triangles: their outward unit normals and offsets (supporting
/// planes `n · x = w`) in structure of arrays, and their corners, in the shape's frame and
/// parry's precision.
pub(super) struct HullPlanes {
    nx: Vec<f32>,
    ny: Vec<f32>,
    nz: Vec<f32>,
    w: Vec<f32>,
    corners: Vec<[glam::Vec3; 3]>,
    /// Each triangle's neighbours across its three edges ([`NONE`] where the neighbour was
    /// a sliver left out).
    adjacent: Vec<[u32; 3]>,
    /// A point inside the hull (its vertices' centroid), the centre of [`HullPlanes::start`]'s
    /// directions.
    centre: glam::Vec3,
    /// For each cell of a cube map of directions about `centre` (`CELLS`² a face), the
    /// triangle whose normal is nearest the cell's middle: where a walk starts.
    start: Vec<u32>,
    /// The hull's vertices, each one's neighbours along edges (`ring[ring_at[v]..ring_at[v
    /// + 1]]`), and for each cell of the cube map the vertex farthest along its middle:
    /// the support function by a walk ([`HullPlanes::support`]).
    vertices: Vec<glam::Vec3>,
    ring_at: Vec<u32>,
    ring: Vec<u32>,
    vertex_start: Vec<u32>,
    /// The same triangles as a mesh (triangle `k` is plane `k`), for its hierarchy of boxes:
    /// the triangles near a cloth's that no plane settles ([`HullPlanes::near_triangles`]).
    mesh: Option<parry3d::shape::TriMesh>,
}

/// No neighbour (see [`HullPlanes`]'s `adjacent`).
const NONE: u32 = u32::MAX;

/// Cells along each edge of a face of the start cube map.
const CELLS: usize = 4;

/// A point's nearest point on a convex polyhedron's boundary (see [`HullPlanes::foot`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct HullFoot {
    /// The nearest point of the boundary.
    pub point: glam::Vec3,
    /// The outward normal there (the direction to the point outside).
    pub normal: glam::Vec3,
    /// The signed distance (negative inside).
    pub signed: f32,
}

impl HullPlanes {
    /// The planes of a convex polyhedron's boundary, or `None` when its triangulation is not
    /// a fit for exact answers (fewer than four triangles, or a corner farther than
    /// round-off inside its own triangle's supporting plane: a triangle that is not part of
    /// the boundary).
    fn build(points: &[glam::Vec3]) -> Option<Self> {
        if points.len() < 4 {
            return None;
        }
        let (verts, tris) = parry3d::transformation::try_convex_hull(points).ok()?;
        if tris.len() < 4 || verts.is_empty() {
            return None;
        }
        let centroid = verts.iter().copied().sum::<glam::Vec3>() / verts.len() as f32;
        let scale = verts
            .iter()
            .map(|v| (*v - centroid).length())
            .fold(0.0f32, f32::max);
        if !(scale.is_finite() && scale > 0.0) {
            return None;
        }
        let mut planes = Self {
            nx: Vec::with_capacity(tris.len()),
            ny: Vec::with_capacity(tris.len()),
            nz: Vec::with_capacity(tris.len()),
            w: Vec::with_capacity(tris.len()),
            corners: Vec::with_capacity(tris.len()),
            adjacent: Vec::with_capacity(tris.len()),
            centre: centroid,
            start: Vec::new(),
            vertices: Vec::new(),
            ring_at: Vec::new(),
            ring: Vec::new(),
            vertex_start: Vec::new(),
            mesh: None,
        };
        // Which kept triangle each of parry's is (slivers are not kept).
        let mut kept = vec![NONE; tris.len()];
        for (i, t) in tris.iter().enumerate() {
            let [a, b, c] = t.map(|i| verts[i as usize]);
            let cross = (b - a).cross(c - a);
            // A sliver (its normal round-off): the triangles around it cover its part of
            // the boundary.
            if cross.length() <= 1e-6 * scale * scale {
                continue;
            }
            let mut n = cross.normalize();
            let mut tri = [a, b, c];
            if n.dot(a - centroid) < 0.0 {
                n = -n;
                tri = [a, c, b];
            }
            let w = verts.iter().map(|v| n.dot(*v)).fold(f32::MIN, f32::max);
            // Its own corners on its supporting plane, to round-off.
            if tri.iter().any(|p| w - n.dot(*p) > 1e-5 * scale) {
                return None;
            }
            planes.nx.push(n.x);
            planes.ny.push(n.y);
            planes.nz.push(n.z);
            planes.w.push(w);
            planes.corners.push(tri);
            kept[i] = planes.adjacent.len() as u32;
            planes.adjacent.push([NONE; 3]);
        }
        if planes.w.len() < 4 {
            return None;
        }
        // Neighbours across edges: each undirected edge's two triangles.
        let mut edges: Vec<(u32, u32, u32)> = Vec::with_capacity(3 * tris.len());
        for (i, t) in tris.iter().enumerate() {
            if kept[i] != NONE {
                for e in 0..3 {
                    let (u, v) = (t[e], t[(e + 1) % 3]);
                    edges.push((u.min(v), u.max(v), kept[i]));
                }
            }
        }
        edges.sort_unstable();
        for pair in edges.windows(2) {
            let ((u, v, a), (u2, v2, b)) = (pair[0], pair[1]);
            if (u, v) == (u2, v2) && a != b {
                for (from, to) in [(a, b), (b, a)] {
                    let slot = &mut planes.adjacent[from as usize];
                    if let Some(free) = slot.iter_mut().find(|j| **j == NONE) {
                        *free = to;
                    }
                }
            }
        }
        planes.start = Self::cube_map(planes.corners.len(), |i| planes.normal(i));
        // The vertices' rings, from every triangle's edges (slivers' included: their edges
        // are the hull's).
        let mut links: Vec<(u32, u32)> = tris
            .iter()
            .flat_map(|t| {
                (0..3).flat_map(move |e| [(t[e], t[(e + 1) % 3]), (t[(e + 1) % 3], t[e])])
            })
            .collect();
        links.sort_unstable();
        links.dedup();
        planes.ring_at = (0..=verts.len())
            .map(|v| links.partition_point(|&(u, _)| (u as usize) < v) as u32)
            .collect();
        planes.ring = links.into_iter().map(|(_, w)| w).collect();
        planes.vertex_start = Self::cube_map(verts.len(), |i| verts[i]);
        planes.vertices = verts;
        let corners: Vec<glam::Vec3> = planes.corners.iter().flatten().copied().collect();
        let indices = (0..planes.corners.len() as u32)
            .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
            .collect();
        planes.mesh = Some(parry3d::shape::TriMesh::new(corners, indices).ok()?);
        // Whole lanes: planes that put every point infinitely far inside.
        while !planes.w.len().is_multiple_of(LANES) {
            planes.nx.push(0.0);
            planes.ny.push(0.0);
            planes.nz.push(0.0);
            planes.w.push(f32::INFINITY);
        }
        Some(planes)
    }

    /// The planes of `shape` when it is a convex polyhedron, kept for as long as the shape
    /// lives (see the module's docs).
    pub(super) fn of(shape: &SharedShape) -> Option<Arc<Self>> {
        type Cache = Vec<(Weak<dyn Shape>, Option<Arc<HullPlanes>>)>;
        static CACHE: Mutex<Cache> = Mutex::new(Vec::new());
        let poly = shape.as_convex_polyhedron()?;
        let key = Arc::as_ptr(&shape.0) as *const ();
        let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
        // A live entry at the same address is this shape: its allocation cannot be reused
        // while a weak reference to it stands.
        if let Some((_, planes)) = cache
            .iter()
            .find(|(w, _)| w.as_ptr() as *const () == key && w.strong_count() > 0)
        {
            return planes.clone();
        }
        cache.retain(|(w, _)| w.strong_count() > 0);
        let planes = Self::build(poly.points()).map(Arc::new);
        cache.push((Arc::downgrade(&shape.0), planes.clone()));
        planes
    }

    /// How many triangles.
    #[cfg(test)]
    pub(super) fn len(&self) -> usize {
        self.corners.len()
    }

    /// The nearest point of the boundary to `p` (in the shape's frame), the outward normal
    /// there, and the signed distance (negative inside): see the module's docs. A point
    /// outside whose foot on its farthest plane falls beside that triangle (near an edge or
    /// a corner) takes the nearest of the nearest points of every triangle it is in front of
    /// (Ericson's point–triangle test, `self_contact::closest_on_triangle`; one of those
    /// holds the nearest point: where it lies on several triangles, `p − q` is
    /// in their normals' cone, and its square `Σ aᵢ (nᵢ · (p − q)) > 0` makes some
    /// `nᵢ · (p − q)` positive); the normal is then the direction from that point. `None`
    /// when a plane puts `p` at `within` or farther (so is the hull).
    pub(super) fn foot(&self, p: glam::Vec3, within: f32) -> Option<HullFoot> {
        // A walk's plane settles a point outside it whose foot lies in its triangle, or one
        // at `within` or beyond; the scan the rest.
        let (s, k) = self.climb(|k| self.signed(k, p), self.start_for(p - self.centre));
        if s >= within {
            return None;
        }
        if s > 0.0 {
            let normal = self.normal(k);
            let point = p - normal * s;
            if self.holds(k, point) {
                return Some(HullFoot {
                    point,
                    normal,
                    signed: s,
                });
            }
        }
        let (best, k) = self.farthest(|x, y, z, w| x * p.x + y * p.y + z * p.z - w);
        if best >= within {
            return None;
        }
        let normal = self.normal(k);
        let point = p - normal * best;
        if best <= 0.0 || self.holds(k, point) {
            return Some(HullFoot {
                point,
                normal,
                signed: best,
            });
        }
        let (mut q, mut d2) = (point, f32::INFINITY);
        for i in 0..self.corners.len() {
            if self.signed(i, p) > 0.0 {
                let [a, b, c] = self.corners[i].map(|v| v.as_dvec3());
                let w = closest_on_triangle(p.as_dvec3(), a, b, c);
                let qi = (a * w[0] + b * w[1] + c * w[2]).as_vec3();
                let di = (p - qi).length_squared();
                if di < d2 {
                    (q, d2) = (qi, di);
                }
            }
        }
        let dist = d2.sqrt();
        let normal = if dist > 0.0 { (p - q) / dist } else { normal };
        Some(HullFoot {
            point: q,
            normal,
            signed: dist,
        })
    }

    /// The distance between the hull and a triangle `t` (a segment when two corners are
    /// one) apart from it, where one of the hull's planes settles it: a plane whose nearest
    /// corner of `t` is `g > 0` out separates them, so they are at least `g` apart; when that
    /// corner's foot on the plane lies in the plane's triangle, they are exactly `g` apart,
    /// nearest at that corner. The plane is found by a walk that raises `g` over the
    /// triangles' neighbours ([`HullPlanes::climb`]), from the triangle whose normal is
    /// nearest the direction of `t`'s first corner. Returns `Ok(None)` when the walk reaches
    /// a plane `reach` or more out, `Ok(Some((corner, normal, g)))` when its last plane
    /// settles the distance (the outward normal, towards the triangle), `Err(k)` otherwise:
    /// overlapping, nearest elsewhere (an edge against an edge, a hull's corner on the
    /// triangle), or a walk ended short of the farthest plane; the caller then takes the
    /// exact pairs with [`HullPlanes::near_triangles`], from the walk's last triangle `k`.
    /// A scan of every plane after such a walk would settle almost none of them: over a 64²
    /// cloth draping on a 642-vertex hull, 22 of 1.38 million in short steps and 147 of
    /// 277,000 in frame-long ones, and no walk ended short of a plane out of reach.
    pub(super) fn triangle(
        &self,
        t: [glam::Vec3; 3],
        reach: f32,
    ) -> Result<Option<(usize, glam::Vec3, f32)>, usize> {
        let [a, b, c] = t;
        let least = |k: usize| {
            let (sa, sb, sc) = (self.signed(k, a), self.signed(k, b), self.signed(k, c));
            sa.min(sb).min(sc)
        };
        let (g, k) = self.climb(least, self.start_for(a - self.centre));
        if g >= reach {
            Ok(None)
        } else if g > 0.0 {
            self.settle(t, k, g).map(Some).ok_or(k)
        } else {
            Err(k)
        }
    }

    /// The hull's triangles that can hold the point nearest to triangle `t` (in the hull's
    /// frame) when that is within `reach`: those whose boxes come within `reach` of `t`'s
    /// (from the mesh's hierarchy), less those that `t` lies wholly behind. Why that is
    /// enough: the nearest pair, `p` on `t` and `q` on the hull, lies along a unit direction
    /// `n` in the normal cone at `q`, `n = Σ λ_f n_f` over the triangles at `q` with
    /// `λ_f ≥ 0`. As `n · n = 1`, some triangle `f` at `q` has `n_f · n > 0`, and `p` is in
    /// front of `f`'s plane by `|p − q| n_f · n > 0`, so `t` is not wholly behind it; and
    /// `q` is within `reach` of `t`. A triangle that crosses `t` has corners of `t` on both
    /// sides of its plane, so is among them too. Behind is widened by the planes' round-off.
    ///
    /// Triangle `first` comes first (the walk's last: often the nearest, so that the pairs
    /// after it are bounded by its distance), then the others.
    pub(super) fn near_triangles(
        &self,
        t: [glam::Vec3; 3],
        reach: f32,
        first: usize,
    ) -> impl Iterator<Item = [glam::Vec3; 3]> + '_ {
        let grow = glam::Vec3::splat(reach);
        let lo = t[0].min(t[1]).min(t[2]) - grow;
        let hi = t[0].max(t[1]).max(t[2]) + grow;
        let size = lo.abs().max(hi.abs()).max_element();
        let near = parry3d::bounding_volume::Aabb::new(lo, hi);
        let boxed = self.mesh.iter().flat_map(move |mesh| {
            use parry3d::bounding_volume::BoundingVolume;
            mesh.bvh().leaves(move |node| node.aabb().intersects(&near))
        });
        let first = first.min(self.corners.len() - 1);
        std::iter::once(first)
            .chain(boxed.map(|id| id as usize).filter(move |k| *k != first))
            .filter_map(move |k| {
                let slack = 4.0 * f32::EPSILON * (3.0 * size + self.w[k].abs());
                let front = t.iter().any(|p| self.signed(k, *p) > -slack);
                front.then_some(self.corners[k])
            })
    }

    /// Whether `p` (in the hull's frame) is inside every plane: in the hull or on it.
    pub(super) fn contains(&self, p: glam::Vec3) -> bool {
        self.farthest(|x, y, z, w| x * p.x + y * p.y + z * p.z - w)
            .0
            <= 0.0
    }

    /// Triangle `t`'s distance `g > 0` from plane `k` (its nearest corner's) settled as its
    /// distance from the hull, when that corner's foot lies in the plane's triangle: the
    /// corner, the normal and `g`.
    #[inline]
    fn settle(&self, t: [glam::Vec3; 3], k: usize, g: f32) -> Option<(usize, glam::Vec3, f32)> {
        let corner = t.iter().position(|p| self.signed(k, *p) == g).unwrap_or(0);
        let normal = self.normal(k);
        self.holds(k, t[corner] - normal * g)
            .then_some((corner, normal, g))
    }

    /// Per cube-map cell, the one of `count` items whose vector `along(i)` reaches farthest
    /// along the cell's middle (a triangle's normal, a vertex's position).
    fn cube_map(count: usize, along: impl Fn(usize) -> glam::Vec3) -> Vec<u32> {
        (0..6 * CELLS * CELLS)
            .map(|cell| {
                let d = Self::cell_direction(cell);
                (0..count)
                    .max_by(|&i, &j| along(i).dot(d).total_cmp(&along(j).dot(d)))
                    .unwrap_or(0) as u32
            })
            .collect()
    }

    /// The middle of cube-map cell `cell`, as a unit direction: face `cell / CELLS²` (the
    /// axis `face / 2`, positive for even faces), then its row and column.
    fn cell_direction(cell: usize) -> glam::Vec3 {
        let (face, rest) = (cell / (CELLS * CELLS), cell % (CELLS * CELLS));
        let at = |i: usize| (i as f32 + 0.5) / CELLS as f32 * 2.0 - 1.0;
        let (axis, sign) = (face / 2, if face % 2 == 0 { 1.0 } else { -1.0 });
        let mut d = [0.0f32; 3];
        d[axis] = sign;
        d[(axis + 1) % 3] = at(rest / CELLS);
        d[(axis + 2) % 3] = at(rest % CELLS);
        glam::Vec3::from_array(d).normalize()
    }

    /// The triangle a walk for a point in direction `d` from the centre starts at: the
    /// start of `d`'s cell of the cube map.
    fn start_for(&self, d: glam::Vec3) -> usize {
        self.start[Self::cell(d)] as usize
    }

    /// The hull's farthest point along `dir` (its support point): a walk along the edges
    /// from the vertex farthest along the middle of `dir`'s cell, each step to the
    /// neighbour farthest along `dir` if it is farther than the vertex itself. On a convex
    /// polyhedron a vertex no neighbour of which is farther is the farthest of all (the
    /// hill climbing of Cameron's enhanced GJK, *A comparison of two fast algorithms for
    /// computing the distance between convex polyhedra*, 1997), so this is the scan of
    /// every vertex parry's `ConvexPolyhedron` makes, in a few steps.
    pub(super) fn support(&self, dir: glam::Vec3) -> glam::Vec3 {
        let mut v = self.vertex_start[Self::cell(dir)] as usize;
        let mut best = self.vertices[v].dot(dir);
        loop {
            let mut next = v;
            let (from, to) = (self.ring_at[v] as usize, self.ring_at[v + 1] as usize);
            for &u in &self.ring[from..to] {
                let s = self.vertices[u as usize].dot(dir);
                if s > best {
                    (best, next) = (s, u as usize);
                }
            }
            if next == v {
                return self.vertices[v];
            }
            v = next;
        }
    }

    /// The cube-map cell of direction `d` (see [`HullPlanes::cell_direction`]; a direction
    /// that is not finite takes cell 0).
    fn cell(d: glam::Vec3) -> usize {
        let a = d.abs();
        let axis = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let face = 2 * axis + usize::from(d[axis] < 0.0);
        let index = |c: f32| {
            let u = (c / a[axis] + 1.0) * 0.5 * CELLS as f32;
            (u.max(0.0) as usize).min(CELLS - 1)
        };
        face * CELLS * CELLS + index(d[(axis + 1) % 3]) * CELLS + index(d[(axis + 2) % 3])
    }

    /// A walk over the triangles' neighbours from `from`, each step to the neighbour with
    /// the largest `f` if it is larger than the triangle's own, until none is: a local
    /// maximum of `f` and its triangle. `f` increases strictly along the walk, so it ends.
    /// Where its plane does not settle a query, a point's scans every plane and a
    /// triangle's takes the exact pairs with [`HullPlanes::near_triangles`].
    #[inline]
    fn climb(&self, f: impl Fn(usize) -> f32, from: usize) -> (f32, usize) {
        let (mut k, mut best) = (from, f(from));
        loop {
            let mut next = k;
            for &j in &self.adjacent[k] {
                if j != NONE {
                    let s = f(j as usize);
                    if s > best {
                        (best, next) = (s, j as usize);
                    }
                }
            }
            if next == k {
                return (best, k);
            }
            k = next;
        }
    }

    /// Triangle `k`'s outward unit normal.
    #[inline(always)]
    fn normal(&self, k: usize) -> glam::Vec3 {
        glam::Vec3::new(self.nx[k], self.ny[k], self.nz[k])
    }

    /// Whether `point`, on triangle `k`'s plane, lies in the triangle (on the inner side of
    /// each of its edges).
    #[inline(always)]
    fn holds(&self, k: usize, point: glam::Vec3) -> bool {
        let ([a, b, c], normal) = (self.corners[k], self.normal(k));
        let left_of = |u: glam::Vec3, v: glam::Vec3| (v - u).cross(point - u).dot(normal) >= 0.0;
        left_of(a, b) && left_of(b, c) && left_of(c, a)
    }

    /// The largest of `f(nx, ny, nz, w)` over the planes and the first plane giving it, in
    /// lanes (the padding planes give `−∞`; a point that is not finite gives plane 0).
    #[inline(always)]
    fn farthest(&self, f: impl Fn(f32, f32, f32, f32) -> f32) -> (f32, usize) {
        let mut acc = [f32::NEG_INFINITY; LANES];
        let mut at = [0u32; LANES];
        let (nx, ny, nz, w) = (
            self.nx.as_chunks::<LANES>().0,
            self.ny.as_chunks::<LANES>().0,
            self.nz.as_chunks::<LANES>().0,
            self.w.as_chunks::<LANES>().0,
        );
        for (chunk, (((x, y), z), w)) in nx.iter().zip(ny).zip(nz).zip(w).enumerate() {
            for l in 0..LANES {
                let s = f(x[l], y[l], z[l], w[l]);
                let more = s > acc[l];
                acc[l] = if more { s } else { acc[l] };
                at[l] = if more { chunk as u32 } else { at[l] };
            }
        }
        let (mut best, mut k) = (f32::NEG_INFINITY, 0);
        for l in 0..LANES {
            let i = at[l] as usize * LANES + l;
            if acc[l] > best || (acc[l] == best && i < k) {
                (best, k) = (acc[l], i);
            }
        }
        (best, if k < self.corners.len() { k } else { 0 })
    }

    /// `p`'s signed distance to triangle `i`'s plane.
    #[inline(always)]
    fn signed(&self, i: usize, p: glam::Vec3) -> f32 {
        self.nx[i] * p.x + self.ny[i] * p.y + self.nz[i] * p.z - self.w[i]
    }
}

impl parry3d::shape::SupportMap for HullPlanes {
    #[inline]
    fn local_support_point(&self, dir: glam::Vec3) -> glam::Vec3 {
        self.support(dir)
    }
}
