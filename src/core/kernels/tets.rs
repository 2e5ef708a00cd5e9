//! Neo-Hookean tet forces in the build's precision: the forces of
//! [`Tets::accumulate_f64`] (element kernels in f64) to round-off of [`Scalar`], several times
//! faster, and parallel within one body.
//!
//! Each element keeps what its force needs and nothing else: its four particles, the gradients
//! `g₁, g₂, g₃` of its shape functions (`g₀ = −(g₁ + g₂ + g₃)`), its rest volume and the
//! material's `C`, `D`. `F = Σₐ (xₐ − x₀) gₐᵀ` uses edge vectors, which keeps f32 accurate far
//! from the origin. Forces go first to a per-element buffer, then each particle sums its
//! elements' forces in a fixed order (the elements' as given). Both passes are cut into the
//! same chunks of consecutive particles, of about [`CHUNK_PARTICLES`] each and as nearly the
//! same work as the particles allow (see `borders`), an element going with the chunk of
//! its lowest vertex (but for the last few of a chunk's, which go with the chunk before, so
//! that its groups of lanes are whole): no two threads write the same memory, the order of
//! every sum is independent of the thread count, and a thread gathers mostly the slots its own
//! element pass wrote. No chunk's elements read a particle before the chunk's first, so in a
//! symplectic Euler step the two passes are one pass of the team
//! (`force_gather_set_then`), each chunk's gather waiting only for the element chunks
//! that reach its particles.
//!
//! Where the processor has AVX, the element pass takes eight elements at a time (four in the
//! f64 build) from a copy of their data laid out by lanes (`Lanes`): the same operations as
//! `element_forces` in the same order, lane by lane (no fused multiply-add), so the same bits
//! on processors with and without it; only the cube root's first estimate, integer arithmetic
//! on the bits, is taken lane by lane in scalar code.
//!
//! [`Tets::accumulate_f64`]: crate::core::fem::Tets::accumulate_f64

use super::{ChunkLists, PhaseFlags, SharedConst, SharedMut, for_each_chunk};
use crate::core::fem::PackedTet;
use crate::core::fem::element::J_MIN;
use crate::math::{Scalar, ToScalar, Vector};
use std::sync::Mutex;

/// Particles per chunk on average, the unit of parallel work of both passes (a tet mesh has
/// about four elements a particle: 5 to 6 µs of work on one core, elements, gather and sweep).
/// Smaller under Miri.
pub const CHUNK_PARTICLES: usize = super::chunk_limit(128, 32);

/// Elements a chunk's element range is rounded to (the lanes' width in f32, twice it in f64).
const ELEMENT_GROUP: usize = 8;

/// The costs of a chunk's work in tenths of a nanosecond, as `perf` shares them out on one
/// thread of the project's machine (the 5000-tet bench box in f32, 56 µs a step: the element
/// lanes 64 %, 7.4 ns an element; the gather 19 %, 0.54 ns a slot; the sweep 4 %, 1.8 ns a
/// particle; see [`borders`]). An element's forces, in lanes.
const COST_ELEMENT: u64 = 74;
/// A slot gathered (see [`COST_ELEMENT`]).
const COST_SLOT: u64 = 5;
/// A particle's sweep (see [`COST_ELEMENT`]).
const COST_PARTICLE: u64 = 18;

/// The chunks of both passes over `bound` particles, whose slots start at `start` and whose
/// elements (by lowest vertex) start at `below`, as borders `0 = b₀ < b₁ < … = bound`.
///
/// Their number is as [`super::chunk_size`]'s (at most [`CHUNK_PARTICLES`] particles a chunk
/// on average), rounded up to a multiple of four beyond two, and each chunk holds as nearly as
/// the particles allow the same estimated work: [`COST_ELEMENT`] for each element whose lowest
/// vertex it holds, [`COST_SLOT`] for each slot it gathers, [`COST_PARTICLE`] for each of its
/// particles. The team gives each thread the same number of chunks, so on two or four threads
/// each gets the same work. With chunks of the same number of particles, the bench box (11
/// layers of 121 particles) had one chunk a layer and its top layer no elements (they go with
/// their lowest vertex): the second of two threads took six layers' gather and sweep against
/// the first's five, about 2.6 % more work by the costs above. The borders depend on the mesh
/// alone, never on the thread count.
fn borders(start: &[u32], below: &[u32]) -> Vec<u32> {
    let bound = start.len() - 1;
    if bound == 0 {
        return vec![0];
    }
    let mut count = bound.div_ceil(CHUNK_PARTICLES);
    if bound >= CHUNK_PARTICLES {
        count = count.max(2);
    }
    if count > 2 {
        count = count.next_multiple_of(4);
    }
    // The work of the particles before `p`.
    let work = |p: usize| {
        COST_ELEMENT * below[p] as u64 + COST_SLOT * start[p] as u64 + COST_PARTICLE * p as u64
    };
    let total = work(bound);
    let mut b = vec![0u32];
    let mut p = 0;
    for k in 1..count {
        let target = total * k as u64 / count as u64;
        while p < bound && work(p + 1) <= target {
            p += 1;
        }
        // `work(p) ≤ target < work(p + 1)`: the nearer of the two.
        let q = if p < bound && work(p + 1) - target < target - work(p) {
            p + 1
        } else {
            p
        };
        b.push(q.clamp(b[k - 1] as usize + 1, bound - (count - k)) as u32);
    }
    b.push(bound as u32);
    b
}

