#!/usr/bin/env python3
"""One row per run of an obstacle study (docs/results/obstacle-her): the four evaluations of its
best checkpoint on the same 500 targets (seed 0) among the task's 1-3 random obstacles, alone
(the closing evaluation, `eval-final-seed0.csv`) and with the shield (`stagerl eval --shield`),
and with the first obstacle across the straight way (`--obstacles-in-path 1`), alone and with
the shield; the training's length, wall time and curriculum stages from `episodes.csv`.

usage: obstacle_summary.py RUNS_DIR > summary.csv

RUNS_DIR holds one folder per run, named CONFIG-sSEED. A run missing one of the four per-trial
CSVs is an error naming the file: no row reports a check that did not run. A run trained behind
the shield (`[task.shield] enabled = true` in its config.toml) is evaluated behind it by default,
so its files are the other way round: alone is `stagerl eval --no-shield` (`...-no-shield.csv`),
with the shield the closing evaluation and `--obstacles-in-path 1`.
"""
import csv
import pathlib
import sys
import tomllib

EVALS = [  # (column prefix, per-trial CSV in the run folder)
    ("alone", "eval-final-seed0.csv"),
    ("shield", "eval-best-trials500-seed0-shield.csv"),
    ("in_way_alone", "eval-best-trials500-seed0-in-path-1.csv"),
    ("in_way_shield", "eval-best-trials500-seed0-in-path-1-shield.csv"),
]

SHIELD_TRAINED_EVALS = [  # the same columns for a run trained behind the shield
    ("alone", "eval-best-trials500-seed0-no-shield.csv"),
    ("shield", "eval-final-seed0.csv"),
    ("in_way_alone", "eval-best-trials500-seed0-in-path-1-no-shield.csv"),
    ("in_way_shield", "eval-best-trials500-seed0-in-path-1.csv"),
]


def evals_of(run):
    """The per-trial CSVs of `run`'s four columns, by whether it was trained behind the shield."""
    config = tomllib.loads((run / "config.toml").read_text()) if (run / "config.toml").exists() else {}
    shield = config.get("task", {}).get("shield", {})
    return SHIELD_TRAINED_EVALS if shield.get("enabled", False) else EVALS


def rates(path):
    if not path.exists():
        sys.exit(f"obstacle_summary.py: {path} is missing (run that evaluation first)")
    rows = list(csv.DictReader(open(path, newline="")))
    if len(rows) != 500:
        sys.exit(f"obstacle_summary.py: {path} holds {len(rows)} trials, expected 500")
    ok = sum(int(r["success"]) for r in rows)
    hit = sum(int(r["collision_steps"]) > 0 for r in rows)
    return f"{100 * ok / len(rows):.1f}", f"{100 * hit / len(rows):.1f}"


def stages(episodes):
    """Episodes at which each curriculum stage after the first was first played."""
    if "curriculum_stage" not in episodes[0]:
        return ""
    begun, last = [], episodes[0]["curriculum_stage"]
    for e in episodes:
        if e["curriculum_stage"] != last:
            begun.append(e["episode"])
            last = e["curriculum_stage"]
    return ";".join(begun)


def main(root):
    root = pathlib.Path(root)
    w = csv.writer(sys.stdout, lineterminator="\n")
    header = ["config", "seed", "episodes", "env_steps", "train_wall_s", "stages_began_at_episode"]
    for prefix, _ in EVALS:
        header += [f"success_{prefix}", f"collisions_{prefix}"]
    w.writerow(header)
    runs = [p for p in root.iterdir() if p.is_dir() and "-s" in p.name]

    def key(p):
        name, seed = p.name.rsplit("-s", 1)
        return (name, int(seed))

    for run in sorted(runs, key=key):
        name, seed = key(run)
        episodes = list(csv.DictReader(open(run / "episodes.csv", newline="")))
        last = episodes[-1]
        row = [name, seed, last["episode"], last["env_steps"], f"{float(last['wall_s']):.0f}",
               stages(episodes)]
        for _, file in evals_of(run):
            row += rates(run / file)
        w.writerow(row)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
