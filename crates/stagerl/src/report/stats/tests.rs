use super::*;

fn normal_sample(n: usize, mean: f64, sd: f64, rng: &mut Rng) -> Vec<f64> {
    (0..n).map(|_| mean + sd * rng.normal()).collect()
}

/// The verdict of comparison 0 inside a family of `family` comparisons, the others null data.
fn verdict_in_family(shift_sd: f64, seeds: usize, family: usize, seed: u64) -> Verdict {
    let mut rng = Rng::new(seed);
    let mut p = Vec::new();
    let mut diffs = Vec::new();
    for k in 0..family {
        let shift = if k == 0 { shift_sd } else { 0.0 };
        let a = normal_sample(seeds, shift, 1.0, &mut rng);
        let b = normal_sample(seeds, 0.0, 1.0, &mut rng);
        p.push(permutation_test(&a, &b, seed + k as u64));
        diffs.push(mean(&a) - mean(&b));
    }
    let adj = holm(&p);
    Verdict::of(diffs[0], adj[0], 1.0)
}

#[test]
fn three_sd_over_20_seeds_is_supported_and_reverse_contradicted() {
    for seed in 0..5 {
        assert_eq!(verdict_in_family(3.0, 20, 21, seed), Verdict::Supported, "seed {seed}");
        assert_eq!(verdict_in_family(-3.0, 20, 21, seed), Verdict::Contradicted, "seed {seed}");
    }
}

#[test]
fn no_difference_is_inconclusive() {
    let inconclusive =
        (0..20).filter(|&s| verdict_in_family(0.0, 20, 21, 100 + s) == Verdict::Inconclusive).count();
    // Holm keeps the family-wise error at 5 %: at most one false verdict in 20 families is
    // already unlikely (p about 0.26); more than two would mean the correction is broken.
    assert!(inconclusive >= 18, "{inconclusive} of 20 null families inconclusive");
}

#[test]
fn bootstrap_ci_of_a_mean_matches_the_t_interval() {
    let mut rng = Rng::new(7);
    for k in 0..5 {
        let a = normal_sample(100, 3.0, 2.0, &mut rng);
        let (blo, bhi) = bootstrap_mean_ci(&a, 0.95, BOOTSTRAP_RESAMPLES, 11 + k);
        let (tlo, thi) = t_interval(&a, 0.95);
        let width = thi - tlo;
        assert!(((bhi - blo) / width - 1.0).abs() < 0.05, "width {} vs {}", bhi - blo, width);
        assert!((blo - tlo).abs() < 0.05 * width && (bhi - thi).abs() < 0.05 * width);
    }
}

#[test]
fn bootstrap_diff_ci_covers_the_true_difference() {
    let mut rng = Rng::new(3);
    let a = normal_sample(40, 1.0, 1.0, &mut rng);
    let b = normal_sample(40, 0.0, 1.0, &mut rng);
    let (lo, hi) = bootstrap_diff_ci(&a, &b, 0.95, BOOTSTRAP_RESAMPLES, 5);
    assert!(lo < mean(&a) - mean(&b) && mean(&a) - mean(&b) < hi);
    assert!(lo > 0.3 && hi < 1.7, "[{lo}, {hi}]");
    // Seeded: the same seed gives the same interval.
    assert_eq!((lo, hi), bootstrap_diff_ci(&a, &b, 0.95, BOOTSTRAP_RESAMPLES, 5));
}

#[test]
fn permutation_test_exact_small_case() {
    // 20 arrangements of 6 values into 3 + 3; only the two extreme splits reach |diff| = 3.
    assert!((permutation_test(&[1.0, 2.0, 3.0], &[4.0, 5.0, 6.0], 0) - 0.1).abs() < 1e-15);
    assert_eq!(permutation_test(&[1.0, 1.0], &[1.0, 1.0], 0), 1.0);
    // With 3 seeds a group can never be significant at 5 %: the smallest p is 2 / 20.
    assert!(permutation_test(&[1.0, 1.0, 1.0], &[0.0, 0.0, 0.0], 0) >= 0.1 - 1e-15);
}

#[test]
fn permutation_test_random_agrees_with_welch_on_normal_data() {
    let mut rng = Rng::new(9);
    let a = normal_sample(20, 0.7, 1.0, &mut rng);
    let b = normal_sample(20, 0.0, 1.0, &mut rng);
    let p_perm = permutation_test(&a, &b, 1);
    let (_, _, p_welch) = welch_t_test(&a, &b);
    assert!((p_perm - p_welch).abs() < 0.3 * p_welch.max(0.01), "perm {p_perm} welch {p_welch}");
}

