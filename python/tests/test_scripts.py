"""The study scripts under scripts/studies/ that results depend on."""

import importlib.util
import os
import tarfile

SCRIPTS = os.path.join(os.path.dirname(__file__), "..", "..", "scripts", "studies")


def load(name):
    spec = importlib.util.spec_from_file_location(name, os.path.join(SCRIPTS, f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_pack_runs_leaves_out_tensorboard_events_and_checkpoints_but_those_kept(tmp_path):
    pack_runs = load("pack_runs")
    runs = tmp_path / "sweep"
    for name in ["sac-sar-seed1", "sac-sar-seed2"]:
        run = runs / name
        (run / "tb").mkdir(parents=True)
        (run / "checkpoints").mkdir()
        (run / "config.toml").write_text("[agent]\n")
        (run / "episodes.csv").write_text("episode,reward,env_steps,wall_s\n1,0.12345,10,0.01\n2,1.5,25,0.02\n")
        (run / "tb" / "events.out.tfevents.1.vm").write_bytes(b"\0" * 64)
        (run / "checkpoints" / "best.safetensors").write_bytes(b"\1" * 32)
        (run / "checkpoints" / "latest.safetensors").write_bytes(b"\2" * 32)
    (runs / "preset.toml").write_text("[sweep]\n")
    dest = tmp_path / "runs.tar.xz"
    keep = {"sac-sar-seed1/checkpoints/best.safetensors"}
    files, _, _ = pack_runs.pack(str(runs), str(dest), keep)
    with tarfile.open(dest) as tar:
        names = sorted(tar.getnames())
    assert names == [
        "runs/preset.toml",
        "runs/sac-sar-seed1/checkpoints/best.safetensors",
        "runs/sac-sar-seed1/config.toml",
        "runs/sac-sar-seed1/episodes.csv.T",
        "runs/sac-sar-seed2/config.toml",
        "runs/sac-sar-seed2/episodes.csv.T",
    ]
    assert files == len(names)
    # Unpacked, the episode log is a CSV again, its running env_steps summed back.
    out = tmp_path / "plain"
    pack_runs.unpack(str(dest), str(out))
    rows = (out / "runs" / "sac-sar-seed1" / "episodes.csv").read_text().splitlines()
    assert rows[0].split(",")[0] == "episode" and rows[2].split(",")[rows[0].split(",").index("env_steps")] == "25"
