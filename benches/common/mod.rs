//! What the benches share (not a bench itself).

use std::time::{Duration, Instant};

/// Times `iters` runs of `work` on a team of `THREADS` threads (default: all cores; the
/// kernels' and solves' passes are shared, with the same bits).
pub fn timed(iters: u64, mut work: impl FnMut() + Send) -> Duration {
    let threads = std::env::var("THREADS")
        .ok()
        .and_then(|t| t.parse().ok())
        .unwrap_or(0);
    bevy_soft_body::core::kernels::with_threads(threads, || {
        let t0 = Instant::now();
        for _ in 0..iters {
            work();
        }
        t0.elapsed()
    })
}
