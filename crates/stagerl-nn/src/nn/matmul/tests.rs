//! The products against plain reference loops, bit for bit, at every SIMD level, on random
//! shapes (edge sizes included) and on the networks' real shapes.

use super::*;
use crate::base::rng::Rng;

const LEVELS: [SimdLevel; 3] = [SimdLevel::Avx512, SimdLevel::Avx2, SimdLevel::Baseline];

/// One chain `acc = fma(a_p, b_p, acc)` over `p = 0..k` in increasing order from `init`.
fn chain(init: f32, k: usize, ab: impl Fn(usize) -> (f32, f32)) -> f32 {
    let mut acc = init;
    for p in 0..k {
        let (a, b) = ab(p);
        acc = a.mul_add(b, acc);
    }
    acc
}

/// The one-column forward order: 16 chains over `p = l (mod 16)`, then the fixed tree.
fn dot16(k: usize, ab: impl Fn(usize) -> (f32, f32)) -> f32 {
    let mut s = [0.0f32; 16];
    for p in 0..k {
        let (a, b) = ab(p);
        s[p % 16] = a.mul_add(b, s[p % 16]);
    }
    let pair = |l: usize| s[l] + s[l + 8];
    let quad = |l: usize| pair(l) + pair(l + 4);
    (quad(0) + quad(2)) + (quad(1) + quad(3))
}

/// Random values of mixed magnitudes (2^-6 .. 2^6), with exact zeros of both signs.
fn values(rng: &mut Rng, n: usize) -> Vec<f32> {
    (0..n)
        .map(|_| match rng.below(16) {
            0 => 0.0,
            1 => -0.0,
            _ => (rng.normal() * 2f64.powi(rng.below(13) as i32 - 6)) as f32,
        })
        .collect()
}

/// Guard values after the outputs, which no product may touch.
const GUARD: usize = 37;

fn assert_same(what: &str, got: &[f32], want: &[f32]) {
    assert_eq!(got.len(), want.len());
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert_eq!(g.to_bits(), w.to_bits(), "{what}: element {i}: {g:e} against the reference {w:e}");
    }
}

fn check_forward(rng: &mut Rng, (m, n, k): (usize, usize, usize)) {
    let (x, w, bias) = (values(rng, m * k), values(rng, n * k), values(rng, n));
    let product: Vec<f32> = (0..m * n)
        .map(|e| {
            let (i, j) = (e / n, e % n);
            let ab = |p: usize| (x[i * k + p], w[j * k + p]);
            if n == 1 {
                dot16(k, ab)
            } else {
                chain(0.0, k, ab)
            }
        })
        .collect();
    for act in [None, Some(Activation::Identity), Some(Activation::Relu), Some(Activation::Tanh)] {
        // The reference: the product, then the bias and activation as the engine's own loop.
        let mut want = product.clone();
        if let Some(f) = act {
            f.add_bias_apply(&mut want, &bias);
        }
        want.extend(std::iter::repeat_n(7.0, GUARD));
        for level in LEVELS {
            let mut y = vec![f32::NAN; m * n + GUARD];
            y[m * n..].fill(7.0);
            forward_at(level, (m, n, k), &mut y, &x, &w, act.map(|f| (&bias[..], f)));
            assert_same(&format!("forward {m}x{n}x{k} {act:?} at {level:?}"), &y, &want);
        }
    }
}

fn check_backward_weight(rng: &mut Rng, (m, n, k): (usize, usize, usize)) {
    let (dy, x, dw0) = (values(rng, k * m), values(rng, k * n), values(rng, m * n + GUARD));
    let want: Vec<f32> = (0..m * n)
        .map(|e| chain(dw0[e], k, |p| (dy[p * m + e / n], x[p * n + e % n])))
        .chain(dw0[m * n..].iter().copied())
        .collect();
    for level in LEVELS {
        let mut dw = dw0.clone();
        backward_weight_at(level, (m, n, k), &mut dw, &dy, &x);
        assert_same(&format!("backward_weight {m}x{n}x{k} at {level:?}"), &dw, &want);
    }
}

