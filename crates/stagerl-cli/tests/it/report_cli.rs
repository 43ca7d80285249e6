//! `stagerl report` on small runs made by `stagerl train`.

use std::path::Path;
use std::process::{Command, Output};

fn stagerl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_stagerl")).args(args).output().expect("spawn stagerl")
}

fn ok(out: &Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "stdout: {stdout}\nstderr: {}", String::from_utf8_lossy(&out.stderr));
    stdout
}

fn is_png(path: &Path) -> bool {
    std::fs::read(path).map(|b| b.len() > 100 && b.starts_with(b"\x89PNG\r\n\x1a\n")).unwrap_or(false)
}

#[test]
fn report_on_trained_runs() {
    let root = std::env::temp_dir().join(format!("stagerl-cli-report-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let runs = root.join("runs");
    std::fs::create_dir_all(&runs).unwrap();
    let cfg = root.join("small.toml");
    std::fs::write(
        &cfg,
        "[agent]\nhidden = [16, 16]\nlearning_starts = 100\n[train]\neval_every_episodes = 10\neval_trials = 5\n",
    )
    .unwrap();
    for (algo, reward) in [("sac", "sar"), ("sac", "posture")] {
        let out = runs.join(format!("{algo}-{reward}-s1"));
        ok(&stagerl(&[
            "train",
            "--config",
            cfg.to_str().unwrap(),
            "--algo",
            algo,
            "--reward",
            reward,
            "--seed",
            "1",
            "--episodes",
            "30",
            "--eval-trials",
            "10",
            "--out",
            out.to_str().unwrap(),
        ]));
    }
    let text = ok(&stagerl(&["report", runs.to_str().unwrap(), "--trajectories", "3"]));
    assert!(text.contains("2 run(s) in 2 group(s)"), "{text}");
    let out = runs.join("report");
    for name in [
        "table1.md",
        "table1.csv",
        "table1.json",
        "claims.md",
        "figure7.svg",
        "figure8.svg",
        "trajectories.csv",
    ] {
        assert!(std::fs::metadata(out.join(name)).map(|m| m.len() > 0).unwrap_or(false), "{name}");
    }
    for name in ["figure7.png", "figure8.png", "trajectories.png"] {
        assert!(is_png(&out.join(name)), "{name}");
    }
    // Paths in the outputs are relative (to the output directory for the files written, to the
    // input directory for the checkpoints rolled out); only provenance.json's commands, as typed,
    // may name the machine's directories.
    for entry in std::fs::read_dir(&out).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if name.ends_with(".png") || name == "provenance.json" {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(!text.contains(root.to_str().unwrap()), "{name} names {}", root.display());
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table1.json")).unwrap()).unwrap();
    assert!(json["files"].as_array().unwrap().iter().any(|f| f == "table1.md"), "{}", json["files"]);
    let ckpt = json["trajectories"][0]["checkpoint"].as_str().unwrap();
    assert!(runs.join(ckpt).is_file() && ckpt.starts_with("sac-"), "{ckpt}");
    // Provenance: the report's own command, the code it was built from (a git commit), times.
    let prov: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("provenance.json")).unwrap()).unwrap();
    let session = prov["sessions"].as_array().unwrap().last().unwrap().clone();
    assert_eq!(session["command"][1], "report", "{session}");
    assert_eq!(session["code"]["git_commit"].as_str().map(str::len), Some(40), "{session}");
    assert!(session["start"].as_str().unwrap().ends_with('Z') && session["wall_s"].as_f64().unwrap() > 0.0);
    let md = std::fs::read_to_string(out.join("table1.md")).unwrap();
    assert!(md.contains("## Provenance") && md.contains("has no `provenance.json`"), "{md}");
    // 30 episodes are too few for the default criterion (W = 100): reported, not an error.
    let md = std::fs::read_to_string(out.join("table1.md")).unwrap();
    assert!(md.contains("run too short"), "{md}");
    assert!(md.contains("| SAC | SAR | ours | 1 (0 conv.) | 30 | did not converge |"), "{md}");
    // Evaluation columns come from the 10 closing trials.
    assert!(md.contains("of 10 |"), "{md}");
    // Trajectories: 3 trials each for the best and the worst reward function, from the home pose.
    let traj = std::fs::read_to_string(out.join("trajectories.csv")).unwrap();
    let runs_drawn: std::collections::BTreeSet<&str> =
        traj.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
    assert_eq!(runs_drawn.len(), 2, "{runs_drawn:?}");
    let starts: Vec<&str> = traj.lines().filter(|l| l.split(',').nth(2) == Some("0")).collect();
    assert_eq!(starts.len(), 6, "{traj}");
    // The same trials as animated 3D views: the targets of trajectories.csv, in order.
    let csv_targets: Vec<Vec<String>> =
        starts.iter().map(|l| l.split(',').skip(6).take(3).map(String::from).collect()).collect();
    let mut view_targets = Vec::new();
    for role in ["best", "worst"] {
        let html = std::fs::read_to_string(out.join(format!("view-{role}.html"))).unwrap();
        let start = html.find("application/json\">").unwrap() + "application/json\">".len();
        let end = start + html[start..].find("</script>").unwrap();
        let data: serde_json::Value = serde_json::from_str(&html[start..end]).unwrap();
        assert!(data["title"].as_str().unwrap().starts_with(role), "{}", data["title"]);
        for t in data["trajectories"].as_array().unwrap() {
            view_targets.push(
                t["target"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap().to_string())
                    .collect::<Vec<_>>(),
            );
        }
    }
    assert_eq!(view_targets, csv_targets);

    // A smaller window lets the criterion run; a bad criterion is an error naming the option.
    ok(&stagerl(&[
        "report",
        runs.to_str().unwrap(),
        "--window",
        "5",
        "--out",
        root.join("r2").to_str().unwrap(),
    ]));
    let bad = stagerl(&[
        "report",
        runs.to_str().unwrap(),
        "--tail-fraction",
        "2",
        "--out",
        root.join("r3").to_str().unwrap(),
    ]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("tail_fraction"));
    let missing = stagerl(&["report", root.join("nope").to_str().unwrap()]);
    assert!(!missing.status.success());
    assert!(String::from_utf8_lossy(&missing.stderr).contains("nope"));

    // A non-UTF-8 output path is refused before any file is written.
    {
        use std::os::unix::ffi::OsStrExt;
        let bad_out = root.join(std::ffi::OsStr::from_bytes(b"out-\xff\xfe"));
        let r = Command::new(env!("CARGO_BIN_EXE_stagerl"))
            .arg("report")
            .arg(&runs)
            .arg("--out")
            .arg(&bad_out)
            .output()
            .unwrap();
        assert_eq!(r.status.code(), Some(1));
        assert!(String::from_utf8_lossy(&r.stderr).contains("is not valid UTF-8"), "{r:?}");
        assert!(!bad_out.exists());
    }
    // So are too many trajectories, and a directory without runs.
    let many = stagerl(&["report", runs.to_str().unwrap(), "--trajectories", "4294967295"]);
    assert_eq!(many.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&many.stderr).contains("--trajectories"));
    let empty = root.join("no-runs");
    std::fs::create_dir_all(&empty).unwrap();
    let r = stagerl(&["report", empty.to_str().unwrap()]);
    assert_eq!(r.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&r.stderr).contains("no runs to report on"));
    assert!(!empty.join("report").exists());
    std::fs::remove_dir_all(&root).ok();
}

