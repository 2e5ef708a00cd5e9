//! Fast force kernels: the same forces as the simple loops in [`crate::core::forces`] and
//! [`crate::core::fem`] (kept there as the references these are tested against), laid out for
//! speed and for parallel evaluation within one body.
//!
//! Two rules shape them:
//! - **Results do not depend on the thread count.** Work is cut into chunks by the size of the
//!   body alone, never by the number of threads, and every particle's forces are summed in an
//!   order fixed by that chunking: one thread running the chunks in turn and many threads
//!   running them at once produce the same bits. No float is ever added atomically.
//! - **A step allocates nothing.** Layouts and their scratch buffers are built once, on the
//!   first evaluation after the topology changed.
//!
//! Both work in two phases: first every element's forces (a spring's on its lower particle,
//! a tet's on its four) into its own slots, several elements at a time in AVX lanes where the
//! processor has it; then every particle sums its slots in a fixed order. On a team of
//! threads, a symplectic Euler step runs both as one pass (`force_gather_set_then`): each
//! chunk's sums wait only for the force chunks that write its slots, not for every thread to
//! finish its forces. [`springs`] keeps
//! springs in rows by their lower particle index, so a particle's own row is contiguous,
//! and hands the springs of a structured mesh (a grid's, which fall into a few offsets
//! between their particles) to [`bands`], which evaluates them on contiguous columns;
//! [`tets`] evaluates neo-Hookean elements in the build's precision with their rest shapes
//! precomputed. [`sweep`] is symplectic Euler's update of every particle, in whole registers
//! in the f64 build.

use crate::math::Vector;

pub mod bands;
pub mod springs;
pub mod sweep;
#[cfg(feature = "parallel")]
pub mod team;
pub mod tets;

/// AVX helpers shared by the f32 kernels.
#[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
pub(crate) mod avx {
    use std::arch::x86_64::*;

    /// The 4×4 transpose of each 128-bit half of `(a, b, c, d)`. From eight 4-lane rows
    /// (`a` = rows 0 and 4, `b` = rows 1 and 5, …) it gives the four 8-lane columns; from four
    /// 8-lane columns it gives the rows back, row `q` in the low half of the `q % 4`-th
    /// register for `q < 4` and in the high half for `q ≥ 4`.
    #[target_feature(enable = "avx")]
    #[inline]
    pub(crate) fn transpose(a: __m256, b: __m256, c: __m256, d: __m256) -> [__m256; 4] {
        let (t0, t1) = (_mm256_unpacklo_ps(a, b), _mm256_unpacklo_ps(c, d));
        let (t2, t3) = (_mm256_unpackhi_ps(a, b), _mm256_unpackhi_ps(c, d));
        let lo = |p: __m256, q: __m256| {
            _mm256_castpd_ps(_mm256_unpacklo_pd(_mm256_castps_pd(p), _mm256_castps_pd(q)))
        };
        let hi = |p: __m256, q: __m256| {
            _mm256_castpd_ps(_mm256_unpackhi_pd(_mm256_castps_pd(p), _mm256_castps_pd(q)))
        };
        [lo(t0, t1), hi(t0, t1), lo(t2, t3), hi(t2, t3)]
    }

    /// Eight 4-lane rows to four 8-lane columns (x, y, z, w of eight vectors).
    #[target_feature(enable = "avx")]
    #[inline]
    pub(crate) fn columns(r: &[__m128; 8]) -> [__m256; 4] {
        transpose(
            _mm256_set_m128(r[4], r[0]),
            _mm256_set_m128(r[5], r[1]),
            _mm256_set_m128(r[6], r[2]),
            _mm256_set_m128(r[7], r[3]),
        )
    }

    /// Three 8-lane columns (x, y, z) to eight 4-lane rows with `w = 0`.
    #[target_feature(enable = "avx")]
    #[inline]
    pub(crate) fn rows(x: __m256, y: __m256, z: __m256) -> [__m128; 8] {
        let t = transpose(x, y, z, _mm256_setzero_ps());
        let lo = |q: usize| _mm256_castps256_ps128(t[q]);
        let hi = |q: usize| _mm256_extractf128_ps::<1>(t[q]);
        [lo(0), lo(1), lo(2), lo(3), hi(0), hi(1), hi(2), hi(3)]
    }
}

/// AVX helpers shared by the f64 kernels.
#[cfg(all(target_arch = "x86_64", feature = "f64"))]
pub(crate) mod avx {
    use std::arch::x86_64::*;

