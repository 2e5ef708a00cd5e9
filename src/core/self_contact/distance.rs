//! The distances of many candidate pairs at once: a pass takes the start distance of every
//! candidate (and a search of every pair its walk found), four pairs of a kind at a time.
//!
//! [`closest_on_triangle`](super::closest_on_triangle) and
//! [`closest_between_segments`](super::closest_between_segments) find the closest points by
//! cases (Ericson's Voronoi regions), one pair at a time: their branches follow the geometry
//! and their divisions depend on each other. Here the distance alone is taken without a
//! data-dependent branch, as the least of every case's distance, each clamped to where it
//! holds, in four lanes:
//!
//! - **point–triangle**: the distance to the point's projection on the plane when that lies
//!   inside the triangle (its barycentric weights compared without dividing), and the
//!   distances to the three edges;
//! - **edge–edge**: the distance between the two lines' closest points when both lie inside
//!   their segments, and the four end-to-segment distances: a convex function's least on the
//!   parameter square is at its critical point or on the square's border.
//!
//! Every case's distance is a distance between points of the two parts, so the least is never
//! below the true distance by more than round-off, and is the true distance to round-off (an
//! ill-conditioned interior point of nearly parallel edges only ever adds a candidate that
//! the ends beat). The lanes are plain `[f64; 4]` arithmetic, element by element, with no
//! fused multiply-add: compiled for AVX where the processor has it and for the baseline
//! otherwise, the same operations in the same order, so the same bits either way.

use glam::DVec3;

/// Pairs a batch holds.
pub(super) const LANES: usize = 4;

#[derive(Clone, Copy)]
struct F([f64; LANES]);

macro_rules! lanewise {
    ($trait:ident, $f:ident, $op:tt) => {
        impl std::ops::$trait for F {
            type Output = F;
            #[inline(always)]
            fn $f(self, o: F) -> F {
                F(std::array::from_fn(|q| self.0[q] $op o.0[q]))
            }
        }
    };
}
lanewise!(Add, add, +);
lanewise!(Sub, sub, -);
lanewise!(Mul, mul, *);
lanewise!(Div, div, /);

/// Lanes' masks: all bits set where true (as the processor's compare gives them).
#[derive(Clone, Copy)]
struct M([bool; LANES]);

impl std::ops::BitAnd for M {
    type Output = M;
    #[inline(always)]
    fn bitand(self, o: M) -> M {
        M(std::array::from_fn(|q| self.0[q] & o.0[q]))
    }
}

impl F {
    #[inline(always)]
    fn splat(v: f64) -> F {
        F([v; LANES])
    }
    /// `a < b ? a : b` lane by lane (the processor's `min`, which keeps `b` for a NaN).
    #[inline(always)]
    fn min(self, o: F) -> F {
        F(std::array::from_fn(|q| {
            if self.0[q] < o.0[q] {
                self.0[q]
            } else {
                o.0[q]
            }
        }))
    }
    /// `a > b ? a : b` lane by lane.
    #[inline(always)]
    fn max(self, o: F) -> F {
        F(std::array::from_fn(|q| {
            if self.0[q] > o.0[q] {
                self.0[q]
            } else {
                o.0[q]
            }
        }))
    }
    #[inline(always)]
    fn lt(self, o: F) -> M {
        M(std::array::from_fn(|q| self.0[q] < o.0[q]))
    }
    #[inline(always)]
    fn le(self, o: F) -> M {
        M(std::array::from_fn(|q| self.0[q] <= o.0[q]))
    }
    /// `m ? self : o` lane by lane.
    #[inline(always)]
    fn select(m: M, a: F, b: F) -> F {
        F(std::array::from_fn(
            |q| if m.0[q] { a.0[q] } else { b.0[q] },
        ))
    }
    #[inline(always)]
    fn sqrt(self) -> F {
        F(self.0.map(f64::sqrt))
    }
}

/// Three coordinates by lanes.
#[derive(Clone, Copy)]
struct V {
    x: F,
    y: F,
    z: F,
}

