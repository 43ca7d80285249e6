//! Tests of the n-critic object: targets, subsets, gradients, saving.

use super::*;
use crate::nn::concat_cols;

const THREE: &[[&str; 3]] =
    &[["q1", "q1_target", "q1_opt"], ["q2", "q2_target", "q2_opt"], ["q3", "q3_target", "q3_opt"]];

fn three(seed: u64) -> Critics {
    Critics::new(THREE, &[5, 16, 16, 1], 1e-3, &mut Rng::new(seed), 8, 2)
}

fn uniform(rng: &mut Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.uniform_range(-1.0, 1.0) as f32).collect()
}

#[test]
fn three_critics_fit_take_the_minimum_and_follow_with_their_targets() {
    let (b, od, ad) = (8, 3, 2);
    let mut c = three(4);
    assert_eq!((c.len(), c.names()[2][1]), (3, "q3_target"));
    let mut rng = Rng::new(5);
    let (obs, act) = (uniform(&mut rng, b * od), uniform(&mut rng, b * ad));
    let mut input = vec![0.0; b * (od + ad)];
    concat_cols(&obs, od, &act, ad, b, &mut input);
    // The target minimum is the elementwise minimum over the three targets.
    let mut y = vec![0.0; b];
    c.target_min(&input, b, &mut y);
    let each: Vec<Vec<f32>> = c.targets.iter_mut().map(|t| t.predict(&input, b).to_vec()).collect();
    for r in 0..b {
        assert_eq!(y[r], each[0][r].min(each[1][r]).min(each[2][r]), "row {r}");
    }
    assert!((0..b).any(|r| each[0][r] != each[1][r]), "the critics differ");
    // Fitting lowers every critic's loss on a fixed batch.
    let target = uniform(&mut rng, b);
    let first = c.fit(&input, &target, 0.0).to_vec();
    let mut last = first.clone();
    for _ in 0..200 {
        last = c.fit(&input, &target, 0.0).to_vec();
    }
    for k in 0..3 {
        assert!(last[k] < first[k] * 0.1, "critic {k}: loss {} -> {}", first[k], last[k]);
    }
    assert_eq!(mean(&last), (last[0] + last[1] + last[2]) / 3.0);
    // Polyak averaging moves every target towards its critic.
    let gap = |c: &Critics, k: usize| -> f32 {
        c.targets[k].params().iter().zip(c.nets[k].params()).map(|(t, q)| (t - q).abs()).sum()
    };
    let before: Vec<f32> = (0..3).map(|k| gap(&c, k)).collect();
    let old: Vec<Vec<f32>> = c.targets.iter().map(|t| t.params().to_vec()).collect();
    c.polyak(0.5);
    for k in 0..3 {
        assert_ne!(c.targets[k].params(), &old[k][..], "target {k} moved");
        assert!(gap(&c, k) < before[k] * 0.6, "target {k}: {} -> {}", before[k], gap(&c, k));
    }
}

#[test]
fn a_drawn_subset_of_targets_makes_the_minimum_and_the_others_are_not_evaluated() {
    let (b, od, ad) = (8, 3, 2);
    let names = &ENSEMBLE[..10];
    let mut c = Critics::new(names, &[od + ad, 16, 1], 1e-3, &mut Rng::new(3), b, ad);
    let mut rng = Rng::new(9);
    let input = uniform(&mut rng, b * (od + ad));
    let each: Vec<Vec<f32>> = c.targets.iter_mut().map(|t| t.predict(&input, b).to_vec()).collect();
    let mut seen = [0usize; 10];
    let mut draws = Rng::new(11);
    for round in 0..200 {
        for q in c.target_q.iter_mut() {
            q.fill(f32::NAN);
        }
        c.choose_targets(2, &mut draws);
        let chosen: Vec<usize> = (0..10).filter(|&k| c.chosen[k]).collect();
        assert_eq!(chosen.len(), 2, "round {round}: {chosen:?}");
        let mut y = vec![0.0; b];
        c.target_min(&input, b, &mut y);
        for r in 0..b {
            assert_eq!(y[r], each[chosen[0]][r].min(each[chosen[1]][r]), "round {round} row {r}");
        }
        for k in (0..10).filter(|k| !chosen.contains(k)) {
            assert!(c.target_q[k].iter().all(|v| v.is_nan()), "target {k} was evaluated");
        }
        // The next minimum, without a draw, is over every target again.
        assert!(c.chosen.iter().all(|&x| x));
        chosen.iter().for_each(|&k| seen[k] += 1);
    }
    // 400 draws over 10 critics: each drawn (expected 40, binomial sd 5.7).
    assert!(seen.iter().all(|&n| (15..=65).contains(&n)), "{seen:?}");
    let mut y = vec![0.0; b];
    c.target_min(&input, b, &mut y);
    for r in 0..b {
        let all = each.iter().map(|q| q[r]).fold(f32::INFINITY, f32::min);
        assert_eq!(y[r], all, "row {r}");
    }
    // The same draws from the same stream.
    let (mut d1, mut d2) = (Rng::new(4), Rng::new(4));
    for _ in 0..20 {
        c.choose_targets(3, &mut d1);
        let first = c.chosen.clone();
        c.choose_targets(3, &mut d2);
        assert_eq!(first, c.chosen);
    }
}