    /// The 4×4 transpose of four 4-lane rows of `f64`: the columns, or from columns the rows.
    #[target_feature(enable = "avx")]
    #[inline]
    pub(crate) fn transpose_pd(a: __m256d, b: __m256d, c: __m256d, d: __m256d) -> [__m256d; 4] {
        let (t0, t1) = (_mm256_unpacklo_pd(a, b), _mm256_unpackhi_pd(a, b));
        let (t2, t3) = (_mm256_unpacklo_pd(c, d), _mm256_unpackhi_pd(c, d));
        [
            _mm256_permute2f128_pd::<0x20>(t0, t2),
            _mm256_permute2f128_pd::<0x20>(t1, t3),
            _mm256_permute2f128_pd::<0x31>(t0, t2),
            _mm256_permute2f128_pd::<0x31>(t1, t3),
        ]
    }

    /// Four packed `DVec3`s (twelve `f64`s in three registers: `x₀y₀z₀x₁`, `y₁z₁x₂y₂`,
    /// `z₂x₃y₃z₃`) to their three columns (x, y, z).
    #[target_feature(enable = "avx")]
    #[inline]
    pub(crate) fn columns3(r0: __m256d, r1: __m256d, r2: __m256d) -> [__m256d; 3] {
        let u0 = _mm256_permute2f128_pd::<0x30>(r0, r1); // x₀ y₀ x₂ y₂
        let u1 = _mm256_permute2f128_pd::<0x21>(r0, r2); // z₀ x₁ z₂ x₃
        let u2 = _mm256_permute2f128_pd::<0x30>(r1, r2); // y₁ z₁ y₃ z₃
        [
            _mm256_blend_pd::<0b1010>(u0, u1),
            _mm256_shuffle_pd::<0b0101>(u0, u2),
            _mm256_blend_pd::<0b1010>(u1, u2),
        ]
    }

    /// [`columns3`] backwards: three columns to four packed `DVec3`s.
    #[target_feature(enable = "avx")]
    #[inline]
    pub(crate) fn rows3(x: __m256d, y: __m256d, z: __m256d) -> [__m256d; 3] {
        let u0 = _mm256_shuffle_pd::<0b0000>(x, y); // x₀ y₀ x₂ y₂
        let u1 = _mm256_blend_pd::<0b1010>(z, x); // z₀ x₁ z₂ x₃
        let u2 = _mm256_shuffle_pd::<0b1111>(y, z); // y₁ z₁ y₃ z₃
        [
            _mm256_permute2f128_pd::<0x20>(u0, u1),
            _mm256_permute2f128_pd::<0x30>(u2, u0),
            _mm256_permute2f128_pd::<0x31>(u1, u2),
        ]
    }
}

/// Runs `job(c)` for every chunk `c` in `0..chunks`: shared with the helpers of the
/// `team::Team` the caller runs in (see [`with_threads`]) when the `parallel` feature is on
/// and there is more than one chunk; one after another otherwise. Jobs must write disjoint
/// memory. The bits are the same either way.
#[inline]
pub(crate) fn for_each_chunk(chunks: usize, job: impl Fn(usize) + Sync + Send) {
    #[cfg(feature = "parallel")]
    if chunks > 1 && team::share(chunks, &job) {
        return;
    }
    for c in 0..chunks {
        job(c);
    }
}

/// Each chunk's mark that the first phase of a two-phase pass ([`for_each_chunk_in_two`]) is
/// done with it: the number of the pass, on a cache line of its own (two: the adjacent-line
/// prefetcher pairs them), so that the thread marking a chunk never shares a line with one
/// waiting for another. Kept by the kernel whose passes they are (sized with its layout, so a
/// pass allocates nothing).
#[derive(Debug, Default)]
#[cfg_attr(not(feature = "parallel"), allow(dead_code))]
pub(crate) struct PhaseFlags {
    pass: std::sync::atomic::AtomicU64,
    done: Vec<Flag>,
}

#[repr(align(128))]
#[derive(Debug, Default)]
#[cfg_attr(not(feature = "parallel"), allow(dead_code))]
struct Flag(std::sync::atomic::AtomicU64);

impl PhaseFlags {
    /// Marks for `chunks` chunks.
    pub(crate) fn new(chunks: usize) -> Self {
        Self {
            pass: Default::default(),
            done: (0..chunks).map(|_| Flag::default()).collect(),
        }
    }
}

impl Clone for PhaseFlags {
    fn clone(&self) -> Self {
        Self::new(self.done.len())
    }
}

