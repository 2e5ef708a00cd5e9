//! The broad phase of contact: a bounding-volume hierarchy over the surface's triangles,
//! refitted to every pass's swept boxes, with normal-cone culling of flat patches.
//!
//! The tree is built once per surface, top-down by median splits of the triangles' centroids
//! at the first pass (after splitting apart its connected pieces, so that two bodies or two
//! cloths of one body never share a node below the nodes that separate them); after that only
//! its boxes and cones are refitted (van den Bergen, *Efficient collision detection of complex
//! deformable models using AABB trees*, 1997), so its nodes stay compact pieces of the
//! surface as it deforms.
//!
//! **Normal cones.** A connected patch of surface whose normals all lie in one open hemisphere
//! cannot touch itself (Volino and Magnenat-Thalmann, *Efficient self-collision detection on
//! smoothly discretized surface animations using geometrical shape regularity*, 1994;
//! Provot, *Collision and self-collision handling in cloth model dedicated to design
//! garments*, 1997), so the self-test of such a node stops there: a flat sheet costs one test
//! at the root, a draped or folded one the seams between its flat nodes (walked down to their
//! leaves: two flat nodes side by side are not culled against each other — that culling, tried,
//! let an intersection through) and its folds. The hemisphere must
//! hold for the whole motion of the pass: along straight paths a triangle's normal is
//! `n(τ) = (1−τ)² B₀ + 2τ(1−τ) B₁ + τ² B₂` with `B₀`, `B₂` the normals at the start and end
//! and `B₁ = ½ (e₀ × f₁ + e₁ × f₀)` (its edges `e`, `f` at the start and end), a combination
//! with non-negative weights, so a direction `d` with `Bₖ · d > 0` for the three control
//! vectors has `n(τ) · d > 0` all along (the Bernstein bound of Tang, Curtis, Yoon and
//! Manocha, *Interactive continuous collision detection between deformable models using
//! connectivity-based culling*, 2009). Rather than fitting a cone (which takes inverse
//! cosines), each triangle records, as bits, which of 26 fixed directions (the faces, edges
//! and corners of a cube) every control vector is strictly on the positive side of; a node's
//! bits are the intersection of its triangles', and a non-empty set is a common hemisphere. It
//! recognises every cone of half-angle up to 62° (no direction lies farther than 28° from the
//! nearest of the 26) and some up to 90°: conservative.
//!
//! Volino and Magnenat-Thalmann's criterion also asks that the patch's contour, projected
//! along that direction, not cross itself. That test is not made: a node is a compact piece of
//! the surface as it was when the tree was built (a median split), and for its projected
//! contour to cross itself while every normal stays in one hemisphere it would have to curl
//! around in its own plane, which takes in-plane stretch or compression far beyond what cloth
//! or a solid's skin undergoes. Patches that are not connected across edges (a median split
//! can cut a U in two arms) are never culled, and neither are patches that reach a cut made by
//! tearing: a slit slides over itself, and the material around a cut's end swings shut, with
//! every normal in one hemisphere and no stretch at all.
//!
//! **Creases.** Touching is not the only thing contact needs to see: pairs within the
//! thickness are repelled, and a patch in one hemisphere can come within the thickness of
//! itself at a crease. A hinge (two triangles sharing an edge) folded nearly flat keeps every
//! vertex far from the triangles but brings the two edges across the fold — which share no
//! vertex — together; on the draping cloth (thickness 8 mm) they were found 1.6 mm (f32) and
//! 0.8 mm (f64) apart at frames' ends with the patch culled. So the two triangles of a hinge
//! whose normals are more than 90° apart at the start or the end of the pass lose their cone
//! bits, and no node holding them is culled. Folded at most 90°, a hinge of two right
//! triangles keeps those edges 0.58 of an edge apart, more than the thickest surface allowed
//! (half an edge). On the 64² draping cloth the rule costs 17 % of a step with
//! self-collision, mostly the walks of the creased nodes (see the benchmarks).
//!
//! **Pairs.** Each vertex and each edge is owned by one triangle (the first that holds it);
//! a pair of triangles with overlapping boxes yields the point–triangle pairs of the vertices
//! each owns against the other and the edge–edge pairs of the edges they own, so every
//! feature pair comes from exactly one triangle pair and is found once.

use super::ContactSurface;
use crate::core::kernels::{SharedMut, for_each_range};
use glam::{DVec3, Mat4, Vec3A, Vec4};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// A box (low and high corners).
pub(super) type Aabb = (DVec3, DVec3);

/// Most triangles in a leaf.
const LEAF: usize = 4;

/// How far (as a factor) a triangle's edges may stretch or shrink from their lengths when the
/// tree was built and its patch still be culled as flat.
pub const DISTORTION: f32 = 1.5;

/// Bounds on a triangle's squared edge lengths (low, high).
type Span = (Vec3A, Vec3A);

/// Nothing (an unused slot of a triangle's owned features).
const NONE: u32 = u32::MAX;

/// The 13 directions whose two signs give the 26 of the cone test (as integer components:
/// the dot product is a signed sum of the vector's components).
#[cfg(test)]
const DIRECTIONS: [[i8; 3]; 13] = [
    [1, 0, 0],
    [0, 1, 0],
    [0, 0, 1],
    [1, 1, 0],
    [1, -1, 0],
    [1, 0, 1],
    [1, 0, -1],
    [0, 1, 1],
    [0, 1, -1],
    [1, 1, 1],
    [1, 1, -1],
    [1, -1, 1],
    [1, -1, -1],
];

/// The dot products of `b` with the 13 `DIRECTIONS`, in order, in four lanes of four (the
/// last three lanes repeat the thirteenth).
#[inline]
fn direction_dots(b: Vec3A) -> [Vec4; 4] {
    let (x, y, z) = (b.x, b.y, b.z);
    let xyz = x - y - z;
    [
        Vec4::new(x, y, z, x + y),
        Vec4::new(x - y, x + z, x - z, y + z),
        Vec4::new(y - z, x + y + z, x + y - z, x - y + z),
        Vec4::splat(xyz),
    ]
}

/// The directions all of whose hemispheres hold a triangle's normal along straight paths
/// from `p0` to `p1` (`f32` positions whose components are at most `qmax`): those of the
/// three Bernstein control vectors, as bits (bit `k`: `DIRECTIONS[k]`, bit `13 + k`: its
/// opposite) set when every control vector is on the positive side by more than the
/// round-off of computing it. The bound: the positions carry a relative error of 2⁻²⁴ (from
/// `f64`), an edge `e` then one of 2⁻²⁴(2 `qmax` + |e|) per component, a component of a
/// cross product `e × f` one of about 2⁻²³(2 `qmax` (|e| + |f|) + 4 |e| |f|) with its own
/// rounding, and a dot product with a direction sums three; `tol` is four times that.
///
/// A triangle whose edges are not within `span` (squared lengths) at both ends has no bits:
/// patches are culled only while no edge has stretched or shrunk past [`DISTORTION`].
#[inline]
pub(super) fn triangle_bits(p0: [Vec3A; 3], p1: [Vec3A; 3], qmax: f32, span: Span) -> u32 {
    let (e0, f0) = (p0[1] - p0[0], p0[2] - p0[0]);
    let (e1, f1) = (p1[1] - p1[0], p1[2] - p1[0]);
    // Squared edge lengths at both ends of the path (the longest along it is at one end).
    let len2 = |e: Vec3A, f: Vec3A| {
        Vec3A::new(
            e.length_squared(),
            f.length_squared(),
            (f - e).length_squared(),
        )
    };
    let (l0, l1) = (len2(e0, f0), len2(e1, f1));
    if !(l0.cmpge(span.0) & l0.cmple(span.1) & l1.cmpge(span.0) & l1.cmple(span.1)).all() {
        return 0;
    }
    // e₀ × f₁ + e₁ × f₀ = e₀ × f₀ + e₁ × f₁ − (e₁ − e₀) × (f₁ − f₀).
    let (n0, n1) = (e0.cross(f0), e1.cross(f1));
    let b0 = direction_dots(n0);
    let b1 = direction_dots(0.5 * (n0 + n1 - (e1 - e0).cross(f1 - f0)));
    let b2 = direction_dots(n1);
    let e = e0.abs().max(e1.abs()).max_element();
    let f = f0.abs().max(f1.abs()).max_element();
    let tol = Vec4::splat(12.0 * f32::EPSILON * (2.0 * qmax * (e + f) + 4.0 * e * f));
    let mut bits = 0;
    for k in 0..4 {
        let lo = b0[k].min(b1[k]).min(b2[k]);
        let hi = b0[k].max(b1[k]).max(b2[k]);
        // The last group holds one direction (its lanes repeat it).
        let keep = if k == 3 { 1 } else { 0xf };
        bits |= (lo.cmpgt(tol).bitmask() & keep) << (4 * k);
        bits |= (hi.cmplt(-tol).bitmask() & keep) << (13 + 4 * k);
    }
    bits
}

/// Four `f32` lanes: one per triangle of a batch (glam's SIMD vector).
type Lanes = Vec4;

/// Three components, each four lanes.
type Lanes3 = [Lanes; 3];

#[inline(always)]
fn sub3(a: Lanes3, b: Lanes3) -> Lanes3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
fn cross3(a: Lanes3, b: Lanes3) -> Lanes3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline(always)]
fn len2(a: Lanes3) -> Lanes {
    a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
}

/// The dot products with the 13 `DIRECTIONS`, in order.
#[inline(always)]
fn dots13(b: Lanes3) -> [Lanes; 13] {
    let [x, y, z] = b;
    let (xy, x_y) = (x + y, x - y);
    [
        x,
        y,
        z,
        xy,
        x_y,
        x + z,
        x - z,
        y + z,
        y - z,
        xy + z,
        xy - z,
        x_y + z,
        x_y - z,
    ]
}

