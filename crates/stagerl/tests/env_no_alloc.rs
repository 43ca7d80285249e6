//! `ReachEnv::step` and `VecEnv::step` allocate nothing: counted with a global allocator.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn stepping_and_resetting_allocate_nothing() {
    let cfg = stagerl::config::Config::default();
    let mut env = stagerl::env::ReachEnv::from_config(&cfg, 1).unwrap();
    let mut venv = stagerl::env::VecEnv::from_config(4, &cfg, 1).unwrap();
    let actions: Vec<f32> = (0..4 * 6).map(|i| ((i * 7919) % 200) as f32 / 100.0 - 1.0).collect();
    env.reset();
    let before = ALLOCS.load(Ordering::Relaxed);
    let mut episodes = 0;
    for k in 0..10_000 {
        let a = &actions[(k % 4) * 6..(k % 4 + 1) * 6];
        if env.step(a).unwrap().done() {
            env.reset();
            episodes += 1;
        }
        venv.step(&actions).unwrap();
    }
    let after = ALLOCS.load(Ordering::Relaxed);
    assert!(episodes > 100, "resets were exercised: {episodes}");
    assert_eq!(after - before, 0, "allocations during 10 000 steps");
}
