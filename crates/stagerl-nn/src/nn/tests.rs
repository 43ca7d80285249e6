//! Cross-cutting tests of the engine: finite-difference gradient checks in f64 (layers, MLPs,
//! losses, the squashed Gaussian, actor-through-critic chains), f32/f64 agreement, determinism
//! and buffer reuse.

use super::*;
use crate::base::rng::Rng;

/// Central-difference step.
const H: f64 = 1e-6;
/// Relative tolerance of the gradient checks.
const TOL: f64 = 1e-6;

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * 1f64.max(a.abs()).max(b.abs())
}

fn assert_grads_close(what: &str, analytic: &[f64], numeric: &[f64]) {
    assert_eq!(analytic.len(), numeric.len(), "{what}: lengths");
    for (i, (&a, &n)) in analytic.iter().zip(numeric).enumerate() {
        assert!(close(a, n, TOL), "{what}[{i}]: analytic {a} vs numeric {n}");
    }
}

/// Central differences of `f` at `x` for every coordinate.
fn numeric_grad(x: &[f64], mut f: impl FnMut(&[f64]) -> f64) -> Vec<f64> {
    let mut x = x.to_vec();
    (0..x.len())
        .map(|i| {
            let x0 = x[i];
            x[i] = x0 + H;
            let fp = f(&x);
            x[i] = x0 - H;
            let fm = f(&x);
            x[i] = x0;
            (fp - fm) / (2.0 * H)
        })
        .collect()
}

fn randn(rng: &mut Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| rng.normal()).collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Pre-activations of every layer, computed naively from the named tensors.
fn naive_pre_activations(net: &Mlp<f64>, x: &[f64], batch: usize) -> Vec<Vec<f64>> {
    let p = net.params();
    let n_layers = net.layers().len();
    let mut input = x.to_vec();
    let mut out = Vec::new();
    for (l, layer) in net.layers().iter().enumerate() {
        let (ni, no) = (layer.in_features, layer.out_features);
        let w = &p[layer.weight_range()];
        let b = &p[layer.bias_range()];
        let mut z = vec![0.0; batch * no];
        for r in 0..batch {
            for o in 0..no {
                z[r * no + o] = b[o] + (0..ni).map(|i| w[o * ni + i] * input[r * ni + i]).sum::<f64>();
            }
        }
        let act = if l + 1 == n_layers { net.output_activation() } else { net.hidden_activation() };
        let mut y = z.clone();
        act.apply(&mut y);
        out.push(z);
        input = y;
    }
    out
}

#[test]
fn linear_weight_bias_and_input_gradients() {
    let mut rng = Rng::new(1);
    let (n_in, n_out, batch) = (5, 4, 3);
    let layer = Linear::new(n_in, n_out, 2); // non-zero offset inside a larger vector
    let mut params = vec![0.0f64; 2 + layer.param_len() + 3];
    layer.init(&mut params, &mut rng);
    let bound = 1.0 / (n_in as f64).sqrt();
    assert!(params[layer.weight_range().start..layer.bias_range().end]
        .iter()
        .all(|p| p.abs() <= bound && *p != 0.0));
    let x = randn(&mut rng, batch * n_in);
    let c = randn(&mut rng, batch * n_out); // L = sum c * y
    let loss = |params: &[f64], x: &[f64]| {
        let mut y = vec![0.0; batch * n_out];
        layer.forward(params, x, batch, &mut y);
        dot(&c, &y)
    };
    let mut grads = vec![0.0; params.len()];
    layer.backward_params(&mut grads, &x, &c, batch);
    let mut dx = vec![f64::NAN; batch * n_in];
    layer.backward_input(&params, &c, batch, &mut dx);

    let num_p = numeric_grad(&params, |p| loss(p, &x));
    assert_grads_close("linear params", &grads, &num_p);
    assert!(grads[..2].iter().chain(&grads[layer.bias_range().end..]).all(|&g| g == 0.0));
    let num_x = numeric_grad(&x, |x| loss(&params, x));
    assert_grads_close("linear input", &dx, &num_x);
    // A block of input columns.
    let mut dx_cols = vec![f64::NAN; batch * 3];
    layer.backward_input_cols(&params, &c, batch, 1..4, &mut dx_cols);
    let mut expect = vec![0.0; batch * 3];
    copy_cols(&dx, n_in, 1, 3, batch, &mut expect);
    for (a, b) in dx_cols.iter().zip(&expect) {
        assert!(close(*a, *b, 1e-14));
    }

    // Gradients accumulate.
    layer.backward_params(&mut grads, &x, &c, batch);
    for (g, n) in grads.iter().zip(&num_p) {
        assert!(close(*g, 2.0 * n, TOL));
    }
}

/// Checks parameter and input gradients of `net` against central differences of
/// L = sum c * net(x); returns the smallest |pre-activation| of the hidden layers.
fn check_mlp_gradients(net: &mut Mlp<f64>, x: &[f64], batch: usize, rng: &mut Rng) {
    let c = randn(rng, batch * net.out_features());
    let y = net.forward(x, batch).to_vec();
    net.zero_grad();
    let dx = net.backward_with_input_grad(&c).to_vec();
    let grads = net.grads().to_vec();

    // Against a naive forward.
    let pre = naive_pre_activations(net, x, batch);
    let mut expect = pre.last().unwrap().clone();
    net.output_activation().apply(&mut expect);
    for (a, b) in y.iter().zip(&expect) {
        assert!(close(*a, *b, 1e-12), "forward {a} vs naive {b}");
    }

    let params = net.params().to_vec();
    let mut probe = net.clone();
    let num_p = numeric_grad(&params, |p| {
        probe.params_mut().copy_from_slice(p);
        dot(&c, probe.predict(x, batch))
    });
    assert_grads_close("mlp params", &grads, &num_p);
    probe.params_mut().copy_from_slice(&params);
    let num_x = numeric_grad(x, |x| dot(&c, probe.predict(x, batch)));
    assert_grads_close("mlp input", &dx, &num_x);

    // Input gradient alone leaves parameter gradients untouched and agrees.
    net.zero_grad();
    let dx_only = net.input_grad(&c).to_vec();
    assert_eq!(dx_only, dx);
    assert!(net.grads().iter().all(|&g| g == 0.0));
    // Backward accumulates.
    net.backward(&c);
    net.backward(&c);
    for (g, g1) in net.grads().iter().zip(&grads) {
        assert!(close(*g, 2.0 * g1, 1e-12));
    }
}

