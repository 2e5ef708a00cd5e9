//! Spring and damper forces by rows: the forces of [`Springs::accumulate_reference`] to
//! round-off, faster, and parallel within one body.
//!
//! Each spring `(a, b)` is stored once in the row of its lower index `i = min(a, b)`, with
//! `j = max(a, b)`; rows are in particle order and a row's springs in order of `j`. Two passes:
//!
//! 1. **Forces.** Every spring's force on `i`, `f = c (x_i − x_j)` with the factor
//!    `c = k (L/l − 1) − b (n·v_r)/l`, goes to its slot of a per-spring buffer — the factors
//!    eight springs at a time with AVX where the processor has it (four in the f64 build), so
//!    square roots and divisions run in parallel lanes, with the scalar loop's operations in
//!    its order (the same bits).
//! 2. **Gather.** Each particle adds the slots of its own row (contiguous: the springs where
//!    it is `i`) and subtracts those of the springs where it is `j` (a list per particle),
//!    each sum in a fixed order.
//!
//! The one-loop reference kernel instead adds into `f[i]` and `f[j]` spring after spring, and
//! each addition waits for the store of the last one to the same particle. The kernel before
//! this one kept each row's sum in a register but still scattered every spring's force to
//! `f_j` as it went, with spill slots where another thread owned `j`: 1.4–1.5× slower than
//! these two passes on a 64² cloth. Here no pass writes where another reads. Both passes are
//! cut into the same chunks of at most [`CHUNK_PARTICLES`] particles (the force pass takes their
//! rows), by the body's size alone, so every sum has the same order on any number of threads,
//! and a thread gathers the slots its own force pass wrote: only the springs that reach into
//! the next chunk pass their forces, and the positions they read, between cores. In a
//! symplectic Euler step the two passes are one pass of the team
//! (`force_gather_set_then`): a chunk's gather waits for the force chunks whose
//! springs reach its particles (on a grid, its own and the one before), not for all of them.
//!
//! Springs that fall into bands (a structured mesh's: many springs with one offset between
//! their particles) are taken by [`super::bands`] instead, in the same chunks and passes: its
//! force pass runs with each chunk's rows, and each particle adds its bands' sums after its
//! row sums.
//!
//! [`Springs::accumulate_reference`]: crate::core::forces::Springs::accumulate_reference

use super::bands::{Bands, LINE};
use super::{ChunkLists, Gather, PhaseFlags, SharedConst, SharedMut};
use crate::core::forces::PackedSpring;
use crate::math::{Scalar, Vector};
use std::sync::Mutex;

/// Most particles per chunk, the unit of parallel work of both passes: the force pass takes the
/// chunk's rows (a cloth's 6 springs a particle: about 9 µs of work on one core, with the
/// gather and sweep that follow), large enough that handing it to a thread costs little.
/// Smaller under Miri.
pub const CHUNK_PARTICLES: usize = super::chunk_limit(1024, 64);

/// A spring's force in the buffer between the two passes: a `Vec3A` (one 16-byte lane group)
/// in the f32 build; in the f64 build a `DVec3` padded to 32 bytes and aligned to them, so the
/// force pass stores a whole AVX register per spring and the gather adds one per slot (a
/// `DVec3`'s 24 bytes straddle registers).
#[cfg(not(feature = "f64"))]
pub(crate) type Slot = Vector;

/// See the f32 build's `Slot`.
#[cfg(feature = "f64")]
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub(crate) struct Slot([f64; 4]);

/// Storing and reading a force in a [`Slot`].
trait SlotExt {
    fn put(v: Vector) -> Self;
    fn get(self) -> Vector;
}

#[cfg(not(feature = "f64"))]
impl SlotExt for Slot {
    #[inline(always)]
    fn put(v: Vector) -> Self {
        v
    }
    #[inline(always)]
    fn get(self) -> Vector {
        self
    }
}

#[cfg(feature = "f64")]
impl SlotExt for Slot {
    #[inline(always)]
    fn put(v: Vector) -> Self {
        Slot([v.x, v.y, v.z, 0.0])
    }
    #[inline(always)]
    fn get(self) -> Vector {
        Vector::new(self.0[0], self.0[1], self.0[2])
    }
}

#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct Col {
    j: u32,
    rest: Scalar,
    k: Scalar,
    damping: Scalar,
}

