//! Contact of a surface with itself (and, for surfaces of several bodies put together, with
//! each other): the method of Bridson, Fedkiw and Anderson, *Robust treatment of collisions,
//! contact and friction for cloth animation* (SIGGRAPH 2002).
//!
//! A pass looks at the motion since the last pass: every surface vertex moves along a
//! straight line from its start `x₀` to its candidate end `x₁` (what the integrator produced)
//! at the average velocity `u = (x₁ − x₀)/τ`. Given a start free of intersections, the pass
//! changes `u` so that the motion is free of them too, in four stages:
//!
//! 1. **Proximity**: point–triangle and edge–edge pairs closer than [`PROXIMITY`] thicknesses
//!    at the start stop approaching: an inelastic impulse with the pair's effective mass, and
//!    Coulomb friction limited by it (`|Δv_t| ≤ μ |Δv_n|`), in Gauss–Seidel sweeps of
//!    sequential impulses (the impulses of a pair accumulated over the pass: it only ever
//!    pushes, its friction stays within μ times its push, and a pair that other pairs'
//!    impulses leave separating faster than the step made it gives back its own push) until
//!    no pair's motion changes by more than [`SEPARATION_SLACK`] thicknesses over the pass:
//!    a layer stopped against the one below pushes that one on, and a stack rests;
//! 2. **Separation**: pairs closer than the thickness at the end are pushed apart in position
//!    only (the velocity is not changed, so the push adds no kinetic energy), in
//!    Gauss–Seidel sweeps (a layer pushed off another pushes the one above it);
//! 3. **Continuous detection**: for each pair, the times at which its four points are
//!    coplanar (roots of a cubic in the pass's time) are checked for contact; a collision
//!    gets an inelastic impulse at that instant and a separation of a tenth of the thickness
//!    in position; repeated in Gauss–Seidel sweeps. Separation and detection alternate in
//!    rounds until neither changes anything ([`SEPARATION_ROUNDS`]): a collision leaves its
//!    pair a tenth of a thickness apart, and a push can end a path that crossed on the
//!    right side, so a pass whose paths are long (a frame-long implicit step) still ends
//!    with its pairs a thickness apart. After the first sweep, a sweep looks only at the
//!    pairs whose particles' paths changed since the last sweep of its kind;
//! 4. **Rigid impact zones**, the fail-safe: vertices of pairs still colliding after the
//!    sweeps are merged into zones (zones sharing a vertex merge), and each zone moves as a
//!    rigid body with its linear and angular momentum, until no pair collides. A rigid motion
//!    of an intersection-free zone keeps it intersection-free, so this ends; if it has not
//!    within its budget, every free surface vertex stays at its start (which was free of
//!    intersections), and the pass reports the failure.
//!
//! The end velocities take their own inelastic impulses along the same normals (and each
//! zone's rigid part), not the change made to `u`: a pair whose end velocities already
//! separate is left alone, so a pass never adds kinetic energy. Pinned and prescribed
//! particles (inverse mass zero) are never moved; particles resting on a collider count
//! [`SUPPORT_MASS`] times heavier.
//!
//! Passes run when the candidate pairs (what the last search found) may have come
//! [`PASS_TRAVEL`] thicknesses closer since the last one (more, for pairs that were farther
//! than the proximity band), when a vertex has left the box the last search gave it, and at
//! the end of every frame (the collision step spans the internal dynamics' steps, as in
//! Bridson et al.), so each pass sees the pairs that can touch make short motions, parts
//! of the surface far from each other need no pass however fast they move, and every frame
//! ends free of intersections. The geometry is computed in `f64` whatever [`Scalar`] is. The
//! broad phase is a bounding-volume hierarchy of swept boxes with normal-cone culling of flat
//! patches (`tree`); its candidate pairs are kept across passes while every vertex stays near
//! the motion it had at the search, relative to the surface's mean (a Verlet list along the
//! motion: see [`AHEAD`]), and the patches it culled stay flat. When a pass outlasts that
//! horizon (frame-long steps), a few vertices its own impulses take out of their tubes get
//! new ones, and only their pairs are looked for again ([`SHORT_GROW`], [`AROUND_SHARE`]).
//! On a team of threads, a whole search's walk is cut into pieces that the threads take as
//! they come, each measuring and keeping its pairs as it finds them; the pieces' outputs
//! are joined in the walk's own order, so the candidates are the same on any number of
//! threads (see `Ctx::walk_and_keep`).

mod distance;
mod tree;

use crate::core::kernels::{SharedMut, current_threads, for_each_chunk, for_each_range};
use crate::math::{Scalar, ToScalar, Vector};
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::time::{Duration, Instant};
use tree::{Found, SurfaceTree, Visit};

/// Settings of a surface's contact with itself and with other such surfaces.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SelfContactParams {
    /// The surface's thickness (m): pairs closer than this repel. Must be positive and less
    /// than half the shortest surface edge at rest (see [`SelfContactParams::validate`]).
    pub thickness: f64,
    /// Coulomb friction coefficient between touching parts of the surface.
    #[serde(default)]
    pub friction: f64,
}

impl Default for SelfContactParams {
    fn default() -> Self {
        Self {
            thickness: 0.005,
            friction: 0.3,
        }
    }
}

/// The largest thickness, as a fraction of the shortest surface edge at rest. A vertex of a
/// flat triangulated sheet is `1/√2` of an edge from the diagonal of the square next to it;
/// a thickness above half an edge would make the sheet at rest repel itself.
pub const MAX_THICKNESS_PER_EDGE: f64 = 0.5;

impl SelfContactParams {
    /// Checks the numbers against the surface's shortest rest edge (`None` when there is no
    /// surface); the problem as `(field, message)`.
    pub fn validate(&self, shortest_edge: Option<f64>) -> Result<(), (&'static str, String)> {
        let t = self.thickness;
        if !(t.is_finite() && t > 0.0) {
            return Err(("thickness", format!("{t} must be a positive number")));
        }
        if !(self.friction.is_finite() && self.friction >= 0.0) {
            return Err((
                "friction",
                format!("{} must be a non-negative number", self.friction),
            ));
        }
        match shortest_edge {
            None => Err((
                "thickness",
                "the body has no surface (triangles) to collide".to_string(),
            )),
            Some(e) if t >= MAX_THICKNESS_PER_EDGE * e => Err((
                "thickness",
                format!(
                    "{t} m is too large for the surface's shortest edge ({e:.4} m): it must be less than half of it ({:.4} m)",
                    MAX_THICKNESS_PER_EDGE * e
                ),
            )),
            Some(_) => Ok(()),
        }
    }
}

/// The triangles of a surface with the edges and vertices derived from them, and where it
/// was torn.
///
/// Features that share a particle are adjacent and never collide. A torn surface records,
/// for each particle, the particle it was split from (`origin`): the broad phase never culls
/// a flat patch that reaches a cut (see `tree`), since a cut's two sides can slide over each
/// other, or the material around its end swing shut, with no stretch.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ContactSurface {
    /// Triangles (particle indices).
    pub triangles: Vec<[u32; 3]>,
    /// Unique edges, each with the smaller index first.
    pub edges: Vec<[u32; 2]>,
    /// Particles on the surface, ascending.
    pub vertices: Vec<u32>,
    /// For each particle up to the largest surface index, the particle it was torn from
    /// (itself if never split).
    pub origin: Vec<u32>,
}

impl ContactSurface {
    /// The surface of the given triangles (nothing torn).
    pub fn new(triangles: &[[u32; 3]]) -> Self {
        Self::torn(triangles, &[])
    }

    /// The surface of the given triangles, particle `i` split by tearing from `torn_from[i]`
    /// (missing entries, and entries out of range: not split). Chains (a copy of a copy) are
    /// followed to their first particle.
    pub fn torn(triangles: &[[u32; 3]], torn_from: &[u32]) -> Self {
        let mut edges: Vec<[u32; 2]> = triangles
            .iter()
            .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
            .map(|[a, b]| [a.min(b), a.max(b)])
            .collect();
        edges.sort_unstable();
        edges.dedup();
        let mut vertices: Vec<u32> = triangles.iter().flatten().copied().collect();
        vertices.sort_unstable();
        vertices.dedup();
        let n = vertices.last().map_or(0, |&v| v as usize + 1);
        let mut s = Self {
            triangles: triangles.to_vec(),
            edges,
            vertices,
            origin: vec![],
        };
        s.set_origins(n, torn_from);
        s
    }

    /// Sets `origin` for `n` particles from `torn_from` (see [`ContactSurface::torn`]).
    fn set_origins(&mut self, n: usize, torn_from: &[u32]) {
        let of = |i: usize| {
            torn_from
                .get(i)
                .map_or(i, |&o| if (o as usize) < n { o as usize } else { i })
        };
        self.origin = (0..n)
            .map(|i| {
                // At most n links: a cycle (bad input) stops where it started.
                let mut o = i;
                for _ in 0..n {
                    let next = of(o);
                    if next == o || next == i {
                        break;
                    }
                    o = next;
                }
                o as u32
            })
            .collect();
    }

    /// The particle each was split from by tearing, chains followed to the first (its own
    /// index when not split).
    pub fn origins(&self) -> &[u32] {
        &self.origin
    }

    /// True when some particle was split from another (the surface was torn).
    pub fn is_torn(&self) -> bool {
        self.origin
            .iter()
            .enumerate()
            .any(|(i, &o)| o as usize != i)
    }

    /// For each particle, whether it lies on a cut: split from another, or split (empty when
    /// nothing was torn).
    pub fn on_cut(&self) -> Vec<bool> {
        if !self.is_torn() {
            return vec![];
        }
        let mut on = vec![false; self.origin.len()];
        for (i, &o) in self.origin.iter().enumerate() {
            if o as usize != i {
                on[i] = true;
                on[o as usize] = true;
            }
        }
        on
    }

    /// Several surfaces as one, the particles of surface `k` shifted by `offsets[k]` (the
    /// surfaces of bodies whose particles are laid end to end).
    pub fn concat(parts: &[(&ContactSurface, u32)]) -> Self {
        let mut s = Self::default();
        let mut torn_from: Vec<u32> = vec![];
        for (p, off) in parts {
            s.triangles
                .extend(p.triangles.iter().map(|t| t.map(|i| i + off)));
            s.edges.extend(p.edges.iter().map(|e| e.map(|i| i + off)));
            s.vertices.extend(p.vertices.iter().map(|i| i + off));
            let lo = *off as usize;
            if torn_from.len() < lo {
                torn_from.extend(torn_from.len() as u32..lo as u32);
            }
            torn_from.truncate(lo);
            torn_from.extend(p.origin.iter().map(|o| o + off));
        }
        let n = s.vertices.iter().max().map_or(0, |&v| v as usize + 1);
        s.set_origins(n, &torn_from);
        s
    }

    /// The shortest edge at positions `x` (`None` without edges).
    pub fn shortest_edge(&self, x: &[DVec3]) -> Option<f64> {
        self.edges
            .iter()
            .map(|e| x[e[0] as usize].distance(x[e[1] as usize]))
            .min_by(f64::total_cmp)
    }

    /// The largest particle index plus one.
    pub fn particle_count(&self) -> usize {
        self.vertices.last().map_or(0, |&v| v as usize + 1)
    }
}

/// What the last pass did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SelfContactReport {
    /// Candidate pairs the broad phase holds (after the pass).
    pub candidates: u32,
    /// Broad-phase searches run (the candidates are kept while every vertex stays within a
    /// thickness of where it was at the last search).
    pub searches: u32,
    /// Pairs of triangles the searches compared (their leaves' boxes overlapping; the pairs
    /// inside flat patches are never compared).
    pub tested: u64,
    /// Times a culled patch stopped being flat between searches and was walked on its own.
    pub resumed: u32,
    /// Times a few vertices left their tubes and only their pairs were looked for again
    /// (see [`AROUND_SHARE`]); not counted in [`SelfContactReport::searches`].
    pub searched_around: u32,
    /// Pairs in the proximity band at the start of the pass (closer than [`PROXIMITY`]
    /// thicknesses: impulses).
    pub proximity: u32,
    /// Pairs pushed apart at the end of the step.
    pub separated: u32,
    /// Collisions found by continuous detection (all passes).
    pub collisions: u32,
    /// Passes run (each: proximity, separation, continuous detection).
    pub passes_run: u32,
    /// Passes that ran because a particle had strayed past its budget (a candidate pair may
    /// have closed its allowance: see [`SelfContact::advance`]). With
    /// [`SelfContactReport::due_tube`] and [`SelfContactReport::due_horizon`], what made
    /// passes due; the rest of [`SelfContactReport::passes_run`] ran at a frame's end.
    pub due_budget: u32,
    /// Passes that ran because a surface vertex had left the tube around the motion it had
    /// at the last search (pairs which are not candidates may have come near).
    pub due_tube: u32,
    /// Passes that ran because the last search's horizon had passed (or no pass had run
    /// yet, or the surface changed).
    pub due_horizon: u32,
    /// The particle that made this pass due (the one furthest past its budget, or the first
    /// out of its tube); none for a pass due by the horizon or at a frame's end. In totals,
    /// the last particle that made a pass due. [`SelfContact::due_counts`] counts them per
    /// particle.
    pub due_particle: Option<u32>,
    /// Continuous-detection sweeps run (one or more per pass).
    pub passes: u32,
    /// Impact zones formed (the fail-safe; usually zero).
    pub zones: u32,
    /// The fail-safe ran out of iterations: the surface was held at its start.
    pub failed: bool,
    /// Passes whose fail-safe ran out of iterations (summed in totals).
    pub failures: u32,
    /// Kinetic energy of the surface's free particles before and after the pass (J); summed
    /// over passes in totals.
    pub kinetic_before: f64,
    /// See [`SelfContactReport::kinetic_before`].
    pub kinetic_after: f64,
    /// The largest rise of kinetic energy in one pass (J): round-off only, since every
    /// impulse is inelastic and every zone keeps only its rigid motion.
    pub kinetic_rise: f64,
    /// Time in the broad phase.
    pub broad: Duration,
    /// Time in the narrow phase and the responses.
    pub narrow: Duration,
}

