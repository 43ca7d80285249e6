//! Tests of `report::claims`.

use super::*;
use crate::base::rng::Rng;
use crate::report::metrics::{Convergence, ConvergenceOutcome, TrainMetrics};
use crate::report::table::RunSummary;
use crate::train::eval::EvalSummary;

#[test]
fn verdicts_combine() {
    use Verdict::*;
    assert_eq!(Verdict::all([Supported, Supported]), Supported);
    assert_eq!(Verdict::all([Supported, Inconclusive]), Inconclusive);
    assert_eq!(Verdict::all([Supported, NotMeasurable]), NotMeasurable);
    assert_eq!(Verdict::all([NotMeasurable, Contradicted, Supported]), Contradicted);
    assert_eq!(Verdict::all([]), NotMeasurable);
    use TableVerdict as T;
    assert_eq!(T::all([T::Holds, T::NotMeasurable]), T::NotMeasurable);
    assert_eq!(T::all([T::NotMeasurable, T::DoesNotHold]), T::DoesNotHold);
}

#[test]
fn the_papers_own_table_on_its_claims() {
    let rows = paper::table1();
    let claims = evaluate(&[], &rows);
    let by_id = |id: &str| claims.iter().find(|c| c.id == id).unwrap();
    // Everything is unmeasurable for us without runs.
    assert!(claims.iter().all(|c| c.verdict == Verdict::NotMeasurable));
    // The paper's table supports these...
    for id in [
        "sac-converges-faster",
        "posture-faster-than-stride",
        "sar-fastest",
        "sar-lowest-std",
        "basic-does-not-converge",
    ] {
        assert_eq!(by_id(id).paper_verdict, TableVerdict::Holds, "{id}");
    }
    // ... but not "posture needs fewer steps" (DDPG: 11 vs 11).
    assert_eq!(by_id("posture-fewer-steps").paper_verdict, TableVerdict::DoesNotHold);
    // Relative differences are computed like the paper's percentages: 10.8 % for posture.
    let c = &by_id("sac-converges-faster").comparisons[0];
    assert!(c.paper.contains("10.8 % earlier"), "{}", c.paper);
}

/// A group of `values.len()` seeds whose runs converged at `e_start[i]` (None: did not) with
/// evaluation success rates `success[i]`.
fn group(algo: Method, reward: RewardFunction, e_start: &[Option<f64>], success: &[f64]) -> GroupSummary {
    let runs: Vec<RunSummary> = e_start
        .iter()
        .zip(success)
        .enumerate()
        .map(|(i, (&e, &s))| RunSummary {
            name: format!("{algo}-{}-{i}", reward.name()),
            seed: i as u64,
            episodes: 5000,
            convergence: Convergence {
                outcome: if e.is_some() {
                    ConvergenceOutcome::Converged
                } else {
                    ConvergenceOutcome::NotSettled
                },
                e_start: e.map(|e| e as u64),
                tail_mean: 10.0,
                tail_std: 1.0,
                band: 1.0,
                first_window_mean: 0.0,
            },
            train: e.map(|e| TrainMetrics {
                e_start: e as u64,
                episodes: 5000 - e as u64,
                mean_reward: 15.0,
                v_stdev: Some(2.0),
                mean_steps_success: Some(6.0),
                mean_steps_all: 7.0,
                success_rate: 0.9,
            }),
            tail_mean_reward: 15.0,
            eval: Some(EvalSummary {
                trials: 500,
                mean_reward: 18.0,
                mean_steps: Some(6.0),
                success_rate: s,
                median_final_distance_m: 0.005,
                mean_final_distance_m: 0.006,
                collision_rate: None,
            }),
            eval_final_checkpoint: None,
            eval_file: None,
            notes: Vec::new(),
        })
        .collect();
    let present: Vec<f64> = e_start.iter().flatten().copied().collect();
    GroupSummary {
        algo,
        reward,
        variant: String::new(),
        primary: true,
        episodes: 5000,
        seeds: runs.len(),
        converged: present.len(),
        e_start: MeanStd::of(&present),
        train_reward: None,
        train_steps: None,
        v_stdev: None,
        eval_reward: None,
        eval_steps: None,
        success_rate: MeanStd::of(success),
        collision_rate: None,
        eval_trials: Some(500),
        excluded: Vec::new(),
        runs,
        notes: Vec::new(),
    }
}

fn normal(n: usize, mean: f64, sd: f64, rng: &mut Rng) -> Vec<Option<f64>> {
    (0..n).map(|_| Some(mean + sd * rng.normal())).collect()
}

/// "With SAR, SAC converges faster than DDPG" with SAC's E_start `shift` standard deviations
/// earlier (negative: later) over `n` seeds each.
fn sac_vs_ddpg_sar(shift: f64, n: usize, seed: u64) -> Claim {
    let mut rng = Rng::new(seed);
    let sac = normal(n, 1000.0 - 100.0 * shift, 100.0, &mut rng);
    let ddpg = normal(n, 1000.0, 100.0, &mut rng);
    let ok = vec![0.99; n];
    let groups = [group(Method::Sac, Sar, &sac, &ok), group(Method::Ddpg, Sar, &ddpg, &ok)];
    evaluate(&groups, &paper::table1()).into_iter().find(|c| c.id == "sar-sac-faster-than-ddpg").unwrap()
}

