"""benchmarks/metaworld.py at tiny sizes: every unit of a task written to its JSON and table, a rerun resumes without
work, and a rerun with other settings is refused before any."""

import functools
import json
import shutil

import pytest
from sb3_genrl.envs import metaworld
from stable_baselines3 import SAC

from sb3_genrl.generative import load

pytestmark = pytest.mark.skipif(not metaworld.installed(), reason=metaworld.INSTALL_HINT)

TINY = ["--tasks", "reach-v3", "--seeds", "0", "--demos", "4", "--epochs", "2", "--episodes", "4", "--batch-episodes", "4"]
TINY += ["--held-out", "4", "--fit-steps", "10"]


@pytest.fixture(autouse=True)
def tiny_stages(monkeypatch):
    """The horizon found from 8 of the expert's resets instead of 100 (each a Meta-World episode of 500 steps), and the
    generator trained for the given epochs instead of at least 4800 minibatch steps."""
    import benchmarks.metaworld as benchmark

    monkeypatch.setattr(benchmark, "expert_horizon", functools.partial(benchmark.expert_horizon, resets=8))
    monkeypatch.setattr(benchmark, "OUTSIDE_GENERATOR_TRAINING", benchmark.OUTSIDE_GENERATOR_TRAINING | {"min_steps": 0})


def test_the_metaworld_benchmark_writes_every_unit_resumes_and_refuses_other_settings(tmp_path, capsys):
    from benchmarks.metaworld import main

    out, work = tmp_path / "metaworld.json", tmp_path / "work"
    argv = [*TINY, "--work", str(work), "--out", str(out)]
    assert main(argv) == 0
    result = json.loads(out.read_text())
    row = result["tasks"]["reach-v3"]
    assert result["settings"]["held_out"] == 4 and result["settings"]["held_out_seed"] == 2**31
    assert "git_commit" in result and result["sb3_genrl"] and result["complete"] is False  # one task and one seed of MT10 x 3
    assert row["demonstrations"]["episodes"] == 4 and row["expert"]["closed_loop"] == row["expert"]["open_loop"] == 1.0
    for method in ("fit", "genrl", "sac"):
        unit = row[method]["0"]
        assert 0.0 <= unit["success"] <= 1.0 and unit["cpu_seconds"] >= 0.0, method
    assert row["genrl"]["0"]["episodes"] == 4 and row["sac"]["0"]["episodes"] == 4
    # the horizon found from the expert, as the quickstart finds it, and the expert scored at it
    assert row["horizon"]["settled"] and row["horizon"]["horizon"] < 100 and row["horizon"]["resets"] == 8
    assert row["reconstruction"]["demonstrations"] == 4 and 0.0 <= row["reconstruction"]["success"] <= 1.0
    # the generator trained as the quickstart trains an outside task's (its checkpoint chosen by its reconstructions)
    assert load(work / "reach-v3" / "vae.pt").selection == result["settings"]["generator_training"]["selection"]
    assert result["settings"]["generator_training"]["selection"] == "reconstruction"
    assert f"| reach-v3 | {row['horizon']['horizon']} | 1.000 | 1.000 |" in out.with_suffix(".md").read_text()
    # the same command again: nothing redone
    stamps = {path: path.stat().st_mtime_ns for path in (work / "reach-v3").rglob("*") if path.is_file()}
    assert main(argv) == 0
    assert json.loads(out.read_text())["tasks"] == result["tasks"]
    assert all(path.stat().st_mtime_ns == stamp for path, stamp in stamps.items() if path.name != "stage.json")
    # a second seed of the fit and GenRL, SAC's seeds as they were: only the new units run
    assert main([*argv, "--seeds", "0", "1", "--sac-seeds", "0"]) == 0
    row = json.loads(out.read_text())["tasks"]["reach-v3"]
    assert sorted(row["fit"]) == sorted(row["genrl"]) == ["0", "1"] and sorted(row["sac"]) == ["0"]
    assert row["genrl"]["0"] == result["tasks"]["reach-v3"]["genrl"]["0"]
    # the work folder made anew, the JSON kept: the seeded dataset is recorded again and SAC's new seed learns from it
    shutil.rmtree(work)
    assert main([*argv, "--seeds", "--sac-seeds", "1"]) == 0
    assert sorted(json.loads(out.read_text())["tasks"]["reach-v3"]["sac"]) == ["0", "1"]
    # ... and a dataset that is not the one the JSON records is refused, naming both
    shutil.rmtree(work)
    recorded = json.loads(out.read_text())
    recorded["tasks"]["reach-v3"]["demonstrations"]["tried"] += 1
    out.write_text(json.dumps(recorded))
    with pytest.raises(RuntimeError, match="differs from the demonstrations"):
        main([*argv, "--seeds", "--sac-seeds", "2"])
    recorded["tasks"]["reach-v3"]["demonstrations"]["tried"] -= 1
    out.write_text(json.dumps(recorded))
    # other settings: refused before any work, naming the setting
    before = out.read_text()
    with pytest.raises(SystemExit) as exit_:
        main([*argv, "--demos", "5"])
    assert exit_.value.code == 2 and "demos 4 (recorded) vs 5 (this run)" in capsys.readouterr().err
    assert out.read_text() == before