impl SelfContactReport {
    /// Adds another pass's counts and times.
    pub fn add(&mut self, o: &SelfContactReport) {
        self.candidates += o.candidates;
        self.searches += o.searches;
        self.tested += o.tested;
        self.resumed += o.resumed;
        self.searched_around += o.searched_around;
        self.proximity += o.proximity;
        self.separated += o.separated;
        self.collisions += o.collisions;
        self.passes += o.passes;
        self.passes_run += o.passes_run;
        self.due_budget += o.due_budget;
        self.due_tube += o.due_tube;
        self.due_horizon += o.due_horizon;
        self.due_particle = o.due_particle.or(self.due_particle);
        self.zones += o.zones;
        self.failed |= o.failed;
        self.failures += o.failures;
        self.kinetic_before += o.kinetic_before;
        self.kinetic_after += o.kinetic_after;
        self.kinetic_rise = self.kinetic_rise.max(o.kinetic_rise);
        self.broad += o.broad;
        self.narrow += o.narrow;
    }
}

/// A pass runs once a candidate pair within the proximity band may have come this many
/// thicknesses closer since the last (a pair beyond it, by as much more as it was beyond; see
/// [`SelfContact::advance`]), and at each frame's end.
pub const PASS_TRAVEL: f64 = 0.5;

/// How far (in thicknesses, in each coordinate) each vertex may stray from its expected
/// motion (see [`AHEAD`]) before the broad phase searches again ([`SHORT_GROW`] when the
/// search's horizon is shorter than its pass).
pub const BROAD_GROW: f64 = 0.5;

/// The search's horizon: after a search each vertex is expected to go on at its velocity
/// relative to the surface's mean, for [`AHEAD_PASSES`] passes as long as the searching one,
/// or until the fastest has gone this many thicknesses, whichever is sooner; the candidates
/// are kept while every vertex stays within [`BROAD_GROW`] of that motion. A part that swings
/// or slides keeps to it for several passes (the 64² draping cloth searches 7.8 times a frame
/// instead of 18.3 with boxes around the paths alone), and parts moving together keep their
/// distance, so their pairs are not candidates.
pub const AHEAD: f64 = 2.0;

/// See [`AHEAD`].
pub const AHEAD_PASSES: f64 = 8.0;

/// [`BROAD_GROW`] for a search whose horizon is shorter than its own pass (the fastest part
/// goes more than [`AHEAD`] thicknesses in a pass against the mean: frame-long steps of a
/// falling or folding cloth). Every later pass then searches at its start whatever the
/// tubes, so they serve the searching pass alone: their width only takes up what that pass's
/// own impulses change, and when those take a few vertices out, only those vertices' pairs are
/// looked for again ([`AROUND_SHARE`]). Narrower tubes make smaller boxes and fewer
/// candidates: on the 64² cloth folding on the sphere with linearly implicit Euler at 1/60 s,
/// 80,000 candidates instead of 125,000 and self-collision's phases 12.7 ms a step instead of
/// 16.5 (see the benchmarks). With short steps the tubes outlast many passes, and narrower
/// ones would make a search of nearly every pass.
pub const SHORT_GROW: f64 = 0.25;

/// When a search's horizon is shorter than its pass (see [`SHORT_GROW`]) and no more than one
/// surface vertex in this many has left its tube in the middle of the pass, only those vertices
/// get new tubes and only their pairs are looked for again (the tree queried with their
/// points', triangles' and edges' boxes), rather than walking the whole tree again. The
/// query costs about 35 µs a vertex on the 64² folding cloth, a walk 9 ms, so past a few
/// hundred vertices the walk is cheaper. With a horizon of several passes a walk also
/// restarts it, which a query does not, so there every vertex out starts a walk (queries
/// there cost more than they saved: see the benchmarks).
pub const AROUND_SHARE: usize = 32;

/// Pairs closer than this many thicknesses at a pass's start stop approaching (with
/// friction). Wider than the thickness the end of a pass restores: a pair held at the
/// thickness by the position push still gets its normal impulse, and so its friction, in
/// the next pass.
pub const PROXIMITY: f64 = 1.5;

/// Mass factor of particles resting on a collider within a pass: a layer lying on another
/// that lies on the ground pushes that one mostly not at all, instead of pushing it into the
/// ground for the ground to push back (which makes stacks jitter). Finite, unlike the
/// infinite mass of shock propagation (Guendelman, Bridson and Fedkiw, *Nonconvex rigid
/// bodies with stacking*, 2003), so that every impulse still conserves momentum and never
/// adds kinetic energy: the resting particles move, and an infinitely heavy moving particle
/// would drive what it touches.
pub const SUPPORT_MASS: f64 = 16.0;

/// Gauss–Seidel sweeps of the proximity impulses in a pass, at most: a layer stopped against
/// the one below pushes that one on, and an impulse at a triangle's point moves its corners
/// unequally, leaving pairs that share them approaching or separating. They stop once no
/// pair's motion over the pass changes by more than [`SEPARATION_SLACK`] thicknesses. Four
/// cloths stacked on a pinned one and stepped a frame at a time (`tests/self_collision.rs`)
/// keep 2·10⁻⁵ J of kinetic energy over 1.5–2 s with 32, 0.14 J with one.
pub const PROXIMITY_SWEEPS: u32 = 32;

/// Gauss–Seidel sweeps of the end separation in a round (see [`SEPARATION_ROUNDS`]): pairs
/// sharing particles push each other back, a layer lying on another on a third over several
/// sweeps.
pub const SEPARATION_SWEEPS: u32 = 8;
/// Rounds of separation and continuous detection in a pass: each round's collisions leave
/// their pairs a tenth of a thickness apart, for the next round's separation to restore. The
/// 32² cloth draping in frame-long steps needed more than 4 in one frame of 300 (a particle
/// ended 2.8 mm from a triangle at an 8 mm thickness, in `f64`); with 8 none came within 6 mm.
pub const SEPARATION_ROUNDS: u32 = 8;
/// A pair within this fraction of the thickness of it at the end is not pushed (it was
/// pushed to the thickness, less round-off).
pub const SEPARATION_SLACK: f64 = 0.01;

/// Continuous-detection passes before the impact zones take over.
pub const CCD_PASSES: u32 = 8;
/// Impact-zone iterations before the fail-safe gives up and holds the surface.
pub const ZONE_ITERATIONS: u32 = 64;

/// A surface's contact handler: its surface, settings and the buffers it reuses (a step
/// allocates nothing once they have grown).
#[derive(Clone, Debug, Default)]
pub struct SelfContact {
    /// The surface.
    pub surface: ContactSurface,
    /// Settings.
    pub params: SelfContactParams,
    /// Continuous-detection sweeps before the impact zones take over ([`CCD_PASSES`]; zero
    /// leaves every collision to the zones).
    pub ccd_passes: u32,
    /// What the last pass did.
    pub last: SelfContactReport,
    /// Totals since the handler was made.
    pub total: SelfContactReport,
    /// Positions at the end of the last pass (the start of the next).
    start: Vec<Vector>,
    /// Time since the last pass.
    since: Scalar,
    /// Particles resting on colliders (empty: none marked).
    support: Vec<bool>,
    /// Why the next pass is due, as [`SelfContact::advance`] found it.
    due: Due,
    /// Per particle, the passes it made due (see [`SelfContact::due_counts`]).
    due_counts: Vec<u32>,
    s: Scratch,
}

/// What made a pass due (see [`SelfContact::advance`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
enum Due {
    /// Not due: a pass now is the frame's end.
    #[default]
    FrameEnd,
    /// A particle strayed past its budget.
    Budget(u32),
    /// A vertex left its tube.
    Tube(u32),
    /// The search's horizon passed (or the budgets are not set).
    Horizon,
}

#[derive(Clone, Debug, Default)]
struct Scratch {
    p0: Vec<DVec3>,
    u: Vec<DVec3>,
    /// The pass's length, and each particle's squared path length over it, `|u h|²`
    /// (kept up to date with `u`, by [`Scratch::touch`] and after the impact zones).
    h: f64,
    step2: Vec<f64>,
    /// End velocities of the surface's particles.
    vel: Vec<DVec3>,
    /// `u` and `vel` as the step gave them, before the proximity impulses (see
    /// [`Ctx::restrain`]).
    u0: Vec<DVec3>,
    vel0: Vec<DVec3>,
    /// The pass's proximity band: its pairs, each with what its impulses changed its
    /// relative velocities by so far (see [`Held`]).
    held: Vec<Held>,
    w: Vec<f64>,
    zone: Vec<u32>,
    tree: SurfaceTree,
    /// Candidate pairs with their distance at the start of the step.
    pairs: Vec<(Pair, f64)>,
    /// Ends of the surface vertices' paths over the pass (`p0 + u τ`), as of the last
    /// broad-phase check.
    p1: Vec<DVec3>,
    /// Where each vertex is headed at the end of the last search's horizon (see [`AHEAD`]).
    p2: Vec<DVec3>,
    /// Changes made to `u` (counted), and the count when the culled patches were last known
    /// to be flat along the paths it gives (`u64::MAX`: not since the pass began).
    edits: u64,
    cones_at: u64,
    /// The count of changes when the candidates were last known to cover the paths
    /// (`u64::MAX`: not since the pass began).
    broad_at: u64,
    /// Vertices whose `u` changed since the cone bits were last computed (`moved_all`: any).
    moved: Vec<u32>,
    moved_mark: Vec<bool>,
    moved_all: bool,
    /// Searches resumed where culled patches stopped being flat.
    resumed: u32,
    hits: Vec<[u32; 4]>,
    /// Per particle, the sweep in or after which its path last changed (see [`Epochs`]).
    changed: Vec<u64>,
    epoch: Epochs,
    zone_sum: Vec<ZoneSum>,
    broad_valid: bool,
    /// Per particle: how far it may stray from the motion it had at the last pass's end
    /// before the next pass is due, less `slope` times the time since (infinite: in no
    /// candidate pair); and its path over the pass (scratch, while the budgets are set).
    budget: Vec<Scalar>,
    travel: Vec<Scalar>,
    /// Per particle: how fast its budget shrinks after the pass (half the largest
    /// [`spread`] of the end velocities of a pair it is in), and its end velocity; the
    /// surface's mean position and velocity at the pass's end.
    slope: Vec<Scalar>,
    vref: Vec<Vector>,
    mean_xref: Vector,
    mean_vref: Vector,
    /// Per particle, as of the last search: where it was at the end of that pass and its
    /// velocity then relative to the surface's mean (its motion is expected to stay within
    /// [`BROAD_GROW`] thicknesses of `base + w τ` for `τ` up to `tube_len` after that
    /// pass's end, relative to the mean position `tube_ref`); `clock` is `τ` at the end of
    /// the current pass. The same in `Scalar` for [`SelfContact::advance`]'s check.
    tube: Vec<(DVec3, DVec3)>,
    tube_ref: DVec3,
    tube_len: f64,
    clock: f64,
    tube_s: Vec<(Vector, Vector)>,
    tube_ref_s: Vector,
    /// How far each vertex may stray from its tube in each coordinate (m; [`BROAD_GROW`] or
    /// [`SHORT_GROW`] thicknesses, as the last search chose), and in `Scalar`.
    grow: f64,
    grow_s: Scalar,
    searches: u32,
    tested: u64,
    /// Vertices out of their tubes (marked in `out_mark`), the pairs a search around them
    /// found, and the count of such searches.
    out: Vec<u32>,
    out_mark: Vec<bool>,
    found: Vec<Pair>,
    searched_around: u32,
    /// A whole search's walk ([`Ctx::walk_and_keep`]): the tree's pieces, where each one's
    /// output lies, and each thread's lists.
    pieces: Vec<Visit>,
    piece_out: Vec<PieceOut>,
    walkers: Vec<Walker>,
}

/// One thread's part of a whole search's walk ([`Ctx::walk_and_keep`]): its stack, the pairs
/// found and not yet measured (at most [`RAW_PAIRS`]), the pairs measured and kept and the
/// nodes culled by the pieces it took, in the order it took them, and the triangle pairs it
/// compared.
#[derive(Clone, Debug, Default)]
struct Walker {
    stack: Vec<Visit>,
    raw: Vec<(Pair, f64)>,
    kept: Vec<(Pair, f64)>,
    culled: Vec<u32>,
    tests: u64,
}

/// Where a piece's output lies: the walker that took it, and its ranges in that walker's
/// `kept` and `culled`.
#[derive(Clone, Copy, Debug, Default)]
struct PieceOut {
    walker: u32,
    kept: [u32; 2],
    culled: [u32; 2],
}

/// Pairs a walker finds before it measures them and keeps those that may come near: a few
/// hundred kilobytes that stay in the cache, instead of every pair the walk finds (several
/// times the candidates it keeps) written out and read twice.
const RAW_PAIRS: usize = 1024;

/// Measures the pairs `raw` ([`distances_in_batches`]), appends those `keep` keeps to `kept`,
/// and empties `raw`. Not inlined into the walk, which calls it once per [`RAW_PAIRS`] pairs.
#[inline(never)]
fn measure_and_keep(
    raw: &mut Vec<(Pair, f64)>,
    kept: &mut Vec<(Pair, f64)>,
    p0: &[DVec3],
    keep: &Keep,
) {
    distances_in_batches(raw, p0);
    for &(pair, d0) in raw.iter() {
        if keep.keeps(pair, d0) {
            kept.push((pair, d0));
        }
    }
    raw.clear();
}

/// What [`Ctx::keep_near`] tests a candidate against: the tubes' velocities and horizon,
/// the particles' squared paths over the pass, and the slack and band.
struct Keep<'a> {
    tube: &'a [(DVec3, DVec3)],
    step2: &'a [f64],
    tube_len: f64,
    h: f64,
    slack: f64,
    band: f64,
}

