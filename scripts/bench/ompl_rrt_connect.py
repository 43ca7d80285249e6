#!/usr/bin/env python3
"""OMPL's RRTConnect (MoveIt's default planner) on stagerl's obstacle problems, as the classical
row beside `stagerl bench obstacles`.

Usage (in a venv with the `ompl` wheel from PyPI, numpy and stagerl's package):

    pip install ompl numpy ./python
    stagerl bench obstacles --problems-out problems.jsonl ...
    python scripts/bench/ompl_rrt_connect.py problems.jsonl --out ompl.jsonl [--budget-s 1.0]

Each line of the problems file is one problem (JSON):
  {"set": "in-the-way", "id": 3, "robot": "ur5", "start_rad": [...], "goal_rad": [...],
   "obstacles": [...], "floor": true, "self_collision": true}
`goal_rad` is the collision-free inverse-kinematics goal stagerl's RRT-Connect planned to, so that
both planners solve the same joint-space query (the time of stagerl's inverse kinematics is not in
OMPL's figure). `obstacles` are in `[[task.obstacles]]`'s schema.

The checker is stagerl's own over the same geometry (`stagerl.Chain(...).checker(...)`): a state
is valid when the arm touches nothing the problem checks. OMPL checks a motion at states no more
than `--resolution-rad` apart in joint space (the Euclidean norm of the joint differences; 5 mrad
by default, at which no point of a 1 m arm moves more than 5 mm between checks). The time is
OMPL's own (`getLastPlanComputationTime` + `getLastSimplificationTime`: the planner and its
shortcutting), one thread. Every returned path is checked again, densely (1 mrad), with the same
checker: a path that touches is counted as a collision, not as a success.

Writes one JSON line per problem (`set`, `id`, `solved`, `collision`, `plan_time_s`,
`path_length_rad` (Euclidean in joint space), `joint_travel_rad` (sum of |dq| over joints, as
stagerl's) and `path_length_m` (the tip's path)) and prints per set: solved, collisions, plan time median and 95th percentile.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def load_problems(path):
    problems = []
    with open(path, encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                p = json.loads(line)
                for key in ("set", "id", "start_rad", "goal_rad"):
                    if key not in p:
                        raise ValueError(f"missing `{key}`")
            except ValueError as e:
                sys.exit(f"{path}: line {n}: {e}")
            problems.append(p)
    return problems


def dense_states(path, step_rad=1e-3):
    """The piecewise-linear joint path at states no more than `step_rad` apart (its corners kept)."""
    rows = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        k = max(1, int(np.ceil(np.linalg.norm(b - a) / step_rad)))
        t = np.linspace(0.0, 1.0, k + 1)[1:, None]
        rows.append(a + t * (b - a))
    return np.concatenate(rows)


def dense_collision(checker, path, step_rad=1e-3):
    """Whether the piecewise-linear joint path touches anything, checked every `step_rad`."""
    hit, _ = checker.check(dense_states(path, step_rad))
    return bool(hit.any())


def solve(problem, chains, budget_s, resolution_rad):
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    import stagerl

    robot = problem.get("robot", "ur5")
    if robot not in chains:
        chains[robot] = stagerl.Chain(robot, problem.get("tip"))
    chain = chains[robot]
    checker = chain.checker(problem.get("obstacles", []), floor=problem.get("floor", True),
                            self_collision=problem.get("self_collision", True))
    dof = chain.dof
    space = ob.RealVectorStateSpace(dof)
    bounds = ob.RealVectorBounds(dof)
    for i in range(dof):
        bounds.setLow(i, float(chain.lower_limits[i]))
        bounds.setHigh(i, float(chain.upper_limits[i]))
    space.setBounds(bounds)
    setup = og.SimpleSetup(space)
    def valid(state):
        return not checker.collides([state[i] for i in range(dof)])

    setup.setStateValidityChecker(valid)
    si = setup.getSpaceInformation()
    si.setStateValidityCheckingResolution(resolution_rad / space.getMaximumExtent())
    setup.setPlanner(og.RRTConnect(si))
    start, goal = space.allocState(), space.allocState()
    for i in range(dof):  # (copyFromReals and copyToReals crash ompl 2.0.1's bindings)
        start[i] = float(problem["start_rad"][i])
        goal[i] = float(problem["goal_rad"][i])
    setup.setStartAndGoalStates(start, goal)
    status = setup.solve(budget_s)
    solved = bool(status) and setup.haveExactSolutionPath()
    result = {"set": problem["set"], "id": problem["id"], "solved": solved, "collision": False,
              "plan_time_s": setup.getLastPlanComputationTime(), "path_length_rad": None,
              "joint_travel_rad": None, "path_length_m": None}
    if solved:
        setup.simplifySolution()
        result["plan_time_s"] += setup.getLastSimplificationTime()
        path = setup.getSolutionPath()
        states = np.array([[path.getState(k)[i] for i in range(dof)] for k in range(path.getStateCount())])
        result["path_length_rad"] = float(np.linalg.norm(np.diff(states, axis=0), axis=1).sum())
        # As `stagerl bench obstacles` measures its plans: the sum of |dq| over joints, and the
        # tip's path (here along the straight joint segments, sampled every 1 mrad).
        result["joint_travel_rad"] = float(np.abs(np.diff(states, axis=0)).sum())
        tips, _ = chain.fk(dense_states(states))
        result["path_length_m"] = float(np.linalg.norm(np.diff(tips, axis=0), axis=1).sum())
        result["collision"] = dense_collision(checker, states)
        result["solved"] = not result["collision"]
    return result


def summary(results):
    sets = {}
    for r in results:
        sets.setdefault(r["set"], []).append(r)
    lines = []
    for name, rs in sets.items():
        t = np.array([r["plan_time_s"] for r in rs if r["solved"]])
        med, p95 = (np.median(t) * 1e3, np.percentile(t, 95) * 1e3) if len(t) else (float("nan"),) * 2
        lines.append(f"{name}: solved {sum(r['solved'] for r in rs)}/{len(rs)}, "
                     f"collisions {sum(r['collision'] for r in rs)}, plan time median {med:.2f} ms, p95 {p95:.2f} ms")
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("problems", help="JSON lines written by `stagerl bench obstacles --problems-out`")
    ap.add_argument("--out", required=True, help="JSON lines, one result per problem")
    ap.add_argument("--budget-s", type=float, default=1.0, help="planning time budget per problem, seconds")
    ap.add_argument("--resolution-rad", type=float, default=5e-3,
                    help="largest joint-space step between checked states of a motion, radians")
    ap.add_argument("--seed", type=int, default=0, help="OMPL's random seed (set once, before the first problem)")
    args = ap.parse_args(argv)
    if not (args.budget_s > 0 and args.resolution_rad > 0):
        sys.exit("--budget-s and --resolution-rad must be > 0")
    from ompl import util as ou
    ou.setLogLevel(ou.LOG_WARN)
    ou.RNG.setSeed(args.seed + 1)  # once, before any sampling (OMPL ignores a seed of 0)
    chains = {}
    results = [solve(p, chains, args.budget_s, args.resolution_rad) for p in load_problems(args.problems)]
    with open(args.out, "w", encoding="utf-8") as f:
        for r in results:
            f.write(json.dumps(r) + "\n")
    for line in summary(results):
        print(line)


if __name__ == "__main__":
    main()