def test_sac_rows_are_taken_from_an_earlier_result_of_the_same_sac_settings_and_data(tmp_path, capsys):
    """--sac-from: GenRL's units made anew (another generator), SAC's taken from an earlier result, which must record
    the same SAC settings (refused before any work) and the same demonstrations (refused as they are recorded)."""
    from benchmarks.metaworld import main

    earlier, work = tmp_path / "earlier.json", tmp_path / "work"
    assert main([*TINY, "--seeds", "--work", str(work), "--out", str(earlier)]) == 0  # SAC's unit alone
    sac = json.loads(earlier.read_text())["tasks"]["reach-v3"]["sac"]
    out = tmp_path / "new.json"
    argv = [*TINY, "--epochs", "3", "--work", str(tmp_path / "new"), "--out", str(out), "--sac-from", str(earlier)]
    with pytest.raises(SystemExit) as exit_:
        main([*argv, "--episodes", "8"])
    message = capsys.readouterr().err
    assert exit_.value.code == 2 and "argument --sac-from" in message and "episodes 4 (recorded) vs 8 (this run)" in message
    assert not out.exists()
    assert main(argv) == 0
    result = json.loads(out.read_text())
    row = result["tasks"]["reach-v3"]
    assert row["sac"] == sac and row["sac_from"]["file"] == str(earlier) and result["settings"]["epochs"] == 3
    assert "0" in row["genrl"] and not (tmp_path / "new" / "reach-v3" / "sac_seed0").exists()  # SAC not run again
    assert f"SAC's rows: from {earlier}" in out.with_suffix(".md").read_text()
    # rows taken on from a result that took them from another keep where they were made
    chained = tmp_path / "chained.json"
    argv = [*TINY, "--epochs", "3", "--work", str(tmp_path / "chained"), "--out", str(chained), "--sac-from", str(out)]
    assert main(argv) == 0
    assert json.loads(chained.read_text())["tasks"]["reach-v3"]["sac_from"] == row["sac_from"]
    assert f"SAC's rows: from {earlier}" in chained.with_suffix(".md").read_text()
    recorded = json.loads(earlier.read_text())
    recorded["tasks"]["reach-v3"]["demonstrations"]["tried"] += 1  # rows made from other demonstrations
    earlier.write_text(json.dumps(recorded))
    third = [*TINY, "--seeds", "--epochs", "3", "--work", str(tmp_path / "new"), "--out", str(tmp_path / "third.json")]
    with pytest.raises(RuntimeError, match="SAC rows were made from the demonstrations"):
        main([*third, "--sac-from", str(earlier)])


