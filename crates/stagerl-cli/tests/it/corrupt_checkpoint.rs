//! Silent corruption is refused: one flipped byte in a tensor or in the metadata of a run's
//! latest, best or final checkpoint makes `train --resume` and `eval` fail with a message naming
//! the file, and nothing on disk changes.

use crate::common;

use common::{run, scratch, snapshot};
use std::path::Path;

const CONFIG: &str = "[agent]\nhidden = [8, 8]\nlearning_starts = 50\nbatch_size = 8\nbuffer_size = 1000\n\
[train]\nepisodes = 4\neval_every_episodes = 2\neval_trials = 2\ncheckpoint_every_episodes = 1\n";

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let p = e.unwrap().path();
        let dest = to.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_dir(&p, &dest);
        } else {
            std::fs::copy(&p, &dest).unwrap();
        }
    }
}

/// Flip the lowest bit of the last tensor value's top byte (doubles or halves it: still finite).
fn flip_tensor(bytes: &mut [u8]) {
    let n = bytes.len();
    bytes[n - 1] ^= 0x01;
}

/// Flip one digit (0<->1, 2<->3, ...) of the metadata entry `agent_rng`: still valid JSON.
fn flip_metadata(bytes: &mut [u8]) {
    let len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header = &bytes[8..8 + len];
    let key = b"\"agent_rng\":\"";
    let at = header.windows(key.len()).position(|w| w == key).expect("agent_rng in the metadata") + key.len();
    let digit = at + header[at..].iter().position(u8::is_ascii_digit).unwrap();
    bytes[8 + digit] ^= 0x01;
}

#[test]
fn a_flipped_byte_in_any_checkpoint_is_refused_naming_the_file() {
    let root = scratch("corrupt");
    let cfg = root.join("c.toml");
    std::fs::write(&cfg, CONFIG).unwrap();
    let good = root.join("good");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let out = run(&["train", "--config", &s(&cfg), "--out", &s(&good), "--eval-trials", "2"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // The pristine run resumes ("already finished") and evaluates from each checkpoint.
    for file in ["latest", "best", "final"] {
        let p = good.join(format!("checkpoints/{file}.safetensors"));
        let out = run(&["eval", "--run", &s(&good), "--checkpoint", &s(&p), "--trials", "2"]);
        assert!(out.status.success(), "{file}: {}", String::from_utf8_lossy(&out.stderr));
    }
    let out = run(&["train", "--resume", &s(&good)]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    let mut failures = Vec::new();
    for file in ["latest", "best", "final"] {
        for (what, flip) in [("tensor", flip_tensor as fn(&mut [u8])), ("metadata", flip_metadata)] {
            let dir = root.join(format!("{file}-{what}"));
            copy_dir(&good, &dir);
            let ck = dir.join(format!("checkpoints/{file}.safetensors"));
            let mut bytes = std::fs::read(&ck).unwrap();
            flip(&mut bytes);
            std::fs::write(&ck, &bytes).unwrap();
            let before = snapshot(&dir);
            let mut commands = vec![
                vec!["train".to_string(), "--resume".into(), s(&dir)],
                vec![
                    "eval".into(),
                    "--run".into(),
                    s(&dir),
                    "--checkpoint".into(),
                    s(&ck),
                    "--trials".into(),
                    "2".into(),
                ],
            ];
            if file == "best" {
                commands.push(vec!["eval".into(), "--run".into(), s(&dir), "--trials".into(), "2".into()]);
            }
            for args in commands {
                let args: Vec<&str> = args.iter().map(String::as_str).collect();
                let out = run(&args);
                let err = String::from_utf8_lossy(&out.stderr);
                let case = format!("{file}: flipped {what} byte: `stagerl {}`", args.join(" "));
                if out.status.code() != Some(1) {
                    failures.push(format!("{case}: exit {:?}, expected 1; stderr: {err}", out.status.code()));
                }
                for needle in [format!("{file}.safetensors"), "checksum mismatch".into()] {
                    if !err.contains(&needle) {
                        failures.push(format!("{case}: stderr does not contain {needle:?}: {err}"));
                    }
                }
                if snapshot(&dir) != before {
                    failures.push(format!("{case}: files on disk changed"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    std::fs::remove_dir_all(&root).ok();
}