#[test]
fn mlp_relu_gradients() {
    let (sizes, batch) = ([5, 8, 7, 3], 4);
    // Resample until no hidden pre-activation is within 1e-4 of the ReLU kink.
    let mut checked = 0;
    for seed in 0..100 {
        let mut rng = Rng::new(100 + seed);
        let mut net = Mlp::<f64>::new(&sizes, Activation::Relu, Activation::Identity, &mut rng);
        let x = randn(&mut rng, batch * sizes[0]);
        let pre = naive_pre_activations(&net, &x, batch);
        let hidden = &pre[..pre.len() - 1];
        if hidden.iter().flatten().any(|z| z.abs() < 1e-4) {
            continue;
        }
        // Both signs occur, so the ReLU mask is exercised.
        assert!(hidden.iter().flatten().any(|&z| z < 0.0));
        check_mlp_gradients(&mut net, &x, batch, &mut rng);
        checked += 1;
        if checked == 3 {
            break;
        }
    }
    assert_eq!(checked, 3);
}

#[test]
fn mlp_tanh_gradients() {
    let mut rng = Rng::new(7);
    let batch = 5;
    let mut net = Mlp::<f64>::new(&[4, 6, 5, 2], Activation::Tanh, Activation::Tanh, &mut rng);
    let x = randn(&mut rng, batch * 4);
    check_mlp_gradients(&mut net, &x, batch, &mut rng);
    // A single layer with an identity output is just a Linear.
    let mut lin = Mlp::<f64>::new(&[3, 2], Activation::Relu, Activation::Identity, &mut rng);
    let x = randn(&mut rng, 2 * 3);
    check_mlp_gradients(&mut lin, &x, 2, &mut rng);
}

#[test]
fn mse_gradient_and_value() {
    let mut rng = Rng::new(3);
    let pred = randn(&mut rng, 7);
    let target = randn(&mut rng, 7);
    let mut grad = vec![0.0; 7];
    let l = mse_loss(&pred, &target, &mut grad);
    let expect: f64 = pred.iter().zip(&target).map(|(p, t)| (p - t).powi(2)).sum::<f64>() / 7.0;
    assert!(close(l, expect, 1e-15));
    assert!(close(mse(&pred, &target), expect, 1e-15));
    let num = numeric_grad(&pred, |p| mse(p, &target));
    assert_grads_close("mse", &grad, &num);
}

/// Checks the squashed Gaussian's backward against central differences of
/// L = sum ca * a + sum cp * logp with respect to the raw input.
fn check_gaussian(bound: LogStdBound, raw: &[f64], batch: usize, act: usize, rng: &mut Rng) {
    let eps = randn(rng, batch * act);
    let ca = randn(rng, batch * act);
    let cp = randn(rng, batch);
    let mut head = SquashedGaussian::<f64>::new(act, bound);
    head.forward(raw, &eps, batch);
    let g = head.backward(&ca, &cp).to_vec();
    let mut probe = SquashedGaussian::<f64>::new(act, bound);
    let num = numeric_grad(raw, |r| {
        let (a, lp) = probe.forward(r, &eps, batch);
        dot(&ca, a) + dot(&cp, lp)
    });
    assert_grads_close("gaussian raw", &g, &num);
}

#[test]
fn squashed_gaussian_values() {
    let mut rng = Rng::new(11);
    let (batch, act) = (3, 2);
    let raw = randn(&mut rng, batch * 2 * act);
    let eps = randn(&mut rng, batch * act);
    let mut head = SquashedGaussian::<f64>::new(act, LogStdBound::default());
    let (a, lp) = head.forward(&raw, &eps, batch);
    let (a, lp) = (a.to_vec(), lp.to_vec());
    for r in 0..batch {
        let mut expect = 0.0;
        for j in 0..act {
            let (mean, l) = (raw[r * 2 * act + j], raw[r * 2 * act + act + j].clamp(-20.0, 2.0));
            let std = l.exp();
            let u = mean + std * eps[r * act + j];
            assert!(close(a[r * act + j], u.tanh(), 1e-14));
            let log_normal =
                -0.5 * ((u - mean) / std).powi(2) - std.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln();
            expect += log_normal - (1.0 - u.tanh().powi(2)).ln();
        }
        assert!(close(lp[r], expect, 1e-10), "{} vs {}", lp[r], expect);
    }
    let mut det = vec![0.0; batch * act];
    head.deterministic(&raw, batch, &mut det);
    for r in 0..batch {
        for j in 0..act {
            assert_eq!(det[r * act + j], raw[r * 2 * act + j].tanh());
        }
    }
    // Saturated tanh: the naive log(1 - a^2) is -inf, the stable form stays finite:
    // -log(1 - tanh(u)^2) ~ 2u - 2 ln 2 for large u.
    let raw = [30.0, -40.0, -20.0, -20.0]; // mean 30, -40; log std -20
    let (a, lp) = head.forward(&raw, &[0.0, 0.0], 1);
    assert_eq!(a, &[1.0, -1.0]);
    let expect = 2.0 * (20.0 - 0.5 * (2.0 * std::f64::consts::PI).ln())
        + (2.0 * 30.0 - 2.0 * std::f64::consts::LN_2)
        + (2.0 * 40.0 - 2.0 * std::f64::consts::LN_2);
    assert!(lp[0].is_finite() && close(lp[0], expect, 1e-12), "{}", lp[0]);
}