/// Springs laid out by rows (see the module docs).
#[derive(Debug)]
pub struct SpringRows {
    /// The upper particle, rest length, stiffness and damping of each spring.
    j: Vec<u32>,
    rest: Vec<Scalar>,
    k: Vec<Scalar>,
    damping: Vec<Scalar>,
    /// The lower particle of each spring.
    col_i: Vec<u32>,
    /// Each spring's lower and upper particle as byte offsets into a slice of [`Vector`]s,
    /// for the lane kernels (empty where the offsets would not fit in `u32`: the scalar loop
    /// then takes every spring).
    ends: Vec<[u32; 2]>,
    /// Particle `p`'s row is springs `row_start[p]..row_start[p + 1]`.
    row_start: Vec<u32>,
    /// The springs whose upper particle is `p`: `upper[upper_start[p]..upper_start[p + 1]]`.
    upper_start: Vec<u32>,
    upper: Vec<u32>,
    /// Each spring's force on its lower particle, from the force pass.
    buffer: Mutex<Vec<Slot>>,
    /// Particles per chunk of both passes (see [`super::chunk_size`]).
    chunk: usize,
    /// For each chunk, its particles that springs in another chunk's rows reach.
    border: ChunkLists,
    /// For each chunk, the particles of other chunks its rows reach.
    reach: ChunkLists,
    /// For each chunk: one past the last particle its force pass reads ([`Self::reads`]), and
    /// the first chunk whose force pass reads any of its particles (its gather waits for
    /// that chunk's force pass and those after it, up to its own).
    reads_end: Vec<u32>,
    first_reader: Vec<u32>,
    /// The marks of the fused pass's force chunks (`force_gather_set_then`).
    flags: PhaseFlags,
    /// Each chunk's part of a sum over the springs ([`Self::energy`]).
    partials: Mutex<Vec<f64>>,
    /// The springs of a structured mesh in bands (see [`super::bands`]); the rows above hold
    /// the others.
    bands: Option<Bands>,
    /// The bands' force columns and each chunk's scratch.
    band_buf: Mutex<BandBuf>,
}

/// The buffers of the band kernel: its force columns, shared by the passes, and a scratch
/// per chunk, each from a cache line's start (one line spare in each allocation): two
/// threads' chunks then share no line (a line both write stalls each at every step).
#[derive(Debug, Default)]
struct BandBuf {
    columns: Vec<Scalar>,
    scratch: Vec<Scalar>,
}

impl BandBuf {
    /// The buffers `bands` (if any) need over `chunks` chunks.
    fn for_bands(bands: Option<&Bands>, chunks: usize) -> Mutex<Self> {
        Mutex::new(bands.map_or_else(Self::default, |b| Self {
            columns: vec![0.0; b.buffer_len() + LINE],
            scratch: vec![0.0; b.scratch_len() * chunks + LINE],
        }))
    }

    /// The force columns and the scratch, from their first whole cache lines.
    fn lines(&mut self) -> (&mut [Scalar], &mut [Scalar]) {
        fn from_line(v: &mut [Scalar]) -> &mut [Scalar] {
            let n = v.len().saturating_sub(LINE);
            let skip = v.as_ptr().align_offset(64).min(v.len() - n);
            &mut v[skip..skip + n]
        }
        (from_line(&mut self.columns), from_line(&mut self.scratch))
    }

    /// [`Self::lines`] as pointers, taken once for a step's force chunks and gathers alike.
    fn pointers(&mut self) -> (SharedMut<Scalar>, SharedMut<Scalar>) {
        let (columns, scratch) = self.lines();
        (
            SharedMut(columns.as_mut_ptr()),
            SharedMut(scratch.as_mut_ptr()),
        )
    }
}

/// Whether the lane kernels run on this processor (AVX in the f32 build; AVX2 in the f64
/// build, whose kernels broadcast lanes across the register's halves).
fn lanes() -> bool {
    #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
    return std::arch::is_x86_feature_detected!("avx");
    #[cfg(all(target_arch = "x86_64", feature = "f64"))]
    return std::arch::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// The address particle 0 would have in `x`, which holds the particles from `from` on: with
/// a spring's byte offsets (`ends`) added, its ends' addresses (only ever those within `x`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn based(x: &[Vector], from: usize) -> *const u8 {
    (x.as_ptr() as *const u8).wrapping_sub(from * std::mem::size_of::<Vector>())
}