impl Keep<'_> {
    /// Whether `pair`, `d0` apart at the pass's start, may come within the proximity band
    /// before the next search (see [`Ctx::keep_near`]). A NaN distance is not kept.
    #[inline(always)]
    fn keeps(&self, pair: Pair, d0: f64) -> bool {
        let spread = spread(pair, pair.ids().map(|i| self.tube[i as usize].1));
        let approach = own_reach(self.step2, pair).min(spread * self.h);
        d0 - approach - spread * self.tube_len - self.slack < self.band
    }
}

impl Scratch {
    /// Notes a change to the average velocities of `ids`.
    fn touch(&mut self, ids: &[u32; 4]) {
        self.edits += 1;
        for &i in ids {
            self.step2[i as usize] = (self.u[i as usize] * self.h).length_squared();
        }
        self.mark(ids);
        if self.moved_all {
            return;
        }
        for &i in ids {
            if !self.moved_mark[i as usize] {
                self.moved_mark[i as usize] = true;
                self.moved.push(i);
            }
        }
    }

    /// Marks the particles `ids` as changed in the sweep under way: their end velocities
    /// changed (and their paths, when [`Scratch::touch`] calls it).
    fn mark(&mut self, ids: &[u32; 4]) {
        for &i in ids {
            self.changed[i as usize] = self.epoch.now;
        }
    }

    /// Whether a particle of `pair` changed its path in or after the sweep `since` (always,
    /// for 0).
    fn changed_since(&self, pair: Pair, since: u64) -> bool {
        self.changed_since_ids(&pair.ids(), since)
    }

    /// [`Scratch::changed_since`] for the particles `ids`.
    fn changed_since_ids(&self, ids: &[u32; 4], since: u64) -> bool {
        since == 0 || ids.iter().any(|&i| self.changed[i as usize] >= since)
    }

    fn clear_moved(&mut self) {
        for &i in &self.moved {
            self.moved_mark[i as usize] = false;
        }
        self.moved.clear();
        self.moved_all = false;
    }
}

/// The kinds of sweep over the candidates, each with its own record in [`Epochs`].
#[derive(Clone, Copy, Debug)]
enum Sweep {
    /// [`Ctx::end_separation`].
    Separation = 0,
    /// Continuous detection and [`Ctx::collision_impulse`].
    Ccd = 1,
    /// [`Ctx::proximity_impulse`].
    Proximity = 2,
}

/// Sweeps counted over the handler's life, so a sweep need look only at the pairs whose
/// paths changed since the last sweep of its kind (what a sweep does to a pair depends on
/// its particles' paths alone): `now` is the sweep under way (or the last), `last` the last
/// of each kind ([`Sweep`]) with the candidate set it swept; `set` counts the candidate sets
/// (a new pass, a search, a resumed walk: pairs no sweep has seen).
#[derive(Clone, Copy, Debug, Default)]
struct Epochs {
    now: u64,
    set: u64,
    last: [(u64, u64); 3],
}

impl Epochs {
    /// Starts a sweep of `kind`: the sweep from which on a change of a pair's particles
    /// means the pair must be looked at (0, all of them, when the candidates are not those
    /// the last sweep of its kind saw).
    fn begin(&mut self, kind: Sweep) -> u64 {
        let last = &mut self.last[kind as usize];
        let since = if last.1 == self.set { last.0 } else { 0 };
        self.now += 1;
        *last = (self.now, self.set);
        since
    }
}

/// A pair in a pass's proximity band: its closest points and normal at the start, and what
/// its impulses changed its relative velocity by so far this pass, along the normal and
/// across it (see [`Ctx::restrain`]), in the average velocities (`u`) and in the end
/// velocities (`vel`).
#[derive(Clone, Copy, Debug)]
struct Held {
    st: Stencil,
    nrm: DVec3,
    /// Whether the later sweeps look at it: not a point whose nearest point on the triangle
    /// is on the triangle's border (see [`Ctx::proximity_sweeps`]).
    again: bool,
    u: (f64, DVec3),
    vel: (f64, DVec3),
}

/// A point–triangle (`[p, a, b, c]`) or edge–edge (`[a, b, c, d]`) pair, by its four
/// particles (looked up once, when a walk finds it: every pass reads them for every
/// candidate).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Pair {
    PointTriangle([u32; 4]),
    EdgeEdge([u32; 4]),
}

impl Pair {
    fn ids(self) -> [u32; 4] {
        match self {
            Pair::PointTriangle(ids) | Pair::EdgeEdge(ids) => ids,
        }
    }
}

/// Four particles and their weights: the pair's relative position is `Σ wᵢ xᵢ`.
#[derive(Clone, Copy, Debug)]
struct Stencil {
    idx: [u32; 4],
    wt: [f64; 4],
}

impl SelfContact {
    /// A handler for `surface`.
    pub fn new(surface: ContactSurface, params: SelfContactParams) -> Self {
        Self {
            surface,
            params,
            ccd_passes: CCD_PASSES,
            ..Default::default()
        }
    }

    /// Starts a frame from positions `x` (free of intersections: the end of the last frame).
    pub fn begin_frame(&mut self, x: &[Vector]) {
        self.start.clear();
        self.start.extend_from_slice(x);
        self.since = 0.0;
        // The reference of the strays (see [`SelfContact::advance`]): the last pass's end,
        // unless the positions were changed since.
        let verts = &self.surface.vertices;
        if verts.last().is_some_and(|&i| (i as usize) < x.len()) {
            self.s.mean_xref = mean_of(verts, x);
        }
    }

    /// After a step of length `h` to positions `x` with end velocities `v`: true when a pass
    /// is due. A candidate pair (one the last search found) at distance `d` when the last
    /// pass ended is due once its parts may have come `max(d − PROXIMITY·thickness, 0) +
    /// PASS_TRAVEL·thickness` closer (each particle's stray from where its end velocity
    /// would have taken it, relative to the surface's mean, plus half the speed at which its
    /// pairs' parts then approached times the time since, is held to half that), so every
    /// pass sees the pairs in its proximity band come at most [`PASS_TRAVEL`] thicknesses
    /// closer whatever the step; and a pass is due when a surface vertex has strayed from the
    /// motion it had at the last search, or that search's horizon has passed (see
    /// [`AHEAD`]), since pairs which are not candidates may then come near. Parts of the
    /// surface far from each other need no pass however fast they move, and parts at rest
    /// none however fast others move past them.
    pub fn advance(&mut self, h: Scalar, x: &[Vector], v: &[Vector]) -> bool {
        if self.start.len() != v.len() || x.len() != v.len() || self.surface.triangles.is_empty() {
            return false;
        }
        let verts = &self.surface.vertices;
        let mean_x = mean_of(verts, x);
        self.since += h;
        self.due = Due::FrameEnd;
        let s = &mut self.s;
        let tau = s.clock + self.since as f64;
        if s.budget.len() != v.len()
            || s.vref.len() != v.len()
            || s.tube_s.len() != x.len()
            || tau > s.tube_len
        {
            self.due = Due::Horizon;
            return true;
        }
        // Each particle's departure from where its velocity at the last pass's end would
        // have taken it, less the mean's (a motion common to the surface brings no two
        // parts closer).
        let since = self.since;
        let dm = mean_x - s.mean_xref - s.mean_vref * since;
        let start = &self.start;
        let over = |i: usize| {
            let stray = (x[i] - start[i] - s.vref[i] * since - dm).length();
            stray + s.slope[i] * since - s.budget[i]
        };
        let mut due = false;
        for &i in verts {
            due |= over(i as usize) > 0.0;
        }
        if due {
            // Named for the report: the particle furthest past its budget (looked for only
            // when a pass is due, once per pass).
            let (mut worst, mut most) = (0, Scalar::NEG_INFINITY);
            for &i in verts {
                let o = over(i as usize);
                if o > most {
                    (worst, most) = (i, o);
                }
            }
            self.due = Due::Budget(worst);
            return true;
        }
        // Each vertex within its tube as the pass's check reads it, but in `Scalar`: a vertex
        // that round-off keeps inside a little longer only makes the pass later, and the pass
        // checks exactly.
        let (d, tau) = (mean_x - s.tube_ref_s, tau as Scalar);
        let g = Vector::splat(s.grow_s);
        let out = verts.iter().find(|&&i| {
            let (base, w) = s.tube_s[i as usize];
            !(x[i as usize] - d - (base + w * tau)).abs().cmple(g).all()
        });
        self.due = out.map_or(Due::FrameEnd, |&i| Due::Tube(i));
        out.is_some()
    }

    /// Per particle, the passes it made due since the handler was made: by straying past its
    /// budget or leaving its tube (see [`SelfContactReport::due_particle`]). A few particles
    /// with most of the count are where the passes' cost comes from: typically a crease
    /// pressed together by its springs and held apart by the thickness, whose particles the
    /// springs drive into their contacts again after every pass.
    pub fn due_counts(&self) -> &[u32] {
        &self.due_counts
    }

    /// True when steps were taken since the last pass (the frame's end then needs one, so
    /// every state a frame delivers is free of intersections).
    pub fn pending(&self) -> bool {
        self.since > 0.0 && !self.start.is_empty()
    }

    /// Particles the next pass treats as heavier ([`SUPPORT_MASS`]: resting on a collider):
    /// cleared to `n` entries for the caller to mark.
    pub fn support_mut(&mut self, n: usize) -> &mut [bool] {
        self.support.clear();
        self.support.resize(n, false);
        &mut self.support
    }

    /// A pass over the motion since the last one (from its end to `x`), with the particles
    /// marked in [`SelfContact::support_mut`] [`SUPPORT_MASS`] times heavier.
    pub fn pass(&mut self, x: &mut [Vector], v: &mut [Vector], inv_mass: &[Scalar]) {
        if self.start.len() != x.len() {
            return;
        }
        let start = std::mem::take(&mut self.start);
        self.resolve(self.since, &start, x, v, inv_mass);
        self.start = start;
        self.start.copy_from_slice(x);
        self.since = 0.0;
        self.support.clear();
    }