#[test]
fn squashed_gaussian_gradients() {
    let mut rng = Rng::new(12);
    let (batch, act) = (4, 3);
    let mut raw: Vec<f64> = randn(&mut rng, batch * 2 * act);
    for v in raw.iter_mut() {
        *v *= 0.7;
    }
    check_gaussian(LogStdBound::default(), &raw, batch, act, &mut rng);
    check_gaussian(LogStdBound::Tanh { min: -5.0, max: 2.0 }, &raw, batch, act, &mut rng);
    // Clamp region: raw log-std above 2 and below -20 (gradient 0 through the clamp).
    raw[act] = 3.0;
    raw[2 * act + act + 1] = -25.0;
    raw[3 * 2 * act + act + 2] = 2.5;
    check_gaussian(LogStdBound::default(), &raw, batch, act, &mut rng);
    check_gaussian(LogStdBound::Tanh { min: -5.0, max: 2.0 }, &raw, batch, act, &mut rng);
    // In the clamp region the only log-std gradient is 0.
    let mut head = SquashedGaussian::<f64>::new(act, LogStdBound::default());
    head.forward(&raw, &randn(&mut rng, batch * act), batch);
    let g = head.backward(&vec![1.0; batch * act], &vec![1.0; batch]);
    assert_eq!(g[act], 0.0);
    assert_eq!(g[2 * act + act + 1], 0.0);
}

/// The DDPG/TD3 actor update: L = mean_b Q(obs_b, pi(obs_b)) differentiated with respect to the
/// actor's parameters through the critic's input gradient.
#[test]
fn actor_through_critic_chain() {
    let mut rng = Rng::new(21);
    let (obs, act, batch) = (5, 3, 4);
    let mut actor = Mlp::<f64>::new(&[obs, 8, act], Activation::Tanh, Activation::Tanh, &mut rng);
    let mut critic =
        Mlp::<f64>::new(&[obs + act, 10, 9, 1], Activation::Tanh, Activation::Identity, &mut rng);
    let o = randn(&mut rng, batch * obs);
    let loss = |actor: &mut Mlp<f64>, critic: &mut Mlp<f64>| {
        let a = actor.predict(&o, batch).to_vec();
        let mut inp = vec![0.0; batch * (obs + act)];
        concat_cols(&o, obs, &a, act, batch, &mut inp);
        critic.predict(&inp, batch).iter().sum::<f64>() / batch as f64
    };

    let a = actor.forward(&o, batch).to_vec();
    let mut inp = vec![0.0; batch * (obs + act)];
    concat_cols(&o, obs, &a, act, batch, &mut inp);
    critic.forward(&inp, batch);
    let dq = vec![1.0 / batch as f64; batch];
    let d_inp = critic.input_grad(&dq).to_vec();
    assert!(critic.grads().iter().all(|&g| g == 0.0));
    let mut da = vec![0.0; batch * act];
    copy_cols(&d_inp, obs + act, obs, act, batch, &mut da);
    // The action columns alone give the same values.
    let da_cols = critic.input_grad_cols(&dq, obs..obs + act).to_vec();
    for (x, y) in da_cols.iter().zip(&da) {
        assert!(close(*x, *y, 1e-14));
    }
    actor.zero_grad();
    actor.backward(&da);

    let params = actor.params().to_vec();
    let mut probe = actor.clone();
    let num = numeric_grad(&params, |p| {
        probe.params_mut().copy_from_slice(p);
        loss(&mut probe, &mut critic)
    });
    assert_grads_close("actor through critic", actor.grads(), &num);
}

/// The SAC actor update: L = mean_b [alpha logp_b - min(Q1, Q2)(obs_b, a_b)] with
/// a_b = tanh(mean + std eps) from the actor's raw output, eps fixed.
#[test]
fn sac_actor_chain() {
    let mut rng = Rng::new(22);
    let (obs, act, batch, alpha) = (4, 2, 5, 0.3);
    let mut actor = Mlp::<f64>::new(&[obs, 8, 2 * act], Activation::Tanh, Activation::Identity, &mut rng);
    let mut q1 = Mlp::<f64>::new(&[obs + act, 7, 1], Activation::Tanh, Activation::Identity, &mut rng);
    let mut q2 = Mlp::<f64>::new(&[obs + act, 7, 1], Activation::Tanh, Activation::Identity, &mut rng);
    let o = randn(&mut rng, batch * obs);
    let eps = randn(&mut rng, batch * act);
    let bound = LogStdBound::default();
    let mut head = SquashedGaussian::<f64>::new(act, bound);
    let mut inp = vec![0.0; batch * (obs + act)];

    let loss = |actor: &mut Mlp<f64>, q1: &mut Mlp<f64>, q2: &mut Mlp<f64>| {
        let mut head = SquashedGaussian::<f64>::new(act, bound);
        let raw = actor.predict(&o, batch).to_vec();
        let (a, lp) = head.forward(&raw, &eps, batch);
        let mut inp = vec![0.0; batch * (obs + act)];
        concat_cols(&o, obs, a, act, batch, &mut inp);
        let v1 = q1.predict(&inp, batch).to_vec();
        let v2 = q2.predict(&inp, batch);
        (0..batch).map(|b| alpha * lp[b] - v1[b].min(v2[b])).sum::<f64>() / batch as f64
    };

    let raw = actor.forward(&o, batch).to_vec();
    let (a, _) = head.forward(&raw, &eps, batch);
    concat_cols(&o, obs, a, act, batch, &mut inp);
    let v1 = q1.forward(&inp, batch).to_vec();
    let v2 = q2.forward(&inp, batch).to_vec();
    let inv_b = 1.0 / batch as f64;
    let (g1, g2): (Vec<f64>, Vec<f64>) =
        (0..batch).map(|b| if v1[b] <= v2[b] { (-inv_b, 0.0) } else { (0.0, -inv_b) }).unzip();
    let mut da = q1.input_grad_cols(&g1, obs..obs + act).to_vec();
    add_assign(&mut da, q2.input_grad_cols(&g2, obs..obs + act));
    let dlp = vec![alpha * inv_b; batch];
    let d_raw = head.backward(&da, &dlp).to_vec();
    actor.zero_grad();
    actor.backward(&d_raw);

    let params = actor.params().to_vec();
    let mut probe = actor.clone();
    let num = numeric_grad(&params, |p| {
        probe.params_mut().copy_from_slice(p);
        loss(&mut probe, &mut q1, &mut q2)
    });
    assert_grads_close("sac actor", actor.grads(), &num);
}

