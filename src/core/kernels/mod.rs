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
//! [`springs`] groups springs into rows by their lower particle index (each row's force on its
//! particle is summed in a register, which breaks the store-to-load chain of the one-loop
//! kernel); [`tets`] evaluates neo-Hookean elements in the build's precision with their rest
//! shapes precomputed, and gathers each vertex's forces over its elements.

pub mod springs;
pub mod tets;

/// Runs `job(c)` for every chunk `c` in `0..chunks`: on the rayon pool the caller runs on
/// (see [`with_threads`]) when the `parallel` feature is on, the caller is one of that pool's
/// threads and there is more than one chunk; one after another otherwise. Jobs must write
/// disjoint memory.
///
/// Only from inside a pool: a parallel call from any other thread goes through rayon's global
/// injector queue, which allocates a block every few dozen calls — and a step allocates
/// nothing. The bits are the same either way.
#[inline]
pub(crate) fn for_each_chunk(chunks: usize, job: impl Fn(usize) + Sync + Send) {
    #[cfg(feature = "parallel")]
    if chunks > 1 && rayon::current_thread_index().is_some() && rayon::current_num_threads() > 1 {
        use rayon::prelude::*;
        (0..chunks).into_par_iter().for_each(job);
        return;
    }
    for c in 0..chunks {
        job(c);
    }
}

/// Runs `f` on a pool of `threads` threads (`0`: all cores), so that the force kernels of a
/// large body called within it share the work; outside such a pool (or a rayon pool of the
/// caller's own, entered with `install`) they run on the calling thread. Without the
/// `parallel` feature `f` simply runs, on one thread. Results are the same bits for any thread
/// count.
pub fn with_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    #[cfg(feature = "parallel")]
    {
        match rayon::ThreadPoolBuilder::new().num_threads(threads).build() {
            Ok(pool) => pool.install(f),
            Err(_) => f(),
        }
    }
    #[cfg(not(feature = "parallel"))]
    {
        let _ = threads;
        f()
    }
}

/// Number of threads the kernels use when called from here (1 outside a pool, and without
/// the `parallel` feature).
pub fn current_threads() -> usize {
    #[cfg(feature = "parallel")]
    {
        if rayon::current_thread_index().is_some() {
            rayon::current_num_threads()
        } else {
            1
        }
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
}

// SAFETY: used only by chunk jobs that write disjoint index ranges (checked by the layouts'
// construction), so no two threads ever touch the same element.
unsafe impl<T: Send> Send for SharedMut<T> {}
// SAFETY: as above.
unsafe impl<T: Send> Sync for SharedMut<T> {}
