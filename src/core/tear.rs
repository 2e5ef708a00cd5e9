//! Tearing: springs and tets stretched past a strain limit break, and the surface tears along
//! them.
//!
//! At the end of a frame every spring's strain `|xₐ − x_b| / L₀ − 1` is compared with the
//! limit, the most strained first. A spring past it that lies along a surface edge tears the
//! surface there: one of its ends (the one with more triangles around it; the other if that
//! one's triangles all lie on one side) is split by the plane through it square to the edge
//! (Müller et al., *Position Based Dynamics*, 2006, §4.5 — tearing by splitting a vertex
//! along the plane perpendicular to an overstretched edge). The triangles around the vertex
//! that hold the edge or whose centres lie on the far side go to a copy of the particle — same position, velocity and texture
//! coordinate, and the share of its mass that those triangles lump onto it (a third of each
//! triangle's area, as a lumped mass matrix does), so momentum is kept exactly — and so do
//! the vertex's springs whose other end lies on the far side, the stretched one among them
//! (freed, it relaxes); an edge that lies on the cut (triangles on both sides) keeps its
//! spring on the near side, and the far side's copy of the edge gets a spring of its own
//! with the same settings. Springs past the limit off the surface, and surface springs whose
//! ends cannot be split (the hole then loses the triangles on that edge), are removed. The
//! cut follows the mesh's
//! edges (nothing is re-meshed): pulled apart, a cloth tears square to the pull, one vertex
//! per broken edge, and a tear running across a strip adds one particle per vertex it passes.
//!
//! Springs that cross a cut without touching the split vertex (bending springs, the other
//! shear diagonal) are not cut by it: they stretch as the cut opens and break by their own
//! strain a moment later. Springs of a body without a surface (a rope) just break.
//!
//! **Tets** break when their largest principal stretch (the square root of the largest
//! eigenvalue of `FᵀF`: [`largest_stretch`]) passes `1 + max_strain` — what a spring along
//! that direction would read, so one limit means the same for both. A broken tet splits off
//! at one of its corners, the node splitting of O'Brien and Hodgins (*Graphical modeling and
//! animation of brittle fracture*, SIGGRAPH 1999) and Parker and O'Brien (*Real-time
//! deformation and fracture in a game environment*, SCA 2009): the plane through the corner
//! square to the stretch divides the tets around it by their centres, and those on the broken
//! tet's side go to a copy of the corner (mass shared by their volumes, clamped as above),
//! so the crack runs along the faces between them and nothing is re-meshed. The corner tried
//! first is the one lowest along the stretch (its sign made the same for every tet), so tets
//! stretched alike crack along one plane of corners; a tet none of whose corners can be split
//! (each has all its tets on one side) is removed. A tet that a crack reached earlier in the
//! same check waits for the next, when its strain is measured again. A surface that is the
//! tets' boundary is recomputed from them, so the crack's faces show; the triangles of any
//! other surface go, at a split corner, with the side of their centres. In a body of tets,
//! springs past the limit just break (the tets carry the surface).
//!
//! Tearing is checked once per frame (a frame is the unit in which a body's layout changes);
//! a spring or tet pulled fast can overshoot the limit within the frame by its strain rate
//! times the frame's length.

use crate::core::driver::Simulation;
use crate::core::fem::element::{RestShape, signed_volume};
use crate::core::fem::mesh::boundary_faces;
use crate::core::ode::ParticleState;
use crate::core::particles::ParticleModel;
use crate::core::scene::{Scene, SceneError};
use crate::math::{Scalar, ToScalar, Vector, VectorExt};
use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

/// The least share of a split particle's mass either side keeps.
pub const MIN_SHARE: f64 = 0.25;

/// When springs break.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TearParams {
    /// Strain at which a spring breaks (`0.5`: at 1.5 times its rest length). Positive.
    pub max_strain: f64,
}

impl Default for TearParams {
    fn default() -> Self {
        Self { max_strain: 0.5 }
    }
}

impl TearParams {
    /// Checks the limit: `Err((field, message))`.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if !(self.max_strain.is_finite() && self.max_strain > 0.0) {
            return Err((
                "max_strain",
                format!(
                    "must be positive and finite (a strain: 0.5 breaks a spring at 1.5 times its rest length), got {}",
                    self.max_strain
                ),
            ));
        }
        Ok(())
    }
}

/// The springs stretched past `max_strain` at positions `x`, ascending, each with its strain
/// (springs given as ends and rest length; a rest length that is not positive never breaks).
pub fn overstretched(
    springs: impl IntoIterator<Item = ([u32; 2], Scalar)>,
    x: &[Vector],
    max_strain: f64,
) -> Vec<(usize, f64)> {
    springs
        .into_iter()
        .enumerate()
        .filter_map(|(k, ([a, b], rest))| {
            let (a, b) = (a as usize, b as usize);
            if rest <= 0.0 || a >= x.len() || b >= x.len() {
                return None;
            }
            let strain = (x[a] - x[b]).length() as f64 / rest as f64 - 1.0;
            (strain > max_strain).then_some((k, strain))
        })
        .collect()
}