/// Whether the element lanes run on this processor (AVX).
fn avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    return std::arch::is_x86_feature_detected!("avx");
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// The address particle 0 would have in `x`, which holds the particles from `from` on: with
/// a particle's index added, its address (only ever those within `x`).
#[inline(always)]
fn based(x: &[Vector], from: usize) -> *const Vector {
    x.as_ptr().wrapping_sub(from)
}

#[derive(Clone, Copy, Debug)]
struct Element {
    v: [u32; 4],
    g: [Vector; 3],
    volume: Scalar,
    c: Scalar,
    d: Scalar,
}

/// [`lane::W`] consecutive elements by lanes, for the AVX pass: lane `q` of block `b` is
/// element `W b + q`.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
struct Lanes {
    v: [[u32; lane::W]; 4],
    /// `g[3 (a − 1) + k]`: component `k` of gradient `g_a`, `a = 1, 2, 3`.
    g: [[Scalar; lane::W]; 9],
    volume: [Scalar; lane::W],
    c: [Scalar; lane::W],
    d: [Scalar; lane::W],
}

/// Tets laid out for the fast kernel (see the module docs).
#[derive(Debug)]
pub struct TetForces {
    elements: Vec<Element>,
    /// The elements of every whole group of [`lane::W`], by lanes.
    #[cfg(target_arch = "x86_64")]
    lanes: Vec<Lanes>,
    /// For particle `p`, its element-force slots are `slots[start[p]..start[p + 1]]`, in the
    /// order of the elements as given (so sums do not depend on the layout's order).
    start: Vec<u32>,
    /// Slot `4 t + a`: element `t`'s force on its vertex `a`.
    slots: Vec<u32>,
    buffer: Mutex<Vec<Vector>>,
    /// Chunk `c` of both passes holds particles `borders[c]..borders[c + 1]` (see
    /// [`borders`]).
    borders: Vec<u32>,
    /// The elements of particle chunk `c`, about those whose lowest vertex is in it, are
    /// `elements[element_start[c]..element_start[c + 1]]`.
    element_start: Vec<u32>,
    /// For each chunk, its particles that elements of other chunks reach.
    border: ChunkLists,
    /// For each chunk, the particles of other chunks its elements reach.
    reach: ChunkLists,
    /// Each chunk's part of a sum over the elements ([`Self::energy`]).
    partials: Mutex<Vec<f64>>,
    /// The marks of the fused pass's force chunks (`force_gather_set_then`).
    flags: PhaseFlags,
    /// For each chunk: one past the highest particle its elements read ([`Self::reads`]),
    /// and the first chunk whose elements read any of its particles (its gather waits for
    /// that chunk's force pass and those after it, up to its own).
    reads_end: Vec<u32>,
    first_reader: Vec<u32>,
}

impl TetForces {
    /// Lays out `tets`.
    pub fn new(tets: &[PackedTet]) -> Self {
        let s = |x: f64| x as Scalar;
        Self::layout(
            tets.iter()
                .map(|t| Element {
                    v: t.v,
                    g: [1, 2, 3].map(|a| t.rest.grad[a].to_array().to_scalar()),
                    volume: s(t.rest.volume),
                    c: s(t.material.c),
                    d: s(t.material.d),
                })
                .collect(),
        )
    }

    fn layout(given: Vec<Element>) -> Self {
        let bound = given
            .iter()
            .flat_map(|t| t.v)
            .map(|i| i as usize + 1)
            .max()
            .unwrap_or(0);
        let lowest = |e: &Element| e.v.iter().min().map_or(0, |&p| p as usize);
        // Elements by their lowest vertex (stably), so that a thread's element pass writes mostly
        // the slots its gather reads, and reads its own particles but at the chunks' borders.
        let mut order: Vec<usize> = (0..given.len()).collect();
        order.sort_by_key(|&k| lowest(&given[k]));
        let mut new_index = vec![0usize; given.len()];
        for (k, &g) in order.iter().enumerate() {
            new_index[g] = k;
        }
        let mut start = vec![0u32; bound + 1];
        let mut below = vec![0u32; bound + 1];
        for t in &given {
            for &p in &t.v {
                start[p as usize + 1] += 1;
            }
            below[lowest(t) + 1] += 1;
        }
        for p in 0..bound {
            start[p + 1] += start[p];
            below[p + 1] += below[p];
        }
        let mut next = start.clone();
        let mut slots = vec![0u32; 4 * given.len()];
        for (g, t) in given.iter().enumerate() {
            for (a, &p) in t.v.iter().enumerate() {
                slots[next[p as usize] as usize] = (4 * new_index[g] + a) as u32;
                next[p as usize] += 1;
            }
        }
        let elements: Vec<Element> = order.iter().map(|&k| given[k]).collect();
        let borders = borders(&start, &below);
        // Chunk `c`'s elements: those whose lowest vertex it holds, the border moved up to
        // the next whole group of lanes (so that the lanes take every element but the last
        // few); which chunk evaluates an element changes no bits. Up, never down: a chunk's
        // elements then read no particle before its own (the fused pass's gathers wait only
        // for force chunks before them).
        let group = ELEMENT_GROUP;
        let element_start: Vec<u32> = borders
            .iter()
            .map(|&b| {
                let e = below[b as usize] as usize;
                (if b as usize == bound {
                    e
                } else {
                    e.next_multiple_of(group).min(elements.len())
                }) as u32
            })
            .collect();
        let chunks = borders.len() - 1;
        let chunk_of = |p: u32| borders.partition_point(|&b| b <= p) - 1;
        let crossing = || {
            (0..chunks).flat_map(|c| {
                let (e0, e1) = (element_start[c] as usize, element_start[c + 1] as usize);
                elements[e0..e1]
                    .iter()
                    .flat_map(move |e| e.v.map(|p| (c, p)))
                    .filter(|&(c, p)| chunk_of(p) != c)
            })
        };
        let border = ChunkLists::new(crossing().map(|(_, p)| (chunk_of(p), p)));
        let reach = ChunkLists::new(crossing());
        let reads_end: Vec<u32> = (0..chunks)
            .map(|c| {
                let (e0, e1) = (element_start[c] as usize, element_start[c + 1] as usize);
                (elements[e0..e1].iter().flat_map(|e| e.v))
                    .map(|p| p + 1)
                    .fold(borders[c], u32::max)
            })
            .collect();
        let first_reader = super::first_readers(|d| borders[d] as usize, &reads_end);
        #[cfg(target_arch = "x86_64")]
        let lanes = elements
            .chunks_exact(lane::W)
            .map(|e| Lanes {
                v: std::array::from_fn(|a| std::array::from_fn(|q| e[q].v[a])),
                g: std::array::from_fn(|i| std::array::from_fn(|q| e[q].g[i / 3][i % 3])),
                volume: std::array::from_fn(|q| e[q].volume),
                c: std::array::from_fn(|q| e[q].c),
                d: std::array::from_fn(|q| e[q].d),
            })
            .collect();
        Self {
            #[cfg(target_arch = "x86_64")]
            lanes,
            start,
            slots,
            buffer: Mutex::new(vec![Vector::ZERO; 4 * elements.len()]),
            elements,
            borders,
            partials: Mutex::new(vec![0.0; element_start.len() - 1]),
            element_start,
            border,
            reach,
            flags: PhaseFlags::new(chunks),
            reads_end,
            first_reader,
        }
    }