/// Runs `first(c)` for every chunk `c` in `0..chunks`, then `second(c)` for every chunk, where
/// `second(c)` needs the first phases of the chunks `after(c)` (a range ending at `c` or
/// before; the marks in `flags` cover them) done and nothing else: on the team (see
/// [`for_each_chunk`]) as one pass, whose threads run their share's first phases and then go
/// on to their second phases, waiting only where one needs a first phase another thread has
/// not finished — instead of two passes and the wait for the slowest thread between them.
/// The bits are the same as one thread running every first phase and then every second.
#[inline]
pub(crate) fn for_each_chunk_in_two(
    chunks: usize,
    flags: &PhaseFlags,
    first: impl Fn(usize) + Sync + Send,
    after: impl Fn(usize) -> std::ops::Range<usize> + Sync + Send,
    second: impl Fn(usize) + Sync + Send,
) {
    #[cfg(feature = "parallel")]
    if chunks > 1 {
        use std::sync::atomic::Ordering::{Acquire, Relaxed, Release};
        // Only the caller counts passes; the chunks compare against this one's number.
        let e = flags.pass.load(Relaxed).wrapping_add(1);
        flags.pass.store(e, Relaxed);
        /// Marks its chunk done when dropped: also when the first phase panics (the team
        /// counts that chunk run and the pass's caller panics after the pass), so that no
        /// second phase waits for ever.
        struct Mark<'a>(Option<&'a Flag>, u64);
        impl Drop for Mark<'_> {
            fn drop(&mut self) {
                if let Some(f) = self.0 {
                    f.0.store(self.1, Release);
                }
            }
        }
        let job = |j: usize| {
            if j < chunks {
                let _mark = Mark(flags.done.get(j), e);
                first(j);
                return;
            }
            let c = j - chunks;
            for d in after(c) {
                let Some(f) = flags.done.get(d) else { continue };
                // The first phases a second one waits for are a share's first work, begun
                // before its thread's second phases (see `team`): a wait is short, unless
                // their thread was descheduled, when the core is yielded to it.
                let mut spins = 0u32;
                while f.0.load(Acquire) != e {
                    spins = spins.saturating_add(1);
                    if spins < 4096 {
                        std::hint::spin_loop();
                    } else {
                        std::thread::yield_now();
                    }
                }
            }
            second(c);
        };
        if team::share_in(chunks, 2, &job) {
            return;
        }
    }
    let _ = (flags, &after);
    for c in 0..chunks {
        first(c);
    }
    for c in 0..chunks {
        second(c);
    }
}

/// For each chunk of a kernel's passes (chunk `d` starting at particle `start(d)`, in
/// ascending order), the first chunk whose force pass reads any of its particles, chunk `c`'s
/// reads ending before particle `reads_end[c]` and starting at or after its own first
/// particle: the first chunk of the range its gather waits for ([`force_gather_set_then`]).
pub(crate) fn first_readers(start: impl Fn(usize) -> usize, reads_end: &[u32]) -> Vec<u32> {
    let chunks = reads_end.len();
    let mut first: Vec<u32> = (0..chunks as u32).collect();
    for (c, &end) in reads_end.iter().enumerate() {
        for (d, f) in first.iter_mut().enumerate().skip(c + 1) {
            if start(d) >= end as usize {
                break;
            }
            *f = (*f).min(c as u32);
        }
    }
    first
}

/// Runs `job(r)` for the consecutive ranges `r` of `chunk` indices that cover `0..n` (the
/// last one shorter), as [`for_each_chunk`] runs chunks: the particle passes' chunking, in one
/// place.
#[inline]
pub(crate) fn for_each_range(
    n: usize,
    chunk: usize,
    job: impl Fn(std::ops::Range<usize>) + Sync + Send,
) {
    for_each_chunk(n.div_ceil(chunk), |c| {
        job(c * chunk..((c + 1) * chunk).min(n))
    });
}

/// `Σ part(c)` over the chunks `0..chunks`, on the team as [`for_each_chunk`] shares them: each
/// chunk's part goes to its entry of `partials` (kept by the kernel, so that the sum allocates
/// nothing once it has as many entries as chunks), and the parts are added in chunk order, so
/// the sum has the same bits on any number of threads.
pub(crate) fn sum_chunks(
    partials: &std::sync::Mutex<Vec<f64>>,
    chunks: usize,
    part: impl Fn(usize) -> f64 + Sync + Send,
) -> f64 {
    sums_chunks(partials, chunks, |c| [part(c)])[0]
}