/// What a tear changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Torn {
    /// Springs stretched past the limit, ascending.
    pub over: Vec<usize>,
    /// Springs removed, ascending: those past the limit that do not lie on a surface edge,
    /// or whose edge could not be split (the others went with the split-off copy).
    pub broken: Vec<usize>,
    /// Springs whose ends moved to a copy: (spring, new ends), ascending by spring.
    pub moved: Vec<(usize, [u32; 2])>,
    /// New particles, in order (the first gets index `n`, the particle count before): the
    /// particle each copies, and its mass.
    pub copies: Vec<(u32, f64)>,
    /// For each split, the original and its copy with the unit direction from each into its
    /// own side (towards the middle of the triangles it keeps), in order: where
    /// [`part_copies`] moves them.
    pub inward: Vec<(u32, Vector)>,
    /// New springs, in order: the spring each copies (its settings) and its ends — the
    /// split-off side's own spring along an edge that lies on the cut.
    pub added: Vec<(usize, [u32; 2])>,
    /// Tets strained past the limit, ascending.
    pub tets_over: Vec<usize>,
    /// Tets removed, ascending: those past the limit none of whose corners could be split.
    pub tets_removed: Vec<usize>,
    /// Tets whose corners moved to copies: (tet, new corners), ascending by tet.
    pub tets_moved: Vec<(usize, [u32; 4])>,
}

impl Torn {
    /// Nothing changed.
    pub fn is_empty(&self) -> bool {
        self.over.is_empty() && self.tets_over.is_empty()
    }
}

