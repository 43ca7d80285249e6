#!/usr/bin/env python3
"""The obstacle benchmark's tables of several seeds side by side: for each config, set and
planner, success and collision rates as the mean over the seeds with their range in brackets
(one seed: its value), from the tables `stagerl bench obstacles --run DIR` prints.

    scripts/studies/bench_seeds.py bench-CONFIG-sN.md [...] > table.md

Each file is named bench-CONFIG-sSEED.md (the config and seed its policy was trained with) and
holds the benchmark's Markdown table (columns `planner`, `set`, `success %`, `collision %`).
One row per config, set and planner, in the order of the first file of each config. A file not
so named, or without the table, is an error naming it; so is a config whose seeds did not run
the same sets and planners (no mean over fewer seeds than the row says).
"""
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from obstacle_seeds import mean_range  # noqa: E402

NAME = re.compile(r"^bench-(?P<config>.+)-s(?P<seed>\d+)\.md$")


def table(path):
    """{(set, planner): (success %, collision %)} of one benchmark file, in its order."""
    if not Path(path).is_file():
        sys.exit(f"bench_seeds.py: {path} is missing (run that benchmark first)")
    lines = [l for l in Path(path).read_text().splitlines() if l.startswith("|")]
    if len(lines) < 3:
        sys.exit(f"bench_seeds.py: {path} holds no benchmark table")
    head = [c.strip() for c in lines[0].strip("|").split("|")]
    try:
        cols = [head.index(c) for c in ("planner", "set", "success %", "collision %")]
    except ValueError:
        sys.exit(f"bench_seeds.py: {path}'s table has no columns planner, set, success %, collision %")
    rows = {}
    for line in lines[2:]:
        cells = [c.strip() for c in line.strip("|").split("|")]
        planner, set_, ok, hit = (cells[i] for i in cols)
        rows[(set_, planner)] = (float(ok), float(hit))
    return rows


def main(paths):
    by = {}  # config -> [(seed, rows)]
    for p in paths:
        m = NAME.match(Path(p).name)
        if not m:
            sys.exit(f"bench_seeds.py: {p} is not named bench-CONFIG-sSEED.md")
        by.setdefault(m["config"], []).append((m["seed"], table(p)))
    print("| config | seeds | set | planner | success % | collision % |")
    print("|---|---|---|---|---|---|")
    for config, runs in by.items():
        keys = list(runs[0][1])
        for seed, rows in runs:
            if set(rows) != set(keys):
                sys.exit(f"bench_seeds.py: bench-{config}-s{seed}.md has other sets or planners than "
                         f"bench-{config}-s{runs[0][0]}.md")
        seeds = ",".join(s for s, _ in runs)
        for key in keys:
            ok = [rows[key][0] for _, rows in runs]
            hit = [rows[key][1] for _, rows in runs]
            print(f"| `{config}` | {seeds} | {key[0]} | {key[1]} | {mean_range(ok)} | {mean_range(hit)} |")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