impl SpringRows {
    /// Lays out `springs` (springs joining a particle to itself exert nothing and are left
    /// out).
    pub fn new(springs: &[PackedSpring]) -> Self {
        let bound = springs
            .iter()
            .map(|s| s.i.max(s.j) as usize + 1)
            .max()
            .unwrap_or(0);
        let chunk = super::chunk_size(bound, CHUNK_PARTICLES);
        // The upper ends of springs that reach from a chunk into another (by their lower
        // particle), whichever kernel takes them.
        let chunk_of = |p: u32| p as usize / chunk;
        let crossing = || {
            (springs.iter().filter(|s| s.i != s.j))
                .map(|s| (s.i.min(s.j), s.i.max(s.j)))
                .filter(|&(i, j)| chunk_of(i) != chunk_of(j))
        };
        let border = ChunkLists::new(crossing().map(|(_, j)| (chunk_of(j), j)));
        let reach = ChunkLists::new(crossing().map(|(i, j)| (chunk_of(i), j)));
        let (bands, others) = Bands::split(springs, bound, chunk);
        let chunks = bound.div_ceil(chunk);
        let mut reads_end: Vec<u32> = (0..chunks)
            .map(|c| {
                let end = ((c + 1) * chunk).min(bound);
                bands.as_ref().map_or(end, |b| b.reads_end(end)) as u32
            })
            .collect();
        for s in springs.iter().filter(|s| s.i != s.j) {
            let e = &mut reads_end[chunk_of(s.i.min(s.j))];
            *e = (*e).max(s.i.max(s.j) + 1);
        }
        let first_reader = super::first_readers(|d| d * chunk, &reads_end);
        let springs = &others[..];
        // Counting sort by the lower index, then by the upper within a row (stable).
        let mut row_start = vec![0u32; bound + 1];
        let mut upper_start = vec![0u32; bound + 1];
        for s in springs.iter().filter(|s| s.i != s.j) {
            row_start[s.i.min(s.j) as usize + 1] += 1;
            upper_start[s.i.max(s.j) as usize + 1] += 1;
        }
        for a in 0..bound {
            row_start[a + 1] += row_start[a];
            upper_start[a + 1] += upper_start[a];
        }
        let total = row_start[bound] as usize;
        let zero = Col {
            j: 0,
            rest: 0.0,
            k: 0.0,
            damping: 0.0,
        };
        let mut cols = vec![zero; total];
        let mut next = row_start.clone();
        for s in springs.iter().filter(|s| s.i != s.j) {
            let a = s.i.min(s.j) as usize;
            cols[next[a] as usize] = Col {
                j: s.i.max(s.j),
                rest: s.rest,
                k: s.k,
                damping: s.damping,
            };
            next[a] += 1;
        }
        let mut col_i = vec![0u32; total];
        for a in 0..bound {
            let (start, end) = (row_start[a] as usize, row_start[a + 1] as usize);
            cols[start..end].sort_by_key(|c| c.j);
            col_i[start..end].fill(a as u32);
        }
        let mut upper = vec![0u32; total];
        let mut next = upper_start.clone();
        for (s, c) in cols.iter().enumerate() {
            upper[next[c.j as usize] as usize] = s as u32;
            next[c.j as usize] += 1;
        }

        // Byte offsets: a load then takes no index arithmetic (the force pass's loop is bound
        // by the processor's vector ports and issue width, and each spring's four loads
        // needed a shift each).
        let size = std::mem::size_of::<Vector>();
        let ends = if bound.saturating_mul(size) <= u32::MAX as usize {
            (cols.iter().zip(&col_i))
                .map(|(c, &i)| [i * size as u32, c.j * size as u32])
                .collect()
        } else {
            Vec::new()
        };
        Self {
            ends,
            j: cols.iter().map(|c| c.j).collect(),
            rest: cols.iter().map(|c| c.rest).collect(),
            k: cols.iter().map(|c| c.k).collect(),
            damping: cols.iter().map(|c| c.damping).collect(),
            col_i,
            row_start,
            upper_start,
            upper,
            buffer: Mutex::new(vec![Slot::default(); total]),
            chunk,
            border,
            reach,
            reads_end,
            first_reader,
            flags: PhaseFlags::new(chunks),
            partials: Mutex::new(vec![0.0; chunks]),
            band_buf: BandBuf::for_bands(bands.as_ref(), chunks),
            bands,
        }
    }

    /// Springs the band kernel takes (the rest are in rows).
    pub fn in_bands(&self) -> usize {
        self.bands.as_ref().map_or(0, Bands::len)
    }

    /// Number of chunks of the force pass (parallel work units).
    pub fn chunks(&self) -> usize {
        self.bound().div_ceil(self.chunk)
    }

    /// Adds the spring forces into `f`, with the dampers' when `v` is given.
    ///
    /// # Safety
    /// `x`, `v` (when given) and `f` hold every particle any spring refers to.
    pub(crate) unsafe fn accumulate(&self, x: &[Vector], v: Option<&[Vector]>, f: &mut [Vector]) {
        let mut guard = self.buffer.lock().unwrap_or_else(|e| e.into_inner());
        let mut bands = self.band_buf.lock().unwrap_or_else(|e| e.into_inner());
        let buf = SharedMut(guard.as_mut_ptr());
        let lines = BandBuf::pointers(&mut bands);
        let slots = SharedConst(buf.ptr() as *const Slot);
        let with_bands = self.with_bands(lines);
        // SAFETY: as the caller guarantees.
        unsafe {
            self.force_pass(x, v, buf, lines);
            super::gather_add(self.gather_of(&with_bands), slots, f);
        }
    }

