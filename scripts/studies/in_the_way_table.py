#!/usr/bin/env python3
"""Success and collision rates of `stagerl eval --obstacles-in-path P` evaluations, per sweep
and algorithm (mean and sample std over seeds, as Table 1 gives them), as a Markdown table.

    scripts/studies/in_the_way_table.py [--file NAME] SWEEP_RUNS [...]

Each SWEEP_RUNS is a sweep's `runs/` folder or its packed `runs.tar.xz` (scripts/studies/pack_runs.py;
unpacked into a temporary folder first), holding run directories named <algo>-<reward>-seed<N>;
in each, NAME (default eval-best-trials500-seed0-in-path-1.csv), a per-trial CSV with the
columns `success` and `collision_steps`. A run without the file is an error naming it."""
import argparse
import csv
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pack_runs import unpack  # noqa: E402


def rates(path: Path) -> tuple:
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        sys.exit(f"{path}: holds no trials")
    n = len(rows)
    return (100 * sum(r["success"] == "1" for r in rows) / n,
            100 * sum(int(r["collision_steps"]) > 0 for r in rows) / n)


def cell(values: list) -> str:
    sd = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{statistics.mean(values):.1f} ± {sd:.1f} %"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--file", default="eval-best-trials500-seed0-in-path-1.csv")
    p.add_argument("sweeps", nargs="+", type=Path)
    a = p.parse_args()
    print("| Sweep | Method | Seeds | Success | Collision rate |")
    print("|---|---|---|---|---|")
    for sweep in a.sweeps:
        with tempfile.TemporaryDirectory() as tmp:
            table(sweep, runs_of(sweep, Path(tmp)), a.file)


def runs_of(sweep: Path, tmp: Path) -> Path:
    """The folder of `sweep`'s runs: itself, or its archive unpacked under `tmp`."""
    if sweep.name.endswith(".tar.xz"):
        unpack(str(sweep), str(tmp))
        return tmp / "runs"
    return sweep


def table(sweep: Path, runs: Path, name: str) -> None:
    groups = {}
    for run in sorted(d for d in runs.iterdir() if d.is_dir() and "-seed" in d.name):
        f = run / name
        if not f.is_file():
            sys.exit(f"{f}: no such file (evaluate the run with stagerl eval --obstacles-in-path first)")
        groups.setdefault(run.name.rsplit("-seed", 1)[0], []).append(rates(f))
    for method, rs in sorted(groups.items(), reverse=True):
        print(f"| {sweep} | {method} | {len(rs)} | {cell([r[0] for r in rs])} | {cell([r[1] for r in rs])} |")


if __name__ == "__main__":
    main()