    /// Makes the motion from `x0` to `x` over a step of length `h` free of intersections
    /// (see the module docs): changes `x` and the end velocities `v` of surface particles with
    /// non-zero inverse mass.
    pub fn resolve(
        &mut self,
        h: Scalar,
        x0: &[Vector],
        x: &mut [Vector],
        v: &mut [Vector],
        inv_mass: &[Scalar],
    ) -> SelfContactReport {
        let h = h as f64;
        // What made this pass due, as the last `advance` found it (a frame's end when it
        // found nothing, or when none ran); the totals add it with the rest.
        let due = std::mem::take(&mut self.due);
        let mut rep = SelfContactReport {
            passes_run: 1,
            due_budget: matches!(due, Due::Budget(_)) as u32,
            due_tube: matches!(due, Due::Tube(_)) as u32,
            due_horizon: (due == Due::Horizon) as u32,
            due_particle: match due {
                Due::Budget(i) | Due::Tube(i) => Some(i),
                Due::FrameEnd | Due::Horizon => None,
            },
            ..Default::default()
        };
        if h.is_nan() || h <= 0.0 || self.surface.triangles.is_empty() {
            self.last = rep;
            return rep;
        }
        let n = x.len();
        // Sized at the first pass (always due by the horizon), so no later one allocates.
        self.due_counts.resize(n, 0);
        if let Some(i) = rep.due_particle {
            self.due_counts[i as usize] += 1;
        }
        let s = &mut self.s;
        s.p0.resize(n, DVec3::ZERO);
        s.u.resize(n, DVec3::ZERO);
        s.step2.resize(n, 0.0);
        s.changed.resize(n, 0);
        // New paths: no sweep has seen them.
        s.epoch.set += 1;
        s.h = h;
        s.vel.resize(n, DVec3::ZERO);
        s.w.resize(n, 0.0);
        s.clock += h;
        // New paths: the culled patches' flatness is unknown.
        s.cones_at = u64::MAX;
        s.broad_at = u64::MAX;
        s.moved_all = true;
        s.moved_mark.resize(n, false);
        // Each vertex is listed at most once: sized now, a pass never grows it.
        s.moved.reserve(n.saturating_sub(s.moved.len()));
        for &i in &self.surface.vertices {
            let i = i as usize;
            let p0 = to_d(x0[i]);
            s.p0[i] = p0;
            s.u[i] = (to_d(x[i]) - p0) / h;
            s.step2[i] = (s.u[i] * h).length_squared();
            s.vel[i] = to_d(v[i]);
            s.w[i] = if self.support.get(i).copied().unwrap_or(false) {
                inv_mass[i] as f64 / SUPPORT_MASS
            } else {
                inv_mass[i] as f64
            };
        }
        rep.kinetic_before = kinetic(&self.surface.vertices, &s.w, &s.vel);
        let ctx = Ctx {
            surf: &self.surface,
            thick: self.params.thickness,
            mu: self.params.friction,
            h,
        };

        // 1–2: proximity at the start (impulses) and at the end (position pushes).
        let t0 = Instant::now();
        let (searches, tested, resumed) = (s.searches, s.tested, s.resumed);
        let around = s.searched_around;
        let rebuilt = ctx.ensure_broad(s);
        let t1 = Instant::now();
        rep.broad += t1 - t0;
        if !rebuilt {
            ctx.start_distances(s, 0);
        }
        rep.proximity = ctx.proximity_sweeps(s);
        rep.narrow += t1.elapsed();
        rep.candidates = s.pairs.len() as u32;

        // 2–3: separation at the end, then continuous detection in Gauss–Seidel passes, in
        // rounds: a collision's response leaves its pair a tenth of a thickness apart, and a
        // separation can end a path that crosses on the right side, so each undoes the other
        // until neither has anything to do.
        let mut clean = false;
        for round in 0..SEPARATION_ROUNDS {
            let t1 = Instant::now();
            // A pair none of whose particles moved since it was last looked at is as that
            // left it; the first sweep of a pass looks at every candidate.
            let mut pushed = 0;
            for _ in 0..SEPARATION_SWEEPS {
                let now = ctx.separation_sweep(s);
                pushed += now;
                if now == 0 {
                    break;
                }
            }
            rep.separated += pushed;
            rep.narrow += t1.elapsed();
            // Nothing moved since the last round's detection found the motion clean.
            if round > 0 && pushed == 0 {
                break;
            }
            clean = false;
            for _ in 0..self.ccd_passes {
                let t0 = Instant::now();
                ctx.ensure_broad(s);
                let t1 = Instant::now();
                rep.broad += t1 - t0;
                rep.passes += 1;
                let found = ctx.ccd_sweep(s);
                rep.narrow += t1.elapsed();
                rep.collisions += found;
                if found == 0 {
                    clean = true;
                    break;
                }
            }
            if !clean {
                break;
            }
        }

        // 4: rigid impact zones.
        if !clean {
            let t0 = Instant::now();
            let ok = ctx.impact_zones(s, &mut rep);
            rep.narrow += t0.elapsed();
            if !ok {
                rep.failed = true;
                rep.failures = 1;
                for &i in &self.surface.vertices {
                    let i = i as usize;
                    if s.w[i] > 0.0 {
                        s.u[i] = DVec3::ZERO;
                        s.vel[i] = DVec3::ZERO;
                    }
                }
            }
        }

        rep.kinetic_after = kinetic(&self.surface.vertices, &s.w, &s.vel);
        rep.kinetic_rise = (rep.kinetic_after - rep.kinetic_before).max(0.0);
        for &i in &self.surface.vertices {
            let i = i as usize;
            if s.w[i] == 0.0 {
                continue;
            }
            x[i] = from_d(s.p0[i] + s.u[i] * h);
            v[i] = from_d(s.vel[i]);
        }
        // How far each particle may travel before the next pass is due (see
        // [`SelfContact::advance`]): half of what its nearest candidate pair may close, that
        // pair's distance at the pass's end bounded below by its distance at the start less
        // the longest path of each of its parts over the pass (the paths' lengths held in
        // `travel` meanwhile). Not [`reach`]'s second bound, though it is one: its larger
        // budgets made fewer and longer passes, whose searches found more pairs (the 64²
        // draping cloth over 2 s: 26.6 passes a frame against 27.2, 2,723 µs a step against
        // 2,175).
        s.travel.clear();
        s.travel.resize(n, 0.0);
        for &i in &self.surface.vertices {
            let i = i as usize;
            s.travel[i] = (s.u[i].length() * h) as Scalar;
        }
        // After the pass a pair's parts come closer by no more than the largest difference of
        // the end velocities of a vertex of one and one of the other ([`spread`]) times the
        // time since, plus how far a vertex of each has strayed from where its own end
        // velocity would have taken it (a motion common to the whole surface taken out): for
        // points `Σ aᵢxᵢ` and `Σ bⱼyⱼ` of the parts, `Δ(Σ aᵢxᵢ − Σ bⱼyⱼ) = τ Σᵢⱼ aᵢbⱼ (vᵢ − vⱼ) +
        // Σ aᵢsᵢ − Σ bⱼsⱼ` with `sₖ` the strays. So each particle's budget shrinks at half
        // that speed (`slope`: the largest over its pairs) and is spent by its stray (see
        // [`SelfContact::advance`]). A part at rest beside one that slides or falls spends
        // nothing, where speeds measured from the surface's mean velocity spent its budget at
        // the mean's speed.
        s.vref.clear();
        s.vref.extend_from_slice(v);
        s.budget.clear();
        s.budget.resize(n, Scalar::INFINITY);
        s.slope.clear();
        s.slope.resize(n, 0.0);
        let (near, band) = (PROXIMITY * ctx.thick, PASS_TRAVEL * ctx.thick);
        for &(pair, d0) in &s.pairs {
            let ids = pair.ids();
            let [a, b, c, d] = ids.map(|i| s.travel[i as usize]);
            let closing = match pair {
                Pair::PointTriangle(..) => a + b.max(c).max(d),
                Pair::EdgeEdge(..) => a.max(b) + c.max(d),
            } as f64;
            let half = (0.5 * ((d0 - closing - near).max(0.0) + band)) as Scalar;
            // Squared here, halved and rooted once per particle below.
            let [va, vb, vc, vd] = ids.map(|i| s.vref[i as usize]);
            let rate2 = match pair {
                Pair::PointTriangle(..) => (va - vb)
                    .length_squared()
                    .max((va - vc).length_squared())
                    .max((va - vd).length_squared()),
                Pair::EdgeEdge(..) => ((va - vc).length_squared())
                    .max((va - vd).length_squared())
                    .max((vb - vc).length_squared())
                    .max((vb - vd).length_squared()),
            };
            for i in ids {
                let i = i as usize;
                s.budget[i] = s.budget[i].min(half);
                s.slope[i] = s.slope[i].max(rate2);
            }
        }
        for r in &mut s.slope {
            *r = 0.5 * r.sqrt();
        }
        let verts = &self.surface.vertices;
        (s.mean_xref, s.mean_vref) = (mean_of(verts, x), mean_of(verts, v));
        rep.searches = s.searches - searches;
        rep.tested = s.tested - tested;
        rep.resumed = s.resumed - resumed;
        rep.searched_around = s.searched_around - around;
        self.last = rep;
        self.total.add(&rep);
        self.total.candidates = rep.candidates;
        rep
    }
}

/// Candidates a chunk of the team's passes over them holds (tens of microseconds of work;
/// smaller under Miri).
const PAIR_CHUNK: usize = crate::core::kernels::chunk_limit(1024, 64);

/// The start distances of `pairs` at positions `p0`, four pairs of a kind at a time
/// ([`distance`]): point–triangle and edge–edge pairs are set aside into their own batch as
/// they come, and a batch's distances written back when it is full (the last ones, part full,
/// at the end). Each lane's distance is its own pair's alone, so the bits do not depend on
/// how the pairs are cut into chunks or batched.
fn distances_in_batches(pairs: &mut [(Pair, f64)], p0: &[DVec3]) {
    const L: usize = distance::LANES;
    // Per kind (point–triangle, edge–edge): the batch's positions, its pairs' indices, and
    // how many it holds.
    let mut y = [[[DVec3::ZERO; 4]; L]; 2];
    let mut at = [[0usize; L]; 2];
    let mut held = [0usize; 2];
    let flush = |pairs: &mut [(Pair, f64)],
                 kind: usize,
                 y: &mut [[DVec3; 4]; L],
                 at: &[usize; L],
                 n: usize| {
        // Unused lanes repeat the first pair.
        for q in n..L {
            y[q] = y[0];
        }
        let d = if kind == 0 {
            distance::point_triangle(y)
        } else {
            distance::edge_edge(y)
        };
        for q in 0..n {
            pairs[at[q]].1 = d[q];
        }
    };
    for k in 0..pairs.len() {
        let pair = pairs[k].0;
        let kind = matches!(pair, Pair::EdgeEdge(..)) as usize;
        let n = held[kind];
        y[kind][n] = pair.ids().map(|i| p0[i as usize]);
        at[kind][n] = k;
        held[kind] = n + 1;
        if n + 1 == L {
            flush(pairs, kind, &mut y[kind], &at[kind], L);
            held[kind] = 0;
        }
    }
    for kind in 0..2 {
        if held[kind] > 0 {
            flush(pairs, kind, &mut y[kind], &at[kind], held[kind]);
        }
    }
}

/// How much closer than its distance a pair's parts can come over the pass of length `h`, as
/// far as a pair with `room` to spare needs to know: the largest travel of a point of the
/// first part plus that of the second (the closest points move no more than the fastest
/// vertex of their part), from each particle's squared path over the pass, `step2`; where
/// that leaves no room, the largest difference of the paths `u h` of a vertex of the first
/// part and one of the second, which is never larger. That too is a bound: for points
/// `Σ aᵢxᵢ` and `Σ bⱼyⱼ` of the parts (weights summing to one) the difference moves by
/// `τ Σᵢⱼ aᵢbⱼ (uᵢ − uⱼ) h`, no more than that, so each such distance, and their least, the
/// pair's, falls by no more. Parts that move together (a falling cloth over a frame-long
/// pass) come no closer however far they go; the first bound is cheaper, and enough for
/// most pairs of a short pass.
fn reach(step2: &[f64], u: &[DVec3], h: f64, pair: Pair, room: f64) -> f64 {
    let own = own_reach(step2, pair);
    if own < room {
        return own;
    }
    (spread(pair, pair.ids().map(|i| u[i as usize])) * h).min(own)
}

/// The first bound of [`reach`]: the largest travel of a vertex of the first part plus that
/// of the second.
#[inline]
fn own_reach(step2: &[f64], pair: Pair) -> f64 {
    let ids = pair.ids();
    let travel = |k: usize| step2[ids[k] as usize];
    let (a, b) = match pair {
        Pair::PointTriangle(..) => (travel(0), travel(1).max(travel(2)).max(travel(3))),
        Pair::EdgeEdge(..) => (travel(0).max(travel(1)), travel(2).max(travel(3))),
    };
    a.sqrt() + b.sqrt()
}

/// The largest difference of the velocities `v` (of the pair's four particles) of a vertex of
/// the first part and one of the second.
#[inline]
fn spread(pair: Pair, v: [DVec3; 4]) -> f64 {
    let apart = |a: usize, b: usize| v[a].distance_squared(v[b]);
    match pair {
        Pair::PointTriangle(..) => apart(0, 1).max(apart(0, 2)).max(apart(0, 3)),
        Pair::EdgeEdge(..) => apart(0, 2)
            .max(apart(0, 3))
            .max(apart(1, 2))
            .max(apart(1, 3)),
    }
    .sqrt()
}

/// The pair a walk found, by its four particles.
fn pair_of(found: Found, triangles: &[[u32; 3]], edges: &[[u32; 2]]) -> Pair {
    match found {
        Found::PointTriangle(p, t) => {
            let t = triangles[t as usize];
            Pair::PointTriangle([p, t[0], t[1], t[2]])
        }
        Found::EdgeEdge(e, f) => {
            let (e, f) = (edges[e as usize], edges[f as usize]);
            Pair::EdgeEdge([e[0], e[1], f[0], f[1]])
        }
    }
}

/// The mean of `x` over the particles `verts` (zero for none).
fn mean_of(verts: &[u32], x: &[Vector]) -> Vector {
    let mut sum = Vector::ZERO;
    for &i in verts {
        sum += x[i as usize];
    }
    sum / verts.len().max(1) as Scalar
}

/// Kinetic energy of the free particles among `verts`.
fn kinetic(verts: &[u32], w: &[f64], vel: &[DVec3]) -> f64 {
    verts
        .iter()
        .map(|&i| i as usize)
        .filter(|&i| w[i] > 0.0)
        .map(|i| 0.5 * vel[i].length_squared() / w[i])
        .sum()
}

fn to_d(v: Vector) -> DVec3 {
    DVec3::new(v.x as f64, v.y as f64, v.z as f64)
}

fn from_d(v: DVec3) -> Vector {
    v.to_array().to_scalar()
}

struct Ctx<'a> {
    surf: &'a ContactSurface,
    thick: f64,
    mu: f64,
    h: f64,
}

/// Distance below which continuous detection calls four coplanar points touching (m).
fn touch_tolerance(thick: f64) -> f64 {
    (1e-3 * thick).max(1e-7)
}