/// [`triangle_bits`] for four triangles at once, from their edges `e` (`[e₀, f₀, e₁, f₁]`:
/// the edges from the first vertex at the start and the end, component-wise in lanes) and
/// spans. Computes the same thing with the same operations in the same order, so the same
/// bits (checked in the tests). Also gives the (unnormalized) normals at the start and the
/// end, `e₀ × f₀` and `e₁ × f₁`, for the crease rule.
#[inline(always)]
fn triangle_bits4(
    e: [Lanes3; 4],
    span_lo: Lanes3,
    span_hi: Lanes3,
    qmax: f32,
) -> ([u32; 4], [Lanes3; 2]) {
    let [e0, f0, e1, f1] = e;
    let n0 = cross3(e0, f0);
    let n1 = cross3(e1, f1);
    let dd = cross3(sub3(e1, e0), sub3(f1, f0));
    let half = Vec4::splat(0.5);
    let b1 = [
        half * (n0[0] + n1[0] - dd[0]),
        half * (n0[1] + n1[1] - dd[1]),
        half * (n0[2] + n1[2] - dd[2]),
    ];
    let l0 = [len2(e0), len2(f0), len2(sub3(f0, e0))];
    let l1 = [len2(e1), len2(f1), len2(sub3(f1, e1))];
    let amax = |a: Lanes3, b: Lanes3| {
        a[0].abs()
            .max(b[0].abs())
            .max(a[1].abs().max(b[1].abs()))
            .max(a[2].abs().max(b[2].abs()))
    };
    let (emax, fmax) = (amax(e0, e1), amax(f0, f1));
    let eps = Vec4::splat(12.0 * f32::EPSILON);
    let tol = eps * (Vec4::splat(2.0 * qmax) * (emax + fmax) + Vec4::splat(4.0) * emax * fmax);
    let (d0, d1, d2) = (dots13(n0), dots13(b1), dots13(n1));
    // Each lane's bits summed as powers of two in `f32` (exact: at most 2¹³ − 1).
    let (mut pos, mut neg) = (Vec4::ZERO, Vec4::ZERO);
    for k in 0..13 {
        let lo = d0[k].min(d1[k]).min(d2[k]);
        let hi = d0[k].max(d1[k]).max(d2[k]);
        let bit = Vec4::splat((1u32 << k) as f32);
        pos += Vec4::select(lo.cmpgt(tol), bit, Vec4::ZERO);
        neg += Vec4::select(hi.cmplt(-tol), bit, Vec4::ZERO);
    }
    let mut within = Vec4::ONE;
    for k in 0..3 {
        let ok = l0[k].cmpge(span_lo[k])
            & l0[k].cmple(span_hi[k])
            & l1[k].cmpge(span_lo[k])
            & l1[k].cmple(span_hi[k]);
        within = Vec4::select(ok, within, Vec4::ZERO);
    }
    let (pos, neg) = ((pos * within).to_array(), (neg * within).to_array());
    let bits = |l: usize| pos[l] as u32 | (neg[l] as u32) << 13;
    ([bits(0), bits(1), bits(2), bits(3)], [n0, n1])
}

/// The spans of each batch of four triangles, lane per triangle (low x, y, z, high x, y, z).
fn span_lanes(span: &[Span]) -> impl Iterator<Item = [Vec4; 6]> + '_ {
    span.chunks_exact(4).map(|c| {
        let lane = |f: fn(&Span) -> f32| Vec4::new(f(&c[0]), f(&c[1]), f(&c[2]), f(&c[3]));
        [
            lane(|s| s.0.x),
            lane(|s| s.0.y),
            lane(|s| s.0.z),
            lane(|s| s.1.x),
            lane(|s| s.1.y),
            lane(|s| s.1.z),
        ]
    })
}

/// Triangles a chunk of [`all_bits`] holds on the team (a multiple of four: the batches'
/// lanes; about ten microseconds of work). Smaller under Miri.
const BITS_CHUNK: usize = crate::core::kernels::chunk_limit(1024, 64);

/// The cone bits of every triangle (`out[t]`) along the paths from `q0` to `q1`, and its
/// normals at the start and the end (`normals[t]`, as [`SurfaceTree::normals_of`] computes
/// them): four at a time, in chunks of [`BITS_CHUNK`] triangles on the team (each
/// triangle's bits are its own, so the same bits on any number of threads).
#[allow(clippy::too_many_arguments)]
fn all_bits(
    triangles: &[[u32; 3]],
    q0: &[Vec3A],
    q1: &[Vec3A],
    qmax: f32,
    span: &[Span],
    span4: &[[Vec4; 6]],
    out: &mut [u32],
    normals: &mut [[Vec3A; 2]],
) {
    let (out, normals) = (SharedMut(out.as_mut_ptr()), SharedMut(normals.as_mut_ptr()));
    for_each_range(triangles.len(), BITS_CHUNK, |r| {
        // The chunk's own (`span4` holds batches of four, and a chunk starts on one).
        let (triangles, span, span4) = (
            &triangles[r.clone()],
            &span[r.clone()],
            &span4[r.start / 4..r.end / 4],
        );
        // SAFETY: each range is its own chunk's.
        let (out, normals) = unsafe { (out.slice(r.clone()), normals.slice(r)) };
        let batches = triangles.len() / 4;
        for c in 0..batches {
            let ts = &triangles[4 * c..4 * c + 4];
            // Each lane's four edges, transposed into components (a 4 × 4 transpose).
            let edges = ts.iter().map(|t| {
                let [a, b, cc] = t.map(|i| i as usize);
                [q0[b] - q0[a], q0[cc] - q0[a], q1[b] - q1[a], q1[cc] - q1[a]]
            });
            let mut cols = [[Vec4::ZERO; 4]; 4];
            for (l, e) in edges.enumerate() {
                for k in 0..4 {
                    cols[k][l] = e[k].extend(0.0);
                }
            }
            let lanes = |c: &[Vec4; 4]| {
                let m = Mat4::from_cols(c[0], c[1], c[2], c[3]).transpose();
                [m.x_axis, m.y_axis, m.z_axis]
            };
            let e = [
                lanes(&cols[0]),
                lanes(&cols[1]),
                lanes(&cols[2]),
                lanes(&cols[3]),
            ];
            let [lo_x, lo_y, lo_z, hi_x, hi_y, hi_z] = span4[c];
            let (bits, [n0, n1]) = triangle_bits4(e, [lo_x, lo_y, lo_z], [hi_x, hi_y, hi_z], qmax);
            out[4 * c..4 * c + 4].copy_from_slice(&bits);
            // The normals back from lanes to one vector per triangle.
            let per_lane = |n: Lanes3| Mat4::from_cols(n[0], n[1], n[2], Vec4::ZERO).transpose();
            let (m0, m1) = (per_lane(n0), per_lane(n1));
            for l in 0..4 {
                normals[4 * c + l] = [Vec3A::from_vec4(m0.col(l)), Vec3A::from_vec4(m1.col(l))];
            }
        }
        for t in 4 * batches..triangles.len() {
            let [a, b, c] = triangles[t].map(|i| i as usize);
            out[t] = triangle_bits([q0[a], q0[b], q0[c]], [q1[a], q1[b], q1[c]], qmax, span[t]);
            let n = |q: &[Vec3A]| (q[b] - q[a]).cross(q[c] - q[a]);
            normals[t] = [n(q0), n(q1)];
        }
    });
}

/// What a search finds: a vertex and a triangle, or two edges (by index).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Found {
    PointTriangle(u32, u32),
    EdgeEdge(u32, u32),
}

/// A box in `f32`.
type Box32 = (Vec3A, Vec3A);

#[cfg(test)]
fn overlap(a: &Aabb, b: &Aabb) -> bool {
    a.0.cmple(b.1).all() && b.0.cmple(a.1).all()
}

fn overlap32(a: &Box32, b: &Box32) -> bool {
    a.0.cmple(b.1).all() && b.0.cmple(a.1).all()
}

fn union(a: Aabb, b: Aabb) -> Aabb {
    (a.0.min(b.0), a.1.max(b.1))
}

fn union32(a: Box32, b: Box32) -> Box32 {
    (a.0.min(b.0), a.1.max(b.1))
}

/// A box's growth by `margin` plus the rounding of the positions (components up to `qmax`) to
/// `f32` (half an ulp of the largest, twice over) and of the margin itself.
fn rounded_margin(margin: f64, qmax: f32) -> Vec3A {
    Vec3A::splat((margin as f32) * (1.0 + f32::EPSILON) + qmax * f32::EPSILON)
}

/// A node: triangles `order[start..end]`; children at `child` and `child + 1` (0: a leaf).
#[derive(Clone, Copy, Debug, Default)]
struct Node {
    start: u32,
    end: u32,
    child: u32,
    /// The node's triangles form one piece across shared edges, with no cut inside it (only
    /// those are culled).
    connected: bool,
}

/// A pair of nodes the walk has yet to take up, and whether a node paired with itself is to be
/// walked even if flat (a culled node found no longer flat, when a search resumes).
pub(super) type Visit = (u32, u32, bool);

/// The most triangles in either node of a pair that [`SurfaceTree::plan`] hands on as a piece
/// of the walk: tens of pieces on a 64² cloth's 7,938 triangles (more where it folds), each
/// microseconds of work, so that two threads taking them as they come end within a piece of
/// each other.
const PIECE_TRIANGLES: u32 = 64;

