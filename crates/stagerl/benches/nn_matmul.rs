//! Hand-run timing of the engine's own matrix products (`stagerl::nn::Linear`'s three products,
//! f32, batch 256, one thread) against `gemm` on the same shapes: the microbenchmark of the
//! kernels in `nn::matmul`.
//!
//! `cargo bench -p stagerl --bench nn_matmul`

use std::hint::black_box;
use std::time::Instant;

use stagerl::nn::Linear;

/// `dst (m x n) = [dst +] lhs (m x k) rhs (k x n)` with gemm; strides as (row, column).
#[allow(clippy::too_many_arguments)]
fn gemm(
    (m, n, k): (usize, usize, usize),
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

/// Best means of 200 calls of `a` and of `b`, in microseconds, measured alternately 15 times
/// (so that both see the same load on a shared machine).
fn time2(mut a: impl FnMut(), mut b: impl FnMut()) -> (f64, f64) {
    for _ in 0..100 {
        a();
        b();
    }
    let mut best = (f64::INFINITY, f64::INFINITY);
    for _ in 0..15 {
        let t = Instant::now();
        for _ in 0..200 {
            a();
        }
        best.0 = best.0.min(t.elapsed().as_secs_f64() * 1e6 / 200.0);
        let t = Instant::now();
        for _ in 0..200 {
            b();
        }
        best.1 = best.1.min(t.elapsed().as_secs_f64() * 1e6 / 200.0);
    }
    best
}

fn main() {
    // `cargo bench` passes `--bench`; under `cargo test --all-targets` there is nothing to check.
    if !std::env::args().any(|a| a == "--bench") {
        println!("nn_matmul: timings only, run with `cargo bench -p stagerl --bench nn_matmul`");
        return;
    }
    let b = 256;
    println!(
        "batch {b}, f32, best means (us) of stagerl against gemm, measured alternately, GFLOP/s of stagerl"
    );
    let (mut total_ours, mut total_gemm) = (0.0, 0.0);
    for (n_in, n_out) in [(16, 64), (22, 64), (64, 64), (64, 1), (64, 6), (64, 12)].into_iter().chain([
        (16, 256),
        (22, 256),
        (256, 256),
        (256, 1),
        (256, 6),
        (256, 12),
    ]) {
        if let Ok(only) = std::env::var("ONLY") {
            if !only.split(' ').any(|o| o == format!("{n_in}->{n_out}")) {
                continue;
            }
        }
        let layer = Linear::new(n_in, n_out, 0);
        let params: Vec<f32> = (0..layer.param_len()).map(|i| (i % 7) as f32 * 0.1 - 0.3).collect();
        let w = &params[layer.weight_range()];
        let x: Vec<f32> = (0..b * n_in).map(|i| (i % 11) as f32 * 0.1 - 0.5).collect();
        let dy: Vec<f32> = (0..b * n_out).map(|i| (i % 5) as f32 * 0.1 - 0.2).collect();
        let (mut y1, mut y2) = (vec![0.0; b * n_out], vec![0.0; b * n_out]);
        let (mut dx1, mut dx2) = (vec![0.0; b * n_in], vec![0.0; b * n_in]);
        let mut grads = vec![0.0; layer.param_len()];
        let flop = 2.0 * (b * n_in * n_out) as f64;
        let flop_da = 2.0 * (b * 6 * n_out) as f64;
        let mut report = |name: &str, (ours, theirs): (f64, f64), flop: f64| {
            (total_ours, total_gemm) = (total_ours + ours, total_gemm + theirs);
            println!(
                "  {n_in:>3}->{n_out:<3} {name:<22} {ours:8.2} us against {theirs:8.2} us ({:5.2}x) {:6.1} GFLOP/s",
                theirs / ours,
                flop / ours * 1e-3
            )
        };
        report(
            "forward y = x W^T",
            time2(
                || layer.forward_no_bias(&params, &x, b, &mut y1),
                || gemm((b, n_out, n_in), &mut y2, (n_out, 1), false, &x, (n_in, 1), w, (1, n_in)),
            ),
            flop,
        );
        let gw = &mut vec![0.0; n_out * n_in];
        report(
            "weight dW += dy^T x",
            time2(
                || layer.backward_weight(&mut grads, &x, &dy, b),
                || gemm((n_out, n_in, b), gw, (n_in, 1), true, &dy, (1, n_out), &x, (n_in, 1)),
            ),
            flop,
        );
        report(
            "input dx = dy W",
            time2(
                || layer.backward_input(&params, &dy, b, &mut dx1),
                || gemm((b, n_in, n_out), &mut dx2, (n_in, 1), false, &dy, (n_out, 1), w, (n_in, 1)),
            ),
            flop,
        );
        if n_in == 22 {
            let (mut da1, mut da2) = (vec![0.0; b * 6], vec![0.0; b * 6]);
            report(
                "input dQ/da (6 cols)",
                time2(
                    || layer.backward_input_cols(&params, &dy, b, 16..22, &mut da1),
                    || gemm((b, 6, n_out), &mut da2, (6, 1), false, &dy, (n_out, 1), &w[16..], (n_in, 1)),
                ),
                flop_da,
            );
        }
        black_box((&y1, &y2, &grads, &dx1, &dx2));
    }
    println!("total {total_ours:.1} us against {total_gemm:.1} us");
}
