#!/usr/bin/env python3
"""One row per run of the demonstrations study (docs/results/demonstrations): the closing
evaluation (the best checkpoint, 500 targets of seed 0, the run's own setting: no shield) and the
two in-the-way evaluations (`stagerl eval --obstacles-in-path 1`, alone and `--shield`), read
from each run's per-trial CSVs; the demonstrations' line and the wall time from its log.

usage: demo_summary.py RUNS_DIR > summary.csv   (RUNS_DIR holds NAME-sN/ folders and NAME-sN.log)
"""
import csv
import pathlib
import re
import sys


def rates(path):
    rows = list(csv.DictReader(open(path)))
    n = len(rows)
    ok = sum(int(r["success"]) for r in rows)
    hit = sum(int(r["collision_steps"]) > 0 for r in rows)
    return f"{100 * ok / n:.1f}", f"{100 * hit / n:.1f}"


def main(root):
    root = pathlib.Path(root)
    w = csv.writer(sys.stdout, lineterminator="\n")
    w.writerow(["config", "seed", "episodes", "env_steps", "train_wall_s", "demo_transitions",
                "success", "collisions", "success_in_way", "collisions_in_way",
                "success_in_way_shield", "collisions_in_way_shield"])
    for run in sorted(p for p in root.iterdir() if p.is_dir() and (p / "done").exists()):
        name, seed = run.name.rsplit("-s", 1)
        episodes = list(csv.DictReader(open(run / "episodes.csv")))
        last = episodes[-1]
        log = (root / f"{run.name}.log").read_text()
        demo = re.search(r"demonstrations: .*: (\d+) transitions", log)
        w.writerow([name, seed, last["episode"], last["env_steps"], f"{float(last['wall_s']):.0f}",
                    demo.group(1) if demo else 0,
                    *rates(run / "eval-final-seed0.csv"),
                    *rates(run / "eval-best-trials500-seed0-in-path-1.csv"),
                    *rates(run / "eval-best-trials500-seed0-in-path-1-shield.csv")])


if __name__ == "__main__":
    main(sys.argv[1])
