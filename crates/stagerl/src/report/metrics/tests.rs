//! Tests of `report::metrics`.

use super::*;
use crate::base::rng::Rng;
use crate::io::csv::TrialRecord;
use crate::train::eval::EvalSummary;

fn crit(floor: f64) -> ConvergenceCriterion {
    ConvergenceCriterion { band_floor: floor, ..ConvergenceCriterion::default() }
}

#[test]
fn step_curve_converges_at_the_step() {
    // Episodes 1..=999 earn -20, episodes 1000..=3000 earn 15.
    let r: Vec<f64> = (1..=3000).map(|e| if e < 1000 { -20.0 } else { 15.0 }).collect();
    let c = convergence(&r, &crit(0.1)).unwrap();
    assert_eq!(c.outcome, ConvergenceOutcome::Converged);
    assert_eq!(c.e_start, Some(1000));
    assert_eq!((c.tail_mean, c.tail_std, c.band), (15.0, 0.0, 0.1));
    // A floor of 0.5 tolerates one low episode in the window: 15 - 35/100 >= 14.5.
    assert_eq!(e_start(&r, &crit(0.5)).unwrap(), Some(999));
}

#[test]
fn noisy_exponential_rise() {
    // R_e = 18 - 40 exp(-e / 300) + 2 z. Tail std ~ 2 so h ~ 2; the window starting at e has the
    // noise-free mean 18 - 40 exp(-e/300) (1 - e^{-1/3}) / (100 (1 - e^{-1/300})), which is
    // 18 - 2 at e = 300 ln(17.0) ~ 850.
    let mut rng = Rng::new(17);
    let r: Vec<f64> =
        (1..=3000).map(|e| 18.0 - 40.0 * (-(e as f64) / 300.0).exp() + 2.0 * rng.normal()).collect();
    let c = convergence(&r, &ConvergenceCriterion::default()).unwrap();
    assert_eq!(c.outcome, ConvergenceOutcome::Converged);
    assert!((c.tail_std - 2.0).abs() < 0.2, "{c:?}");
    let g = 40.0 * (1.0 - (-1.0f64 / 3.0).exp()) / (100.0 * (1.0 - (-1.0f64 / 300.0).exp()));
    let expect = 300.0 * (g / 2.0f64).ln();
    assert!((expect - 850.0).abs() < 5.0, "{expect}");
    let e = c.e_start.unwrap() as f64;
    assert!((e - expect).abs() < 100.0, "E_start {e}, noise-free answer {expect}");
}

#[test]
fn curves_that_never_settle() {
    let mut rng = Rng::new(5);
    // A ramp still rising at the end.
    let ramp: Vec<f64> = (0..3000).map(|e| 0.02 * e as f64 + rng.normal()).collect();
    let c = convergence(&ramp, &ConvergenceCriterion::default()).unwrap();
    assert_eq!((c.outcome, c.e_start), (ConvergenceOutcome::NotSettled, None));
    // A noiseless ramp of any slope.
    let ramp: Vec<f64> = (0..3000).map(|e| 1e-4 * e as f64).collect();
    assert_eq!(e_start(&ramp, &crit(0.0)).unwrap(), None);
    // Flat noise: nothing learned (the sparse reward that never succeeds is all zeros).
    let flat: Vec<f64> = (0..3000).map(|_| rng.normal()).collect();
    assert_eq!(convergence(&flat, &crit(0.5)).unwrap().outcome, ConvergenceOutcome::NoImprovement);
    assert_eq!(e_start(&vec![0.0; 3000], &crit(0.5)).unwrap(), None);
    // A collapse at the end: the tail's halves differ by 24 > h = 19.9.
    let mut late: Vec<f64> = (0..3000).map(|e| if e < 500 { -20.0 } else { 15.0 }).collect();
    late[2920..].iter_mut().for_each(|x| *x = -30.0);
    let c = convergence(&late, &crit(0.5)).unwrap();
    assert_eq!(c.outcome, ConvergenceOutcome::NotSettled, "{c:?}");
    // A late step: the tail holds both levels.
    let step: Vec<f64> = (0..3000).map(|e| if e < 2850 { -20.0 } else { 15.0 }).collect();
    assert_eq!(convergence(&step, &crit(0.5)).unwrap().outcome, ConvergenceOutcome::NotSettled);
    // Too short for W + L.
    assert_eq!(convergence(&[1.0; 150], &crit(0.5)).unwrap().outcome, ConvergenceOutcome::TooShort);
}

