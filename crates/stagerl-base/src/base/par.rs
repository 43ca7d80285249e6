//! Fork-join parallelism inside one training run: a [`Pool`] of worker threads that an update's
//! matrix products and element-wise passes split their rows over.
//!
//! **Results do not depend on the number of threads.** Work is only ever split into pieces that
//! write disjoint outputs, each output value computed by the same sequence of operations as on
//! one thread (rows of a product, ranges of an element-wise pass; never a reduction split in
//! two). So a run gives the same bits with `--threads 1` and `--threads 2`, and the thread count
//! is not part of a run's configuration.
//!
//! The pool is made current for the calling thread with [`install`]; the engine's loops ask for
//! it with [`split`], which runs serially where no pool is installed or the work is too small to
//! be worth waking a worker (a few microseconds). The calling thread always takes pieces itself,
//! so a worker that the system has not scheduled yet delays nothing: the caller finishes the
//! pieces alone. Workers spin briefly after a job (the next one usually follows within
//! microseconds during an update), then sleep until woken.

use std::cell::Cell;
use std::ops::Range;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering::*};
use std::sync::{Arc, Mutex};
use std::thread::{JoinHandle, Thread};

use crate::{Error, Result};

/// The most threads a pool may have.
pub const MAX_THREADS: usize = 64;

/// Spin iterations (about 30-60 us) before an idle worker sleeps.
const SPINS_BEFORE_SLEEP: u32 = 20_000;

/// A job: `f(0..tasks)`, each index run once by whichever thread claims it.
struct Job {
    /// The closure, lifetime erased; valid while the job's epoch is open (see `Pool::for_each`).
    f: *const (dyn Fn(usize) + Sync),
    tasks: usize,
}

struct Shared {
    /// The current job's number; a change wakes the workers.
    epoch: AtomicU64,
    /// The last job whose tasks are all done (workers that see it no longer touch that job).
    closed: AtomicU64,
    /// Workers inside a job (holding its closure).
    users: AtomicUsize,
    /// Next task index to claim, and tasks finished, of the current job.
    next: AtomicUsize,
    done: AtomicUsize,
    /// Written by the caller before `epoch` is raised, read by workers after they see it.
    job: Mutex<Option<JobPtr>>,
    shutdown: AtomicBool,
    /// Per worker: asleep (the caller must wake it).
    asleep: Vec<AtomicBool>,
    /// The first panic of a worker's task, re-raised by the caller.
    panic: Mutex<Option<Box<dyn std::any::Any + Send>>>,
    /// Workers that have started running (`Pool::new` waits for all).
    started: AtomicUsize,
}

#[derive(Clone, Copy)]
struct JobPtr(*const (dyn Fn(usize) + Sync), usize);
// SAFETY: the pointer is only dereferenced while the job is open, and the closure is `Sync`.
unsafe impl Send for JobPtr {}

/// Worker threads for [`split`]; see the module docs. Dropping the pool stops them.
pub struct Pool {
    shared: Arc<Shared>,
    threads: Vec<(JoinHandle<()>, Thread)>,
    /// Serialises `for_each` calls from different threads on one pool.
    busy: Mutex<()>,
}

impl std::fmt::Debug for Pool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Pool({} threads)", self.threads())
    }
}

impl Pool {
    /// A pool of `threads` threads in all: the caller and `threads - 1` workers.
    /// Errors: `threads` outside `1..=MAX_THREADS`, or a thread that cannot be started.
    pub fn new(threads: usize) -> Result<Pool> {
        if !(1..=MAX_THREADS).contains(&threads) {
            return Err(Error::InvalidInput(format!(
                "threads = {threads} is invalid: 1 to {MAX_THREADS} threads for one run"
            )));
        }
        let shared = Arc::new(Shared {
            epoch: AtomicU64::new(0),
            closed: AtomicU64::new(0),
            users: AtomicUsize::new(0),
            next: AtomicUsize::new(0),
            done: AtomicUsize::new(0),
            job: Mutex::new(None),
            shutdown: AtomicBool::new(false),
            asleep: (1..threads).map(|_| AtomicBool::new(false)).collect(),
            panic: Mutex::new(None),
            started: AtomicUsize::new(0),
        });
        let mut handles = Vec::with_capacity(threads - 1);
        for w in 0..threads - 1 {
            let s = Arc::clone(&shared);
            let h = std::thread::Builder::new()
                .name(format!("stagerl-worker-{}", w + 1))
                .spawn(move || worker(&s, w))
                .map_err(|e| {
                    Error::InvalidInput(format!("threads = {threads}: cannot start a worker thread ({e})"))
                })?;
            let t = h.thread().clone();
            handles.push((h, t));
        }
        // Wait until every worker runs, so that starting a thread (which allocates) is over
        // before the pool's first job.
        while shared.started.load(Acquire) < threads - 1 {
            std::thread::yield_now();
        }
        Ok(Pool { shared, threads: handles, busy: Mutex::new(()) })
    }

