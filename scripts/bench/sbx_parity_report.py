#!/usr/bin/env python3
"""The sbx parity table and figure (issue 36, item 4) from the runs' evaluations.

    python scripts/bench/sbx_parity_report.py --dir docs/results/sbx-parity

reads ``DIR/evals.csv`` (columns algo, impl, seed, env_steps, success_rate,
median_final_distance_m, wall_s: sbx's rows as ``sbx_parity.py`` writes them, stagerl's rows
collected from each run's ``eval.csv`` by ``--collect``) and writes ``DIR/table.md`` (success at
each checkpoint, mean and sample standard deviation over the seeds, per algorithm and
implementation; wall time) and ``DIR/success.svg`` and ``DIR/success.png``.

    python scripts/bench/sbx_parity_report.py --dir DIR --collect crossq RUN_DIR SEED WALL_S

appends a stagerl run's evaluations (its ``eval.csv``) to ``DIR/evals.csv``; ``WALL_S`` is the
run's whole wall time (the process's, as measured around ``stagerl train``).

An evaluation belongs to checkpoint ``k * every`` when it is the first at or after it (both
sides evaluate after the episode that passes a multiple of ``every``, so up to one episode late).
"""

from __future__ import annotations

import argparse
import csv
import math
import os
from collections import defaultdict

FIELDS = ["algo", "impl", "seed", "env_steps", "success_rate", "median_final_distance_m", "wall_s", "eval_s"]


def collect(path: str, algo: str, run_dir: str, seed: int, wall_s: float) -> None:
    with open(os.path.join(run_dir, "eval.csv"), newline="") as f:
        rows = list(csv.DictReader(f))
    new = not os.path.exists(path) or os.path.getsize(path) == 0
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        if new:
            w.writeheader()
        for i, r in enumerate(rows):
            last = i == len(rows) - 1
            w.writerow(dict(algo=algo, impl="stagerl", seed=seed, env_steps=r["env_steps"],
                            success_rate=r["success_rate"],
                            median_final_distance_m=r.get("median_final_distance_m", ""),
                            wall_s=f"{wall_s:.2f}" if last else r.get("wall_s", ""), eval_s=""))