    /// Number of chunks of the passes (parallel work units).
    pub fn chunks(&self) -> usize {
        self.element_start.len() - 1
    }

    /// The elastic energy `Σ V ψ(F)`: each element's in the build's precision with
    /// [`inv_cbrt`], summed in f64 by chunk on the team, the chunks' sums in order (the same
    /// bits on any number of threads). The reference [`Tets::energy`] to that precision's
    /// round-off, and several times faster (the divergence guard's check).
    ///
    /// [`Tets::energy`]: crate::core::fem::Tets::energy
    ///
    /// # Safety
    /// `x` holds every particle any element refers to.
    pub(crate) unsafe fn energy(&self, x: &[Vector]) -> f64 {
        super::sum_chunks(&self.partials, self.chunks(), |c| {
            let r = self.element_start[c] as usize..self.element_start[c + 1] as usize;
            let mut sum = 0.0;
            for e in &self.elements[r] {
                // SAFETY: the caller guarantees the indices.
                let [fa, fb, fc] = unsafe { deformation(e, x, 0) };
                let j = fa.dot(fb.cross(fc));
                let i1 = fa.dot(fa) + fb.dot(fb) + fc.dot(fc);
                let r = inv_cbrt(j.max(J_MIN as Scalar));
                let psi = e.c * (r * r * i1 - 3.0) + e.d * (j - 1.0) * (j - 1.0);
                sum += (e.volume * psi) as f64;
            }
            sum
        })
    }

    /// One more than the largest particle index used.
    pub fn bound(&self) -> usize {
        self.start.len() - 1
    }

    /// Adds the elastic forces into `f`.
    ///
    /// # Safety
    /// `x` and `f` hold every particle any element refers to.
    pub(crate) unsafe fn accumulate(&self, x: &[Vector], f: &mut [Vector]) {
        let mut guard = self.buffer.lock().unwrap_or_else(|e| e.into_inner());
        // SAFETY: as the caller guarantees.
        unsafe {
            self.force_pass(x, &mut guard);
            super::gather_add(self, SharedConst(guard.as_ptr()), f);
        }
    }