def test_the_metaworld_benchmark_refuses_an_unknown_task_before_any_work(tmp_path, capsys):
    from benchmarks.metaworld import main

    with pytest.raises(SystemExit) as exit_:
        main(["--tasks", "push", "--work", str(tmp_path / "work"), "--out", str(tmp_path / "r.json")])
    assert exit_.value.code == 2 and "unknown Meta-World task 'push'" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_runs_of_other_tasks_into_one_json_keep_each_others_rows(tmp_path, monkeypatch):
    """Two runs of the benchmark with other --tasks (as on two cores) write one JSON: each save keeps the other's rows."""
    import benchmarks.metaworld as benchmark

    out, work = tmp_path / "metaworld.json", tmp_path / "work"
    run_task = benchmark.run_task

    def other_run_writes_first(task, args, result, save):  # the other run saves its task after this one started
        other = {"benchmark": "metaworld", "settings": benchmark.settings(args), "tasks": {"push-v3": {"expert": {}}}}
        out.write_text(json.dumps(other))
        run_task(task, args, result, save)

    monkeypatch.setattr(benchmark, "run_task", other_run_writes_first)
    assert benchmark.main([*TINY, "--sac-seeds", "--work", str(work), "--out", str(out)]) == 0
    tasks = json.loads(out.read_text())["tasks"]
    assert list(tasks) == ["reach-v3", "push-v3"]  # MT10's order
    assert tasks["push-v3"] == {"expert": {}} and "0" in tasks["reach-v3"]["genrl"]
    lines = out.with_suffix(".md").read_text().splitlines()
    reach = next(line for line in lines if line.startswith("| reach-v3 |"))
    assert "| not run |" in reach and lines[-1].startswith("| mean over the 2 tasks |")  # no SAC seed asked for
    assert not out.with_name("metaworld.json.lock").exists()


def test_a_stopped_sac_run_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    """SAC's run (hours per task, ``genrl baseline sac``'s) checkpoints its model and replay buffer; the same command
    after a stop goes on from the checkpoint's episode, says so in its row, and a finished run keeps its model, not its
    checkpoint."""
    from sb3_genrl.baselines import train as baseline_train

    import benchmarks.metaworld as benchmark

    out, work = tmp_path / "metaworld.json", tmp_path / "work"
    argv = [*TINY, "--seeds", "--episodes", "6", "--work", str(work), "--out", str(out)]
    monkeypatch.setattr(benchmark, "SAC_CHECKPOINT_EVERY", 2)
    checkpoint = baseline_train.ReplayBufferCheckpoint

    class StopAfterFirstCheckpoint(checkpoint):
        def save(self, episodes):
            super().save(episodes)
            raise KeyboardInterrupt  # the run stopped right after its first checkpoint

    monkeypatch.setattr(baseline_train, "ReplayBufferCheckpoint", StopAfterFirstCheckpoint)
    with pytest.raises(KeyboardInterrupt):
        benchmark.main(argv)
    folder = work / "reach-v3" / "sac_seed0"
    state = json.loads((folder / "checkpoint" / "state.json").read_text())
    assert state["episodes"] == 2 and "sac" not in json.loads(out.read_text())["tasks"]["reach-v3"]
    monkeypatch.setattr(baseline_train, "ReplayBufferCheckpoint", checkpoint)
    assert benchmark.main(argv) == 0
    row = json.loads(out.read_text())["tasks"]["reach-v3"]["sac"]["0"]
    assert row["resumed_at_episodes"] == [2] and row["episodes"] == 6 and row["cpu_seconds"] > 0.0
    assert (folder / "sac_policy.zip").is_file() and not (folder / "checkpoint").exists()
    horizon = json.loads(out.read_text())["tasks"]["reach-v3"]["horizon"]["horizon"]
    assert SAC.load(folder / "sac_policy.zip").num_timesteps == 6 * horizon
    # the row's success is the saved policy's on the held-out resets, as genrl baseline sac scores it
    summary = json.loads((folder / "summary.json").read_text())
    assert row["success"] == summary["final_eval"]["success_rate"] and summary["final_eval"]["resets"] == 4


def test_the_horizons_benchmark_writes_each_tasks_horizon_and_cost_and_resumes(tmp_path, monkeypatch):
    import benchmarks.metaworld_horizons as horizons

    monkeypatch.setattr(horizons, "expert_horizon", functools.partial(horizons.expert_horizon, resets=8))
    monkeypatch.setattr(horizons, "COST_RESETS", 2)
    out = tmp_path / "horizons.json"
    assert horizons.main(["--tasks", "reach-v3", "--out", str(out)]) == 0
    row = json.loads(out.read_text())["tasks"]["reach-v3"]
    assert row["settled"] and row["resets"] == 8 and 0 < row["expert_mean_steps"] <= row["horizon"] < 500
    assert row["horizon_episode_ms"] == pytest.approx(row["step_ms"] * row["horizon"], abs=0.1)
    assert f"| reach-v3 | {row['horizon']} | yes |" in out.with_suffix(".md").read_text()
    stamp = out.stat().st_mtime_ns
    assert horizons.main(["--tasks", "reach-v3", "--out", str(out)]) == 0 and out.stat().st_mtime_ns == stamp  # done
