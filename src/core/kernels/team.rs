//! A team of threads for the kernels' chunked passes: the caller and its helpers each run
//! their own share of a pass's chunks (taking over only a share nobody has begun within
//! [`GRACE`]), and helpers that find no pass spin for a while before they sleep.
//!
//! A pass may come in two phases (`share_in`): each thread runs the first phases of its
//! share's chunks and goes on to their second phases, which may wait for the first phases of
//! chunks before them (a force kernel's sums waiting for the forces they sum), so that a step
//! hands its chunks to the team once instead of once per phase.
//!
//! Why not a work-stealing pool: a step of a large body is one to three short parallel passes
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
//! thread. A pass allocates nothing: its description (the job, a pointer to the caller's
//! reference to its closure, and the number of chunks) is written into the team's shared
//! state, and a helper calls the job only for a chunk it has claimed, which the caller waits
//! for. `miri/` holds tests that run this code under Miri.

use std::cell::Cell;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::Ordering::{AcqRel, Acquire, Relaxed, Release, SeqCst};
use std::sync::atomic::{AtomicBool, AtomicPtr, AtomicU64, AtomicUsize, fence};
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

/// The chunks thread `t` of `threads` runs first: an even share, in order, so that a thread
/// takes the same part of every pass (the gather's particles are then mostly those whose
/// springs it evaluated, their slots still in its own cache).
fn share_of(t: usize, threads: usize, chunks: usize) -> std::ops::Range<usize> {
    t * chunks / threads..(t + 1) * chunks / threads
}

/// The places in claim order of share `t`'s jobs in a pass of `chunks` chunks in `phases`
/// phases (1 or 2): `phases` jobs for each chunk of [`share_of`].
fn jobs_of(t: usize, threads: usize, chunks: usize, phases: usize) -> std::ops::Range<usize> {
    let r = share_of(t, threads, chunks);
    phases * r.start..phases * r.end
}

/// The job at place `k` of share `share` ([`jobs_of`]). One phase: chunk `k`. Two phases
/// (jobs `c` and `chunks + c` for chunk `c`'s first and second): the share's chunks' first
/// phases from its last chunk down (the next share's second phases wait for the last ones),
/// then their second phases in order (the first of them reads what the share's first phases
/// wrote last, still in the cache). A share's first phases never wait for anything, and a
/// second phase waits only for first phases of its own share or of shares before it: whoever
/// runs a share, every pass ends.
fn job_at(k: usize, share: &std::ops::Range<usize>, chunks: usize, phases: usize) -> usize {
    if phases == 1 {
        return k;
    }
    let (a, b) = (share.start / 2, share.end / 2);
    let i = k - share.start;
    let n = b - a;
    if i < n {
        b - 1 - i
    } else {
        chunks + a + (i - n)
    }
}

/// Bits of a share's claim word, and of a thread's done word, that count chunks (a pass of
/// more chunks runs on its caller alone); the 48 bits above hold the pass's number, modulo
/// 2^48, compared within a window of 2^47 passes (four years at a pass a microsecond).
const COUNT_BITS: u32 = 16;
const COUNT_MASK: u64 = (1 << COUNT_BITS) - 1;
const TAG_MASK: u64 = u64::MAX >> COUNT_BITS;

/// How the pass number `tag` (of a claim or done word) stands to pass `e`, modulo 2^48.
fn order(tag: u64, e: u64) -> std::cmp::Ordering {
    let d = tag.wrapping_sub(e) & TAG_MASK;
    if d == 0 {
        std::cmp::Ordering::Equal
    } else if d <= TAG_MASK / 2 {
        std::cmp::Ordering::Greater
    } else {
        std::cmp::Ordering::Less
    }
}

/// A pass's job as its caller holds it, while the pass runs (not for longer: the lifetime
/// is the helpers' to keep, see [`Shared::run`]).
type Job = &'static (dyn Fn(usize) + Sync);

/// An atomic on a cache line of its own (two lines: the adjacent-line prefetcher pairs them),
/// so that what one thread writes every chunk never shares a line with what another reads.
#[repr(align(128))]
#[derive(Default)]
struct Line(AtomicU64);