/// The largest principal stretch of a deformation gradient `F` (the square root of the
/// largest eigenvalue `λ₁` of `C = FᵀF`) and the unit direction it stretches along in the
/// deformed body (`F v / |F v|` for the eigenvector `v` of `C`; any unit vector when `F`
/// stretches every direction alike). The eigenvalues in closed form (Smith, *Eigenvalues of a
/// symmetric 3 × 3 matrix*, Communications of the ACM, 1961); the eigenvector of whichever of
/// `λ₁` and `λ₃` lies farther from `λ₂` as the longest cross product of two rows of `C − λ I`,
/// and when that is `λ₃`, `v` from the 2 × 2 problem in the plane square to it (Eberly, *A
/// robust eigensolver for 3 × 3 symmetric matrices*, 2014): a repeated `λ₁` is then exact.
pub fn largest_stretch(f: &DMat3) -> (f64, DVec3) {
    let c = f.transpose() * *f;
    let (a00, a11, a22) = (c.x_axis.x, c.y_axis.y, c.z_axis.z);
    let (a01, a02, a12) = (c.y_axis.x, c.z_axis.x, c.z_axis.y);
    let p1 = a01 * a01 + a02 * a02 + a12 * a12;
    let q = (a00 + a11 + a22) / 3.0;
    let p2 = (a00 - q).powi(2) + (a11 - q).powi(2) + (a22 - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    let v = if p > 0.0 && p.is_finite() {
        let b = (c - DMat3::from_diagonal(DVec3::splat(q))) * (1.0 / p);
        let phi = (0.5 * b.determinant()).clamp(-1.0, 1.0).acos() / 3.0;
        let l1 = q + 2.0 * p * phi.cos();
        let l3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
        let l2 = 3.0 * q - l1 - l3;
        let null = |l: f64| {
            let m = c - DMat3::from_diagonal(DVec3::splat(l));
            // `m` is symmetric: its columns are its rows.
            let (r0, r1, r2) = (m.x_axis, m.y_axis, m.z_axis);
            [r0.cross(r1), r0.cross(r2), r1.cross(r2)]
                .into_iter()
                .max_by(|a, b| a.length_squared().total_cmp(&b.length_squared()))
                .unwrap_or(DVec3::X)
                .normalize_or(DVec3::X)
        };
        if l1 - l2 >= l2 - l3 {
            null(l1)
        } else {
            let u3 = null(l3);
            let e1 = u3.any_orthonormal_vector();
            let e2 = u3.cross(e1);
            let (a, b, d) = (e1.dot(c * e1), e1.dot(c * e2), e2.dot(c * e2));
            let theta = 0.5 * (2.0 * b).atan2(a - d);
            e1 * theta.cos() + e2 * theta.sin()
        }
    } else {
        DVec3::X
    };
    let lambda = (c * v).dot(v);
    let d = *f * v;
    let d = if d.length() > 0.0 { d.normalize() } else { v };
    (lambda.max(0.0).sqrt(), d)
}

/// The tets strained past `max_strain` at positions `x`, ascending, each with its strain —
/// its largest principal stretch minus one, what a spring along that direction would read, so
/// a limit means the same for springs and tets — and the direction of that stretch
/// ([`largest_stretch`]). Tets given as corners and rest shape; corners out of range never
/// break.
pub fn overstrained_tets<'a>(
    tets: impl IntoIterator<Item = ([u32; 4], &'a RestShape)>,
    x: &[Vector],
    max_strain: f64,
) -> Vec<(usize, f64, Vector)> {
    tets.into_iter()
        .enumerate()
        .filter_map(|(k, (v, rest))| {
            if v.iter().any(|&i| i as usize >= x.len()) {
                return None;
            }
            let f = rest.deformation_gradient(v.map(|i| DVec3::from_array(x[i as usize].to_f64())));
            // Gershgorin's bound on the largest eigenvalue of `C = FᵀF` first: near rest, in
            // any rotation, `C` is near `I` and the bound near 1, so most tets need no more.
            let c = f.transpose() * f;
            let row = |r: DVec3| r.abs().element_sum();
            let bound = row(c.x_axis).max(row(c.y_axis)).max(row(c.z_axis));
            if bound <= (1.0 + max_strain).powi(2) {
                return None;
            }
            let (stretch, d) = largest_stretch(&f);
            let strain = stretch - 1.0;
            (strain > max_strain).then(|| (k, strain, d.to_array().to_scalar()))
        })
        .collect()
}

/// The tets of [`overstrained_tets`]'s list, most strained first (ties: lower index first),
/// with their directions.
pub fn tets_by_strain(over: &[(usize, f64, Vector)]) -> Vec<(usize, Vector)> {
    let mut o = over.to_vec();
    o.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    o.into_iter().map(|(k, _, d)| (k, d)).collect()
}

/// True when `triangles` are the boundary of `tets` ([`boundary_faces`]), each triangle up to
/// a rotation of its corners, in any order: a surface that tearing recomputes from the tets.
pub fn is_boundary_of(triangles: &[[u32; 3]], tets: &[[u32; 4]]) -> bool {
    let canonical = |t: &[u32; 3]| {
        let k = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
        [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
    };
    let mut a: Vec<[u32; 3]> = triangles.iter().map(canonical).collect();
    let mut b: Vec<[u32; 3]> = boundary_faces(tets).iter().map(canonical).collect();
    a.sort_unstable();
    b.sort_unstable();
    a == b
}

/// For each of `n` particles, the indices of the items (triangles, springs) that hold it.
fn incidence<const N: usize>(items: &[[u32; N]], n: usize) -> Vec<Vec<usize>> {
    let mut of: Vec<Vec<usize>> = vec![vec![]; n];
    for (k, item) in items.iter().enumerate() {
        for &c in item {
            if let Some(l) = of.get_mut(c as usize) {
                l.push(k);
            }
        }
    }
    of
}

fn area(x: &[Vector], t: &[u32; 3]) -> f64 {
    let [a, b, c] = t.map(|i| x[i as usize]);
    0.5 * (b - a).cross(c - a).length() as f64
}

/// The springs of [`overstretched`]'s list, most strained first (ties: lower index first).
pub fn by_strain(over: &[(usize, f64)]) -> Vec<usize> {
    let mut o = over.to_vec();
    o.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    o.into_iter().map(|(k, _)| k).collect()
}

/// A body's connectivity as tearing changes it: its springs' ends and its surface triangles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TearMesh {
    /// Each spring's ends (springs a tear adds are appended).
    pub springs: Vec<[u32; 2]>,
    /// Surface triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Tets' corners (empty: a body without tets).
    pub tets: Vec<[u32; 4]>,
    /// For each spring added by the running tear, the spring it copies.
    source: Vec<usize>,
}

impl TearMesh {
    /// A body's springs (their ends) and surface triangles.
    pub fn new(springs: Vec<[u32; 2]>, triangles: Vec<[u32; 3]>) -> Self {
        Self {
            springs,
            triangles,
            tets: vec![],
            source: vec![],
        }
    }

    /// The same with the body's tets (their corners).
    pub fn with_tets(mut self, tets: Vec<[u32; 4]>) -> Self {
        self.tets = tets;
        self
    }

    /// Tears at the springs `broken` (indices into [`TearMesh::springs`] of springs past the
    /// limit, most strained first) at positions `x` (see the module docs).
    /// Appends the copies' masses to `mass` (taking them from their originals) and renumbers
    /// the triangles and spring ends in place. Broken springs stay in the list (the caller
    /// drops the ones named in the result), so spring indices stay valid.
    pub fn tear(&mut self, broken: &[usize], x: &[Vector], mass: &mut Vec<f64>) -> Torn {
        self.tear_with_tets(broken, &[], x, mass)
    }

    /// [`TearMesh::tear`], and then the tets `broken_tets` (indices into [`TearMesh::tets`]
    /// of tets past the limit, most strained first, each with the direction of its largest
    /// stretch: [`tets_by_strain`]): each splits off at a corner (see the module docs), or is
    /// named in [`Torn::tets_removed`] when none of its corners can be split. Removed tets
    /// stay in the list, as broken springs do. When the triangles are the tets' boundary
    /// ([`is_boundary_of`]), they become the boundary of the tets left, crack faces and all.
    pub fn tear_with_tets(
        &mut self,
        broken: &[usize],
        broken_tets: &[(usize, Vector)],
        x: &[Vector],
        mass: &mut Vec<f64>,
    ) -> Torn {
        let mut torn = Torn::default();
        let boundary = !self.tets.is_empty() && is_boundary_of(&self.triangles, &self.tets);
        let mut x = x.to_vec();
        // Triangles and springs at each particle.
        let mut vt = incidence(&self.triangles, x.len());
        let mut at = incidence(&self.springs, x.len());
        let n0 = self.springs.len();
        self.source = (0..n0).collect();
        let mut removed = vec![false; self.springs.len()];
        let mut dead = vec![false; self.triangles.len()];
        for &k in broken {
            if k >= self.springs.len() || removed[k] {
                continue;
            }
            torn.over.push(k);
            let [a, b] = self.springs[k];
            // In a body of tets the tets carry the surface: its springs just break.
            let on_surface = self.tets.is_empty()
                && vt
                    .get(a as usize)
                    .is_some_and(|l| l.iter().any(|&t| self.triangles[t].contains(&b)));
            if on_surface {
                let (v, w) = if vt[b as usize].len() > vt[a as usize].len() {
                    (b, a)
                } else {
                    (a, b)
                };
                // Split one end (or, when all its triangles lie on one side, the other): the
                // edge goes with the far side, and its spring with it, no longer stretched
                // once the copy is free to move.
                if self.split(
                    v,
                    w,
                    &mut x,
                    mass,
                    &mut vt,
                    &mut at,
                    &mut removed,
                    &mut torn,
                ) || self.split(
                    w,
                    v,
                    &mut x,
                    mass,
                    &mut vt,
                    &mut at,
                    &mut removed,
                    &mut torn,
                ) {
                    continue;
                }
                // Neither end can be split: the spring breaks and the triangles on its edge
                // go (a small hole rather than a triangle that no spring holds).
                let [a, b] = self.springs[k];
                let on_edge: Vec<usize> = vt[a as usize]
                    .iter()
                    .copied()
                    .filter(|&t| self.triangles[t].contains(&b))
                    .collect();
                for t in on_edge {
                    dead[t] = true;
                    for c in self.triangles[t] {
                        vt[c as usize].retain(|&u| u != t);
                    }
                }
            }
            removed[k] = true;
            torn.broken.push(k);
        }
        let mut vtet = incidence(&self.tets, x.len());
        let mut gone = vec![false; self.tets.len()];
        let mut seen = vec![false; self.tets.len()];
        let mut touched = vec![];
        // Particles split by this tear: a tet with a corner among them has been reached by
        // the crack since its strain was measured, and waits for the next check.
        let mut cracked = vec![false; x.len()];
        for &(k, dir) in broken_tets {
            if k >= self.tets.len() || seen[k] {
                continue;
            }
            seen[k] = true;
            torn.tets_over.push(k);
            if self.tets[k]
                .iter()
                .any(|&c| cracked.get(c as usize).copied().unwrap_or(true))
            {
                continue;
            }
            // Its corners from the lowest along the stretch, the direction's sign made the same
            // for every tet (its largest component positive): tets stretched alike split at
            // their corners on the same side, so a crack across a layer of tets stays in one
            // plane of corners instead of zigzagging through the layer. Ties: the corner in
            // more tets first (inside the body before its rim).
            let dir = if dir.abs().max_element() == dir.x.abs() {
                dir * dir.x.signum()
            } else if dir.abs().max_element() == dir.y.abs() {
                dir * dir.y.signum()
            } else {
                dir * dir.z.signum()
            };
            let mut corners = self.tets[k];
            corners.sort_by(|&a, &b| {
                let (pa, pb) = (x[a as usize].dot(dir), x[b as usize].dot(dir));
                pa.total_cmp(&pb)
                    .then(vtet[b as usize].len().cmp(&vtet[a as usize].len()))
            });
            let split = corners.into_iter().find(|&c| {
                self.split_tet(
                    c,
                    k,
                    dir,
                    &mut x,
                    mass,
                    &mut vt,
                    &mut at,
                    &mut vtet,
                    &mut removed,
                    &mut touched,
                    &mut torn,
                )
            });
            if let Some(c) = split {
                cracked[c as usize] = true;
                cracked.resize(x.len(), true);
            } else {
                gone[k] = true;
                for c in self.tets[k] {
                    vtet[c as usize].retain(|&u| u != k);
                }
                torn.tets_removed.push(k);
            }
        }
        torn.tets_over.sort_unstable();
        torn.tets_removed.sort_unstable();
        touched.sort_unstable();
        touched.dedup();
        torn.tets_moved = touched
            .into_iter()
            .filter(|&t| !gone[t])
            .map(|t| (t, self.tets[t]))
            .collect();
        if boundary {
            let left: Vec<[u32; 4]> = (self.tets.iter().zip(&gone))
                .filter(|(_, g)| !**g)
                .map(|(t, _)| *t)
                .collect();
            self.triangles = boundary_faces(&left);
        }
        if dead.iter().any(|&d| d) {
            let mut k = 0;
            self.triangles.retain(|_| {
                k += 1;
                !dead[k - 1]
            });
        }
        torn.broken.sort_unstable();
        torn.over.sort_unstable();
        torn.moved.sort_by_key(|m| m.0);
        // A spring moved twice: its last ends.
        let mut last: Vec<(usize, [u32; 2])> = vec![];
        for m in torn.moved.drain(..) {
            match last.last_mut() {
                Some(l) if l.0 == m.0 => *l = (m.0, self.springs[m.0]),
                _ => last.push((m.0, self.springs[m.0])),
            }
        }
        torn.moved = last
            .into_iter()
            .filter(|(k, _)| *k < n0 && !removed[*k])
            .collect();
        torn.added = (n0..self.springs.len())
            .filter(|&k| !removed[k])
            .map(|k| (self.source[k], self.springs[k]))
            .collect();
        self.source.clear();
        torn
    }

    /// Splits vertex `v` by the plane through it square to the broken edge to `w` (see the
    /// module docs); the triangles holding the edge go with `w`. False when all of `v`'s
    /// triangles lie on one side (nothing to split).
    #[allow(clippy::too_many_arguments)]
    fn split(
        &mut self,
        v: u32,
        w: u32,
        x: &mut Vec<Vector>,
        mass: &mut Vec<f64>,
        vt: &mut Vec<Vec<usize>>,
        at: &mut Vec<Vec<usize>>,
        removed: &mut Vec<bool>,
        torn: &mut Torn,
    ) -> bool {
        let xv = x[v as usize];
        let d = x[w as usize] - xv;
        let far_side = |p: Vector| (p - xv).dot(d) > 0.0;
        let (far, near): (Vec<usize>, Vec<usize>) = vt[v as usize].iter().partition(|&&t| {
            let tri = self.triangles[t];
            let c = tri.map(|i| x[i as usize]);
            tri.contains(&w) || far_side((c[0] + c[1] + c[2]) / 3.0)
        });
        if far.is_empty() || near.is_empty() {
            return false;
        }
        let a_far: f64 = far.iter().map(|&t| area(x, &self.triangles[t])).sum();
        let a_near: f64 = near.iter().map(|&t| area(x, &self.triangles[t])).sum();
        let inward = [&near, &far]
            .map(|side| (middle(&self.triangles, side, v, x) - xv).normalize_or_zero());
        let new = add_copy(v, [a_far, a_near], inward, x, mass, torn);
        renumber(&mut self.triangles, &far, v, new);
        vt[v as usize] = near;
        vt.push(far);
        let tris = &self.triangles;
        let (near, far) = (&vt[v as usize], &vt[new as usize]);
        move_springs(
            &mut self.springs,
            &mut self.source,
            [v, new],
            |o| far.iter().any(|&t| tris[t].contains(&o)),
            |o| near.iter().any(|&t| tris[t].contains(&o)),
            |o| far_side(x[o as usize]),
            at,
            removed,
            torn,
        );
        true
    }

    /// Splits corner `v` of the broken tet `k` by the plane through it square to the
    /// direction `dir` of the tet's largest stretch: the tets at `v` whose centres lie on
    /// `k`'s side of the plane (`k` among them) go to a copy of `v`, the others stay. False
    /// when they all lie on one side (nothing to split). Surface triangles at `v` go by the
    /// side of their centres, springs as in [`TearMesh::split`].
    #[allow(clippy::too_many_arguments)]
    fn split_tet(
        &mut self,
        v: u32,
        k: usize,
        dir: Vector,
        x: &mut Vec<Vector>,
        mass: &mut Vec<f64>,
        vt: &mut Vec<Vec<usize>>,
        at: &mut Vec<Vec<usize>>,
        vtet: &mut Vec<Vec<usize>>,
        removed: &mut Vec<bool>,
        touched: &mut Vec<usize>,
        torn: &mut Torn,
    ) -> bool {
        let xv = x[v as usize];
        let mean =
            |c: &[u32]| c.iter().map(|&i| x[i as usize]).sum::<Vector>() / c.len().max(1) as Scalar;
        let sign = (mean(&self.tets[k]) - xv).dot(dir);
        if sign == 0.0 || !sign.is_finite() {
            return false;
        }
        let far_side = move |p: Vector| (p - xv).dot(dir) * sign > 0.0;
        let (far, near): (Vec<usize>, Vec<usize>) = vtet[v as usize]
            .iter()
            .partition(|&&t| t == k || far_side(mean(&self.tets[t])));
        if far.is_empty() || near.is_empty() {
            return false;
        }
        let volume = |t: &usize| {
            signed_volume(self.tets[*t].map(|i| DVec3::from_array(x[i as usize].to_f64()))).abs()
        };
        let v_far: f64 = far.iter().map(volume).sum();
        let v_near: f64 = near.iter().map(volume).sum();
        let inward =
            [&near, &far].map(|side| (middle(&self.tets, side, v, x) - xv).normalize_or_zero());
        let (tri_far, tri_near): (Vec<usize>, Vec<usize>) = vt[v as usize]
            .iter()
            .partition(|&&t| far_side(mean(&self.triangles[t])));
        let new = add_copy(v, [v_far, v_near], inward, x, mass, torn);
        renumber(&mut self.tets, &far, v, new);
        touched.extend_from_slice(&far);
        renumber(&mut self.triangles, &tri_far, v, new);
        vtet[v as usize] = near;
        vtet.push(far);
        vt[v as usize] = tri_near;
        vt.push(tri_far);
        let tets = &self.tets;
        let (near, far) = (&vtet[v as usize], &vtet[new as usize]);
        move_springs(
            &mut self.springs,
            &mut self.source,
            [v, new],
            |o| far.iter().any(|&t| tets[t].contains(&o)),
            |o| near.iter().any(|&t| tets[t].contains(&o)),
            |o| far_side(x[o as usize]),
            at,
            removed,
            torn,
        );
        true
    }
}

/// The mean of the corners other than `v` of the items `ids` (a side's triangles or tets
/// around `v`): the middle of that side, seen from `v`.
fn middle<const N: usize>(items: &[[u32; N]], ids: &[usize], v: u32, x: &[Vector]) -> Vector {
    let mut sum = Vector::ZERO;
    for &t in ids {
        for c in items[t] {
            if c != v {
                sum += x[c as usize];
            }
        }
    }
    sum / ((N - 1) * ids.len()).max(1) as Scalar
}

/// Splits particle `v`: appends a copy at its position with the far side's share of its mass
/// (`far / (far + near)` of the sides' areas or volumes), recorded in `torn` with each side's
/// inward direction (`[near, far]`). Returns the copy's index.
fn add_copy(
    v: u32,
    [far, near]: [f64; 2],
    inward: [Vector; 2],
    x: &mut Vec<Vector>,
    mass: &mut Vec<f64>,
    torn: &mut Torn,
) -> u32 {
    // Clamped to a quarter to three quarters: a sliver's tiny lumped mass on the same springs
    // would raise the fastest frequency 2√(k/m) past what the body's step can carry
    // (measured: a 1e-3 share made a torn flap blow up under symplectic Euler).
    let share = if far + near > 0.0 {
        (far / (far + near)).clamp(MIN_SHARE, 1.0 - MIN_SHARE)
    } else {
        0.5
    };
    let m0 = mass[v as usize];
    let new = mass.len() as u32;
    mass.push(m0 * share);
    mass[v as usize] = m0 * (1.0 - share);
    x.push(x[v as usize]);
    torn.copies.push((v, m0 * share));
    torn.inward.push((v, inward[0]));
    torn.inward.push((new, inward[1]));
    new
}

/// Replaces `v` by `new` in the items `ids`.
fn renumber<const N: usize>(items: &mut [[u32; N]], ids: &[usize], v: u32, new: u32) {
    for &t in ids {
        for c in &mut items[t] {
            if *c == v {
                *c = new;
            }
        }
    }
}

/// Moves the springs at `v` to its copy `new` when their other end lies with the copy's
/// side only (`with_far` and not `with_near`: an edge of the elements that went there), or
/// with neither side's elements and on the far side of the plane (`far_side`). An edge with
/// elements on both sides lies on the cut: its spring stays, and the far side gets a spring
/// of its own along its copy of the edge.
#[allow(clippy::too_many_arguments)]
fn move_springs(
    springs: &mut Vec<[u32; 2]>,
    source: &mut Vec<usize>,
    [v, new]: [u32; 2],
    with_far: impl Fn(u32) -> bool,
    with_near: impl Fn(u32) -> bool,
    far_side: impl Fn(u32) -> bool,
    at: &mut Vec<Vec<usize>>,
    removed: &mut Vec<bool>,
    torn: &mut Torn,
) {
    let mut mine = vec![];
    let mut cut_edges = vec![];
    at[v as usize].retain(|&k| {
        let [a, b] = springs[k];
        let other = if a == v { b } else { a };
        if removed[k] {
            return true;
        }
        let moves = match (with_far(other), with_near(other)) {
            (true, false) => true,
            (true, true) => {
                cut_edges.push((k, other));
                false
            }
            (false, true) => false,
            (false, false) => far_side(other),
        };
        if !moves {
            return true;
        }
        springs[k] = if a == v { [new, b] } else { [a, new] };
        torn.moved.push((k, springs[k]));
        mine.push(k);
        false
    });
    for (k, other) in cut_edges {
        let added = springs.len();
        springs.push([new, other]);
        source.push(source.get(k).copied().unwrap_or(k));
        removed.push(false);
        at[other as usize].push(added);
        mine.push(added);
    }
    at.push(mine);
}

/// Extends a surface's record of which particle each was torn from (`torn_from`; empty:
/// nothing torn yet) over its `n` particles before a tear and the tear's `copies` after them,
/// each copy torn from what its parent was torn from.
pub fn record_copies(torn_from: &mut Vec<u32>, n: usize, copies: &[(u32, f64)]) {
    torn_from.truncate(n);
    let from = torn_from.len() as u32;
    torn_from.extend(from..n as u32);
    for &(parent, _) in copies {
        let root = torn_from[parent as usize];
        torn_from.push(root);
    }
}

/// Moves each split particle and its copy `gap / 2` into their own sides ([`Torn::inward`]),
/// for a surface that collides with itself: its contact passes need every pair of features
/// apart at the start of a pass, and a cut's two sides start coincident (distance zero, no
/// normal between them). Into its own side, towards the middle of the triangles it keeps,
/// each stays inside its own fan, so no edge of one side crosses one of the other (parting
/// them along the broken edge instead can: a triangle is given to a side by its centre, and
/// its corners may lie across the plane).
/// Particles for which `held` is true (pinned, or on a prescribed path) are not moved.
pub fn part_copies(torn: &Torn, x: &mut [Vector], gap: f64, held: impl Fn(usize) -> bool) {
    for &(i, dir) in &torn.inward {
        if held(i as usize) {
            continue;
        }
        if let Some(p) = x.get_mut(i as usize) {
            *p += dir * (0.5 * gap) as Scalar;
        }
    }
}

/// Tears a scene's body after a frame of `sim` (made from the scene): the springs and tets
/// over the scene's [`Scene::tearing`] limit break, the surface tears along them, and — when
/// anything changed — the scene takes the state's positions and velocities, the new
/// particles, springs, tets and triangles (the springs' rest lengths and the tets' rest
/// shapes written out, so the new positions do not become them), and `sim` is rebuilt from it
/// at the same time (its [`Simulation::replace`]). Returns what changed, in the scene's
/// numbering before the call (spring and tet indices) and after it (new particles are
/// appended in order).
pub fn tear_scene(
    scene: &mut Scene,
    sim: &mut Simulation<ParticleState, ParticleModel>,
) -> Result<Torn, SceneError> {
    let Some(params) = scene.tearing else {
        return Ok(Torn::default());
    };
    let rest: Vec<f64> = (0..scene.springs.len())
        .map(|k| scene.rest_length(k))
        .collect();
    let broken = overstretched(
        scene
            .springs
            .iter()
            .zip(&rest)
            .map(|(s, &l)| ([s.a as u32, s.b as u32], l as Scalar)),
        &sim.state.x,
        params.max_strain,
    );
    let tet_rest: Vec<[DVec3; 4]> = (0..scene.tets.len()).map(|k| scene.tet_rest(k)).collect();
    let tet_corners: Vec<[u32; 4]> = scene
        .tets
        .iter()
        .map(|t| t.vertices.map(|i| i as u32))
        .collect();
    // A tet whose rest shape has no volume never ran (the scene was refused): skipped.
    let shapes: Vec<Option<RestShape>> = tet_rest.iter().map(|&r| RestShape::new(r)).collect();
    let mut broken_tets = overstrained_tets(
        tet_corners
            .iter()
            .zip(&shapes)
            .filter_map(|(&c, s)| s.as_ref().map(|s| (c, s))),
        &sim.state.x,
        params.max_strain,
    );
    // Back to the scene's numbering when some tet was skipped.
    if shapes.iter().any(Option::is_none) {
        let valid: Vec<usize> = (0..shapes.len()).filter(|&k| shapes[k].is_some()).collect();
        for b in &mut broken_tets {
            b.0 = valid[b.0];
        }
    }
    if broken.is_empty() && broken_tets.is_empty() {
        return Ok(Torn::default());
    }
    // Rest lengths and shapes fixed before the positions move to the current state.
    for (sp, l) in scene.springs.iter_mut().zip(&rest) {
        sp.rest_length = Some(*l);
    }
    for (t, r) in scene.tets.iter_mut().zip(&tet_rest) {
        t.rest = Some(r.map(|p| p.to_array()));
    }
    let mut mesh = TearMesh::new(
        scene
            .springs
            .iter()
            .map(|s| [s.a as u32, s.b as u32])
            .collect(),
        scene
            .surface
            .as_ref()
            .map_or(vec![], |s| s.triangles.clone()),
    )
    .with_tets(tet_corners);
    let mut mass: Vec<f64> = scene.particles.iter().map(|p| p.mass).collect();
    let torn = mesh.tear_with_tets(
        &by_strain(&broken),
        &tets_by_strain(&broken_tets),
        &sim.state.x,
        &mut mass,
    );
    for (i, p) in scene.particles.iter_mut().enumerate() {
        p.position = sim.state.x[i].to_f64();
        p.velocity = sim.state.v[i].to_f64();
        p.mass = mass[i];
    }
    let n_before = scene.particles.len();
    for &(parent, m) in &torn.copies {
        let mut q = scene.particles[parent as usize].clone();
        q.mass = m;
        let new = scene.particles.len();
        scene.particles.push(q);
        let copied: Vec<_> = scene
            .motions
            .iter()
            .filter(|d| d.particle == parent as usize)
            .cloned()
            .collect();
        for mut d in copied {
            d.particle = new;
            scene.motions.push(d);
        }
        if let Some(s) = &mut scene.surface
            && !s.uvs.is_empty()
        {
            let uv = s.uvs[parent as usize];
            s.uvs.push(uv);
        }
    }
    if let Some(s) = &mut scene.surface {
        record_copies(&mut s.torn_from, n_before, &torn.copies);
    }
    if let Some(sc) = scene.self_collision
        && !torn.copies.is_empty()
    {
        let mut x: Vec<Vector> = scene
            .particles
            .iter()
            .map(|p| p.position.to_scalar())
            .collect();
        let held =
            |i: usize| scene.particles[i].pinned || scene.motions.iter().any(|m| m.particle == i);
        part_copies(&torn, &mut x, sc.thickness, held);
        for (p, x) in scene.particles.iter_mut().zip(&x) {
            p.position = x.to_f64();
        }
    }
    for (k, [a, b]) in &torn.moved {
        scene.springs[*k].a = *a as usize;
        scene.springs[*k].b = *b as usize;
    }
    let n_springs = scene.springs.len();
    for &(k, [a, b]) in &torn.added {
        // Each side keeps one of the edge's two triangles: each spring takes half of the
        // edge's stiffness and damping, so the split stores no energy the edge did not.
        let sp = &mut scene.springs[k];
        sp.stiffness *= 0.5;
        sp.damping *= 0.5;
        let mut sp = sp.clone();
        sp.a = a as usize;
        sp.b = b as usize;
        scene.springs.push(sp);
    }
    let mut k = 0;
    scene.springs.retain(|_| {
        k += 1;
        k > n_springs || torn.broken.binary_search(&(k - 1)).is_err()
    });
    for &(k, corners) in &torn.tets_moved {
        scene.tets[k].vertices = corners.map(|i| i as usize);
    }
    let mut k = 0;
    scene.tets.retain(|_| {
        k += 1;
        torn.tets_removed.binary_search(&(k - 1)).is_err()
    });
    if let Some(s) = &mut scene.surface {
        s.triangles = mesh.triangles;
    }
    let (model, state) = scene.build()?;
    sim.replace(model, state);
    Ok(torn)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, EulerRot};

    /// `F = R diag(s) Qᵀ` (a stretch along `Q`'s axes, then a rotation): its largest stretch is
    /// the largest `|s|`, and the direction returned is a unit eigenvector of `F Fᵀ` for it
    /// (along `R`'s column of that `s` when it is the only one), whether the stretches are
    /// distinct, repeated, all equal, zero or reflected.
    #[test]
    fn the_largest_stretch_is_the_largest_singular_value() {
        let q = DMat3::from_quat(DQuat::from_euler(EulerRot::XYZ, 0.3, -1.1, 0.7));
        let r = DMat3::from_quat(DQuat::from_euler(EulerRot::XYZ, 2.0, 0.4, -0.5));
        let mut cases = vec![
            (r, [1.5, 0.8, 1.1], q),
            (r, [0.9, 0.9, 2.0], q),
            (r, [1.2, 1.2, 1.2], q),
            (r, [1.3, 1.3, 0.5], q),
            (r, [0.0, 0.5, 0.2], q),
            (r, [-1.4, 0.7, 1.0], q),
            (r, [1.0 + 1e-9, 1.0, 1.0], q),
        ];
        // And 200 random ones (a fixed linear congruential sequence).
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..200 {
            let mut rot = || {
                DMat3::from_quat(DQuat::from_euler(
                    EulerRot::XYZ,
                    6.3 * next(),
                    6.3 * next(),
                    6.3 * next(),
                ))
            };
            let (a, b) = (rot(), rot());
            cases.push((a, [3.0 * next() - 1.0, 2.0 * next(), 2.0 * next()], b));
        }
        for (r, s, q) in cases {
            let f = r * DMat3::from_diagonal(DVec3::from_array(s)) * q.transpose();
            let (stretch, d) = largest_stretch(&f);
            let abs = s.map(f64::abs);
            let top = abs.iter().copied().fold(0.0, f64::max);
            assert!((stretch - top).abs() < 1e-12, "{s:?}: {stretch}");
            assert!((d.length() - 1.0).abs() < 1e-12, "{s:?}: {d}");
            let residual = f * (f.transpose() * d) - d * (top * top);
            assert!(residual.length() < 1e-9, "{s:?}: residual {residual}");
            let tied = abs.iter().filter(|&&a| top - a < 1e-6).count();
            if tied == 1 {
                let i = (0..3).find(|&i| abs[i] == top).unwrap();
                assert!((d.dot(r.col(i)).abs() - 1.0).abs() < 1e-9, "{s:?}: {d}");
            }
        }
    }
}
