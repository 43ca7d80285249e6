//! Tests of `sweep`.

use super::*;

const PRESET: &str =
    "[sweep]\nalgorithms = [\"ddpg\", \"sac\"]\nrewards = [\"posture\", \"sar\"]\nseeds = [1, 2, 3]\n\
                      eval_trials = 20\n[train]\nepisodes = 7\n";

#[test]
fn preset_expands_in_order_and_shards_cover_every_run_once() {
    let p = Preset::from_toml_str(PRESET, Path::new("p.toml")).unwrap();
    assert_eq!(p.base.train.episodes, 7);
    let runs = p.runs();
    assert_eq!(runs.len(), 12);
    assert_eq!(runs[0].name, "ddpg-posture-seed1");
    assert_eq!(runs[11].name, "sac-sar-seed3");
    assert_eq!(runs[4].config.reward.function, RewardFunction::Sar);
    assert_eq!(runs[4].config.train.seed, 2);
    let mut seen: Vec<usize> = Vec::new();
    for i in 0..5 {
        seen.extend(shard(runs.clone(), i, 5).unwrap().iter().map(|r| r.index));
    }
    seen.sort_unstable();
    assert_eq!(seen, (0..12).collect::<Vec<_>>());
    assert!(shard(runs.clone(), 5, 5).is_err());
    assert!(shard(runs, 0, 0).is_err());
}

#[test]
fn shard_from_flags_or_slurm_with_step() {
    let env = |vars: &'static [(&'static str, &'static str)]| {
        move |name: &str| vars.iter().find(|(k, _)| *k == name).map(|(_, v)| v.to_string())
    };
    let none = env(&[]);
    assert_eq!(resolve_shard(None, None, &none).unwrap(), (0, 1));
    assert_eq!(resolve_shard(Some(2), Some(5), &none).unwrap(), (2, 5));
    assert!(resolve_shard(Some(2), None, &none).unwrap_err().to_string().contains("task count"));
    // --array=0-19:2: ids 0, 2, .., 18 are tasks 0 .. 9 of 10.
    let stepped = env(&[
        ("SLURM_ARRAY_TASK_ID", "14"),
        ("SLURM_ARRAY_TASK_MIN", "0"),
        ("SLURM_ARRAY_TASK_STEP", "2"),
        ("SLURM_ARRAY_TASK_COUNT", "10"),
    ]);
    assert_eq!(resolve_shard(None, None, &stepped).unwrap(), (7, 10));
    let offset =
        env(&[("SLURM_ARRAY_TASK_ID", "7"), ("SLURM_ARRAY_TASK_MIN", "1"), ("SLURM_ARRAY_TASK_STEP", "3")]);
    assert_eq!(resolve_shard(None, Some(4), &offset).unwrap(), (2, 4));
    let off_grid = env(&[
        ("SLURM_ARRAY_TASK_ID", "5"),
        ("SLURM_ARRAY_TASK_STEP", "2"),
        ("SLURM_ARRAY_TASK_COUNT", "10"),
    ]);
    let e = resolve_shard(None, None, &off_grid).unwrap_err().to_string();
    assert!(e.contains("SLURM_ARRAY_TASK_STEP = 2"), "{e}");
    // Explicit flags win: malformed variables are not even read.
    let bad = env(&[("SLURM_ARRAY_TASK_ID", "x"), ("SLURM_ARRAY_TASK_COUNT", "-1")]);
    assert_eq!(resolve_shard(Some(1), Some(3), &bad).unwrap(), (1, 3));
    let e = resolve_shard(None, Some(3), &bad).unwrap_err().to_string();
    assert!(e.contains("SLURM_ARRAY_TASK_ID") && e.contains("\"x\""), "{e}");
    let e = resolve_shard(Some(0), None, &bad).unwrap_err().to_string();
    assert!(e.contains("SLURM_ARRAY_TASK_COUNT"), "{e}");
    let below = env(&[("SLURM_ARRAY_TASK_ID", "0"), ("SLURM_ARRAY_TASK_MIN", "1")]);
    assert!(resolve_shard(None, None, &below).unwrap_err().to_string().contains("below"));
}

#[test]
fn bundled_presets_resolve_by_name_and_paths_by_path() {
    let (p, text) = Preset::resolve("smoke").unwrap();
    assert_eq!(text, BUNDLED_PRESETS[0].1);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/presets/smoke.toml");
    let (q, from_file) = Preset::resolve(path.to_str().unwrap()).unwrap();
    assert_eq!((p, text), (q, from_file));
    let e = Preset::resolve("nope").unwrap_err().to_string();
    assert!(e.contains("nope") && e.contains("smoke, quick, tuned, paper"), "{e}");
}