    /// The gather of the rows, or of the rows and the bands together (`with_bands`).
    fn gather_of<'a>(
        &'a self,
        with_bands: &'a Option<WithBands<'a>>,
    ) -> &'a dyn Gather<Slot = Slot> {
        match with_bands {
            Some(w) => w,
            None => self,
        }
    }

    /// The gather of the rows and the bands together, when there are bands (the band
    /// buffers' columns and scratch as [`BandBuf::pointers`] gives them).
    fn with_bands(
        &self,
        (columns, scratch): (SharedMut<Scalar>, SharedMut<Scalar>),
    ) -> Option<WithBands<'_>> {
        let bands = self.bands.as_ref()?;
        Some(WithBands {
            rows: self,
            bands,
            columns: SharedConst(columns.ptr() as *const Scalar),
            scratch,
        })
    }

    /// Sets `f` to the spring forces (with the dampers' when `damped`), as if it were zeroed
    /// first and [`Self::accumulate`]d into (the same bits), then runs `finish` on each chunk
    /// of particles on the thread that gathered it (see [`super::Chunk`]).
    ///
    /// # Safety
    /// `x`, `v` and `f` hold every particle any spring refers to.
    pub(crate) unsafe fn set_then(
        &self,
        x: &mut [Vector],
        v: &mut [Vector],
        damped: bool,
        f: &mut [Vector],
        finish: super::Finish<'_>,
    ) {
        let mut guard = self.buffer.lock().unwrap_or_else(|e| e.into_inner());
        let mut bands = self.band_buf.lock().unwrap_or_else(|e| e.into_inner());
        let buf = SharedMut(guard.as_mut_ptr());
        let lines = BandBuf::pointers(&mut bands);
        let slots = SharedConst(buf.ptr() as *const Slot);
        let lanes = lanes();
        let force = |c: usize, r: super::Reads<'_>| {
            // SAFETY: the chunk's reads (see `force_gather_set_then`); it writes only its own
            // slots and band entries.
            unsafe { self.force_chunk(c, (r.x, damped.then_some(r.v), r.from), buf, lines, lanes) }
        };
        let reads = |c: usize| self.reads(c);
        let after = |c: usize| self.first_reader[c] as usize;
        let with_bands = self.with_bands(lines);
        // SAFETY: as the caller guarantees; `force` and `reads` as `force_gather_set_then`
        // asks, and `slots` the slots `force` writes. The gathers read the slots and the band
        // columns through pointers, each entry where it lies: no entry a gather reads is
        // written while it runs (it waits for every force chunk that writes one), and no entry
        // a force chunk writes is read meanwhile.
        unsafe {
            super::force_gather_set_then(
                self.gather_of(&with_bands),
                &self.flags,
                force,
                reads,
                after,
                slots,
                x,
                v,
                f,
                finish,
            );
        }
    }

    /// The elastic energy `Σ ½ k (l − L)²`: each spring's in the build's precision, summed in
    /// f64 by chunk of rows on the team, the chunks' sums in order (the same bits on any number
    /// of threads). [`Springs::energy`] to round-off; the divergence guard's check, which on
    /// the caller alone took about 1 % of the bench cloth's steps.
    ///
    /// [`Springs::energy`]: crate::core::forces::Springs::energy
    ///
    /// # Safety
    /// `x` holds every particle any spring refers to.
    pub(crate) unsafe fn energy(&self, x: &[Vector]) -> f64 {
        super::sum_chunks(&self.partials, self.chunks(), |c| {
            let p0 = c * self.chunk;
            let p1 = (p0 + self.chunk).min(self.bound());
            let (s0, s1) = (self.row_start[p0] as usize, self.row_start[p1] as usize);
            let mut sum = 0.0f64;
            for s in s0..s1 {
                // SAFETY: spring indices are below the layout's count; particle indices below
                // the bound the caller guarantees.
                unsafe {
                    let i = *self.col_i.get_unchecked(s) as usize;
                    let j = *self.j.get_unchecked(s) as usize;
                    let d = *x.get_unchecked(i) - *x.get_unchecked(j);
                    let e = d.length() - *self.rest.get_unchecked(s);
                    sum += (0.5 * *self.k.get_unchecked(s) * e * e) as f64;
                }
            }
            if let Some(b) = &self.bands {
                sum += b.energy(p0, p1, x);
            }
            sum
        })
    }

    /// One more than the largest particle index a spring refers to.
    pub fn bound(&self) -> usize {
        self.row_start.len() - 1
    }

    /// The force pass: every spring's force on its lower particle into its slot of `buf`.
    ///
    /// # Safety
    /// `x` and `v` (when given) hold every particle any spring refers to.
    unsafe fn force_pass(
        &self,
        x: &[Vector],
        v: Option<&[Vector]>,
        buf: SharedMut<Slot>,
        (columns, scratch): (SharedMut<Scalar>, SharedMut<Scalar>),
    ) {
        let lanes = lanes();
        super::for_each_chunk(self.chunks(), |c| {
            // SAFETY: as the caller guarantees; a chunk writes only its own springs' slots and
            // its bands' entries.
            unsafe { self.force_chunk(c, (x, v, 0), buf, (columns, scratch), lanes) }
        });
    }

    /// Chunk `c`'s springs: each row spring's force on its lower particle into its slot of
    /// `buf`, each band spring's into its band's force columns (through the chunk's scratch).
    /// `x` and `v` hold the particles from `from` on (at least up to what the chunk reads:
    /// [`Self::reads`]).
    ///
    /// # Safety
    /// `x` and `v` (when given) hold the chunk's reads; `buf` has a slot per spring, the
    /// columns and scratch are the band buffers'; nothing else writes the chunk's slots and
    /// entries meanwhile.
    unsafe fn force_chunk(
        &self,
        c: usize,
        (x, v, from): (&[Vector], Option<&[Vector]>, usize),
        buf: SharedMut<Slot>,
        (columns, scratch): (SharedMut<Scalar>, SharedMut<Scalar>),
        lanes: bool,
    ) {
        let _ = lanes;
        let p = c * self.chunk..((c + 1) * self.chunk).min(self.bound());
        let r = self.row_start[p.start] as usize..self.row_start[p.end] as usize;
        let s1 = r.end;
        // The rows at the chunk's end reach into the next chunk, whose positions (and
        // velocities) another thread's sweep may have written last: asked for now, they
        // arrive while the first rows are evaluated (two threads, the same run: bench
        // cloth 31.3 → 31.0 µs a step, 32² cloth 10.8 → 10.0).
        let reach = self.reach.of(c);
        super::prefetch(x, reach, from);
        if let Some(v) = v {
            super::prefetch(v, reach, from);
        }
        // SAFETY: as the caller guarantees.
        unsafe {
            #[allow(unused_mut)]
            let mut s = r.start;
            #[cfg(target_arch = "x86_64")]
            if lanes && !self.ends.is_empty() {
                s = self.forces_avx(s, s1, (x, v, from), buf.ptr());
            }
            self.forces(s, s1, (x, v, from), buf.ptr());
            if let Some(b) = &self.bands {
                let at = c * b.scratch_len();
                b.forces(
                    p.start,
                    p.end,
                    (x, v, from),
                    columns.ptr(),
                    scratch.ptr().add(at),
                );
            }
        }
    }

    /// The particles chunk `c`'s force pass reads: from its first, up to the farthest upper
    /// end of its springs (of its bands, the chunk and the largest offset after it).
    fn reads(&self, c: usize) -> std::ops::Range<usize> {
        c * self.chunk..self.reads_end[c] as usize
    }

    /// Particle `p`'s row (the slots it adds) and the springs where it is the upper end (the
    /// slots it subtracts).
    ///
    /// # Safety
    /// `p` is below the bound.
    #[inline(always)]
    unsafe fn springs_of(&self, p: usize) -> (std::ops::Range<usize>, &[u32]) {
        // SAFETY: `p + 1` indexes the starts, which have one entry past the bound; the lists
        // hold every spring.
        unsafe {
            let row = *self.row_start.get_unchecked(p) as usize
                ..*self.row_start.get_unchecked(p + 1) as usize;
            let up = *self.upper_start.get_unchecked(p) as usize
                ..*self.upper_start.get_unchecked(p + 1) as usize;
            (row, self.upper.get_unchecked(up))
        }
    }

    /// Particles `p0..p1` add their rows' slots and subtract their upper slots, into
    /// `out[p − p0]` as [`super::Gather::gather_chunk`] says.
    ///
    /// # Safety
    /// `p1 ≤` the bound; `out` points to at least `p1 − p0` vectors; `buf` as
    /// [`super::Gather::gather_chunk`] says.
    #[inline(always)]
    unsafe fn gather(&self, p0: usize, p1: usize, buf: *const Slot, out: *mut Vector, set: bool) {
        for p in p0..p1 {
            // SAFETY: `p` is below the bound; the layout's slots are below the number of
            // springs.
            unsafe {
                let (row, up) = self.springs_of(p);
                let f = out.add(p - p0);
                let base = if set { Vector::ZERO } else { *f };
                if row.is_empty() && up.is_empty() {
                    *f = base;
                    continue;
                }
                // Two terms a round, still added one after another (the same bits as one
                // loop): half the loop branches, and a loop body the processor's front end
                // takes whole wherever the code lands (one loop a term ran the bench cloth's
                // step in 53 µs in one build and 61–64 in others, by where its branches fell).
                let slot = |s: usize| (*buf.add(s)).get();
                let mut plus = Vector::ZERO;
                let mut k = row.start;
                while k + 2 <= row.end {
                    plus = plus + slot(k) + slot(k + 1);
                    k += 2;
                }
                if k < row.end {
                    plus += slot(k);
                }
                let mut minus = Vector::ZERO;
                let mut k = 0;
                while k + 2 <= up.len() {
                    let (a, b) = (*up.get_unchecked(k), *up.get_unchecked(k + 1));
                    minus = minus + slot(a as usize) + slot(b as usize);
                    k += 2;
                }
                if k < up.len() {
                    minus += slot(*up.get_unchecked(k) as usize);
                }
                *f = base + (plus - minus);
            }
        }
    }

    /// Springs `s..s1` one at a time: `c` as in the module docs, the force `d c` into `buf`.
    ///
    /// # Safety
    /// `s1 ≤` the number of springs; particle indices below the bound; `buf` has a slot per
    /// spring.
    #[inline(always)]
    unsafe fn forces(
        &self,
        s: usize,
        s1: usize,
        (x, v, from): (&[Vector], Option<&[Vector]>, usize),
        buf: *mut Slot,
    ) {
        for s in s..s1 {
            // SAFETY: as the caller guarantees.
            unsafe {
                let i = *self.col_i.get_unchecked(s) as usize - from;
                let j = *self.j.get_unchecked(s) as usize - from;
                let (rest, k) = (*self.rest.get_unchecked(s), *self.k.get_unchecked(s));
                let d = *x.get_unchecked(i) - *x.get_unchecked(j);
                let l = d.length();
                let coef = match v {
                    Some(v) => {
                        let inv = if l > 0.0 { 1.0 / l } else { 0.0 };
                        let along = d.dot(*v.get_unchecked(i) - *v.get_unchecked(j)) * inv;
                        // f_i = n (−k (l − L) − b n·v_r) with n = d/l.
                        (-k * (l - rest) - *self.damping.get_unchecked(s) * along) * inv
                    }
                    // −k (l − L) d/l = d·k (L/l − 1); zero-length springs exert nothing.
                    None if l > 0.0 => k * (rest / l - 1.0),
                    None => 0.0,
                };
                *buf.add(s) = Slot::put(d * coef);
            }
        }
    }

    /// Eight springs at a time in AVX: the factors as [`Self::forces`] computes them, lane
    /// by lane with the same operations (no fused multiply-add, so the same bits), and the
    /// forces `d c` into `buf`, from spring `s` on. Returns where it stopped, fewer than
    /// eight springs before `s1`.
    #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
    #[target_feature(enable = "avx")]
    unsafe fn forces_avx(
        &self,
        s: usize,
        s1: usize,
        (x, v, from): (&[Vector], Option<&[Vector]>, usize),
        buf: *mut Slot,
    ) -> usize {
        // SAFETY: as the caller guarantees.
        unsafe {
            match v {
                Some(v) => self.lanes_f32::<true>(s, s1, (x, v, from), buf),
                None => self.lanes_f32::<false>(s, s1, (x, x, from), buf),
            }
        }
    }

    /// [`Self::forces_avx`]'s loop, with the dampers' term when `DAMPED` (`v` is not read
    /// otherwise).
    ///
    /// # Safety
    /// As for [`Self::forces_avx`].
    #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
    #[target_feature(enable = "avx")]
    #[inline]
    unsafe fn lanes_f32<const DAMPED: bool>(
        &self,
        mut s: usize,
        s1: usize,
        (x, v, from): (&[Vector], &[Vector], usize),
        buf: *mut Slot,
    ) -> usize {
        use super::avx::columns;
        use std::arch::x86_64::*;
        // SAFETY: `s + 7 < s1 ≤` the number of springs; the byte offsets address whole
        // `Vec3A`s (16-byte aligned `__m128`s) of `x` and `v`, below the bound the caller
        // guarantees.
        unsafe {
            let zero = _mm256_setzero_ps();
            let one = _mm256_set1_ps(1.0);
            let (xb, vb) = (based(x, from), based(v, from));
            let ends = self.ends.as_ptr();
            let (rest_p, k_p, damping_p) =
                (self.rest.as_ptr(), self.k.as_ptr(), self.damping.as_ptr());
            let at = |b: *const u8, o: u32| _mm_load_ps(b.add(o as usize) as *const f32);
            while s + 8 <= s1 {
                // Each spring's position difference and (damped) velocity difference from
                // one read of its ends.
                let mut d = [_mm_setzero_ps(); 8];
                let mut w = [_mm_setzero_ps(); 8];
                for q in 0..8 {
                    let [oi, oj] = *ends.add(s + q);
                    d[q] = _mm_sub_ps(at(xb, oi), at(xb, oj));
                    if DAMPED {
                        w[q] = _mm_sub_ps(at(vb, oi), at(vb, oj));
                    }
                }
                let [dx, dy, dz, _] = columns(&d);
                let ld = |a: *const Scalar| _mm256_loadu_ps(a.add(s));
                let (rest, k) = (ld(rest_p), ld(k_p));
                let dd = _mm256_add_ps(
                    _mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
                    _mm256_mul_ps(dz, dz),
                );
                let l = _mm256_sqrt_ps(dd);
                let pos = _mm256_cmp_ps::<_CMP_GT_OQ>(l, zero);
                let coef = if DAMPED {
                    let [wx, wy, wz, _] = columns(&w);
                    let inv = _mm256_and_ps(_mm256_div_ps(one, l), pos);
                    let along = _mm256_mul_ps(
                        _mm256_add_ps(
                            _mm256_add_ps(_mm256_mul_ps(dx, wx), _mm256_mul_ps(dy, wy)),
                            _mm256_mul_ps(dz, wz),
                        ),
                        inv,
                    );
                    let neg_k = _mm256_xor_ps(k, _mm256_set1_ps(-0.0));
                    let mag = _mm256_sub_ps(
                        _mm256_mul_ps(neg_k, _mm256_sub_ps(l, rest)),
                        _mm256_mul_ps(ld(damping_p), along),
                    );
                    _mm256_mul_ps(mag, inv)
                } else {
                    let r = _mm256_div_ps(rest, l);
                    _mm256_and_ps(_mm256_mul_ps(k, _mm256_sub_ps(r, one)), pos)
                };
                // d c lane by lane (the products `Vec3A * f32` takes), back to rows.
                let rows = super::avx::rows(
                    _mm256_mul_ps(dx, coef),
                    _mm256_mul_ps(dy, coef),
                    _mm256_mul_ps(dz, coef),
                );
                for (q, row) in rows.into_iter().enumerate() {
                    _mm_store_ps(buf.add(s + q) as *mut f32, row);
                }
                s += 8;
            }
        }
        s
    }
}