#[test]
fn the_actor_side_of_the_mean_goes_through_every_critic_equally() {
    // The linear critics of the test below: Q_k = s_k + (k + 1) a_0 - k a_1.
    let (b, od, ad) = (4, 3, 2);
    let mut c = Critics::new(THREE, &[od + ad, 1], 1e-3, &mut Rng::new(1), b, ad);
    for (k, q) in c.nets.iter_mut().enumerate() {
        let p = q.params_mut();
        p.fill(0.0);
        (p[k], p[3], p[4]) = (1.0, (k + 1) as f32, -(k as f32));
    }
    let input: Vec<f32> = (0..b * (od + ad)).map(|i| (i % 7) as f32 * 0.5 - 1.0).collect();
    let mean = c.forward_mean(&input, b).to_vec();
    for r in 0..b {
        let x = &input[r * (od + ad)..(r + 1) * (od + ad)];
        let sum: f32 = (0..3).map(|k| x[k] + (k + 1) as f32 * x[3] - k as f32 * x[4]).sum();
        assert!((mean[r] - sum / 3.0).abs() < 1e-6, "row {r}: {} vs {}", mean[r], sum / 3.0);
    }
    // d mean / d a = (1/3) sum_k [(k + 1), -k] = [2, -1], times the loss gradient.
    let da = c.input_grad_mean(-0.5, od..od + ad).to_vec();
    for r in 0..b {
        assert!((da[r * ad] + 1.0).abs() < 1e-6 && (da[r * ad + 1] - 0.5).abs() < 1e-6, "{da:?}");
    }
}

#[test]
fn the_actor_side_goes_through_each_rows_smallest_critic() {
    // Linear critics of inputs [s_0, s_1, s_2 | a_0, a_1]: Q_k = s_k + (k + 1) a_0 - k a_1, so
    // that row r, whose smallest s is s_{r mod 3}, goes through critic r mod 3.
    let (b, od, ad) = (9, 3, 2);
    let mut c = Critics::new(THREE, &[od + ad, 1], 1e-3, &mut Rng::new(1), b, ad);
    for (k, q) in c.nets.iter_mut().enumerate() {
        let p = q.params_mut();
        p.fill(0.0);
        (p[k], p[3], p[4]) = (1.0, (k + 1) as f32, -(k as f32));
    }
    let mut input = vec![0.0; b * (od + ad)];
    for r in 0..b {
        for j in 0..od {
            input[r * (od + ad) + j] = if j == r % 3 { -1.0 - r as f32 } else { r as f32 };
        }
        input[r * (od + ad) + od] = 0.25 * r as f32;
    }
    let qmin = c.forward_min(&input, b).to_vec();
    for r in 0..b {
        let k = r % 3;
        assert_eq!(qmin[r], -1.0 - r as f32 + (k + 1) as f32 * 0.25 * r as f32, "row {r}");
    }
    let da = c.input_grad_min(-0.5, od..od + ad).to_vec();
    for r in 0..b {
        let k = r % 3;
        assert_eq!(da[r * ad..(r + 1) * ad], [-0.5 * (k + 1) as f32, 0.5 * k as f32], "row {r}");
    }
    // The first critic alone (TD3, DDPG).
    let q1 = c.forward_first(&input, b).to_vec();
    assert!((0..b).all(|r| q1[r] == input[r * (od + ad)] + input[r * (od + ad) + od]), "{q1:?}");
    let d1 = c.input_grad_first(0.25, od..od + ad).to_vec();
    assert_eq!(d1, [0.25, 0.0].repeat(b));
    // Of equal values the first critic is taken (as SAC's `Q1 <= Q2`).
    let tie = [0.0; 5];
    assert_eq!(c.forward_min(&tie, 1), [0.0]);
    assert_eq!(c.input_grad_min(-1.0, od..od + ad), [-1.0, 0.0]);
}