/// The hierarchy and what its last search found.
#[derive(Clone, Debug, Default)]
pub(super) struct SurfaceTree {
    nodes: Vec<Node>,
    /// Triangles in leaf order.
    order: Vec<u32>,
    /// Per triangle: the vertices it owns (`NONE` pads).
    owned_vertices: Vec<[u32; 3]>,
    /// Per triangle: the edges (indices into the surface's edge list) it owns.
    owned_edges: Vec<[u32; 3]>,
    /// The triangle count it was built for.
    built_for: usize,
    /// Pairs of triangles that share an edge (hinges), for the crease rule.
    hinges: Vec<[u32; 2]>,
    /// Per vertex (compressed rows): the hinges whose triangles it is a corner of.
    vertex_hinge_start: Vec<u32>,
    vertex_hinges: Vec<u32>,
    /// Per triangle: its normals at the start and end of the paths (crease rule).
    tnormal: Vec<[Vec3A; 2]>,
    /// Per triangle: the squared edge lengths it may have and still be culled.
    span: Vec<Span>,
    /// The same for each batch of four triangles, lane per triangle (low x, y, z, high x,
    /// y, z).
    span4: Vec<[Vec4; 6]>,
    /// Per vertex (compressed rows): the triangles around it.
    vertex_start: Vec<u32>,
    vertex_tris: Vec<u32>,
    /// Per triangle: swept box (relative to `origin`, in `f32`, rounded outwards) and cone
    /// bits of the last refit.
    tbox: Vec<Box32>,
    tbits: Vec<u32>,
    /// Per vertex and per edge: the swept box of the last refit, as the triangles' (a
    /// triangle's box is the union of its vertices').
    vbox: Vec<Box32>,
    ebox: Vec<Box32>,
    /// Per node: box and cone bits of the last refit.
    nbox: Vec<Box32>,
    nbits: Vec<u32>,
    /// The surface's vertices at the start and end of the pass relative to `origin`, in `f32`
    /// ([`SurfaceTree::load`]), and the largest component among them.
    q0: Vec<Vec3A>,
    q1: Vec<Vec3A>,
    /// Where each vertex may be headed after the pass ([`SurfaceTree::stretch`]; empty: the
    /// ends of the paths).
    q2: Vec<Vec3A>,
    qmax: f32,
    origin: DVec3,
    /// Nodes the last search did not test against themselves as flat: their triangles'
    /// common bits must stay non-empty for its pairs to stay complete.
    culled: Vec<u32>,
    /// Culled nodes found no longer flat, not yet walked.
    failed: Vec<u32>,
    /// Per triangle: the culled node it lies in (`NONE`: none).
    culled_of: Vec<u32>,
    /// Per vertex and per edge: the triangle that owns it (`NONE`: none).
    vertex_owner: Vec<u32>,
    edge_owner: Vec<u32>,
    /// Where the last refit's boxes are measured from, and the largest component of the
    /// positions they hold.
    box_origin: DVec3,
    box_qmax: f32,
    /// Scratch of [`SurfaceTree::search_around`]: the features it has queried.
    seen_tri: Vec<bool>,
    seen_edge: Vec<bool>,
    around_stack: Vec<u32>,
    around_tris: Vec<u32>,
    around_edges: Vec<u32>,
    stack: Vec<Visit>,
    /// Scratch of [`SurfaceTree::search`]: its pieces, and the nodes a piece culled.
    pieces: Vec<Visit>,
    piece_culled: Vec<u32>,
    /// Triangle pairs the last search compared.
    pub triangle_pairs: u64,
}

impl SurfaceTree {
    /// Whether the tree was built for a surface of `triangles` triangles.
    pub fn built_for(&self, triangles: usize) -> bool {
        self.built_for == triangles && !self.nodes.is_empty()
    }