/// What the caller and the helpers share.
///
/// A pass costs as few transfers of cache lines between cores as it can (each is about
/// 0.1–0.2 µs on a virtual machine's cores): the caller publishes the pass on one line the
/// helpers read; each thread claims its share's chunks on a line of its own; each thread
/// counts the chunks it finished on a line of its own, which the caller reads at the end. No
/// read-modify-write touches a line another thread is using while a pass runs, and neither
/// side waits for the other before it starts its chunks. (With one counter of chunks done
/// and one of helpers inside the pass, a pass of nothing took 1.12–1.20 µs on the project's
/// machine with two threads; this way 0.48–0.51 µs: `docs/BENCHMARKS.md`.)
struct Shared {
    /// `2e` once pass `e`'s description below is written; odd while it is being written (a
    /// sequence lock: a helper reads the description, then this again, and uses it only if
    /// nothing changed).
    seq: AtomicU64,
    /// Where the pass's caller keeps its job (a [`Job`] on its stack): valid while pass
    /// `seq / 2` runs, which a helper knows by claiming one of its chunks. A thin pointer to
    /// the caller's reference, rather than the reference's two words as integers: a pointer
    /// made back from integers has no provenance, and a vtable pointer without it is
    /// undefined behaviour (Miri: "expected a vtable pointer").
    job: AtomicPtr<Job>,
    /// The pass's number of chunks, and of phases (jobs per chunk: see [`job_at`]).
    chunks: AtomicUsize,
    phases: AtomicUsize,
    /// Helpers parked, or about to.
    parked: AtomicUsize,
    stop: AtomicBool,
    /// The helpers, to wake them.
    helpers: OnceLock<Vec<Thread>>,
    /// For each thread's share (the caller's first, which only the caller runs): the pass's
    /// number and the next chunk to claim. A chunk is claimed by a compare-exchange of the
    /// share's thread, or of a thread that takes over a share not begun within [`GRACE`].
    claim: Box<[Line]>,
    /// For each helper (index 0 unused): the pass's number and the chunks it has finished in
    /// that pass. The pass is over when these and the caller's own count add up to its
    /// chunks; what the chunks wrote is then visible to the caller (release and acquire).
    done: Box<[Line]>,
    /// A chunk panicked in the pass in progress.
    panicked: AtomicBool,
}

impl Shared {
    fn threads(&self) -> usize {
        self.claim.len()
    }

    /// Claims the next chunk of share `t` in pass `e`, if any is left: the caller of a pass
    /// `e` is still waiting for the chunk claimed, so its job stays valid until it is done.
    fn claim(&self, t: usize, e: u64, share: &std::ops::Range<usize>) -> Option<usize> {
        let word = &self.claim[t].0;
        let mut v = word.load(Acquire);
        loop {
            let next = match order(v >> COUNT_BITS, e) {
                std::cmp::Ordering::Equal => (v & COUNT_MASK) as usize,
                // Not begun in this pass.
                std::cmp::Ordering::Less => share.start,
                // A later pass: this one is over.
                std::cmp::Ordering::Greater => return None,
            };
            if next >= share.end {
                return None;
            }
            match word.compare_exchange_weak(
                v,
                e << COUNT_BITS | (next as u64 + 1),
                AcqRel,
                Acquire,
            ) {
                Ok(_) => return Some(next),
                Err(w) => v = w,
            }
        }
    }

    /// Whether share `t`'s thread (or another) has begun it in pass `e`.
    fn begun(&self, t: usize, e: u64) -> bool {
        order(self.claim[t].0.load(Acquire) >> COUNT_BITS, e) != std::cmp::Ordering::Less
    }

    /// Runs chunk `c` of the pass; a chunk that panics is noted (the pass's caller panics
    /// once the pass is over) and counts as run.
    fn run_chunk(&self, f: &(dyn Fn(usize) + Sync), c: usize) {
        if catch_unwind(AssertUnwindSafe(|| f(c))).is_err() {
            self.panicked.store(true, Release);
        }
    }

    /// Runs the jobs of share `t` of pass `e` that nobody else claims; returns how many.
    fn run_share(
        &self,
        t: usize,
        e: u64,
        (chunks, phases): (usize, usize),
        f: &(dyn Fn(usize) + Sync),
    ) -> u64 {
        let share = jobs_of(t, self.threads(), chunks, phases);
        let mut ran = 0;
        while let Some(k) = self.claim(t, e, &share) {
            self.run_chunk(f, job_at(k, &share, chunks, phases));
            ran += 1;
        }
        ran
    }

