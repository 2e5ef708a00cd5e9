//! An exact triangle–triangle intersection test, written apart from the crate's collision code
//! (which it checks): Shewchuk's exact orientation predicates (`robust`) on the positions as
//! `f64` (exact for both precisions), and a sweep over the triangles' boxes.

use robust::{Coord, Coord3D, orient2d, orient3d};

type P = [f64; 3];

fn c3(p: P) -> Coord3D<f64> {
    Coord3D {
        x: p[0],
        y: p[1],
        z: p[2],
    }
}

fn o3(a: P, b: P, c: P, d: P) -> f64 {
    orient3d(c3(a), c3(b), c3(c), c3(d))
}

fn sign(x: f64) -> i8 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}

/// Drops the coordinate along which the triangle `t`'s normal is largest (exact: a projection
/// along an axis keeps the coordinates as they are).
fn project(t: &[P; 3]) -> impl Fn(P) -> Coord<f64> {
    let u = [t[1][0] - t[0][0], t[1][1] - t[0][1], t[1][2] - t[0][2]];
    let v = [t[2][0] - t[0][0], t[2][1] - t[0][1], t[2][2] - t[0][2]];
    let n = [
        (u[1] * v[2] - u[2] * v[1]).abs(),
        (u[2] * v[0] - u[0] * v[2]).abs(),
        (u[0] * v[1] - u[1] * v[0]).abs(),
    ];
    let drop = if n[0] >= n[1] && n[0] >= n[2] {
        0
    } else if n[1] >= n[2] {
        1
    } else {
        2
    };
    move |p: P| match drop {
        0 => Coord { x: p[1], y: p[2] },
        1 => Coord { x: p[2], y: p[0] },
        _ => Coord { x: p[0], y: p[1] },
    }
}

fn segments_meet_2d(a: Coord<f64>, b: Coord<f64>, c: Coord<f64>, d: Coord<f64>) -> bool {
    let d1 = sign(orient2d(a, b, c));
    let d2 = sign(orient2d(a, b, d));
    let d3 = sign(orient2d(c, d, a));
    let d4 = sign(orient2d(c, d, b));
    if d1 * d2 < 0 && d3 * d4 < 0 {
        return true;
    }
    let on = |p: Coord<f64>, q: Coord<f64>, r: Coord<f64>| {
        r.x >= p.x.min(q.x) && r.x <= p.x.max(q.x) && r.y >= p.y.min(q.y) && r.y <= p.y.max(q.y)
    };
    (d1 == 0 && on(a, b, c))
        || (d2 == 0 && on(a, b, d))
        || (d3 == 0 && on(c, d, a))
        || (d4 == 0 && on(c, d, b))
}

fn inside_2d(p: Coord<f64>, t: [Coord<f64>; 3]) -> bool {
    let s = [
        sign(orient2d(t[0], t[1], p)),
        sign(orient2d(t[1], t[2], p)),
        sign(orient2d(t[2], t[0], p)),
    ];
    !(s.contains(&1) && s.contains(&-1))
}

/// Two coplanar triangles (given projected) overlap.
fn triangles_meet_2d(a: [Coord<f64>; 3], b: [Coord<f64>; 3]) -> bool {
    for i in 0..3 {
        for j in 0..3 {
            if segments_meet_2d(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]) {
                return true;
            }
        }
    }
    inside_2d(a[0], b) || inside_2d(b[0], a)
}

/// Segment `pq` meets the closed triangle `t` (not coplanar with it).
fn segment_meets_triangle(p: P, q: P, t: &[P; 3]) -> bool {
    let sp = sign(o3(t[0], t[1], t[2], p));
    let sq = sign(o3(t[0], t[1], t[2], q));
    if sp * sq > 0 || (sp == 0 && sq == 0) {
        return false;
    }
    let s = [
        sign(o3(p, q, t[0], t[1])),
        sign(o3(p, q, t[1], t[2])),
        sign(o3(p, q, t[2], t[0])),
    ];
    !(s.contains(&1) && s.contains(&-1))
}

/// Whether two closed triangles share a point.
pub fn triangles_intersect(a: &[P; 3], b: &[P; 3]) -> bool {
    let sa = b.map(|p| sign(o3(a[0], a[1], a[2], p)));
    if sa.iter().all(|&s| s > 0) || sa.iter().all(|&s| s < 0) {
        return false;
    }
    let sb = a.map(|p| sign(o3(b[0], b[1], b[2], p)));
    if sb.iter().all(|&s| s > 0) || sb.iter().all(|&s| s < 0) {
        return false;
    }
    if sa == [0, 0, 0] {
        let pr = project(a);
        return triangles_meet_2d(a.map(&pr), b.map(&pr));
    }
    for i in 0..3 {
        if segment_meets_triangle(a[i], a[(i + 1) % 3], b)
            || segment_meets_triangle(b[i], b[(i + 1) % 3], a)
        {
            return true;
        }
    }
    false
}

fn boxes(x: &[P], tris: &[[u32; 3]], grow: f64) -> Vec<(P, P)> {
    tris.iter()
        .map(|t| {
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for &i in t {
                for k in 0..3 {
                    lo[k] = lo[k].min(x[i as usize][k] - grow);
                    hi[k] = hi[k].max(x[i as usize][k] + grow);
                }
            }
            (lo, hi)
        })
        .collect()
}