#[test]
fn three_sd_over_20_seeds_is_supported_none_inconclusive_reverse_contradicted() {
    let c = sac_vs_ddpg_sar(3.0, 20, 1);
    assert_eq!(c.verdict, Verdict::Supported, "{:?}", c.comparisons[0].stats);
    let st = c.comparisons[0].stats.as_ref().unwrap();
    assert!(st.diff < -200.0 && st.ci95.1 < 0.0 && st.p_holm < 0.05 && st.p_holm >= st.p);
    assert_eq!(sac_vs_ddpg_sar(-3.0, 20, 2).verdict, Verdict::Contradicted);
    let c = sac_vs_ddpg_sar(0.0, 20, 3);
    assert_eq!(c.verdict, Verdict::Inconclusive);
    assert!(c.comparisons[0].stats.as_ref().unwrap().seeds_needed.is_some());
    // Three seeds cannot resolve even a large effect: the permutation test's smallest p is 0.1.
    let c = sac_vs_ddpg_sar(3.0, 3, 4);
    assert_eq!(c.verdict, Verdict::Inconclusive);
    let need = c.comparisons[0].stats.as_ref().unwrap().seeds_needed.unwrap();
    assert!((3..=20).contains(&need), "{need}");
}

#[test]
fn a_group_that_never_converges_loses_on_e_start_and_convergence_counts() {
    let mut rng = Rng::new(5);
    let ok = vec![0.99; 20];
    let dense = normal(20, 1500.0, 200.0, &mut rng);
    let never = vec![None; 20];
    let mut groups = vec![group(Method::Ddpg, Basic, &never, &[0.0; 20])];
    for a in PAPER_ALGOS {
        for r in [Posture, Stride, Har, Sar] {
            groups.push(group(a, r, &dense, &ok));
        }
    }
    groups.push(group(Method::Sac, Basic, &never, &[0.0; 20]));
    let claims = evaluate(&groups, &paper::table1());
    let basic = claims.iter().find(|c| c.id == BASIC_CLAIM).unwrap();
    assert_eq!(basic.verdict, Verdict::Supported, "{:#?}", basic.comparisons[0]);
    assert_eq!(basic.comparisons[0].stats.as_ref().unwrap().test, Test::FisherExact);
    assert!(basic.detail.contains("0 of 20 seeds converged"), "{}", basic.detail);
}

#[test]
fn markdown_names_the_method_and_every_verdict() {
    let c = sac_vs_ddpg_sar(3.0, 20, 1);
    let md = render_markdown(&[c]);
    assert!(md.contains("permutation test") && md.contains("Holm-Bonferroni"), "{md}");
    assert!(md.contains("1 claims: 1 supported, 0 contradicted, 0 inconclusive"), "{md}");
    assert!(md.contains("| E_start | SAC+SAR"), "{md}");
}

/// A study of a learner other than the paper's (CrossQ's rewards) gets the reward claims checked
/// with that learner, and says so; the claims that compare SAC with DDPG stay unmeasurable; a
/// study that holds SAC (or DDPG) beside other learners keeps the paper's two.
#[test]
fn reward_claims_are_checked_with_the_learners_a_study_of_others_holds() {
    let mut rng = Rng::new(9);
    let ok = vec![0.99; 20];
    let never = vec![None; 20];
    let mut groups = vec![group(Method::Crossq, Basic, &never, &[0.0; 20])];
    for r in [Posture, Stride, Har, Sar] {
        groups.push(group(Method::Crossq, r, &normal(20, 1500.0, 200.0, &mut rng), &ok));
    }
    assert_eq!(claim_learners(&groups), vec![Method::Crossq]);
    let claims = evaluate(&groups, &paper::table1());
    let by_id = |id: &str| claims.iter().find(|c| c.id == id).unwrap();
    let basic = by_id(BASIC_CLAIM);
    assert_eq!(basic.verdict, Verdict::Supported, "{:#?}", basic.comparisons);
    assert!(
        basic.statement.contains("with CrossQ") && basic.detail.contains("CrossQ+Basic: 0 of 20"),
        "{basic:?}"
    );
    assert!(basic.comparisons.iter().all(|k| k.better.0 == Method::Crossq && k.worse.0 == Method::Crossq));
    let sar = by_id("sar-fastest");
    assert_eq!(sar.comparisons.len(), 3);
    assert_ne!(sar.verdict, Verdict::NotMeasurable);
    for id in ["sac-converges-faster", "sar-sac-faster-than-ddpg", "ddpg-sar-headline"] {
        assert_eq!(by_id(id).verdict, Verdict::NotMeasurable, "{id}");
    }
    let md = render_markdown(&claims);
    assert!(md.contains("are checked with CrossQ;"), "{md}");
    // Beside SAC, CrossQ's groups do not change the paper's claims (nor add comparisons).
    let mut with_sac = groups.clone();
    with_sac.push(group(Method::Sac, Sar, &normal(20, 1500.0, 200.0, &mut rng), &ok));
    assert_eq!(claim_learners(&with_sac), PAPER_ALGOS.to_vec());
    let claims = evaluate(&with_sac, &paper::table1());
    assert!(claims.iter().flat_map(|c| &c.comparisons).all(|k| k.better.0 != Method::Crossq));
    assert!(!render_markdown(&claims).contains("are checked with"));
    // No runs at all: the paper's learners (every claim unmeasurable, as before).
    assert_eq!(claim_learners(&[]), PAPER_ALGOS.to_vec());
}