    /// Sets `f` to the elastic forces, as if it were zeroed first and
    /// [`Self::accumulate`]d into (the same bits), then runs `finish` on each chunk of
    /// particles on the thread that gathered it (see [`super::Chunk`]).
    ///
    /// # Safety
    /// `x`, `v` and `f` hold every particle any element refers to.
    pub(crate) unsafe fn set_then(
        &self,
        x: &mut [Vector],
        v: &mut [Vector],
        f: &mut [Vector],
        finish: super::Finish<'_>,
    ) {
        let mut guard = self.buffer.lock().unwrap_or_else(|e| e.into_inner());
        let buf = SharedMut(guard.as_mut_ptr());
        let avx = avx();
        let force = |c: usize, r: super::Reads<'_>| {
            // SAFETY: the chunk's reads (see `force_gather_set_then`); it writes only its own
            // elements' slots.
            unsafe { self.force_chunk(c, (r.x, r.from), buf, avx) }
        };
        let reads = |c: usize| self.reads(c);
        let after = |c: usize| self.first_reader[c] as usize;
        // SAFETY: as the caller guarantees; `force` and `reads` as `force_gather_set_then`
        // asks, and `buf` the slots `force` writes.
        unsafe {
            super::force_gather_set_then(
                self,
                &self.flags,
                force,
                reads,
                after,
                SharedConst(buf.ptr()),
                x,
                v,
                f,
                finish,
            );
        }
    }

    /// The force pass: every element's forces on its four particles into its slots of `buf`.
    ///
    /// # Safety
    /// `x` holds every particle any element refers to.
    unsafe fn force_pass(&self, x: &[Vector], buf: &mut [Vector]) {
        let buf = SharedMut(buf.as_mut_ptr());
        let avx = avx();
        for_each_chunk(self.chunks(), |c| {
            // SAFETY: as the caller guarantees; a chunk writes only its elements' slots.
            unsafe { self.force_chunk(c, (x, 0), buf, avx) }
        });
    }

    /// Chunk `c`'s elements: each one's forces on its four particles into its slots of `buf`.
    /// `x` holds the particles from `from` on (at least what the chunk reads:
    /// [`Self::reads`]).
    ///
    /// # Safety
    /// `x` holds the chunk's reads; `buf` has four slots per element, and nothing else writes
    /// the chunk's meanwhile; `avx` only where the processor has AVX.
    unsafe fn force_chunk(
        &self,
        c: usize,
        (x, from): (&[Vector], usize),
        buf: SharedMut<Vector>,
        avx: bool,
    ) {
        let _ = avx;
        // What the chunk's elements read of other chunks, perhaps written last by another
        // thread's sweep: asked for now, in flight together (see the springs' pass).
        super::prefetch(x, self.reach.of(c), from);
        let (e0, e1) = (
            self.element_start[c] as usize,
            self.element_start[c + 1] as usize,
        );
        // The lanes take whole groups of `W` elements from the layout's start: the
        // elements before the chunk's first whole group, and after its last, one by one.
        #[allow(unused_mut)]
        let (mut head, mut tail) = (e0..e1, e1..e1);
        #[cfg(target_arch = "x86_64")]
        if avx {
            let first = e0.next_multiple_of(lane::W).min(e1);
            head = e0..first;
            // SAFETY: AVX is present; `first` is a multiple of `W` (or `e1`); as below.
            tail = unsafe { self.elements_avx(first..e1, (x, from), buf.ptr()) }..e1;
        }
        for range in [head, tail] {
            for (e, t) in self.elements[range.clone()].iter().zip(range) {
                // SAFETY: the element's particles are in `x`, as the caller guarantees;
                // element `t` writes only its own four slots.
                unsafe {
                    let out = element_forces(e, x, from);
                    let b = buf.ptr().add(4 * t);
                    for (a, fa) in out.into_iter().enumerate() {
                        *b.add(a) = fa;
                    }
                }
            }
        }
    }

    /// The particles chunk `c`'s elements read: from the chunk's first (no element of the
    /// chunk has its lowest vertex before it) to their highest vertex.
    fn reads(&self, c: usize) -> std::ops::Range<usize> {
        self.borders[c] as usize..self.reads_end[c] as usize
    }
}

impl super::Gather for TetForces {
    type Slot = Vector;

    fn bound(&self) -> usize {
        TetForces::bound(self)
    }

    fn chunks(&self) -> usize {
        TetForces::chunks(self)
    }

    fn range(&self, c: usize) -> std::ops::Range<usize> {
        self.borders[c] as usize..self.borders[c + 1] as usize
    }

    fn border(&self) -> &ChunkLists {
        &self.border
    }

