//! What the benches share (not a bench itself).

use std::time::{Duration, Instant};

/// Times `iters` runs of `work` on a team of `THREADS` threads (default: all cores; the
/// kernels' and solves' passes are shared, with the same bits).
#[allow(dead_code)] // A bench uses this or `timed_in_turn`.
pub fn timed(iters: u64, mut work: impl FnMut() + Send) -> Duration {
    bevy_soft_body::core::kernels::with_threads(threads(), || {
        let t0 = Instant::now();
        for _ in 0..iters {
            work();
        }
        t0.elapsed()
    })
}

/// Times `iters` runs of `work` on `on` as [`timed`] does, calling `restart` untimed before
/// a run whenever `window` runs have been timed since the last restart (`done` counts them
/// across calls): the mean is then over the same `window` runs however many are asked for.
#[allow(dead_code)] // A bench uses this or `timed`.
pub fn timed_in_turn<T: Send>(
    iters: u64,
    (window, done): (u64, &mut u64),
    on: &mut T,
    mut restart: impl FnMut(&mut T) + Send,
    mut work: impl FnMut(&mut T) + Send,
) -> Duration {
    bevy_soft_body::core::kernels::with_threads(threads(), || {
        let mut total = Duration::ZERO;
        for _ in 0..iters {
            if *done == window {
                restart(on);
                *done = 0;
            }
            let t0 = Instant::now();
            work(on);
            total += t0.elapsed();
            *done += 1;
        }
        total
    })
}

/// `THREADS` from the environment (0, all cores, when unset).
fn threads() -> usize {
    std::env::var("THREADS")
        .ok()
        .and_then(|t| t.parse().ok())
        .unwrap_or(0)
}