    /// Threads in all (the caller included).
    pub fn threads(&self) -> usize {
        self.threads.len() + 1
    }

    /// Run `f(k)` for every `k` in `0..tasks`, on the caller and the workers; returns when all
    /// are done. A panic in a task is re-raised here (after every task has finished).
    pub fn for_each(&self, tasks: usize, f: &(dyn Fn(usize) + Sync)) {
        if tasks == 0 {
            return;
        }
        if self.threads.is_empty() || tasks == 1 {
            return (0..tasks).for_each(f);
        }
        let _one_job_at_a_time = self.busy.lock().unwrap_or_else(|p| p.into_inner());
        SPLIT_JOBS.fetch_add(1, Relaxed);
        let s = &*self.shared;
        // SAFETY (of the erased lifetime): workers dereference the pointer only between seeing
        // the new epoch with `closed` below it and leaving `users`; `Open::drop` closes the
        // epoch and waits until `users` is 0 before this frame (and `f`) can end, also when a
        // task of the caller panics.
        let erased: *const (dyn Fn(usize) + Sync + '_) = f;
        let erased: *const (dyn Fn(usize) + Sync + 'static) = unsafe { std::mem::transmute(erased) };
        *s.job.lock().unwrap_or_else(|p| p.into_inner()) = Some(JobPtr(erased, tasks));
        // Task 0 is the caller's (so its data stays in the caller's cache); workers start at 1.
        s.next.store(1, Relaxed);
        s.done.store(0, Relaxed);
        let epoch = s.epoch.load(Relaxed) + 1;
        s.epoch.store(epoch, SeqCst);
        for (w, (_, t)) in self.threads.iter().enumerate() {
            if s.asleep[w].swap(false, SeqCst) {
                t.unpark();
            }
        }
        let open = Open { s, epoch, tasks };
        // Inside a task this thread has no pool: a nested `split` runs serially (the pool is busy).
        install(None, || {
            run_task(s, f, 0);
            run_tasks(s, &Job { f: erased, tasks });
        });
        drop(open);
        if let Some(p) = s.panic.lock().unwrap_or_else(|p| p.into_inner()).take() {
            std::panic::resume_unwind(p);
        }
    }
}

/// The caller's hold on an open job: dropping it waits for every task, closes the job and waits
/// until no worker holds its closure.
struct Open<'a> {
    s: &'a Shared,
    epoch: u64,
    tasks: usize,
}

impl Drop for Open<'_> {
    fn drop(&mut self) {
        let s = self.s;
        // Tasks nobody took (the caller's own task 0 panics inside `run_task`, so this only
        // matters if `install` itself unwinds) are claimed so no worker starts them.
        while s.next.fetch_add(1, AcqRel) < self.tasks {
            s.done.fetch_add(1, AcqRel);
        }
        while s.done.load(Acquire) < self.tasks {
            std::hint::spin_loop();
        }
        s.closed.store(self.epoch, SeqCst);
        while s.users.load(SeqCst) != 0 {
            std::hint::spin_loop();
        }
    }
}

/// Claim and run tasks of `job` until none is left.
fn run_tasks(s: &Shared, job: &Job) {
    loop {
        let k = s.next.fetch_add(1, AcqRel);
        if k >= job.tasks {
            return;
        }
        // SAFETY: the job is open (see `Pool::for_each`).
        run_task(s, unsafe { &*job.f }, k);
    }
}

/// Run task `k`, keeping a panic for the caller, and count it done.
fn run_task(s: &Shared, f: &(dyn Fn(usize) + Sync), k: usize) {
    if let Err(p) = catch_unwind(AssertUnwindSafe(|| f(k))) {
        let mut slot = s.panic.lock().unwrap_or_else(|p| p.into_inner());
        slot.get_or_insert(p);
    }
    s.done.fetch_add(1, AcqRel);
}