    #[inline(always)]
    unsafe fn gather_chunk(
        &self,
        p0: usize,
        p1: usize,
        buf: *const Vector,
        out: *mut Vector,
        set: bool,
    ) {
        for p in p0..p1 {
            // SAFETY: `p` is below the bound; slots are below the buffer's length.
            unsafe {
                let f = out.add(p - p0);
                let base = if set { Vector::ZERO } else { *f };
                let (s0, s1) = (
                    *self.start.get_unchecked(p),
                    *self.start.get_unchecked(p + 1),
                );
                if s0 == s1 {
                    *f = base;
                    continue;
                }
                // Four terms a round, still added one after another (the same bits as one
                // loop), as in the spring gather.
                let mut acc = Vector::ZERO;
                let slot = |s: u32| *buf.add(s as usize);
                let mut list = self
                    .slots
                    .get_unchecked(s0 as usize..s1 as usize)
                    .chunks_exact(4);
                for q in &mut list {
                    acc = acc + slot(q[0]) + slot(q[1]) + slot(q[2]) + slot(q[3]);
                }
                for &q in list.remainder() {
                    acc += slot(q);
                }
                *f = base + acc;
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
impl TetForces {
    /// `element_forces` for the whole groups of [`lane::W`] in `range` (which starts at a
    /// multiple of `W`), into their slots of `buf`; returns where the elements left over start.
    ///
    /// # Safety
    /// As [`Self::accumulate`]; `buf` holds four slots per element; the processor has AVX.
    #[target_feature(enable = "avx")]
    unsafe fn elements_avx(
        &self,
        range: std::ops::Range<usize>,
        (x, from): (&[Vector], usize),
        buf: *mut Vector,
    ) -> usize {
        use lane::*;
        let xb = based(x, from);
        let mut t = range.start;
        while t + W <= range.end {
            // SAFETY: `t + W ≤ m`, so block `t / W` is whole; particle indices are below the
            // bound the caller guarantees; `buf` has the slots; AVX is present.
            unsafe {
                let l = self.lanes.get_unchecked(t / W);
                let p = |a: usize| V(positions(xb, &l.v[a]));
                let x0 = p(0);
                let (e1, e2, e3) = (p(1).sub(x0), p(2).sub(x0), p(3).sub(x0));
                let g: [L; 9] = std::array::from_fn(|i| load(&l.g[i]));
                let fa = e1.scale(g[0]).add(e2.scale(g[3])).add(e3.scale(g[6]));
                let fb = e1.scale(g[1]).add(e2.scale(g[4])).add(e3.scale(g[7]));
                let fc = e1.scale(g[2]).add(e2.scale(g[5])).add(e3.scale(g[8]));
                let (ca, cb, cc) = (fb.cross(fc), fc.cross(fa), fa.cross(fb));
                let j = fa.dot(ca);
                let i1 = add(add(fa.dot(fa), fb.dot(fb)), fc.dot(fc));
                let j_min = splat(J_MIN as Scalar);
                let r = inv_cbrt_lanes(max(j, j_min));
                let a23 = mul(r, r);
                let c = load(&l.c);
                let iso = and(
                    div(mul(mul(mul(splat(-2.0 / 3.0), c), a23), i1), j),
                    greater(j, j_min),
                );
                let two = splat(2.0);
                let s_f = mul(mul(two, c), a23);
                let s_c = add(iso, mul(mul(two, load(&l.d)), sub(j, splat(1.0))));
                let (pa, pb, pc) = (
                    fa.scale(s_f).add(ca.scale(s_c)),
                    fb.scale(s_f).add(cb.scale(s_c)),
                    fc.scale(s_f).add(cc.scale(s_c)),
                );
                let mv = neg(load(&l.volume));
                let f = |a: usize| {
                    pa.scale(g[3 * a])
                        .add(pb.scale(g[3 * a + 1]))
                        .add(pc.scale(g[3 * a + 2]))
                        .scale(mv)
                };
                let (f1, f2, f3) = (f(0), f(1), f(2));
                let f0 = V(f1.add(f2).add(f3).0.map(neg));
                for (a, fa) in [f0, f1, f2, f3].into_iter().enumerate() {
                    store_vectors(fa.0, |q| buf.add(4 * (t + q) + a));
                }
            }
            t += W;
        }
        t
    }
}

/// [`inv_cbrt`] in lanes: the first estimate lane by lane (integer division of the bits), then
/// the same Newton steps.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn inv_cbrt_lanes(x: lane::L) -> lane::L {
    use lane::*;
    let mut a = [0.0; W];
    store(x, &mut a);
    let mut y = load_unaligned(&a.map(inv_cbrt_estimate));
    for _ in 0..INV_CBRT_STEPS {
        let xyyy = mul(mul(mul(x, y), y), y);
        y = mul(y, mul(sub(splat(4.0), xyyy), splat(1.0 / 3.0)));
    }
    y
}

/// `W` 3-vectors by components, with the operations `element_forces` uses on [`Vector`], in
/// the same order (glam's dot sums `(x + y) + z`; its cross takes the same two products).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct V([lane::L; 3]);

#[cfg(target_arch = "x86_64")]
impl V {
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self(std::array::from_fn(|k| lane::add(self.0[k], o.0[k])))
    }

    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Self(std::array::from_fn(|k| lane::sub(self.0[k], o.0[k])))
    }

    #[inline(always)]
    fn scale(self, s: lane::L) -> Self {
        Self(self.0.map(|c| lane::mul(c, s)))
    }

    #[inline(always)]
    fn dot(self, o: Self) -> lane::L {
        use lane::{add, mul};
        let [x, y, z] = std::array::from_fn(|k| mul(self.0[k], o.0[k]));
        add(add(x, y), z)
    }

    #[inline(always)]
    fn cross(self, o: Self) -> Self {
        use lane::{mul, sub};
        let ([ax, ay, az], [bx, by, bz]) = (self.0, o.0);
        Self([
            sub(mul(ay, bz), mul(az, by)),
            sub(mul(az, bx), mul(ax, bz)),
            sub(mul(ax, by), mul(ay, bx)),
        ])
    }
}

/// AVX lanes of the build's precision: eight `f32` or four `f64`. The functions are only
/// inlined into [`TetForces::elements_avx`], which runs where the processor has AVX.
#[cfg(target_arch = "x86_64")]
mod lane {
    #![allow(clippy::undocumented_unsafe_blocks)] // each: AVX, present where inlined
    use crate::math::{Scalar, Vector};
    use std::arch::x86_64::*;

    /// Lanes per register.
    pub const W: usize = 32 / std::mem::size_of::<Scalar>();

    macro_rules! lanes {
        ($l:ty, $ops:tt) => {
            /// One register of lanes.
            pub type L = $l;
            lanes!(@ops $ops);
        };
        (@ops { $($name:ident = $op:ident;)* }) => {
            $(
                #[inline(always)]
                pub fn $name(a: L, b: L) -> L {
                    unsafe { $op(a, b) }
                }
            )*
        };
    }

    #[cfg(not(feature = "f64"))]
    lanes!(__m256, {
        add = _mm256_add_ps;
        sub = _mm256_sub_ps;
        mul = _mm256_mul_ps;
        div = _mm256_div_ps;
        max = _mm256_max_ps;
        and = _mm256_and_ps;
        xor = _mm256_xor_ps;
    });
    #[cfg(feature = "f64")]
    lanes!(__m256d, {
        add = _mm256_add_pd;
        sub = _mm256_sub_pd;
        mul = _mm256_mul_pd;
        div = _mm256_div_pd;
        max = _mm256_max_pd;
        and = _mm256_and_pd;
        xor = _mm256_xor_pd;
    });

    #[inline(always)]
    pub fn splat(v: Scalar) -> L {
        #[cfg(not(feature = "f64"))]
        return unsafe { _mm256_set1_ps(v) };
        #[cfg(feature = "f64")]
        return unsafe { _mm256_set1_pd(v) };
    }

    #[inline(always)]
    pub fn neg(a: L) -> L {
        xor(a, splat(-0.0))
    }

    /// All bits set in the lanes where `a > b` (false for NaN), clear elsewhere.
    #[inline(always)]
    pub fn greater(a: L, b: L) -> L {
        #[cfg(not(feature = "f64"))]
        return unsafe { _mm256_cmp_ps::<_CMP_GT_OQ>(a, b) };
        #[cfg(feature = "f64")]
        return unsafe { _mm256_cmp_pd::<_CMP_GT_OQ>(a, b) };
    }

