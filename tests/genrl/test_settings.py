"""The check of GenRL's settings (sb3_genrl/genrl/settings.py) and the command line's --genrl-kwargs."""

from __future__ import annotations

import argparse

import gymnasium as gym
import pytest
from conftest import FastReachEnv, LinearGenerator, ReachEnv

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.genrl import check_genrl_settings


def test_check_genrl_settings_refuses_unknown_names_and_policies():
    settings = {
        "policy": "ContextStdPolicy",
        "target_kl": 0.03,
        "policy_kwargs": {"net_arch": [8]},
        "hindsight_kwargs": {"history": 2},
    }
    checked = check_genrl_settings(settings)
    assert checked == settings and checked is not settings and type(checked) is dict  # a plain copy
    assert checked["hindsight_kwargs"] is not settings["hindsight_kwargs"]
    with pytest.raises(ValueError, match=r"--genrl-kwargs: 'target_kll' is not a GenRL setting"):
        check_genrl_settings({"target_kll": 0.03}, "--genrl-kwargs")
    with pytest.raises(ValueError, match=r"'a', 'seed' are not GenRL settings"):  # where it runs is not a setting
        check_genrl_settings({"seed": 1, "a": 2})
    with pytest.raises(ValueError, match="unknown policy 'CnnPolicy'"):
        check_genrl_settings({"policy": "CnnPolicy"})
    with pytest.raises(TypeError, match="expected a dict"):
        check_genrl_settings([("target_kl", 0.03)])
    # the values GenRL would refuse, before any work: alone, and against the others' defaults (e_step="trpo")
    with pytest.raises(ValueError, match="--genrl-kwargs: value_history must be a positive integer, got 0"):
        check_genrl_settings({"value_history": 0}, "--genrl-kwargs")
    with pytest.raises(ValueError, match="hindsight_kwargs needs e_step='trpo'"):
        check_genrl_settings({"hindsight_kwargs": {}, "e_step": "kl_penalty"})
    assert check_genrl_settings({"hindsight_kwargs": {"history": 2}}) == {"hindsight_kwargs": {"history": 2}}
    assert check_genrl_settings({"hindsight_kwargs": None, "e_step": "kl_penalty"}) == {
        "hindsight_kwargs": None,
        "e_step": "kl_penalty",
    }


def test_genrl_kwargs_argument_parses_and_checks_json():
    from sb3_genrl.genrl.train import genrl_kwargs_argument, genrl_kwargs_override_argument

    # settings laid over a task's are checked as any others: one hindsight_kwargs dict holds the settings that
    # depend on each other
    text = '{"hindsight_kwargs": {"regression_steps": 8}}'
    assert genrl_kwargs_override_argument(text) == genrl_kwargs_argument(text) == {"hindsight_kwargs": {"regression_steps": 8}}
    for parse in (genrl_kwargs_argument, genrl_kwargs_override_argument):
        with pytest.raises(argparse.ArgumentTypeError, match="needs regression_steps > 0"):
            parse('{"hindsight_kwargs": {"regression_weighted": true}}')
        with pytest.raises(argparse.ArgumentTypeError, match="'x' is not a GenRL setting"):
            parse('{"x": 1}')

    assert genrl_kwargs_argument('{"target_kl": 0.03}') == {"target_kl": 0.03}
    for text, message in (("{", "not JSON"), ("[1]", "expected a dict"), ('{"x": 1}', "'x' is not a GenRL setting")):
        with pytest.raises(argparse.ArgumentTypeError, match=message):
            genrl_kwargs_argument(text)