#[test]
fn welch_statistic_and_degrees_of_freedom() {
    let a = [1.0, 2.0, 3.0, 4.0, 5.0];
    let b = [2.0, 4.0, 6.0, 8.0, 10.0, 12.0];
    let (t, df, p) = welch_t_test(&a, &b);
    let se2: f64 = 2.5 / 5.0 + 14.0 / 6.0;
    assert!((t - (-4.0 / se2.sqrt())).abs() < 1e-12);
    let want_df = se2 * se2 / ((0.5f64).powi(2) / 4.0 + (14.0f64 / 6.0).powi(2) / 5.0);
    assert!((df - want_df).abs() < 1e-12);
    assert!((p - special::student_t_two_sided(t, df)).abs() < 1e-15 && p > 0.04 && p < 0.06);
    assert_eq!(welch_t_test(&[2.0, 2.0], &[2.0, 2.0]).2, 1.0);
    assert_eq!(welch_t_test(&[2.0, 2.0], &[1.0, 1.0]).2, 0.0);
}

#[test]
fn holm_adjusts_in_input_order() {
    let adj = holm(&[0.01, 0.04, 0.03, 0.005]);
    let want = [0.03, 0.06, 0.06, 0.02];
    for (x, w) in adj.iter().zip(want) {
        assert!((x - w).abs() < 1e-15, "{adj:?}");
    }
    assert_eq!(holm(&[0.6, 0.9]), vec![1.0, 1.0]);
}

#[test]
fn claim_verdict_combines_comparisons() {
    use Verdict::*;
    assert_eq!(Verdict::all([Supported, Supported]), Supported);
    assert_eq!(Verdict::all([Supported, Inconclusive]), Inconclusive);
    assert_eq!(Verdict::all([Supported, Contradicted, Inconclusive]), Contradicted);
    assert_eq!(Verdict::all([]), Inconclusive);
    assert_eq!(Verdict::of(-0.2, 0.01, -1.0), Supported);
    assert_eq!(Verdict::of(0.2, 0.01, -1.0), Contradicted);
    assert_eq!(Verdict::of(0.2, 0.05, 1.0), Inconclusive);
}

#[test]
fn seeds_for_power_matches_textbook_values() {
    // Two-sided alpha 0.05, power 0.8: 17 per group for d = 1, 64 for d = 0.5 (Cohen 1988).
    assert_eq!(seeds_for_power(1.0, 0.05, 0.8), Some(17));
    assert_eq!(seeds_for_power(-0.5, 0.05, 0.8), Some(64));
    assert_eq!(seeds_for_power(0.0, 0.05, 0.8), None);
}

#[test]
fn fisher_exact_lady_tasting_tea() {
    // Fisher's tea-tasting table [[3, 1], [1, 3]]: two-sided p = 34 / 70.
    assert!((fisher_exact(3, 1, 1, 3) - 34.0 / 70.0).abs() < 1e-12);
    assert!((fisher_exact(4, 0, 0, 4) - 2.0 / 70.0).abs() < 1e-12);
    assert!((fisher_exact(2, 2, 2, 2) - 1.0).abs() < 1e-12);
}

#[test]
fn iqm_and_profiles() {
    let v: Vec<f64> = (1..=8).map(f64::from).collect();
    assert_eq!(iqm(&v), 4.5);
    assert_eq!(iqm(&[5.0, 1.0, 3.0]), 3.0);
    assert_eq!(performance_profile(&v, &[0.0, 4.0, 8.0]), vec![1.0, 0.5, 0.0]);
    assert_eq!(probability_of_improvement(&[2.0, 3.0], &[1.0, 2.0]), 0.875);
    let (lo, hi) = stratified_bootstrap_ci(&[&v, &[10.0, 20.0]], iqm, 0.95, 2000, 1);
    assert!(lo <= hi && lo >= 1.0 && hi <= 20.0);
}

#[test]
fn effect_reports_relative_difference_and_cohen_d() {
    let e = Effect::of(&[2.0, 4.0], &[1.0, 3.0]);
    assert_eq!(e.diff, 1.0);
    assert_eq!(e.relative, Some(0.5));
    assert!((e.cohen_d.unwrap() - 1.0 / 2f64.sqrt()).abs() < 1e-15);
    assert_eq!(Effect::of(&[1.0, 1.0], &[1.0, 1.0]).cohen_d, None);
}