    /// Runs `f` on every job of `chunks` chunks in `phases` phases ([`job_at`]), sharing them
    /// with the helpers; returns when all are done.
    fn run(&self, chunks: usize, phases: usize, f: &(dyn Fn(usize) + Sync)) {
        let threads = self.threads();
        let e = self.seq.load(Relaxed) / 2 + 1;
        // The helpers' use of the job: a helper calls it only for a chunk of pass `e` it has
        // claimed, and this function returns only once every chunk is done, so `job` (and
        // what it refers to) outlives every such call.
        let job: &(dyn Fn(usize) + Sync) = f;
        let job = std::ptr::from_ref(&job).cast::<Job>().cast_mut();
        self.seq.store(2 * e - 1, Relaxed);
        fence(Release);
        self.job.store(job, Relaxed);
        self.chunks.store(chunks, Relaxed);
        self.phases.store(phases, Relaxed);
        self.seq.store(2 * e, Release);
        // A helper that parks while this is published may miss the wake-up: its share is
        // taken over after `GRACE`, and the next pass wakes it.
        if self.parked.load(Relaxed) > 0
            && let Some(helpers) = self.helpers.get()
        {
            for h in helpers {
                h.unpark();
            }
        }
        // The caller's own share: only it claims there.
        let mut mine = 0;
        let share = jobs_of(0, threads, chunks, phases);
        for k in share.clone() {
            self.run_chunk(f, job_at(k, &share, chunks, phases));
            mine += 1;
        }
        let jobs = phases * chunks;
        let finished = |t: usize| {
            let d = self.done[t].0.load(Acquire);
            if order(d >> COUNT_BITS, e) == std::cmp::Ordering::Equal {
                d & COUNT_MASK
            } else {
                0
            }
        };
        let since = Instant::now();
        let mut spins = 0u32;
        let mut looked = false;
        loop {
            let total: u64 = mine + (1..threads).map(finished).sum::<u64>();
            if total as usize >= jobs {
                break;
            }
            // A share not begun within `GRACE` (its helper parked, descheduled or gone) is
            // taken over; a share begun is left to its thread (see `work`). Its claim line is
            // read only then: read while its thread claims there, it would stall that thread.
            if !looked && spins >= 64 && since.elapsed() >= GRACE {
                looked = true;
                for t in 1..threads {
                    if finished(t) == 0 && !self.begun(t, e) {
                        mine += self.run_share(t, e, (chunks, phases), f);
                    }
                }
            }
            // A helper a few microseconds behind is waited for spinning (a yield is a system
            // call, slow in a virtual machine); one far behind, with the core yielded to it.
            spins = spins.saturating_add(1);
            if spins < 4096 {
                std::hint::spin_loop();
            } else {
                thread::yield_now();
            }
        }
        assert!(
            !self.panicked.swap(false, Acquire),
            "a soft-body force kernel panicked"
        );
    }

