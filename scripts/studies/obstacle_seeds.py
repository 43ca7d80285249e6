#!/usr/bin/env python3
"""One row per config of an obstacle study's summary.csv (scripts/studies/obstacle_summary.py):
each evaluation's success and collision rates as the mean over the config's seeds with their
range in brackets (one seed: its value), the seeds, and the training's wall time range.

    scripts/studies/obstacle_seeds.py summary.csv [CONFIG ...] > table.md

With CONFIGs, those rows in that order (a config the file lacks is an error naming it);
without, every config in the file's order.
"""
import csv
import sys

EVALS = [("alone", "1-3 random obstacles, alone"), ("shield", "the same, with the shield"),
         ("in_way_alone", "in the way, alone"), ("in_way_shield", "in the way, with the shield")]


def mean_range(v):
    """The mean of `v` with its range in brackets (one value: the value), to 0.1."""
    mean = sum(v) / len(v)
    return f"{mean:.1f}" if len(v) == 1 else f"{mean:.1f} [{min(v):.1f}-{max(v):.1f}]"


def cell(rows, key):
    return mean_range([float(r[key]) for r in rows])


def main(path, configs):
    rows = list(csv.DictReader(open(path, newline="")))
    by = {}
    for r in rows:
        by.setdefault(r["config"], []).append(r)
    for c in configs:
        if c not in by:
            sys.exit(f"obstacle_seeds.py: {path} has no runs of config {c!r}")
    print("| config | seeds | " + " | ".join(f"{title}: success / collisions %" for _, title in EVALS)
          + " | training s |")
    print("|---|---|" + "---|" * len(EVALS) + "---|")
    for c in configs or list(by):
        rs = by[c]
        walls = [int(r["train_wall_s"]) for r in rs]
        cells = [f"{cell(rs, 'success_' + k)} / {cell(rs, 'collisions_' + k)}" for k, _ in EVALS]
        seeds = ",".join(r["seed"] for r in rs)
        print(f"| `{c}` | {seeds} | " + " | ".join(cells) + f" | {min(walls)}-{max(walls)} |")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2:])
