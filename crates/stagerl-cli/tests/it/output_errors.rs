//! Output errors are errors, never panics: a pipe closed early (`| head -1`) or a full disk
//! (`> /dev/full`) give a non-zero exit (not 101, the code of a panic) and a message on standard
//! error, and so does a closed standard output for `fk` and `reward`; `train` whose output goes away saves its run and says how to
//! resume it.

use crate::common;

use common::{bin, redirected, scratch, spawn_piped};
use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::Output;

const FK_LINE: &str = "{\"joints\":[0,0,0,0,0,0]}\n";
const REWARD_LINE: &str =
    "{\"ee_pos\":[0,0,0],\"ee_quat\":[0,0,0,1],\"target\":[0.3,0,0],\"joint_vel\":[0,0,0,0,0,0]}\n";

/// Run `stagerl args`, read one line of its output, then close the pipe (as `| head -1` does).
fn head_1(args: &[&str], stdin: &str) -> (String, Output) {
    let mut child = spawn_piped(bin().args(args));
    let mut input = child.stdin.take().unwrap();
    let stdin = stdin.to_string();
    let feeder = std::thread::spawn(move || {
        let _ = input.write_all(stdin.as_bytes());
    });
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut first).unwrap();
    // The reader is dropped here: the pipe is closed.
    let out = child.wait_with_output().unwrap();
    feeder.join().unwrap();
    (first, out)
}

fn assert_clean_error(case: &str, out: &Output, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{case}: exit {:?}; stderr: {err}", out.status);
    assert!(!err.contains("panicked"), "{case}: {err}");
    assert!(err.contains(needle), "{case}: {needle:?} not in {err}");
}

