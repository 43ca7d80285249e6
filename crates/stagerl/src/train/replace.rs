//! Replacing a run: a new run in a directory that held an older one (`train --force`, or a run
//! restarted because it was killed before its first checkpoint) first removes everything the
//! older run wrote, so that nothing of it (an evaluation, TensorBoard events, a checkpoint) is
//! read as the new run's.
//!
//! What is removed: `config.toml`, `episodes.csv`, `eval.csv`, the evaluations (`eval-*.csv` and
//! their `eval-*.json` records, from `train`, `reproduce` and `eval`), the checkpoints
//! (`checkpoints/{latest,final,best}.safetensors`), the TensorBoard event files in `tb/`, and
//! stale temporary files of atomic writes. Anything else (files of the user's, a `report/`
//! directory) is left alone: the directory's other contents are not the run's to delete.

use std::path::PathBuf;

use super::RunDir;
use crate::{Error, Result};

/// Whether `name` (in the run's root) is an evaluation file a run writes.
fn is_evaluation(name: &str) -> bool {
    name.starts_with("eval-") && (name.ends_with(".csv") || name.ends_with(".json"))
}

/// Remove the files of an older run from `dir` (see the module docs); returns what was removed,
/// relative to the run directory.
pub fn remove_previous_run(dir: &RunDir) -> Result<Vec<PathBuf>> {
    let mut doomed: Vec<PathBuf> =
        vec![dir.config(), dir.episodes(), dir.eval(), dir.latest(), dir.final_checkpoint(), dir.best()];
    if let Ok(entries) = std::fs::read_dir(&dir.root) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if is_evaluation(&name) && e.file_type().is_ok_and(|t| t.is_file()) {
                doomed.push(e.path());
            }
        }
    }
    doomed.extend(crate::io::tensorboard::event_files(&dir.tb())?);
    let mut removed = Vec::new();
    for p in doomed {
        match std::fs::remove_file(&p) {
            Ok(()) => removed.push(p),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(Error::io(&p, e)),
        }
    }
    for d in dir.written_dirs() {
        removed.extend(crate::io::remove_stale_temps(&d)?);
    }
    removed.sort();
    Ok(removed.iter().map(|p| p.strip_prefix(&dir.root).unwrap_or(p).to_path_buf()).collect())
}

/// A short list of removed files for a message: `n files (a, b, c, ...)`.
pub fn describe(removed: &[PathBuf]) -> String {
    const SHOWN: usize = 8;
    let names: Vec<String> = removed.iter().take(SHOWN).map(|p| p.display().to_string()).collect();
    let more =
        if removed.len() > SHOWN { format!(", and {} more", removed.len() - SHOWN) } else { String::new() };
    format!("{} file(s) ({}{more})", removed.len(), names.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn removes_the_runs_files_and_leaves_the_users() {
        let root = std::env::temp_dir().join(format!("stagerl-replace-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let dir = RunDir::new(&root);
        for sub in ["checkpoints", "tb", "report"] {
            std::fs::create_dir_all(root.join(sub)).unwrap();
        }
        let runs = [
            "config.toml",
            "episodes.csv",
            "eval.csv",
            "eval-seed0.csv",
            "eval-final-seed0.csv",
            "eval-final-seed0.json",
            "eval-best-trials5-seed3.csv",
            "checkpoints/latest.safetensors",
            "checkpoints/best.safetensors",
            "tb/events.out.tfevents.1.h.2",
            "tb/events.out.tfevents.3.h.4",
            "checkpoints/latest.safetensors.tmp-77",
        ];
        let users =
            ["notes.md", "eval-notes.txt", "report/table1.md", "checkpoints/mine.safetensors", "tb/README"];
        for f in runs.iter().chain(&users) {
            std::fs::write(root.join(f), b"x").unwrap();
        }
        let removed = remove_previous_run(&dir).unwrap();
        let mut want: Vec<PathBuf> = runs.iter().map(PathBuf::from).collect();
        want.sort();
        assert_eq!(removed, want);
        for f in users {
            assert!(root.join(f).exists(), "{f} removed");
        }
        assert!(describe(&removed).starts_with("12 file(s) (checkpoints/best.safetensors, "));
        assert!(describe(&removed).ends_with(", and 4 more)"));
        assert!(remove_previous_run(&dir).unwrap().is_empty());
        std::fs::remove_dir_all(&root).unwrap();
    }
}
