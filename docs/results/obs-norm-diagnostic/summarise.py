"""Summarise the diagnostic's runs: runs.csv (one row per run) and a Markdown table per config.

    python3 summarise.py /work/runs-obsnorm > table.md
"""
import csv
import pathlib
import statistics
import sys

root = pathlib.Path(sys.argv[1])
here = pathlib.Path(__file__).parent
CONFIGS = ["no-obstacles", "no-obstacles-norm", "no-obstacles-ln", "far-random", "far-random-norm", "far-random-ln",
           "far-random-3", "far-random-3-norm", "far-random-blind"]


def closing(path):
    rows = list(csv.DictReader(open(path)))
    success = 100.0 * sum(int(r["success"]) for r in rows) / len(rows)
    touched = 100.0 * sum(int(r["collision_steps"] or 0) > 0 for r in rows) / len(rows)
    return len(rows), success, touched


out = []
for config in CONFIGS:
    for run in sorted(root.glob(f"{config}-s[0-9]")):
        if not (run / "eval-final-seed0.json").exists():
            continue
        n, best, best_touch = closing(run / "eval-final-seed0.csv")
        _, final, _ = closing(run / "eval-final-seed0-final-checkpoint.csv")
        episodes = list(csv.DictReader(open(run / "episodes.csv")))
        out.append({
            "config": config, "seed": run.name.rsplit("-s", 1)[1], "episodes": len(episodes),
            "env_steps": episodes[-1]["env_steps"], "trials": n,
            "success_best_pct": f"{best:.1f}", "contact_trials_best_pct": f"{best_touch:.1f}",
            "success_final_pct": f"{final:.1f}", "wall_s": episodes[-1]["wall_s"],
        })
with open(here / "runs.csv", "w", newline="") as f:
    w = csv.DictWriter(f, fieldnames=list(out[0]))
    w.writeheader()
    w.writerows(out)

print("| Config | Seeds | Success, best checkpoint | Success, final checkpoint | Trials with a contact (best) |")
print("|---|---|---|---|---|")
for config in CONFIGS:
    rs = [r for r in out if r["config"] == config]
    if not rs:
        continue
    def col(k):
        xs = [float(r[k]) for r in rs]
        each = ", ".join(f"{x:.1f}" for x in xs)
        return f"{statistics.mean(xs):.1f} % ({each})"
    seeds = ", ".join(r["seed"] for r in rs)
    print(f"| `{config}` | {seeds} | {col('success_best_pct')} | {col('success_final_pct')} | {col('contact_trials_best_pct')} |")