@pytest.mark.parametrize(
    ("hindsight_kwargs", "message"),
    [
        ({"regression_steps": -1}, r"hindsight_kwargs\['regression_steps'\] must be an integer >= 0, got -1"),
        ({"regression_steps": 1.5}, r"hindsight_kwargs\['regression_steps'\] must be an integer >= 0"),
        ({"regression_steps": True}, r"hindsight_kwargs\['regression_steps'\] must be an integer >= 0"),
        ({"regression_lr": 0.0}, r"hindsight_kwargs\['regression_lr'\] must be positive"),
        ({"regression_batch_size": 0}, r"hindsight_kwargs\['regression_batch_size'\] must be an integer >= 1"),
        ({"regression_batch_size": True}, r"hindsight_kwargs\['regression_batch_size'\] must be an integer >= 1"),
        (
            {"regression_steps": 4, "regression_weighted": 1},
            r"hindsight_kwargs\['regression_weighted'\] must be True or False",
        ),
        (
            {"regression_weighted": True},
            r"hindsight_kwargs\['regression_weighted'\] weights the regression's pulls, which "
            "needs regression_steps > 0",
        ),
        ({"refit_every": -64}, r"hindsight_kwargs\['refit_every'\] must be an integer >= 0, got -64"),
        ({"refit_every": 64, "refit_steps": 0}, r"hindsight_kwargs\['refit_steps'\] must be an integer >= 1, got 0"),
        ({"refit_every": 64, "refit_start": 0}, r"hindsight_kwargs\['refit_start'\] must be an integer >= 1 or None"),
        (
            {"refit_start": 512},
            r"hindsight_kwargs\['refit_start'\] is the episode of the first refit, which needs "
            "refit_every > 0",
        ),
        ({"history": 0}, r"hindsight_kwargs\['history'\] must be an integer >= 1, got 0"),
        ({"history": 1.5}, r"hindsight_kwargs\['history'\] must be an integer >= 1"),
        ({"histroy": 2}, r"hindsight_kwargs: 'histroy' not among its settings \(history, regression_steps"),
        ("yes", "hindsight_kwargs must be a dict or None, got 'yes'"),
        (True, "hindsight_kwargs must be a dict or None, got True"),
    ],
    ids=[
        "steps-negative",
        "steps-fraction",
        "steps-bool",
        "lr-zero",
        "batch-zero",
        "batch-bool",
        "weighted-int",
        "weighted-without-steps",
        "refit-negative",
        "refit-steps-zero",
        "refit-start-zero",
        "refit-start-without-every",
        "history-zero",
        "history-fraction",
        "unknown-key",
        "string",
        "bool",
    ],
)
def test_hindsight_kwargs_are_checked(hindsight_kwargs, message):
    with pytest.raises(ValueError, match=message):
        GenRL(FastReachEnv(), LinearGenerator(), hindsight_kwargs=hindsight_kwargs)
    with pytest.raises(ValueError, match=f"--genrl-kwargs: {message}"):
        check_genrl_settings({"hindsight_kwargs": hindsight_kwargs}, "--genrl-kwargs")


def test_hindsight_is_checked():
    with pytest.raises(ValueError, match="hindsight_kwargs needs e_step='trpo'"):
        GenRL(FastReachEnv(), LinearGenerator(), hindsight_kwargs={}, e_step="kl_penalty")
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, hindsight_kwargs={})  # its task has no hindsight(info)
    with pytest.raises(ValueError, match=r"info\['hindsight'\]"):
        model.learn(64)
    assert model.num_timesteps == 1  # refused at the first pull, not after the rollout
    dict_env = LatentActionWrapper(
        ReachEnv(),
        LinearGenerator(),
        context=lambda obs: {"goal": obs[:2]},
        context_space=gym.spaces.Dict({"goal": gym.spaces.Box(-1, 1, (2,))}),
    )
    with pytest.raises(ValueError, match="hindsight_kwargs relabels Box contexts"):
        GenRL("MultiInputPolicy", dict_env, hindsight_kwargs={})


def test_one_episode_per_batch_is_refused_as_sb3_and_sb3_contrib_refuse_it():
    from conftest import FastReachEnv, LinearGenerator

    for expected in (ValueError, AssertionError):  # sb3-genrl's convention and SB3's (PPO, TRPO: AssertionError)
        with pytest.raises(expected, match="n_steps \\* n_envs >= 2"):
            GenRL(FastReachEnv(), LinearGenerator(), n_steps=1)


def test_a_batch_size_of_zero_is_refused_naming_it():
    with pytest.raises(ValueError, match="batch_size must be a positive integer, got 0"):
        GenRL(FastReachEnv(), LinearGenerator(), batch_size=0)
    with pytest.raises(ValueError, match="batch_size must be a positive integer, got 0"):
        check_genrl_settings({"batch_size": 0})