/// [`sum_chunks`] of `K` sums at once (`partials` holds `K` entries a chunk).
pub(crate) fn sums_chunks<const K: usize>(
    partials: &std::sync::Mutex<Vec<f64>>,
    chunks: usize,
    part: impl Fn(usize) -> [f64; K] + Sync + Send,
) -> [f64; K] {
    let mut partials = partials.lock().unwrap_or_else(|e| e.into_inner());
    if partials.len() < K * chunks {
        partials.resize(K * chunks, 0.0);
    }
    let out = SharedMut(partials.as_mut_ptr());
    for_each_chunk(chunks, |c| {
        let p = part(c);
        // SAFETY: `K c + K ≤ K chunks ≤` the entries; each chunk writes its own `K`.
        unsafe { std::ptr::copy_nonoverlapping(p.as_ptr(), out.ptr().add(K * c), K) }
    });
    let mut sum = [0.0; K];
    for p in partials[..K * chunks].chunks_exact(K) {
        for (s, v) in sum.iter_mut().zip(p) {
            *s += v;
        }
    }
    sum
}

/// One chunk of a fused particle pass (a force kernel's gather and what follows it): its
/// particles' positions, velocities and the forces the kernel has just set for them.
pub struct Chunk<'a> {
    /// The particles' indices.
    pub range: std::ops::Range<usize>,
    /// Their positions.
    pub x: &'a mut [Vector],
    /// Their velocities.
    pub v: &'a mut [Vector],
    /// Their forces.
    pub f: &'a mut [Vector],
}