    /// Builds the hierarchy over the surface's triangles at positions `x`.
    pub fn build(&mut self, surf: &ContactSurface, x: &[DVec3]) {
        let (triangles, edges) = (&surf.triangles[..], &surf.edges[..]);
        let nt = triangles.len();
        self.built_for = nt;
        self.nodes.clear();
        self.order.clear();
        self.culled.clear();
        if nt == 0 {
            return;
        }
        let edge_of = |a: u32, b: u32| -> u32 {
            let key = [a.min(b), a.max(b)];
            edges.binary_search(&key).map_or(NONE, |k| k as u32)
        };
        let tri_edges: Vec<[u32; 3]> = triangles
            .iter()
            .map(|t| {
                [
                    edge_of(t[0], t[1]),
                    edge_of(t[1], t[2]),
                    edge_of(t[2], t[0]),
                ]
            })
            .collect();

        let at = |i: u32| {
            let p = x.get(i as usize).copied().unwrap_or(DVec3::ZERO);
            if p.is_finite() { p } else { DVec3::ZERO }
        };
        let d2 = DISTORTION * DISTORTION;
        self.span.clear();
        self.span.extend(triangles.iter().map(|t| {
            let [a, b, c] = t.map(at);
            let l = Vec3A::new(
                (b - a).length_squared() as f32,
                (c - a).length_squared() as f32,
                (c - b).length_squared() as f32,
            );
            (l / d2, l * d2)
        }));
        self.span4.clear();
        self.span4.extend(span_lanes(&self.span));

        // Ownership: the first triangle holding a vertex or an edge owns it.
        let nv = x.len();
        let mut vertex_taken = vec![false; nv];
        let mut edge_taken = vec![false; edges.len()];
        self.owned_vertices.clear();
        self.owned_edges.clear();
        self.vertex_owner.clear();
        self.vertex_owner.resize(nv, NONE);
        self.edge_owner.clear();
        self.edge_owner.resize(edges.len(), NONE);
        for (ti, (t, te)) in triangles.iter().zip(&tri_edges).enumerate() {
            let mut ov = [NONE; 3];
            let mut oe = [NONE; 3];
            for k in 0..3 {
                let v = t[k] as usize;
                if v < nv && !vertex_taken[v] {
                    vertex_taken[v] = true;
                    ov[k] = t[k];
                    self.vertex_owner[v] = ti as u32;
                }
                let e = te[k];
                if e != NONE && !edge_taken[e as usize] {
                    edge_taken[e as usize] = true;
                    oe[k] = e;
                    self.edge_owner[e as usize] = ti as u32;
                }
            }
            self.owned_vertices.push(ov);
            self.owned_edges.push(oe);
        }

        // Hinges: the triangles on the two sides of each edge that has two.
        let mut first = vec![NONE; edges.len()];
        self.hinges.clear();
        for (t, te) in tri_edges.iter().enumerate() {
            for &e in te.iter().filter(|&&e| e != NONE) {
                match first[e as usize] {
                    NONE => first[e as usize] = t as u32,
                    u => self.hinges.push([u, t as u32]),
                }
            }
        }
        let corners = |h: &[u32; 2]| {
            let [a, b] = h.map(|t| triangles[t as usize]);
            let mut v: Vec<u32> = a
                .into_iter()
                .chain(b)
                .filter(|&v| (v as usize) < nv)
                .collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        self.vertex_hinge_start.clear();
        self.vertex_hinge_start.resize(nv + 1, 0);
        for h in &self.hinges {
            for v in corners(h) {
                self.vertex_hinge_start[v as usize + 1] += 1;
            }
        }
        for k in 0..nv {
            self.vertex_hinge_start[k + 1] += self.vertex_hinge_start[k];
        }
        let mut fill = self.vertex_hinge_start.clone();
        self.vertex_hinges.clear();
        self.vertex_hinges
            .resize(self.vertex_hinge_start[nv] as usize, 0);
        for (k, h) in self.hinges.iter().enumerate() {
            for v in corners(h) {
                self.vertex_hinges[fill[v as usize] as usize] = k as u32;
                fill[v as usize] += 1;
            }
        }

        // Triangles around each vertex.
        self.vertex_start.clear();
        self.vertex_start.resize(nv + 1, 0);
        for t in triangles {
            for &v in t.iter().filter(|&&v| (v as usize) < nv) {
                self.vertex_start[v as usize + 1] += 1;
            }
        }
        for k in 0..nv {
            self.vertex_start[k + 1] += self.vertex_start[k];
        }
        let mut fill = self.vertex_start.clone();
        self.vertex_tris.clear();
        self.vertex_tris.resize(self.vertex_start[nv] as usize, 0);
        for (k, t) in triangles.iter().enumerate() {
            for &v in t.iter().filter(|&&v| (v as usize) < nv) {
                self.vertex_tris[fill[v as usize] as usize] = k as u32;
                fill[v as usize] += 1;
            }
        }

        // Triangles around each edge (compressed rows), for connectivity.
        let mut edge_start = vec![0u32; edges.len() + 1];
        for te in &tri_edges {
            for &e in te.iter().filter(|&&e| e != NONE) {
                edge_start[e as usize + 1] += 1;
            }
        }
        for k in 0..edges.len() {
            edge_start[k + 1] += edge_start[k];
        }
        let mut fill = edge_start.clone();
        let mut edge_tris = vec![0u32; edge_start[edges.len()] as usize];
        for (t, te) in tri_edges.iter().enumerate() {
            for &e in te.iter().filter(|&&e| e != NONE) {
                edge_tris[fill[e as usize] as usize] = t as u32;
                fill[e as usize] += 1;
            }
        }

        // Clusters merged along shared edges, the pair whose joint box has the shortest
        // diagonal first (as in Garland, Willmott and Heckbert's *Hierarchical face
        // clustering on polygonal surfaces*, 2001, with compactness for the cost): every
        // cluster is one piece of surface, small and compact ones merge first.
        let tri_box: Vec<Aabb> = triangles
            .iter()
            .map(|t| {
                t.iter().fold((DVec3::MAX, DVec3::MIN), |(l, h), &i| {
                    let p = x.get(i as usize).copied().unwrap_or(DVec3::ZERO);
                    let p = if p.is_finite() { p } else { DVec3::ZERO };
                    (l.min(p), h.max(p))
                })
            })
            .collect();
        let mut cl: Vec<Cluster> = tri_box
            .iter()
            .map(|&b| Cluster {
                bx: b,
                size: 1,
                children: None,
                alive: true,
                neighbours: Vec::new(),
            })
            .collect();
        for k in 0..edges.len() {
            let ts = &edge_tris[edge_start[k] as usize..edge_start[k + 1] as usize];
            for &a in ts {
                for &b in ts {
                    if a != b && !cl[a as usize].neighbours.contains(&b) {
                        cl[a as usize].neighbours.push(b);
                    }
                }
            }
        }
        let cost = |a: &Cluster, b: &Cluster| {
            let u = union(a.bx, b.bx);
            (u.1 - u.0).length_squared().to_bits()
        };
        let mut heap = BinaryHeap::new();
        for a in 0..nt {
            for &b in &cl[a].neighbours {
                if (a as u32) < b {
                    heap.push(Reverse((cost(&cl[a], &cl[b as usize]), a as u32, b)));
                }
            }
        }
        while let Some(Reverse((_, a, b))) = heap.pop() {
            if !(cl[a as usize].alive && cl[b as usize].alive) {
                continue;
            }
            let c = cl.len() as u32;
            let mut neighbours: Vec<u32> = cl[a as usize]
                .neighbours
                .iter()
                .chain(&cl[b as usize].neighbours)
                .copied()
                .filter(|&n| n != a && n != b)
                .collect();
            neighbours.sort_unstable();
            neighbours.dedup();
            for &n in &neighbours {
                let ns = &mut cl[n as usize].neighbours;
                ns.retain(|&m| m != a && m != b);
                ns.push(c);
            }
            cl[a as usize].alive = false;
            cl[b as usize].alive = false;
            let merged = Cluster {
                bx: union(cl[a as usize].bx, cl[b as usize].bx),
                size: cl[a as usize].size + cl[b as usize].size,
                children: Some((a, b)),
                alive: true,
                neighbours: Vec::new(),
            };
            for &n in &neighbours {
                heap.push(Reverse((cost(&merged, &cl[n as usize]), c, n)));
            }
            cl[a as usize].neighbours = Vec::new();
            cl[b as usize].neighbours = Vec::new();
            cl.push(Cluster {
                neighbours,
                ..merged
            });
        }
        // What is left are the surface's pieces: joined top-down by median splits of their
        // boxes' centres.
        let mut roots: Vec<u32> = (0..cl.len() as u32)
            .filter(|&c| cl[c as usize].alive)
            .collect();
        let root = join(&mut cl, &mut roots);

        // Laid out top-down: each node's triangles contiguous in `order`, children in pairs
        // after their parent; clusters of at most `LEAF` triangles become leaves.
        self.nodes.push(Node::default());
        let mut todo = vec![(root, 0usize)];
        let mut below = Vec::new();
        while let Some((c, n)) = todo.pop() {
            let start = self.order.len() as u32;
            match cl[c as usize].children {
                Some((a, b)) if cl[c as usize].size as usize > LEAF => {
                    let child = self.nodes.len();
                    self.nodes.push(Node::default());
                    self.nodes.push(Node::default());
                    self.nodes[n].child = child as u32;
                    // The first child is laid out first: it is popped first.
                    todo.push((b, child + 1));
                    todo.push((a, child));
                    self.nodes[n].start = start;
                }
                _ => {
                    below.push(c);
                    while let Some(d) = below.pop() {
                        match cl[d as usize].children {
                            Some((a, b)) => {
                                below.push(b);
                                below.push(a);
                            }
                            None => self.order.push(d),
                        }
                    }
                    self.nodes[n].start = start;
                    self.nodes[n].end = self.order.len() as u32;
                }
            }
        }
        // Inner nodes end where their second child ends.
        for n in (0..self.nodes.len()).rev() {
            let child = self.nodes[n].child as usize;
            if child != 0 {
                self.nodes[n].start = self.nodes[child].start;
                self.nodes[n].end = self.nodes[child + 1].end;
            }
        }
        let mut parent: Vec<u32> = (0..nt as u32).collect();
        let mut stamp = vec![NONE; nt];
        // A torn surface: the particles on a cut (split, or split from).
        let on_cut = surf.on_cut();
        for n in 0..self.nodes.len() {
            let node = self.nodes[n];
            let range = &self.order[node.start as usize..node.end as usize];
            self.nodes[n].connected = connected(
                range,
                &tri_edges,
                &edge_start,
                &edge_tris,
                n as u32,
                &mut stamp,
                &mut parent,
            ) && !touches_cut(range, triangles, &on_cut);
        }

        self.tbox.resize(nt, (Vec3A::ZERO, Vec3A::ZERO));
        self.tbits.resize(nt, 0);
        self.culled_of.clear();
        self.culled_of.resize(nt, NONE);
        self.seen_tri.clear();
        self.seen_tri.resize(nt, false);
        self.seen_edge.clear();
        self.seen_edge.resize(edges.len(), false);
        self.vbox.resize(x.len(), (Vec3A::ZERO, Vec3A::ZERO));
        self.ebox.resize(edges.len(), (Vec3A::ZERO, Vec3A::ZERO));
        self.nbox
            .resize(self.nodes.len(), (Vec3A::ZERO, Vec3A::ZERO));
        self.nbits.resize(self.nodes.len(), 0);
        // Each search lists a node at most once in each, and walks at most a node pair per
        // node on its stack at a time: sized now, a later pass allocates nothing.
        let n = self.nodes.len();
        for v in [&mut self.culled, &mut self.failed] {
            v.reserve(n.saturating_sub(v.len()));
        }
        self.stack.reserve((2 * n).saturating_sub(self.stack.len()));
    }

    /// Takes the surface's vertices `verts` at the start `p0` and end `p1` of the pass, for
    /// [`SurfaceTree::refit`] and [`SurfaceTree::still_flat`]: in `f32` relative to their
    /// mean (the cone test and the boxes allow for the rounding).
    pub fn load(&mut self, verts: &[u32], p0: &[DVec3], p1: &[DVec3]) {
        let n = verts.len().max(1) as f64;
        let origin = verts.iter().map(|&i| p0[i as usize]).sum::<DVec3>() / n;
        self.q0.resize(p0.len(), Vec3A::ZERO);
        self.q1.resize(p0.len(), Vec3A::ZERO);
        let mut qmax = Vec3A::ZERO;
        for &i in verts {
            let i = i as usize;
            let (a, b) = ((p0[i] - origin).as_vec3a(), (p1[i] - origin).as_vec3a());
            self.q0[i] = a;
            self.q1[i] = b;
            qmax = qmax.max(a.abs()).max(b.abs());
        }
        self.qmax = qmax.max_element();
        self.origin = origin;
        self.q2.clear();
    }

    /// Stretches the vertices' boxes of the next refit to also hold `p2` (where each may be
    /// headed), leaving the paths (and so the cone bits) as loaded.
    pub fn stretch(&mut self, verts: &[u32], p2: &[DVec3]) {
        self.q2.clear();
        self.q2.extend_from_slice(&self.q1);
        let mut qmax = self.qmax;
        for &i in verts {
            let i = i as usize;
            let c = (p2[i] - self.origin).as_vec3a();
            self.q2[i] = c;
            qmax = qmax.max(c.abs().max_element());
        }
        self.qmax = qmax;
    }

    /// Takes new ends `p1` of the paths of `moved` vertices (the starts and the others as
    /// last loaded).
    pub fn load_some(&mut self, moved: &[u32], p1: &[DVec3]) {
        let mut qmax = self.qmax;
        for &i in moved {
            let i = i as usize;
            let b = (p1[i] - self.origin).as_vec3a();
            self.q1[i] = b;
            qmax = qmax.max(b.abs().max_element());
        }
        self.qmax = qmax;
    }

    /// Refits the boxes (the paths over the pass of the vertices, edges and triangles, as
    /// [`SurfaceTree::load`]ed, grown by `margin`) and the cone bits.
    pub fn refit(&mut self, triangles: &[[u32; 3]], edges: &[[u32; 2]], margin: f64) {
        let m = rounded_margin(margin, self.qmax);
        (self.box_origin, self.box_qmax) = (self.origin, self.qmax);
        self.vbox.resize(self.q0.len(), (Vec3A::ZERO, Vec3A::ZERO));
        for ((b, &s), &e) in self.vbox.iter_mut().zip(&self.q0).zip(&self.q1) {
            *b = (s.min(e) - m, s.max(e) + m);
        }
        for (b, &c) in self.vbox.iter_mut().zip(&self.q2) {
            *b = (b.0.min(c - m), b.1.max(c + m));
        }
        self.boxes_from_vertices(triangles, edges);
        let (q0, q1, qmax) = (&self.q0, &self.q1, self.qmax);
        self.tnormal.resize(triangles.len(), [Vec3A::ZERO; 2]);
        all_bits(
            triangles,
            q0,
            q1,
            qmax,
            &self.span,
            &self.span4,
            &mut self.tbits,
            &mut self.tnormal,
        );
        self.all_creases();
        self.refit_nodes(true);
    }

    /// Whether every node the last search culled is still flat along the paths as
    /// [`SurfaceTree::load`]ed: the cone bits of the triangles around the vertices `moved` (all, with
    /// `None`) are recomputed, the others' are those of the same paths.
    pub fn still_flat(&mut self, triangles: &[[u32; 3]], moved: Option<&[u32]>) -> bool {
        if self.culled.is_empty() {
            return true;
        }
        self.tnormal.resize(triangles.len(), [Vec3A::ZERO; 2]);
        let (q0, q1, qmax, tbits) = (&self.q0, &self.q1, self.qmax, &mut self.tbits);
        let (span, span4, tnormal) = (&self.span, &self.span4, &mut self.tnormal);
        let mut bits_of = |t: usize| {
            let [a, b, c] = triangles[t].map(|i| i as usize);
            tbits[t] = triangle_bits([q0[a], q0[b], q0[c]], [q1[a], q1[b], q1[c]], qmax, span[t]);
        };
        match moved {
            None => {
                all_bits(triangles, q0, q1, qmax, span, span4, tbits, tnormal);
                self.all_creases();
            }
            Some(moved) => {
                for &v in moved {
                    let v = v as usize;
                    if v + 1 < self.vertex_start.len() {
                        let (lo, hi) = (self.vertex_start[v], self.vertex_start[v + 1]);
                        for k in lo..hi {
                            bits_of(self.vertex_tris[k as usize] as usize);
                        }
                    }
                }
                // After every recomputed triangle (a hinge's other side may be among them).
                for &v in moved {
                    let v = v as usize;
                    if v + 1 < self.vertex_start.len() {
                        let (lo, hi) = (self.vertex_start[v], self.vertex_start[v + 1]);
                        for k in lo..hi {
                            self.normals_of(triangles, self.vertex_tris[k as usize] as usize);
                        }
                    }
                }
                for &v in moved {
                    let v = v as usize;
                    if v + 1 < self.vertex_hinge_start.len() {
                        let (lo, hi) = (self.vertex_hinge_start[v], self.vertex_hinge_start[v + 1]);
                        for k in lo..hi {
                            self.crease(self.vertex_hinges[k as usize] as usize);
                        }
                    }
                }
            }
        }
        let node_bits = |n: u32| {
            let node = self.nodes[n as usize];
            self.order[node.start as usize..node.end as usize]
                .iter()
                .fold(u32::MAX, |b, &t| b & self.tbits[t as usize])
        };
        let flat = |&n: &u32| node_bits(n) != 0;
        // The nodes no longer flat go to `failed`, for `search` to take up.
        self.failed.clear();
        self.failed.extend(self.culled.iter().filter(|c| !flat(c)));
        if self.failed.is_empty() {
            return true;
        }
        let failed = &self.failed;
        self.culled.retain(|c| !failed.contains(c));
        for &n in failed {
            let node = self.nodes[n as usize];
            for &t in &self.order[node.start as usize..node.end as usize] {
                self.culled_of[t as usize] = NONE;
            }
        }
        false
    }

    /// The crease rule: the two triangles of hinge `h` lose their cone bits (so no node
    /// holding either is culled) when their normals are more than 90° apart at the start or
    /// the end of the paths. The normal-cone criterion keeps a patch from crossing itself,
    /// not from coming within the thickness of itself: a hinge folded nearly flat keeps every
    /// vertex far from the triangles but brings the two edges across the fold (the diagonals
    /// of the folded pair, which share no vertex) together — measured 1.0 mm apart at a
    /// thickness of 8 mm on the draping cloth, with the patch culled. Folded at most 90°, a
    /// hinge of two right triangles (a grid's) keeps them 0.58 of an edge apart, 0.45 at 120°
    /// and 0.09 at 170°; the thickest surface allowed is half an edge.
    fn crease(&mut self, h: usize) {
        let [t, u] = self.hinges[h].map(|t| t as usize);
        let ([n0, n1], [m0, m1]) = (self.tnormal[t], self.tnormal[u]);
        if n0.dot(m0) < 0.0 || n1.dot(m1) < 0.0 {
            self.tbits[t] = 0;
            self.tbits[u] = 0;
        }
    }

    /// Triangle `t`'s (unnormalized) normals at the start and end of the paths.
    fn normals_of(&mut self, triangles: &[[u32; 3]], t: usize) {
        let [a, b, c] = triangles[t].map(|i| i as usize);
        let n = |q: &[Vec3A]| (q[b] - q[a]).cross(q[c] - q[a]);
        self.tnormal[t] = [n(&self.q0), n(&self.q1)];
    }

    /// The crease rule over every hinge (the normals as [`all_bits`] left them).
    fn all_creases(&mut self) {
        for h in 0..self.hinges.len() {
            self.crease(h);
        }
    }

    /// The nodes' cone bits (and boxes, with `boxes`) from their triangles', bottom-up.
    fn refit_nodes(&mut self, boxes: bool) {
        for n in (0..self.nodes.len()).rev() {
            let node = self.nodes[n];
            if node.child == 0 {
                let ts = &self.order[node.start as usize..node.end as usize];
                let mut bits = u32::MAX;
                let mut bx = (Vec3A::MAX, Vec3A::MIN);
                for &t in ts {
                    bits &= self.tbits[t as usize];
                    if boxes {
                        bx = union32(bx, self.tbox[t as usize]);
                    }
                }
                self.nbits[n] = bits;
                if boxes {
                    self.nbox[n] = bx;
                }
            } else {
                let (l, r) = (node.child as usize, node.child as usize + 1);
                self.nbits[n] = self.nbits[l] & self.nbits[r];
                if boxes {
                    self.nbox[n] = union32(self.nbox[l], self.nbox[r]);
                }
            }
        }
    }

    /// Walks the tree against itself (after [`SurfaceTree::refit`]) and calls `found` for
    /// every point–triangle pair and every edge–edge pair (edge indices) whose boxes (the
    /// refit's) overlap, neither sharing a particle, each once; flat connected nodes are
    /// culled.
    ///
    /// With `resume`, only the nodes that [`SurfaceTree::still_flat`] found no longer
    /// flat are walked (the boxes of the last refit still holding the paths, and the bits
    /// those of the paths now): the pairs they hold are added to what the last search found.
    ///
    /// The walk is [`SurfaceTree::plan`]'s pieces walked in order ([`SurfaceTree::walk_piece`]),
    /// which is how the team walks them too, each piece on whichever thread takes it.
    pub fn search(
        &mut self,
        triangles: &[[u32; 3]],
        edges: &[[u32; 2]],
        resume: bool,
        mut found: impl FnMut(Found),
    ) {
        let mut pieces = std::mem::take(&mut self.pieces);
        self.plan(resume, &mut pieces);
        let mut stack = std::mem::take(&mut self.stack);
        let mut culled = std::mem::take(&mut self.piece_culled);
        let mut tests = 0;
        for &piece in &pieces {
            culled.clear();
            tests += self.walk_piece(piece, triangles, edges, &mut stack, &mut culled, &mut found);
            self.take_culled(&culled);
        }
        self.triangle_pairs = tests;
        (self.pieces, self.stack, self.piece_culled) = (pieces, stack, culled);
    }

    /// The top of a walk (see [`SurfaceTree::search`]), down to pairs of nodes of at most
    /// [`PIECE_TRIANGLES`] triangles each, which it lists in `pieces` in the order a walk
    /// takes them up, rather than walking on into them; a node to be culled as flat is a
    /// piece too. The pieces, walked in that order, find what the whole walk finds in the
    /// order it finds it (the walk is depth first: a pair's descendants are all taken up
    /// before the next pair), and cull what it culls; any thread can walk any piece (they
    /// only read the tree). Clears what the last search culled unless `resume`.
    pub fn plan(&mut self, resume: bool, pieces: &mut Vec<Visit>) {
        pieces.clear();
        self.triangle_pairs = 0;
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = std::mem::take(&mut self.stack);
        stack.clear();
        if resume {
            self.refit_nodes(false);
            stack.extend(self.failed.iter().map(|&n| (n, n, true)));
            self.failed.clear();
        } else {
            self.culled.clear();
            self.failed.clear();
            self.culled_of.fill(NONE);
            stack.push((0, 0, false));
        }
        while let Some(visit @ (a, b, keep)) = stack.pop() {
            let (na, nb) = (self.nodes[a as usize], self.nodes[b as usize]);
            if a != b && !overlap32(&self.nbox[a as usize], &self.nbox[b as usize]) {
                continue;
            }
            let small = (na.end - na.start).max(nb.end - nb.start) <= PIECE_TRIANGLES;
            let leaves = na.child == 0 && nb.child == 0;
            if small || leaves || (a == b && self.flat(a, keep)) {
                pieces.push(visit);
            } else {
                self.children(a, b, &mut stack);
            }
        }
        self.stack = stack;
        // Headroom, as for the candidates: a walk should not allocate each time it passes
        // the last largest count.
        pieces.reserve(pieces.len() / 2);
    }

    /// Walks the node pair `piece` (one of [`SurfaceTree::plan`]'s), calling `found` for the
    /// pairs in it and listing in `culled` the nodes it culls as flat (for
    /// [`SurfaceTree::take_culled`]); returns the number of triangle pairs it compared.
    /// Reads the tree only, so that the team's threads walk pieces side by side.
    pub fn walk_piece(
        &self,
        piece: Visit,
        triangles: &[[u32; 3]],
        edges: &[[u32; 2]],
        stack: &mut Vec<Visit>,
        culled: &mut Vec<u32>,
        found: &mut impl FnMut(Found),
    ) -> u64 {
        stack.clear();
        stack.push(piece);
        let mut tests = 0u64;
        while let Some((a, b, keep)) = stack.pop() {
            let (na, nb) = (self.nodes[a as usize], self.nodes[b as usize]);
            if a == b {
                if self.flat(a, keep) {
                    culled.push(a);
                    continue;
                }
                if na.child == 0 {
                    let ts = &self.order[na.start as usize..na.end as usize];
                    for i in 0..ts.len() {
                        for j in i + 1..ts.len() {
                            tests += 1;
                            self.pair(triangles, edges, ts[i], ts[j], found);
                        }
                    }
                    continue;
                }
            } else {
                if !overlap32(&self.nbox[a as usize], &self.nbox[b as usize]) {
                    continue;
                }
                if na.child == 0 && nb.child == 0 {
                    for &t in &self.order[na.start as usize..na.end as usize] {
                        for &u in &self.order[nb.start as usize..nb.end as usize] {
                            tests += 1;
                            self.pair(triangles, edges, t, u, found);
                        }
                    }
                    continue;
                }
            }
            self.children(a, b, stack);
        }
        tests
    }

    /// Records the nodes a piece culled ([`SurfaceTree::walk_piece`]), pieces in order, as
    /// culled by the search: [`SurfaceTree::still_flat`] checks them and
    /// [`SurfaceTree::search_around`] leaves their pairs out.
    pub fn take_culled(&mut self, culled: &[u32]) {
        for &a in culled {
            self.culled.push(a);
            let n = self.nodes[a as usize];
            for &t in &self.order[n.start as usize..n.end as usize] {
                self.culled_of[t as usize] = a;
            }
        }
    }

    /// Whether node `a`, paired with itself, is culled: one connected piece whose triangles
    /// share a hemisphere (unless `keep`: a culled node found no longer flat).
    #[inline]
    fn flat(&self, a: u32, keep: bool) -> bool {
        !keep && self.nodes[a as usize].connected && self.nbits[a as usize] != 0
    }

    /// Pushes the pairs of children that the walk takes up after the pair of nodes `a` and
    /// `b` (not both leaves): a node against itself, its children against each other and
    /// each against itself; two nodes, the larger one's children against the other.
    #[inline]
    fn children(&self, a: u32, b: u32, stack: &mut Vec<Visit>) {
        let (na, nb) = (self.nodes[a as usize], self.nodes[b as usize]);
        if a == b {
            let (l, r) = (na.child, na.child + 1);
            stack.push((l, r, false));
            stack.push((r, r, false));
            stack.push((l, l, false));
            return;
        }
        let split_a = match (na.child == 0, nb.child == 0) {
            (false, true) => true,
            (true, false) => false,
            _ => na.end - na.start >= nb.end - nb.start,
        };
        if split_a {
            stack.push((na.child + 1, b, false));
            stack.push((na.child, b, false));
        } else {
            stack.push((a, nb.child + 1, false));
            stack.push((a, nb.child, false));
        }
    }

    /// Gives vertex `v` the box of the points `pts` grown by `margin`, in place of the one the
    /// last [`SurfaceTree::refit`] gave it (measured from the same origin, rounded outwards
    /// as it rounds); [`SurfaceTree::refit_boxes`] then takes it up.
    pub fn set_vertex_box(&mut self, v: u32, pts: &[DVec3], margin: f64) {
        let q = pts.iter().map(|&p| (p - self.box_origin).as_vec3a());
        let (lo, hi) = q.fold((Vec3A::MAX, Vec3A::MIN), |(lo, hi), q| {
            (lo.min(q), hi.max(q))
        });
        let qmax = lo.abs().max(hi.abs()).max_element().max(self.box_qmax);
        let m = rounded_margin(margin, qmax);
        self.vbox[v as usize] = (lo - m, hi + m);
    }

    /// The triangles', edges' and nodes' boxes again from the vertices' (after
    /// [`SurfaceTree::set_vertex_box`]).
    pub fn refit_boxes(&mut self, triangles: &[[u32; 3]], edges: &[[u32; 2]]) {
        self.boxes_from_vertices(triangles, edges);
        self.refit_nodes(true);
    }

    /// The triangles' and edges' boxes from their vertices' (a triangle's box is the union of
    /// its vertices').
    fn boxes_from_vertices(&mut self, triangles: &[[u32; 3]], edges: &[[u32; 2]]) {
        let vb = &self.vbox;
        for (b, tri) in self.tbox.iter_mut().zip(triangles) {
            let [x, y, z] = tri.map(|i| vb[i as usize]);
            *b = union32(union32(x, y), z);
        }
        for (b, e) in self.ebox.iter_mut().zip(edges) {
            *b = union32(vb[e[0] as usize], vb[e[1] as usize]);
        }
    }

    /// Calls `found` for every point–triangle and edge–edge pair with a feature at one of the
    /// vertices `around` (the vertex, a triangle or an edge it is a corner of) whose boxes
    /// overlap, neither sharing a particle, except the pairs inside a node the last search
    /// culled (a resumed walk finds those if it stops being flat): with the pairs the walks
    /// found of the features at no vertex of `around`, every pair [`SurfaceTree::search`]
    /// would find. A pair with features at two of them may be reported twice.
    pub fn search_around(
        &mut self,
        triangles: &[[u32; 3]],
        edges: &[[u32; 2]],
        around: &[u32],
        mut found: impl FnMut(Found),
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = std::mem::take(&mut self.around_stack);
        let culled_of = &self.culled_of;
        let apart = |t: u32, u: u32| {
            let c = culled_of[t as usize];
            c == NONE || c != culled_of[u as usize]
        };
        let edge_at = |a: u32, b: u32| {
            edges
                .binary_search(&[a.min(b), a.max(b)])
                .map_or(NONE, |k| k as u32)
        };
        let mut tris = std::mem::take(&mut self.around_tris);
        let mut edge_list = std::mem::take(&mut self.around_edges);
        tris.clear();
        edge_list.clear();
        for &v in around {
            let v = v as usize;
            // The point against every triangle.
            let (vb, owner) = (self.vbox[v], self.vertex_owner[v]);
            if owner != NONE {
                self.overlapping(&vb, &mut stack, |t| {
                    if !triangles[t as usize].contains(&(v as u32)) && apart(owner, t) {
                        found(Found::PointTriangle(v as u32, t));
                    }
                });
            }
            if v + 1 < self.vertex_start.len() {
                let (lo, hi) = (self.vertex_start[v], self.vertex_start[v + 1]);
                for &t in &self.vertex_tris[lo as usize..hi as usize] {
                    if !self.seen_tri[t as usize] {
                        tris.push(t);
                    }
                    for &u in &triangles[t as usize] {
                        let e = edge_at(v as u32, u);
                        if u as usize != v && e != NONE && !self.seen_edge[e as usize] {
                            self.seen_edge[e as usize] = true;
                            edge_list.push(e);
                        }
                    }
                    self.seen_tri[t as usize] = true;
                }
            }
        }
        // Each triangle against every point.
        for &t in &tris {
            let tb = self.tbox[t as usize];
            let tt = triangles[t as usize];
            self.overlapping(&tb, &mut stack, |u| {
                for &p in &self.owned_vertices[u as usize] {
                    if p != NONE
                        && !tt.contains(&p)
                        && overlap32(&self.vbox[p as usize], &tb)
                        && apart(u, t)
                    {
                        found(Found::PointTriangle(p, t));
                    }
                }
            });
            self.seen_tri[t as usize] = false;
        }
        // Each edge against every edge.
        for &e in &edge_list {
            let (eb, ea, owner) = (
                self.ebox[e as usize],
                edges[e as usize],
                self.edge_owner[e as usize],
            );
            self.overlapping(&eb, &mut stack, |u| {
                for &f in &self.owned_edges[u as usize] {
                    if self.edge_near(edges, ea, &eb, f) && apart(owner, u) {
                        found(Found::EdgeEdge(e, f));
                    }
                }
            });
            self.seen_edge[e as usize] = false;
        }
        self.around_stack = stack;
        self.around_tris = tris;
        self.around_edges = edge_list;
    }

    /// Whether edge `f` (`NONE`: none) shares no particle with the edge `ea` and its box
    /// overlaps `eb`.
    #[inline(always)]
    fn edge_near(&self, edges: &[[u32; 2]], ea: [u32; 2], eb: &Box32, f: u32) -> bool {
        if f == NONE {
            return false;
        }
        let fa = edges[f as usize];
        !fa.contains(&ea[0]) && !fa.contains(&ea[1]) && overlap32(eb, &self.ebox[f as usize])
    }

    /// Calls `leaf(t)` for every triangle whose box overlaps `bx` (the last refit's).
    fn overlapping(&self, bx: &Box32, stack: &mut Vec<u32>, mut leaf: impl FnMut(u32)) {
        stack.clear();
        stack.push(0);
        while let Some(n) = stack.pop() {
            if !overlap32(&self.nbox[n as usize], bx) {
                continue;
            }
            let node = self.nodes[n as usize];
            if node.child == 0 {
                for &t in &self.order[node.start as usize..node.end as usize] {
                    if overlap32(&self.tbox[t as usize], bx) {
                        leaf(t);
                    }
                }
            } else {
                stack.push(node.child + 1);
                stack.push(node.child);
            }
        }
    }

    /// The vertex–triangle and edge–edge pairs of triangles `t` and `u` whose boxes overlap,
    /// each vertex and edge taken by the one triangle that owns it, pairs that share a
    /// particle left out.
    #[inline(always)]
    fn pair(
        &self,
        triangles: &[[u32; 3]],
        edges: &[[u32; 2]],
        t: u32,
        u: u32,
        found: &mut impl FnMut(Found),
    ) {
        let (tb, ub) = (&self.tbox[t as usize], &self.tbox[u as usize]);
        if !overlap32(tb, ub) {
            return;
        }
        let (tt, tu) = (triangles[t as usize], triangles[u as usize]);
        for (own, other, other_tri, ob) in [(t, u, tu, ub), (u, t, tt, tb)] {
            for &p in &self.owned_vertices[own as usize] {
                if p != NONE && !other_tri.contains(&p) && overlap32(&self.vbox[p as usize], ob) {
                    found(Found::PointTriangle(p, other));
                }
            }
        }
        for &e in &self.owned_edges[t as usize] {
            if e == NONE {
                continue;
            }
            let (ea, eb) = (edges[e as usize], &self.ebox[e as usize]);
            for &f in &self.owned_edges[u as usize] {
                if self.edge_near(edges, ea, eb, f) {
                    found(Found::EdgeEdge(e, f));
                }
            }
        }
    }
}

/// A cluster of triangles while the tree is built.
struct Cluster {
    bx: Aabb,
    size: u32,
    children: Option<(u32, u32)>,
    alive: bool,
    neighbours: Vec<u32>,
}

/// Joins the clusters `roots` under new clusters by median splits of their boxes' centres
/// along the longest extent; returns the top one.
fn join(cl: &mut Vec<Cluster>, roots: &mut [u32]) -> u32 {
    if roots.len() == 1 {
        return roots[0];
    }
    let centre = |cl: &[Cluster], c: u32| {
        let b = cl[c as usize].bx;
        0.5 * (b.0 + b.1)
    };
    let (lo, hi) = roots.iter().fold((DVec3::MAX, DVec3::MIN), |(l, h), &c| {
        (l.min(centre(cl, c)), h.max(centre(cl, c)))
    });
    let axis = longest_axis(hi - lo);
    let mid = roots.len() / 2;
    roots.select_nth_unstable_by(mid, |&a, &b| {
        centre(cl, a)[axis]
            .total_cmp(&centre(cl, b)[axis])
            .then(a.cmp(&b))
    });
    let (l, r) = roots.split_at_mut(mid);
    let (a, b) = (join(cl, l), join(cl, r));
    cl.push(Cluster {
        bx: union(cl[a as usize].bx, cl[b as usize].bx),
        size: cl[a as usize].size + cl[b as usize].size,
        children: Some((a, b)),
        alive: true,
        neighbours: Vec::new(),
    });
    cl.len() as u32 - 1
}

fn longest_axis(d: DVec3) -> usize {
    if d.x >= d.y && d.x >= d.z {
        0
    } else if d.y >= d.z {
        1
    } else {
        2
    }
}

/// Whether any of the triangles `range` has a corner on a cut (`on_cut`, empty when nothing was
/// torn). A node that reaches a cut is never culled: the cut's two sides can slide over each
/// other (a slit, when both lie in the node) or the material on either side of the cut's end
/// can swing shut around it (a notch) with every normal in one hemisphere and no stretch —
/// the in-plane curling the normal-cone test assumes cloth cannot do.
fn touches_cut(range: &[u32], triangles: &[[u32; 3]], on_cut: &[bool]) -> bool {
    !on_cut.is_empty()
        && range.iter().any(|&t| {
            triangles[t as usize]
                .iter()
                .any(|&c| on_cut.get(c as usize).copied().unwrap_or(false))
        })
}

/// Whether the triangles `range` (of node `node`) are one piece across shared edges: a
/// union–find over them (`stamp` marks membership, `parent` is scratch).
#[allow(clippy::too_many_arguments)]
fn connected(
    range: &[u32],
    tri_edges: &[[u32; 3]],
    edge_start: &[u32],
    edge_tris: &[u32],
    node: u32,
    stamp: &mut [u32],
    parent: &mut [u32],
) -> bool {
    for &t in range {
        stamp[t as usize] = node;
        parent[t as usize] = t;
    }
    let mut pieces = range.len();
    for &t in range {
        for &e in tri_edges[t as usize].iter().filter(|&&e| e != NONE) {
            let e = e as usize;
            for &u in &edge_tris[edge_start[e] as usize..edge_start[e + 1] as usize] {
                if u != t && stamp[u as usize] == node {
                    let (rt, ru) = (super::find(parent, t), super::find(parent, u));
                    if rt != ru {
                        parent[rt.max(ru) as usize] = rt.min(ru);
                        pieces -= 1;
                    }
                }
            }
        }
    }
    pieces == 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::forces::wind::unit;
    use std::collections::BTreeSet;

    fn rand_unit(seed: &mut u64) -> DVec3 {
        loop {
            let v = DVec3::new(unit(seed), unit(seed), unit(seed)) * 2.0 - 1.0;
            if v.length_squared() > 1e-3 && v.length_squared() <= 1.0 {
                return v.normalize();
            }
        }
    }

    fn f(v: DVec3) -> Vec3A {
        v.as_vec3a()
    }

    const ANY: Span = (Vec3A::ZERO, Vec3A::splat(f32::INFINITY));

    #[test]
    fn the_26_directions_cover_the_sphere_within_28_degrees() {
        // The docs' claim: no direction lies farther than 28° from the nearest of the 26, so
        // every cone of half-angle up to 62° lies in one of their hemispheres.
        let dirs: Vec<DVec3> = DIRECTIONS
            .iter()
            .flat_map(|d| {
                let v = DVec3::new(d[0] as f64, d[1] as f64, d[2] as f64).normalize();
                [v, -v]
            })
            .collect();
        let mut seed = 7;
        let worst = (0..20_000)
            .map(|_| {
                let v = rand_unit(&mut seed);
                dirs.iter().map(|d| d.dot(v)).fold(-1.0, f64::max).acos()
            })
            .fold(0.0, f64::max);
        assert!(worst.to_degrees() < 28.0, "{}", worst.to_degrees());
        // Triangles with normals in a random 61° cone all share a direction.
        for _ in 0..200 {
            let axis = rand_unit(&mut seed);
            let mut bits = u32::MAX;
            for _ in 0..50 {
                // A normal within 61° of the axis.
                let n = loop {
                    let n = rand_unit(&mut seed);
                    if n.dot(axis) >= 61f64.to_radians().cos() {
                        break n;
                    }
                };
                let (u, v) = n.any_orthonormal_pair();
                let tri = [DVec3::ZERO, u * 0.1, v * 0.1].map(f);
                bits &= triangle_bits(tri, tri, 0.1, ANY);
            }
            assert_ne!(bits, 0);
        }
    }

    #[test]
    fn cone_bits_hold_all_along_the_straight_paths() {
        // Independent check: the normal of the triangle interpolated at many instants, in
        // f64, against every direction whose bit is set.
        let mut seed = 11;
        let mut set = 0;
        for _ in 0..20_000 {
            let base = DVec3::new(unit(&mut seed), unit(&mut seed), unit(&mut seed));
            let p0 = [0, 1, 2].map(|_| base + rand_unit(&mut seed) * 0.02);
            // Moves up to about the triangle's size: normals may turn over.
            let p1 = p0.map(|p| p + rand_unit(&mut seed) * 0.02 * unit(&mut seed));
            let qmax = p0
                .iter()
                .chain(&p1)
                .map(|p| p.abs().max_element())
                .fold(0.0, f64::max);
            let bits = triangle_bits(p0.map(f), p1.map(f), qmax as f32, ANY);
            for k in 0..26 {
                if bits & (1 << k) == 0 {
                    continue;
                }
                set += 1;
                let d = DIRECTIONS[k % 13];
                let d = DVec3::new(d[0] as f64, d[1] as f64, d[2] as f64)
                    * if k < 13 { 1.0 } else { -1.0 };
                for s in 0..=64 {
                    let tau = s as f64 / 64.0;
                    let p = [0, 1, 2].map(|i| p0[i].lerp(p1[i], tau));
                    let n = (p[1] - p[0]).cross(p[2] - p[0]);
                    assert!(n.dot(d) > 0.0, "bit {k} at τ = {tau}: {p0:?} → {p1:?}");
                }
            }
        }
        assert!(set > 10_000, "the check saw too few bits: {set}");
    }

    /// A grid of `n × n` vertices (spacing `h`) in the plane y = 0, folded by `fold` about
    /// the line x = `x_fold`: the part beyond goes back over the rest at a height `gap`.
    fn folded_grid(n: usize, h: f64, x_fold: f64, gap: f64) -> (Vec<[u32; 3]>, Vec<DVec3>) {
        let mut x = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let (u, z) = (i as f64 * h, j as f64 * h);
                let p = if u <= x_fold {
                    DVec3::new(u, 0.0, z)
                } else {
                    // Around a half circle of diameter `gap`, then back.
                    let s = u - x_fold;
                    let r = 0.5 * gap;
                    let arc = std::f64::consts::PI * r;
                    if s <= arc {
                        let a = s / r;
                        DVec3::new(x_fold + r * a.sin(), r - r * a.cos(), z)
                    } else {
                        DVec3::new(x_fold - (s - arc), gap, z)
                    }
                };
                x.push(p);
            }
        }
        let mut tris = Vec::new();
        let id = |i: usize, j: usize| (j * n + i) as u32;
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                tris.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                tris.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        (tris, x)
    }

    type Pairs = (BTreeSet<(u32, u32)>, BTreeSet<(u32, u32)>);

    /// The tree's pairs for a still surface with vertex boxes grown by `m`.
    fn tree_pairs(tris: &[[u32; 3]], x: &[DVec3], m: f64) -> Pairs {
        tree_pairs_torn(tris, &[], x, m)
    }

    /// [`tree_pairs`] on a torn surface (particle `i` split from `from[i]`).
    fn tree_pairs_torn(tris: &[[u32; 3]], from: &[u32], x: &[DVec3], m: f64) -> Pairs {
        let surf = ContactSurface::torn(tris, from);
        let mut tree = SurfaceTree::default();
        tree.build(&surf, x);
        tree.load(&surf.vertices, x, x);
        tree.refit(tris, &surf.edges, m);
        let (mut pt, mut ee) = (BTreeSet::new(), BTreeSet::new());
        let (mut npt, mut nee) = (0, 0);
        tree.search(tris, &surf.edges, false, |found| match found {
            Found::PointTriangle(p, t) => {
                npt += 1;
                pt.insert((p, t));
            }
            Found::EdgeEdge(e, f) => {
                nee += 1;
                ee.insert((e.min(f), e.max(f)));
            }
        });
        assert_eq!(npt + nee, pt.len() + ee.len(), "a pair was reported twice");
        TESTED.with(|c| c.set(tree.triangle_pairs));
        (pt, ee)
    }

    /// Every pair of `near` is among the `found` ones (names the first that is not).
    fn assert_covers(found: &Pairs, near: &Pairs) {
        let missing_pt = near.0.difference(&found.0).next();
        let missing_ee = near.1.difference(&found.1).next();
        assert!(
            missing_pt.is_none() && missing_ee.is_none(),
            "missed: {missing_pt:?} {missing_ee:?}"
        );
    }

    thread_local! {
        /// Triangle pairs the last `tree_pairs` compared.
        static TESTED: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
    }

    /// Every point–triangle and edge–edge pair (no shared particle) whose boxes overlap, or
    /// (with `within`) whose features are closer than that: all pairs, no tree.
    fn brute_pairs(tris: &[[u32; 3]], x: &[DVec3], m: f64, within: Option<f64>) -> Pairs {
        use crate::core::self_contact::{closest_between_segments, closest_on_triangle};
        let surf = ContactSurface::new(tris);
        let bx = |ids: &[u32]| {
            ids.iter().fold((DVec3::MAX, DVec3::MIN), |(l, h), &i| {
                (l.min(x[i as usize] - m), h.max(x[i as usize] + m))
            })
        };
        let (mut pt, mut ee) = (BTreeSet::new(), BTreeSet::new());
        for &p in &surf.vertices {
            for (t, tri) in tris.iter().enumerate() {
                if tri.contains(&p) {
                    continue;
                }
                let keep = match within {
                    None => overlap(&bx(&[p]), &bx(tri)),
                    Some(d) => {
                        let y = tri.map(|i| x[i as usize]);
                        let b = closest_on_triangle(x[p as usize], y[0], y[1], y[2]);
                        let q = y[0] * b[0] + y[1] * b[1] + y[2] * b[2];
                        x[p as usize].distance(q) < d
                    }
                };
                if keep {
                    pt.insert((p, t as u32));
                }
            }
        }
        for (e, a) in surf.edges.iter().enumerate() {
            for (g, b) in surf.edges.iter().enumerate().skip(e + 1) {
                if b.contains(&a[0]) || b.contains(&a[1]) {
                    continue;
                }
                let keep = match within {
                    None => overlap(&bx(a), &bx(b)),
                    Some(d) => {
                        let [p1, q1, p2, q2] = [a[0], a[1], b[0], b[1]].map(|i| x[i as usize]);
                        let (s, t) = closest_between_segments(p1, q1, p2, q2);
                        p1.lerp(q1, s).distance(p2.lerp(q2, t)) < d
                    }
                };
                if keep {
                    ee.insert((e as u32, g as u32));
                }
            }
        }
        (pt, ee)
    }

    #[test]
    fn without_flat_patches_the_search_finds_exactly_the_overlapping_pairs() {
        // A soup of random small triangles (no shared edges, normals everywhere: nothing is
        // culled) sharing some vertices.
        let mut seed = 3;
        let x: Vec<DVec3> = (0..120)
            .map(|_| DVec3::new(unit(&mut seed), unit(&mut seed), unit(&mut seed)) * 0.3)
            .collect();
        let tris: Vec<[u32; 3]> = (0..150)
            .map(|_| {
                loop {
                    let t = [0, 1, 2].map(|_| (unit(&mut seed) * 120.0) as u32);
                    if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
                        break t;
                    }
                }
            })
            .collect();
        let m = 0.02;
        let found = tree_pairs(&tris, &x, m);
        let all = brute_pairs(&tris, &x, m, None);
        assert!(
            all.0.len() > 100 && all.1.len() > 100,
            "{} {}",
            all.0.len(),
            all.1.len()
        );
        assert_eq!(found, all);
    }

    #[test]
    fn a_flat_sheet_with_a_slit_keeps_every_near_pair_across_the_cut() {
        // A flat 24² sheet (2 cm spacing) slit along twelve vertices of its middle row, as a
        // tear splits them: each gets a copy at its place, which the triangles below the row
        // take. Then the lower side's edge slides 6 mm over the upper side, 1 mm above it —
        // every normal still up, no edge stretched past 1.5 times, so without knowing the cut
        // the patch looks flat and is culled whole. Knowing it, every pair nearer than the
        // margins (exact distances, apart from the tree) is among the candidates.
        let (n, h, m) = (24, 0.02, 0.004);
        let (mut tris, mut x) = folded_grid(n, h, 1.0, 0.0);
        let mut from: Vec<u32> = (0..x.len() as u32).collect();
        let row = 12;
        for i in 6..18 {
            let v = (row * n + i) as u32;
            let copy = x.len() as u32;
            x.push(x[v as usize]);
            from.push(v);
            for t in tris.iter_mut() {
                let below = t.iter().map(|&c| x[c as usize].z).sum::<f64>() / 3.0 < row as f64 * h;
                if below && t.contains(&v) {
                    *t = t.map(|c| if c == v { copy } else { c });
                }
            }
        }
        for p in &mut x[n * n..] {
            *p += DVec3::new(0.0, 0.001, 0.3 * h);
        }
        let near = brute_pairs(&tris, &x, m, Some(2.0 * m));
        assert!(near.0.len() > 20, "the sides overlap: {}", near.0.len());
        let plain = tree_pairs(&tris, &x, m);
        assert!(
            !near.0.is_subset(&plain.0),
            "without the cut the slit is culled: the rule matters on this sheet"
        );
        let found = tree_pairs_torn(&tris, &from, &x, m);
        assert_covers(&found, &near);
        // Chains (a copy of a copy) lead to the first particle; an index out of range leaves a
        // particle its own, and a cycle (bad input) ends without looping.
        let surf = ContactSurface::torn(&[[0, 1, 2], [3, 4, 5]], &[0, 1, 2, 0, 3, 9]);
        assert_eq!(surf.origin, vec![0, 1, 2, 0, 0, 5]);
        assert_eq!(surf.on_cut(), vec![true, false, false, true, true, false]);
        let cycle = ContactSurface::torn(&[[0, 1, 2]], &[1, 0, 2]);
        assert_eq!(cycle.origin, vec![1, 0, 2]);
        assert!(ContactSurface::new(&tris).on_cut().is_empty());
    }

    #[test]
    fn a_search_around_some_vertices_finds_what_a_walk_finds_there() {
        // The sheet folded over itself 6 mm apart: flat parts culled, the fold's layers near.
        let (h, m) = (0.02, 0.004);
        let (tris, x) = folded_grid(24, h, 0.25, 0.006);
        let surf = ContactSurface::new(&tris);
        let edges = &surf.edges;
        let mut tree = SurfaceTree::default();
        tree.build(&surf, &x);
        tree.load(&surf.vertices, &x, &x);
        tree.refit(&tris, edges, m);
        let walk = |tree: &mut SurfaceTree| {
            let mut set = BTreeSet::new();
            tree.search(&tris, edges, false, |f| {
                set.insert(match f {
                    Found::PointTriangle(p, t) => (0, p, t),
                    Found::EdgeEdge(e, f) => (1, e.min(f), e.max(f)),
                });
            });
            set
        };
        let before = walk(&mut tree);
        // Every fifth vertex, and a strip of them across the flat lower layer (inside culled
        // nodes), moved: some to 8 mm up (through the upper layer), some along a path
        // sideways.
        let around: Vec<u32> = (0..x.len() as u32)
            .filter(|&v| v % 5 == 0 || (v / 24 == 12 && v % 24 < 8))
            .collect();
        assert!(
            around
                .iter()
                .any(|&v| tree.culled_of[tree.vertex_owner[v as usize] as usize] != NONE),
            "a moved vertex lies in a culled node"
        );
        for &v in &around {
            let p = x[v as usize];
            if v % 2 == 0 {
                // Gone from where it was.
                tree.set_vertex_box(v, &[p + DVec3::new(0.0, 0.008, 0.0)], m);
            } else {
                tree.set_vertex_box(v, &[p, p + DVec3::new(0.01, 0.0, 0.0)], m);
            }
        }
        tree.refit_boxes(&tris, edges);
        let after = walk(&mut tree);
        let mut found = Vec::new();
        tree.search_around(&tris, edges, &around, |f| {
            found.push(match f {
                Found::PointTriangle(p, t) => (0, p, t),
                Found::EdgeEdge(e, f) => (1, e.min(f), e.max(f)),
            })
        });
        let near: BTreeSet<_> = found.iter().copied().collect();
        // A pair with a feature at a moved vertex.
        let at = |&(kind, a, b): &(u8, u32, u32)| {
            let ids: Vec<u32> = if kind == 0 {
                std::iter::once(a).chain(tris[b as usize]).collect()
            } else {
                edges[a as usize]
                    .into_iter()
                    .chain(edges[b as usize])
                    .collect()
            };
            ids.iter().any(|i| around.contains(i))
        };
        let after_at: BTreeSet<_> = after.iter().copied().filter(at).collect();
        assert_eq!(near, after_at, "the pairs around the moved vertices");
        // With the pairs found before away from them: what the walk finds now.
        let kept: BTreeSet<_> = before.iter().copied().filter(|p| !at(p)).collect();
        assert_eq!(kept.union(&near).copied().collect::<BTreeSet<_>>(), after);
        // The moves made pairs and ended some.
        let before_at: BTreeSet<_> = before.iter().copied().filter(at).collect();
        assert!(near.difference(&before_at).count() > 50, "new pairs");
        assert!(before_at.difference(&near).count() > 10, "pairs ended");
    }

    #[test]
    fn a_flat_sheet_is_culled_whole_and_a_folded_one_keeps_every_near_pair() {
        let (h, m) = (0.02, 0.004);
        // Flat: nothing to test.
        let (tris, x) = folded_grid(24, h, 1.0, 0.0);
        let (pt, ee) = tree_pairs(&tris, &x, m);
        assert!(pt.is_empty() && ee.is_empty(), "{} {}", pt.len(), ee.len());
        assert_eq!(TESTED.with(|c| c.get()), 0);
        // Folded over itself at a gap of 6 mm: every pair closer than the boxes' margins (the
        // exact distance, computed apart from the tree) is among the candidates.
        let (tris, x) = folded_grid(24, h, 0.25, 0.006);
        let found = tree_pairs(&tris, &x, m);
        let near = brute_pairs(&tris, &x, m, Some(2.0 * m));
        let all = brute_pairs(&tris, &x, m, None);
        assert!(near.0.len() > 200, "the layers are near: {}", near.0.len());
        assert_covers(&found, &near);
        assert!(found.0.is_subset(&all.0) && found.1.is_subset(&all.1));
        // Flat parts cost little: of the 560,000 triangle pairs, those compared are a few
        // per triangle of the two layers.
        let tested = TESTED.with(|c| c.get());
        assert!(tested < 20 * tris.len() as u64, "{tested}");
    }

    #[test]
    fn the_batched_cone_bits_are_the_reference_bits() {
        // Random triangles and motions (some past their spans, some turning over), in a
        // count that leaves a remainder after the batches of four.
        let mut seed = 5;
        let n = 403;
        let q0: Vec<Vec3A> = (0..3 * n)
            .map(|_| {
                f(DVec3::new(
                    unit(&mut seed),
                    unit(&mut seed),
                    unit(&mut seed),
                ))
            })
            .collect();
        let q1: Vec<Vec3A> = q0
            .iter()
            .map(|&p| p + f(rand_unit(&mut seed) * 0.3 * unit(&mut seed)))
            .collect();
        let tris: Vec<[u32; 3]> = (0..n as u32)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect();
        let span: Vec<Span> = (0..n)
            .map(|_| {
                let l = Vec3A::splat(unit(&mut seed) as f32);
                (l * 0.2, l * 4.0)
            })
            .collect();
        let mut out = vec![0; n];
        let mut normals = vec![[Vec3A::ZERO; 2]; n];
        let span4: Vec<[Vec4; 6]> = span_lanes(&span).collect();
        all_bits(&tris, &q0, &q1, 1.0, &span, &span4, &mut out, &mut normals);
        let mut set = 0;
        for (t, tri) in tris.iter().enumerate() {
            let [a, b, c] = tri.map(|i| i as usize);
            let want = triangle_bits([q0[a], q0[b], q0[c]], [q1[a], q1[b], q1[c]], 1.0, span[t]);
            assert_eq!(out[t], want, "triangle {t}");
            let n = |q: &[Vec3A]| (q[b] - q[a]).cross(q[c] - q[a]);
            assert_eq!(normals[t], [n(&q0), n(&q1)], "triangle {t}'s normals");
            set += (want != 0) as u32;
        }
        assert!(set > 40 && set < n as u32 - 40, "{set}");
    }

    #[test]
    fn stretched_triangles_are_never_culled() {
        let tri = [DVec3::ZERO, DVec3::X * 0.1, DVec3::Z * 0.1];
        let l = Vec3A::new(0.01, 0.01, 0.02);
        let d2 = DISTORTION * DISTORTION;
        let span = (l / d2, l * d2);
        let q = tri.map(f);
        assert_ne!(triangle_bits(q, q, 0.1, span), 0);
        let far = [tri[0], tri[1] * 1.6, tri[2]].map(f);
        assert_eq!(triangle_bits(q, far, 0.16, span), 0);
        let near = [tri[0], tri[1] * 0.6, tri[2]].map(f);
        assert_eq!(triangle_bits(near, q, 0.1, span), 0);
    }
}
