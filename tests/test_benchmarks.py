"""The benchmark scripts check their arguments and output paths before any work, as the command line does."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from conftest import HANG_S

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"


def _run_benchmark(script: str, argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """``python -m benchmarks.<name> ARGV`` as run from the repository root, in ``cwd`` (the root on PYTHONPATH)."""
    environment = os.environ | {"PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    return subprocess.run(
        [sys.executable, "-m", f"benchmarks.{Path(script).stem}", *argv],
        cwd=cwd,
        env=environment,
        capture_output=True,
        text=True,
        timeout=HANG_S,
    )


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
            ["--task", "basketball", "--genrl-kwargs", '{"hindsight_kwargs": {"history": -1}}', "--out", "r.json"],
            "argument --genrl-kwargs: hindsight_kwargs['history'] must be an integer >= 0, got -1",
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
    done = _run_benchmark(script, argv, tmp_path)
    assert done.returncode == 2 and message in done.stderr, done.stderr
    # argparse names the script by its file (Python 3.14: by its -m command)
    assert done.stderr.splitlines()[-1].split(": error: ")[0] in (script, f"python -m benchmarks.{Path(script).stem}")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["FILE", "FOLDER"]  # nothing was written


def test_the_benchmarks_are_a_package_without_path_edits():
    for path in sorted(BENCHMARKS.glob("*.py")):
        assert "sys.path" not in path.read_text() and "noqa: E402" not in path.read_text(), path.name
    done = subprocess.run(  # as the docs run it: from the repository root, nothing on PYTHONPATH
        [sys.executable, "-m", "benchmarks.genrl", "--task", "hockey", "--episodes", "0"],
        cwd=ROOT,
        env={name: value for name, value in os.environ.items() if name != "PYTHONPATH"},
        capture_output=True,
        text=True,
        timeout=HANG_S,
    )
    assert done.returncode == 2 and "argument --episodes: must be an integer >= 1, got 0" in done.stderr


@pytest.mark.slow
def test_the_wheel_ships_the_library_and_not_the_benchmark_scripts(tmp_path):
    # the wheel built from a copy of the source tree (the build writes its build/ and egg-info beside the sources)
    source = tmp_path / "source"
    for folder in ("sb3_genrl", "envs", "baselines", "hyperparams", "benchmarks"):
        shutil.copytree(ROOT / folder, source / folder, ignore=shutil.ignore_patterns("__pycache__", "results"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, source / name)
    done = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-w", "wheel", "./source"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=HANG_S,
    )
    assert done.returncode == 0, done.stderr
    (wheel,) = (tmp_path / "wheel").glob("sb3_genrl-*.whl")
    shipped = set(zipfile.ZipFile(wheel).namelist())
    assert not {name for name in shipped if name.startswith(("benchmarks/", "sb3_genrl/benchmarks/"))}
    # every module of the library, its tasks and its baselines, installed under sb3_genrl (pyproject's package-dir)
    library = {
        (installed + "/" + path.relative_to(ROOT / folder).as_posix())
        for folder, installed in (("sb3_genrl", "sb3_genrl"), ("envs", "sb3_genrl/envs"), ("baselines", "sb3_genrl/baselines"))
        for path in (ROOT / folder).rglob("*.py")
    }
    assert {"sb3_genrl/envs/__init__.py", "sb3_genrl/baselines/__init__.py"} <= library
    assert sorted(library - shipped) == []


def test_the_genrl_benchmark_takes_the_tasks_entry_and_writes_its_default_output():
    from benchmarks.genrl import RESULTS, arguments
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


def test_the_throughput_update_replaces_a_tasks_rows_of_the_same_kind_whatever_its_batch(tmp_path):
    from benchmarks.genrl_throughput import updated_runs

    def row(task, n_envs, batch, cli=False):
        kept = {"task": task, "n_envs": f"cli ({n_envs})" if cli else n_envs, "batch": batch}
        return kept | ({"cli_command": "genrl train-policy"} if cli else {"batch_episodes": batch})

    before = [row("hockey", 2, 16), row("hockey", 16, 16), row("hockey", 16, 16, cli=True)]
    before += [row("basketball", 2, 16), row("basketball", 16, 16), row("basketball", 16, 16, cli=True)]
    path = tmp_path / "throughput.json"
    path.write_text(json.dumps({"runs": before}))
    # hockey measured again with a batch of 32: its "N" row (32 envs) and its CLI row replace the 16-episode ones
    measured = [row("hockey", 32, 32, cli=True), row("hockey", 2, 32), row("hockey", 32, 32)]
    runs = updated_runs(str(path), measured)
    assert [(r["task"], r["n_envs"], r["batch"]) for r in runs] == [
        ("hockey", 2, 32),
        ("hockey", 32, 32),
        ("hockey", "cli (32)", 32),
        ("basketball", 2, 16),
        ("basketball", 16, 16),
        ("basketball", "cli (16)", 16),
    ]
    assert updated_runs(str(tmp_path / "none.json"), measured[:1]) == measured[:1]


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
    from benchmarks.baselines_results import merge_results as merge

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
    done = _run_benchmark(
        "baselines.py",
        [
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
        tmp_path,
    )
    assert done.returncode != 0 and "--merge: cannot merge into" in done.stderr, done.stderr
    assert "episodes: 3000 there, 40 now" in done.stderr
    assert sorted(path.name for path in tmp_path.iterdir()) == ["result.json"]  # no runs, demonstrations or output


def test_baselines_reuses_an_archived_runs_evaluation_and_refuses_a_stale_one(tmp_path):
    from sb3_genrl.baselines.evaluation import EVAL_GOALS

    import sb3_genrl
    from benchmarks import baselines as module
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