/// What a fused pass does with each chunk once its forces are set: add the per-particle
/// forces, sweep, check (see [`crate::core::particles`]'s symplectic Euler).
pub type Finish<'a> = &'a (dyn Fn(Chunk<'_>) + Sync);

/// A limit on the size of a pass's chunks: `normal`, or `small` when Miri interprets the
/// crate, so that the bodies it can interpret in minutes still make several chunks and the
/// team's hand-offs run (`miri/`). Sums follow the chunks, so a Miri build's bits may differ
/// from a normal build's; within either they do not depend on the thread count.
pub(crate) const fn chunk_limit(normal: usize, small: usize) -> usize {
    if cfg!(miri) { small } else { normal }
}

/// The particles per chunk of a body's passes: at most `most`, at least two chunks when the
/// body has `most` particles or more (so that it still shares its work), and as even as that
/// allows, so that no chunk is a sliver that leaves a thread short. It depends on the body
/// alone, never on the thread count.
pub(crate) fn chunk_size(n: usize, most: usize) -> usize {
    let chunks = n.div_ceil(most).max(if n >= most { 2 } else { 1 });
    n.div_ceil(chunks).max(1)
}

/// A list of indices for each chunk of a pass: `items[start[c]..start[c + 1]]` for chunk `c`
/// (the particles of a chunk that another chunk's elements read, for
/// [`force_gather_set_then`]).
#[derive(Clone, Debug, Default)]
pub(crate) struct ChunkLists {
    start: Vec<u32>,
    items: Vec<u32>,
}

impl ChunkLists {
    /// From `(chunk, item)` pairs, in any order, with repeats; each list sorted.
    pub(crate) fn new(pairs: impl Iterator<Item = (usize, u32)>) -> Self {
        let mut pairs: Vec<(usize, u32)> = pairs.collect();
        pairs.sort_unstable();
        pairs.dedup();
        let chunks = pairs.last().map_or(0, |&(c, _)| c + 1);
        let mut start = vec![0u32; chunks + 1];
        for &(c, _) in &pairs {
            start[c + 1] += 1;
        }
        for c in 0..chunks {
            start[c + 1] += start[c];
        }
        Self {
            start,
            items: pairs.into_iter().map(|(_, i)| i).collect(),
        }
    }

    /// Chunk `c`'s list (empty past the last chunk with one).
    pub(crate) fn of(&self, c: usize) -> &[u32] {
        match (self.start.get(c), self.start.get(c + 1)) {
            (Some(&a), Some(&b)) => &self.items[a as usize..b as usize],
            _ => &[],
        }
    }
}

/// Writes back each element `i` of `items` (indices into `s`, from `s[0]`), unchanged, once
/// per cache line: the line's copies in other cores' caches are invalidated now, while the
/// caller goes on, instead of when it next stores there. A store to a line another core holds
/// waits for that core's copy to be invalidated, and stores commit in order, so a pass's
/// stores to such lines stall it one after another. (`PREFETCHW`, the write prefetch, did not
/// do this on the project's machine.)
#[inline]
pub(crate) fn claim_lines<T>(s: &mut [T], items: &[u32], base: usize) {
    let mut last = usize::MAX;
    for &i in items {
        let e = &mut s[i as usize - base];
        // One store a cache line: a second to the same line waits for nothing.
        let line = e as *mut T as usize / 64;
        if line != last {
            last = line;
            // SAFETY: `e` is a valid, exclusive reference; writing back what was read
            // changes nothing but its cache line's state.
            unsafe { std::ptr::write_volatile(e, std::ptr::read_volatile(e)) };
        }
    }
}

/// Asks for the cache lines of `s[i − from]` for each `i` of `items` (sorted), once a line,
/// without waiting for them: a pass asks at a chunk's start for what another core last wrote
/// and the chunk reads only near its end, and the lines arrive while it works.
#[inline]
pub(crate) fn prefetch<T>(s: &[T], items: &[u32], from: usize) {
    let mut last = usize::MAX;
    for &i in items {
        let Some(e) = (i as usize).checked_sub(from).and_then(|i| s.get(i)) else {
            continue;
        };
        let line = e as *const T as usize / 64;
        if line != last {
            last = line;
            #[cfg(target_arch = "x86_64")]
            // SAFETY: a prefetch of a valid address reads nothing.
            unsafe {
                use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
                _mm_prefetch::<_MM_HINT_T0>(e as *const T as *const i8);
            }
        }
    }
}

/// A kernel's gather: every particle sums the slots its elements' force pass wrote, in a fixed
/// order, in chunks of particles that the force pass shares.
pub(crate) trait Gather: Sync {
    /// What the force pass writes per slot.
    type Slot: Sync;
    /// One more than the largest particle index an element refers to.
    fn bound(&self) -> usize;
    /// Number of chunks of both passes (at least one when the bound is not zero).
    fn chunks(&self) -> usize;
    /// Chunk `c`'s particles, for `c <` [`Self::chunks`]: consecutive ranges from 0 to the
    /// bound.
    fn range(&self, c: usize) -> std::ops::Range<usize>;
    /// For each chunk, its particles that other chunks' elements read.
    fn border(&self) -> &ChunkLists;
    /// Particles `p0..p1` sum their slots into `out[p − p0]`: added to it, or set when `set`
    /// (as `0 + sum`, the bits of adding to a zeroed force).
    ///
    /// The slots are read through a pointer, each where it lies: while one chunk gathers,
    /// another thread's force chunks may be writing other slots of the same buffer (see
    /// [`force_gather_set_then`]), which a slice over the buffer would not allow.
    ///
    /// # Safety
    /// `p1 ≤` the bound; `out` points to at least `p1 − p0` vectors; `buf` points to the force
    /// pass's slots, those the chunk reads written and not being written.
    unsafe fn gather_chunk(
        &self,
        p0: usize,
        p1: usize,
        buf: *const Self::Slot,
        out: *mut Vector,
        set: bool,
    );
}

/// Adds every particle's gathered force into `f`, in the kernel's chunks on the team.
///
/// # Safety
/// `f` holds the kernel's particles; `buf` is its force pass's.
pub(crate) unsafe fn gather_add<K: Gather + ?Sized>(
    kernel: &K,
    buf: SharedConst<K::Slot>,
    f: &mut [Vector],
) {
    assert!(f.len() >= kernel.bound(), "forces past the array");
    let fp = SharedMut(f.as_mut_ptr());
    for_each_chunk(kernel.chunks(), |c| {
        let r = kernel.range(c);
        // SAFETY: particles below the bound; each chunk writes its own particles only.
        unsafe { kernel.gather_chunk(r.start, r.end, buf.ptr(), fp.ptr().add(r.start), false) }
    });
}

/// The chunks of a pass over `n` particles that follows a kernel's chunks: the kernel's, then
/// the particles past its bound in chunks of [`springs::CHUNK_PARTICLES`] (particles no element
/// refers to, swept alone), for `n ≥` the bound. Returns their number and chunk `c`'s range.
fn chunks_over<K: Gather + ?Sized>(
    kernel: &K,
    n: usize,
) -> (usize, impl Fn(usize) -> std::ops::Range<usize>) {
    let (own, bound) = (kernel.chunks(), kernel.bound());
    let tail = springs::CHUNK_PARTICLES;
    let range = move |c: usize| {
        if c < own {
            kernel.range(c)
        } else {
            let p0 = bound + (c - own) * tail;
            p0..(p0 + tail).min(n)
        }
    };
    (own + (n - bound).div_ceil(tail), range)
}

/// A kernel's force pass, then every particle's gathered force set into `f` (zero past the
/// kernel's particles) and `finish` run on each chunk on the thread that gathered it — in one
/// pass of the team ([`for_each_chunk_in_two`]; the particles past the kernel's bound in
/// chunks of their own). `force(c, reads)` evaluates chunk `c`'s elements into their slots,
/// reading the particles `reads(c)` of `x` and `v` (handed to it as slices of those alone);
/// chunk `c`'s gather and `finish` wait for the force chunks from `first_reader(c)` to `c` —
/// those whose reads reach its particles — and for no other. One pass where there were four
/// (the forces, clearing them, gathering, sweeping), each handing every particle to the team
/// and waiting for its slowest thread: a hand-over costs a few microseconds on a two-core
/// machine, a thread goes on from its force chunks to its gathers without waiting for the
/// other threads' force chunks, and it sweeps the forces it has just summed while they are in
/// its cache.
///
/// Before it gathers, a chunk claims the cache lines of its border particles' positions and
/// velocities ([`claim_lines`], [`Gather::border`]): those the force pass read from another
/// chunk, and so perhaps from another core. Claimed after the gather, by the sweep's stores,
/// they stalled the sweep: on two threads the 64² cloth's first chunk of the second share
/// swept in 4.4 µs where the others took 1.7. Claimed first, the invalidations proceed while
/// the chunk gathers, and its sweep took 1.8 µs (a write prefetch, `PREFETCHW`, left it at
/// 3.8).
///
/// Which memory a job touches: a force chunk reads its `reads` of `x` and `v` (which no
/// gather writes meanwhile: those of the chunks it reaches wait for it) and writes its own
/// slots; a gather reads the slots of the force chunks it waited for and writes its own
/// particles. No slot is read and written at once, and no reference covers memory another
/// thread writes meanwhile: the force chunks read the positions and velocities through slices
/// of their reads alone, and the gathers read the slots (which other threads' force chunks
/// may still be writing elsewhere in the buffer) through a pointer, each where it lies.
///
/// # Safety
/// `force(c, _)` writes only chunk `c`'s slots and reads nothing of `x` and `v` but
/// `reads(c)`, which starts at or after chunk `c`'s first particle and ends at or before the
/// bound; every chunk `d > c` with particles in `reads(c)` has `first_reader(d) ≤ c`, and
/// `first_reader(d) ≤ d`; `buf` points to the slots the force chunks write (the gathers read
/// them).
///
/// # Panics
/// If `x`, `v` and `f` differ in length.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn force_gather_set_then<K: Gather + ?Sized>(
    kernel: &K,
    flags: &PhaseFlags,
    force: impl Fn(usize, Reads) + Sync + Send,
    reads: impl Fn(usize) -> std::ops::Range<usize> + Sync + Send,
    first_reader: impl Fn(usize) -> usize + Sync + Send,
    buf: SharedConst<K::Slot>,
    x: &mut [Vector],
    v: &mut [Vector],
    f: &mut [Vector],
    finish: Finish<'_>,
) {
    let n = f.len();
    assert!(
        x.len() == n && v.len() == n,
        "state and force arrays differ in length"
    );
    let bound = kernel.bound();
    assert!(n >= bound, "forces past the array");
    let (chunks, range) = chunks_over(kernel, n);
    let own = kernel.chunks();
    let (xp, vp, fp) = (
        SharedMut(x.as_mut_ptr()),
        SharedMut(v.as_mut_ptr()),
        SharedMut(f.as_mut_ptr()),
    );
    // The particles past the bound (chunks `own` on) are read by no force chunk.
    let after = |c: usize| {
        if c < own {
            first_reader(c)..c + 1
        } else {
            c..c
        }
    };
    for_each_chunk_in_two(
        chunks,
        flags,
        |c| {
            if c < own {
                let r = reads(c);
                // SAFETY: chunk `c`'s reads, below the bound; while it runs no job writes
                // them (a gather waits for every force chunk whose reads reach its chunk).
                force(c, unsafe { Reads::new(xp, vp, r) });
            }
        },
        after,
        |c| {
            // SAFETY: the ranges are disjoint and below `n`, the length of the three slices,
            // which this function borrows exclusively; each chunk's job alone touches its
            // range, and the force chunks that read its particles are done.
            unsafe { gather_set_chunk(kernel, buf, (xp, vp, fp), c, range(c), finish) }
        },
    );
}

/// What a force chunk of [`force_gather_set_then`] reads of the positions and velocities: the
/// particles `range`, addressed by their indices in the whole arrays (the slices hold those
/// particles alone, so that another thread may write the others meanwhile).
#[derive(Clone, Copy)]
pub(crate) struct Reads<'a> {
    pub x: &'a [Vector],
    pub v: &'a [Vector],
    pub from: usize,
}