/// Pairs of triangles sharing no particle whose boxes overlap (sweep along x).
fn candidate_pairs(x: &[P], tris: &[[u32; 3]], grow: f64, mut f: impl FnMut(usize, usize)) {
    let b = boxes(x, tris, grow);
    let mut order: Vec<usize> = (0..tris.len()).collect();
    order.sort_by(|&i, &j| b[i].0[0].total_cmp(&b[j].0[0]));
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if b[j].0[0] > b[i].1[0] {
                break;
            }
            let overlap = (1..3).all(|d| b[i].0[d] <= b[j].1[d] && b[j].0[d] <= b[i].1[d]);
            if overlap && !tris[i].iter().any(|v| tris[j].contains(v)) {
                f(i, j);
            }
        }
    }
}

/// The number of pairs of triangles that share no particle and intersect.
pub fn intersecting_pairs(x: &[P], tris: &[[u32; 3]]) -> usize {
    let mut n = 0;
    candidate_pairs(x, tris, 0.0, |i, j| {
        let t = |k: usize| tris[k].map(|v| x[v as usize]);
        if triangles_intersect(&t(i), &t(j)) {
            n += 1;
        }
    });
    n
}

fn sub(a: P, b: P) -> P {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: P, b: P) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: P, b: P) -> P {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn point_segment(p: P, a: P, b: P) -> f64 {
    let ab = sub(b, a);
    let t = (dot(sub(p, a), ab) / dot(ab, ab).max(1e-300)).clamp(0.0, 1.0);
    let q = [a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]];
    dot(sub(p, q), sub(p, q)).sqrt()
}

/// Distance from `p` to the triangle: to its plane when the projection falls inside (all
/// three edge normals agree), else to the nearest edge.
pub fn point_triangle_distance(p: P, t: &[P; 3]) -> f64 {
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    let nn = dot(n, n);
    if nn > 0.0 {
        let inside = (0..3).all(|i| dot(cross(sub(t[(i + 1) % 3], t[i]), sub(p, t[i])), n) >= 0.0);
        if inside {
            return dot(sub(p, t[0]), n).abs() / nn.sqrt();
        }
    }
    (0..3)
        .map(|i| point_segment(p, t[i], t[(i + 1) % 3]))
        .fold(f64::INFINITY, f64::min)
}

/// The smallest distance from a particle of the surface to a triangle it is not a vertex of,
/// among pairs closer than `within` (infinity when none is).
pub fn closest_approach(x: &[P], tris: &[[u32; 3]], within: f64) -> f64 {
    let b = boxes(x, tris, within);
    let mut verts: Vec<u32> = tris.iter().flatten().copied().collect();
    verts.sort_unstable();
    verts.dedup();
    let mut order: Vec<usize> = (0..tris.len()).collect();
    order.sort_by(|&i, &j| b[i].0[0].total_cmp(&b[j].0[0]));
    let lows: Vec<f64> = order.iter().map(|&i| b[i].0[0]).collect();
    let max_width = b.iter().map(|(lo, hi)| hi[0] - lo[0]).fold(0.0, f64::max);
    let mut best = f64::INFINITY;
    for &v in &verts {
        let p = x[v as usize];
        let from = lows.partition_point(|&l| l < p[0] - max_width);
        for &i in &order[from..] {
            if b[i].0[0] > p[0] {
                break;
            }
            let inside = (0..3).all(|d| b[i].0[d] <= p[d] && p[d] <= b[i].1[d]);
            if inside && !tris[i].contains(&v) {
                let d = point_triangle_distance(p, &tris[i].map(|k| x[k as usize]));
                best = best.min(d);
            }
        }
    }
    best
}

/// Distance between segments `p1 q1` and `p2 q2` (Ericson, *Real-Time Collision Detection*,
/// §5.1.9: the closest points' parameters, clamped to the segments).
pub fn segment_distance(p1: P, q1: P, p2: P, q2: P) -> f64 {
    let (d1, d2, r) = (sub(q1, p1), sub(q2, p2), sub(p1, p2));
    let (a, e, f) = (dot(d1, d1), dot(d2, d2), dot(d2, r));
    let (s, t) = if a <= 1e-300 && e <= 1e-300 {
        (0.0, 0.0)
    } else if a <= 1e-300 {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = dot(d1, r);
        if e <= 1e-300 {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = dot(d1, d2);
            let denom = a * e - b * b;
            let mut s = if denom > 0.0 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    let c1 = [p1[0] + d1[0] * s, p1[1] + d1[1] * s, p1[2] + d1[2] * s];
    let c2 = [p2[0] + d2[0] * t, p2[1] + d2[1] * t, p2[2] + d2[2] * t];
    dot(sub(c1, c2), sub(c1, c2)).sqrt()
}

/// The smallest distance between two edges of the surface that share no particle, among
/// pairs closer than `within` (infinity when none is).
pub fn closest_edge_approach(x: &[P], tris: &[[u32; 3]], within: f64) -> f64 {
    let mut edges: Vec<[u32; 2]> = tris
        .iter()
        .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
        .map(|[a, b]| [a.min(b), a.max(b)])
        .collect();
    edges.sort_unstable();
    edges.dedup();
    let lo = |e: &[u32; 2]| x[e[0] as usize][0].min(x[e[1] as usize][0]);
    let hi = |e: &[u32; 2]| x[e[0] as usize][0].max(x[e[1] as usize][0]);
    edges.sort_by(|a, b| lo(a).total_cmp(&lo(b)));
    let mut best = f64::INFINITY;
    for (k, e) in edges.iter().enumerate() {
        for f in &edges[k + 1..] {
            if lo(f) > hi(e) + within {
                break;
            }
            if f.contains(&e[0]) || f.contains(&e[1]) {
                continue;
            }
            let p = |i: u32| x[i as usize];
            best = best.min(segment_distance(p(e[0]), p(e[1]), p(f[0]), p(f[1])));
        }
    }
    best
}