#[test]
fn f32_and_f64_forward_agree() {
    let sizes = [22, 64, 64, 12];
    let n64 = Mlp::<f64>::new(&sizes, Activation::Relu, Activation::Tanh, &mut Rng::new(5));
    let mut n32 = Mlp::<f32>::new(&sizes, Activation::Relu, Activation::Tanh, &mut Rng::new(5));
    let mut n64 = n64;
    for (a, b) in n32.params().iter().zip(n64.params()) {
        assert_eq!(*a, *b as f32, "same seed, same initial weights");
    }
    let batch = 9;
    let mut rng = Rng::new(6);
    let x64 = randn(&mut rng, batch * sizes[0]);
    let x32: Vec<f32> = x64.iter().map(|&v| v as f32).collect();
    // Use exactly the f32 weights in both.
    let p: Vec<f64> = n32.params().iter().map(|&v| v as f64).collect();
    n64.params_mut().copy_from_slice(&p);
    let x64: Vec<f64> = x32.iter().map(|&v| v as f64).collect();
    let y64 = n64.forward(&x64, batch).to_vec();
    let y32 = n32.forward(&x32, batch);
    for (a, b) in y32.iter().zip(&y64) {
        assert!(close(*a as f64, *b, 1e-5), "{a} vs {b}");
    }
}

/// Trains a small regression with Adam for `steps` steps; returns the final parameters and the
/// first and last losses.
fn train_regression(seed: u64, steps: usize, lr: f64) -> (Vec<f32>, f32, f32) {
    let mut rng = Rng::new(seed);
    let (batch, n_in) = (32, 3);
    let mut net = Mlp::<f32>::new(&[n_in, 16, 16, 1], Activation::Tanh, Activation::Identity, &mut rng);
    let mut adam = Adam::new(net.num_params(), lr);
    let x: Vec<f32> = (0..batch * n_in).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect();
    let y: Vec<f32> = x.chunks(n_in).map(|r| 0.5 * r[0] - r[1] + 0.25 * r[2] * r[0] + 0.1).collect();
    let mut grad = vec![0.0f32; batch];
    let (mut first, mut last) = (0.0, 0.0);
    for step in 0..steps {
        let pred = net.forward(&x, batch);
        let l = mse_loss(pred, &y, &mut grad);
        if step == 0 {
            first = l;
        }
        last = l;
        net.zero_grad();
        net.backward(&grad);
        let (p, g) = net.params_and_grads();
        adam.step(p, g);
    }
    (net.params().to_vec(), first, last)
}

#[test]
fn adam_fits_a_tiny_regression() {
    let (_, first, last) = train_regression(9, 1000, 1e-2);
    assert!(last * 100.0 < first, "loss {first} -> {last}");
}

#[test]
fn same_seed_gives_bit_identical_training() {
    let (a, ..) = train_regression(4, 10, 1e-3);
    let (b, ..) = train_regression(4, 10, 1e-3);
    let (c, ..) = train_regression(5, 10, 1e-3);
    assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
    assert_ne!(a, c);
}

#[test]
fn buffers_are_reused_across_batch_sizes_and_inference_leaves_training_cache() {
    let mut rng = Rng::new(30);
    let sizes = [6, 10, 4];
    let mut net = Mlp::<f64>::new(&sizes, Activation::Tanh, Activation::Identity, &mut rng);
    let x_big = randn(&mut rng, 8 * 6);
    let x_small = randn(&mut rng, 2 * 6);
    let g_big = randn(&mut rng, 8 * 4);

    let mut fresh = net.clone();
    let y_ref = fresh.forward(&x_big, 8).to_vec();
    fresh.backward(&g_big);
    let grads_ref = fresh.grads().to_vec();

    // Small batch first, then big, then inference in between forward and backward.
    net.forward(&x_small, 2);
    net.backward(&g_big[..2 * 4]);
    net.zero_grad();
    assert_eq!(net.forward(&x_big, 8), &y_ref[..]);
    let p = net.predict(&x_small, 2).to_vec();
    let mut ws = Workspace::default();
    assert_eq!(net.predict_with(&x_small, 2, &mut ws), &p[..]);
    assert_eq!(net.output(), &y_ref[..]);
    assert_eq!(net.batch(), 8);
    net.backward(&g_big);
    assert_eq!(net.grads(), &grads_ref[..]);
    // Prediction equals the training forward on the same input.
    assert_eq!(net.predict(&x_big, 8), &y_ref[..]);
}

