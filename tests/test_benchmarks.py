"""The benchmark scripts check their arguments and output paths before any work, as the command line does."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import HANG_S

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.mark.parametrize(
    ("script", "argv", "message"),
    [
        ("genrl.py", ["--episodes", "0"], "argument --episodes: must be an integer >= 1, got 0"),
        ("genrl.py", ["--task", "golf"], "argument --task: invalid choice: 'golf'"),
        (
            "genrl.py",
            ["--task", "basketball", "--out", "FILE/result.json"],
            "argument --out: 'FILE/result.json' cannot be created",
        ),
        ("genrl.py", ["--genrl-kwargs", '{"target_kl": 0.02}'], "--genrl-kwargs needs --out"),
        ("genrl.py", ["--library-defaults"], "--library-defaults needs --out"),
        (
            "genrl.py",
            ["--task", "basketball", "--genrl-kwargs", '{"hindsight_kwargs": {"history": 0}}', "--out", "r.json"],
            "argument --genrl-kwargs: hindsight_kwargs['history'] must be an integer >= 1, got 0",
        ),
        ("genrl.py", ["--genrl-kwargs", '{"hindsigt": true}', "--out", "r.json"], "hindsigt"),
        (
            "genrl.py",
            ["--library-defaults", "--genrl-kwargs", '{"hindsight_kwargs": {"regression_weighted": true}}', "--out", "r.json"],
            "argument --genrl-kwargs: hindsight_kwargs['regression_weighted']",
        ),
        (
            "genrl.py",
            ["--task", "basketball", "--genrl-kwargs", '{"e_step": "kl_penalty"}', "--out", "r.json"],
            "argument --genrl-kwargs: hindsight_kwargs needs e_step='trpo'",
        ),  # basketball's hindsight, laid over
        ("baselines.py", ["--task", "golf"], "argument --task: invalid choice: 'golf'"),
        ("baselines.py", ["--work", "FILE"], "argument --work: 'FILE' is a file; expected a folder"),
        ("baselines.py", ["--genrl-kwargs", '{"gama": 1}'], "argument --genrl-kwargs: 'gama' is not a GenRL setting"),
        ("behaviour_cloning.py", ["--out", "result.txt"], "argument --out: 'result.txt' must end in .json"),
        (
            "generator_training.py",
            ["--device", "bogus", "--out", "out.json"],
            "argument --device: must be 'auto' or a torch device",
        ),
        ("precision_recall.py", ["--out", "FOLDER"], "argument --out: 'FOLDER' is a folder; expected a file name"),
        ("precision_recall.py", ["--repeats", "0"], "argument --repeats: must be an integer >= 1, got 0"),
        ("sim_throughput.py", ["--repeats", "0"], "argument --repeats: must be an integer >= 1, got 0"),
        ("reachable.py", ["--task", "hockey", "--generator", "missing.pt", "--out", "out.json"], "missing.pt is not a file"),
    ],
)
def test_benchmarks_refuse_bad_arguments_before_any_work(tmp_path, script, argv, message):
    (tmp_path / "FILE").write_text("")
    (tmp_path / "FOLDER").mkdir()
    done = subprocess.run(
        [sys.executable, str(BENCHMARKS / script), *argv], cwd=tmp_path, capture_output=True, text=True, timeout=HANG_S
    )
    assert done.returncode == 2 and message in done.stderr, done.stderr
    assert done.stderr.splitlines()[-1].startswith(f"{script}: error: ")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["FILE", "FOLDER"]  # nothing was written


def test_the_benchmarks_are_a_package_without_path_edits():
    for path in sorted(BENCHMARKS.glob("*.py")):
        assert "sys.path" not in path.read_text() and "noqa: E402" not in path.read_text(), path.name
    done = subprocess.run(
        [sys.executable, "-m", "sb3_genrl.benchmarks.genrl", "--task", "hockey", "--episodes", "0"],
        capture_output=True,
        text=True,
        timeout=HANG_S,
    )
    assert done.returncode == 2 and "argument --episodes: must be an integer >= 1, got 0" in done.stderr


def test_the_genrl_benchmark_takes_the_tasks_entry_and_writes_its_default_output():
    from sb3_genrl.benchmarks.genrl import RESULTS, arguments

    from sb3_genrl.hyperparams import load_genrl_settings

    for task, env_id in (("hockey", "GenRL/Hockey-v0"), ("basketball", "GenRL/Basketball-v0")):
        setting, args = arguments(["--task", task])
        episodes, batch_episodes, kwargs = load_genrl_settings(env_id)
        assert (setting.task, args.episodes, args.genrl_kwargs) == (task, episodes, kwargs | {"n_steps": batch_episodes})
        assert args.out == str(Path(RESULTS) / f"genrl_{task}.json")  # genrl_hockey.json, genrl_basketball.json
    _, args = arguments(["--task", "hockey", "--genrl-kwargs", '{"hindsight_kwargs": {"history": 30}}', "--out", "r.json"])
    assert args.genrl_kwargs["hindsight_kwargs"] == {"history": 30, "regression_steps": 512}  # laid over the entry
    _, args = arguments(["--task", "hockey", "--library-defaults", "--out", "r.json"])
    assert args.genrl_kwargs == {}


def _result(methods, **changes):
    result = {
        "benchmark": "baselines",
        "task": "basketball",
        "horizon": 78,
        "episodes": 3000,
        "seeds": [0, 1, 2],
        "window": 64,
        "sb3_genrl": "1",
        "worst_reward": -16.0,
        "demos": "runs/demonstrations",
        "jobs": 1,
        "methods": {method: {"row": f"{method} of this result"} for method in methods},
    }
    return result | changes


def test_baselines_merge_keeps_the_other_methods_in_order_and_refuses_other_settings():
    from sb3_genrl.benchmarks.baselines_results import merge_results as merge

    previous = _result(["genrl", "ppo", "sac", "latent-trpo"], generator_sha256="abc")
    current = _result(["sac", "sac-her"], demo_dataset={"task": "basketball", "seed": 0, "episodes": 4000}, jobs=2)
    merged = merge(previous, current)
    assert list(merged["methods"]) == ["genrl", "ppo", "sac", "sac-her", "latent-trpo"]  # the benchmark's order
    assert merged["methods"]["sac"] == current["methods"]["sac"]  # a method run again replaces the earlier row
    assert merged["methods"]["genrl"] == previous["methods"]["genrl"]
    assert merged["merged_methods"] == ["genrl", "ppo", "latent-trpo"]
    assert merged["generator_sha256"] == "abc" and merged["jobs"] == 2  # kept from before; this call's own
    assert merged["demo_dataset"] == current["demo_dataset"]  # (not held by the earlier result: not compared)
    again = merge(merged, _result(["ppo"], demo_dataset=current["demo_dataset"]))
    assert again["merged_methods"] == ["genrl", "sac", "sac-her", "latent-trpo"]
    for key, value in [
        ("episodes", 1000),
        ("seeds", [0]),
        ("task", "hockey"),
        ("demos", "elsewhere"),
        ("generator_sha256", "other"),
        ("sb3_genrl", "2"),
    ]:
        with pytest.raises(ValueError, match=f"{key}: .* there, .* now"):
            merge(previous, _result(["sac"], **{key: value}))
    with pytest.raises(ValueError, match="demo_dataset"):
        merge(merged, _result(["sac"], demo_dataset={"task": "basketball", "seed": 1, "episodes": 4000}))


def test_baselines_merge_refuses_a_result_of_other_settings_before_any_work(tmp_path):
    out = tmp_path / "result.json"
    out.write_text(json.dumps(_result(["sac"])))  # basketball, 3000 episodes, seeds 0 1 2
    done = subprocess.run(
        [
            sys.executable,
            str(BENCHMARKS / "baselines.py"),
            "--task",
            "basketball",
            "--episodes",
            "40",
            "--methods",
            "sac-her",
            "--merge",
            "--out",
            str(out),
            "--work",
            str(tmp_path / "work"),
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=HANG_S,
    )
    assert done.returncode != 0 and "--merge: cannot merge into" in done.stderr, done.stderr
    assert "episodes: 3000 there, 40 now" in done.stderr
    assert sorted(path.name for path in tmp_path.iterdir()) == ["result.json"]  # no runs, demonstrations or output


def test_baselines_reuses_an_archived_runs_evaluation_and_refuses_a_stale_one(tmp_path):
    from sb3_genrl.baselines.evaluation import EVAL_GOALS
    from sb3_genrl.benchmarks import baselines as module

    import sb3_genrl
    from sb3_genrl.hyperparams import EVAL_GOAL_SEED

    run = tmp_path / "sac" / "seed0"
    run.mkdir(parents=True)
    with pytest.raises(ValueError, match="has neither sac_policy.zip nor its final evaluation"):
        module.final_evaluation(run, "sac", "basketball", None)
    record = {
        "policy_sha256": "digest of the policy it had",
        "task": "basketball",
        "goals": EVAL_GOALS,
        "goal_seed": EVAL_GOAL_SEED,
        "generator_sha256": None,
        "sb3_genrl": sb3_genrl.__version__,
    } | {name: 1.0 for name in module.FINAL_RESULTS}
    (run / "final_eval.json").write_text(json.dumps(record))
    assert module.final_evaluation(run, "sac", "basketball", None) == record  # no policy file to evaluate again
    with pytest.raises(ValueError, match="its final_eval.json was made with another task"):
        module.final_evaluation(run, "sac", "hockey", None)
    (run / "final_eval.json").write_text(json.dumps(record | {"sb3_genrl": "0.0.1"}))
    with pytest.raises(ValueError, match="was made with another sb3_genrl"):
        module.final_evaluation(run, "sac", "basketball", None)
    del record["object_unmoved"]
    (run / "final_eval.json").write_text(json.dumps(record))
    with pytest.raises(ValueError, match="its final_eval.json lacks object_unmoved"):
        module.final_evaluation(run, "sac", "basketball", None)