#[test]
fn preset_errors_name_the_field() {
    let cases = [
        ("[train]\nepisodes = 3\n", "no [sweep]"),
        ("[sweep]\nalgorithms = []\nrewards = [\"sar\"]\nseeds = [1]\n", "sweep.algorithms"),
        ("[sweep]\nalgorithms = [\"a2c\"]\nrewards = [\"sar\"]\nseeds = [1]\n", "a2c"),
        ("[sweep]\nalgorithms = [\"sac\"]\nrewards = [\"sar\"]\nseeds = [1, 1]\n", "sweep.seeds"),
        ("[sweep]\nalgorithms = [\"sac\"]\nrewards = [\"sar\"]\nseeds = [1]\nextra = 2\n", "extra"),
        (
            "[sweep]\nalgorithms = [\"sac\"]\nrewards = [\"sar\"]\nseeds = [1]\n[train]\nepisodes = 0\n",
            "train.episodes",
        ),
    ];
    for (text, needle) in cases {
        let e = Preset::from_toml_str(text, Path::new("p.toml")).unwrap_err().to_string();
        assert!(e.contains(needle), "{text:?}: {e}");
    }
}

#[test]
fn each_run_keeps_only_its_algorithms_section() {
    let text = format!(
        "{PRESET}[agent]\ngamma = 0.9\n[agent.ddpg]\nnoise = \"ou\"\n[agent.sac]\ninit_alpha = 0.5\n"
    );
    let p = Preset::from_toml_str(&text, Path::new("p.toml")).unwrap();
    for run in p.runs() {
        let agent = &run.config.agent;
        assert_eq!(agent.gamma, 0.9, "{}", run.name);
        assert_eq!(agent.sections(), vec![agent.algo], "{}", run.name);
        run.config.validate().unwrap();
        let written = run.config.to_toml_string();
        match agent.algo {
            Algo::Ddpg => {
                assert_eq!(agent.ddpg().noise, crate::agent::NoiseKind::Ou);
                assert!(written.contains("[agent.ddpg]") && !written.contains("[agent.sac]"), "{written}");
            }
            Algo::Sac => {
                assert_eq!(agent.sac().init_alpha, 0.5);
                assert!(written.contains("[agent.sac]") && !written.contains("[agent.ddpg]"), "{written}");
            }
            Algo::Td3 | Algo::Ppo | Algo::Crossq => unreachable!("not in the sweep"),
        }
        // The run's resolved config.toml reads back as the same config.
        assert_eq!(Config::from_toml_str(&written, Path::new("config.toml")).unwrap(), run.config);
    }
    // A section of an algorithm outside the sweep is refused, naming it and the sweep's.
    let e = Preset::from_toml_str(&format!("{PRESET}[agent.td3]\npolicy_delay = 3\n"), Path::new("p.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("agent.td3") && e.contains("ddpg, sac"), "{e}");
    // A section's values are checked like a run's.
    let e = Preset::from_toml_str(&format!("{PRESET}[agent.ddpg]\nnoise_sigma = -1\n"), Path::new("p.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("agent.ddpg.noise_sigma"), "{e}");
}

#[test]
fn her_variants_multiply_the_runs() {
    let text = "[sweep]\nalgorithms = [\"sac\"]\nrewards = [\"basic\", \"sar\"]\nseeds = [1, 2]\nher = [\"off\", \"future\"]\n[agent.her]\nk = 2\n";
    let p = Preset::from_toml_str(text, Path::new("t.toml")).unwrap();
    let names: Vec<String> = p.runs().into_iter().map(|r| r.name).collect();
    assert_eq!(
        names,
        [
            "sac-basic-seed1",
            "sac-basic-seed2",
            "sac-basic-her-future-seed1",
            "sac-basic-her-future-seed2",
            "sac-sar-seed1",
            "sac-sar-seed2",
            "sac-sar-her-future-seed1",
            "sac-sar-her-future-seed2"
        ]
    );
    // PPO in the same sweep runs once per reward and seed, without relabelling, also when
    // only `[agent.her]` asks for it.
    let with_ppo = text.replace("[\"sac\"]", "[\"sac\", \"ppo\"]");
    for t in [with_ppo.clone(), with_ppo.replace("her = [\"off\", \"future\"]\n", "")] {
        let runs = Preset::from_toml_str(&t, Path::new("t.toml")).unwrap().runs();
        let ppo: Vec<&str> =
            runs.iter().filter(|r| r.config.agent.algo == Algo::Ppo).map(|r| r.name.as_str()).collect();
        assert_eq!(ppo, ["ppo-basic-seed1", "ppo-basic-seed2", "ppo-sar-seed1", "ppo-sar-seed2"], "{t}");
        assert!(runs.iter().all(|r| r.config.validate().is_ok()));
    }
    let her = p.runs()[2].config.agent.her.unwrap();
    assert_eq!((her.strategy, her.k), (crate::agent::HerStrategy::Future, 2));
    assert_eq!(p.runs()[0].config.agent.her, None);
    for bad in ["[\"sometimes\"]", "[\"off\", \"off\"]"] {
        let t = text.replace("[\"off\", \"future\"]", bad);
        let e = Preset::from_toml_str(&t, Path::new("t.toml")).unwrap_err().to_string();
        assert!(e.contains("sweep.her"), "{e}");
    }
}

#[test]
fn variants_run_beside_their_algorithm_and_excludes_remove_runs() {
    let text = "[sweep]\nalgorithms = [\"sac\", \"ddpg\"]\nrewards = [\"basic\", \"sar\"]\nseeds = [1]\n\
                her = [\"off\", \"future\"]\n\
                exclude = [{ reward = \"basic\", her = \"off\" }, { reward = \"sar\", her = \"future\" }, \
                { algorithm = \"ddpg\" }]\n\
                [[sweep.variants]]\nname = \"redq\"\nalgorithm = \"sac\"\n\
                [sweep.variants.agent]\nupdates_per_step = 3\n[sweep.variants.agent.sac]\nn_critics = 5\ncritic_subset = 2\n\
                [agent]\ngamma = 0.9\n[agent.sac]\ninit_alpha = 0.5\n[train]\nepisodes = 7\n";
    let p = Preset::from_toml_str(text, Path::new("t.toml")).unwrap();
    let runs = p.runs();
    let names: Vec<&str> = runs.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(
        names,
        ["sac-basic-her-future-seed1", "sac-sar-seed1", "redq-basic-her-future-seed1", "redq-sar-seed1"]
    );
    assert_eq!(runs.iter().map(|r| r.index).collect::<Vec<_>>(), [0, 1, 2, 3]);
    for r in &runs {
        r.config.validate().unwrap();
        // The preset's settings reach every run; the variant's only its own, over them.
        assert_eq!((r.config.agent.gamma, r.config.agent.sac().init_alpha), (0.9, 0.5), "{}", r.name);
        let redq = r.name.starts_with("redq");
        assert_eq!(r.config.agent.updates_per_step, if redq { 3 } else { 1 }, "{}", r.name);
        assert_eq!(r.config.agent.sac().n_critics, if redq { 5 } else { 2 }, "{}", r.name);
        assert_eq!(r.config.agent.sac().critic_subset, redq.then_some(2), "{}", r.name);
        assert_eq!(r.config.agent.algo, Algo::Sac);
    }
    // Errors name the field.
    let cases = [
        (text.replace("name = \"redq\"", "name = \"sac\""), "sweep.variants[0].name"),
        (text.replace("name = \"redq\"", "name = \"../x\""), "sweep.variants[0].name"),
        (text.replace("algorithm = \"sac\"\n", "algorithm = \"td3\"\n"), "sweep.variants[0].algorithm"),
        (text.replace("n_critics = 5", "n_critics = 500"), "agent.sac.n_critics"),
        (text.replace("updates_per_step = 3", "algo = \"td3\""), "sweep.variants[0].agent.algo"),
        (text.replace("{ algorithm = \"ddpg\" }", "{ algorithm = \"droq\" }"), "sweep.exclude[2]"),
        (text.replace("{ algorithm = \"ddpg\" }", "{}"), "sweep.exclude[2]"),
        (text.replace("{ algorithm = \"ddpg\" }", "{ seed = 1 }"), "seed"),
    ];
    for (t, needle) in cases {
        let e = Preset::from_toml_str(&t, Path::new("t.toml")).unwrap_err().to_string();
        assert!(e.contains(needle), "{needle}: {e}");
    }
}

/// Every file of `configs/` (presets, studies), a preset (bundled or run by path) or a config (`--config`),
/// parses, and each config validates, so that a documented command never meets a config error.
#[test]
fn every_config_file_parses() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs");
    let mut paths = Vec::new();
    for dir in ["presets", "studies", "studies/pilot-ddpg"] {
        paths.extend(std::fs::read_dir(root.join(dir)).unwrap().map(|e| e.unwrap().path()));
    }
    let mut seen = 0;
    for path in paths {
        if path.extension().is_some_and(|e| e == "toml") {
            let text = std::fs::read_to_string(&path).unwrap();
            seen += 1;
            if !text.contains("[sweep]") {
                let c = crate::config::Config::from_toml_str(&text, &path);
                c.and_then(|c| c.validate()).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                continue;
            }
            let p = Preset::from_toml_str(&text, &path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert!(!p.runs().is_empty(), "{}", path.display());
            for r in p.runs() {
                r.config.validate().unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            }
        }
    }
    assert!(seen >= 25, "{seen} config files under {}", root.display());
}

#[test]
fn bundled_presets_parse() {
    let issue_36 = ["sample-efficiency", "crossq-rewards"];
    for (name, _) in
        BUNDLED_PRESETS.iter().filter(|(n, _)| !n.starts_with("learners") && !issue_36.contains(n))
    {
        let (p, _) = Preset::resolve(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(p.sweep.algorithms, vec![Algo::Ddpg, Algo::Sac], "{name}");
        // The paper's presets cover its five rewards.
        assert_eq!(p.sweep.rewards.len(), 5, "{name}");
    }
    // DDPG and SAC with and without HER, PPO once: 2 x 3 x 2 x 3 + 3 x 3.
    let (learners, _) = Preset::resolve("learners").unwrap();
    assert_eq!((learners.runs().len(), learners.base.train.episodes), (45, 5000));
    assert!(learners
        .runs()
        .iter()
        .all(|r| r.config.agent.algo.is_off_policy() || r.config.agent.her.is_none()));
    let (long, _) = Preset::resolve("learners-long").unwrap();
    assert_eq!((long.runs().len(), long.base.train.episodes), (6, 30000));
    // Issue 36: SAC, DroQ, REDQ and CrossQ on SAR and on basic + HER, 5 seeds, 30 000 env steps.
    let (se, _) = Preset::resolve("sample-efficiency").unwrap();
    let runs = se.runs();
    assert_eq!(runs.len(), 4 * 2 * 5);
    for r in &runs {
        assert_eq!(r.config.train.env_steps, Some(30_000), "{}", r.name);
        assert_eq!(
            r.config.agent.her.is_some(),
            r.config.reward.function == RewardFunction::Basic,
            "{}",
            r.name
        );
    }
    let droq = runs.iter().find(|r| r.name == "droq-sar-seed1").unwrap();
    assert_eq!((droq.config.agent.updates_per_step, droq.config.agent.sac().critic_layer_norm), (20, true));
    assert_eq!(droq.config.agent.sac().policy_delay, 20);
    let redq = runs.iter().find(|r| r.name == "redq-basic-her-future-seed5").unwrap();
    assert_eq!((redq.config.agent.sac().n_critics, redq.config.agent.sac().critic_subset), (10, Some(2)));
    let (cr, _) = Preset::resolve("crossq-rewards").unwrap();
    assert_eq!(cr.runs().len(), 5 * 5);
    assert!(cr
        .runs()
        .iter()
        .all(|r| r.config.agent.algo == Algo::Crossq && r.config.train.env_steps == Some(30_000)));
    let (paper, _) = Preset::resolve("paper").unwrap();
    assert_eq!(
        (paper.sweep.seeds.len(), paper.base.train.episodes, paper.sweep.eval_trials),
        (20, 10000, 500)
    );
    assert_eq!(paper.base.task.max_steps, 50);
    // The paper regime, named: gamma 0.99 and unscaled observations (the check that the values
    // are the regime's is below).
    assert_eq!(paper.sweep.regime, Some(crate::report::reference::Regime::Paper));
    // The tuned regime: the library's defaults at 10 seeds x 5000 episodes.
    let (tuned, _) = Preset::resolve("tuned").unwrap();
    assert_eq!((tuned.sweep.seeds.len(), tuned.base.train.episodes), (10, 5000));
    let d = Config::default();
    assert_eq!(
        (tuned.base.agent.gamma, tuned.base.task.obs_delta_scale),
        (d.agent.gamma, d.task.obs_delta_scale)
    );
}

#[test]
fn a_named_regime_must_be_the_presets_settings() {
    let named = |regime: &str, rest: &str| {
        let text =
            PRESET.replace("eval_trials = 20\n", &format!("eval_trials = 20\nregime = \"{regime}\"\n"));
        Preset::from_toml_str(&format!("{text}{rest}"), Path::new("p.toml"))
    };
    // The defaults are the tuned regime's settings; the paper regime needs its own.
    assert_eq!(named("tuned", "").unwrap().sweep.regime, Some(crate::report::reference::Regime::Tuned));
    let e = named("paper", "").unwrap_err().to_string();
    assert!(e.contains("agent.gamma") && e.contains("0.99") && e.contains("sweep.regime"), "{e}");
    let e = named("paper", "[agent]\ngamma = 0.99\n").unwrap_err().to_string();
    assert!(e.contains("task.obs_delta_scale"), "{e}");
    assert!(named("paper", "[agent]\ngamma = 0.99\n[task]\nobs_delta_scale = 1.0\n").is_ok());
    assert!(named("custom", "[agent]\ngamma = 0.9\n").is_ok());
    assert!(named("fast", "").is_err(), "an unknown regime");
    // Every bundled preset's regime holds (each constructor checks it).
    for name in [
        "paper",
        "tuned",
        "quick",
        "smoke",
        "learners",
        "learners-long",
        "sample-efficiency",
        "crossq-rewards",
    ] {
        Preset::resolve(name).unwrap();
    }
}
