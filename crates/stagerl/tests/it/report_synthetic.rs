//! `stagerl::report::generate` on small synthetic run directories: the table's values against the
//! CSVs (recomputed here by brute force), every output file present, the PNGs valid, and broken or
//! partial runs reported instead of crashing.

use serde_json::Value;
use stagerl::agent::Algo;
use stagerl::base::rng::Rng;
use stagerl::config::Config;
use stagerl::io::csv::write_trials_csv;
use stagerl::io::csv::TrialRecord;
use stagerl::io::csv::{EpisodeCsv, EpisodeRecord};
use stagerl::report::{self, ReportOptions};
use stagerl::reward::RewardFunction;
use std::path::{Path, PathBuf};

const EPISODES: u64 = 600;

struct Run {
    rewards: Vec<f64>,
    steps: Vec<u32>,
    success: Vec<bool>,
    trials: Option<Vec<TrialRecord>>,
}

/// A run whose reward rises from about -25 to about 18 around `knee`, with noise.
fn write_run(
    dir: &Path,
    algo: Algo,
    reward: RewardFunction,
    seed: u64,
    knee: f64,
    episodes: u64,
    with_eval: bool,
) -> Run {
    std::fs::create_dir_all(dir).unwrap();
    let mut cfg = Config::default();
    cfg.agent.algo = algo;
    cfg.reward.function = reward;
    cfg.train.seed = seed;
    cfg.train.episodes = EPISODES;
    cfg.train.eval_every_episodes = 100;
    std::fs::write(dir.join("config.toml"), cfg.to_toml_string()).unwrap();
    let mut rng = Rng::new(seed * 31 + knee as u64);
    let mut csv = EpisodeCsv::create(&dir.join("episodes.csv")).unwrap();
    let mut run = Run { rewards: Vec::new(), steps: Vec::new(), success: Vec::new(), trials: None };
    let mut env_steps = 0;
    for e in 1..=episodes {
        let p = 1.0 / (1.0 + (-(e as f64 - knee) / 25.0).exp());
        let success = rng.uniform() < p * 0.97;
        let steps = if success { 5 + rng.below(8) as u32 } else { 50 };
        let r = if success { 19.0 - 0.1 * f64::from(steps) } else { -25.0 + 3.0 * rng.normal() };
        env_steps += u64::from(steps);
        csv.write(&EpisodeRecord {
            episode: e,
            reward: r,
            steps,
            success,
            final_distance_m: if success { 0.008 } else { 0.2 },
            env_steps,
            wall_s: e as f64 * 0.01,
            collision_steps: Some(u32::from(!success)),
            curriculum_stage: None,
        })
        .unwrap();
        run.rewards.push(r);
        run.steps.push(steps);
        run.success.push(success);
    }
    let mut eval =
        String::from("episode,env_steps,success_rate,mean_reward,mean_steps,median_final_distance_m\n");
    for k in 1..=episodes / 100 {
        let s = (k as f64 * 0.2).min(1.0);
        let steps = if k == 1 { String::new() } else { format!("{}", 12.0 - k as f64) };
        eval.push_str(&format!("{},{},{s},{},{steps},0.01\n", k * 100, k * 2000, -20.0 + 38.0 * s));
    }
    std::fs::write(dir.join("eval.csv"), eval).unwrap();
    if with_eval {
        let trials: Vec<TrialRecord> = (1..=40)
            .map(|t| {
                let success = rng.uniform() < 0.9;
                let steps = if success { 4 + rng.below(6) as u32 } else { 50 };
                TrialRecord {
                    trial: t,
                    reward: if success { 19.5 - 0.1 * f64::from(steps) } else { -10.0 },
                    steps,
                    success,
                    start_distance_m: 0.4,
                    final_distance_m: if success { 0.005 } else { 0.05 },
                    target: [-0.3, 0.1, 0.4],
                    // A few trials touch something (one in eight, at random).
                    collision_steps: Some(if rng.below(8) == 0 { 1 + rng.below(3) as u32 } else { 0 }),
                }
            })
            .collect();
        write_trials_csv(&dir.join(format!("eval-seed{}.csv", 1_000_003)), &trials).unwrap();
        run.trials = Some(trials);
    }
    run
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

fn std(x: &[f64]) -> f64 {
    let m = mean(x);
    (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64).sqrt()
}

/// E_start by brute force, straight from the definition (window 100, tail 10 %, band max(s, 0.5)).
fn e_start_ref(r: &[f64]) -> Option<usize> {
    let (n, w) = (r.len(), 100);
    let l = ((0.1 * n as f64).ceil() as usize).max(w);
    if n < w + l {
        return None;
    }
    let tail = &r[n - l..];
    let (mu, h) = (mean(tail), std(tail).max(0.5));
    if (mean(&tail[..l / 2]) - mean(&tail[l / 2..])).abs() > h || mean(&r[..w]) >= mu - 2.0 * h {
        return None;
    }
    let inside = |j: usize| (mean(&r[j..j + w]) - mu).abs() <= h;
    let e = (0..=n - w).find(|&e| (e..=n - w).all(inside))?;
    (e <= n - l).then_some(e + 1)
}

struct Expect {
    e_start: f64,
    reward: f64,
    v_stdev: f64,
    steps: f64,
}

fn expected(run: &Run) -> Expect {
    let e = e_start_ref(&run.rewards).expect("the synthetic run converges");
    let after = &run.rewards[e - 1..];
    let ok_steps: Vec<f64> =
        (e - 1..run.rewards.len()).filter(|&i| run.success[i]).map(|i| f64::from(run.steps[i])).collect();
    Expect { e_start: e as f64, reward: mean(after), v_stdev: std(after), steps: mean(&ok_steps) }
}

fn close(v: &Value, want: f64) {
    let got = v.as_f64().unwrap_or_else(|| panic!("{v} is not a number"));
    assert!((got - want).abs() < 1e-9 * want.abs().max(1.0), "got {got}, want {want}");
}

fn png_size(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap();
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "{} is not a PNG", path.display());
    assert_eq!(&b[12..16], b"IHDR");
    let be = |i: usize| u32::from_be_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
    (be(16), be(20))
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("stagerl-report-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn report_of_synthetic_runs() {
    let root = temp_dir("synthetic");
    // Depth 1 and depth 2 runs.
    let a1 = write_run(&root.join("sac-sar-1"), Algo::Sac, RewardFunction::Sar, 1, 150.0, EPISODES, true);
    let a2 =
        write_run(&root.join("sweep/sac-sar-2"), Algo::Sac, RewardFunction::Sar, 2, 220.0, EPISODES, true);
    // A group with one complete run without a per-trial evaluation and one still training.
    let b1 = write_run(
        &root.join("sweep/ddpg-posture-1"),
        Algo::Ddpg,
        RewardFunction::Posture,
        1,
        300.0,
        EPISODES,
        false,
    );
    write_run(&root.join("sweep/ddpg-posture-2"), Algo::Ddpg, RewardFunction::Posture, 2, 300.0, 250, true);
    // An unreadable config, and a run whose episodes.csv is malformed.
    std::fs::create_dir_all(root.join("broken")).unwrap();
    std::fs::write(root.join("broken/config.toml"), "[agent]\nalgo = \"a2c\"\n").unwrap();
    std::fs::write(root.join("broken/episodes.csv"), "").unwrap();
    write_run(&root.join("bad-csv"), Algo::Sac, RewardFunction::Har, 1, 100.0, 10, false);
    std::fs::write(root.join("bad-csv/episodes.csv"), "episode,reward\n1,2\n").unwrap();
    // A non-finite reward in an otherwise complete run.
    write_run(&root.join("td3-nan"), Algo::Td3, RewardFunction::Sar, 1, 100.0, EPISODES, false);
    let text = std::fs::read_to_string(root.join("td3-nan/episodes.csv")).unwrap();
    let text = text.replacen("\n7,", "\n7,NaN,50,0,0.2,0,0.0\n7x,", 1);
    let text: String = text.lines().filter(|l| !l.starts_with("7x,")).map(|l| format!("{l}\n")).collect();
    std::fs::write(root.join("td3-nan/episodes.csv"), text).unwrap();

    // The study's regime, as a sweep's recorded preset names it (the runs' values are not read).
    std::fs::write(root.join("preset.toml"), "[sweep]\nregime = \"tuned\"\n").unwrap();

    let out = root.join("report");
    let r = report::generate(&root, &ReportOptions::new(&out)).unwrap();

    // Files.
    for name in [
        "table1.md",
        "table1.csv",
        "table1.json",
        "claims.md",
        "figure7.png",
        "figure7.svg",
        "figure8.png",
        "figure8.svg",
        "aggregates.md",
        "performance_profile.png",
        "performance_profile.svg",
    ] {
        let p = out.join(name);
        assert!(std::fs::metadata(&p).map(|m| m.len() > 0).unwrap_or(false), "{name} missing or empty");
    }
    // No checkpoints: no trajectories, a warning instead.
    assert!(!out.join("trajectories.png").exists());
    assert!(r.warnings.iter().any(|w| w.contains("no trajectories")), "{:?}", r.warnings);
    let (w, h) = png_size(&out.join("figure7.png"));
    // Each panel has its legend beside it (230 px), outside the data.
    assert_eq!((w, h), (60 + (640 + 230) * 3, 110 + 420 * 2), "three algorithms, two rows");
    let (w, h) = png_size(&out.join("figure8.png"));
    assert_eq!((w, h), (60 + (640 + 230) * 3, 110 + 420 * 3));
    // The study is named (regime, seeds, episodes), and the scripted controller is a reference row
    // evaluated on the runs' targets: it reaches every target of this task.
    let md = std::fs::read_to_string(out.join("table1.md")).unwrap();
    assert!(md.contains("tuned regime (our defaults"), "{md}");
    assert!(md.contains("## Reference: the scripted Jacobian controller"), "{md}");
    assert!(!r.reference.is_empty());
    for row in &r.reference {
        assert!(row.summary.success_rate > 0.95, "{row:?}");
        assert!(md.contains(&format!(
            "| Jacobian controller | {} |",
            stagerl::report::table::reward_title(row.reward)
        )));
    }
    assert!(std::fs::read_to_string(out.join("claims.md")).unwrap().contains("Jacobian controller"));
    assert!(!r.input.is_absolute(), "outputs name the input by its directory name: {:?}", r.input);
    assert!(std::fs::read_to_string(out.join("figure7.svg")).unwrap().starts_with("<svg"));

    // Values against the CSVs.
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table1.json")).unwrap()).unwrap();
    let groups = json["groups"].as_array().unwrap();
    let group = |algo: &str, reward: &str| {
        groups
            .iter()
            .find(|g| g["algo"] == algo && g["reward"] == reward)
            .unwrap_or_else(|| panic!("{algo} {reward}"))
    };
    let sar = group("sac", "sar");
    assert_eq!((sar["seeds"].as_u64(), sar["converged"].as_u64()), (Some(2), Some(2)));
    let (x1, x2) = (expected(&a1), expected(&a2));
    close(&sar["runs"][0]["train"]["e_start"], x1.e_start);
    close(&sar["runs"][1]["train"]["e_start"], x2.e_start);
    close(&sar["e_start"]["mean"], mean(&[x1.e_start, x2.e_start]));
    close(&sar["e_start"]["std"], std(&[x1.e_start, x2.e_start]));
    close(&sar["train_reward"]["mean"], mean(&[x1.reward, x2.reward]));
    close(&sar["train_reward"]["std"], std(&[x1.reward, x2.reward]));
    close(&sar["v_stdev"]["mean"], mean(&[x1.v_stdev, x2.v_stdev]));
    close(&sar["train_steps"]["mean"], mean(&[x1.steps, x2.steps]));
    let ev = |run: &Run| {
        let t = run.trials.as_ref().unwrap();
        let ok: Vec<f64> = t.iter().filter(|t| t.success).map(|t| f64::from(t.steps)).collect();
        let hit = t.iter().filter(|t| t.collision_steps.unwrap() > 0).count() as f64;
        (
            mean(&t.iter().map(|t| t.reward).collect::<Vec<_>>()),
            mean(&ok),
            ok.len() as f64 / t.len() as f64,
            hit / t.len() as f64,
        )
    };
    let (e1, e2) = (ev(&a1), ev(&a2));
    close(&sar["eval_reward"]["mean"], mean(&[e1.0, e2.0]));
    close(&sar["eval_steps"]["mean"], mean(&[e1.1, e2.1]));
    close(&sar["success_rate"]["mean"], mean(&[e1.2, e2.2]));
    close(&sar["success_rate"]["std"], std(&[e1.2, e2.2]));
    assert!(e1.3 > 0.0 || e2.3 > 0.0, "the synthetic trials touch something");
    close(&sar["collision_rate"]["mean"], mean(&[e1.3, e2.3]));
    close(&sar["collision_rate"]["std"], std(&[e1.3, e2.3]));

    let posture = group("ddpg", "posture");
    assert_eq!(posture["seeds"].as_u64(), Some(1));
    close(&posture["e_start"]["mean"], expected(&b1).e_start);
    assert!(posture["e_start"]["std"].is_null(), "one seed: no std");
    assert!(posture["eval_reward"].is_null());
    let notes: Vec<&str> = posture["notes"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect();
    assert!(notes.iter().any(|n| n.contains("incomplete: 250 of 600 episodes")), "{notes:?}");
    assert!(notes.iter().any(|n| n.contains("no per-trial evaluation CSV")), "{notes:?}");

    // The broken runs are reported, not fatal.
    assert!(r.skipped.iter().any(|s| s.name == "broken"), "{:?}", r.skipped);
    let har = group("sac", "har");
    assert_eq!(har["seeds"].as_u64(), Some(0));
    assert!(har["notes"].to_string().contains("no episodes read (episodes.csv not read"), "{}", har["notes"]);
    let td3 = group("td3", "sar");
    assert_eq!((td3["seeds"].as_u64(), td3["converged"].as_u64()), (Some(1), Some(0)));
    assert_eq!(td3["runs"][0]["convergence"]["outcome"], "invalid_data");
    assert!(td3["notes"].to_string().contains("not finite"), "{}", td3["notes"]);

    // The Markdown table shows ours beside the paper's, with the notes.
    let md = std::fs::read_to_string(out.join("table1.md")).unwrap();
    assert!(md.contains("| SAC | SAR | paper | 20 | 10000 | 3593 | 16.830 ± 0.255 |"), "{md}");
    let row = md.lines().find(|l| l.starts_with("| SAC | SAR | ours |")).unwrap();
    assert!(
        row.contains(&format!(
            "{:.0} ± {:.0}",
            mean(&[x1.e_start, x2.e_start]),
            std(&[x1.e_start, x2.e_start])
        )),
        "{row}"
    );
    assert!(
        row.contains(&format!("{:.1} ± {:.1} %", 100.0 * mean(&[e1.2, e2.2]), 100.0 * std(&[e1.2, e2.2]))),
        "{row}"
    );
    assert!(
        row.contains(&format!("{:.1} ± {:.1} % |", 100.0 * mean(&[e1.3, e2.3]), 100.0 * std(&[e1.3, e2.3]))),
        "the collision rate is the last value column: {row}"
    );
    assert!(md.contains("| DDPG | Stride | ours | 0 | — | not run |"), "{md}");
    assert!(md.contains("ddpg-posture-2 (seed 2) excluded: incomplete"), "{md}");
    assert!(md.contains("`broken`"), "{md}");

    // CSV: one row per group and per paper row.
    let csv = std::fs::read_to_string(out.join("table1.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + groups.len() + 10);
    let sar_row = csv.lines().find(|l| l.starts_with("ours,sac,sar,")).unwrap();
    assert!(sar_row.contains(&format!(",{},", mean(&[x1.e_start, x2.e_start]))), "{sar_row}");

    // Claims: listed in Markdown and JSON; SAC+SAR vs DDPG+SAR cannot be compared (not run).
    let claims = json["claims"].as_array().unwrap();
    assert!(claims.len() >= 15);
    let c = claims.iter().find(|c| c["id"] == "sar-sac-faster-than-ddpg").unwrap();
    assert_eq!(c["verdict"], "not_measurable");
    let c = claims.iter().find(|c| c["id"] == "sac-converges-faster").unwrap();
    assert_eq!(c["paper_verdict"], "holds");
    let claims_md = std::fs::read_to_string(out.join("claims.md")).unwrap();
    assert!(claims_md.contains("DDPG+SAR not run"), "{claims_md}");

    if std::env::var_os("STAGERL_KEEP_REPORT").is_none() {
        std::fs::remove_dir_all(&root).ok();
    }
}

#[test]
fn an_empty_directory_and_a_missing_one_are_errors_writing_nothing() {
    let root = temp_dir("empty");
    let e = report::generate(&root, &ReportOptions::new(root.join("out"))).unwrap_err().to_string();
    assert!(e.contains("no runs to report on") && e.contains("empty"), "{e}");
    assert!(!root.join("out").exists());
    let e =
        report::generate(&root.join("nope"), &ReportOptions::new(root.join("out2"))).unwrap_err().to_string();
    assert!(e.contains("nope"), "{e}");
    // A directory of non-runs: an error that says what was not read.
    std::fs::create_dir_all(root.join("junk")).unwrap();
    std::fs::write(root.join("junk/config.toml"), "not toml [").unwrap();
    std::fs::write(root.join("junk/episodes.csv"), "x").unwrap();
    let e = report::generate(&root, &ReportOptions::new(root.join("out"))).unwrap_err().to_string();
    assert!(e.contains("no runs to report on") && e.contains("junk"), "{e}");
    assert!(!root.join("out").exists());
    std::fs::remove_dir_all(&root).ok();
}
