//! Records the git commit the library is built from, and whether the work tree had changes, as
//! `STAGERL_GIT_COMMIT` and `STAGERL_GIT_DIRTY` (empty when not built from a git checkout), for
//! the provenance of results (`stagerl::run::provenance`).

use std::path::Path;
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    // Any change to the sources, presets or assets may change the dirty flag.
    for dir in ["../../crates", "../../configs", "../../assets", "../../Cargo.toml"] {
        println!("cargo:rerun-if-changed={dir}");
    }
    println!("cargo:rerun-if-changed=build.rs");
    let commit = git(&["rev-parse", "HEAD"]).unwrap_or_default();
    let dirty = if commit.is_empty() {
        String::new()
    } else {
        // Tracked files changed (untracked files do not make a build dirty).
        git(&["status", "--porcelain", "--untracked-files=no"])
            .map(|s| (!s.is_empty()).to_string())
            .unwrap_or_default()
    };
    // Build again when HEAD moves or the index changes (a commit, a checkout, a staged edit).
    for p in ["HEAD", "index", "packed-refs"] {
        if let Some(path) = git(&["rev-parse", "--git-path", p]) {
            if Path::new(&path).exists() {
                println!("cargo:rerun-if-changed={path}");
            }
        }
    }
    if let Some(head_ref) = git(&["symbolic-ref", "-q", "HEAD"]) {
        if let Some(path) = git(&["rev-parse", "--git-path", &head_ref]) {
            if Path::new(&path).exists() {
                println!("cargo:rerun-if-changed={path}");
            }
        }
    }
    println!("cargo:rustc-env=STAGERL_GIT_COMMIT={commit}");
    println!("cargo:rustc-env=STAGERL_GIT_DIRTY={dirty}");
}