def mean_sd(xs: list[float]) -> tuple[float, float]:
    m = sum(xs) / len(xs)
    sd = math.sqrt(sum((x - m) ** 2 for x in xs) / (len(xs) - 1)) if len(xs) > 1 else float("nan")
    return m, sd


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dir", required=True)
    p.add_argument("--every", type=int, default=1000)
    p.add_argument("--collect", nargs=4, metavar=("ALGO", "RUN_DIR", "SEED", "WALL_S"))
    args = p.parse_args()
    path = os.path.join(args.dir, "evals.csv")
    if args.collect:
        algo, run_dir, seed, wall = args.collect
        collect(path, algo, run_dir, int(seed), float(wall))
        return

    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    # (algo, impl, seed) -> {checkpoint: success}, and the run's last wall_s and env steps.
    curves: dict = defaultdict(dict)
    dists: dict = defaultdict(dict)
    wall: dict = {}
    for r in rows:
        key = (r["algo"], r["impl"], int(r["seed"]))
        steps = int(r["env_steps"])
        # the first evaluation at or after checkpoint k (evaluations come after the episode that
        # passes a multiple of `every`, so less than one episode late): floor(steps / every).
        k = steps // args.every * args.every
        curves[key].setdefault(k, float(r["success_rate"]))
        dists[key].setdefault(k, float(r["median_final_distance_m"]))
        if r["wall_s"]:
            wall[key] = (float(r["wall_s"]), steps)
    algos = sorted({k[0] for k in curves})
    lines = []
    for algo in algos:
        # stagerl, sbx, then any diagnostic variant (an `impl` of another name, e.g. sbx with
        # stagerl's log-std bound).
        impls = ["stagerl", "sbx"] + sorted({im for (a, im, _) in curves if a == algo} - {"stagerl", "sbx"})
        seeds = {i: sorted(s for (a, im, s) in curves if a == algo and im == i) for i in impls}
        ks = sorted({k for (a, _, _), c in curves.items() if a == algo for k in c})
        lines.append(f"### {algo}\n")
        lines.append("| env steps | " + " | ".join(f"{i} success % (seeds {', '.join(map(str, seeds[i]))})" for i in impls) + " | difference (stagerl - sbx), pp |")
        lines.append("|---|" + "---|" * (len(impls) + 1))
        for k in ks:
            cells, means = [], {}
            for i in impls:
                xs = [curves[(algo, i, s)][k] * 100 for s in seeds[i] if k in curves[(algo, i, s)]]
                if xs:
                    m, sd = mean_sd(xs)
                    means[i] = m
                    cells.append(f"{m:.1f} ± {sd:.1f} ({' / '.join(f'{x:.1f}' for x in xs)})")
                else:
                    cells.append("-")
            diff = f"{means['stagerl'] - means['sbx']:+.1f}" if "stagerl" in means and "sbx" in means else "-"
            lines.append(f"| {k} | " + " | ".join(cells) + f" | {diff} |")
        lines.append("")
        lines.append("Median final distance, cm (mean ± sd over the seeds):\n")
        lines.append("| env steps | " + " | ".join(impls) + " | difference, cm |")
        lines.append("|---|" + "---|" * (len(impls) + 1))
        for k in ks:
            cells, means = [], {}
            for i in impls:
                xs = [dists[(algo, i, s)][k] * 100 for s in seeds[i] if k in dists[(algo, i, s)]]
                if xs:
                    m, sd = mean_sd(xs)
                    means[i] = m
                    cells.append(f"{m:.1f} ± {sd:.1f}")
                else:
                    cells.append("-")
            diff = f"{means['stagerl'] - means['sbx']:+.1f}" if "stagerl" in means and "sbx" in means else "-"
            lines.append(f"| {k} | " + " | ".join(cells) + f" | {diff} |")
        # Each seed's mean over the second half of the budget (checkpoints >= half the last):
        # one number per run, then Welch's t of the difference.
        half = [k for k in ks if k >= ks[-1] / 2]
        lines.append("")
        lines.append(f"Per run, the mean over checkpoints {half[0]}-{half[-1]} (one value a seed):\n")
        lines.append("| measure | stagerl | other | other's value | difference (stagerl - other) | Welch t |")
        lines.append("|---|---|---|---|---|---|")
        for name, table, scale in (("success %", curves, 100), ("median final distance, cm", dists, 100)):
            per_impl = {}
            for i in impls:
                per_impl[i] = [sum(table[(algo, i, s)][k] for k in half) / len(half) * scale
                               for s in seeds[i] if all(k in table[(algo, i, s)] for k in half)]
            for other in impls[1:]:
                if len(per_impl["stagerl"]) < 2 or len(per_impl[other]) < 2:
                    continue
                (ma, sa), (mb, sb) = mean_sd(per_impl["stagerl"]), mean_sd(per_impl[other])
                se = math.sqrt(sa ** 2 / len(per_impl["stagerl"]) + sb ** 2 / len(per_impl[other]))
                t = (ma - mb) / se if se > 0 else float("nan")
                lines.append(f"| {name} | {ma:.2f} ± {sa:.2f} | {other} | {mb:.2f} ± {sb:.2f} | {ma - mb:+.2f} | {t:+.2f} |")
        lines.append("")
        lines.append("| impl | wall s per run (seeds) | mean wall s | env steps | ms per env step |")
        lines.append("|---|---|---|---|---|")
        per = {}
        for i in impls:
            ws = [wall[(algo, i, s)] for s in seeds[i] if (algo, i, s) in wall]
            if not ws:
                continue
            m = sum(w for w, _ in ws) / len(ws)
            st = sum(n for _, n in ws) / len(ws)
            per[i] = (m, m / st)
            lines.append(f"| {i} | {' / '.join(f'{w:.1f}' for w, _ in ws)} | {m:.1f} | {st:.0f} | {1000 * m / st:.2f} |")
        if "stagerl" in per and "sbx" in per:
            lines.append(f"\nWall-clock ratio sbx / stagerl: {per['sbx'][0] / per['stagerl'][0]:.2f}x per run, "
                         f"{per['sbx'][1] / per['stagerl'][1]:.2f}x per env step.\n")
    with open(os.path.join(args.dir, "table.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))

    import matplotlib
    matplotlib.use("Agg")
    matplotlib.rcParams["svg.hashsalt"] = "sbx-parity"
    matplotlib.rcParams["svg.fonttype"] = "none"
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(algos), figsize=(5.2 * len(algos), 7.2), squeeze=False)
    colours = defaultdict(lambda: "tab:green", {"stagerl": "tab:blue", "sbx": "tab:orange"})
    for col, algo in enumerate(algos):
        impls = ["stagerl", "sbx"] + sorted({im for (a, im, _) in curves if a == algo} - {"stagerl", "sbx"})
        for row, (table, ylabel) in enumerate(((curves, "success % (within 1 cm), deterministic policy"),
                                               (dists, "median final distance, cm"))):
            ax = axes[row][col]
            for i in impls:
                seeds = sorted(s for (a, im, s) in table if a == algo and im == i)
                if not seeds:
                    continue
                for s in seeds:
                    c = table[(algo, i, s)]
                    ks = sorted(c)
                    ax.plot(ks, [100 * c[k] for k in ks], color=colours[i], alpha=0.3, lw=0.8)
                ks = sorted({k for s in seeds for k in table[(algo, i, s)]})
                ms = [sum(100 * table[(algo, i, s)][k] for s in seeds if k in table[(algo, i, s)])
                      / sum(1 for s in seeds if k in table[(algo, i, s)]) for k in ks]
                ax.plot(ks, ms, color=colours[i], lw=2, marker="o", ms=3, ls="-" if i in ("stagerl", "sbx") else "--",
                        label=f"{i} (mean of {len(seeds)} seeds)")
            if row == 0:
                ax.set_title(f"{algo} on stagerl/Reach-v0 (SAR, 200 targets)")
            else:
                ax.set_yscale("log")
            ax.set_xlabel("environment steps")
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(args.dir, "success.svg"), metadata={"Date": None})
    fig.savefig(os.path.join(args.dir, "success.png"), dpi=90)


if __name__ == "__main__":
    main()
