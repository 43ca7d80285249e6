"""The study scripts under scripts/studies/ that results depend on."""

import importlib.util
import os
import tarfile

SCRIPTS = os.path.join(os.path.dirname(__file__), "..", "..", "scripts", "studies")


def load(name):
    spec = importlib.util.spec_from_file_location(name, os.path.join(SCRIPTS, f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_pack_runs_leaves_out_tensorboard_events_and_checkpoints_but_those_kept(tmp_path):
    pack_runs = load("pack_runs")
    runs = tmp_path / "sweep"
    for name in ["sac-sar-seed1", "sac-sar-seed2"]:
        run = runs / name
        (run / "tb").mkdir(parents=True)
        (run / "checkpoints").mkdir()
        (run / "config.toml").write_text("[agent]\n")
        (run / "episodes.csv").write_text("episode,reward,env_steps,wall_s\n1,0.12345,10,0.01\n2,1.5,25,0.02\n")
        (run / "tb" / "events.out.tfevents.1.vm").write_bytes(b"\0" * 64)
        (run / "checkpoints" / "best.safetensors").write_bytes(b"\1" * 32)
        (run / "checkpoints" / "latest.safetensors").write_bytes(b"\2" * 32)
    (runs / "preset.toml").write_text("[sweep]\n")
    dest = tmp_path / "runs.tar.xz"
    keep = {"sac-sar-seed1/checkpoints/best.safetensors"}
    files, _, _ = pack_runs.pack(str(runs), str(dest), keep)
    with tarfile.open(dest) as tar:
        names = sorted(tar.getnames())
    assert names == [
        "runs/preset.toml",
        "runs/sac-sar-seed1/checkpoints/best.safetensors",
        "runs/sac-sar-seed1/config.toml",
        "runs/sac-sar-seed1/episodes.csv.T",
        "runs/sac-sar-seed2/config.toml",
        "runs/sac-sar-seed2/episodes.csv.T",
    ]
    assert files == len(names)
    # Unpacked, the episode log is a CSV again, its running env_steps summed back.
    out = tmp_path / "plain"
    pack_runs.unpack(str(dest), str(out))
    rows = (out / "runs" / "sac-sar-seed1" / "episodes.csv").read_text().splitlines()
    assert rows[0].split(",")[0] == "episode" and rows[2].split(",")[rows[0].split(",").index("env_steps")] == "25"


def test_obstacle_summary_counts_successes_and_contacts_and_refuses_a_missing_evaluation(tmp_path, capsys):
    summary = load("obstacle_summary")
    run = tmp_path / "her-s2"
    run.mkdir()
    (run / "episodes.csv").write_text(
        "episode,reward,steps,success,final_distance_m,env_steps,collision_steps,curriculum_stage,wall_s\n"
        "1,0,5,0,0.3,5,0,0,0.0\n2,21,4,1,0.005,9,0,1,0.1\n3,21,4,1,0.005,13,0,1,0.2\n4,-10,2,0,0.2,15,1,2,12.6\n"
    )
    header = "trial,reward,steps,success,collision_steps\n"
    # 500 trials each: successes and trials with a contact step (a count, not a flag) differ per file.
    for i, (_, file) in enumerate(summary.EVALS):
        rows = [f"{t},0,5,{int(t <= 100 * (i + 1))},{3 if t > 490 - i else 0}\n" for t in range(1, 501)]
        (run / file).write_text(header + "".join(rows))
    summary.main(str(tmp_path))
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("config,seed,episodes,env_steps,train_wall_s,stages_began_at_episode,success_alone")
    assert out[1] == "her,2,4,15,13,2;4,20.0,2.0,40.0,2.2,60.0,2.4,80.0,2.6"
    # A run whose shielded evaluation did not run is an error naming the file, not a row of zeros.
    (run / summary.EVALS[1][1]).unlink()
    try:
        summary.main(str(tmp_path))
    except SystemExit as e:
        assert summary.EVALS[1][1] in str(e) and "missing" in str(e)
    else:
        raise AssertionError("a missing evaluation was not refused")
    # A run trained behind the shield: alone is its --no-shield evaluation, shielded its own.
    (run / summary.EVALS[1][1]).write_text(header + "".join(f"{t},0,5,1,0\n" for t in range(1, 501)))
    (run / "config.toml").write_text("[task.shield]\nenabled = true\n")
    for i, (_, file) in enumerate(summary.SHIELD_TRAINED_EVALS):
        rows = [f"{t},0,5,{int(t <= 50 * (i + 1))},{1 if t > 500 - 10 * i else 0}\n" for t in range(1, 501)]
        (run / file).write_text(header + "".join(rows))
    summary.main(str(tmp_path))
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == "her,2,4,15,13,2;4,10.0,0.0,20.0,2.0,30.0,4.0,40.0,6.0", out[-1]


def test_obstacle_seeds_averages_each_config_over_its_seeds(tmp_path, capsys):
    seeds = load("obstacle_seeds")
    summary = tmp_path / "summary.csv"
    cols = ["success_alone", "collisions_alone", "success_shield", "collisions_shield", "success_in_way_alone",
            "collisions_in_way_alone", "success_in_way_shield", "collisions_in_way_shield"]
    head = "config,seed,episodes,env_steps,train_wall_s,stages_began_at_episode," + ",".join(cols)
    summary.write_text(head + "\n"
                       "a,1,10,100,50,,80.0,5.0,81.0,0.0,50.0,20.0,60.0,0.0\n"
                       "a,2,10,100,70,,90.0,7.0,91.0,0.0,60.0,30.0,70.0,0.0\n"
                       "b,1,10,100,9,,70.0,1.0,71.0,0.0,40.0,10.0,45.0,0.0\n")
    seeds.main(str(summary), ["b", "a"])
    out = capsys.readouterr().out.splitlines()
    assert out[2] == "| `b` | 1 | 70.0 / 1.0 | 71.0 / 0.0 | 40.0 / 10.0 | 45.0 / 0.0 | 9-9 |", out[2]
    assert out[3] == ("| `a` | 1,2 | 85.0 [80.0-90.0] / 6.0 [5.0-7.0] | 86.0 [81.0-91.0] / 0.0 [0.0-0.0] "
                      "| 55.0 [50.0-60.0] / 25.0 [20.0-30.0] | 65.0 [60.0-70.0] / 0.0 [0.0-0.0] | 50-70 |"), out[3]
    try:
        seeds.main(str(summary), ["c"])
    except SystemExit as e:
        assert "'c'" in str(e)
    else:
        raise AssertionError("a missing config was not refused")


def test_bench_seeds_averages_each_set_and_planner_over_the_seeds(tmp_path, capsys):
    seeds = load("bench_seeds")
    head = ("obstacles: 200 problems per set\n| planner | set | success % | collision % | path length m |\n"
            "|---|---|---|---|---|\n")
    files = []
    for seed, (ok, hit) in [(1, (80.0, 10.0)), (2, (90.0, 4.0))]:
        f = tmp_path / f"bench-a-b-s{seed}.md"
        f.write_text(head + f"| policy | in-the-way | {ok} | {hit} | 0.5 |\n| policy+shield | in-the-way | {ok + 5} | 0.0 | - |\n")
        files.append(str(f))
    one = tmp_path / "bench-c-s3.md"
    one.write_text(head + "| policy | free | 100.0 | 0.0 | 0.4 |\n")
    seeds.main(files + [str(one)])
    out = capsys.readouterr().out.splitlines()
    assert out[2] == "| `a-b` | 1,2 | in-the-way | policy | 85.0 [80.0-90.0] | 7.0 [4.0-10.0] |", out[2]
    assert out[3] == "| `a-b` | 1,2 | in-the-way | policy+shield | 90.0 [85.0-95.0] | 0.0 [0.0-0.0] |", out[3]
    assert out[4] == "| `c` | 3 | free | policy | 100.0 | 0.0 |", out[4]
    # A seed that ran other sets is refused rather than averaged over fewer seeds.
    other = tmp_path / "bench-c-s4.md"
    other.write_text(head + "| policy | narrow-gap | 0.0 | 100.0 | - |\n")
    for bad, word in [([str(one), str(other)], "other sets"), ([str(tmp_path / "x.md")], "not named"),
                      ([str(tmp_path / "bench-d-s1.md")], "missing")]:
        try:
            seeds.main(bad)
        except SystemExit as e:
            assert word in str(e), e
        else:
            raise AssertionError(f"{bad} was not refused")