    /// From an aligned array (the fields of `Lanes`).
    #[inline(always)]
    pub fn load(a: &[Scalar; W]) -> L {
        #[cfg(not(feature = "f64"))]
        return unsafe { _mm256_load_ps(a.as_ptr()) };
        #[cfg(feature = "f64")]
        return unsafe { _mm256_load_pd(a.as_ptr()) };
    }

    #[inline(always)]
    pub fn load_unaligned(a: &[Scalar; W]) -> L {
        #[cfg(not(feature = "f64"))]
        return unsafe { _mm256_loadu_ps(a.as_ptr()) };
        #[cfg(feature = "f64")]
        return unsafe { _mm256_loadu_pd(a.as_ptr()) };
    }

    #[inline(always)]
    pub fn store(v: L, a: &mut [Scalar; W]) {
        #[cfg(not(feature = "f64"))]
        unsafe {
            _mm256_storeu_ps(a.as_mut_ptr(), v)
        };
        #[cfg(feature = "f64")]
        unsafe {
            _mm256_storeu_pd(a.as_mut_ptr(), v)
        };
    }

    /// The x, y, z columns of the particles `idx`, from `x`, particle 0's address (see
    /// `based`).
    ///
    /// # Safety
    /// Every index addresses a particle of the slice `x` was made from.
    #[inline(always)]
    pub unsafe fn positions(x: *const Vector, idx: &[u32; W]) -> [L; 3] {
        let p = |q: usize| unsafe { *x.add(idx[q] as usize) };
        #[cfg(not(feature = "f64"))]
        {
            // `Vec3A` is one `__m128`: transpose eight of them.
            let [cx, cy, cz, _] =
                unsafe { super::super::avx::columns(&std::array::from_fn(|q| p(q).into())) };
            [cx, cy, cz]
        }
        #[cfg(feature = "f64")]
        {
            let v: [Vector; W] = std::array::from_fn(p);
            [v.map(|v| v.x), v.map(|v| v.y), v.map(|v| v.z)].map(|c| load_unaligned(&c))
        }
    }

    /// Writes the `W` vectors whose x, y, z columns are `c` to `at(0)`, …, `at(W − 1)`.
    ///
    /// # Safety
    /// Each `at(q)` is valid for a write of one [`Vector`] (and 16-byte aligned).
    #[inline(always)]
    pub unsafe fn store_vectors(c: [L; 3], at: impl Fn(usize) -> *mut Vector) {
        #[cfg(not(feature = "f64"))]
        for (q, row) in unsafe { super::super::avx::rows(c[0], c[1], c[2]) }
            .into_iter()
            .enumerate()
        {
            unsafe { _mm_store_ps(at(q) as *mut f32, row) };
        }
        #[cfg(feature = "f64")]
        {
            let mut a = [[0.0; W]; 3];
            for (ck, ak) in c.into_iter().zip(&mut a) {
                store(ck, ak);
            }
            let [ax, ay, az] = a;
            for (q, ((x, y), z)) in ax.into_iter().zip(ay).zip(az).enumerate() {
                unsafe { *at(q) = Vector::new(x, y, z) };
            }
        }
    }
}

/// The forces `f_a = −V P g_a` of one element, with CSC417's `P` (see
/// [`NeoHookeanConstants::stress`](crate::core::fem::element::NeoHookeanConstants::stress)).
///
/// # Safety
/// The element's particles are in `x`.
#[inline(always)]
unsafe fn element_forces(e: &Element, x: &[Vector], from: usize) -> [Vector; 4] {
    // SAFETY: the caller guarantees the indices.
    let [fa, fb, fc] = unsafe { deformation(e, x, from) };
    let [g1, g2, g3] = e.g;
    // cof F = J F⁻ᵀ, finite for flat and inverted elements.
    let (ca, cb, cc) = (fb.cross(fc), fc.cross(fa), fa.cross(fb));
    let j = fa.dot(ca);
    let i1 = fa.dot(fa) + fb.dot(fb) + fc.dot(fc);
    let r = inv_cbrt(j.max(J_MIN as Scalar));
    let a23 = r * r;
    let iso = if j > J_MIN as Scalar {
        -2.0 / 3.0 * e.c * a23 * i1 / j
    } else {
        0.0
    };
    let s_f = 2.0 * e.c * a23;
    let s_c = iso + 2.0 * e.d * (j - 1.0);
    // P = s_f F + s_c cof F, by columns; f_a = −V P g_a.
    let (pa, pb, pc) = (
        fa * s_f + ca * s_c,
        fb * s_f + cb * s_c,
        fc * s_f + cc * s_c,
    );
    let mv = -e.volume;
    let f1 = (pa * g1.x + pb * g1.y + pc * g1.z) * mv;
    let f2 = (pa * g2.x + pb * g2.y + pc * g2.z) * mv;
    let f3 = (pa * g3.x + pb * g3.y + pc * g3.z) * mv;
    [-(f1 + f2 + f3), f1, f2, f3]
}

/// The columns of `F = Σ_a (x_a − x_0) g_aᵀ`.
///
/// # Safety
/// The element's particles are in `x`.
#[inline(always)]
unsafe fn deformation(e: &Element, x: &[Vector], from: usize) -> [Vector; 3] {
    let x = based(x, from);
    // SAFETY: the caller guarantees the indices.
    let p = |a: usize| unsafe { *x.add(e.v[a] as usize) };
    let x0 = p(0);
    let (e1, e2, e3) = (p(1) - x0, p(2) - x0, p(3) - x0);
    let [g1, g2, g3] = e.g;
    [
        e1 * g1.x + e2 * g2.x + e3 * g3.x,
        e1 * g1.y + e2 * g2.y + e3 * g3.y,
        e1 * g1.z + e2 * g2.z + e3 * g3.z,
    ]
}

/// `x^(−1/3)` for `x ≥ J_MIN` (the isochoric factor's argument): an exponent-bit estimate
/// refined by Newton's iteration `y ← y (4 − x y³)/3`, which converges quadratically from the
/// estimate's 3 % to the precision's round-off in 3 (f32) or 4 (f64) steps — the library `cbrt`
/// was a third of the element kernel's time.
#[inline(always)]
pub fn inv_cbrt(x: Scalar) -> Scalar {
    let mut y = inv_cbrt_estimate(x);
    for _ in 0..INV_CBRT_STEPS {
        y *= (4.0 - x * y * y * y) * (1.0 / 3.0);
    }
    y
}

/// Newton steps [`inv_cbrt`] takes from [`inv_cbrt_estimate`].
const INV_CBRT_STEPS: usize = if cfg!(feature = "f64") { 4 } else { 3 };

/// [`inv_cbrt`]'s first estimate, from the exponent bits (within 3 %).
#[inline(always)]
fn inv_cbrt_estimate(x: Scalar) -> Scalar {
    #[cfg(not(feature = "f64"))]
    return f32::from_bits(0x54a2_fa8c - x.to_bits() / 3);
    #[cfg(feature = "f64")]
    return f64::from_bits(0x553e_f0ff_289d_d796 - x.to_bits() / 3);
}

impl Clone for TetForces {
    fn clone(&self) -> Self {
        let buffer = self
            .buffer
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        Self {
            elements: self.elements.clone(),
            #[cfg(target_arch = "x86_64")]
            lanes: self.lanes.clone(),
            start: self.start.clone(),
            slots: self.slots.clone(),
            buffer: Mutex::new(buffer),
            borders: self.borders.clone(),
            element_start: self.element_start.clone(),
            border: self.border.clone(),
            reach: self.reach.clone(),
            partials: Mutex::new(vec![0.0; self.chunks()]),
            flags: self.flags.clone(),
            reads_end: self.reads_end.clone(),
            first_reader: self.first_reader.clone(),
        }
    }
}

#[cfg(test)]
mod layout_tests {
    use super::*;
    use crate::core::fem::mesh::TetMesh;
    use crate::core::kernels::Gather;