impl super::Gather for SpringRows {
    type Slot = Slot;

    fn bound(&self) -> usize {
        SpringRows::bound(self)
    }

    fn chunks(&self) -> usize {
        SpringRows::chunks(self)
    }

    fn range(&self, c: usize) -> std::ops::Range<usize> {
        c * self.chunk..((c + 1) * self.chunk).min(self.bound())
    }

    fn border(&self) -> &ChunkLists {
        &self.border
    }

    /// In registers where the build has a faster form.
    #[inline(always)]
    unsafe fn gather_chunk(
        &self,
        p0: usize,
        p1: usize,
        buf: *const Slot,
        out: *mut Vector,
        set: bool,
    ) {
        // SAFETY: as the caller guarantees.
        unsafe {
            #[cfg(all(target_arch = "x86_64", feature = "f64"))]
            if std::arch::is_x86_feature_detected!("avx") {
                self.gather_avx(p0, p1, buf, out, set);
                return;
            }
            self.gather(p0, p1, buf, out, set);
        }
    }
}

#[cfg(all(target_arch = "x86_64", feature = "f64"))]
impl SpringRows {
    /// Four springs at a time in AVX, in f64: the factors as [`Self::forces`] computes them, lane
    /// by lane with the same operations (no fused multiply-add, so the same bits), and the
    /// forces `d c` into `buf`, from spring `s` on. Returns where it stopped, fewer than
    /// four springs before `s1`.
    ///
    /// Each `DVec3` is loaded whole into a register (a masked load: its 24 bytes, never the
    /// next particle's), the four differences transposed to columns, and the four forces
    /// transposed back and stored as whole 32-byte slots.
    #[target_feature(enable = "avx2")]
    unsafe fn forces_avx(
        &self,
        mut s: usize,
        s1: usize,
        (x, v, from): (&[Vector], Option<&[Vector]>, usize),
        buf: *mut Slot,
    ) -> usize {
        use super::avx::transpose_pd;
        use std::arch::x86_64::*;
        // SAFETY: `s + 3 < s1 ≤` the number of springs; the byte offsets address whole `DVec3`s
        // below the bound the caller guarantees; a masked load reads only the three lanes of its
        // `DVec3`; slots are 32-byte aligned.
        unsafe {
            let zero = _mm256_setzero_pd();
            let one = _mm256_set1_pd(1.0);
            let xyz = _mm256_set_epi64x(0, -1, -1, -1);
            let ends = self.ends.as_ptr();
            while s + 4 <= s1 {
                // The byte offsets of each spring's ends (see `ends`).
                let e = |q: usize| *ends.add(s + q);
                let load =
                    |a: *const u8, o: u32| _mm256_maskload_pd(a.add(o as usize) as *const f64, xyz);
                let diff = |a: &[Vector], q: usize| {
                    let [oi, oj] = e(q);
                    let a = based(a, from);
                    _mm256_sub_pd(load(a, oi), load(a, oj))
                };
                let col = |a: &[Scalar]| _mm256_loadu_pd(a.as_ptr().add(s));
                let d = [diff(x, 0), diff(x, 1), diff(x, 2), diff(x, 3)];
                let [dx, dy, dz, _] = transpose_pd(d[0], d[1], d[2], d[3]);
                let (rest, k) = (col(&self.rest), col(&self.k));
                let dd = _mm256_add_pd(
                    _mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
                    _mm256_mul_pd(dz, dz),
                );
                let l = _mm256_sqrt_pd(dd);
                let pos = _mm256_cmp_pd::<_CMP_GT_OQ>(l, zero);
                let coef = match v {
                    Some(v) => {
                        let [wx, wy, wz, _] =
                            transpose_pd(diff(v, 0), diff(v, 1), diff(v, 2), diff(v, 3));
                        let damping = col(&self.damping);
                        let inv = _mm256_and_pd(_mm256_div_pd(one, l), pos);
                        let along = _mm256_mul_pd(
                            _mm256_add_pd(
                                _mm256_add_pd(_mm256_mul_pd(dx, wx), _mm256_mul_pd(dy, wy)),
                                _mm256_mul_pd(dz, wz),
                            ),
                            inv,
                        );
                        let neg_k = _mm256_xor_pd(k, _mm256_set1_pd(-0.0));
                        let mag = _mm256_sub_pd(
                            _mm256_mul_pd(neg_k, _mm256_sub_pd(l, rest)),
                            _mm256_mul_pd(damping, along),
                        );
                        _mm256_mul_pd(mag, inv)
                    }
                    None => {
                        let r = _mm256_div_pd(rest, l);
                        _mm256_and_pd(_mm256_mul_pd(k, _mm256_sub_pd(r, one)), pos)
                    }
                };
                // Each force is its difference row times its factor broadcast: four
                // shuffles, where a transpose back takes eight.
                let c = [
                    _mm256_permute4x64_pd::<0x00>(coef),
                    _mm256_permute4x64_pd::<0x55>(coef),
                    _mm256_permute4x64_pd::<0xaa>(coef),
                    _mm256_permute4x64_pd::<0xff>(coef),
                ];
                for q in 0..4 {
                    _mm256_store_pd(buf.add(s + q) as *mut f64, _mm256_mul_pd(d[q], c[q]));
                }
                s += 4;
            }
        }
        s
    }