impl Reads<'_> {
    /// # Safety
    /// `r` lies within both arrays, and nothing writes it while the slices live.
    unsafe fn new(x: SharedMut<Vector>, v: SharedMut<Vector>, r: std::ops::Range<usize>) -> Self {
        // SAFETY: as the caller guarantees.
        unsafe {
            Self {
                x: std::slice::from_raw_parts(x.ptr().add(r.start), r.len()),
                v: std::slice::from_raw_parts(v.ptr().add(r.start), r.len()),
                from: r.start,
            }
        }
    }
}

/// Chunk `c` (particles `r`) of [`force_gather_set_then`]'s gathers: claims its border lines,
/// sets its forces to the gathered slots and runs `finish` on it.
///
/// # Safety
/// `r` is below the length of the three arrays, and no other job touches it while this runs;
/// `buf` is the kernel's force pass's.
unsafe fn gather_set_chunk<K: Gather + ?Sized>(
    kernel: &K,
    buf: SharedConst<K::Slot>,
    (xp, vp, fp): (SharedMut<Vector>, SharedMut<Vector>, SharedMut<Vector>),
    c: usize,
    r: std::ops::Range<usize>,
    finish: Finish<'_>,
) {
    // SAFETY: as the caller guarantees.
    let (x, v, f) = unsafe {
        (
            xp.slice(r.clone()),
            vp.slice(r.clone()),
            fp.slice(r.clone()),
        )
    };
    let mine = kernel.border().of(c);
    claim_lines(x, mine, r.start);
    claim_lines(v, mine, r.start);
    let end = r.end.min(kernel.bound()).max(r.start);
    if end > r.start {
        // SAFETY: particles below the bound; `f` is the chunk's `r.len()` forces.
        unsafe { kernel.gather_chunk(r.start, end, buf.ptr(), f.as_mut_ptr(), true) };
    }
    f[end - r.start..].fill(Vector::ZERO);
    finish(Chunk { range: r, x, v, f });
}