#[test]
fn named_tensors_tile_the_flat_vector() {
    let net = Mlp::<f32>::new(&[3, 5, 2], Activation::Relu, Activation::Identity, &mut Rng::new(0));
    let t = net.tensors();
    let names: Vec<&str> = t.iter().map(|t| t.name.as_str()).collect();
    assert_eq!(names, ["layer0.weight", "layer0.bias", "layer1.weight", "layer1.bias"]);
    assert_eq!(t[0].shape, vec![5, 3]);
    assert_eq!(t[1].shape, vec![5]);
    assert_eq!(t[2].shape, vec![2, 5]);
    let mut next = 0;
    for info in &t {
        assert_eq!(info.offset, next);
        next = info.range().end;
    }
    assert_eq!(next, net.num_params());
    assert_eq!(net.grads().len(), net.num_params());
}

#[test]
fn polyak_between_networks() {
    let mut target = Mlp::<f64>::new(&[2, 3, 1], Activation::Relu, Activation::Identity, &mut Rng::new(1));
    let source = Mlp::<f64>::new(&[2, 3, 1], Activation::Relu, Activation::Identity, &mut Rng::new(2));
    let before = target.params().to_vec();
    target.polyak_from(&source, 0.5);
    for ((t, b), s) in target.params().iter().zip(&before).zip(source.params()) {
        assert_eq!(*t, 0.5 * b + 0.5 * s);
    }
    target.copy_params_from(&source);
    assert_eq!(target.params(), source.params());
}

/// The multiversioned loops of the engine (see `crate::base::simd`) give the same bits at every level.
mod simd_levels {
    use crate::base::rng::Rng;
    use crate::base::simd::SimdLevel;
    use crate::nn::activation::{backward_kernel_at, backward_sum_kernel_at, bias_apply_kernel_at};
    use crate::nn::adam::{adam_kernel_at, Coefs};
    use crate::nn::ops::{polyak_kernel_at, scale_at, sum_of_squares_at};
    use crate::nn::Activation;

    const LEVELS: [SimdLevel; 3] = [SimdLevel::Avx512, SimdLevel::Avx2, SimdLevel::Baseline];

    /// Values of every magnitude, both signs, zeros, subnormals and a lane-count-unfriendly length.
    fn values(rng: &mut Rng, n: usize) -> Vec<f32> {
        (0..n)
            .map(|i| match i % 7 {
                0 => 0.0,
                1 => -(f32::MIN_POSITIVE / 3.0) * rng.uniform() as f32,
                2 => (rng.normal() * 1e-20) as f32,
                3 => (rng.normal() * 1e6) as f32,
                _ => rng.normal() as f32,
            })
            .collect()
    }

    fn bits(x: &[f32]) -> Vec<u32> {
        x.iter().map(|v| v.to_bits()).collect()
    }

    /// Every multiversioned loop gives the same bits at every level (where the CPU has it).
    #[test]
    fn every_level_is_bit_identical() {
        let mut rng = Rng::new(11);
        let (rows, cols) = (37, 29);
        let n = rows * cols;
        let (y0, g0, b0, p0, m0) = (
            values(&mut rng, n),
            values(&mut rng, n),
            values(&mut rng, cols),
            values(&mut rng, n),
            values(&mut rng, n),
        );
        let v0: Vec<f32> = values(&mut rng, n).iter().map(|v| v * v).collect();
        let mut outs: Vec<Vec<Vec<u32>>> = Vec::new();
        for level in LEVELS {
            let mut out = Vec::new();
            for act in [Activation::Identity, Activation::Relu, Activation::Tanh] {
                let mut y = y0.clone();
                bias_apply_kernel_at(level, act, &mut y, &b0);
                let (mut g, mut gb) = (g0.clone(), b0.clone());
                backward_sum_kernel_at(level, act, &y, &mut g, &mut gb);
                let mut g2 = g0.clone();
                backward_kernel_at(level, act, &y, &mut g2);
                out.extend([bits(&y), bits(&g), bits(&gb), bits(&g2)]);
            }
            let (mut p, mut m, mut v) = (p0.clone(), m0.clone(), v0.clone());
            let c = Coefs {
                b1: 0.9,
                b2: 0.999,
                c1: 0.1,
                c2: 1e-3,
                step_size: 1e-3,
                inv_sqrt_bias2: 3.7,
                eps: 1e-8,
            };
            adam_kernel_at(level, &mut p, &g0, &mut m, &mut v, c);
            out.extend([bits(&p), bits(&m), bits(&v)]);
            let mut t = p0.clone();
            polyak_kernel_at(level, &mut t, &y0, 0.995, 0.005);
            scale_at(level, &mut t, 0.37);
            out.push(bits(&t));
            out.push(vec![sum_of_squares_at(level, &g0).to_bits()]);
            outs.push(out);
        }
        assert_eq!(outs[0], outs[2], "AVX-512 (or its fallback) differs from the baseline");
        assert_eq!(outs[1], outs[2], "AVX2 (or its fallback) differs from the baseline");
    }
}