impl V {
    #[inline(always)]
    fn load(y: &[[DVec3; 4]; LANES], k: usize) -> V {
        V {
            x: F(std::array::from_fn(|q| y[q][k].x)),
            y: F(std::array::from_fn(|q| y[q][k].y)),
            z: F(std::array::from_fn(|q| y[q][k].z)),
        }
    }
    #[inline(always)]
    fn sub(self, o: V) -> V {
        V {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
    #[inline(always)]
    fn add(self, o: V) -> V {
        V {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }
    #[inline(always)]
    fn scale(self, s: F) -> V {
        V {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }
    #[inline(always)]
    fn dot(self, o: V) -> F {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    #[inline(always)]
    fn cross(self, o: V) -> V {
        V {
            x: self.y * o.z - self.z * o.y,
            y: self.z * o.x - self.x * o.z,
            z: self.x * o.y - self.y * o.x,
        }
    }
}

/// The squared distance from `p` to the segment from `a` along `d` (`dd = |d|²`): the
/// parameter clamped to the segment (a segment of no length gives its end).
#[inline(always)]
fn point_segment(p: V, a: V, d: V, dd: F) -> F {
    let ap = p.sub(a);
    let t = (ap.dot(d) / dd.max(F::splat(f64::MIN_POSITIVE)))
        .min(F::splat(1.0))
        .max(F::splat(0.0));
    let r = ap.sub(d.scale(t));
    r.dot(r)
}

/// Distances from point `y[q][0]` to triangle `y[q][1..4]`.
#[inline(always)]
fn point_triangle_body(y: &[[DVec3; 4]; LANES]) -> [f64; LANES] {
    let (p, a, b, c) = (V::load(y, 0), V::load(y, 1), V::load(y, 2), V::load(y, 3));
    let (ab, ac, bc, ap) = (b.sub(a), c.sub(a), c.sub(b), p.sub(a));
    let n = ab.cross(ac);
    let nn = n.dot(n);
    // The projection of `p` is `a + (vn ab + wn ac) / nn`; taken as that point of the
    // triangle (not as the distance to the plane, which a nearly degenerate triangle's
    // normal gets wrong), so that it is a distance between the parts whatever the rounding.
    let vn = ap.cross(ac).dot(n);
    let wn = ab.cross(ap).dot(n);
    let zero = F::splat(0.0);
    let inside = zero.lt(nn) & zero.le(vn) & zero.le(wn) & (vn + wn).le(nn);
    let inv = F::splat(1.0) / nn.max(F::splat(f64::MIN_POSITIVE));
    let w = ap.sub(ab.scale(vn * inv)).sub(ac.scale(wn * inv));
    let plane = F::select(inside, w.dot(w), F::splat(f64::INFINITY));
    let edges = point_segment(p, a, ab, ab.dot(ab))
        .min(point_segment(p, a, ac, ac.dot(ac)))
        .min(point_segment(p, b, bc, bc.dot(bc)));
    plane.min(edges).sqrt().0
}

/// Distances between segments `y[q][0] y[q][1]` and `y[q][2] y[q][3]`.
#[inline(always)]
fn edge_edge_body(y: &[[DVec3; 4]; LANES]) -> [f64; LANES] {
    let (p1, q1, p2, q2) = (V::load(y, 0), V::load(y, 1), V::load(y, 2), V::load(y, 3));
    let (d1, d2, r) = (q1.sub(p1), q2.sub(p2), p1.sub(p2));
    let (a, e, b) = (d1.dot(d1), d2.dot(d2), d1.dot(d2));
    let (c, f) = (d1.dot(r), d2.dot(r));
    let denom = a * e - b * b;
    let inv = F::splat(1.0) / denom.max(F::splat(f64::MIN_POSITIVE));
    let (s, t) = ((b * f - c * e) * inv, (a * f - b * c) * inv);
    let (zero, one) = (F::splat(0.0), F::splat(1.0));
    // The same test of nearly parallel lines as `closest_between_segments`.
    let inner =
        (F::splat(1e-14) * a * e).lt(denom) & zero.lt(s) & s.lt(one) & zero.lt(t) & t.lt(one);
    let w = r.add(d1.scale(s)).sub(d2.scale(t));
    let interior = F::select(inner, w.dot(w), F::splat(f64::INFINITY));
    let ends = point_segment(p1, p2, d2, e)
        .min(point_segment(q1, p2, d2, e))
        .min(point_segment(p2, p1, d1, a))
        .min(point_segment(q2, p1, d1, a));
    interior.min(ends).sqrt().0
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn point_triangle_avx(y: &[[DVec3; 4]; LANES]) -> [f64; LANES] {
    point_triangle_body(y)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn edge_edge_avx(y: &[[DVec3; 4]; LANES]) -> [f64; LANES] {
    edge_edge_body(y)
}

fn avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Distances of four point–triangle pairs (`[p, a, b, c]` each).
pub(super) fn point_triangle(y: &[[DVec3; 4]; LANES]) -> [f64; LANES] {
    #[cfg(target_arch = "x86_64")]
    if avx() {
        // SAFETY: the processor has AVX.
        return unsafe { point_triangle_avx(y) };
    }
    point_triangle_body(y)
}

/// Distances of four edge–edge pairs (`[a, b, c, d]` each: edges `ab` and `cd`).
pub(super) fn edge_edge(y: &[[DVec3; 4]; LANES]) -> [f64; LANES] {
    #[cfg(target_arch = "x86_64")]
    if avx() {
        // SAFETY: the processor has AVX.
        return unsafe { edge_edge_avx(y) };
    }
    edge_edge_body(y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::self_contact::{closest_between_segments, closest_on_triangle};

    /// Random pairs, with the degenerate ones the cases meet: parallel and collinear edges,
    /// edges and triangles of no extent, points on the plane, in the triangle, on an edge.
    fn pairs() -> Vec<[DVec3; 4]> {
        let mut rnd = crate::math::test_rng(0x9e37_79b9_7f4a_7c15u64);
        let mut out = vec![];
        for k in 0..4000 {
            let mut y = [0; 4].map(|_| DVec3::new(rnd(), rnd(), rnd()));
            match k % 10 {
                // Parallel edges (and a triangle with two parallel sides: degenerate).
                1 => y[3] = y[2] + (y[1] - y[0]) * rnd(),
                // Collinear.
                2 => {
                    y[2] = y[0] + (y[1] - y[0]) * (2.0 * rnd());
                    y[3] = y[0] + (y[1] - y[0]) * (2.0 * rnd());
                }
                // A part of no extent.
                3 => y[1] = y[0],
                4 => y[3] = y[2],
                // The point on the triangle's plane, inside it, or on an edge.
                5 => {
                    let (s, t) = (0.5 * (rnd() + 1.0), 0.5 * (rnd() + 1.0));
                    y[0] = y[1] + (y[2] - y[1]) * s + (y[3] - y[1]) * t;
                }
                6 => {
                    let (s, t) = (0.25 * (rnd() + 1.0), 0.25 * (rnd() + 1.0));
                    y[0] = y[1] + (y[2] - y[1]) * s + (y[3] - y[1]) * t;
                }
                7 => y[0] = y[1].lerp(y[2], 0.5 * (rnd() + 1.0)),
                // Far from the origin, small: the f32 build's surfaces in f64.
                8 => {
                    let o = DVec3::new(40.0, -25.0, 90.0);
                    y = y.map(|v| o + v * 0.01);
                }
                _ => {}
            }
            out.push(y);
        }
        out
    }

    fn batches(ys: &[[DVec3; 4]], f: impl Fn(&[[DVec3; 4]; LANES]) -> [f64; LANES]) -> Vec<f64> {
        ys.chunks(LANES)
            .flat_map(|c| {
                let y = std::array::from_fn(|q| c[q.min(c.len() - 1)]);
                f(&y)[..c.len()].to_vec()
            })
            .collect()
    }

    #[test]
    fn lanes_give_the_distances_of_the_closest_points() {
        let ys = pairs();
        let pt = batches(&ys, point_triangle);
        let ee = batches(&ys, edge_edge);
        for (k, y) in ys.iter().enumerate() {
            let scale = y.iter().map(|v| v.length()).fold(1.0, f64::max);
            let b = closest_on_triangle(y[0], y[1], y[2], y[3]);
            let want = y[0].distance(y[1] * b[0] + y[2] * b[1] + y[3] * b[2]);
            assert!(
                (pt[k] - want).abs() <= 1e-12 * scale,
                "point–triangle {k}: {} against {want} ({y:?})",
                pt[k]
            );
            let (s, t) = closest_between_segments(y[0], y[1], y[2], y[3]);
            let want = y[0].lerp(y[1], s).distance(y[2].lerp(y[3], t));
            assert!(
                (ee[k] - want).abs() <= 1e-12 * scale,
                "edge–edge {k}: {} against {want} ({y:?})",
                ee[k]
            );
        }
    }

    #[test]
    fn lanes_give_the_same_bits_with_and_without_avx() {
        let ys = pairs();
        let base = |f: fn(&[[DVec3; 4]; LANES]) -> [f64; LANES]| {
            batches(&ys, f)
                .iter()
                .map(|d| d.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(base(point_triangle), base(point_triangle_body));
        assert_eq!(base(edge_edge), base(edge_edge_body));
    }
}
