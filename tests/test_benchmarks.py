"""The benchmark scripts check their arguments and output paths before any work, as the command line does."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.mark.parametrize(("script", "argv", "message"), [
    ("genrl_hockey.py", ["--episodes", "0"], "argument --episodes: must be an integer >= 1, got 0"),
    ("genrl_basketball.py", ["--out", "FILE/result.json"], "argument --out: 'FILE/result.json' cannot be created"),
    ("genrl_hockey.py", ["--genrl-kwargs", '{"hindsight": true}'], "--genrl-kwargs needs --out"),
    ("genrl_hockey.py", ["--library-defaults"], "--library-defaults needs --out"),
    ("genrl_basketball.py", ["--genrl-kwargs", '{"hindsight": false}', "--out", "r.json"],
     "argument --genrl-kwargs: hindsight_history"),
    ("genrl_hockey.py", ["--genrl-kwargs", '{"hindsigt": true}', "--out", "r.json"], "hindsigt"),
    ("genrl_hockey.py", ["--library-defaults", "--genrl-kwargs", '{"hindsight_regression": 8}', "--out", "r.json"],
     "argument --genrl-kwargs: hindsight_regression=8 fits the policy to relabelled pulls, which needs hindsight=True"),
    ("baselines.py", ["--task", "golf"], "argument --task: invalid choice: 'golf'"),
    ("baselines.py", ["--work", "FILE"], "argument --work: 'FILE' is a file; expected a folder"),
    ("behaviour_cloning.py", ["--out", "result.txt"], "argument --out: 'result.txt' must end in .json"),
    ("generator_training.py", ["--device", "bogus", "--out", "out.json"],
     "argument --device: must be 'auto' or a torch device"),
    ("precision_recall.py", ["--out", "FOLDER"], "argument --out: 'FOLDER' is a folder; expected a file name"),
    ("sim_throughput.py", ["--repeats", "0"], "argument --repeats: must be an integer >= 1, got 0"),
    ("genrl_tuning.py", ["--generator", "missing.pt"], "argument --generator: 'missing.pt' does not exist"),
    ("network_fit.py", ["--task", "hockey", "--generator", "missing.pt"], "argument --generator: 'missing.pt' does not exist"),
    ("network_fit.py", ["--task", "hockey", "--generator", "FILE", "--out", "FOLDER"], "argument --out: 'FOLDER' is a folder"),
    ("network_fit.py", ["--task", "golf", "--generator", "FILE"], "argument --task: invalid choice: 'golf'"),
    ("basketball_diagnosis.py", ["--data", "FOLDER", "--generator", "FILE", "--name", "../x"], "argument --name: '../x'"),
    ("reachable.py", ["--task", "hockey", "--generator", "missing.pt", "--out", "out.json"], "missing.pt is not a file"),
])
def test_benchmarks_refuse_bad_arguments_before_any_work(tmp_path, script, argv, message):
    (tmp_path / "FILE").write_text("")
    (tmp_path / "FOLDER").mkdir()
    done = subprocess.run([sys.executable, str(BENCHMARKS / script), *argv], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2 and message in done.stderr, done.stderr
    assert done.stderr.splitlines()[-1].startswith(f"{script}: error: ")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["FILE", "FOLDER"]  # nothing was written


def _baselines_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("baselines_benchmark", BENCHMARKS / "baselines.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _result(methods, **changes):
    result = {"benchmark": "baselines", "task": "basketball", "horizon": 78, "episodes": 3000, "seeds": [0, 1, 2],
              "window": 64, "sb3_genrl": "1", "worst_reward": -16.0, "demos": "runs/demonstrations", "jobs": 1,
              "methods": {method: {"row": f"{method} of this result"} for method in methods}}
    return result | changes


def test_baselines_merge_keeps_the_other_methods_in_order_and_refuses_other_settings():
    merge = _baselines_module().merge_results
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
    for key, value in [("episodes", 1000), ("seeds", [0]), ("task", "hockey"), ("demos", "elsewhere"),
                       ("generator_sha256", "other"), ("sb3_genrl", "2")]:
        with pytest.raises(ValueError, match=f"{key}: .* there, .* now"):
            merge(previous, _result(["sac"], **{key: value}))
    with pytest.raises(ValueError, match="demo_dataset"):
        merge(merged, _result(["sac"], demo_dataset={"task": "basketball", "seed": 1, "episodes": 4000}))


def test_baselines_merge_refuses_a_result_of_other_settings_before_any_work(tmp_path):
    out = tmp_path / "result.json"
    out.write_text(json.dumps(_result(["sac"])))  # basketball, 3000 episodes, seeds 0 1 2
    done = subprocess.run([sys.executable, str(BENCHMARKS / "baselines.py"), "--task", "basketball", "--episodes", "40",
                           "--methods", "sac-her", "--merge", "--out", str(out), "--work", str(tmp_path / "work")],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode != 0 and "--merge: cannot merge into" in done.stderr, done.stderr
    assert "episodes: 3000 there, 40 now" in done.stderr
    assert sorted(path.name for path in tmp_path.iterdir()) == ["result.json"]  # no runs, demonstrations or output


def test_baselines_reuses_an_archived_runs_evaluation_and_refuses_a_stale_one(tmp_path):
    from sb3_genrl.baselines.train import EVAL_GOAL_SEED, EVAL_GOALS

    import sb3_genrl

    module = _baselines_module()
    run = tmp_path / "sac" / "seed0"
    run.mkdir(parents=True)
    with pytest.raises(ValueError, match="has neither sac_policy.zip nor its final evaluation"):
        module.final_evaluation(run, "sac", "basketball", None)
    record = {"policy_sha256": "digest of the policy it had", "task": "basketball", "goals": EVAL_GOALS,
              "goal_seed": EVAL_GOAL_SEED, "generator_sha256": None, "sb3_genrl": sb3_genrl.__version__} \
        | {name: 1.0 for name in module.FINAL_RESULTS}
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