/// The committed reports regenerate from the committed runs: `stagerl report` on a study's
/// packed runs (`docs/results/STUDY/runs.tar.xz`) writes the committed `table1.md` (but the line
/// naming the version that wrote it), `claims.md` and `aggregates.md`, byte for byte. `learners`
/// holds two sweeps (folders of runs one level deeper) and its logs store `env_steps` as
/// differences (`env_steps:diff`).
#[test]
fn the_committed_reports_regenerate_from_the_committed_runs() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    // crossq-rewards, sample-efficiency, obstacle-her and obstacle-shield were reported without
    // trajectories (their archives hold no checkpoint).
    for (study, regime, trajectories) in [
        ("quick", "tuned regime", "5"),
        ("tuned", "tuned regime", "5"),
        ("quick-dynamic", "tuned regime", "5"),
        ("paper", "paper regime", "5"),
        ("learners", "tuned regime", "5"),
        ("crossq-rewards", "tuned regime", "0"),
        ("sample-efficiency", "tuned regime", "0"),
        ("obstacle-her", "custom settings", "0"),
        ("obstacle-shield", "custom settings", "0"),
    ] {
        let dir = root.join("docs/results").join(study);
        let out = crate::common::scratch(&format!("regenerate-{study}"));
        let archive = dir.join("runs.tar.xz");
        let args = [
            "report",
            archive.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--trajectories",
            trajectories,
        ];
        ok(&stagerl(&args));
        let text = |p: &Path| std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        for name in ["claims.md", "aggregates.md", "table1.md"] {
            let (ours, committed) = (text(&out.join(name)), text(&dir.join(name)));
            let keep = |t: &str| {
                t.lines().filter(|l| !l.starts_with("This report: `")).map(str::to_owned).collect::<Vec<_>>()
            };
            if name != "aggregates.md" {
                assert!(ours.contains(regime), "{study}/{name}: the regime the preset names");
                // Named by the archive it was read from, not by the folder inside it.
                assert!(
                    ours.contains(&format!("Study `{study}/runs.tar.xz`")),
                    "{study}/{name}: the study's name"
                );
            }
            assert_eq!(keep(&ours), keep(&committed), "{study}/{name} differs from the committed one");
        }
        std::fs::remove_dir_all(&out).ok();
    }
}

