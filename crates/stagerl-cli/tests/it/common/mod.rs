//! Helpers shared by the CLI integration tests.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

/// The `stagerl` binary under test.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_stagerl"))
}

/// A fresh, empty scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("stagerl-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A run's episodes.csv without the wall-time column (the only one allowed to differ).
pub fn episodes_without_wall(dir: &Path) -> Vec<String> {
    std::fs::read_to_string(dir.join("episodes.csv"))
        .unwrap()
        .lines()
        .map(|l| l.rsplit_once(',').unwrap().0.to_string())
        .collect()
}

/// Run `stagerl args` to completion with no input.
pub fn run(args: &[&str]) -> Output {
    bin().args(args).env("RUST_BACKTRACE", "0").stdin(Stdio::null()).output().unwrap()
}

/// Start `cmd` with its three standard streams piped (and no backtraces).
pub fn spawn_piped(cmd: &mut Command) -> Child {
    cmd.env("RUST_BACKTRACE", "0")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn")
}

/// Write `input` to a child's piped stdin, then wait for it: a command that refuses its
/// arguments or its first line exits without reading the rest, and the pipe it leaves broken is
/// its answer, not the test's error (any other write error is).
pub fn feed(mut child: Child, input: &str) -> Output {
    use std::io::Write;
    match child.stdin.take().unwrap().write_all(input.as_bytes()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {}
        r => r.unwrap(),
    }
    child.wait_with_output().unwrap()
}

/// Run `stagerl args` with its standard output opened by the shell redirection `redirect`
/// (`>/dev/full`, `>&-`, ...), `stdin` on standard input.
pub fn redirected(args: &[&str], redirect: &str, stdin: &str) -> Output {
    let script = format!("exec \"$0\" \"$@\" {redirect}");
    let mut sh = Command::new("sh");
    sh.arg("-c").arg(script).arg(env!("CARGO_BIN_EXE_stagerl")).args(args);
    feed(spawn_piped(&mut sh), stdin)
}

/// Every file and directory under `dir`, with the files' bytes; but the run directories' lock
/// files (`.stagerl.lock`), which any process taking a run rewrites with its pid (bookkeeping of
/// the lock, not a result of the run).
pub fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Option<Vec<u8>>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.file_name().is_some_and(|n| n == stagerl::run::dir::LOCK_FILE) {
                continue;
            }
            let link = std::fs::symlink_metadata(&p).unwrap().file_type().is_symlink();
            if link {
                // Its target's name, not its contents (it may point at /dev/zero).
                let target = std::fs::read_link(&p).unwrap();
                out.insert(p.clone(), Some(target.to_string_lossy().as_bytes().to_vec()));
            } else if p.is_dir() {
                out.insert(p.clone(), None);
                stack.push(p);
            } else {
                out.insert(p.clone(), Some(std::fs::read(&p).unwrap()));
            }
        }
    }
    out
}

/// Assert that run `cut` (stopped and resumed) ended as the uninterrupted run `full`: the same
/// `episodes.csv` but wall time (`episodes` rows and a header), `eval.csv` (`evals` rows and a
/// header) and final checkpoint. `what` describes the stops for the messages.
pub fn assert_same_run(full: &Path, cut: &Path, episodes: usize, evals: usize, what: &str) {
    assert_eq!(episodes_without_wall(full).len(), episodes + 1);
    assert_eq!(
        episodes_without_wall(full),
        episodes_without_wall(cut),
        "episodes.csv (but wall time) differs {what}"
    );
    let eval = |d: &Path| std::fs::read_to_string(d.join("eval.csv")).unwrap();
    assert_eq!(eval(full).lines().count(), evals + 1);
    assert_eq!(eval(full), eval(cut), "eval.csv differs {what}");
    let ck = |d: &Path| {
        stagerl::io::checkpoint::Checkpoint::load(&d.join("checkpoints/final.safetensors")).unwrap()
    };
    let (a, b) = (ck(full), ck(cut));
    assert!(a.tensor_names().count() > 15);
    assert!(a.same_contents(&b), "final networks or metadata differ {what}");
}

/// Every scalar of a run's TensorBoard event files (`tb/`), as `(tag, step, value)`, files in
/// name order.
pub fn tb_scalars(dir: &Path) -> Vec<(String, i64, f32)> {
    let mut files: Vec<PathBuf> =
        std::fs::read_dir(dir.join("tb")).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    files.iter().flat_map(|f| stagerl::io::tensorboard::read_scalars(f).unwrap()).collect()
}

/// Panics unless every tag of `scalars` has the steps `1..=n` exactly once each (`eval/` tags:
/// the multiples of `eval_every` and `n`).
pub fn assert_steps_once(scalars: &[(String, i64, f32)], n: i64, eval_every: i64, what: &str) {
    let mut by_tag: std::collections::BTreeMap<&str, Vec<i64>> = Default::default();
    for (tag, step, _) in scalars {
        by_tag.entry(tag.as_str()).or_default().push(*step);
    }
    assert!(by_tag.contains_key("train/episode_reward"), "{what}: no train/episode_reward");
    for (tag, mut steps) in by_tag {
        steps.sort_unstable();
        let expect: Vec<i64> = if tag.starts_with("eval/") {
            (1..=n).filter(|s| s % eval_every == 0 || *s == n).collect()
        } else if tag.starts_with("train/") {
            (1..=n).collect()
        } else {
            // Losses start with learning: a contiguous range ending at n.
            let first = *steps.first().unwrap();
            (first..=n).collect()
        };
        assert_eq!(steps, expect, "{what}: steps of {tag}");
    }
}

/// The data of a view page (`stagerl view`, `plan --view`): the JSON in its data script.
pub fn view_data(html: &str) -> serde_json::Value {
    let tag = "type=\"application/json\">";
    let start = html.find(tag).unwrap() + tag.len();
    let end = start + html[start..].find("</script>").unwrap();
    serde_json::from_str(&html[start..end]).unwrap()
}
