#!/usr/bin/env python3
"""Pack a study's run directories into one small, reproducible archive (`runs.tar.xz`).

    scripts/studies/pack_runs.py RUNS_DIR STUDY_DIR/runs.tar.xz [--report STUDY_DIR/table1.json]
    scripts/studies/pack_runs.py --unpack STUDY_DIR/runs.tar.xz FOLDER     # plain CSVs again

`stagerl report STUDY_DIR/runs.tar.xz --out STUDY_DIR` regenerates the study's report from it
(docs/results/README.md, "How results are kept"). What goes in, under `runs/`:

- every file of RUNS_DIR but checkpoints and TensorBoard events: each run's `config.toml`,
  closing-evaluation records (`*.json`), `episodes.csv`, `eval.csv` and per-trial evaluation
  CSVs, and the sweep's `preset.toml`, `provenance.json` and `README.md`;
- checkpoints only of the runs the report rolls out for its trajectory figure and 3D views (the
  `trajectories[].checkpoint` of the report's `table1.json`, given with --report), so that the
  whole report, figures included, regenerates from the archive;
- the CSVs' floating-point columns at a stated resolution (`RESOLUTION` below), not at the 17
  significant digits the trainer writes: rewards to 1e-3 in episode logs and 1e-4 in
  evaluations, distances and target coordinates to 1e-6 m in evaluations and 1e-4 m in episode
  logs (a column the report does not read; success is a column of its own), seconds to 0.1 s.
  The counts, steps, success and collision columns are exact. Files at full precision are in the
  git history (see the study's README for the commit).
- each of these CSVs transposed, as `NAME.csv.T` (line i: column i's name and values), which
  compresses about 30 % better; `stagerl report` and `--unpack` write them back as `NAME.csv`.
  The episode logs' `env_steps`, a running count, is stored as its differences (`env_steps:diff`,
  summed back on reading), which takes it from about 10 % of an archive to almost nothing.

The archive is byte-for-byte reproducible: entries sorted by name, owner 0, mode 0644 or 0755,
modification time 0, xz preset 9e. Symbolic links inside RUNS_DIR are followed (a study whose
runs are links into another study's runs gets copies).
"""

import argparse
import csv
import io
import json
import lzma
import os
import sys
import tarfile

# Column name -> decimals, per file kind. Columns not named are copied as they are.
RESOLUTION = {
    "episodes": {"reward": 3, "final_distance_m": 4, "wall_s": 1},
    "eval": {"mean_reward": 4, "median_final_distance_m": 6, "mean_steps": 3},
    "trials": {
        "reward": 4,
        "start_distance_m": 6,
        "final_distance_m": 6,
        "target_x_m": 6,
        "target_y_m": 6,
        "target_z_m": 6,
    },
}

# Integer columns stored as differences (`NAME:diff`, first value as is), per file kind: a
# running count compresses to almost nothing that way. `stagerl report` and --unpack sum them back.
DIFFERENCES = {"episodes": {"env_steps"}}
DIFF_SUFFIX = ":diff"

SKIP_DIRS = {"tb", "tensorboard", "checkpoints"}  # `tb`: a run's TensorBoard events


def kind_of(name):
    if name == "episodes.csv":
        return "episodes"
    if name == "eval.csv":
        return "eval"
    if name.startswith("eval") and name.endswith(".csv"):
        return "trials"
    return None


def fixed(text, decimals):
    """`text` rounded to `decimals` places, trailing zeros dropped ("-0" written "0")."""
    if text == "":
        return text
    value = float(text)
    if value != value or value in (float("inf"), float("-inf")):
        return text
    out = f"{value:.{decimals}f}"
    if "." in out:
        out = out.rstrip("0").rstrip(".")
    return "0" if out in ("-0", "") else out


def round_csv(data, kind):
    """The CSV `data` rounded by RESOLUTION[kind], transposed (see `transposed`)."""
    rules = RESOLUTION[kind]
    rows = list(csv.reader(io.StringIO(data.decode("utf-8"))))
    if not rows:
        return data
    header = rows[0]
    places = [rules.get(h) for h in header]
    if any(len(row) != len(header) for row in rows[1:]):
        sys.exit("pack_runs: a CSV row has another number of fields than its header")
    rounded = [header] + [[v if p is None else fixed(v, p) for v, p in zip(row, places)] for row in rows[1:]]
    for j, name in enumerate(header):
        if name in DIFFERENCES.get(kind, ()):
            differenced(rounded, j)
    return transposed(rounded)


def differenced(rows, j):
    """Column `j` of `rows` (header first) as differences, renamed `NAME:diff`; left as it is
    unless every value is an integer."""
    values = [row[j] for row in rows[1:]]
    if not all(v.lstrip("-").isdigit() for v in values):
        return
    rows[0][j] += DIFF_SUFFIX
    previous = 0
    for row, v in zip(rows[1:], values):
        row[j] = str(int(v) - previous)
        previous = int(v)