fn worker(s: &Shared, w: usize) {
    s.started.fetch_add(1, Release);
    let mut seen = 0u64;
    loop {
        let mut spins = 0u32;
        let epoch = loop {
            if s.shutdown.load(Acquire) {
                return;
            }
            let e = s.epoch.load(Acquire);
            if e != seen {
                break e;
            }
            spins += 1;
            if spins < SPINS_BEFORE_SLEEP {
                std::hint::spin_loop();
            } else {
                s.asleep[w].store(true, SeqCst);
                if s.epoch.load(SeqCst) == seen && !s.shutdown.load(SeqCst) {
                    std::thread::park();
                }
                s.asleep[w].store(false, SeqCst);
                spins = 0;
            }
        };
        seen = epoch;
        s.users.fetch_add(1, SeqCst);
        if s.closed.load(SeqCst) < epoch {
            let job = *s.job.lock().unwrap_or_else(|p| p.into_inner());
            if let Some(JobPtr(f, tasks)) = job {
                run_tasks(s, &Job { f, tasks });
            }
        }
        s.users.fetch_sub(1, SeqCst);
    }
}

impl Drop for Pool {
    fn drop(&mut self) {
        self.shared.shutdown.store(true, SeqCst);
        for (_, t) in &self.threads {
            t.unpark();
        }
        for (h, _) in self.threads.drain(..) {
            let _ = h.join();
        }
    }
}

/// Jobs split over more than one thread so far, by every pool of the process.
static SPLIT_JOBS: AtomicU64 = AtomicU64::new(0);

/// How many jobs every pool of the process has split over more than one thread so far (for
/// tests and diagnostics: whether work was split at all).
pub fn split_jobs() -> u64 {
    SPLIT_JOBS.load(Relaxed)
}

thread_local! {
    /// The pool installed on this thread ([`install`]), if any.
    static CURRENT: Cell<Option<*const Pool>> = const { Cell::new(None) };
}

/// Run `f` with `pool` as this thread's pool for [`split`] (none: serial), then restore the
/// previous one.
pub fn install<R>(pool: Option<&Pool>, f: impl FnOnce() -> R) -> R {
    struct Restore(Option<*const Pool>);
    impl Drop for Restore {
        fn drop(&mut self) {
            CURRENT.with(|c| c.set(self.0));
        }
    }
    let _restore = Restore(CURRENT.with(|c| c.replace(pool.map(|p| p as *const Pool))));
    f()
}

/// Threads of the pool installed on this thread (1 if none).
pub fn current_threads() -> usize {
    // SAFETY: an installed pool outlives its `install` scope, inside which this runs.
    CURRENT.with(|c| c.get().map_or(1, |p| unsafe { &*p }.threads()))
}

/// Split `0..n` into contiguous ranges, their starts multiples of `align`, and run `f` on each
/// across this thread's pool; serially (one call with `0..n`) without a pool or when
/// `n * cost` (the caller's estimate of the work, e.g. multiply-adds) is below `min_cost`. `f`
/// must write disjoint outputs per range, with values that do not depend on the split.
pub fn split(n: usize, align: usize, cost: usize, min_cost: usize, f: &(dyn Fn(Range<usize>) + Sync)) {
    let pool = CURRENT.with(Cell::get);
    let Some(pool) = pool else { return f(0..n) };
    // SAFETY: as in `current_threads`.
    let pool = unsafe { &*pool };
    let align = align.max(1);
    let pieces = pool.threads().min(n.div_ceil(align));
    if pieces <= 1 || n.saturating_mul(cost) < min_cost {
        return f(0..n);
    }
    let per = n.div_ceil(pieces).div_ceil(align) * align;
    pool.for_each(n.div_ceil(per), &|k| f(k * per..((k + 1) * per).min(n)));
}

/// [`split`] over the rows of `out` (`rows` rows of `row_len` values): `f(range, rows_of_out)`
/// gets each range of rows with those rows of `out` alone, so the pieces cannot overlap.
///
/// # Panics
/// If `out` holds fewer than `rows * row_len` values.
#[allow(clippy::too_many_arguments)]
pub fn split_rows_mut<T: Send>(
    out: &mut [T],
    rows: usize,
    row_len: usize,
    align: usize,
    cost: usize,
    min_cost: usize,
    f: &(dyn Fn(Range<usize>, &mut [T]) + Sync),
) {
    let out = &mut out[..rows * row_len];
    let base = Base(out.as_mut_ptr());
    let base = &base;
    split(rows, align, cost, min_cost, &|r: Range<usize>| {
        // SAFETY: `split` gives disjoint ranges inside 0..rows, so these slices are disjoint
        // parts of `out`, alive for this call.
        let piece =
            unsafe { std::slice::from_raw_parts_mut(base.0.add(r.start * row_len), r.len() * row_len) };
        f(r, piece)
    });
}