/// Runs `f` with a team of `threads` threads (`0`: one per core) sharing the force kernels of
/// large bodies it steps: on this thread, with `threads − 1` helpers spawned for the call
/// (keep a `team::Team` to reuse them). Without the `parallel` feature `f` simply runs, on
/// one thread. Results are the same bits for any thread count.
pub fn with_threads<R>(threads: usize, f: impl FnOnce() -> R) -> R {
    #[cfg(feature = "parallel")]
    {
        team::Team::new(threads).run(f)
    }
    #[cfg(not(feature = "parallel"))]
    {
        let _ = threads;
        f()
    }
}

/// Number of threads the kernels use when called from here (1 outside a team, and without
/// the `parallel` feature).
pub fn current_threads() -> usize {
    #[cfg(feature = "parallel")]
    {
        team::current_threads()
    }
    #[cfg(not(feature = "parallel"))]
    {
        1
    }
}

/// A raw pointer that may cross threads: each chunk job writes only its own, disjoint part of
/// the slice it points into.
pub(crate) struct SharedMut<T>(pub *mut T);
impl<T> Clone for SharedMut<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for SharedMut<T> {}
impl<T> SharedMut<T> {
    /// The pointer (a method, so closures capture the whole `Sync` wrapper, not its field).
    #[inline(always)]
    pub(crate) fn ptr(self) -> *mut T {
        self.0
    }

    /// The elements `r` as a slice.
    ///
    /// # Safety
    /// `r` lies within the allocation, and nothing else reads or writes it while the slice
    /// lives (a chunk job's own range).
    #[inline(always)]
    pub(crate) unsafe fn slice<'a>(self, r: std::ops::Range<usize>) -> &'a mut [T] {
        // SAFETY: as the caller guarantees.
        unsafe { std::slice::from_raw_parts_mut(self.0.add(r.start), r.len()) }
    }
}

// SAFETY: used only by chunk jobs that write disjoint index ranges (checked by the layouts'
// construction), so no two threads ever touch the same element.
unsafe impl<T: Send> Send for SharedMut<T> {}
// SAFETY: as above.
unsafe impl<T: Send> Sync for SharedMut<T> {}