def transposed(rows):
    """Line i holds column i (its name, then its values): a column's values side by side
    compress about 30 % better than rows. `stagerl report` (and --unpack) turn a `NAME.csv.T`
    entry back into `NAME.csv`."""
    return "".join(",".join(col) + "\n" for col in zip(*rows)).encode("utf-8")


def untransposed(data):
    cols = [line.split(",") for line in data.decode("utf-8").splitlines()]
    for c in cols:
        if c[0].endswith(DIFF_SUFFIX):
            total = 0
            for i in range(1, len(c)):
                total += int(c[i])
                c[i] = str(total)
            c[0] = c[0][: -len(DIFF_SUFFIX)]
    return "".join(",".join(row) + "\n" for row in zip(*cols)).encode("utf-8")


def kept_checkpoints(report):
    if report is None:
        return set()
    with open(report, encoding="utf-8") as f:
        doc = json.load(f)
    return {t["checkpoint"] for t in doc.get("trajectories", [])}


def entries(runs_dir, keep):
    """(archive name, bytes, executable) of every file to pack, sorted by name."""
    out = []
    for root, dirs, files in os.walk(runs_dir, followlinks=True):
        rel_root = os.path.relpath(root, runs_dir)
        parts = [] if rel_root == "." else rel_root.split(os.sep)
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for name in sorted(files):
            if name.startswith("."):
                continue
            rel = "/".join(parts + [name])
            if any(p in SKIP_DIRS for p in parts) and rel not in keep:
                continue
            path = os.path.join(root, name)
            with open(path, "rb") as f:
                data = f.read()
            # a run's own CSVs (beside its config.toml), at any depth: a study may hold several
            # sweeps (learners/ and learners-long/), each a folder of runs
            in_run = bool(parts) and os.path.isfile(os.path.join(root, "config.toml"))
            kind = kind_of(name) if in_run else None
            if kind is not None:
                data = round_csv(data, kind)
                rel += ".T"
            out.append(("runs/" + rel, data, os.access(path, os.X_OK) and name.endswith(".sh")))
    missing = keep - {e[0][len("runs/") :] for e in out}
    if missing:
        sys.exit(f"pack_runs: checkpoints named by the report are missing: {sorted(missing)}")
    return sorted(out)


def pack(runs_dir, dest, keep):
    items = entries(runs_dir, keep)
    raw = io.BytesIO()
    with tarfile.open(fileobj=raw, mode="w", format=tarfile.PAX_FORMAT) as tar:
        for name, data, executable in items:
            info = tarfile.TarInfo(name)
            info.size = len(data)
            info.mode = 0o755 if executable else 0o644
            info.mtime = 0
            info.uid = info.gid = 0
            info.uname = info.gname = ""
            tar.addfile(info, io.BytesIO(data))
    packed = lzma.compress(raw.getvalue(), format=lzma.FORMAT_XZ, check=lzma.CHECK_CRC64,
                           preset=9 | lzma.PRESET_EXTREME)
    tmp = f"{dest}.tmp-{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(packed)
    os.replace(tmp, dest)
    return len(items), len(raw.getvalue()), len(packed)


def unpack(archive, dest):
    """Unpack `archive` into `dest` with every `NAME.csv.T` written back as `NAME.csv`."""
    with tarfile.open(archive, "r:xz") as tar:
        for m in tar.getmembers():
            parts = m.name.split("/")
            if m.name.startswith("/") or ".." in parts or not (m.isfile() or m.isdir()):
                sys.exit(f"pack_runs: refusing entry {m.name!r}")
            target = os.path.join(dest, *parts)
            if m.isdir():
                os.makedirs(target, exist_ok=True)
                continue
            os.makedirs(os.path.dirname(target), exist_ok=True)
            data = tar.extractfile(m).read()
            if target.endswith(".csv.T"):
                target, data = target[:-2], untransposed(data)
            with open(target, "wb") as f:
                f.write(data)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs_dir", help="the runs to pack (with --unpack: the archive)")
    ap.add_argument("dest", help="the archive to write (runs.tar.xz; with --unpack: a folder)")
    ap.add_argument("--report", help="the study's table1.json: keep the checkpoints it rolls out")
    ap.add_argument("--unpack", action="store_true", help="unpack an archive into plain CSVs")
    args = ap.parse_args()
    if args.unpack:
        unpack(args.runs_dir, args.dest)
        print(f"pack_runs: unpacked {args.runs_dir} into {args.dest}")
        return
    if not os.path.isdir(args.runs_dir):
        sys.exit(f"pack_runs: {args.runs_dir} is not a directory")
    if not os.path.isdir(os.path.dirname(os.path.abspath(args.dest))):
        sys.exit(f"pack_runs: the folder of {args.dest} does not exist")
    n, raw, packed = pack(args.runs_dir, args.dest, kept_checkpoints(args.report))
    print(f"pack_runs: {n} files, {raw / 1e6:.1f} MB as tar, {packed / 1e6:.2f} MB packed: {args.dest}")


if __name__ == "__main__":
    main()