    /// [`Self::gather`] with each slot one AVX register: the same sums, component by
    /// component in the same order, so the same bits.
    ///
    /// # Safety
    /// As for [`Self::gather`].
    #[target_feature(enable = "avx")]
    unsafe fn gather_avx(
        &self,
        p0: usize,
        p1: usize,
        buf: *const Slot,
        out: *mut Vector,
        set: bool,
    ) {
        use std::arch::x86_64::*;
        for p in p0..p1 {
            // SAFETY: as for `gather`; slots are 32-byte aligned.
            unsafe {
                let (row, up) = self.springs_of(p);
                let f = out.add(p - p0);
                let base = if set { Vector::ZERO } else { *f };
                if row.is_empty() && up.is_empty() {
                    *f = base;
                    continue;
                }
                let mut plus = _mm256_setzero_pd();
                for s in row {
                    plus = _mm256_add_pd(plus, _mm256_load_pd(buf.add(s) as *const f64));
                }
                let mut minus = _mm256_setzero_pd();
                for &s in up {
                    let f = buf.add(s as usize) as *const f64;
                    minus = _mm256_add_pd(minus, _mm256_load_pd(f));
                }
                let mut r = [0.0f64; 4];
                _mm256_storeu_pd(r.as_mut_ptr(), _mm256_sub_pd(plus, minus));
                *f = base + Vector::new(r[0], r[1], r[2]);
            }
        }
    }
}

