"""The settings files (``hyperparams/<algo>.yml``) and their loader, :mod:`sb3_genrl.hyperparams`."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import pytest
import yaml
from torch import nn

from sb3_genrl import hyperparams
from sb3_genrl.hyperparams import (
    EVAL_GOAL_SEED,
    TUNING_GOAL_SEED,
    known_algos,
    lay_over,
    load_genrl_settings,
    load_hyperparams,
    parse_kwargs,
)
from sb3_genrl.study.quickstart import DEFAULT_BATCH_EPISODES, DEFAULT_POLICY_EPISODES, OUTSIDE_TASK_KWARGS

ROOT = Path(__file__).resolve().parents[1]


def test_every_file_is_installed_and_every_entry_loads():
    assert set(known_algos()) == {path.stem for path in (ROOT / "hyperparams").glob("*.yml")}
    assert {"genrl", "ppo", "sac"} <= set(known_algos())
    for algo in known_algos():
        for env_id in hyperparams._entries(algo):
            entry = load_hyperparams(algo, env_id)
            assert isinstance(entry["n_timesteps"], int) and isinstance(entry["policy"], str), (algo, env_id)
            assert isinstance(entry.get("policy_kwargs", {}), dict)
    assert load_hyperparams("ppo", "GenRL/Hockey-v0")["policy_kwargs"]["activation_fn"] is nn.ReLU


def test_an_entry_is_a_fresh_copy():
    entry = load_hyperparams("genrl", "GenRL/Hockey-v0")
    entry["hindsight_kwargs"]["history"] = 1
    assert load_hyperparams("genrl", "GenRL/Hockey-v0")["hindsight_kwargs"]["history"] == 60


def test_unknown_env_ids_and_algorithms_are_refused_naming_what_is_known():
    with pytest.raises(
        ValueError,
        match=r"hyperparams/genrl\.yml has no entry for 'GenRL/Golf-v0'; known env ids: "
        r"FetchPickAndPlace-v4, FetchPush-v4, FetchReach-v4, FetchSlide-v4, "
        r"GenRL/Basketball-v0, GenRL/Hockey-v0",
    ):
        load_hyperparams("genrl", "GenRL/Golf-v0")
    with pytest.raises(ValueError, match=r"no settings file tqc\.yml for 'tqc'; known: genrl, .*ppo, sac"):
        load_hyperparams("tqc", "GenRL/Hockey-v0")


def test_genrl_settings_of_the_tasks():
    assert load_genrl_settings("GenRL/Hockey-v0") == (
        3000,
        32,
        {
            "policy": "MlpPolicy",
            "hindsight_kwargs": {"history": 60, "regression_steps": 512},
            "policy_kwargs": {"net_arch": {"pi": [64, 64, 64], "vf": [64, 64]}},
        },
    )
    episodes, batch_episodes, kwargs = load_genrl_settings("GenRL/Basketball-v0")
    assert (episodes, batch_episodes, kwargs["policy"], kwargs["hindsight_kwargs"]) == (
        20000,
        16,
        "ContextStdPolicy",
        {"history": 60, "regression_steps": 512},
    )


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ({"n_timesteps": 100, "n_steps": 8, "normalize": True}, "'normalize' is not a GenRL setting"),
        ({"n_timesteps": 100, "n_steps": 8, "hindsight_kwargs": {"history": -1}}, r"hindsight_kwargs\['history'\]"),
        ({"n_timesteps": 100, "n_steps": 8, "policy": "CnnPolicy"}, "unknown policy 'CnnPolicy'"),
        ({"n_timesteps": 100, "n_steps": 8, "e_step": "kl_penalty", "hindsight_kwargs": {}}, "needs e_step='trpo'"),
        ({"n_steps": 8}, "needs n_timesteps"),
        ({"n_timesteps": 100, "n_steps": 1}, "the episodes per iteration, must be at least 2"),
        ({"n_timesteps": 100.5, "n_steps": 8}, "n_timesteps must be an integer of at least 1, got 100.5"),
        ({"n_timesteps": 100, "n_steps": 8.0}, "n_steps must be an integer of at least 1, got 8.0"),
        ({"n_timesteps": 100, "n_steps": 8, "n_envs": 0}, "n_envs must be an integer of at least 1, got 0"),
        (
            {"n_timesteps": 100, "n_steps": 8, "policy_kwargs": "dict(net_arch=[8], activation_fn=os.system)"},
            "'os.system' is not a class of torch.nn",
        ),
    ],
)
def test_a_bad_genrl_entry_gets_the_validators_error_naming_the_file_and_env_id(monkeypatch, entry, message):
    monkeypatch.setattr(hyperparams, "_entries", lambda algo: {"Toy/Reach-v0": entry})
    with pytest.raises(ValueError, match=message) as error:
        load_genrl_settings("Toy/Reach-v0")
    assert "genrl.yml" in str(error.value) and "Toy/Reach-v0" in str(error.value)


def test_a_budget_written_as_rl_zoo3_writes_it_is_taken_as_an_integer(monkeypatch):
    """rl-zoo3's files write budgets as floats (``n_timesteps: !!float 3e3``)."""
    entry = yaml.safe_load("n_timesteps: !!float 3e3\nn_steps: 16\n")
    monkeypatch.setattr(hyperparams, "_entries", lambda algo: {"Toy/Reach-v0": entry})
    episodes, batch_episodes, _ = load_genrl_settings("Toy/Reach-v0")
    assert episodes == 3000 and isinstance(episodes, int) and batch_episodes == 16