/// A preset with a variant of SAC (REDQ) and a budget of environment steps: the variant's runs
/// are named after it, Table 1 has a REDQ row of its own beside SAC's, and the report adds the
/// steps to 95 % success (`sample_efficiency.md`, `table1.json`'s `sample_efficiency`).
#[test]
fn a_sweep_with_a_variant_on_a_step_budget_reports_each_method() {
    let root = std::env::temp_dir().join(format!("stagerl-cli-report-variants-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    let preset = root.join("p.toml");
    std::fs::write(
        &preset,
        "[sweep]\nalgorithms = [\"sac\"]\nrewards = [\"sar\"]\nseeds = [1, 2]\neval_trials = 5\n\
         [[sweep.variants]]\nname = \"redq\"\nalgorithm = \"sac\"\n\
         [sweep.variants.agent]\nupdates_per_step = 2\n[sweep.variants.agent.sac]\nn_critics = 3\ncritic_subset = 2\n\
         [agent]\nhidden = [16, 16]\nlearning_starts = 100\n\
         [train]\nenv_steps = 400\neval_every_env_steps = 200\neval_trials = 4\n",
    )
    .unwrap();
    let sweep = root.join("sweep");
    ok(&stagerl(&["reproduce", "--preset", preset.to_str().unwrap(), "--out", sweep.to_str().unwrap()]));
    for name in ["sac-sar-seed1", "sac-sar-seed2", "redq-sar-seed1", "redq-sar-seed2"] {
        assert!(sweep.join(name).join("eval.csv").is_file(), "{name}");
    }
    let text = ok(&stagerl(&["report", sweep.to_str().unwrap(), "--trajectories", "0"]));
    assert!(text.contains("4 run(s) in 2 group(s)"), "{text}");
    let out = sweep.join("report");
    let table = std::fs::read_to_string(out.join("table1.md")).unwrap();
    assert!(table.contains("| SAC | SAR | ours | 2 "), "{table}");
    assert!(table.contains("| REDQ | SAR | ours | 2 "), "{table}");
    assert!(!table.contains("## Other configurations"), "{table}");
    let se = std::fs::read_to_string(out.join("sample_efficiency.md")).unwrap();
    for needle in ["| SAC | SAR |", "| REDQ | SAR |", "- REDQ + SAR: "] {
        assert!(se.contains(needle), "{needle}: {se}");
    }
    // Figure 8 is drawn against the environment steps, one panel column per method.
    let fig8 = std::fs::read_to_string(out.join("figure8.svg")).unwrap();
    assert!(fig8.contains("environment steps") && fig8.contains("REDQ — success rate"), "figure8.svg");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table1.json")).unwrap()).unwrap();
    let rows = json["sample_efficiency"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[1]["method"], "redq");
    // Each seed's evaluations are at 200 and 400 steps or just past them (at most an episode).
    for r in rows {
        assert_eq!(r["budget"], 400);
        assert_eq!(r["steps_to_threshold"].as_array().unwrap().len(), 2);
        let end = r["success_end"][0].as_u64().unwrap();
        assert!((400..450).contains(&end), "{r}");
    }
    let _ = std::fs::remove_dir_all(&root);
}
