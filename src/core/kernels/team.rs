//! A team of threads for the kernels' chunked passes: the caller and its helpers each run
//! their own share of a pass's chunks (taking over only a share nobody has begun within
//! [`GRACE`]), and helpers that find no pass spin for a while before they sleep.
//!
//! Why not a work-stealing pool: a step of a large body is two or three short parallel passes
//! (tens of microseconds each) with a few microseconds of serial work between them, frame
//! after frame. A pool whose idle workers go to sleep within microseconds pays a wake-up for
//! nearly every pass, and in a virtual machine a wake-up goes through the hypervisor: on the
//! project's 2-core machine rayon's `join` of two 10 µs jobs took 11.4 µs back to back and
//! 51.9 µs (against 30) with 20 µs of serial work between them (`docs/BENCHMARKS.md`). Here a
//! helper spins for [`SPIN`] after its last chunk, which covers the serial gaps of a step and
//! of the steps of a frame, and only then parks; a pass that finds helpers parked wakes them.
//!
//! Which thread runs a chunk never changes what it computes: chunks write disjoint memory and
//! every sum is ordered by the chunking alone (see [`super`]), so the bits are those of one
//! thread. A pass allocates nothing: its description lives on the caller's stack for as long
//! as the caller waits for it.

use std::cell::Cell;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, AtomicPtr, AtomicUsize, Ordering::SeqCst};
use std::sync::{Arc, Mutex, OnceLock, TryLockError};
use std::thread::{self, JoinHandle, Thread};
use std::time::{Duration, Instant};

/// How long a helper keeps spinning after its last chunk before it parks: longer than the
/// serial work between two passes of a step and between steps (a few to tens of
/// microseconds), short enough that a game's idle helper gives its core back within a frame.
pub const SPIN: Duration = Duration::from_micros(300);

/// How long a thread done with its own share waits for another thread to begin its share
/// before it takes that share's chunks: a spinning helper begins within a microsecond, a
/// parked one takes tens of microseconds to wake.
pub const GRACE: Duration = Duration::from_micros(5);

/// One parallel pass: `f(c)` for every `c < chunks`.
struct Pass<'a> {
    f: &'a (dyn Fn(usize) + Sync),
    chunks: usize,
    /// Chunks finished.
    done: AtomicUsize,
    /// A chunk panicked.
    panicked: AtomicBool,
}

/// The chunks thread `t` of `threads` runs first: an even share, in order, so that a thread
/// takes the same part of every pass (the gather's particles are then mostly those whose
/// springs it evaluated, their slots still in its own cache).
fn share_of(t: usize, threads: usize, chunks: usize) -> std::ops::Range<usize> {
    t * chunks / threads..(t + 1) * chunks / threads
}

/// What the caller and the helpers share.
struct Shared {
    /// The pass in progress, or null.
    pass: AtomicPtr<Pass<'static>>,
    /// Bumped when a pass is published.
    epoch: AtomicUsize,
    /// Helpers looking at the pass (the caller waits for none before its pass goes away).
    active: AtomicUsize,
    /// Helpers parked, or about to.
    parked: AtomicUsize,
    stop: AtomicBool,
    /// The helpers, to wake them.
    helpers: OnceLock<Vec<Thread>>,
    /// For each thread (the caller first), the next chunk of its share to claim.
    next: Box<[AtomicUsize]>,
}

/// Spins on `done` with a pause hint, yielding the core after a while (when the machine has
/// more runnable threads than cores, the thread waited for may need it).
fn spin_until(mut done: impl FnMut() -> bool) {
    let mut spins = 0u32;
    while !done() {
        if spins < 256 {
            std::hint::spin_loop();
            spins += 1;
        } else {
            thread::yield_now();
        }
    }
}

impl Shared {
    /// Runs `f` on every chunk, sharing them with the helpers; returns when all are done.
    fn run(&self, chunks: usize, f: &(dyn Fn(usize) + Sync)) {
        let pass = Pass {
            f,
            chunks,
            done: AtomicUsize::new(0),
            panicked: AtomicBool::new(false),
        };
        let threads = self.next.len();
        for (t, next) in self.next.iter().enumerate() {
            next.store(share_of(t, threads, chunks).start, SeqCst);
        }
        // SAFETY (of the helpers' reads through this pointer): it is cleared below, and this
        // function returns only once no helper is between reading it and being done with it.
        let ptr = &pass as *const Pass<'_> as *mut Pass<'static>;
        self.pass.store(ptr, SeqCst);
        self.epoch.fetch_add(1, SeqCst);
        if self.parked.load(SeqCst) > 0
            && let Some(helpers) = self.helpers.get()
        {
            for h in helpers {
                h.unpark();
            }
        }
        self.work(&pass, 0);
        spin_until(|| pass.done.load(SeqCst) >= chunks);
        self.pass.store(std::ptr::null_mut(), SeqCst);
        spin_until(|| self.active.load(SeqCst) == 0);
        assert!(
            !pass.panicked.load(SeqCst),
            "a soft-body force kernel panicked"
        );
    }

