#!/usr/bin/env python3
"""The obstacle benchmark's table: every planner of `stagerl bench obstacles` and OMPL's
RRTConnect on the same problems, from the per-plan files scripts/studies/obstacle_benchmark.sh
writes (OUT/<set>/plans.jsonl and OUT/ompl.jsonl, or the same packed with xz).

    scripts/studies/obstacle_table.py OUT > table.md

Per set and planner: success (reached, or for OMPL solved, with no contact along the path),
collisions, the tip's path length and the joint travel (sum of |dq|) averaged over the successes,
plan time median and 95th percentile over every problem (one thread), and the shield's changed
commands and stops per plan. A cell with nothing to average says "-".
"""

import json
import lzma
import sys
from pathlib import Path

SETS = ["free", "in-the-way", "random-3", "random-6", "narrow-gap"]
PLANNERS = ["jacobian", "jacobian+shield", "policy", "policy+shield", "rrt-connect", "ompl-rrtconnect"]


def quantile(values, q):
    v = sorted(values)
    return v[int((len(v) - 1) * q + 0.5)] if v else None  # as stagerl rounds (half away from zero)


def fmt(x, spec):
    return "-" if x is None else format(x, spec)


def mean(values):
    return sum(values) / len(values) if values else None


def lines(path):
    """The lines of `path`, or of `path`.xz (the committed results keep the per-plan files packed)."""
    if path.exists():
        return path.read_text().splitlines()
    return lzma.open(f"{path}.xz", "rt").read().splitlines()


def rows_of(out):
    by = {}
    for s in SETS:
        for line in lines(out / s / "plans.jsonl"):
            p = json.loads(line)
            by.setdefault((p["set"], p["planner"]), []).append(p)
    for line in lines(out / "ompl.jsonl"):
        r = json.loads(line)
        by.setdefault((r["set"], "ompl-rrtconnect"), []).append(
            dict(r, success=r["solved"] and not r["collision"]))
    return by


def main(out):
    by = rows_of(Path(out))
    print("| set | planner | problems | success % | collision % | path length m | joint travel rad "
          "| plan time median ms | p95 ms | shield changes/plan | shield stops/plan |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for s in SETS:
        for planner in PLANNERS:
            ps = by.get((s, planner))
            if not ps:
                continue
            n = len(ps)
            ok = [p for p in ps if p["success"]]
            times = [1e3 * p["plan_time_s"] for p in ps]
            shielded = "shield_steps" in ps[0]
            per_plan = (lambda k: fmt(sum(p[k] for p in ps) / n, ".2f")) if shielded else (lambda k: "-")
            print(f"| {s} | {planner} | {n} | {100 * len(ok) / n:.1f} | {100 * sum(p['collision'] for p in ps) / n:.1f} "
                  f"| {fmt(mean([p['path_length_m'] for p in ok]), '.3f')} "
                  f"| {fmt(mean([p['joint_travel_rad'] for p in ok]), '.3f')} "
                  f"| {fmt(quantile(times, 0.5), '.3f')} | {fmt(quantile(times, 0.95), '.3f')} "
                  f"| {per_plan('shield_interventions')} | {per_plan('shield_stops')} |")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