    /// Helper `me` runs the chunks of its share of pass `e`, then those of any other helper's
    /// share not begun within [`GRACE`] (a helper parked, descheduled or gone). A share its
    /// thread has begun is left to it: taking chunks of a running share saves a few
    /// microseconds and costs more, since the chunk's springs and slots, and the particles it
    /// writes, are in the other core's cache (taking about one chunk a step that way, two
    /// threads were 7 % slower on the bench cloth). A chunk that panics is counted done and
    /// noted, so that the pass ends and its caller panics after it.
    ///
    /// `f` is called only for a chunk claimed in pass `e`, which keeps it valid (see `run`).
    fn work(&self, me: usize, e: u64, (chunks, phases): (usize, usize), f: *const Job) {
        let threads = self.threads();
        let mut ran = 0u64;
        let count = |ran: u64| self.done[me].0.store(e << COUNT_BITS | ran, Release);
        for k in 0..threads - 1 {
            let t = 1 + (me - 1 + k) % (threads - 1);
            let share = jobs_of(t, threads, chunks, phases);
            if k > 0 && !share.is_empty() {
                let since = Instant::now();
                let begun = loop {
                    if self.begun(t, e) {
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
            while let Some(c) = self.claim(t, e, &share) {
                // SAFETY: job `c` of pass `e` is claimed and not yet counted done, so pass
                // `e`'s caller is still waiting and its job alive for this call.
                self.run_chunk(unsafe { *f }, job_at(c, &share, chunks, phases));
                ran += 1;
                count(ran);
            }
        }
    }

    /// A helper's life: passes as they come, spinning between them, parked when idle.
    fn help(&self, me: usize) {
        let mut seen = self.seq.load(Acquire) / 2;
        let mut idle_since = Instant::now();
        let mut spins = 0u32;
        while !self.stop.load(Relaxed) {
            let s = self.seq.load(Acquire);
            if s.is_multiple_of(2) && s / 2 != seen {
                let f = self.job.load(Relaxed);
                let chunks = self.chunks.load(Relaxed);
                let phases = self.phases.load(Relaxed);
                fence(Acquire);
                if self.seq.load(Relaxed) != s {
                    // Rewritten meanwhile: that pass is over, the next one is coming.
                    continue;
                }
                seen = s / 2;
                self.work(me, seen, (chunks, phases), f);
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
            // Park, unless a pass came meanwhile. A pass published as this helper parks may
            // miss it (see `run`): that pass's share is taken over, the next pass wakes it,
            // and a timeout bounds the sleep if no pass comes; woken with no pass, it parks
            // again at once.
            self.parked.fetch_add(1, SeqCst);
            if self.seq.load(SeqCst) / 2 == seen && !self.stop.load(SeqCst) {
                thread::park_timeout(SPIN * 100);
            }
            self.parked.fetch_sub(1, SeqCst);
            if self.seq.load(Acquire) / 2 != seen {
                idle_since = Instant::now();
            }
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
            seq: AtomicU64::new(0),
            job: AtomicPtr::new(std::ptr::null_mut()),
            chunks: AtomicUsize::new(0),
            phases: AtomicUsize::new(1),
            parked: AtomicUsize::new(0),
            stop: AtomicBool::new(false),
            helpers: OnceLock::new(),
            claim: (0..threads).map(|_| Line::default()).collect(),
            done: (0..threads).map(|_| Line::default()).collect(),
            panicked: AtomicBool::new(false),
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
/// is no team to share them with, or more than 65,535 chunks (a body of 67 million particles
/// in the spring kernel's chunks).
pub(crate) fn share(chunks: usize, job: &(dyn Fn(usize) + Sync)) -> bool {
    share_in(chunks, 1, job)
}

/// [`share`] of a pass in two phases (`phases` 2) or one: `job(c)` and `job(chunks + c)` for
/// every chunk `c`, each thread running the first phases of its share's chunks before their
/// second phases (see [`job_at`]), so that a second phase may wait for the first phases of
/// chunks before it (their own or another share's) and the pass still ends. Returns false
/// (having run nothing) as [`share`] does.
pub(crate) fn share_in(chunks: usize, phases: usize, job: &(dyn Fn(usize) + Sync)) -> bool {
    let shared = CURRENT.with(|c| c.get());
    if shared.is_null() || (phases * chunks) as u64 > COUNT_MASK {
        return false;
    }
    // Inside the pass this thread runs chunks too; a kernel a chunk calls runs on this thread.
    let _restore = Restore(CURRENT.with(|c| c.replace(std::ptr::null())));
    // SAFETY: `CURRENT` is set only within `Team::run`, which borrows the team (and so its
    // `Arc<Shared>`) for as long as it is set.
    unsafe { &*shared }.run(chunks, phases, job);
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

    /// Pass numbers compare within their window across the wrap of their 48 bits, and a pass
    /// of more chunks than a claim word counts runs on its caller alone.
    #[test]
    fn pass_numbers_wrap_and_huge_passes_run_alone() {
        use std::cmp::Ordering::*;
        let top = TAG_MASK;
        assert_eq!(order(5, 5), Equal);
        assert_eq!(order(4, 5), Less);
        assert_eq!(order(6, 5), Greater);
        // Across the wrap: 2^48 − 1 is the pass before 0 (and the tag of pass 2^48 is 0).
        assert_eq!(order(top, 0), Less);
        assert_eq!(order(0, top), Greater);
        assert_eq!(order(((1u64 << 48) + 3) & top, 3), Equal);
        assert_eq!(order(0, top / 2), Less);
        let team = Team::new(2);
        team.run(|| {
            assert!(!share(COUNT_MASK as usize + 1, &|_| {}));
            assert!(share(COUNT_MASK as usize, &|_| {}));
        });
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