/// DroQ's hidden layers, written out naively from the named tensors and a given mask per hidden
/// layer (`None`: no dropout): `y = relu(LN(drop(x W^T + b)))`, the output layer plain.
fn naive_normed_forward(net: &Mlp<f64>, x: &[f64], batch: usize, masks: Option<&[Vec<f64>]>) -> Vec<f64> {
    let p = net.params();
    let tensors = net.tensors();
    let find = |name: &str| tensors.iter().find(|t| t.name == name).map(|t| &p[t.range()]);
    let n_layers = net.layers().len();
    let mut input = x.to_vec();
    for (l, layer) in net.layers().iter().enumerate() {
        let (ni, no) = (layer.in_features, layer.out_features);
        let (w, b) = (find(&format!("layer{l}.weight")).unwrap(), find(&format!("layer{l}.bias")).unwrap());
        let mut z = vec![0.0; batch * no];
        for r in 0..batch {
            for o in 0..no {
                z[r * no + o] = b[o] + (0..ni).map(|i| w[o * ni + i] * input[r * ni + i]).sum::<f64>();
            }
        }
        if l + 1 < n_layers {
            if let Some(m) = masks {
                z.iter_mut().zip(&m[l]).for_each(|(v, m)| *v *= m);
            }
            if let (Some(s), Some(c)) = (find(&format!("ln{l}.scale")), find(&format!("ln{l}.bias"))) {
                for row in z.chunks_mut(no) {
                    let mu = row.iter().sum::<f64>() / no as f64;
                    let var = row.iter().map(|v| (v - mu) * (v - mu)).sum::<f64>() / no as f64;
                    for (j, v) in row.iter_mut().enumerate() {
                        *v = s[j] * (*v - mu) / (var + LN_EPS).sqrt() + c[j];
                    }
                }
            }
            net.hidden_activation().apply(&mut z);
        } else {
            net.output_activation().apply(&mut z);
        }
        input = z;
    }
    input
}

/// Dropout then layer normalisation after the hidden layers (DroQ's critic): the forward pass
/// equals the naive formulas with the same masks (drawn from the same stream: one uniform per
/// value, `u < p` dropped, kept values scaled by 1 / (1 - p)); parameter and input gradients
/// equal central differences with the masks held fixed; inference normalises without dropping.
#[test]
fn dropout_and_layer_norm_values_and_gradients() {
    let (sizes, batch, p) = ([5usize, 7, 6, 2], 4, 0.3);
    for hn in [
        HiddenNorm { dropout: 0.0, layer_norm: true },
        HiddenNorm { dropout: p, layer_norm: true },
        HiddenNorm { dropout: p, layer_norm: false },
    ] {
        let mut rng = Rng::new(3);
        let mut net =
            Mlp::<f64>::with_norm(&sizes, Activation::Relu, Activation::Identity, Some(hn), &mut rng);
        // Plain layers drawn as `Mlp::new` draws them; scales 1 and biases 0, then moved off them.
        let plain = Mlp::<f64>::new(&sizes, Activation::Relu, Activation::Identity, &mut Rng::new(3));
        assert_eq!(&net.params()[..plain.num_params()], plain.params());
        let names: Vec<String> = net.tensors().iter().map(|t| t.name.clone()).collect();
        assert_eq!(names.iter().any(|n| n == "ln1.bias"), hn.layer_norm, "{names:?}");
        let extra = net.num_params() - plain.num_params();
        assert_eq!(extra, if hn.layer_norm { 2 * (7 + 6) } else { 0 });
        if hn.layer_norm {
            assert_eq!(&net.params()[plain.num_params()..plain.num_params() + 7], &[1.0; 7]);
        }
        for v in net.params_mut()[plain.num_params()..].iter_mut() {
            *v += 0.3 * rng.normal();
        }
        let x = randn(&mut rng, batch * sizes[0]);
        // The masks the stream gives: the same draws, in order, layer by layer.
        let mut draws = Rng::new(77);
        let masks: Vec<Vec<f64>> = sizes[1..3]
            .iter()
            .map(|&h| {
                (0..batch * h).map(|_| if draws.uniform() < p { 0.0 } else { 1.0 / (1.0 - p) }).collect()
            })
            .collect();
        let dropping = hn.dropout > 0.0;
        let y = net.forward_dropout(&x, batch, &mut Rng::new(77)).to_vec();
        let expect = naive_normed_forward(&net, &x, batch, dropping.then_some(&masks[..]));
        for (a, b) in y.iter().zip(&expect) {
            assert!(close(*a, *b, 1e-12), "{hn:?}: {a} vs {b}");
        }
        if dropping {
            assert!(masks.iter().flatten().any(|&m| m == 0.0), "something dropped");
        }
        // Gradients: loss = sum(y * c).
        let c = randn(&mut rng, batch * 2);
        net.zero_grad();
        net.forward_dropout(&x, batch, &mut Rng::new(77));
        let dx = net.backward_with_input_grad(&c).to_vec();
        let analytic = net.grads().to_vec();
        let m = dropping.then_some(&masks[..]);
        let probe = net.clone();
        let numeric = numeric_grad(net.params(), |theta| {
            let mut q = probe.clone();
            q.params_mut().copy_from_slice(theta);
            dot(&naive_normed_forward(&q, &x, batch, m), &c)
        });
        assert_grads_close(&format!("{hn:?} params"), &analytic, &numeric);
        let numeric_x = numeric_grad(&x, |xs| dot(&naive_normed_forward(&probe, xs, batch, m), &c));
        assert_grads_close(&format!("{hn:?} input"), &dx, &numeric_x);
        // The input columns alone, without touching the parameter gradients.
        net.forward_dropout(&x, batch, &mut Rng::new(77));
        let cols = net.input_grad_cols(&c, 1..4).to_vec();
        for r in 0..batch {
            assert_eq!(cols[r * 3..r * 3 + 3], dx[r * 5 + 1..r * 5 + 4], "row {r}");
        }
        assert_eq!(net.grads(), &analytic[..]);
        // Inference and a training pass without a stream: normalised, nothing dropped.
        let inferred = net.predict(&x, batch).to_vec();
        let expect = naive_normed_forward(&net, &x, batch, None);
        assert!(inferred.iter().zip(&expect).all(|(a, b)| close(*a, *b, 1e-12)));
        assert_eq!(net.forward(&x, batch), &inferred[..]);
    }
}