#[test]
fn collapse_before_the_tail_moves_e_start_after_it() {
    let mut r: Vec<f64> = (0..3000).map(|e| if e < 500 { -20.0 } else { 15.0 }).collect();
    r[1500..1600].iter_mut().for_each(|x| *x = -20.0);
    // Windows overlapping the collapse by more than 1.43 episodes leave the band (h = 0.5).
    assert_eq!(e_start(&r, &crit(0.5)).unwrap(), Some(1600));
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    assert!(convergence(&[1.0, f64::NAN], &ConvergenceCriterion::default()).is_err());
    for bad in [
        ConvergenceCriterion { window: 0, ..Default::default() },
        ConvergenceCriterion { tail_fraction: 1.0, ..Default::default() },
        ConvergenceCriterion { band_k: -1.0, ..Default::default() },
        ConvergenceCriterion { band_k: 0.0, band_floor: 0.0, ..Default::default() },
    ] {
        assert!(convergence(&[1.0; 10], &bad).is_err(), "{bad:?}");
    }
    assert_eq!(
        convergence(&[], &ConvergenceCriterion::default()).unwrap().outcome,
        ConvergenceOutcome::TooShort
    );
}

#[test]
fn eq17_by_hand() {
    let r = [-5.0, 0.0, 2.0, 4.0, 6.0];
    // From the third episode: mean (2 + 4 + 6) / 3 = 4, std sqrt((4 + 0 + 4) / 2) = 2.
    assert_eq!(eq17(&r, 3), Some((4.0, Some(2.0))));
    assert_eq!(eq17(&r, 5), Some((6.0, None)));
    assert_eq!(eq17(&r, 1).unwrap().0, 1.4);
    assert_eq!(eq17(&r, 0), None);
    assert_eq!(eq17(&r, 6), None);
}

#[test]
fn train_and_eval_metrics_by_hand() {
    let rec = |episode, reward, steps, success| EpisodeRecord {
        collision_steps: None,
        curriculum_stage: None,
        episode,
        reward,
        steps,
        success,
        final_distance_m: 0.0,
        env_steps: 0,
        wall_s: 0.0,
    };
    let rs =
        [rec(1, -30.0, 50, false), rec(2, 10.0, 50, false), rec(3, 19.0, 6, true), rec(4, 19.0, 8, true)];
    let m = train_metrics(&rs, 2).unwrap();
    assert_eq!((m.e_start, m.episodes), (2, 3));
    assert_eq!(m.mean_reward, 16.0);
    assert!((m.v_stdev.unwrap() - 27.0f64.sqrt()).abs() < 1e-12);
    assert_eq!(m.mean_steps_success, Some(7.0));
    assert_eq!(m.mean_steps_all, 64.0 / 3.0);
    assert!((m.success_rate - 2.0 / 3.0).abs() < 1e-15);
    assert!(train_metrics(&rs, 5).is_none());

    let t = |trial, reward, steps, success| TrialRecord {
        collision_steps: None,
        trial,
        reward,
        steps,
        success,
        start_distance_m: 0.4,
        final_distance_m: 0.0,
        target: [0.0; 3],
    };
    let e = EvalSummary::of(&[
        t(1, 18.0, 6, true),
        t(2, -4.0, 50, false),
        t(3, 19.0, 4, true),
        t(4, 19.0, 5, true),
    ])
    .unwrap();
    assert_eq!((e.trials, e.mean_reward, e.mean_steps, e.success_rate), (4, 13.0, Some(5.0), 0.75));
    assert_eq!((e.median_final_distance_m, e.mean_final_distance_m), (0.0, 0.0));
    assert!(EvalSummary::of(&[]).is_none());
}

#[test]
fn mean_std_over_seeds() {
    let a = MeanStd::of(&[1.0, 2.0, 3.0, 4.0]).unwrap();
    assert_eq!(a.mean, 2.5);
    assert!((a.std.unwrap() - (5.0f64 / 3.0).sqrt()).abs() < 1e-15);
    assert_eq!(MeanStd::of(&[7.0]).unwrap().std, None);
    assert!(MeanStd::of(&[]).is_none());
    assert_eq!(MeanStd::of_present([Some(1.0), None, Some(3.0)]).unwrap().n, 2);
}

#[test]
fn moving_averages() {
    assert_eq!(window_means(&[1.0, 2.0, 3.0, 4.0], 2), vec![1.5, 2.5, 3.5]);
    assert!(window_means(&[1.0], 2).is_empty());
    assert_eq!(trailing_moving_average(&[1.0, 3.0, 5.0, 7.0], 2), vec![1.0, 2.0, 4.0, 6.0]);
    let long: Vec<f64> = (0..5000).map(|i| (i % 7) as f64 * 0.1).collect();
    let m = window_means(&long, 100);
    for (j, v) in m.iter().enumerate().step_by(333) {
        let direct: f64 = long[j..j + 100].iter().sum::<f64>() / 100.0;
        assert!((v - direct).abs() < 1e-12);
    }
}