impl Ctx<'_> {
    /// Finds the candidate pairs again unless every surface vertex's path over this pass
    /// (start and end) still lies within [`BROAD_GROW`] thicknesses of the motion it had when
    /// they were last found, within that search's horizon ([`AHEAD`]): kept across passes
    /// and steps (a Verlet list along the motion), so a body at rest, or swinging or sliding
    /// smoothly, searches rarely.
    fn ensure_broad(&self, s: &mut Scratch) -> bool {
        // Nothing changed since the last check.
        if s.broad_valid && s.broad_at == s.edits {
            return false;
        }
        let h = self.h;
        let verts = &self.surf.vertices;
        let nv = verts.len().max(1) as f64;
        s.p1.resize(s.p0.len(), DVec3::ZERO);
        let (mut sum0, mut sum1) = (DVec3::ZERO, DVec3::ZERO);
        for &i in verts {
            let i = i as usize;
            let p1 = s.p0[i] + s.u[i] * h;
            s.p1[i] = p1;
            sum0 += s.p0[i];
            sum1 += p1;
        }
        let (mean0, mean1) = (sum0 / nv, sum1 / nv);
        let grow = s.grow;
        if s.broad_valid && s.tube.len() == s.p0.len() && s.clock <= s.tube_len {
            // Each vertex must still be within `grow` (in each coordinate) of where its motion
            // at the search takes it, relative to the surface's mean position (a common
            // translation changes no distance), at the start and the end of the pass (and so
            // all along it: both straight).
            let (t0, t1) = (s.clock - h, s.clock);
            let (d0, d1) = (mean0 - s.tube_ref, mean1 - s.tube_ref);
            let g = DVec3::splat(grow);
            let out_of = |i: usize| {
                let (base, w) = s.tube[i];
                let e0 = s.p0[i] - d0 - (base + w * t0);
                let e1 = s.p1[i] - d1 - (base + w * t1);
                !e0.abs().max(e1.abs()).cmple(g).all()
            };
            let inside = !verts.iter().any(|&i| out_of(i as usize));
            // A few vertices out: new tubes for them, their pairs found again (below).
            let around = !inside && s.tube_len < h && {
                s.out.clear();
                s.out
                    .extend(verts.iter().copied().filter(|&i| out_of(i as usize)));
                s.out.len() * AROUND_SHARE <= verts.len()
            };
            // The culled patches must still be flat along the paths as they are now.
            if (inside || around) && s.cones_at != s.edits {
                let moved = (!s.moved_all).then_some(&s.moved[..]);
                if s.moved_all {
                    s.tree.load(verts, &s.p0, &s.p1);
                } else {
                    s.tree.load_some(&s.moved, &s.p1);
                }
                if !s.tree.still_flat(&self.surf.triangles, moved) {
                    // Walk what is no longer flat (the boxes still hold): its pairs join the
                    // candidates.
                    let from = s.pairs.len();
                    self.walk(s, true);
                    s.epoch.set += 1;
                    s.resumed += 1;
                    self.start_distances(s, from);
                }
                s.cones_at = s.edits;
                s.clear_moved();
            }
            if around {
                self.search_around(s, [d0, d1], t1, (mean1 - mean0) / h);
            }
            if inside || around {
                s.broad_at = s.edits;
                return false;
            }
        }
        self.broad_phase(s, mean1);
        s.epoch.set += 1;
        s.clock = 0.0;
        s.tube_s.clear();
        s.tube_s
            .extend(s.tube.iter().map(|&(b, w)| (from_d(b), from_d(w))));
        s.tube_ref_s = from_d(mean1);
        s.broad_valid = true;
        s.broad_at = s.edits;
        s.searches += 1;
        true
    }

    /// Drops the candidates from index `from` on that cannot come within the proximity band
    /// before the next search. At the pass's end a pair is at least its distance now less the
    /// pass's approach; after, each vertex is within the tubes' width (`grow`) of its tube in
    /// each coordinate (√3 `grow`), and the tubes bring the pair's parts closer by at most the
    /// largest difference of their vertices' velocities (relative to the mean) times the
    /// search's horizon. That difference, times the pass's length, is also [`reach`]'s second
    /// bound on the pass's approach (the velocities relative to the mean differ as the
    /// velocities do). Marked on the team (a pair to drop gets a NaN distance: a NaN distance
    /// would fail the test as well), then dropped in order.
    fn keep_near(&self, s: &mut Scratch, from: usize) {
        let pairs = &mut s.pairs[from..];
        let (n, out) = (pairs.len(), SharedMut(pairs.as_mut_ptr()));
        let keep = self.keep(s);
        for_each_range(n, PAIR_CHUNK, |r| {
            // SAFETY: each range is its own chunk's.
            for (pair, d0) in unsafe { out.slice(r) } {
                if !keep.keeps(*pair, *d0) {
                    *d0 = f64::NAN;
                }
            }
        });
        let mut pairs = std::mem::take(&mut s.pairs);
        pairs.retain(|&(_, d0)| !d0.is_nan());
        s.pairs = pairs;
    }

    /// [`Ctx::keep_near`]'s test, with the tubes of the last search (or of this one, once its
    /// tubes are set).
    fn keep<'a>(&self, s: &'a Scratch) -> Keep<'a> {
        Keep {
            tube: &s.tube,
            step2: &s.step2,
            tube_len: s.tube_len,
            h: self.h,
            slack: 2.0 * 3f64.sqrt() * s.grow,
            band: PROXIMITY * self.thick,
        }
    }

    /// The vertices `s.out`, out of their tubes at the pass's times `t1 - h` and `t1` (the
    /// surface's mean then `d` from the tubes' reference), get new tubes along their
    /// velocities now relative to the mean (`mean_u`) up to the search's horizon, and boxes
    /// that hold their paths over this pass (as the others' boxes hold theirs: from the
    /// start or from the start less `d[0]`, to the end less `d[1]`) and their tubes; the
    /// candidates with one of their particles are dropped, and the tree queried for their
    /// points', triangles' and edges' pairs, which replace them. The other vertices are in
    /// their tubes and their boxes hold them, so the candidates are what a walk would find,
    /// and more (pairs whose tubes the search would have told apart are kept if their boxes
    /// overlap). The sweeps see the new pairs through their particles' change marks.
    fn search_around(&self, s: &mut Scratch, d: [DVec3; 2], t1: f64, mean_u: DVec3) {
        let margin = 0.5 * PROXIMITY * self.thick + s.grow;
        let out = std::mem::take(&mut s.out);
        s.out_mark.resize(s.p0.len(), false);
        for &i in &out {
            let i = i as usize;
            let w = s.u[i] - mean_u;
            let end = s.p1[i] - d[1];
            let base = end - w * t1;
            s.tube[i] = (base, w);
            s.tube_s[i] = (from_d(base), from_d(w));
            let ahead = end + w * (s.tube_len - t1);
            let path = [s.p0[i], s.p1[i], s.p0[i] - d[0], end, ahead];
            s.tree.set_vertex_box(i as u32, &path, margin);
            s.out_mark[i] = true;
        }
        let (tris, edges) = (&self.surf.triangles, &self.surf.edges);
        s.tree.refit_boxes(tris, edges);
        let mark = &s.out_mark;
        s.pairs
            .retain(|(p, _)| !p.ids().iter().any(|&k| mark[k as usize]));
        let from = s.pairs.len();
        let found = &mut s.found;
        found.clear();
        s.tree.search_around(tris, edges, &out, |f| {
            // Edge pairs in one order, so a pair found from both its edges is one.
            let f = match f {
                Found::EdgeEdge(e, g) => Found::EdgeEdge(e.min(g), e.max(g)),
                f => f,
            };
            found.push(pair_of(f, tris, edges));
        });
        found.sort_unstable_by_key(|p| match *p {
            Pair::PointTriangle(ids) => (0, ids),
            Pair::EdgeEdge(ids) => (1, ids),
        });
        found.dedup();
        s.pairs.extend(found.iter().map(|&p| (p, 0.0)));
        self.start_distances(s, from);
        self.keep_near(s, from);
        for k in from..s.pairs.len() {
            let ids = s.pairs[k].0.ids();
            s.mark(&ids);
        }
        for &i in &out {
            s.out_mark[i as usize] = false;
        }
        s.out = out;
        s.searched_around += 1;
    }

    /// Candidate pairs: swept boxes (start to end, grown by the thickness and `grow`) that
    /// overlap; adjacent pairs (sharing a particle) excluded, and pairs within flat connected
    /// patches culled (see `tree`).
    fn broad_phase(&self, s: &mut Scratch, mean1: DVec3) {
        // Each vertex's path, and its motion on from the path's end at its velocity relative
        // to the surface's mean (a part that swings or slides keeps to it for several
        // passes) over the search's horizon ([`AHEAD`]), all grown by `grow` (how far it may
        // stray before the next search) and half the reach (the tree's boxes): two sets
        // within the reach of each other while they stay within `grow` have overlapping boxes.
        let reach = PROXIMITY * self.thick;
        let verts = &self.surf.vertices;
        let nv = verts.len().max(1) as f64;
        let mean_u = verts.iter().map(|&i| s.u[i as usize]).sum::<DVec3>() / nv;
        let fastest = verts
            .iter()
            .map(|&i| (s.u[i as usize] - mean_u).length_squared())
            .fold(0.0, f64::max)
            .sqrt();
        s.tube_len = (AHEAD_PASSES * self.h).min(AHEAD * self.thick / fastest);
        let grow = if s.tube_len < self.h {
            SHORT_GROW
        } else {
            BROAD_GROW
        } * self.thick;
        (s.grow, s.grow_s) = (grow, grow as Scalar);
        s.tube_ref = mean1;
        s.tube.resize(s.p0.len(), (DVec3::ZERO, DVec3::ZERO));
        s.p2.resize(s.p0.len(), DVec3::ZERO);
        for &i in verts {
            let i = i as usize;
            let w = s.u[i] - mean_u;
            s.tube[i] = (s.p1[i], w);
            s.p2[i] = s.p1[i] + w * s.tube_len;
        }
        let tris = &self.surf.triangles;
        if !s.tree.built_for(tris.len()) {
            s.tree.build(self.surf, &s.p0);
        }
        s.tree.load(verts, &s.p0, &s.p1);
        s.tree.stretch(verts, &s.p2);
        s.tree.refit(tris, &self.surf.edges, 0.5 * reach + grow);
        self.walk_and_keep(s);
        s.cones_at = s.edits;
        s.clear_moved();
    }

    /// Walks the tree (all of it, or with `resume` the nodes no longer flat) and appends the
    /// pairs it finds to the candidates (distance still to be set).
    fn walk(&self, s: &mut Scratch, resume: bool) {
        let (triangles, edges) = (&self.surf.triangles, &self.surf.edges);
        let pairs = &mut s.pairs;
        s.tree.search(triangles, edges, resume, |found| {
            pairs.push((pair_of(found, triangles, edges), 0.0))
        });
        // Headroom of half what a walk found: the count wanders as a resting body settles,
        // and a pass should not allocate each time it passes the last largest.
        let want = s.pairs.len() + s.pairs.len() / 2;
        s.pairs.reserve(want.saturating_sub(s.pairs.len()));
        s.tested += s.tree.triangle_pairs;
    }

    /// A whole search's walk on the team, as the candidates: [`SurfaceTree::plan`]'s pieces
    /// taken by the threads as they come (a fold's pairs lie in a few of them, so fixed
    /// shares would leave one thread most of the work), each walked by the thread that took
    /// it, its pairs measured ([`distances_in_batches`]) and kept by [`Ctx::keep_near`]'s
    /// test as they are found, a batch of [`RAW_PAIRS`] at a time. The kept pairs and the
    /// culled nodes are then taken piece by piece in the plan's order: the candidates, their
    /// order and distances are what one thread walking the whole tree, measuring every pair
    /// and dropping those not kept, would give, on any number of threads.
    fn walk_and_keep(&self, s: &mut Scratch) {
        let (tris, edges) = (&self.surf.triangles, &self.surf.edges);
        let mut pieces = std::mem::take(&mut s.pieces);
        s.tree.plan(false, &mut pieces);
        let threads = current_threads().max(1);
        if s.walkers.len() < threads {
            s.walkers.resize_with(threads, Walker::default);
        }
        s.piece_out
            .reserve(pieces.capacity().saturating_sub(s.piece_out.len()));
        s.piece_out.resize(pieces.len(), PieceOut::default());
        let next = AtomicUsize::new(0);
        let walkers = SharedMut(s.walkers.as_mut_ptr());
        let outs = SharedMut(s.piece_out.as_mut_ptr());
        let keep = self.keep(s);
        let (tree, p0) = (&s.tree, &s.p0);
        let measure = |raw: &mut Vec<(Pair, f64)>, kept: &mut Vec<(Pair, f64)>| {
            measure_and_keep(raw, kept, p0, &keep)
        };
        for_each_chunk(threads, |w| {
            // SAFETY: chunk `w` is walker `w`'s alone (`w < threads <= walkers.len()`).
            let me = unsafe { &mut *walkers.ptr().add(w) };
            let Walker {
                stack,
                raw,
                kept,
                culled,
                tests,
            } = me;
            (*tests, _) = (0, raw.reserve(RAW_PAIRS));
            kept.clear();
            culled.clear();
            loop {
                let k = next.fetch_add(1, Relaxed);
                if k >= pieces.len() {
                    break;
                }
                let (k0, c0) = (kept.len() as u32, culled.len() as u32);
                *tests += tree.walk_piece(pieces[k], tris, edges, stack, culled, &mut |f| {
                    raw.push((pair_of(f, tris, edges), 0.0));
                    if raw.len() == RAW_PAIRS {
                        measure(raw, kept);
                    }
                });
                measure(raw, kept);
                let out = PieceOut {
                    walker: w as u32,
                    kept: [k0, kept.len() as u32],
                    culled: [c0, culled.len() as u32],
                };
                // SAFETY: piece `k` was taken by this thread alone (`k < piece_out.len()`).
                unsafe { *outs.ptr().add(k) = out };
            }
        });
        // One walker took every piece (always, on one thread): its list is the candidates.
        let alone = s
            .piece_out
            .iter()
            .all(|o| o.walker == s.piece_out[0].walker);
        if alone && !s.piece_out.is_empty() {
            std::mem::swap(
                &mut s.pairs,
                &mut s.walkers[s.piece_out[0].walker as usize].kept,
            );
        } else {
            s.pairs.clear();
        }
        for out in &s.piece_out {
            let walker = &s.walkers[out.walker as usize];
            if !alone {
                let [a, b] = out.kept.map(|k| k as usize);
                s.pairs.extend_from_slice(&walker.kept[a..b]);
            }
            let [a, b] = out.culled.map(|k| k as usize);
            s.tree.take_culled(&walker.culled[a..b]);
        }
        let tests = s.walkers[..threads].iter().map(|w| w.tests).sum();
        s.tree.triangle_pairs = tests;
        s.tested += tests;
        // Headroom of half the count (see [`Ctx::walk`]); a walker may take every piece.
        let want = s.pairs.len() + s.pairs.len() / 2;
        s.pairs.reserve(want.saturating_sub(s.pairs.len()));
        let culled = s.walkers[..threads]
            .iter()
            .map(|w| w.culled.len())
            .sum::<usize>();
        for w in &mut s.walkers {
            w.kept.reserve(want.saturating_sub(w.kept.len()));
            w.culled
                .reserve((culled + culled / 2).saturating_sub(w.culled.len()));
        }
        s.pieces = pieces;
    }

    /// The distance at the start of the pass (fixed for the pass: the start does not move) of
    /// each candidate pair from index `from` on: on the team, in chunks of [`PAIR_CHUNK`]
    /// (see [`distances_in_batches`]).
    fn start_distances(&self, s: &mut Scratch, from: usize) {
        let p0 = &s.p0;
        let pairs = &mut s.pairs[from..];
        let n = pairs.len();
        let out = SharedMut(pairs.as_mut_ptr());
        for_each_range(n, PAIR_CHUNK, |r| {
            // SAFETY: each range is its own chunk's.
            distances_in_batches(unsafe { out.slice(r) }, p0);
        });
    }

    /// The pair's closest points at positions `y` (the pair's four points): the stencil
    /// weights, the distance and the unit normal from the second part to the first.
    fn closest(pair: Pair, y: [DVec3; 4]) -> ([f64; 4], f64, DVec3) {
        let (wt, d) = match pair {
            Pair::PointTriangle(..) => {
                let b = closest_on_triangle(y[0], y[1], y[2], y[3]);
                let q = y[1] * b[0] + y[2] * b[1] + y[3] * b[2];
                ([1.0, -b[0], -b[1], -b[2]], y[0] - q)
            }
            Pair::EdgeEdge(..) => {
                let (a, b) = closest_between_segments(y[0], y[1], y[2], y[3]);
                let p = y[0].lerp(y[1], a);
                let q = y[2].lerp(y[3], b);
                ([1.0 - a, a, b - 1.0, -b], p - q)
            }
        };
        let dist = d.length();
        let nrm = if dist > 1e-12 {
            d / dist
        } else {
            // Touching: the plane's normal, either side.
            let c = match pair {
                Pair::PointTriangle(..) => (y[2] - y[1]).cross(y[3] - y[1]),
                Pair::EdgeEdge(..) => (y[1] - y[0]).cross(y[3] - y[2]),
            };
            c.try_normalize().unwrap_or(DVec3::Y)
        };
        (wt, dist, nrm)
    }

    fn relative(st: &Stencil, v: &[DVec3]) -> DVec3 {
        (0..4).map(|k| v[st.idx[k] as usize] * st.wt[k]).sum()
    }

    /// Applies the relative velocity change `dvr` (along any direction) to the pair in
    /// `field` (average or end velocities) with the pair's effective mass.
    fn apply(w: &[f64], field: &mut [DVec3], st: &Stencil, dvr: DVec3) {
        let wm: f64 = (0..4)
            .map(|k| st.wt[k] * st.wt[k] * w[st.idx[k] as usize])
            .sum();
        if wm <= 0.0 {
            return;
        }
        let j = dvr / wm;
        for k in 0..4 {
            let i = st.idx[k] as usize;
            field[i] += j * (st.wt[k] * w[i]);
        }
    }

    /// The pair stops approaching, in the average velocities (the motion over the step) and
    /// in the end velocities, each by its own inelastic impulse: a pair whose end velocities
    /// already separate is left as it is.
    fn inelastic(&self, s: &mut Scratch, st: &Stencil, nrm: DVec3) {
        // One impulse: nothing held before it, and no separation to bound.
        let once = |w: &[f64], field: &mut [DVec3]| {
            Self::restrain(
                w,
                field,
                f64::INFINITY,
                st,
                nrm,
                self.mu,
                &mut (0.0, DVec3::ZERO),
            )
        };
        if once(&s.w, &mut s.u) > 0.0 {
            s.touch(&st.idx);
        }
        once(&s.w, &mut s.vel);
    }

    fn positions(ids: [u32; 4], f: impl Fn(usize) -> DVec3) -> [DVec3; 4] {
        ids.map(|i| f(i as usize))
    }

    /// Takes a candidate pair into the pass's proximity band when it is closer than
    /// [`PROXIMITY`] thicknesses at the start (and the proximity is its own: see
    /// [`Ctx::proper`]), with its closest points and normal there, and restrains it
    /// ([`Ctx::restrain_held`]); `None` when it is not in the band.
    fn proximity_impulse(&self, s: &mut Scratch, pair: Pair, d0: f64) -> Option<f64> {
        if d0 >= PROXIMITY * self.thick {
            return None;
        }
        let ids = pair.ids();
        let y = Self::positions(ids, |i| s.p0[i]);
        let (wt, d, nrm) = Self::closest(pair, y);
        if d >= PROXIMITY * self.thick || !Self::proper(pair, &wt) {
            return None;
        }
        // A point whose nearest point on the triangle lies on its border (one weight zero):
        // the normal tilts off the surfaces' where two layers lie on each other.
        let border = matches!(pair, Pair::PointTriangle(..)) && wt[1..].iter().any(|&b| -b < 1e-6);
        s.held.push(Held {
            st: Stencil { idx: ids, wt },
            nrm,
            again: !border,
            u: (0.0, DVec3::ZERO),
            vel: (0.0, DVec3::ZERO),
        });
        Some(self.restrain_held(s, s.held.len() - 1))
    }

    /// The pair in the proximity band's `slot` stops approaching and separates no faster
    /// than the step made it, with friction (see [`Ctx::restrain`]), in the average and in
    /// the end velocities: by how much its motion over the pass changed (0 when it was
    /// within those bounds and nothing slid).
    fn restrain_held(&self, s: &mut Scratch, slot: usize) -> f64 {
        let held = &mut s.held[slot];
        let (st, nrm) = (held.st, held.nrm);
        // What the step made the pair separate at, in each field: no faster after.
        let cap = |start: &[DVec3]| Self::relative(&st, start).dot(nrm).max(0.0);
        let (cap_u, cap_vel) = (cap(&s.u0), cap(&s.vel0));
        let by = Self::restrain(&s.w, &mut s.u, cap_u, &st, nrm, self.mu, &mut held.u);
        let end = Self::restrain(&s.w, &mut s.vel, cap_vel, &st, nrm, self.mu, &mut held.vel);
        if by > 0.0 {
            s.touch(&st.idx);
        } else if end > 0.0 {
            s.mark(&st.idx);
        }
        by * self.h
    }

    /// Sequential impulses with accumulated impulses (Catto, *Iterative dynamics with
    /// temporal coherence*, GDC 2005) on the pair's relative velocity in `field` (average or
    /// end velocities), `held` being what the pair's impulses changed it by so far this pass,
    /// along `nrm` and across it. Along the normal: an approaching pair stops; one separating
    /// faster than `cap` (what the step made it separate at; other pairs' impulses on
    /// particles it shares) is brought back towards that, but only by undoing its own
    /// pushes, so over the pass a
    /// pair only ever pushes. Across it, friction stops the relative velocity as far as
    /// Coulomb allows, within μ times the pair's push so far, so sweeps that undo and redo a
    /// push give no fresh friction. What a pair's impulses add up to over the pass is so one
    /// impulse within Coulomb's cone, as Bridson et al.'s single inelastic impulse is. How
    /// much the relative velocity changed (0 when nothing did).
    fn restrain(
        w: &[f64],
        field: &mut [DVec3],
        cap: f64,
        st: &Stencil,
        nrm: DVec3,
        mu: f64,
        held: &mut (f64, DVec3),
    ) -> f64 {
        let vr = Self::relative(st, field);
        let vn = vr.dot(nrm);
        let dn = if vn < 0.0 {
            -vn
        } else if vn > cap {
            (cap - vn).max(-held.0)
        } else {
            0.0
        };
        held.0 += dn;
        let budget = mu * held.0.max(0.0);
        let want = held.1 - (vr - nrm * vn);
        let len = want.length();
        let across = if len > budget {
            want * (budget / len)
        } else {
            want
        };
        let dt = across - held.1;
        held.1 = across;
        let change = (nrm * dn + dt).length();
        if change > 0.0 {
            Self::apply(w, field, st, nrm * dn + dt);
        }
        change
    }

    /// Whether a proximity is the pair's own: any point–triangle pair, and edges whose
    /// closest points are interior to both. Otherwise an end of an edge is nearest and a
    /// point–triangle pair of that end covers it; and the direction between the points, tilted
    /// off the surfaces' normal for the nearly parallel edges of two layers lying on each
    /// other, would push sideways and make the layers' stiff in-plane springs ring (measured:
    /// it doubles the kinetic energy of two resting cloths).
    fn proper(pair: Pair, wt: &[f64; 4]) -> bool {
        const END: f64 = 1e-6;
        match pair {
            Pair::PointTriangle(..) => true,
            Pair::EdgeEdge(..) => {
                let (a, b) = (wt[1], -wt[3]);
                a > END && a < 1.0 - END && b > END && b < 1.0 - END
            }
        }
    }

    /// The proximity impulses ([`Ctx::proximity_impulse`]) in Gauss–Seidel sweeps against
    /// the motion the step gave: a layer stopped against the one below pushes that one on,
    /// and an impulse can leave a pair sharing its particles approaching or separating. The
    /// first sweep looks at every candidate; the later ones at those it found in the
    /// proximity band whose particles changed since the last, until no pair's motion over the
    /// pass changed by more than [`SEPARATION_SLACK`] thicknesses. They leave out points
    /// whose nearest point on the triangle is on its border: their normal tilts off the
    /// surfaces' (a point of one layer beside another's edge), and pushing them until they
    /// settled crushed the draping cloth's triangles in its plane (with linearly implicit
    /// Euler at 1/60 s in `f64`, a particle came within 2.9 mm of the triangle beside it at
    /// an 8 mm thickness; 7.5 mm leaving them out, 7.3 mm with one sweep). The number of
    /// pairs in the band.
    fn proximity_sweeps(&self, s: &mut Scratch) -> u32 {
        s.u0.clone_from(&s.u);
        s.vel0.clone_from(&s.vel);
        s.held.clear();
        // A pass's first sweep of any kind sees every candidate; this one starts the count of
        // changes for the later ones.
        s.epoch.begin(Sweep::Proximity);
        let mut off = 0;
        for k in 0..s.pairs.len() {
            let (pair, d0) = s.pairs[k];
            if let Some(by) = self.proximity_impulse(s, pair, d0) {
                off += u32::from(by > SEPARATION_SLACK * self.thick);
            }
        }
        for _ in 1..PROXIMITY_SWEEPS {
            if off == 0 {
                break;
            }
            off = 0;
            let since = s.epoch.begin(Sweep::Proximity);
            for slot in 0..s.held.len() {
                let held = &s.held[slot];
                if held.again && s.changed_since_ids(&held.st.idx, since) {
                    let by = self.restrain_held(s, slot);
                    off += u32::from(by > SEPARATION_SLACK * self.thick);
                }
            }
        }
        s.held.len() as u32
    }

    /// A Gauss–Seidel sweep of `kind` over the candidates whose particles' paths changed
    /// since the last sweep of that kind (the others are as that sweep left them; all of
    /// them, when the candidates are not those it swept: see [`Epochs`]): `visit` looks at a
    /// pair (with its distance at the start) and says whether it acted. The number of pairs
    /// it acted on.
    fn sweep(
        &self,
        s: &mut Scratch,
        kind: Sweep,
        mut visit: impl FnMut(&Self, &mut Scratch, Pair, f64) -> bool,
    ) -> u32 {
        let since = s.epoch.begin(kind);
        let mut acted = 0;
        for k in 0..s.pairs.len() {
            let (pair, d0) = s.pairs[k];
            if s.changed_since(pair, since) && visit(self, s, pair, d0) {
                acted += 1;
            }
        }
        acted
    }

    /// A sweep of [`Ctx::end_separation`]; the number of pairs pushed.
    fn separation_sweep(&self, s: &mut Scratch) -> u32 {
        self.sweep(s, Sweep::Separation, Self::end_separation)
    }

    /// A sweep of continuous detection, each collision answered at once (see
    /// [`Ctx::collision_impulse`]); the number of collisions.
    fn ccd_sweep(&self, s: &mut Scratch) -> u32 {
        self.sweep(s, Sweep::Ccd, |ctx, s, pair, d0| {
            let Some((st, nrm)) = ctx.ccd(s, pair, d0) else {
                return false;
            };
            ctx.collision_impulse(s, &st, nrm);
            true
        })
    }

    /// Pushes the pair apart to the thickness at the end of the pass, in position only (see
    /// the module docs); true when it did.
    fn end_separation(&self, s: &mut Scratch, pair: Pair, d0: f64) -> bool {
        let ids = pair.ids();
        let room = d0 - self.thick;
        if room - reach(&s.step2, &s.u, self.h, pair, room) >= 0.0 {
            return false;
        }
        let y = Self::positions(ids, |i| s.p0[i] + s.u[i] * self.h);
        let (wt, d, nrm) = Self::closest(pair, y);
        if d >= (1.0 - SEPARATION_SLACK) * self.thick || !Self::proper(pair, &wt) {
            return false;
        }
        // Only when the pair is on the same side as at the start (otherwise it crossed: the
        // continuous detection deals with it).
        let y0 = Self::positions(ids, |i| s.p0[i]);
        let r0: DVec3 = (0..4).map(|k| y0[k] * wt[k]).sum();
        if r0.dot(nrm) < 0.0 {
            return false;
        }
        let st = Stencil { idx: ids, wt };
        Self::apply(&s.w, &mut s.u, &st, nrm * ((self.thick - d) / self.h));
        s.touch(&st.idx);
        true
    }

    /// The earliest contact of the pair over the step: (the stencil at that instant, the
    /// unit normal).
    fn ccd(&self, s: &Scratch, pair: Pair, d0: f64) -> Option<(Stencil, DVec3)> {
        let ids = pair.ids();
        let tol = touch_tolerance(self.thick);
        let room = d0 - tol;
        if room - reach(&s.step2, &s.u, self.h, pair, room) > 0.0 {
            return None;
        }
        let x0 = Self::positions(ids, |i| s.p0[i]);
        let dx = Self::positions(ids, |i| s.u[i] * self.h);
        // Coplanarity of the four points along their paths: det(e₁, e₂, e₃) = 0 with eₖ linear
        // in τ; for a point–triangle pair e = (b−a, c−a, p−a), for edges (b−a, d−c, c−a).
        let (ea, eb, ec, da, db, dc) = match pair {
            Pair::PointTriangle(..) => (
                x0[2] - x0[1],
                x0[3] - x0[1],
                x0[0] - x0[1],
                dx[2] - dx[1],
                dx[3] - dx[1],
                dx[0] - dx[1],
            ),
            Pair::EdgeEdge(..) => (
                x0[1] - x0[0],
                x0[3] - x0[2],
                x0[2] - x0[0],
                dx[1] - dx[0],
                dx[3] - dx[2],
                dx[2] - dx[0],
            ),
        };
        let det = |a: DVec3, b: DVec3, c: DVec3| a.cross(b).dot(c);
        let c0 = det(ea, eb, ec);
        let c1 = det(da, eb, ec) + det(ea, db, ec) + det(ea, eb, dc);
        let c2 = det(da, db, ec) + det(da, eb, dc) + det(ea, db, dc);
        let c3 = det(da, db, dc);
        let mut found = None;
        cubic_roots_in_unit(c3, c2, c1, c0, |tau| {
            if found.is_some() {
                return;
            }
            let y = [0, 1, 2, 3].map(|k| x0[k] + dx[k] * tau);
            let (wt, d, nrm) = Self::closest(pair, y);
            if d <= tol {
                found = Some((Stencil { idx: ids, wt }, nrm));
            }
        });
        let (st, mut nrm) = found?;
        // Orient the normal against the approach.
        let vr = Self::relative(&st, &s.u);
        if vr.dot(nrm) > 0.0 {
            nrm = -nrm;
        }
        Some((st, nrm))
    }

    /// Response to a collision: the approach stops (with friction), and the pair separates
    /// by a tenth of the thickness by the step's end in position only. The change is to the
    /// pair's average velocities, so to its whole straight path from the start: with the
    /// approach stopped the pair keeps its distance at the start all along, and a relative
    /// `sep / h` ends it `sep` farther. (Spread over what is left of the pass after the
    /// collision instant instead, a collision near the pass's end moved its pair up to a
    /// thousand times `sep`: 0.8 m at an 8 mm thickness, spikes of elastic energy of
    /// hundreds of joules in a pile stepped a frame at a time.)
    fn collision_impulse(&self, s: &mut Scratch, st: &Stencil, nrm: DVec3) {
        self.inelastic(s, st, nrm);
        let sep = 0.1 * self.thick;
        Self::apply(&s.w, &mut s.u, st, nrm * (sep / self.h));
        s.touch(&st.idx);
    }

    /// All pairs colliding over the step (with the current motion), as their particles.
    fn collisions(&self, s: &mut Scratch) {
        self.ensure_broad(s);
        let mut hits = std::mem::take(&mut s.hits);
        hits.clear();
        for k in 0..s.pairs.len() {
            let (pair, d0) = s.pairs[k];
            if self.ccd(s, pair, d0).is_some() {
                hits.push(pair.ids());
            }
        }
        s.hits = hits;
    }

    /// The fail-safe; true when the motion ends free of collisions.
    fn impact_zones(&self, s: &mut Scratch, rep: &mut SelfContactReport) -> bool {
        let n = s.p0.len();
        s.zone.clear();
        s.zone.extend(0..n as u32);
        for _ in 0..ZONE_ITERATIONS {
            let t0 = Instant::now();
            self.collisions(s);
            rep.broad += t0.elapsed();
            if s.hits.is_empty() {
                return true;
            }
            for k in 0..s.hits.len() {
                let ids = s.hits[k];
                for w in 1..4 {
                    union(&mut s.zone, ids[0], ids[w]);
                }
            }
            rep.zones += self.rigidify(s);
        }
        self.collisions(s);
        s.hits.is_empty()
    }

    /// Moves every zone of more than one particle rigidly with its momentum and angular
    /// momentum (about its centre of mass at the start); then gives the end velocities each
    /// zone's rigid part (momentum and angular momentum about its centre at the end kept; the
    /// relative motion, and only its energy, removed). Returns the number of zones.
    fn rigidify(&self, s: &mut Scratch) -> u32 {
        let n = s.p0.len();
        s.zone_sum.clear();
        s.zone_sum.resize(n, ZoneSum::default());
        for &i in &self.surf.vertices {
            let r = find(&mut s.zone, i) as usize;
            let i = i as usize;
            let z = &mut s.zone_sum[r];
            z.count += 1;
            if s.w[i] == 0.0 {
                z.fixed += 1;
                z.fixed_u += s.u[i];
                z.fixed_v += s.vel[i];
            }
        }
        let zones = self.fit_zones(s, false);
        for &i in &self.surf.vertices {
            let r = find(&mut s.zone, i) as usize;
            let i = i as usize;
            let z = s.zone_sum[r];
            if s.w[i] == 0.0 || z.count < 2 {
                continue;
            }
            let new_end = if z.fixed > 0 {
                // A zone holding pinned or prescribed particles translates with them.
                s.p0[i] + z.fixed_u / z.fixed as f64 * self.h
            } else {
                let turn = glam::DQuat::from_scaled_axis(z.omega * self.h);
                z.xc + z.uc * self.h + turn * (s.p0[i] - z.xc)
            };
            s.u[i] = (new_end - s.p0[i]) / self.h;
            s.step2[i] = (s.u[i] * self.h).length_squared();
        }
        s.edits += 1;
        s.moved_all = true;
        self.fit_zones(s, true);
        for &i in &self.surf.vertices {
            let r = find(&mut s.zone, i) as usize;
            let i = i as usize;
            let z = s.zone_sum[r];
            if s.w[i] == 0.0 || z.count < 2 {
                continue;
            }
            s.vel[i] = if z.fixed > 0 {
                z.fixed_v / z.fixed as f64
            } else {
                z.uc + z.omega.cross(s.p0[i] + s.u[i] * self.h - z.xc)
            };
        }
        zones
    }

    /// Each zone's rigid motion: the centre of mass `xc` of its free particles, their mean
    /// velocity `uc` and the angular velocity `omega` with their angular momentum about `xc` —
    /// at the start with the average velocities (`end` false), or at the end with the end
    /// velocities. Returns the number of zones of more than one particle.
    fn fit_zones(&self, s: &mut Scratch, end: bool) -> u32 {
        let h = self.h;
        let at = |s: &Scratch, i: usize| {
            if end {
                (s.p0[i] + s.u[i] * h, s.vel[i])
            } else {
                (s.p0[i], s.u[i])
            }
        };
        for z in s.zone_sum.iter_mut() {
            (z.m, z.xc, z.uc, z.l, z.inertia) = (
                0.0,
                DVec3::ZERO,
                DVec3::ZERO,
                DVec3::ZERO,
                glam::DMat3::ZERO,
            );
        }
        for &i in &self.surf.vertices {
            let r = find(&mut s.zone, i) as usize;
            let i = i as usize;
            if s.w[i] == 0.0 || s.zone_sum[r].count < 2 {
                continue;
            }
            let (x, v) = at(s, i);
            let m = 1.0 / s.w[i];
            let z = &mut s.zone_sum[r];
            z.m += m;
            z.xc += x * m;
            z.uc += v * m;
        }
        let mut zones = 0;
        for z in s.zone_sum.iter_mut() {
            if z.count > 1 && z.m > 0.0 {
                zones += 1;
                z.xc /= z.m;
                z.uc /= z.m;
            }
        }
        for &i in &self.surf.vertices {
            let r = find(&mut s.zone, i) as usize;
            let i = i as usize;
            if s.w[i] == 0.0 || s.zone_sum[r].count < 2 {
                continue;
            }
            let (x, v) = at(s, i);
            let m = 1.0 / s.w[i];
            let z = &mut s.zone_sum[r];
            let d = x - z.xc;
            z.l += d.cross(v - z.uc) * m;
            z.inertia += glam::DMat3::from_diagonal(DVec3::splat(d.length_squared()) * m)
                - glam::DMat3::from_cols(d * d.x, d * d.y, d * d.z) * m;
        }
        for z in s.zone_sum.iter_mut() {
            z.omega = solve_inertia(z.inertia, z.l);
        }
        zones
    }
}