/// Dropout's masks: about a fraction p dropped, kept values scaled so that the mean is kept.
#[test]
fn dropout_keeps_the_mean() {
    let mut z = vec![1.0f64; 100_000];
    let mut mask = vec![0.0; z.len()];
    super::norm::dropout_forward(&mut z, &mut mask, 0.2, &mut Rng::new(5));
    let dropped = mask.iter().filter(|&&m| m == 0.0).count() as f64 / z.len() as f64;
    assert!((dropped - 0.2).abs() < 0.005, "{dropped}");
    let mean = z.iter().sum::<f64>() / z.len() as f64;
    assert!((mean - 1.0).abs() < 0.01, "{mean}");
    assert!(mask.iter().all(|&m| m == 0.0 || m == 1.25));
}

/// Batch renormalisation written out independently (f64), with the corrections `r` and `d`
/// given (the backward pass holds them constant) or computed from `x` itself.
fn naive_renorm(
    x: &[f64],
    (batch, n): (usize, usize),
    s: &BatchRenormSettings,
    (ra_mean, ra_var, warmed): (&[f64], &[f64], bool),
    rd: Option<&[(f64, f64)]>,
    (scale, bias): (&[f64], &[f64]),
) -> (Vec<f64>, Vec<(f64, f64)>) {
    let mut y = vec![0.0; batch * n];
    let mut used = Vec::new();
    for j in 0..n {
        let col: Vec<f64> = (0..batch).map(|b| x[b * n + j]).collect();
        let mu = col.iter().sum::<f64>() / batch as f64;
        let var = col.iter().map(|v| (v - mu).powi(2)).sum::<f64>() / batch as f64;
        let ra_sd = (ra_var[j] + s.eps).sqrt();
        let (r, d) = match rd {
            Some(rd) => rd[j],
            None => (
                ((var + s.eps).sqrt() / ra_sd).max(1.0 / s.r_max).min(s.r_max),
                ((mu - ra_mean[j]) / ra_sd).max(-s.d_max).min(s.d_max),
            ),
        };
        used.push((r, d));
        let (m, v) = if warmed { (mu - d * var.sqrt() / r, var / (r * r)) } else { (mu, var) };
        for b in 0..batch {
            y[b * n + j] = scale[j] * (col[b] - m) / (v + s.eps).sqrt() + bias[j];
        }
    }
    (y, used)
}

/// Batch renormalisation: values against the independent formulas before and after the
/// warm-up (with the corrections clipped and not), running statistics and the pass count,
/// inference with the running statistics; gradients of the input, scale and bias against
/// central differences with r and d held constant.
#[test]
fn batch_renorm_values_statistics_and_gradients() {
    let (batch, n) = (6, 4);
    let s = BatchRenormSettings { warmup_steps: 2, ..BatchRenormSettings::default() };
    let mut rng = Rng::new(8);
    let scale: Vec<f64> = (0..n).map(|_| 1.0 + 0.3 * rng.normal()).collect();
    let bias = randn(&mut rng, n);
    let mut layer = BatchRenorm::<f64>::new(n, s);
    // Running statistics moved so that feature 0's r and d are clipped, the others not.
    layer.stats.mean = vec![-40.0, 0.2, -0.1, 0.0];
    layer.stats.var = vec![0.001, 1.5, 0.6, 1.0];
    for pass in 0..4 {
        let x: Vec<f64> = (0..batch * n).map(|i| rng.normal() * (1.0 + (i % n) as f64) + 0.5).collect();
        let (ra_mean, ra_var, steps) = (layer.stats.mean.clone(), layer.stats.var.clone(), layer.stats.steps);
        let warmed = steps >= s.warmup_steps;
        assert_eq!(warmed, pass >= 2);
        let mut y = vec![0.0; batch * n];
        layer.forward_train(&x, batch, (&scale, &bias), &mut y);
        let (expect, rd) =
            naive_renorm(&x, (batch, n), &s, (&ra_mean, &ra_var, warmed), None, (&scale, &bias));
        for (a, b) in y.iter().zip(&expect) {
            assert!(close(*a, *b, 1e-12), "pass {pass}: {a} vs {b}");
        }
        if pass == 2 {
            assert_eq!(rd[0], (3.0, 5.0), "feature 0 clipped");
            assert!(rd[1].0 < 3.0 && rd[1].0 > 1.0 / 3.0 && rd[1].1.abs() < 5.0, "{:?}", rd[1]);
        }
        // Running statistics: momentum 0.99 towards the batch's mean and (biased) variance.
        for j in 0..n {
            let col: Vec<f64> = (0..batch).map(|b| x[b * n + j]).collect();
            let mu = col.iter().sum::<f64>() / batch as f64;
            let var = col.iter().map(|v| (v - mu).powi(2)).sum::<f64>() / batch as f64;
            assert!(close(layer.stats.mean[j], 0.99 * ra_mean[j] + 0.01 * mu, 1e-14));
            assert!(close(layer.stats.var[j], 0.99 * ra_var[j] + 0.01 * var, 1e-14));
        }
        assert_eq!(layer.stats.steps, steps + 1);
        // Gradients with the corrections held at this pass's values.
        let c = randn(&mut rng, batch * n);
        let mut dx = vec![0.0; batch * n];
        let (mut ds, mut db) = (vec![0.0; n], vec![0.0; n]);
        layer.backward((&x, &c), batch, &scale, &mut dx, Some((&mut ds, &mut db)));
        let stats = (&ra_mean[..], &ra_var[..], warmed);
        let f = |xs: &[f64], sc: &[f64], bi: &[f64]| {
            dot(&naive_renorm(xs, (batch, n), &s, stats, Some(&rd), (sc, bi)).0, &c)
        };
        assert_grads_close(&format!("pass {pass} dx"), &dx, &numeric_grad(&x, |xs| f(xs, &scale, &bias)));
        assert_grads_close(&format!("pass {pass} dscale"), &ds, &numeric_grad(&scale, |sc| f(&x, sc, &bias)));
        assert_grads_close(&format!("pass {pass} dbias"), &db, &numeric_grad(&bias, |bi| f(&x, &scale, bi)));
    }
    // Inference: the running statistics, nothing updated.
    let x = randn(&mut rng, batch * n);
    let before = layer.stats.clone();
    let mut y = vec![0.0; batch * n];
    layer.forward_eval(&x, batch, (&scale, &bias), &mut y);
    for b in 0..batch {
        for j in 0..n {
            let e = scale[j] * (x[b * n + j] - before.mean[j]) / (before.var[j] + s.eps).sqrt() + bias[j];
            assert!(close(y[b * n + j], e, 1e-12));
        }
    }
    assert_eq!(layer.stats, before);
}

