//! Hand-run timing of the nn engine on SAC-like workloads (single thread, f32, batch 256).
//!
//! `cargo bench -p stagerl --bench nn_sac`
//!
//! 1. forward + backward of two critics (obs 16 + act 6 -> h -> h -> 1, parameter gradients)
//!    and an actor (16 -> h -> h -> 12), hidden 64 and 256;
//! 2. a full SAC update (obs 18, act 6): target actor sample, two target critics, two critic
//!    regressions with Adam, the actor update through both critics and the squashed Gaussian
//!    with Adam, and the Polyak updates, i.e. the workload of the 0.6 ms / 3.5 ms targets.

use std::alloc::{GlobalAlloc, Layout, System};
use std::hint::black_box;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use stagerl::base::rng::Rng;
use stagerl::nn::{add_assign, concat_cols, mse_loss, Activation, Adam, LogStdBound, Mlp, SquashedGaussian};

const BATCH: usize = 256;

/// The system allocator, counting allocations (to check that a warmed-up update allocates
/// nothing in stagerl itself).
struct CountingAlloc;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as ours.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as ours.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

fn randn(rng: &mut Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.normal() as f32).collect()
}

/// Nanoseconds of CPU time used by this thread (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`): unlike
/// wall time it does not count the time other processes hold the core.
#[cfg(all(target_os = "linux", target_pointer_width = "64"))]
fn cpu_ns() -> Option<u64> {
    #[repr(C)]
    struct Timespec {
        sec: i64,
        nsec: i64,
    }
    extern "C" {
        fn clock_gettime(clock: i32, ts: *mut Timespec) -> i32;
    }
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut ts = Timespec { sec: 0, nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec (64-bit Linux layout); libc is linked by std.
    let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    (rc == 0).then(|| ts.sec as u64 * 1_000_000_000 + ts.nsec as u64)
}

#[cfg(not(all(target_os = "linux", target_pointer_width = "64")))]
fn cpu_ns() -> Option<u64> {
    None
}

/// Milliseconds per call of `f`: (best, median) over `reps` windows of `iters` calls, measured as
/// on-CPU time where the OS reports it, wall time otherwise.
fn time(mut f: impl FnMut(), iters: usize, reps: usize) -> (f64, f64) {
    for _ in 0..iters {
        f();
    }
    let mut per_call: Vec<f64> = (0..reps)
        .map(|_| {
            let (c0, t0) = (cpu_ns(), Instant::now());
            for _ in 0..iters {
                f();
            }
            let wall = t0.elapsed().as_secs_f64();
            let secs = match (c0, cpu_ns()) {
                (Some(a), Some(b)) => (b - a) as f64 * 1e-9,
                _ => wall,
            };
            secs * 1e3 / iters as f64
        })
        .collect();
    per_call.sort_by(f64::total_cmp);
    (per_call[0], per_call[reps / 2])
}

fn forward_backward(hidden: usize) -> (f64, f64) {
    forward_backward_with(hidden, 20, 41)
}

fn forward_backward_with(hidden: usize, iters: usize, reps: usize) -> (f64, f64) {
    let (obs, act) = (16, 6);
    let mut rng = Rng::new(0);
    let mut q1 =
        Mlp::<f32>::new(&[obs + act, hidden, hidden, 1], Activation::Relu, Activation::Identity, &mut rng);
    let mut q2 = q1.clone();
    let mut actor =
        Mlp::<f32>::new(&[obs, hidden, hidden, 2 * act], Activation::Relu, Activation::Identity, &mut rng);
    let x_q = randn(&mut rng, BATCH * (obs + act));
    let x_a = randn(&mut rng, BATCH * obs);
    let g_q = randn(&mut rng, BATCH);
    let g_a = randn(&mut rng, BATCH * 2 * act);
    time(
        || {
            for q in [&mut q1, &mut q2] {
                q.forward(&x_q, BATCH);
                q.zero_grad();
                q.backward(&g_q);
            }
            actor.forward(&x_a, BATCH);
            actor.zero_grad();
            actor.backward(&g_a);
            black_box((q1.grads()[0], q2.grads()[0], actor.grads()[0]));
        },
        iters,
        reps,
    )
}

struct Sac {
    obs: usize,
    act: usize,
    actor: Mlp<f32>,
    q: [Mlp<f32>; 2],
    q_target: [Mlp<f32>; 2],
    actor_opt: Adam<f32>,
    q_opt: [Adam<f32>; 2],
    head: SquashedGaussian<f32>,
    // A replay batch.
    o: Vec<f32>,
    a: Vec<f32>,
    r: Vec<f32>,
    o2: Vec<f32>,
    done: Vec<f32>,
    eps: Vec<f32>,
    // Scratch.
    inp: Vec<f32>,
    y: Vec<f32>,
    g: Vec<f32>,
    da: Vec<f32>,
    dlp: Vec<f32>,
    ga: Vec<f32>,
    gb: Vec<f32>,
}

impl Sac {
    fn new(obs: usize, act: usize, hidden: usize) -> Self {
        let mut rng = Rng::new(1);
        let actor =
            Mlp::new(&[obs, hidden, hidden, 2 * act], Activation::Relu, Activation::Identity, &mut rng);
        let mk = |rng: &mut Rng| {
            Mlp::new(&[obs + act, hidden, hidden, 1], Activation::Relu, Activation::Identity, rng)
        };
        let q = [mk(&mut rng), mk(&mut rng)];
        let q_target = q.clone();
        let n_q = q[0].num_params();
        Sac {
            obs,
            act,
            actor_opt: Adam::new(actor.num_params(), 3e-4),
            q_opt: [Adam::new(n_q, 1e-3), Adam::new(n_q, 1e-3)],
            actor,
            q,
            q_target,
            head: SquashedGaussian::new(act, LogStdBound::default()),
            o: randn(&mut rng, BATCH * obs),
            a: (0..BATCH * act).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect(),
            r: randn(&mut rng, BATCH),
            o2: randn(&mut rng, BATCH * obs),
            done: (0..BATCH).map(|i| (i % 50 == 0) as u8 as f32).collect(),
            eps: randn(&mut rng, BATCH * act),
            inp: vec![0.0; BATCH * (obs + act)],
            y: vec![0.0; BATCH],
            g: vec![0.0; BATCH],
            da: vec![0.0; BATCH * act],
            dlp: vec![0.0; BATCH],
            ga: vec![0.0; BATCH],
            gb: vec![0.0; BATCH],
        }
    }

    fn update(&mut self) {
        let (obs, act, b) = (self.obs, self.act, BATCH);
        let (alpha, gamma, tau) = (0.2f32, 0.99f32, 0.005f32);
        // Critic targets.
        let raw = self.actor.predict(&self.o2, b);
        let (a2, lp2) = self.head.forward(raw, &self.eps, b);
        concat_cols(&self.o2, obs, a2, act, b, &mut self.inp);
        let [t1, t2] = &mut self.q_target;
        let v1 = t1.predict(&self.inp, b);
        let v2 = t2.predict(&self.inp, b);
        for i in 0..b {
            let v = v1[i].min(v2[i]) - alpha * lp2[i];
            self.y[i] = self.r[i] + gamma * (1.0 - self.done[i]) * v;
        }
        // Critic regressions.
        concat_cols(&self.o, obs, &self.a, act, b, &mut self.inp);
        for (q, opt) in self.q.iter_mut().zip(&mut self.q_opt) {
            let pred = q.forward(&self.inp, b);
            mse_loss(pred, &self.y, &mut self.g);
            q.zero_grad();
            q.backward(&self.g);
            let (p, g) = q.params_and_grads();
            opt.step(p, g);
        }
        // Actor.
        let raw = self.actor.forward(&self.o, b);
        let (a, _) = self.head.forward(raw, &self.eps, b);
        concat_cols(&self.o, obs, a, act, b, &mut self.inp);
        let [q1, q2] = &mut self.q;
        let v1 = q1.forward(&self.inp, b);
        let v2 = q2.forward(&self.inp, b);
        let inv_b = 1.0 / b as f32;
        for i in 0..b {
            let first = v1[i] <= v2[i];
            self.ga[i] = if first { -inv_b } else { 0.0 };
            self.gb[i] = if first { 0.0 } else { -inv_b };
        }
        let d1 = q1.input_grad_cols(&self.ga, obs..obs + act);
        self.da.copy_from_slice(d1);
        let d2 = q2.input_grad_cols(&self.gb, obs..obs + act);
        add_assign(&mut self.da, d2);
        self.dlp.iter_mut().for_each(|d| *d = alpha * inv_b);
        let d_raw = self.head.backward(&self.da, &self.dlp);
        self.actor.zero_grad();
        self.actor.backward(d_raw);
        let (p, g) = self.actor.params_and_grads();
        self.actor_opt.step(p, g);
        // Targets.
        for (t, q) in self.q_target.iter_mut().zip(&self.q) {
            t.polyak_from(q, tau);
        }
    }
}

fn main() {
    // `cargo bench` passes `--bench`; under `cargo test --all-targets` run each workload once as
    // a smoke test instead of timing it.
    if !std::env::args().any(|a| a == "--bench") {
        for hidden in [64, 256] {
            let (fb, _) = forward_backward_with(hidden, 1, 1);
            let mut sac = Sac::new(18, 6, hidden);
            sac.update();
            assert!(fb.is_finite() && sac.actor.params().iter().all(|p| p.is_finite()));
        }
        println!("nn_sac: smoke run done (timings with `cargo bench -p stagerl --bench nn_sac`)");
        return;
    }
    // Optional hidden sizes on the command line (`cargo bench --bench nn_sac -- 64`).
    let mut hiddens: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    if hiddens.is_empty() {
        hiddens = vec![64, 256];
    }
    println!("nn engine, f32, batch {BATCH}, single thread; ms per call, best / median of 41 windows of 20 calls (on-CPU time)");
    for &hidden in &hiddens {
        let (best, med) = forward_backward(hidden);
        println!("  fwd+bwd 2 critics (22-{hidden}-{hidden}-1) + actor (16-{hidden}-{hidden}-12): {best:.3} / {med:.3}");
    }
    for &hidden in &hiddens {
        let mut sac = Sac::new(18, 6, hidden);
        let (best, med) = time(|| sac.update(), 20, 41);
        let before = ALLOCATIONS.load(Ordering::Relaxed);
        for _ in 0..10 {
            sac.update();
        }
        let allocs = (ALLOCATIONS.load(Ordering::Relaxed) - before) as f64 / 10.0;
        black_box(sac.actor.params()[0]);
        println!("  full SAC update (obs 18, act 6, hidden {hidden}):               {best:.3} / {med:.3}  ({allocs} heap allocations per update)");
    }
}