/// `f(k, &mut a[k], &mut b[k])` for every `k`: [`for_each_mut3`] with two slices.
pub fn for_each_mut<A: Send, B: Send>(a: &mut [A], b: &mut [B], f: &(dyn Fn(usize, &mut A, &mut B) + Sync)) {
    // A `Vec` of zero-sized values allocates nothing, at any length.
    let mut units = vec![(); a.len()];
    for_each_mut3(a, b, &mut units, &|k, x, y, _| f(k, x, y));
}

/// `f(k, &mut a[k], &mut b[k], &mut c[k])` for every `k`, one item per task across this thread's
/// pool (item 0 on the calling thread), e.g. twin critics with their optimisers and scratch.
/// Each call touches its own items only, so the results are those of the serial loop.
///
/// # Panics
/// If the slices differ in length.
pub fn for_each_mut3<A: Send, B: Send, C: Send>(
    a: &mut [A],
    b: &mut [B],
    c: &mut [C],
    f: &(dyn Fn(usize, &mut A, &mut B, &mut C) + Sync),
) {
    let n = a.len();
    assert!(b.len() == n && c.len() == n, "par::for_each_mut3: slices of different lengths");
    let (pa, pb, pc) = (Base(a.as_mut_ptr()), Base(b.as_mut_ptr()), Base(c.as_mut_ptr()));
    let (pa, pb, pc) = (&pa, &pb, &pc);
    for_each_index(n, &|k| {
        // SAFETY: each index is run once, so the items `k` are borrowed by one call only, while
        // the slices stay borrowed mutably by this function.
        let (x, y, z) = unsafe { (&mut *pa.0.add(k), &mut *pb.0.add(k), &mut *pc.0.add(k)) };
        f(k, x, y, z)
    });
}

/// `a()` on the calling thread and `b()` on a worker of this thread's pool, at once (one after
/// the other without a pool).
pub fn join<A: FnOnce() + Send, B: FnOnce() + Send>(a: A, b: B) {
    if current_threads() == 1 {
        a();
        return b();
    }
    let (a, b) = (Mutex::new(Some(a)), Mutex::new(Some(b)));
    for_each_index(2, &|k| {
        if k == 0 {
            if let Some(f) = a.lock().unwrap_or_else(|p| p.into_inner()).take() {
                f();
            }
        } else if let Some(f) = b.lock().unwrap_or_else(|p| p.into_inner()).take() {
            f();
        }
    });
}

/// `f(k)` for `k` in `0..n`, one task each across this thread's pool (`f(0)` on the calling
/// thread), or serially without one.
fn for_each_index(n: usize, f: &(dyn Fn(usize) + Sync)) {
    match CURRENT.with(Cell::get) {
        // SAFETY: as in `current_threads`.
        Some(p) if n > 1 => unsafe { &*p }.for_each(n, f),
        _ => (0..n).for_each(f),
    }
}

