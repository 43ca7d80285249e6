//! A global allocator that counts allocations, for the tests that check a hot path allocates
//! nothing. A test file installs it with
//! `#[global_allocator] static GLOBAL: common::Counting = common::Counting;`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The system allocator, counting each allocation and reallocation.
pub struct Counting;

thread_local! {
    /// Allocations made by this thread (tests run in parallel threads).
    static COUNT: Cell<usize> = const { Cell::new(0) };
}

/// Allocations made by the worker threads of `stagerl::base::par` pools.
static WORKERS: AtomicUsize = AtomicUsize::new(0);

fn count() {
    let _ = COUNT.try_with(|c| c.set(c.get() + 1));
    if std::thread::current().name().is_some_and(|n| n.starts_with("stagerl-worker")) {
        WORKERS.fetch_add(1, Ordering::Relaxed);
    }
}

/// Held by each test that makes a pool, so that no other pool's workers allocate (in their
/// warm-up) while one counts its workers' allocations.
#[allow(dead_code)] // not every test makes a pool
pub static POOL_TESTS: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Allocations made by the calling thread so far.
pub fn allocs() -> usize {
    COUNT.with(Cell::get)
}

/// Allocations made by `stagerl::base::par` workers so far (all pools of the test binary).
#[allow(dead_code)] // not every test makes a pool
pub fn worker_allocs() -> usize {
    WORKERS.load(Ordering::Relaxed)
}

// SAFETY: forwards to the system allocator unchanged.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as ours.
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        // SAFETY: same contract as ours.
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as ours.
        unsafe { System.realloc(p, l, n) }
    }
}