#[derive(Clone, Copy, Debug, Default)]
struct ZoneSum {
    count: u32,
    fixed: u32,
    fixed_u: DVec3,
    fixed_v: DVec3,
    m: f64,
    xc: DVec3,
    uc: DVec3,
    l: DVec3,
    inertia: glam::DMat3,
    omega: DVec3,
}

fn solve_inertia(i: glam::DMat3, l: DVec3) -> DVec3 {
    // Zones of collinear particles have a singular inertia: regularize by a tiny fraction of
    // its trace (the spin about the line is then zero).
    let tr = i.x_axis.x + i.y_axis.y + i.z_axis.z;
    let reg = i + glam::DMat3::from_diagonal(DVec3::splat(1e-9 * tr.max(1e-30)));
    let det = reg.determinant();
    if det.abs() > 0.0 && det.is_finite() {
        reg.inverse() * l
    } else {
        DVec3::ZERO
    }
}

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let p = parent[parent[i as usize] as usize];
        parent[i as usize] = p;
        i = p;
    }
    i
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        // The smaller index is the root: deterministic.
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        parent[hi as usize] = lo;
    }
}

/// Calls `f` with the roots in `[0, 1]` of `c₃τ³ + c₂τ² + c₁τ + c₀`, ascending: the interval
/// is split at the cubic's critical points and each monotone piece with a sign change (or a
/// zero end) is bisected to round-off.
pub fn cubic_roots_in_unit(c3: f64, c2: f64, c1: f64, c0: f64, mut f: impl FnMut(f64)) {
    let p = |t: f64| ((c3 * t + c2) * t + c1) * t + c0;
    // Critical points: 3c₃τ² + 2c₂τ + c₁ = 0.
    let mut cuts = [0.0, 1.0, 1.0, 1.0];
    let mut nc = 1;
    let (a, b, c) = (3.0 * c3, 2.0 * c2, c1);
    let scale = a.abs().max(b.abs()).max(c.abs());
    if scale > 0.0 {
        if a.abs() > 1e-12 * scale {
            let disc = b * b - 4.0 * a * c;
            if disc >= 0.0 {
                let sq = disc.sqrt();
                let q = -0.5 * (b + b.signum() * sq);
                let mut r = [q / a, if q != 0.0 { c / q } else { q / a }];
                r.sort_by(f64::total_cmp);
                for t in r {
                    if t > 0.0 && t < 1.0 {
                        cuts[nc] = t;
                        nc += 1;
                    }
                }
            }
        } else if b.abs() > 0.0 {
            let t = -c / b;
            if t > 0.0 && t < 1.0 {
                cuts[nc] = t;
                nc += 1;
            }
        }
    }
    cuts[nc] = 1.0;
    cuts[..=nc].sort_by(f64::total_cmp);
    let mut last = f64::NEG_INFINITY;
    let mut emit = |t: f64, f: &mut dyn FnMut(f64)| {
        if t > last + 1e-12 {
            last = t;
            f(t);
        }
    };
    for k in 0..nc {
        let (mut lo, mut hi) = (cuts[k], cuts[k + 1]);
        let (flo, fhi) = (p(lo), p(hi));
        if flo == 0.0 {
            emit(lo, &mut f);
            continue;
        }
        if fhi == 0.0 {
            emit(hi, &mut f);
            continue;
        }
        if (flo < 0.0) == (fhi < 0.0) {
            continue;
        }
        let neg_lo = flo < 0.0;
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            let fm = p(mid);
            if (fm < 0.0) == neg_lo {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo < 1e-13 {
                break;
            }
        }
        // The earlier end of the bracket: a contact is never reported late.
        emit(lo, &mut f);
    }
}