/// A raw pointer to read from on several threads: each reads only elements nothing writes
/// meanwhile (a gather's slots, once the force chunks that write them are done).
pub(crate) struct SharedConst<T>(pub *const T);
impl<T> Clone for SharedConst<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for SharedConst<T> {}
impl<T> SharedConst<T> {
    /// The pointer (a method, so closures capture the whole `Sync` wrapper).
    #[inline(always)]
    pub(crate) fn ptr(self) -> *const T {
        self.0
    }
}
// SAFETY: as `SharedMut`: the jobs read only elements no other job writes at the time.
unsafe impl<T: Sync> Send for SharedConst<T> {}
// SAFETY: as above.
unsafe impl<T: Sync> Sync for SharedConst<T> {}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every body size up to 5000 against both kernels' limits: chunks of at most `most`
    /// particles cover the body with none empty, differ by at most one particle, and a body
    /// of `most` particles or more has two chunks at least.
    #[test]
    fn chunks_are_even_and_bounded() {
        for most in [128, 1024] {
            for n in 1..5000 {
                let size = chunk_size(n, most);
                let chunks = n.div_ceil(size);
                assert!(size <= most, "n {n}: {size} > {most}");
                assert!((chunks - 1) * size < n, "n {n}: an empty chunk");
                let last = n - (chunks - 1) * size;
                assert!(size - last < chunks, "n {n}: sizes {size} and {last}");
                assert!(n < most || chunks >= 2, "n {n}: one chunk");
            }
        }
        assert_eq!(chunk_size(0, 1024), 1);
    }

    /// A two-phase pass on a team of three: every first and second phase runs once a pass,
    /// and a second phase finds the first phases it waits for done — whichever thread ran
    /// them, over passes of many sizes, with pauses that let the helpers park (so that
    /// shares are taken over), and with the waits spanning shares (each second phase waits
    /// for every first phase before it) or not (each for its own and the one before).
    #[cfg(feature = "parallel")]
    #[test]
    fn a_two_phase_pass_runs_each_phase_once_and_in_order() {
        use std::sync::atomic::{AtomicU64, Ordering::SeqCst};
        let team = team::Team::new(3);
        let flags = PhaseFlags::new(40);
        let firsts: Vec<AtomicU64> = (0..40).map(|_| AtomicU64::new(0)).collect();
        let seconds: Vec<AtomicU64> = (0..40).map(|_| AtomicU64::new(0)).collect();
        team.run(|| {
            for pass in 1..=600u64 {
                let chunks = 2 + (pass as usize * 7) % 38;
                let all = pass % 2 == 0;
                let after = |c: usize| {
                    if all {
                        0..c + 1
                    } else {
                        c.saturating_sub(1)..c + 1
                    }
                };
                for_each_chunk_in_two(
                    chunks,
                    &flags,
                    |c| {
                        if c % 5 == 0 {
                            std::thread::sleep(std::time::Duration::from_micros(20));
                        }
                        firsts[c].fetch_add(1, SeqCst);
                    },
                    after,
                    |c| {
                        for d in after(c) {
                            assert_eq!(firsts[d].load(SeqCst), pass, "pass {pass}: {d} before {c}");
                        }
                        seconds[c].fetch_add(1, SeqCst);
                    },
                );
                for (c, n) in seconds[..chunks].iter().enumerate() {
                    assert_eq!(n.load(SeqCst), pass, "pass {pass}, chunk {c}");
                }
                // The chunks past this pass's count, brought level for the next.
                for c in chunks..40 {
                    firsts[c].fetch_add(1, SeqCst);
                    seconds[c].fetch_add(1, SeqCst);
                }
                if pass % 150 == 0 {
                    std::thread::sleep(team::SPIN * 3);
                }
            }
        });
    }

    /// A first phase that panics panics the pass's caller instead of leaving the second phases
    /// that wait for it waiting, and the team goes on.
    #[cfg(feature = "parallel")]
    #[test]
    fn a_panicking_first_phase_panics_the_caller() {
        let team = team::Team::new(2);
        let flags = PhaseFlags::new(8);
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            team.run(|| {
                for_each_chunk_in_two(
                    8,
                    &flags,
                    |c| assert_ne!(c, 3, "chunk 3"),
                    |c| 0..c + 1,
                    |_| {},
                )
            })
        }));
        assert!(r.is_err());
        let n = std::sync::atomic::AtomicUsize::new(0);
        team.run(|| {
            for_each_chunk_in_two(
                8,
                &flags,
                |_| {},
                |c| 0..c + 1,
                |_| {
                    n.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                },
            )
        });
        assert_eq!(n.into_inner(), 8);
    }

    /// The lists against a map built directly, from pairs in random order with repeats.
    #[test]
    fn chunk_lists_hold_each_chunks_items_once_in_order() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move |k: u64| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed % k
        };
        let pairs: Vec<(usize, u32)> = (0..3000)
            .map(|_| (rnd(7) as usize * 2, rnd(500) as u32))
            .collect();
        let lists = ChunkLists::new(pairs.iter().copied());
        let mut want = std::collections::BTreeMap::<usize, std::collections::BTreeSet<u32>>::new();
        for &(c, i) in &pairs {
            want.entry(c).or_default().insert(i);
        }
        for c in 0..20 {
            let expected: Vec<u32> = want.get(&c).map_or(vec![], |s| s.iter().copied().collect());
            assert_eq!(lists.of(c), &expected[..], "chunk {c}");
        }
        assert!(ChunkLists::default().of(0).is_empty());
    }
}