#[test]
fn full_disk_and_closed_stdout_are_errors() {
    let many_fk = FK_LINE.repeat(2000);
    for (args, stdin) in [
        (&["config"][..], ""),
        (&["--help"][..], ""),
        (&["--version"][..], ""),
        (&["fk", "--help"][..], ""),
        (&["demo", "--trials", "5"][..], ""),
        (&["fk"][..], many_fk.as_str()),
        (&["reward", "--function", "sar"][..], REWARD_LINE),
        (&["bench", "env", "--steps", "100"][..], ""),
    ] {
        let out = redirected(args, ">/dev/full", stdin);
        assert_clean_error(&format!("{args:?} >/dev/full"), &out, "No space left on device");
        // Standard error closed as well: still a failure, silently.
        let out = redirected(args, ">/dev/full 2>&-", stdin);
        assert_eq!(out.status.code(), Some(1), "{args:?} >/dev/full 2>&-");
    }
    // fk and reward, whose product is their output, refuse a closed standard output.
    for (args, stdin) in [(&["fk"][..], FK_LINE), (&["reward", "--function", "sar"][..], REWARD_LINE)] {
        let out = redirected(args, ">&-", stdin);
        assert_clean_error(&format!("{args:?} >&-"), &out, "standard output is closed");
        let out = redirected(args, ">&- 2>&-", stdin);
        assert_eq!(out.status.code(), Some(1), "{args:?} >&- 2>&-");
    }
    // `> /dev/null` is not a closed output.
    let out = redirected(&["fk"], ">/dev/null", FK_LINE);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn a_pipe_closed_early_is_an_error() {
    let (first, out) = head_1(&["demo", "--trials", "2000"], "");
    assert!(first.starts_with("scripted Jacobian controller"), "{first}");
    assert_clean_error("demo | head -1", &out, "Broken pipe");
    // fk and reward answer line by line: the pipe closes while they still have input.
    let (first, out) = head_1(&["fk"], &FK_LINE.repeat(200_000));
    assert!(first.starts_with("{\"position\""), "{first}");
    assert_clean_error("fk | head -1", &out, "Broken pipe");
    let (first, out) = head_1(&["reward", "--function", "sar"], &REWARD_LINE.repeat(200_000));
    assert!(first.starts_with("{\"distance\""), "{first}");
    assert_clean_error("reward | head -1", &out, "Broken pipe");
}

#[test]
fn train_whose_output_closes_saves_the_run_and_says_how_to_resume() {
    let root = scratch("output-train");
    let cfg = root.join("c.toml");
    // The lines after "training ..." are printed at the evaluations, every 5 episodes.
    std::fs::write(
        &cfg,
        "[agent]\nhidden = [8, 8]\nlearning_starts = 100\nbatch_size = 8\nbuffer_size = 5000\n\
         [train]\nepisodes = 300\neval_every_episodes = 5\neval_trials = 2\ncheckpoint_every_episodes = 1000\n",
    )
    .unwrap();
    let dir = root.join("run");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (first, out) = head_1(&["train", "--config", &s(&cfg), "--out", &s(&dir), "--eval-trials", "3"], "");
    assert!(first.starts_with("training"), "{first}");
    assert_clean_error("train | head -1", &out, "Broken pipe");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("stagerl train --resume {}", s(&dir))), "{err}");
    // It stops at the first line that fails: an evaluation's (every 5 episodes), before the end.
    let episode: u64 = err
        .split("stopped after episode ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .unwrap()
        .parse()
        .unwrap();
    assert!(episode.is_multiple_of(5) && episode < 300, "{err}");
    assert!(dir.join("checkpoints/latest.safetensors").exists());
    assert!(!dir.join("checkpoints/final.safetensors").exists());

    // It resumes and finishes like any interrupted run.
    let out = bin().args(["train", "--resume", &s(&dir), "--eval-trials", "3"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(dir.join("checkpoints/final.safetensors").exists());
    assert!(dir.join("eval-final-seed0.csv").exists() && dir.join("eval-final-seed0.json").exists());

    // A full disk on standard output from the start: refused before anything is trained.
    let full = root.join("full");
    let out = redirected(&["train", "--config", &s(&cfg), "--out", &s(&full)], ">/dev/full", "");
    assert_clean_error("train >/dev/full", &out, "No space left on device");
    assert!(!full.join("episodes.csv").exists());
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn reproduce_whose_output_closes_stops_and_resumes() {
    let root = scratch("output-reproduce");
    let preset = root.join("p.toml");
    std::fs::write(
        &preset,
        "[sweep]\nalgorithms = [\"sac\"]\nrewards = [\"sar\", \"basic\", \"posture\"]\nseeds = [1]\neval_trials = 2\n\
         [agent]\nhidden = [8, 8]\nbatch_size = 8\nbuffer_size = 2000\nlearning_starts = 50\n\
         [train]\nepisodes = 40\neval_every_episodes = 0\ncheckpoint_every_episodes = 10\n",
    )
    .unwrap();
    let out_dir = root.join("sweep");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let args = ["reproduce", "--preset", &s(&preset), "--out", &s(&out_dir), "--jobs", "1"];
    // The first line is the sweep's; the line of the first finished run fails and stops the sweep.
    let (first, out) = head_1(&args, "");
    assert!(first.starts_with("reproduce"), "{first}");
    assert_clean_error("reproduce | head -1", &out, "Broken pipe");
    assert!(String::from_utf8_lossy(&out.stderr).contains("Run the same command again"));
    // The same command finishes the sweep.
    let out = bin().args(args).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("all 3 runs done"));
    std::fs::remove_dir_all(&root).ok();
}

/// Every command's `--help` ends with an example to copy.
#[test]
fn every_commands_help_has_an_example() {
    let top = String::from_utf8(bin().arg("--help").output().unwrap().stdout).unwrap();
    // The commands, as the top-level help lists them (two spaces, the name, spaces, the text).
    let commands: Vec<String> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .filter(|c| c != "help")
        .collect();
    assert!(commands.len() >= 12, "{commands:?} from\n{top}");
    let mut helps: Vec<Vec<String>> = commands.iter().map(|c| vec![c.clone()]).collect();
    helps.extend(["env", "update", "train", "plan"].map(|b| vec!["bench".to_string(), b.to_string()]));
    for args in helps {
        let o = bin().args(&args).arg("--help").output().unwrap();
        let text = String::from_utf8(o.stdout).unwrap();
        assert!(o.status.success(), "{args:?}");
        assert!(
            text.contains("\nExample:\n  stagerl ")
                || text.contains("\nExamples:\n  stagerl ")
                || text.contains("\nExample:\n  echo "),
            "{args:?} --help has no example:\n{text}"
        );
    }
}
