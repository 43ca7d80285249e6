//! Hand-run timing of the rewards over 1 M rows on one thread: `RewardTerms::compute` a row at
//! a time (into the same columns) against `reward::batch::compute_rows`, and `acos` alone over
//! the same rows' cosines (the part no block can speed up: glibc's `acos` is called per row).
//!
//! `cargo bench -p stagerl --bench reward_batch`

use std::hint::black_box;
use std::mem::MaybeUninit;
use std::time::Instant;

use stagerl::base::rng::Rng;
use stagerl::reward::batch::{compute_rows, Rows, COLUMNS};
use stagerl::reward::{RewardConfig, RewardTerms};

const N: usize = 1_000_000;

fn best_ms(mut f: impl FnMut()) -> f64 {
    (0..7)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let mut rng = Rng::new(1);
    let mut uniform =
        |lo: f64, hi: f64, n: usize| (0..n).map(|_| rng.uniform_range(lo, hi)).collect::<Vec<f64>>();
    let (p, t, v) = (uniform(-1.0, 1.0, 3 * N), uniform(-1.0, 1.0, 3 * N), uniform(-3.0, 3.0, 6 * N));
    let mut q = uniform(-1.0, 1.0, 4 * N);
    for row in q.chunks_mut(4) {
        let norm = row.iter().map(|x| x * x).sum::<f64>().sqrt();
        row.iter_mut().for_each(|x| *x /= norm);
    }
    let rows = Rows::new(&p, &q, &t, &v, 6, None).unwrap();
    let cfg = RewardConfig::default();
    let mut buf = vec![MaybeUninit::<f64>::uninit(); COLUMNS * N];
    let mut reached = vec![false; N];

    let row_ms = best_ms(|| {
        let mut cols = buf.chunks_mut(N);
        let mut cols: [&mut [MaybeUninit<f64>]; COLUMNS] = std::array::from_fn(|_| cols.next().unwrap());
        for i in 0..N {
            let input = rows.input(i);
            assert!(input.is_valid());
            let terms = RewardTerms::compute(&cfg, 0.05, &input);
            assert!(terms.all_finite());
            reached[i] = terms.reached;
            let [(_, d), _, rest @ ..] = terms.reported();
            cols[0][i].write(d);
            for (col, (_, x)) in cols[1..].iter_mut().zip(rest) {
                col[i].write(x);
            }
        }
        black_box(&buf);
    });
    let batch_ms = best_ms(|| {
        let mut cols = buf.chunks_mut(N);
        let mut cols: [&mut [MaybeUninit<f64>]; COLUMNS] = std::array::from_fn(|_| cols.next().unwrap());
        compute_rows(&cfg, 0.05, &rows, 0, &mut cols, &mut reached).unwrap();
        black_box(&buf);
    });
    let cosines: Vec<f64> = uniform(-1.0, 1.0, N);
    let mut phi = vec![0.0; N];
    let acos_ms = best_ms(|| {
        for (y, x) in phi.iter_mut().zip(&cosines) {
            *y = x.acos();
        }
        black_box(&phi);
    });
    println!("1 M rows, one thread, best of 7: row by row {row_ms:.1} ms, compute_rows {batch_ms:.1} ms, acos alone {acos_ms:.1} ms");
}