/// The row kernel with its bands, as one gather: each particle's row sums first, then its
/// bands'.
struct WithBands<'a> {
    rows: &'a SpringRows,
    bands: &'a Bands,
    columns: SharedConst<Scalar>,
    scratch: SharedMut<Scalar>,
}

impl super::Gather for WithBands<'_> {
    type Slot = Slot;

    fn bound(&self) -> usize {
        self.rows.bound()
    }

    fn chunks(&self) -> usize {
        self.rows.chunks()
    }

    fn range(&self, c: usize) -> std::ops::Range<usize> {
        <SpringRows as super::Gather>::range(self.rows, c)
    }

    fn border(&self) -> &ChunkLists {
        &self.rows.border
    }

    #[inline(always)]
    unsafe fn gather_chunk(
        &self,
        p0: usize,
        p1: usize,
        buf: *const Slot,
        out: *mut Vector,
        set: bool,
    ) {
        // SAFETY: as the caller guarantees; `p0` starts a chunk (the gathers hand over whole
        // chunks), whose scratch this is.
        unsafe {
            // Every spring in a band (a plain grid): nothing to sum by rows, and the bands set
            // the forces (as `0 + sum`, the bits of adding to zeroed forces).
            let rows = !self.rows.k.is_empty();
            if rows {
                <SpringRows as super::Gather>::gather_chunk(self.rows, p0, p1, buf, out, set);
            }
            let at = p0 / self.rows.chunk * self.bands.scratch_len();
            let out = (out, set && !rows);
            let columns = self.columns.ptr();
            (self.bands).gather(p0, p1, columns, self.scratch.ptr().add(at), out);
        }
    }
}