/// CrossQ's batch-renormalised MLP: parameter gradients of a training pass against central
/// differences (during the warm-up, where the pass is a smooth function of the parameters;
/// after it the corrections are held constant, as the layer's own test checks); the running
/// statistics move once per pass; the folded plain MLP computes the network's inference (each
/// norm with its running statistics, then the layer) to f64 rounding; no allocation-visible
/// growth after `reserve` (the same buffers).
#[test]
fn brn_mlp_gradients_statistics_and_folded_inference() {
    let (batch, sizes) = (7, [3, 5, 4, 2]);
    let settings = BatchRenormSettings { warmup_steps: 1_000, ..BatchRenormSettings::default() };
    let mut rng = Rng::new(21);
    let mut net = BrnMlp::<f64>::new(&sizes, settings, &mut rng);
    // Scales and biases away from 1 and 0, so that their gradients are tested in general.
    let n_lin = net.num_params() - 2 * (3 + 5 + 4);
    for p in &mut net.params_mut()[n_lin..] {
        *p += 0.3 * rng.normal();
    }
    let x: Vec<f64> = (0..batch * 3).map(|i| rng.normal() * (1.0 + (i % 3) as f64) + 0.7).collect();
    let c = randn(&mut rng, batch * 2);
    net.zero_grad();
    net.forward_train(&x, batch);
    assert_eq!(net.norms.iter().map(|n| n.stats.steps).collect::<Vec<_>>(), vec![1, 1, 1]);
    net.backward(&c);
    let analytic = net.grads().to_vec();
    let params = net.params().to_vec();
    let numeric = numeric_grad(&params, |p| {
        let mut n = net.clone();
        n.params_mut().copy_from_slice(p);
        dot(n.forward_train(&x, batch), &c)
    });
    assert_grads_close("BrnMlp params", &analytic, &numeric);
    let names: Vec<String> = net.tensors().into_iter().map(|t| t.name).collect();
    assert_eq!(names[6..], ["bn0.scale", "bn0.bias", "bn1.scale", "bn1.bias", "bn2.scale", "bn2.bias"]);
    assert_eq!(net.tensors().iter().map(TensorInfo::len).sum::<usize>(), net.num_params());
    // A few more passes move the running statistics; then the folded network.
    for _ in 0..5 {
        let x: Vec<f64> = (0..batch * 3).map(|_| 2.0 * rng.normal() - 1.0).collect();
        net.forward_train(&x, batch);
    }
    let mut folded = Mlp::<f64>::new(&sizes, Activation::Relu, Activation::Identity, &mut Rng::new(0));
    net.fold_into(&mut folded);
    let xs = randn(&mut rng, batch * 3);
    let mut h = xs.clone();
    let mut at = n_lin;
    for (k, w) in sizes.windows(2).enumerate() {
        let (scale, bias) = (&net.params()[at..at + w[0]], &net.params()[at + w[0]..at + 2 * w[0]]);
        at += 2 * w[0];
        let mut y = vec![0.0; batch * w[0]];
        net.norms[k].forward_eval(&h, batch, (scale, bias), &mut y);
        let layer = Linear::new(w[0], w[1], sizes.windows(2).take(k).map(|v| v[0] * v[1] + v[1]).sum());
        h = vec![0.0; batch * w[1]];
        let act = if k + 2 < sizes.len() { Activation::Relu } else { Activation::Identity };
        layer.forward_act(net.params(), &y, batch, &mut h, act);
    }
    for (a, b) in folded.predict(&xs, batch).iter().zip(&h) {
        assert!(close(*a, *b, 1e-12), "{a} vs {b}");
    }
    // The statistics round trip, and bad ones are refused.
    let stats = net.running_stats();
    let mut other = BrnMlp::<f64>::new(&sizes, settings, &mut Rng::new(1));
    other.set_running_stats(&stats).unwrap();
    assert_eq!(other.running_stats(), stats);
    assert!(other.set_running_stats(&stats[..2]).unwrap_err().contains("2 batch-renorm layers"));
    let mut bad = stats.clone();
    bad[1].var[0] = -1.0;
    assert!(other.set_running_stats(&bad).unwrap_err().contains("bn1"));
}
