//! Tearing: springs stretched past a strain limit break, and the surface tears along them.
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
//! Tearing is checked once per frame (a frame is the unit in which a body's layout changes);
//! a spring pulled fast can overshoot the limit within the frame by its strain rate times the
//! frame's length.

use crate::core::driver::Simulation;
use crate::core::ode::ParticleState;
use crate::core::particles::ParticleModel;
use crate::core::scene::{Scene, SceneError};
use crate::math::{Scalar, ToScalar, Vector, VectorExt};
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
}

impl Torn {
    /// Nothing changed.
    pub fn is_empty(&self) -> bool {
        self.over.is_empty()
    }
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
    /// For each spring added by the running tear, the spring it copies.
    source: Vec<usize>,
}

impl TearMesh {
    /// A body's springs (their ends) and surface triangles.
    pub fn new(springs: Vec<[u32; 2]>, triangles: Vec<[u32; 3]>) -> Self {
        Self {
            springs,
            triangles,
            source: vec![],
        }
    }

    /// Tears at the springs `broken` (indices into [`TearMesh::springs`] of springs past the
    /// limit, most strained first) at positions `x` (see the module docs).
    /// Appends the copies' masses to `mass` (taking them from their originals) and renumbers
    /// the triangles and spring ends in place. Broken springs stay in the list (the caller
    /// drops the ones named in the result), so spring indices stay valid.
    pub fn tear(&mut self, broken: &[usize], x: &[Vector], mass: &mut Vec<f64>) -> Torn {
        let mut torn = Torn::default();
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
            let on_surface = vt
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
        // Clamped to a quarter to three quarters: a sliver's tiny lumped mass on the same
        // springs would raise the fastest frequency 2√(k/m) past what the body's step can
        // carry (measured: a 1e-3 share made a torn flap blow up under symplectic Euler).
        let share = if a_far + a_near > 0.0 {
            (a_far / (a_far + a_near)).clamp(MIN_SHARE, 1.0 - MIN_SHARE)
        } else {
            0.5
        };
        let m0 = mass[v as usize];
        let new = mass.len() as u32;
        mass.push(m0 * share);
        mass[v as usize] = m0 * (1.0 - share);
        x.push(xv);
        torn.copies.push((v, m0 * share));
        // Each side's middle: the mean of its triangles' other corners.
        let middle = |tris: &[usize]| {
            let mut sum = Vector::ZERO;
            for &t in tris {
                for c in self.triangles[t] {
                    if c != v {
                        sum += x[c as usize];
                    }
                }
            }
            sum / (2 * tris.len()).max(1) as Scalar
        };
        torn.inward
            .push((v, (middle(&near) - xv).normalize_or_zero()));
        torn.inward
            .push((new, (middle(&far) - xv).normalize_or_zero()));
        for &t in &far {
            for c in &mut self.triangles[t] {
                if *c == v {
                    *c = new;
                }
            }
        }
        vt[v as usize] = near;
        vt.push(far);
        let mut mine = vec![];
        let mut cut_edges = vec![];
        let tris = &self.triangles;
        let (near, far) = (&vt[v as usize], &vt[new as usize]);
        at[v as usize].retain(|&k| {
            let [a, b] = self.springs[k];
            let other = if a == v { b } else { a };
            // An edge of the fan goes where all its triangles went; an edge with triangles on
            // both sides lies on the cut: it stays, and the far side gets a spring of its own
            // along its copy of the edge. Any other spring goes by its far end's side.
            let with_far = far.iter().any(|&t| tris[t].contains(&other));
            let with_near = near.iter().any(|&t| tris[t].contains(&other));
            if removed[k] {
                return true;
            }
            let moves = match (with_far, with_near) {
                (true, false) => true,
                (true, true) => {
                    cut_edges.push((k, other));
                    false
                }
                (false, true) => false,
                (false, false) => far_side(x[other as usize]),
            };
            if !moves {
                return true;
            }
            self.springs[k] = if a == v { [new, b] } else { [a, new] };
            torn.moved.push((k, self.springs[k]));
            mine.push(k);
            false
        });
        for (k, other) in cut_edges {
            let added = self.springs.len();
            self.springs.push([new, other]);
            self.source.push(self.source.get(k).copied().unwrap_or(k));
            removed.push(false);
            at[other as usize].push(added);
            mine.push(added);
        }
        at.push(mine);
        true
    }
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

/// Tears a scene's body after a frame of `sim` (made from the scene): the springs over the
/// scene's [`Scene::tearing`] limit break, the surface tears along them, and — when anything
/// changed — the scene takes the state's positions and velocities, the new particles and
/// the new springs and triangles, and `sim` is rebuilt from it at the same time (its
/// [`Simulation::replace`]). Returns what changed, in the scene's numbering before the
/// call (spring indices) and after it (new particles are appended in order).
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
    if broken.is_empty() {
        return Ok(Torn::default());
    }
    // Rest lengths fixed before the positions move to the current state.
    for (sp, l) in scene.springs.iter_mut().zip(&rest) {
        sp.rest_length = Some(*l);
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
    );
    let mut mass: Vec<f64> = scene.particles.iter().map(|p| p.mass).collect();
    let torn = mesh.tear(&by_strain(&broken), &sim.state.x, &mut mass);
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
        let mut sp = scene.springs[k].clone();
        sp.a = a as usize;
        sp.b = b as usize;
        scene.springs.push(sp);
    }
    let mut k = 0;
    scene.springs.retain(|_| {
        k += 1;
        k > n_springs || torn.broken.binary_search(&(k - 1)).is_err()
    });
    if let Some(s) = &mut scene.surface {
        s.triangles = mesh.triangles;
    }
    let (model, state) = scene.build()?;
    sim.replace(model, state);
    Ok(torn)
}