impl Clone for SpringRows {
    fn clone(&self) -> Self {
        let buffer = self
            .buffer
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        Self {
            j: self.j.clone(),
            rest: self.rest.clone(),
            k: self.k.clone(),
            damping: self.damping.clone(),
            col_i: self.col_i.clone(),
            ends: self.ends.clone(),
            row_start: self.row_start.clone(),
            upper_start: self.upper_start.clone(),
            upper: self.upper.clone(),
            buffer: Mutex::new(buffer),
            chunk: self.chunk,
            border: self.border.clone(),
            reach: self.reach.clone(),
            reads_end: self.reads_end.clone(),
            first_reader: self.first_reader.clone(),
            flags: self.flags.clone(),
            partials: Mutex::new(vec![0.0; self.chunks()]),
            band_buf: BandBuf::for_bands(self.bands.as_ref(), self.chunks()),
            bands: self.bands.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What each chunk's force pass reads, and the first chunk whose reads reach each chunk,
    /// against a direct count over the springs: on a grid (its springs in bands, which read
    /// the largest offset past their chunk) and on random networks with long springs (some
    /// reaching several chunks up, some none).
    #[test]
    fn reads_and_first_readers_match_the_springs() {
        let spring = |i: u32, j: u32| PackedSpring {
            i,
            j,
            rest: 0.1,
            k: 10.0,
            damping: 0.0,
        };
        let w = 64u32;
        let grid: Vec<PackedSpring> = (0..w * w)
            .flat_map(|p| [1, w - 1, w, w + 1, 2, 2 * w].map(move |o| (p, p + o)))
            .filter(|&(_, q)| q < w * w)
            .map(|(p, q)| spring(q, p))
            .collect();
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = move |k: u32| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed % k as u64) as u32
        };
        let mut networks = vec![grid];
        for n in [3000u32, 9000] {
            let mut s: Vec<PackedSpring> = (0..n)
                .map(|_| {
                    let i = rnd(n);
                    let j = if rnd(8) == 0 {
                        rnd(n)
                    } else {
                        (i + rnd(40)).min(n - 1)
                    };
                    spring(i, j)
                })
                .collect();
            s.push(spring(0, n - 1));
            networks.push(s);
        }
        for springs in networks {
            let rows = SpringRows::new(&springs);
            let chunks = rows.chunks();
            assert!(chunks >= 2);
            let bound = rows.bound();
            let first = |c: usize| c * rows.chunk;
            let mut end: Vec<usize> = (0..chunks)
                .map(|c| match &rows.bands {
                    Some(b) => b.reads_end(first(c + 1).min(bound)),
                    None => first(c + 1).min(bound),
                })
                .collect();
            for s in springs.iter().filter(|s| s.i != s.j) {
                let (lo, hi) = (s.i.min(s.j) as usize, s.i.max(s.j) as usize);
                let c = lo / rows.chunk;
                end[c] = end[c].max(hi + 1);
            }
            for c in 0..chunks {
                assert_eq!(rows.reads(c), first(c)..end[c], "chunk {c}");
                let want = (0..=c).find(|&d| end[d] > first(c)).unwrap();
                assert_eq!(rows.first_reader[c] as usize, want, "chunk {c}");
            }
        }
    }
}