    /// Thread `me` runs the chunks of its share, then those of any share whose thread has
    /// not begun it within [`GRACE`] (a helper parked, descheduled or gone). A share its thread
    /// has begun is left to it: taking chunks of a running share saves a few microseconds and
    /// costs more, since the chunk's springs and slots, and the particles it writes, are in the
    /// other core's cache (taking about one chunk a step that way, two threads were 7 % slower
    /// on the bench cloth). A chunk that panics is counted done and noted, so that the pass
    /// ends and its caller panics after it.
    fn work(&self, pass: &Pass<'_>, me: usize) {
        let threads = self.next.len();
        for k in 0..threads {
            let t = (me + k) % threads;
            let share = share_of(t, threads, pass.chunks);
            if k > 0 && !share.is_empty() {
                let since = Instant::now();
                let begun = loop {
                    if self.next[t].load(SeqCst) > share.start {
                        break true;
                    }
                    if since.elapsed() >= GRACE {
                        break false;
                    }
                    std::hint::spin_loop();
                };
                if begun {
                    continue;
                }
            }
            loop {
                let c = self.next[t].fetch_add(1, SeqCst);
                if c >= share.end {
                    break;
                }
                if catch_unwind(AssertUnwindSafe(|| (pass.f)(c))).is_err() {
                    pass.panicked.store(true, SeqCst);
                }
                pass.done.fetch_add(1, SeqCst);
            }
        }
    }

    /// A helper's life: passes as they come, spinning between them, parked when idle.
    fn help(&self, me: usize) {
        let mut seen = self.epoch.load(SeqCst);
        let mut idle_since = Instant::now();
        let mut spins = 0u32;
        while !self.stop.load(SeqCst) {
            let epoch = self.epoch.load(SeqCst);
            if epoch != seen {
                seen = epoch;
                self.active.fetch_add(1, SeqCst);
                let p = self.pass.load(SeqCst);
                if !p.is_null() {
                    // SAFETY: read after `active` counted this helper; the caller clears the
                    // pointer before it waits for `active` to fall to zero, so a pointer read
                    // now stays valid until this helper is done and uncounted.
                    self.work(unsafe { &*p }, me);
                }
                self.active.fetch_sub(1, SeqCst);
                idle_since = Instant::now();
                spins = 0;
                continue;
            }
            // Spin, then yield the core between looks (to whatever else the machine has to
            // run: a helper that burns its time slice is the one the scheduler preempts in
            // the middle of its next chunk, and the pass waits for it), then park.
            spins += 1;
            if spins < 256 {
                std::hint::spin_loop();
                continue;
            }
            if idle_since.elapsed() < SPIN {
                thread::yield_now();
                continue;
            }
            // Park, unless a pass came meanwhile: the caller bumps the epoch before it reads
            // `parked`, this helper raises `parked` before it reads the epoch, so one of the
            // two sees the other (and an unpark that comes first makes the park return).
            self.parked.fetch_add(1, SeqCst);
            if self.epoch.load(SeqCst) == seen && !self.stop.load(SeqCst) {
                thread::park();
            }
            self.parked.fetch_sub(1, SeqCst);
            idle_since = Instant::now();
        }
    }
}

thread_local! {
    /// The team whose [`Team::run`] this thread is in (null: none, or inside a pass).
    static CURRENT: Cell<*const Shared> = const { Cell::new(std::ptr::null()) };
}

/// Puts `CURRENT` back as it was when dropped (also when unwinding).
struct Restore(*const Shared);

impl Drop for Restore {
    fn drop(&mut self) {
        CURRENT.with(|c| c.set(self.0));
    }
}

/// Threads that share the chunked passes of force kernels called within [`Team::run`]: the
/// calling thread and `threads − 1` helpers, spawned once and kept until the team is dropped.
pub struct Team {
    shared: Arc<Shared>,
    workers: Vec<JoinHandle<()>>,
    /// Held by the thread in [`Team::run`]: a team serves one caller at a time.
    busy: Mutex<()>,
}

impl Team {
    /// A team of `threads` threads in all (`0`: one per core). A helper that cannot be
    /// spawned is done without.
    pub fn new(threads: usize) -> Self {
        let threads = if threads == 0 {
            thread::available_parallelism().map_or(1, |n| n.get())
        } else {
            threads
        };
        let shared = Arc::new(Shared {
            pass: AtomicPtr::new(std::ptr::null_mut()),
            epoch: AtomicUsize::new(0),
            active: AtomicUsize::new(0),
            parked: AtomicUsize::new(0),
            stop: AtomicBool::new(false),
            helpers: OnceLock::new(),
            next: (0..threads).map(|_| AtomicUsize::new(0)).collect(),
        });
        let mut workers = Vec::new();
        for i in 1..threads {
            let s = Arc::clone(&shared);
            match thread::Builder::new()
                .name(format!("soft-body kernels {i}"))
                .spawn(move || s.help(i))
            {
                Ok(h) => workers.push(h),
                Err(_) => break,
            }
        }
        // Set before any pass (a pass needs `run`, which needs the team built).
        let _ = shared
            .helpers
            .set(workers.iter().map(|w| w.thread().clone()).collect());
        Self {
            shared,
            workers,
            busy: Mutex::new(()),
        }
    }