/// A raw pointer shared by the tasks of one job (see its uses).
struct Base<T>(*mut T);
// SAFETY: every use hands each task disjoint elements, borrowed mutably by the caller until
// the job has ended.
unsafe impl<T: Send> Sync for Base<T> {}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicU32;

    #[test]
    fn every_task_runs_once_on_any_pool() {
        for threads in [1, 2, 3, 5] {
            let pool = Pool::new(threads).unwrap();
            for tasks in [0, 1, 2, 7, 100] {
                let hits: Vec<AtomicU32> = (0..tasks).map(|_| AtomicU32::new(0)).collect();
                for _ in 0..50 {
                    pool.for_each(tasks, &|k| {
                        hits[k].fetch_add(1, Relaxed);
                    });
                }
                assert!(hits.iter().all(|h| h.load(Relaxed) == 50), "threads {threads}, tasks {tasks}");
            }
        }
    }

    #[test]
    fn split_covers_the_range_in_aligned_pieces() {
        let pool = Pool::new(2).unwrap();
        for n in [0, 1, 5, 8, 9, 255, 256, 257] {
            let seen = Mutex::new(Vec::new());
            install(Some(&pool), || split(n, 8, 1000, 1, &|r| seen.lock().unwrap().push(r)));
            let mut seen = seen.into_inner().unwrap();
            seen.sort_by_key(|r| r.start);
            let covered: Vec<usize> = seen.iter().flat_map(|r| r.clone()).collect();
            assert_eq!(covered, (0..n).collect::<Vec<_>>(), "n = {n}");
            assert!(seen.iter().all(|r| r.start % 8 == 0));
            assert!(seen.len() <= 2);
            if n >= 16 {
                assert_eq!(seen.len(), 2, "n = {n}: both threads get a piece");
            }
        }
        // Too little work, or no pool: one call.
        let calls = AtomicU32::new(0);
        install(Some(&pool), || {
            split(256, 8, 1, 1 << 20, &|_| {
                calls.fetch_add(1, Relaxed);
            })
        });
        split(256, 8, 1000, 1, &|_| {
            calls.fetch_add(1, Relaxed);
        });
        assert_eq!(calls.load(Relaxed), 2);
        assert_eq!(current_threads(), 1);
        assert_eq!(install(Some(&pool), current_threads), 2);
    }

    #[test]
    fn a_split_inside_a_task_runs_serially() {
        let pool = Pool::new(2).unwrap();
        let inner = AtomicUsize::new(0);
        install(Some(&pool), || {
            split(64, 8, 1, 1, &|_| {
                split(64, 8, 1, 1, &|r| {
                    assert_eq!(r, 0..64, "nested: one serial call");
                    inner.fetch_add(1, Relaxed);
                });
            })
        });
        assert_eq!(inner.load(Relaxed), 2);
    }

    #[test]
    fn for_each_mut_gives_each_call_its_items() {
        let pool = Pool::new(2).unwrap();
        let (mut a, mut b, mut c) = (vec![0u64; 5], vec![1u64; 5], vec![0usize; 5]);
        for _ in 0..100 {
            install(Some(&pool), || {
                for_each_mut3(&mut a, &mut b, &mut c, &|k, x, y, z| {
                    *x += k as u64;
                    *y += 1;
                    *z = k;
                })
            });
        }
        assert_eq!(a, [0, 100, 200, 300, 400]);
        assert_eq!(b, [101; 5]);
        assert_eq!(c, [0, 1, 2, 3, 4]);
        let (mut c, mut d) = (vec![1], vec![2]);
        for_each_mut(&mut c, &mut d, &|_, x, y| std::mem::swap(x, y));
        assert_eq!((c[0], d[0]), (2, 1));
        // More items than a pool may have threads.
        let (mut c, mut d) = (vec![0usize; 3 * MAX_THREADS], vec![1usize; 3 * MAX_THREADS]);
        install(Some(&pool), || for_each_mut(&mut c, &mut d, &|k, x, y| (*x, *y) = (k, *y + k)));
        assert!(c.iter().zip(&d).enumerate().all(|(k, (&x, &y))| x == k && y == k + 1));
        // join: both run, on two threads with the pool.
        let (mut x, mut y) = (0, 0);
        let (tx, ty) = (std::sync::Mutex::new(None), std::sync::Mutex::new(None));
        install(Some(&pool), || {
            join(
                || {
                    x = 1;
                    *tx.lock().unwrap() = Some(std::thread::current().id());
                },
                || {
                    y = 2;
                    *ty.lock().unwrap() = Some(std::thread::current().id());
                },
            )
        });
        assert_eq!((x, y), (1, 2));
        assert_eq!(tx.into_inner().unwrap(), Some(std::thread::current().id()), "a runs on the caller");
    }

    #[test]
    fn a_panicking_task_reaches_the_caller_and_the_pool_goes_on() {
        let pool = Pool::new(2).unwrap();
        for _ in 0..20 {
            let r = catch_unwind(AssertUnwindSafe(|| {
                pool.for_each(4, &|k| {
                    if k == 3 {
                        panic!("task 3");
                    }
                })
            }));
            assert!(r.is_err());
        }
        let sum = AtomicUsize::new(0);
        pool.for_each(10, &|k| {
            sum.fetch_add(k, Relaxed);
        });
        assert_eq!(sum.load(Relaxed), 45);
    }

    #[test]
    fn workers_wake_after_sleeping_and_bad_sizes_are_refused() {
        let pool = Pool::new(2).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(50));
        let sum = AtomicUsize::new(0);
        pool.for_each(64, &|k| {
            sum.fetch_add(k, Relaxed);
        });
        assert_eq!(sum.load(Relaxed), 2016);
        let e = Pool::new(0).unwrap_err().to_string();
        assert!(e.contains("threads = 0") && e.contains("1 to 64"), "{e}");
        assert!(Pool::new(65).is_err());
    }
}