/// `dx = dy W[:, start..start + n]` for a weight `k x (start + n + after)`, alone and fused with
/// the backward pass of each activation (with and without the bias gradient).
fn check_backward_input(rng: &mut Rng, (m, n, k): (usize, usize, usize), (start, after): (usize, usize)) {
    let w_rs = start + n + after;
    let (dy, weight) = (values(rng, m * k), values(rng, k * w_rs));
    let product: Vec<f32> = (0..m * n)
        .map(|e| chain(0.0, k, |p| (dy[e / n * k + p], weight[p * w_rs + start + e % n])))
        .collect();
    // Outputs of a previous layer: of either sign with zeros (ReLU), inside (-1, 1) (tanh).
    let ys: Vec<f32> = values(rng, m * n).iter().map(|v| (v * 0.1).clamp(-0.99, 0.99)).collect();
    let bias_grad0 = values(rng, n);
    let derivs = [None, Some(Activation::Identity), Some(Activation::Relu), Some(Activation::Tanh)];
    for (f, with_sum) in derivs.into_iter().flat_map(|f| [(f, false), (f, true)]) {
        if f.is_none() && with_sum {
            continue;
        }
        // The reference: the product, then the activation's own backward loop.
        let (mut want, mut want_bias) = (product.clone(), bias_grad0.clone());
        match (f, with_sum) {
            (Some(f), true) => f.backward_sum(&ys, &mut want, &mut want_bias),
            (Some(f), false) => f.backward(&ys, &mut want),
            (None, _) => {}
        }
        want.extend(std::iter::repeat_n(7.0, GUARD));
        for level in LEVELS {
            let mut dx = vec![f32::NAN; m * n + GUARD];
            dx[m * n..].fill(7.0);
            let mut bias_grad = bias_grad0.clone();
            let deriv = f.map(|f| Deriv { ys: &ys, f, bias_grad: with_sum.then_some(&mut bias_grad[..]) });
            backward_input_at(level, (m, n, k), &mut dx, &dy, (&weight[start..], w_rs), deriv);
            let what = format!(
                "backward_input {m}x{n}x{k} cols {start}.. of {w_rs} {f:?} sum {with_sum} at {level:?}"
            );
            assert_same(&what, &dx, &want);
            assert_same(&format!("{what}: bias gradient"), &bias_grad, &want_bias);
        }
    }
}

#[test]
fn every_level_matches_the_reference_on_random_small_shapes_and_edges() {
    let mut rng = Rng::new(10);
    for _ in 0..300 {
        let (m, n, k) = (1 + rng.below(40) as usize, 1 + rng.below(80) as usize, 1 + rng.below(40) as usize);
        check_forward(&mut rng, (m, n, k));
        check_backward_weight(&mut rng, (m, n, k));
        let (start, after) = (rng.below(5) as usize, rng.below(5) as usize);
        check_backward_input(&mut rng, (m, n, k), (start, after));
    }
}

/// Batch 256, observations 16, critic inputs 22, hidden 64 and 256, outputs 1, 6 and 12, and
/// sizes past the forward pass's depth and column blocks (128 and 64).
#[test]
fn every_level_matches_the_reference_on_the_networks_shapes() {
    let mut rng = Rng::new(11);
    for (i, o) in [(16, 64), (22, 64), (64, 64), (64, 1), (64, 6), (64, 12), (22, 256), (256, 256), (256, 1)]
        .into_iter()
        .chain([(256, 12), (256, 6), (129, 65), (300, 130), (255, 127), (17, 1), (3, 2)])
    {
        check_forward(&mut rng, (256, o, i));
        check_backward_weight(&mut rng, (o, i, 256));
        check_backward_input(&mut rng, (256, i, o), (0, 0));
    }
    // dQ/da: the action columns 16..22 of a critic's first layer.
    for h in [64, 256] {
        check_backward_input(&mut rng, (256, 6, h), (16, 0));
    }
    check_backward_input(&mut rng, (33, 40, 7), (3, 100));
}