def test_n_envs_times_n_steps_is_the_batch():
    entries = {"Toy/Reach-v0": {"n_timesteps": 64, "n_envs": 2, "n_steps": 8}}
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(hyperparams, "_entries", lambda algo: entries)
        assert load_genrl_settings("Toy/Reach-v0") == (64, 16, {})


def test_policy_kwargs_strings_are_parsed_without_eval():
    assert parse_kwargs(
        "dict(log_std_init=-2, ortho_init=False, activation_fn=nn.ReLU, net_arch=dict(pi=[256, 256], vf=[256, 256]))"
    ) == {"log_std_init": -2, "ortho_init": False, "activation_fn": nn.ReLU, "net_arch": {"pi": [256, 256], "vf": [256, 256]}}
    assert parse_kwargs("dict(activation_fn=th.nn.Tanh, n=(1, 2.5), name='final', none=None)") == {
        "activation_fn": nn.Tanh,
        "n": (1, 2.5),
        "name": "final",
        "none": None,
    }
    assert parse_kwargs({"net_arch": [64]}) == {"net_arch": [64]} and parse_kwargs("{'a': 1}") == {"a": 1}
    for text in (
        "__import__('os').system('true')",
        "dict(a=open('x'))",
        "dict(a=nn.Module.__subclasses__)",
        "dict(a=nn.functional)",
        "dict(**x)",
        "dict(a=b)",
        "[1, 2]",
        "dict(a=-'x')",
        "dict(a=1 + 2)",
    ):
        with pytest.raises(ValueError, match="policy_kwargs: "):
            parse_kwargs(text, "policy_kwargs")


def test_lay_over_merges_mappings_and_replaces_the_rest():
    settings = {"hindsight_kwargs": {"history": 120, "regression_steps": 512}, "target_kl": 0.01, "policy_kwargs": {}}
    laid = lay_over(settings, {"hindsight_kwargs": {"history": 30}, "target_kl": 0.02, "gae": None})
    assert laid == {
        "hindsight_kwargs": {"history": 30, "regression_steps": 512},
        "target_kl": 0.02,
        "policy_kwargs": {},
        "gae": None,
    }
    assert lay_over(settings, {"hindsight_kwargs": None})["hindsight_kwargs"] is None  # hindsight off
    assert settings["hindsight_kwargs"]["history"] == 120  # unchanged


def test_the_genrl_that_train_policy_builds_is_the_entrys(hockey_generator, tmp_path, cli):
    from sb3_genrl.run.train import genrl_settings

    code, out, err = cli(
        "train-policy",
        "--task",
        "hockey",
        "--generator",
        hockey_generator,
        "--episodes",
        32,
        "--device",
        "cpu",
        "--no-progress-bar",
        "--out",
        tmp_path / "run",
    )
    assert code == 0, err
    assert "success:" not in out  # hockey's score is a distance: no line on a success it never reports
    _, batch_episodes, kwargs = load_genrl_settings("GenRL/Hockey-v0")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    # the command plays an iteration's episodes together by default: N = n_steps x n_envs = batch_episodes
    assert summary["n_envs"] == batch_episodes
    # and its minibatch is one iteration's episodes, GenRL's default of 64 capped at the batch
    n_steps = batch_episodes // summary["n_envs"]
    assert summary["genrl_settings"] == genrl_settings(kwargs | {"n_steps": n_steps, "batch_size": batch_episodes})
    assert summary["iterations"] == 32 // batch_episodes