    /// Threads in all, the caller included.
    pub fn threads(&self) -> usize {
        self.workers.len() + 1
    }

    /// Runs `f` on this thread with the team's helpers sharing the chunked passes of the
    /// kernels it calls. If another thread is running in the team already, `f` runs on this
    /// thread alone (the same bits either way).
    pub fn run<R>(&self, f: impl FnOnce() -> R) -> R {
        // A kernel that panicked in an earlier `run` poisoned nothing the team relies on.
        let _busy = match self.busy.try_lock() {
            Ok(g) => g,
            Err(TryLockError::Poisoned(p)) => p.into_inner(),
            Err(TryLockError::WouldBlock) => return f(),
        };
        if self.workers.is_empty() {
            return f();
        }
        let _restore = Restore(CURRENT.with(|c| c.replace(Arc::as_ptr(&self.shared))));
        f()
    }
}

impl Drop for Team {
    fn drop(&mut self) {
        self.shared.stop.store(true, SeqCst);
        for w in &self.workers {
            w.thread().unpark();
        }
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

impl std::fmt::Debug for Team {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Team")
            .field("threads", &self.threads())
            .finish()
    }
}

/// Runs `job(c)` for every `c < chunks` on the team this thread runs in, if any (see
/// [`Team::run`]); one after another otherwise. Returns false (having run nothing) when there
/// is no team to share them with.
pub(crate) fn share(chunks: usize, job: &(dyn Fn(usize) + Sync)) -> bool {
    let shared = CURRENT.with(|c| c.get());
    if shared.is_null() {
        return false;
    }
    // Inside the pass this thread runs chunks too; a kernel a chunk calls runs on this thread.
    let _restore = Restore(CURRENT.with(|c| c.replace(std::ptr::null())));
    // SAFETY: `CURRENT` is set only within `Team::run`, which borrows the team (and so its
    // `Arc<Shared>`) for as long as it is set.
    unsafe { &*shared }.run(chunks, job);
    true
}

/// Threads in the team this thread runs in (1 outside one).
pub(crate) fn current_threads() -> usize {
    let shared = CURRENT.with(|c| c.get());
    if shared.is_null() {
        1
    } else {
        // SAFETY: as in `share`.
        unsafe { &*shared }.helpers.get().map_or(1, |h| h.len() + 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicU64;

    /// Every chunk runs exactly once per pass, whoever runs it, over many passes with and
    /// without pauses long enough for the helpers to park.
    #[test]
    fn every_chunk_runs_once_per_pass() {
        let team = Team::new(3);
        assert_eq!(team.threads(), 3);
        team.run(|| {
            assert_eq!(current_threads(), 3);
            let counts: Vec<AtomicU64> = (0..37).map(|_| AtomicU64::new(0)).collect();
            for pass in 0..2000u64 {
                let chunks = 1 + (pass as usize * 7) % 37;
                assert!(share(chunks, &|c| {
                    counts[c].fetch_add(1, SeqCst);
                }));
                if pass % 500 == 499 {
                    thread::sleep(SPIN * 3);
                }
            }
            let expected = |c: usize| (0..2000).filter(|p| c < 1 + (p * 7) % 37).count() as u64;
            for (c, n) in counts.iter().enumerate() {
                assert_eq!(n.load(SeqCst), expected(c), "chunk {c}");
            }
        });
        assert_eq!(current_threads(), 1);
        assert!(!share(4, &|_| {}));
    }

    /// A pass from inside a chunk runs on its own thread; a second caller runs alone.
    #[test]
    fn nested_passes_and_a_busy_team_run_alone() {
        let team = Team::new(2);
        team.run(|| {
            let inner = AtomicUsize::new(0);
            assert!(share(4, &|_| {
                assert!(!share(3, &|_| {}));
                inner.fetch_add(1, SeqCst);
            }));
            assert_eq!(inner.load(SeqCst), 4);
            // The team is busy with this thread: another thread's `run` goes alone.
            thread::scope(|s| {
                s.spawn(|| team.run(|| assert_eq!(current_threads(), 1)));
            });
        });
    }

    /// A chunk that panics on a helper panics the pass's caller, and the team goes on.
    #[test]
    fn a_panicking_chunk_panics_the_caller() {
        let team = Team::new(2);
        let r = catch_unwind(AssertUnwindSafe(|| {
            team.run(|| {
                share(64, &|c| {
                    if c == 63 {
                        panic!("chunk 63");
                    }
                    thread::sleep(Duration::from_micros(20));
                })
            })
        }));
        assert!(r.is_err());
        let n = AtomicUsize::new(0);
        team.run(|| {
            share(8, &|_| {
                n.fetch_add(1, SeqCst);
            })
        });
        assert_eq!(n.load(SeqCst), 8);
    }
}
