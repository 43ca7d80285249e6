//! `STAGERL_SIMD` caps the instruction set: a run trained at every level this CPU has gives the
//! same bits (episodes, evaluations and checkpoints), the timings say the level they ran at, and
//! a value that is not a level is refused, naming the variable.

use crate::common::{bin, scratch};
use std::path::Path;

/// The run's files a result depends on: `episodes.csv` without its wall-time column, every
/// other CSV, the `best` and `final` checkpoints (`latest` holds the training's wall time too).
fn fingerprint(run: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    for dir in [run.to_path_buf(), run.join("checkpoints")] {
        let mut names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
        names.sort();
        for p in names.into_iter().filter(|p| p.is_file()) {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if name.ends_with(".csv") || name == "best.safetensors" || name == "final.safetensors" {
                let bytes = std::fs::read(&p).unwrap();
                let bytes = if name == "episodes.csv" {
                    let text = String::from_utf8(bytes).unwrap();
                    let head = text.lines().next().unwrap().split(',').position(|c| c == "wall_s").unwrap();
                    let rows = text.lines().map(|l| {
                        let mut cells: Vec<&str> = l.split(',').collect();
                        cells.remove(head);
                        cells.join(",")
                    });
                    rows.collect::<Vec<_>>().join("\n").into_bytes()
                } else {
                    bytes
                };
                files.push((name, bytes));
            }
        }
    }
    files
}

#[test]
fn every_simd_level_trains_the_same_bits_and_a_bad_level_is_refused() {
    let dir = scratch("simd-levels");
    let config = dir.join("small.toml");
    std::fs::write(
        &config,
        "[agent]\nhidden = [16, 16]\nbatch_size = 32\nlearning_starts = 100\n[train]\nepisodes = 6\neval_trials = 5\n",
    )
    .unwrap();
    let train = |level: Option<&str>| {
        let out_dir = dir.join(level.unwrap_or("detected"));
        let mut cmd = bin();
        cmd.args([
            "train",
            "--config",
            config.to_str().unwrap(),
            "--seed",
            "3",
            "--out",
            out_dir.to_str().unwrap(),
        ]);
        match level {
            Some(l) => cmd.env("STAGERL_SIMD", l),
            None => cmd.env_remove("STAGERL_SIMD"),
        };
        let out = cmd.output().unwrap();
        assert!(out.status.success(), "{level:?}: {}", String::from_utf8_lossy(&out.stderr));
        fingerprint(&out_dir)
    };
    let detected = train(None);
    assert!(
        detected.iter().any(|(n, _)| n == "best.safetensors") && detected.len() >= 4,
        "{:?}",
        detected.len()
    );
    // Levels the CPU lacks run at its own (the cap only narrows), so every name is tried.
    for level in ["avx512", "avx2", "baseline"] {
        assert!(train(Some(level)) == detected, "STAGERL_SIMD={level} trained other bits");
    }
    // The timings say where they ran.
    let out = bin()
        .args(["bench", "update", "--hidden", "16", "--updates", "3"])
        .env("STAGERL_SIMD", "baseline")
        .output()
        .unwrap();
    assert!(out.status.success() && String::from_utf8_lossy(&out.stdout).contains("\"simd\":\"baseline\""));
    let out = bin().args(["bench", "update", "--updates", "1"]).env("STAGERL_SIMD", "avx3").output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("STAGERL_SIMD") && err.contains("avx512, avx2, baseline"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