def test_the_goal_seeds_are_named_once():
    assert (EVAL_GOAL_SEED, TUNING_GOAL_SEED) == (12345, 777)
    pattern = re.compile(r"\b(12345|777)\b")
    found = [
        str(path.relative_to(ROOT))
        for folder in ("sb3_genrl", "envs", "baselines", "benchmarks", "examples")
        for path in sorted((ROOT / folder).rglob("*.py"))
        if path.name != "hyperparams.py" and pattern.search(path.read_text())
    ]
    assert found == []


def test_changed_settings_names_each_setting_that_differs_from_genrls_defaults(monkeypatch):
    import sb3_genrl.hyperparams as hyperparams

    settings = {
        "policy": "MlpPolicy",
        "batch_size": 64,
        "target_kl": 0.03,  # batch_size 64 is GenRL's default
        "policy_kwargs": {"net_arch": {"pi": [64, 64], "vf": [64, 64]}, "log_std_init": -2.0},
        "hindsight_kwargs": {"history": 1, "regression_steps": 64},  # history 1 is the default
        "callback": [{"sb3_genrl.genrl.demonstrations.DemonstrationCallback": {"fit_steps": 100, "keep": True}}],
    }
    monkeypatch.setattr(hyperparams, "load_genrl_settings", lambda env_id: (3000, 32, settings))
    assert hyperparams.changed_settings("Any-v0") == [
        "n_steps",
        "target_kl",
        "policy_kwargs.log_std_init",
        "hindsight_kwargs",
        "hindsight_kwargs.regression_steps",
        "callback: DemonstrationCallback",
        "DemonstrationCallback.fit_steps",
    ]
    monkeypatch.setattr(hyperparams, "load_genrl_settings", lambda env_id: (3000, 64, {"policy": "ContextStdPolicy"}))
    assert hyperparams.changed_settings("Any-v0") == ["policy"]


def test_the_readme_counts_the_settings_each_task_changes(monkeypatch):
    readme = (Path(__file__).parents[1] / "README.md").read_text()
    rows = [line for line in readme.splitlines() if line.startswith("| ") and re.search(r"\| \d+: ", line)]
    counted = {}
    for line in rows:
        ids, count = re.findall(r"`([^`]+)`", line.split("|")[2]), int(re.search(r"\| (\d+): ", line).group(1))
        counted |= dict.fromkeys(ids, count)
    # the row of the tasks without an entry counts the settings the quickstart gives them
    entry_less = counted.pop("metaworld/<name>")
    assert counted == {env_id: len(hyperparams.changed_settings(env_id)) for env_id in hyperparams.known_env_ids("genrl")}
    outside = (DEFAULT_POLICY_EPISODES, DEFAULT_BATCH_EPISODES, copy.deepcopy(OUTSIDE_TASK_KWARGS))
    monkeypatch.setattr(hyperparams, "load_genrl_settings", lambda env_id: outside)
    assert entry_less == len(hyperparams.changed_settings("metaworld/<name>"))


@pytest.mark.parametrize("path", sorted((ROOT / "hyperparams").glob("*.yml")), ids=lambda path: path.name)
def test_settings_files_keep_one_line_comments_and_leave_the_reasons_to_the_docs(path):
    lines = path.read_text().splitlines()
    header = 0
    while header < len(lines) and lines[header].startswith("#"):
        header += 1
    assert header <= 3, f"{path.name}: a header of {header} comment lines (at most 3; the reasons go to the docs)"
    comment_only = [i for i, line in enumerate(lines[header:], start=header) if line.lstrip().startswith("#")]
    runs = [i for i in comment_only if i - 1 in comment_only]
    assert not runs, f"{path.name}: comments of several lines at line {runs[0]} (one line per setting)"
    assert all(len(line) <= 127 for line in lines), path.name
