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
//! Both work in two passes: first every element's forces (a spring's on its lower particle,
//! a tet's on its four) into its own slots, several elements at a time in AVX lanes where the
//! processor has it; then every particle sums its slots in a fixed order. [`springs`] keeps
//! springs in rows by their lower particle index, so a particle's own row is contiguous;
//! [`tets`] evaluates neo-Hookean elements in the build's precision with their rest shapes
//! precomputed. [`sweep`] is symplectic Euler's update of every particle, in whole registers
//! in the f64 build.

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
#[derive(Clone, Copy)]
pub(crate) struct SharedMut<T>(pub *mut T);
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