/// Empty products: `k = 0` overwrites with +0.0 (or leaves an accumulated output), `m = 0` or
/// `n = 0` touches nothing.
#[test]
fn empty_products() {
    for level in LEVELS {
        let mut y = vec![f32::NAN; 12];
        forward_at(level, (3, 4, 0), &mut y, &[], &[], None);
        assert!(y.iter().all(|v| v.to_bits() == 0));
        forward_at(level, (3, 4, 0), &mut y, &[], &[], Some((&[1.0, -2.0, 3.0, -4.0], Activation::Relu)));
        assert_eq!(y, [1.0, 0.0, 3.0, 0.0].repeat(3));
        let mut dw = vec![2.5f32; 12];
        backward_weight_at(level, (3, 4, 0), &mut dw, &[], &[]);
        assert!(dw.iter().all(|&v| v == 2.5));
        let mut dx = vec![f32::NAN; 12];
        backward_input_at(level, (3, 4, 0), &mut dx, &[], (&[], 4), None);
        assert!(dx.iter().all(|v| v.to_bits() == 0));
        let mut y = vec![1.0f32; 4];
        forward_at(level, (0, 4, 3), &mut y, &[], &[0.0; 12], None);
        backward_weight_at(level, (4, 0, 3), &mut y, &[0.0; 12], &[]);
        assert_eq!(y, [1.0; 4]);
    }
}

/// `f64` runs the same chains (the portable loops), checked against an `f64` reference.
#[test]
fn f64_follows_the_same_order() {
    let mut rng = Rng::new(12);
    let (m, n, k) = (9, 5, 37);
    let x: Vec<f64> = (0..m * k).map(|_| rng.normal()).collect();
    let w: Vec<f64> = (0..n * k).map(|_| rng.normal()).collect();
    let mut y = vec![0.0; m * n];
    forward((m, n, k), &mut y, &x, &w, None);
    for (e, &v) in y.iter().enumerate() {
        let (i, j) = (e / n, e % n);
        let want = (0..k).fold(0.0f64, |acc, p| x[i * k + p].mul_add(w[j * k + p], acc));
        assert_eq!(v.to_bits(), want.to_bits());
    }
    let mut dw = vec![0.5; k * n];
    backward_weight((k, n, m), &mut dw, &x, &y);
    for (e, &v) in dw.iter().enumerate() {
        let (i, j) = (e / n, e % n);
        let want = (0..m).fold(0.5f64, |acc, p| x[p * k + i].mul_add(y[p * n + j], acc));
        assert_eq!(v.to_bits(), want.to_bits());
    }
}

/// The fused bias and ReLU give the bits of the separate loop also where the sum is a zero of
/// either sign or NaN (`maxps` keeps its second operand, +0.0, in both cases).
#[test]
fn fused_relu_on_zeros_and_nan() {
    // Column 0 of row 0 is -0.0 (products that underflow to -0.0), row 1 is NaN, row 2 an
    // exact cancellation to +0.0; biases of both signed zeros.
    let (m, n, k) = (3, 2, 2);
    let x = [-1e-30f32, -1e-30, f32::NAN, 1.0, 2.0, -2.0];
    let w = [1e-30f32, 1e-30, 1.0, 1.0];
    for bias in [[-0.0f32, 0.0], [0.0, -0.0]] {
        for f in [Activation::Identity, Activation::Relu] {
            let mut want = vec![0.0f32; m * n];
            forward_at(SimdLevel::Baseline, (m, n, k), &mut want, &x, &w, None);
            f.add_bias_apply(&mut want, &bias);
            if f == Activation::Identity && bias[0].is_sign_negative() {
                assert_eq!(want[0].to_bits(), (-0.0f32).to_bits(), "the case is exercised");
            }
            for level in LEVELS {
                let mut y = vec![7.0f32; m * n];
                forward_at(level, (m, n, k), &mut y, &x, &w, Some((&bias, f)));
                for (g, w) in y.iter().zip(&want) {
                    assert!(
                        g.to_bits() == w.to_bits() || (g.is_nan() && w.is_nan()),
                        "{f:?} at {level:?}: {g} {w}"
                    );
                }
            }
        }
    }
}

/// The kernels this CPU has are the ones the tests above ran.
#[test]
fn the_cpus_simd_levels_have_kernels() {
    #[cfg(target_arch = "x86_64")]
    {
        let detected = crate::base::simd::simd_level();
        eprintln!("SIMD level of this CPU: {detected:?}");
        assert_eq!(Simd::at(SimdLevel::Avx512).is_some(), detected == SimdLevel::Avx512);
        assert_eq!(Simd::at(SimdLevel::Avx2).is_some(), detected != SimdLevel::Baseline);
        assert!(Simd::at(SimdLevel::Baseline).is_none());
    }
}
