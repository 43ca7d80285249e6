//! Outputs and inputs that are not regular files, with real processes: a FIFO (and a process
//! substitution's `/dev/fd/N`) as `--out`/`--view`/`--checkpoint` is refused at once, never
//! opened (which would hang) nor read; and the temporary files of a killed export are removed by
//! the next one (those of a live process are not).

use crate::common;

use common::{bin, scratch};
use stagerl::agent::Algo;
use stagerl::config::Config;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};

/// Wait for `child`; one that has not ended after a generous while is hung (the failure these
/// tests are about): it is killed and the test fails, instead of hanging the test run.
fn finish(mut child: Child, what: &str) -> Output {
    for _ in 0..1200 {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let _ = child.kill();
    let _ = child.wait();
    panic!("{what}: still running after 120 s (blocked on a FIFO?)");
}

fn spawn(cmd: &mut Command) -> Child {
    cmd.env("RUST_BACKTRACE", "0")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn mkfifo(p: &Path) {
    let ok = Command::new("mkfifo").arg(p).status().unwrap();
    assert!(ok.success(), "mkfifo {}", p.display());
}

fn is_fifo(p: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    std::fs::symlink_metadata(p).is_ok_and(|m| m.file_type().is_fifo())
}

fn small_run(dir: &Path) {
    let mut cfg = Config::default();
    cfg.agent.algo = Algo::Sac;
    cfg.agent.hidden = vec![8, 8];
    cfg.agent.batch_size = 8;
    cfg.agent.buffer_size = 1000;
    cfg.agent.learning_starts = 30;
    cfg.train.episodes = 2;
    cfg.train.eval_every_episodes = 0;
    cfg.train.checkpoint_every_episodes = 1;
    stagerl::train::train(&cfg, dir, |_| {}).unwrap();
}

#[test]
fn a_fifo_as_output_or_checkpoint_is_refused_without_blocking() {
    let dir = scratch("fifo");
    let run = dir.join("run");
    small_run(&run);
    let fifo = dir.join("out.fifo");
    mkfifo(&fifo);
    let (r, f) = (run.to_str().unwrap(), fifo.to_str().unwrap());
    let cases: [(&[&str], &str); 5] = [
        (&["export", "--run", r, "--out", f, "--force"], "is a FIFO (named pipe), not a regular file"),
        (&["view", "--run", r, "--targets", "1", "--out", f], "is a FIFO (named pipe), not a regular file"),
        (
            &["plan", "--controller", "jacobian", "--target", "0.4,0.2,0.3", "--view", f],
            "is a FIFO (named pipe), not a regular file",
        ),
        (
            &["export", "--run", r, "--checkpoint", f, "--out", "/nonexistent-dir/p.onnx"],
            "is a FIFO (named pipe); a checkpoint must be a regular file",
        ),
        (&["eval", "--run", r, "--checkpoint", f, "--trials", "1"], "a checkpoint must be a regular file"),
    ];
    for (args, expect) in cases {
        let what = format!("stagerl {}", args.join(" "));
        let out = finish(spawn(bin().args(args)), &what);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{what}: {err}");
        assert!(err.contains(expect) && err.contains("out.fifo"), "{what}: {err}");
        assert!(is_fifo(&fifo), "{what}: the FIFO was replaced");
    }
    // A process substitution, `--view >(cat)`: /dev/fd/N, a pipe.
    let script = format!(
        "exec {} plan --controller jacobian --target 0.4,0.2,0.3 --view >(cat > /dev/null)",
        env!("CARGO_BIN_EXE_stagerl")
    );
    let out = finish(spawn(Command::new("bash").args(["-c", &script])), "--view >(cat)");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("/dev/fd/") && err.contains("not a regular file"), "{err}");
    // Nothing was left beside the outputs.
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.contains(".tmp-")), "{names:?}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_temporary_files_of_a_killed_export_are_removed_by_the_next_one() {
    let dir = scratch("stale-export");
    let run = dir.join("run");
    small_run(&run);
    // A real process, killed: its pid is that of a dead writer.
    let mut victim = Command::new("sleep").arg("60").spawn().unwrap();
    let dead = victim.id();
    victim.kill().unwrap();
    victim.wait().unwrap();
    let live = std::process::id();
    let model = dir.join("policy.onnx");
    let stale = dir.join(format!("policy.onnx.tmp-{dead}"));
    let of_live = dir.join(format!("policy.onnx.tmp-{live}"));
    let of_other = dir.join(format!("other.onnx.tmp-{dead}"));
    let not_a_pid = dir.join("policy.onnx.tmp-12x");
    for p in [&stale, &of_live, &of_other, &not_a_pid] {
        std::fs::write(p, b"half an ONNX model").unwrap();
    }
    // A symbolic link with a stale name (a pid no process has) is not followed nor removed.
    let link = dir.join("policy.onnx.tmp-999999999");
    std::os::unix::fs::symlink(&of_other, &link).unwrap();
    let out = finish(
        spawn(bin().args(["export", "--run", run.to_str().unwrap(), "--out", model.to_str().unwrap()])),
        "export",
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(model.is_file());
    assert!(!stale.exists(), "the killed writer's temporary file is still there");
    for p in [&of_live, &of_other, &not_a_pid] {
        assert_eq!(std::fs::read(p).unwrap(), b"half an ONNX model", "{} changed", p.display());
    }
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    std::fs::remove_dir_all(&dir).ok();
}