/// Barycentric weights of the point of triangle `abc` closest to `p` (Ericson, *Real-Time
/// Collision Detection*, §5.1.5). A triangle whose corners lie on a line (to within
/// `sin² θ ≤ 10⁻¹⁴` between its sides, where the regions' tests lose their meaning) is the
/// union of its edges: the nearest of their closest points.
pub fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> [f64; 3] {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    if ab.cross(ac).length_squared() <= 1e-14 * ab.length_squared() * ac.length_squared() {
        // On edge `u v` at parameter `t`: the weights of `u` and `v` (their corners' indices).
        let on_edge = |u: DVec3, v: DVec3| {
            let d = v - u;
            let t = ((p - u).dot(d) / d.length_squared().max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
            (p.distance_squared(u + d * t), t)
        };
        let (ab_d, ab_t) = on_edge(a, b);
        let (ac_d, ac_t) = on_edge(a, c);
        let (bc_d, bc_t) = on_edge(b, c);
        return if ab_d <= ac_d && ab_d <= bc_d {
            [1.0 - ab_t, ab_t, 0.0]
        } else if ac_d <= bc_d {
            [1.0 - ac_t, 0.0, ac_t]
        } else {
            [0.0, 1.0 - bc_t, bc_t]
        };
    }
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = va + vb + vc;
    if denom.is_nan() || denom == 0.0 {
        // Degenerate triangle: the nearest of its vertices.
        let da = ap.length_squared();
        let db = bp.length_squared();
        let dc = cp.length_squared();
        return if da <= db && da <= dc {
            [1.0, 0.0, 0.0]
        } else if db <= dc {
            [0.0, 1.0, 0.0]
        } else {
            [0.0, 0.0, 1.0]
        };
    }
    let v = vb / denom;
    let w = vc / denom;
    [1.0 - v - w, v, w]
}

/// Parameters `(s, t)` of the closest points `p₁ + s(q₁ − p₁)` and `p₂ + t(q₂ − p₂)` of two
/// segments (Ericson, *Real-Time Collision Detection*, §5.1.9).
pub fn closest_between_segments(p1: DVec3, q1: DVec3, p2: DVec3, q2: DVec3) -> (f64, f64) {
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p1 - p2;
    let a = d1.length_squared();
    let e = d2.length_squared();
    let f = d2.dot(r);
    let eps = 1e-30;
    if a <= eps && e <= eps {
        return (0.0, 0.0);
    }
    let (s, t);
    if a <= eps {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(r);
        if e <= eps {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(d2);
            let denom = a * e - b * b;
            let mut s0 = if denom > 1e-14 * a * e {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t0 = 0.0;
                s0 = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t0 = 1.0;
                s0 = ((b - c) / a).clamp(0.0, 1.0);
            }
            s = s0;
            t = t0;
        }
    }
    (s, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_roots_match_a_factored_cubic() {
        // (τ − 0.2)(τ − 0.5)(τ − 0.9) = τ³ − 1.6τ² + 0.73τ − 0.09.
        let mut r = vec![];
        cubic_roots_in_unit(1.0, -1.6, 0.73, -0.09, |t| r.push(t));
        assert_eq!(r.len(), 3, "{r:?}");
        for (a, b) in r.iter().zip([0.2, 0.5, 0.9]) {
            assert!((a - b).abs() < 1e-12, "{r:?}");
        }
        // A double root at 0.5 (tangency) and one outside: τ (τ−0.5)² − … shifted: (τ−0.5)²(τ−2).
        let mut r = vec![];
        cubic_roots_in_unit(1.0, -3.0, 2.25, -0.5, |t| r.push(t));
        assert_eq!(r.len(), 1, "{r:?}");
        assert!((r[0] - 0.5).abs() < 1e-6, "{r:?}");
    }

    /// The distance between a pair's parts with its four particles at `y` (Ericson's
    /// closest points, checked against brute force below).
    fn part_distance(pair: Pair, y: [DVec3; 4]) -> f64 {
        Ctx::closest(pair, y).1
    }

    #[test]
    fn reach_bounds_how_much_closer_a_pair_comes_over_the_pass() {
        let mut rnd = crate::math::test_rng(777u64);
        let h = 0.5;
        let ids = [0, 1, 2, 3];
        for case in 0..4000 {
            let pair = if case % 2 == 0 {
                Pair::PointTriangle(ids)
            } else {
                Pair::EdgeEdge(ids)
            };
            let p0 = [0; 4].map(|_| DVec3::new(rnd(), rnd(), rnd()));
            // Each its own velocity, on a common one up to ten times larger.
            let common = DVec3::new(rnd(), rnd(), rnd()) * 10.0 * rnd().abs();
            let u = [0; 4].map(|_| DVec3::new(rnd(), rnd(), rnd()) + common);
            let step2 = u.map(|v| (v * h).length_squared());
            let own = reach(&step2, &u, h, pair, f64::INFINITY);
            let least = reach(&step2, &u, h, pair, f64::NEG_INFINITY);
            assert!(least <= own);
            let d0 = part_distance(pair, p0);
            for k in 1..=32 {
                let tau = k as f64 / 32.0;
                let d = part_distance(pair, [0, 1, 2, 3].map(|i| p0[i] + u[i] * h * tau));
                assert!(
                    d >= d0 - least * tau - 1e-12,
                    "case {case}, τ = {tau}: {d} < {d0} − {least} τ"
                );
            }
        }
        // A common velocity brings nothing closer, however fast.
        let p0 = [DVec3::Z, DVec3::ZERO, DVec3::X, DVec3::Y];
        let u = [DVec3::new(3.0, -40.0, 7.0); 4];
        let step2 = u.map(|v| (v * h).length_squared());
        let pair = Pair::PointTriangle(ids);
        assert_eq!(reach(&step2, &u, h, pair, f64::NEG_INFINITY), 0.0);
        let end = part_distance(pair, [0, 1, 2, 3].map(|i| p0[i] + u[i] * h));
        assert!((end - part_distance(pair, p0)).abs() < 1e-13, "{end}");
        // A point heading straight at the triangle's interior closes by exactly the bound.
        let p0 = [DVec3::new(0.2, 0.2, 1.0), DVec3::ZERO, DVec3::X, DVec3::Y];
        let mut u = [DVec3::new(3.0, -4.0, 0.0); 4];
        u[0].z -= 1.5;
        let step2 = u.map(|v| (v * h).length_squared());
        let least = reach(&step2, &u, h, pair, f64::NEG_INFINITY);
        assert!((least - 0.75).abs() < 1e-15, "{least}");
        let end = part_distance(pair, [0, 1, 2, 3].map(|i| p0[i] + u[i] * h));
        assert!((end - (1.0 - least)).abs() < 1e-15, "{end}");
    }

    /// Two 6 × 6 sheets of 1 cm cells in the plane z = 0 and the plane `gap` above it, the
    /// upper one turned 20° about z and shifted, so that their pairs are of every kind.
    fn two_sheets(gap: f64) -> (ContactSurface, Vec<DVec3>) {
        let (n, edge) = (6u32, 0.01);
        let mut triangles = vec![];
        let mut x = vec![];
        for sheet in 0..2 {
            let base = sheet * n * n;
            let (c, s) = (20f64.to_radians().cos(), 20f64.to_radians().sin());
            for j in 0..n {
                for i in 0..n {
                    let (a, b) = (i as f64 * edge, j as f64 * edge);
                    x.push(if sheet == 0 {
                        DVec3::new(a, b, 0.0)
                    } else {
                        DVec3::new(c * a - s * b + 0.012, s * a + c * b - 0.004, gap)
                    });
                }
            }
            for j in 0..n - 1 {
                for i in 0..n - 1 {
                    let k = base + j * n + i;
                    triangles.push([k, k + 1, k + n + 1]);
                    triangles.push([k, k + n + 1, k + n]);
                }
            }
        }
        (ContactSurface::new(&triangles), x)
    }

    #[test]
    fn no_pass_is_due_before_a_candidate_pair_may_have_closed_its_allowance() {
        // A pass sets each particle's budget; then the particles follow curved paths (their
        // end velocities, each its own acceleration) on a fast common motion (a fall and a
        // drift, which brings no two parts closer). Until `advance` says a pass is due, a
        // candidate pair within the proximity band at the pass's end has come at most
        // PASS_TRAVEL thicknesses closer, and any other stays out of the band by as much
        // less. The upper sheet sinks towards the lower at a steady speed, which strays from
        // nothing: only the pairs' approach speed at the pass's end makes their pass due
        // (the test fails with `slope` left at zero).
        let thick = 0.004;
        let (near, band) = (PROXIMITY * thick, PASS_TRAVEL * thick);
        let mut rnd = crate::math::test_rng(4242u64);
        for _ in 0..20 {
            // 2.5 thicknesses apart at the pass's end: out of the band, within the search's reach.
            let (hp, sink) = (0.1, 0.05);
            let (surface, p) = two_sheets(2.5 * thick + sink * hp);
            let nv = p.len();
            let mut sc = SelfContact::new(
                surface,
                SelfContactParams {
                    thickness: thick,
                    friction: 0.3,
                },
            );
            let jitter = |rnd: &mut dyn FnMut() -> f64, m: f64| DVec3::new(rnd(), rnd(), rnd()) * m;
            let vel: Vec<DVec3> = (0..nv)
                .map(|i| {
                    let down = if i >= nv / 2 { -sink } else { 0.0 };
                    DVec3::new(0.0, 0.0, down) + jitter(&mut rnd, 0.005)
                })
                .collect();
            let acc: Vec<DVec3> = (0..nv).map(|_| jitter(&mut rnd, 0.2)).collect();
            let x0: Vec<Vector> = p.iter().map(|&q| from_d(q)).collect();
            let mut x: Vec<Vector> = (0..nv).map(|i| from_d(p[i] + vel[i] * hp)).collect();
            let mut v: Vec<Vector> = vel.iter().map(|&q| from_d(q)).collect();
            sc.begin_frame(&x0);
            assert!(sc.advance(hp as Scalar, &x, &v), "the first pass is due");
            sc.pass(&mut x, &mut v, &vec![1.0; nv]);
            assert_eq!(
                sc.last.proximity + sc.last.separated + sc.last.collisions,
                0
            );
            let at = |x: &[Vector], pair: Pair| {
                part_distance(pair, pair.ids().map(|i| to_d(x[i as usize])))
            };
            let pairs: Vec<(Pair, f64)> =
                sc.s.pairs
                    .iter()
                    .map(|&(pair, _)| (pair, at(&x, pair)))
                    .collect();
            let across = pairs.iter().filter(|(pair, _)| {
                let ids = pair.ids();
                (ids[0] as usize >= nv / 2) != (ids[3] as usize >= nv / 2)
            });
            assert!(across.count() > 100, "{} candidates", pairs.len());
            let (xe, ve) = (x.clone(), v.clone());
            let dt = 1e-3;
            let mut free = 0;
            for k in 1..=1000 {
                let t = k as f64 * dt;
                let common = DVec3::new(2.0 * t, -9.0 * t - 4.9 * t * t, 0.5 * t);
                let common_v = DVec3::new(2.0, -9.0 - 9.8 * t, 0.5);
                for i in 0..nv {
                    x[i] = from_d(to_d(xe[i]) + to_d(ve[i]) * t + 0.5 * acc[i] * t * t + common);
                    v[i] = from_d(to_d(ve[i]) + acc[i] * t + common_v);
                }
                if sc.advance(dt as Scalar, &x, &v) {
                    break;
                }
                free = k;
                for &(pair, end) in &pairs {
                    let d = at(&x, pair);
                    assert!(d >= end.min(near) - band - 1e-6, "τ = {t}: {d} from {end}");
                }
            }
            // Not at once (a pass is due when the budgets are spent, not before).
            assert!(free >= 20, "{free} steps");
        }
    }

    #[test]
    fn a_pass_names_what_made_it_due() {
        // Everything at rest after a first pass; then one thing at a time that makes the next
        // pass due, each named in the pass's report: a particle moved past its budget (the
        // one furthest past it named), a vertex out of its tube, the horizon, and a frame's
        // end with nothing due.
        let thick = 0.004;
        let (surface, p) = two_sheets(2.5 * thick);
        let nv = p.len();
        let params = SelfContactParams {
            thickness: thick,
            friction: 0.3,
        };
        let mut sc = SelfContact::new(surface, params);
        let x0: Vec<Vector> = p.iter().map(|&q| from_d(q)).collect();
        let (mut x, mut v) = (x0.clone(), vec![Vector::ZERO; nv]);
        let w = vec![1.0; nv];
        let hp: Scalar = 1e-3;
        sc.begin_frame(&x0);
        // No budgets yet: due as at the horizon.
        assert!(sc.advance(hp, &x, &v));
        sc.pass(&mut x, &mut v, &w);
        assert_eq!((sc.last.due_horizon, sc.last.due_particle), (1, None));
        // Two particles of the upper sheet pushed down towards the lower: 2.5 thicknesses
        // apart at rest, a pair's allowance is (2.5 − PROXIMITY + PASS_TRAVEL) thicknesses,
        // each particle's budget half that (1.5 · 4 mm / 2 = 3 mm). Both go past it; the
        // second further.
        let (a, b) = (nv / 2 + 14, nv / 2 + 21);
        let budget = 0.5 * (2.5 - PROXIMITY + PASS_TRAVEL) * thick;
        let mut moved = x.clone();
        moved[a].z -= (budget + 0.2e-3) as Scalar;
        moved[b].z -= (budget + 0.5e-3) as Scalar;
        assert!(sc.advance(hp, &moved, &v));
        sc.pass(&mut moved, &mut v, &w);
        assert_eq!(
            (sc.last.due_budget, sc.last.due_particle),
            (1, Some(b as u32))
        );
        // Moved within its budget (a quarter of it, the others still) over a short step (the
        // search of that pass set the two particles' tubes going down at the speed they
        // came): nothing is due, and the pass then is a frame's end.
        let mut within = moved;
        within[a].z -= (0.25 * budget) as Scalar;
        assert!(!sc.advance(0.1 * hp, &within, &v));
        sc.pass(&mut within, &mut v, &w);
        let frame_end = sc.last;
        assert_eq!(
            (
                frame_end.due_budget,
                frame_end.due_tube,
                frame_end.due_horizon
            ),
            (0, 0, 0)
        );
        assert_eq!(frame_end.due_particle, None);
        // The totals keep the last particle that made a pass due.
        assert_eq!(sc.total.due_particle, Some(b as u32));
        // Two triangles sharing an edge have no candidate pairs (every pair shares a
        // particle): no budget is ever spent, and a vertex moved sideways by twice BROAD_GROW
        // thicknesses (three quarters of that from the surface's mean) leaves its tube.
        let quad = ContactSurface::new(&[[0, 1, 2], [0, 2, 3]]);
        let mut sc1 = SelfContact::new(quad, params);
        let y0: Vec<Vector> = [(0.0, 0.0), (0.01, 0.0), (0.01, 0.01), (0.0, 0.01)]
            .map(|(a, b)| Vector::new(a, b, 0.0))
            .to_vec();
        let (mut y, mut u, w1) = (y0.clone(), vec![Vector::ZERO; 4], vec![1.0; 4]);
        sc1.begin_frame(&y0);
        assert!(sc1.advance(hp, &y, &u));
        sc1.pass(&mut y, &mut u, &w1);
        assert_eq!(sc1.last.candidates, 0);
        let k = 2;
        y[k].x += (2.0 * BROAD_GROW * thick) as Scalar;
        assert!(sc1.advance(hp, &y, &u));
        sc1.pass(&mut y, &mut u, &w1);
        assert_eq!(
            (sc1.last.due_tube, sc1.last.due_particle),
            (1, Some(k as u32))
        );
        // Still, but past the search's horizon (AHEAD_PASSES passes as long as the last).
        assert!(sc1.advance((AHEAD_PASSES as Scalar + 1.0) * hp, &y, &u));
        sc1.pass(&mut y, &mut u, &w1);
        assert_eq!((sc1.last.due_horizon, sc1.last.due_particle), (1, None));
        // Totals and the per-particle counts.
        let t = sc.total;
        assert_eq!(
            (t.passes_run, t.due_budget, t.due_tube, t.due_horizon),
            (3, 1, 0, 1)
        );
        assert_eq!(sc.due_counts()[b], 1);
        assert_eq!(sc.due_counts().iter().sum::<u32>(), 1);
        assert_eq!(sc1.due_counts()[k], 1);
    }

    #[test]
    fn closest_points_against_brute_force() {
        let mut rnd = crate::math::test_rng(12345u64);
        for _ in 0..200 {
            let v = [0; 5].map(|_| DVec3::new(rnd(), rnd(), rnd()));
            let b = closest_on_triangle(v[0], v[1], v[2], v[3]);
            let q = v[1] * b[0] + v[2] * b[1] + v[3] * b[2];
            let d = v[0].distance(q);
            let n = 200;
            for i in 0..=n {
                for j in 0..=(n - i) {
                    let (s, t) = (i as f64 / n as f64, j as f64 / n as f64);
                    let g = v[1] + (v[2] - v[1]) * s + (v[3] - v[1]) * t;
                    assert!(v[0].distance(g) >= d - 1e-12);
                }
            }
            let (s, t) = closest_between_segments(v[0], v[1], v[2], v[3]);
            let d = v[0].lerp(v[1], s).distance(v[2].lerp(v[3], t));
            for i in 0..=n {
                for j in 0..=n {
                    let g = v[0]
                        .lerp(v[1], i as f64 / n as f64)
                        .distance(v[2].lerp(v[3], j as f64 / n as f64));
                    assert!(g >= d - 1e-12);
                }
            }
        }
    }
}