    /// The elements of `mesh` as the kernel takes them (only their vertices matter here).
    fn elements(mesh: &TetMesh) -> Vec<Element> {
        mesh.tets
            .iter()
            .map(|t| Element {
                v: *t,
                g: [Vector::X, Vector::Y, Vector::Z],
                volume: 1.0,
                c: 1.0,
                d: 1.0,
            })
            .collect()
    }

    /// The chunks of tet boxes (11 layers of 121 particles, as the bench's box; 10 layers of
    /// 441; one of a few particles), laid out as given and with the particles numbered at
    /// random: every element in exactly one chunk, next to its lowest vertex (no farther than
    /// the rounding to whole groups of lanes, where every chunk's elements start); a multiple of
    /// four chunks; each chunk's estimated work within the largest particle's and a group's of
    /// the mean, so that the first half of the chunks (one thread's share of two) holds half
    /// the work to 1 %. Borders at even particle counts fail it (the first chunk of the
    /// 11-layer box 6.5 % over the mean).
    #[test]
    fn chunks_share_the_estimated_work_evenly() {
        let mut rng = crate::math::test_rng(0x2545_f491_4f6c_dd1d);
        for cells in [[10, 10, 10], [20, 20, 9], [2, 1, 1]] {
            let mesh = TetMesh::tet_box([0.1, 0.1, 0.1], cells).unwrap();
            let given = elements(&mesh);
            let n = mesh.vertices.len();
            let mut shuffled = given.clone();
            let mut perm: Vec<u32> = (0..n as u32).collect();
            for i in (1..n).rev() {
                let j = ((rng() + 1.0) / 2.0 * (i + 1) as f64) as usize;
                perm.swap(i, j.min(i));
            }
            for e in &mut shuffled {
                e.v = e.v.map(|p| perm[p as usize]);
            }
            for given in [given, shuffled] {
                let m = given.len();
                let t = TetForces::layout(given);
                let count = t.chunks();
                assert!(count <= 2 || count.is_multiple_of(4), "{count} chunks");
                assert_eq!(t.borders[0], 0);
                assert_eq!(t.borders[count] as usize, n);
                assert!(t.borders.windows(2).all(|w| w[0] < w[1]));
                assert_eq!(t.element_start[0], 0);
                assert_eq!(t.element_start[count] as usize, m);
                assert!(t.element_start.windows(2).all(|w| w[0] <= w[1]));
                // Whole groups of lanes: no element left to the scalar kernel but the last few.
                assert!(
                    t.element_start[..count]
                        .iter()
                        .all(|&e| (e as usize).is_multiple_of(ELEMENT_GROUP))
                );
                let mut below = vec![0u64; n];
                for e in &t.elements {
                    below[*e.v.iter().min().unwrap() as usize] += 1;
                }
                let mut work = vec![0u64; count];
                let mut largest = 0;
                for (c, work_c) in work.iter_mut().enumerate() {
                    let r = t.range(c);
                    for p in r.clone() {
                        let slots = (t.start[p + 1] - t.start[p]) as u64;
                        let w = COST_SLOT * slots + COST_PARTICLE + COST_ELEMENT * below[p];
                        largest = largest.max(w);
                        *work_c += w;
                    }
                    let (e0, e1) = (t.element_start[c] as usize, t.element_start[c + 1] as usize);
                    for (k, e) in t.elements[e0..e1].iter().enumerate() {
                        let low = *e.v.iter().min().unwrap() as usize;
                        // None before the chunk; past it, only among its last group.
                        assert!(
                            r.contains(&low) || (low >= r.end && e1 - e0 - 1 - k < ELEMENT_GROUP),
                            "chunk {c}: element {} of lowest vertex {low} outside {r:?}",
                            e0 + k
                        );
                    }
                }
                // What each chunk's elements read, and the first chunk whose elements read
                // each chunk's particles, counted directly.
                let end: Vec<usize> = (0..count)
                    .map(|c| {
                        let (e0, e1) =
                            (t.element_start[c] as usize, t.element_start[c + 1] as usize);
                        (t.elements[e0..e1].iter().flat_map(|e| e.v))
                            .map(|p| p as usize + 1)
                            .fold(t.borders[c] as usize, usize::max)
                    })
                    .collect();
                for c in 0..count {
                    assert_eq!(t.reads(c), t.range(c).start..end[c], "chunk {c}");
                    let want = (0..=c).find(|&d| end[d] > t.range(c).start).unwrap();
                    assert_eq!(t.first_reader[c] as usize, want, "chunk {c}");
                }
                let total: u64 = work.iter().sum();
                let mean = total as f64 / count as f64;
                let slack = (largest + ELEMENT_GROUP as u64 * COST_ELEMENT) as f64;
                for (c, &w) in work.iter().enumerate() {
                    assert!(
                        (w as f64 - mean).abs() <= slack,
                        "chunk {c}: {w} against {mean}"
                    );
                }
                if count >= 4 {
                    let half: u64 = work[..count / 2].iter().sum();
                    let share = half as f64 / total as f64;
                    assert!((share - 0.5).abs() < 0.01, "{share}");
                }
            }
        }
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;

    /// The AVX pass (eight f32 or four f64 lanes) gives the scalar kernel's bits, element by element: on random
    /// elements of both orientations, elements squashed flat (coplanar vertices) or with two
    /// vertices at one point, elements shrunk to `J = 0.4³ < J_MIN` (the frozen isochoric
    /// branch), and a tail (five or one) that the scalar kernel takes.
    #[test]
    fn lanes_give_the_scalar_bits() {
        if !std::arch::is_x86_feature_detected!("avx") {
            return;
        }
        let mut rng = crate::math::test_rng(0x9e37_79b9_7f4a_7c15u64);
        let mut rnd = move || rng() as Scalar;
        let n = 40;
        let x: Vec<Vector> = (0..n)
            .map(|_| Vector::new(rnd(), rnd(), rnd()) * 0.1 + Vector::new(3.0, -2.0, 1.0))
            .collect();
        let mut x = x;
        // Flat: particle 3 in the plane of 0, 1, 2; coincident: 7 on 4.
        x[3] = x[0] + (x[1] - x[0]) * 0.3 + (x[2] - x[0]) * 0.5;
        x[7] = x[4];
        // A unit right tet (gradients e_x, e_y, e_z) shrunk to 0.4: F = 0.4 I.
        for (a, dx) in [Vector::ZERO, Vector::X, Vector::Y, Vector::Z]
            .into_iter()
            .enumerate()
        {
            x[36 + a] = x[36] + dx * 0.4;
        }
        let m = 8 * 6 + 5;
        let elements: Vec<Element> = (0..m)
            .map(|t| {
                let (v, g) = match t % 4 {
                    0 => ([0, 1, 2, 3], None),
                    1 => ([4, 5, 6, 7], None),
                    2 => ([36, 37, 38, 39], Some([Vector::X, Vector::Y, Vector::Z])),
                    _ => (std::array::from_fn(|a| ((t * 7 + a * 11) % n) as u32), None),
                };
                Element {
                    v,
                    g: g.unwrap_or_else(|| {
                        std::array::from_fn(|_| Vector::new(rnd(), rnd(), rnd()) * 20.0)
                    }),
                    volume: 1e-4 * (1.5 + rnd()),
                    c: 1e5 * (1.5 + rnd()),
                    d: 1e6 * (1.5 + rnd()),
                }
            })
            .collect();
        let forces = TetForces::layout(elements);
        let mut buf = vec![Vector::splat(Scalar::NAN); 4 * m];
        // SAFETY: AVX is present; `x` holds every particle; `buf` four slots per element.
        let rest = unsafe { forces.elements_avx(0..m, (&x, 0), buf.as_mut_ptr()) };
        assert_eq!(rest, m - m % lane::W);
        let mut signs = [0; 3];
        for (t, e) in forces.elements.iter().enumerate().take(rest) {
            // SAFETY: as above.
            let want = unsafe { element_forces(e, &x, 0) };
            for a in 0..4 {
                let got = buf[4 * t + a];
                assert_eq!(
                    got.to_array().map(Scalar::to_bits),
                    want[a].to_array().map(Scalar::to_bits),
                    "element {t}, vertex {a}"
                );
            }
            let p = |a: usize| x[e.v[a] as usize] - x[e.v[0] as usize];
            let col = |k: usize| (1..4).map(|a| p(a) * e.g[a - 1][k]).sum::<Vector>();
            let j = col(0).cross(col(1)).dot(col(2));
            signs[(j > 0.0) as usize + (j > J_MIN as Scalar) as usize] += 1;
        }
        // Every branch is taken: J ≤ 0, 0 < J ≤ J_MIN, J > J_MIN.
        assert!(signs.iter().all(|&k| k > 0), "{signs:?}");
    }
}
