//! Hand-run timing of the single-threaded `gemm` products behind one dense layer
//! (batch 256), for the layouts the engine uses and their alternatives.
//!
//! `cargo bench -p stagerl --bench nn_gemm`

use std::hint::black_box;
use std::time::Instant;

/// `dst (m x n) = [dst +] lhs (m x k) rhs (k x n)`; strides as (row, column).
#[allow(clippy::too_many_arguments)]
fn mm(
    m: usize,
    n: usize,
    k: usize,
    dst: &mut [f32],
    ds: (usize, usize),
    acc: bool,
    lhs: &[f32],
    ls: (usize, usize),
    rhs: &[f32],
    rs: (usize, usize),
) {
    assert!(dst.len() >= m * n && lhs.len() >= m * k && rhs.len() >= k * n);
    // SAFETY: every view is an m x n, m x k or k x n matrix inside a slice at least that long.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            ds.1 as isize,
            ds.0 as isize,
            acc,
            lhs.as_ptr(),
            ls.1 as isize,
            ls.0 as isize,
            rhs.as_ptr(),
            rs.1 as isize,
            rs.0 as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        )
    }
}

fn time(mut f: impl FnMut()) -> f64 {
    for _ in 0..50 {
        f();
    }
    let mut best = f64::INFINITY;
    for _ in 0..7 {
        let t = Instant::now();
        for _ in 0..200 {
            f();
        }
        best = best.min(t.elapsed().as_secs_f64() * 1e6 / 200.0);
    }
    best
}

fn main() {
    // `cargo bench` passes `--bench`; under `cargo test --all-targets` there is nothing to check.
    if !std::env::args().any(|a| a == "--bench") {
        println!("nn_gemm: timings only, run with `cargo bench -p stagerl --bench nn_gemm`");
        return;
    }
    // The CPU's f32 peak as gemm reaches it on one core: large square products, where packing
    // and call overhead vanish. The FLOP floor of an update is its FLOPs over this rate.
    for size in [512, 1024] {
        let a = vec![0.5f32; size * size];
        let mut c = vec![0.0f32; size * size];
        let t = Instant::now();
        let reps = 8;
        for _ in 0..reps {
            mm(size, size, size, &mut c, (size, 1), true, &a, (size, 1), &a, (size, 1));
        }
        let secs = t.elapsed().as_secs_f64() / reps as f64;
        println!(
            "peak: {size}^3 product {:.1} GFLOP/s (one thread)",
            2.0 * (size as f64).powi(3) / secs * 1e-9
        );
        black_box(&c);
    }
    if let Some((gflops, isa)) = fma_peak() {
        println!(
            "peak: independent {isa} fused multiply-adds, no memory traffic {gflops:.1} GFLOP/s (one thread)"
        );
    }
    let b = 256;
    println!("batch {b}, f32, best of 7 means (us) and GFLOP/s");
    for (n_in, n_out) in [(24, 64), (64, 64), (64, 1), (24, 256), (256, 256), (256, 12)] {
        let x = vec![0.5f32; b * n_in];
        let w = vec![0.25f32; n_out * n_in];
        let dy = vec![0.1f32; b * n_out];
        let mut y = vec![0.0f32; b * n_out];
        let mut gw = vec![0.0f32; n_out * n_in];
        let mut dx = vec![0.0f32; b * n_in];
        let flop = 2.0 * (b * n_in * n_out) as f64;
        let report = |name: &str, us: f64| {
            println!("  {n_in:>3}->{n_out:<3} {name:<34} {us:8.2} us {:6.1} GFLOP/s", flop / us * 1e-3)
        };
        // Forward y = x W^T, W stored [out, in] (PyTorch) or [in, out].
        report(
            "fwd  W[out,in]",
            time(|| mm(b, n_out, n_in, &mut y, (n_out, 1), true, &x, (n_in, 1), &w, (1, n_in))),
        );
        report(
            "fwd  W[in,out]",
            time(|| mm(b, n_out, n_in, &mut y, (n_out, 1), true, &x, (n_in, 1), &w, (n_out, 1))),
        );
        // Weight gradient dW += dy^T x, stored [out, in] or [in, out].
        report(
            "dW   [out,in] += dy^T x",
            time(|| mm(n_out, n_in, b, &mut gw, (n_in, 1), true, &dy, (1, n_out), &x, (n_in, 1))),
        );
        report(
            "dW   [in,out] += x^T dy",
            time(|| mm(n_in, n_out, b, &mut gw, (n_out, 1), true, &x, (1, n_in), &dy, (n_out, 1))),
        );
        // Input gradient dx = dy W.
        report(
            "dx   W[out,in]",
            time(|| mm(b, n_in, n_out, &mut dx, (n_in, 1), false, &dy, (n_out, 1), &w, (n_in, 1))),
        );
        report(
            "dx   W[in,out]",
            time(|| mm(b, n_in, n_out, &mut dx, (n_in, 1), false, &dy, (n_out, 1), &w, (1, n_out))),
        );
        black_box((&y, &gw, &dx));
    }
}

/// The core's f32 fused multiply-add rate with no memory traffic at all (12 independent vector
/// accumulators, so latency is hidden): the hardware's ceiling, above any matrix kernel's.
/// `None` off x86-64 or without AVX2 + FMA.
fn fma_peak() -> Option<(f64, &'static str)> {
    #[cfg(target_arch = "x86_64")]
    {
        let iters = 20_000_000usize;
        let (lanes, isa, run): (usize, &str, fn(usize) -> f32) =
            if std::arch::is_x86_feature_detected!("avx512f") {
                (16, "AVX-512", |n| unsafe { fma512(n) })
            } else if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                (8, "AVX2", |n| unsafe { fma256(n) })
            } else {
                return None;
            };
        run(iters / 10);
        let mut best = f64::INFINITY;
        for _ in 0..5 {
            let t = Instant::now();
            black_box(run(black_box(iters)));
            best = best.min(t.elapsed().as_secs_f64());
        }
        let flop = (iters * 12 * lanes * 2) as f64;
        Some((flop / best * 1e-9, isa))
    }
    #[cfg(not(target_arch = "x86_64"))]
    None
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn fma512(iters: usize) -> f32 {
    use std::arch::x86_64::*;
    let m = _mm512_set1_ps(0.999_999);
    let c = _mm512_set1_ps(1e-7);
    let mut acc = [_mm512_set1_ps(1.0); 12];
    for _ in 0..iters {
        for a in acc.iter_mut() {
            *a = _mm512_fmadd_ps(*a, m, c);
        }
    }
    acc.iter().map(|&a| _mm512_reduce_add_ps(a)).sum()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fma256(iters: usize) -> f32 {
    use std::arch::x86_64::*;
    let m = _mm256_set1_ps(0.999_999);
    let c = _mm256_set1_ps(1e-7);
    let mut acc = [_mm256_set1_ps(1.0); 12];
    for _ in 0..iters {
        for a in acc.iter_mut() {
            *a = _mm256_fmadd_ps(*a, m, c);
        }
    }
    let mut out = [0f32; 8];
    let s = acc.iter().fold(_mm256_setzero_ps(), |s, &a| _mm256_add_ps(s, a));
    _mm256_storeu_ps(out.as_mut_ptr(), s);
    out.iter().sum()
}
